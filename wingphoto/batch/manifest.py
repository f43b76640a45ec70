"""The batch manifest: one TOML file listing the trials of a study and how to run each.

A manifest has an optional ``[batch]`` table, an optional ``[defaults]`` table holding any
trial key (shared by every trial; a trial's own value wins), and one ``[[trial]]`` table per
trial. The reference, with an example, is ``docs/batch.md``; in short::

    [batch]
    name = "sample study"
    group_by = ["condition"]          # label columns of summary.csv (default: every label)

    [defaults]
    calibration = {left = "calibration/left", right = "calibration/right",
                   pattern_size = [9, 6], square_size = 8.0}   # or "Calib_Results_stereo.mat"
    left = "flapping/left"            # any wingphoto.read_sequence source
    right = "flapping/right"
    picks = "flapping/picks.json"     # wingphoto.picks file (JSON or CSV)

    [defaults.analysis]               # the [analysis] schema of wingphoto.config
    length_pairs = [[18, 19], [20, 21]]
    reference_ids = [20, 21, 22, 23, 24, 25]

    [[trial]]
    id = "open-1"
    labels = {condition = "open air", wing = "engineered"}
    frames = [0, 30]                  # [start, stop) or [start, stop, step] of the sequence

Relative paths are relative to the manifest's folder. Every key is checked when the
manifest is read, so a typo fails before any work starts.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import tomllib

__all__ = ["CalibrationSpec", "TrialSpec", "Manifest", "load_manifest", "TRIAL_KEYS"]

#: Keys a ``[[trial]]`` (or ``[defaults]``) table may hold.
TRIAL_KEYS = ("id", "labels", "calibration", "left", "right", "picks", "frames", "points",
              "analysis", "track", "force")
#: Keys of a calibration table (calibration from folders of checkerboard pairs).
CALIBRATION_KEYS = ("left", "right", "pattern_size", "square_size", "options")
_MERGED = ("labels", "analysis", "track")  # tables merged key by key over the defaults
_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
_GLOB = re.compile(r"[*?\[]")


def _resolve(base, value, what, source):
    """An absolute path string for ``value`` (relative to ``base``); globs kept as patterns."""
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"{source}: {what} must be a path string, got {value!r}")
    text = os.path.expanduser(value)
    if not os.path.isabs(text):
        text = os.path.join(str(base), text)
    return os.path.normpath(text) if not _GLOB.search(text) else text


@dataclass(frozen=True)
class CalibrationSpec:
    """Where a trial's stereo calibration comes from.

    Either ``mat`` (a toolbox ``Calib_Results_stereo.mat``) or the calibration folders
    ``left``/``right`` with the board's ``pattern_size`` (inner corners per row and
    column) and ``square_size`` (mm); ``options`` go to
    :func:`wingphoto.calibrate.calibrate_stereo`. Paths are absolute.
    """

    mat: str | None = None
    left: str | None = None
    right: str | None = None
    pattern_size: tuple | None = None
    square_size: float | None = None
    options: dict = field(default_factory=dict)

    def key(self):
        """A short hash of the specification: trials with equal keys share one calibration."""
        text = json.dumps(dataclasses.asdict(self), sort_keys=True, default=list)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def describe(self):
        """One line naming the source."""
        if self.mat is not None:
            return f"calibration file {self.mat}"
        return (f"calibration folders {self.left} + {self.right} "
                f"(board {self.pattern_size[0]}x{self.pattern_size[1]}, {self.square_size:g} mm squares)")


@dataclass(frozen=True)
class TrialSpec:
    """One trial of a batch, with every path resolved and every default applied.

    Attributes
    ----------
    id : str
        Unique name; also the trial's output folder name.
    labels : dict of str -> str
        Condition labels (``condition``, ``wing``, ``repeat`` ...); ``summary.csv`` groups
        trials by them.
    calibration : CalibrationSpec
    left, right : str
        The two image sequences (folder, glob pattern or multi-page TIFF; absolute).
    picks : str
        Picks file (:func:`wingphoto.picks.load_picks`): each marker clicked in the first
        frame of ``frames``.
    frames : (int, int, int) or None
        ``(start, stop, step)`` slice of the sequences to analyse; None: all frames. Output
        tables keep the sequences' own frame numbers.
    points : tuple of int or None
        Markers to track and analyse; None: every picked marker.
    analysis : dict
        The ``[analysis]`` table (:class:`wingphoto.config.AnalysisSettings`).
    track : dict
        Options of :func:`wingphoto.track.track_markers` (``search_radius`` ...).
    force : bool
        Go on when the sequence check fails (the one ``--force`` of the CLI).
    """

    id: str
    labels: dict
    calibration: CalibrationSpec
    left: str
    right: str
    picks: str
    frames: tuple | None = None
    points: tuple | None = None
    analysis: dict = field(default_factory=dict)
    track: dict = field(default_factory=dict)
    force: bool = False
    source: str = field(default="manifest", compare=False, repr=False)

    def settings(self):
        """The trial's :class:`wingphoto.config.AnalysisSettings`."""
        from ..config import AnalysisSettings

        return AnalysisSettings.from_dict(self.analysis, source=f"{self.source} [analysis]")

    def fingerprint(self):
        """Hash of everything that changes the trial's results (labels excluded) and the picks.

        A finished trial whose fingerprint still matches is skipped on a re-run; one whose
        fingerprint changed is recomputed.
        """
        spec = {k: v for k, v in dataclasses.asdict(self).items() if k not in ("labels", "source", "id")}
        try:
            spec["picks_sha256"] = hashlib.sha256(Path(self.picks).read_bytes()).hexdigest()
        except OSError:
            spec["picks_sha256"] = None
        text = json.dumps(spec, sort_keys=True, default=list)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def to_dict(self):
        """Plain JSON-able values (written to the trial's ``trial.json``)."""
        d = dataclasses.asdict(self)
        d.pop("source")
        return json.loads(json.dumps(d, default=list))


@dataclass(frozen=True)
class Manifest:
    """A parsed batch manifest.

    Attributes
    ----------
    path : pathlib.Path
        The manifest file (absolute).
    name : str
        ``[batch] name`` (default: the file name).
    trials : tuple of TrialSpec
        In manifest order (the order of ``summary.csv`` and ``trials.csv``).
    group_by : tuple of str
        Label columns ``summary.csv`` groups by.
    """

    path: Path
    name: str
    trials: tuple
    group_by: tuple

    def __len__(self):
        return len(self.trials)

    def trial(self, trial_id):
        """The trial named ``trial_id``."""
        for t in self.trials:
            if t.id == trial_id:
                return t
        raise ValueError(f"{self.path}: no trial {trial_id!r}; trials: {[t.id for t in self.trials]}")


def _calibration(value, base, source):
    where = f"{source} calibration"
    if isinstance(value, str):
        mat = _resolve(base, value, "calibration", source)
        if not mat.lower().endswith(".mat"):
            raise ValueError(
                f"{where} = {value!r}: give a toolbox Calib_Results_stereo.mat, or a table "
                "{left = ..., right = ..., pattern_size = [9, 6], square_size = 8.0} of calibration folders"
            )
        return CalibrationSpec(mat=mat)
    if not isinstance(value, dict):
        raise ValueError(f"{where} must be a .mat path or a table of calibration folders, got {value!r}")
    unknown = sorted(set(value) - set(CALIBRATION_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; known keys: {list(CALIBRATION_KEYS)}")
    missing = [k for k in ("left", "right", "pattern_size", "square_size") if k not in value]
    if missing:
        raise ValueError(f"{where}: missing {missing} "
                         "(calibration folders need left, right, pattern_size, square_size)")
    ps = value["pattern_size"]
    if (not isinstance(ps, list) or len(ps) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 2 for v in ps)):
        raise ValueError(f"{where}: pattern_size must be two whole numbers of inner corners, e.g. [9, 6], got {ps!r}")
    sq = value["square_size"]
    if isinstance(sq, bool) or not isinstance(sq, (int, float)) or not sq > 0:
        raise ValueError(f"{where}: square_size must be a positive length in mm, got {sq!r}")
    options = value.get("options", {})
    if not isinstance(options, dict):
        raise ValueError(f"{where}: options must be a table of calibrate_stereo keyword arguments")
    return CalibrationSpec(left=_resolve(base, value["left"], "calibration.left", source),
                           right=_resolve(base, value["right"], "calibration.right", source),
                           pattern_size=tuple(ps), square_size=float(sq), options=dict(options))


def _frames(value, source):
    if value is None:
        return None
    ok = (isinstance(value, list) and len(value) in (2, 3)
          and all(isinstance(v, int) and not isinstance(v, bool) for v in value))
    if not ok or value[0] < 0 or value[1] <= value[0] or (len(value) == 3 and value[2] < 1):
        raise ValueError(
            f"{source}: frames must be [start, stop] or [start, stop, step] with 0 <= start < stop "
            f"and step >= 1 (frame numbers of the sequence, stop excluded), got {value!r}"
        )
    return (value[0], value[1], value[2] if len(value) == 3 else 1)


def _trial(raw, defaults, base, source, index):
    unknown = sorted(set(raw) - set(TRIAL_KEYS))
    if unknown:
        raise ValueError(f"{source}: trial {index + 1} has unknown key(s) {unknown}; known keys: {list(TRIAL_KEYS)}")
    tid = raw.get("id")
    if not isinstance(tid, str) or not _ID.match(tid):
        raise ValueError(
            f"{source}: trial {index + 1} needs an id of letters, digits, '.', '_' or '-' "
            f"(it names the trial's folder), got {tid!r}"
        )
    where = f"{source} trial {tid!r}"
    merged = dict(defaults)
    for key, value in raw.items():
        if key in _MERGED:
            if not isinstance(value, dict):
                raise ValueError(f"{where}: {key} must be a table (key = value), got {value!r}")
            merged[key] = {**merged.get(key, {}), **value}
        else:
            merged[key] = value
    for key in ("calibration", "left", "right", "picks"):
        if key not in merged:
            raise ValueError(f"{where}: no {key!r} (give it in the trial or in [defaults])")
    labels = {}
    for k, v in merged.get("labels", {}).items():
        if isinstance(v, (dict, list)):
            raise ValueError(f"{where}: label {k!r} must be a single value (text or number), got {v!r}")
        labels[str(k)] = str(v).lower() if isinstance(v, bool) else str(v)
    points = merged.get("points")
    if points is not None:
        if (not isinstance(points, list) or not points
                or not all(isinstance(p, int) and not isinstance(p, bool) and p >= 0 for p in points)):
            raise ValueError(f"{where}: points must be a non-empty list of marker numbers (from 0), got {points!r}")
        points = tuple(sorted(set(points)))
    force = merged.get("force", False)
    if not isinstance(force, bool):
        raise ValueError(f"{where}: force must be true or false, got {force!r}")
    spec = TrialSpec(
        id=tid,
        labels=labels,
        calibration=_calibration(merged["calibration"], base, where),
        left=_resolve(base, merged["left"], "left", where),
        right=_resolve(base, merged["right"], "right", where),
        picks=_resolve(base, merged["picks"], "picks", where),
        frames=_frames(merged.get("frames"), where),
        points=points,
        analysis=dict(merged.get("analysis", {})),
        track=dict(merged.get("track", {})),
        force=force,
        source=where,
    )
    settings = spec.settings()  # validate the [analysis] table now, not on a worker
    if points is not None:
        used = set(sum(settings.length_pairs, ())) | set(settings.reference_ids)
        missing = sorted(used - set(points))
        if missing:
            raise ValueError(f"{where}: [analysis] uses markers {missing} that are not in points = {list(points)}")
    return spec


def load_manifest(path):
    """Read and check a batch manifest (TOML).

    Parameters
    ----------
    path : str or Path
        The manifest file; relative paths inside it are relative to its folder.

    Returns
    -------
    Manifest

    Raises
    ------
    FileNotFoundError
        The manifest does not exist.
    ValueError
        Invalid TOML, an unknown key, a missing path key, a duplicate trial id, or invalid
        ``[analysis]`` settings; the message names the trial and the key.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "study.toml").write_text('''
    ... [defaults]
    ... calibration = "Calib_Results_stereo.mat"
    ... picks = "picks.json"
    ... [[trial]]
    ... id = "t1"
    ... labels = {condition = "vacuum"}
    ... left = "t1/left"
    ... right = "t1/right"
    ... frames = [0, 100]
    ... ''')
    >>> m = load_manifest(d / "study.toml")
    >>> m.trials[0].frames, m.trials[0].labels, m.group_by
    ((0, 100, 1), {'condition': 'vacuum'}, ('condition',))
    """
    path = Path(path).expanduser().resolve()
    if not path.is_file():
        raise FileNotFoundError(f"batch manifest {path} not found; see docs/batch.md for the format")
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path} is not valid TOML: {exc}") from None
    unknown = sorted(set(doc) - {"batch", "defaults", "trial"})
    if unknown:
        raise ValueError(f"{path}: unknown table(s) {unknown}; a manifest has [batch], [defaults] and [[trial]]")
    batch = doc.get("batch", {})
    bad = sorted(set(batch) - {"name", "group_by"})
    if bad:
        raise ValueError(f"{path}: unknown [batch] key(s) {bad}; known keys: ['name', 'group_by']")
    defaults = doc.get("defaults", {})
    if not isinstance(defaults, dict):
        raise ValueError(f"{path}: [defaults] must be a table")
    bad = sorted(set(defaults) - set(TRIAL_KEYS) | ({"id"} & set(defaults)))
    if bad:
        raise ValueError(f"{path}: [defaults] has key(s) {bad} that cannot be shared; "
                         f"known keys: {list(TRIAL_KEYS[1:])}")
    raws = doc.get("trial", [])
    if not isinstance(raws, list) or not raws:
        raise ValueError(f"{path}: no trials; add one [[trial]] table per trial (see docs/batch.md)")
    base = path.parent
    trials = tuple(_trial(raw, defaults, base, str(path), k) for k, raw in enumerate(raws))
    seen = set()
    for t in trials:
        if t.id.lower() in seen:
            raise ValueError(f"{path}: trial id {t.id!r} is used twice (ids name folders; make them unique)")
        seen.add(t.id.lower())
    labels = list(dict.fromkeys(k for t in trials for k in t.labels))
    group_by = batch.get("group_by", labels)
    if isinstance(group_by, str):
        group_by = [group_by]
    if not isinstance(group_by, list) or not all(isinstance(g, str) for g in group_by):
        raise ValueError(f"{path}: [batch] group_by must be a list of label names, got {group_by!r}")
    missing = [g for g in group_by if g not in labels]
    if missing:
        raise ValueError(f"{path}: [batch] group_by names label(s) {missing} that no trial has; labels: {labels}")
    return Manifest(path=path, name=str(batch.get("name", path.stem)), trials=trials, group_by=tuple(group_by))
