"""The stages of one trial, as plain functions a Dask worker (or the calling process) runs.

Each stage takes the trial's :class:`~wingphoto.batch.manifest.TrialSpec` and folder
paths (never image data: frames are read where the stage runs, from the paths), writes its
result into the trial's work folder ``OUT/.partial/ID`` atomically, and returns a small
dict. A stage whose result file already exists returns at once, which is how an
interrupted batch resumes; the tracker's own checkpoint resumes a half-tracked sequence.
:func:`finish_trial` renames the work folder to ``OUT/trials/ID`` when everything is
written, so a trial folder is either complete or absent.

Every stage appends to the trial's ``log.txt`` (its own messages, the library's warnings,
and the traceback of a failure) and raises :class:`TrialError` naming the stage on failure.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import shutil
import threading
import time
import traceback
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["TrialError", "calibrate_shared", "check_sequences", "track_camera", "finish_trial",
           "TRIAL_FILE", "LENGTH_COLUMNS"]

log = logging.getLogger(__name__)
#: Per-trial messages go to the trial's log file only (not to the console).
_TRIAL_LOG = logging.getLogger("wingphoto_batch_trial")
_TRIAL_LOG.propagate = False
_TRIAL_LOG.setLevel(logging.INFO)

#: Written last into a finished trial folder; holds the fingerprint that lets a re-run skip it.
TRIAL_FILE = "trial.json"
#: Columns of a trial's ``lengths.csv`` (one row per frame and length pair, mm).
LENGTH_COLUMNS = ("frame", "i", "j", "length")


class TrialError(Exception):
    """A trial stage failed: ``stage`` names it and ``message`` says why.

    Parameters
    ----------
    stage : str
        ``calibrate``, ``check sequences``, ``track left``, ``track right`` or ``analyse``.
    message : str
        The original error's type and message.
    log : str, optional
        The log file holding the traceback (the trial's, or a shared stage's).
    """

    def __init__(self, stage, message, log=None):
        super().__init__(stage, message, log)
        self.stage = stage
        self.message = message
        self.log = log

    def __str__(self):
        return f"{self.stage}: {self.message}"


# ----------------------------------------------------------------------------- plumbing
class _ThreadFilter(logging.Filter):
    """Keep the records of one thread: concurrent trials in one worker keep separate logs."""

    def __init__(self):
        super().__init__()
        self.ident = threading.get_ident()

    def filter(self, record):
        return record.thread == self.ident


_pyplot_lock = threading.Lock()
_cv_lock = threading.Lock()
_cv_users = 0
_cv_saved = None


@contextlib.contextmanager
def _single_threaded_opencv():
    """Run OpenCV on one thread while inside (restored when the last user leaves).

    OpenCV's multi-threaded chessboard detection gives results that differ in the last
    bits from run to run; one thread makes every stage reproducible bit for bit, so the
    batch tables are identical whichever engine ran them. The batch gets its parallelism
    from running trials and cameras side by side instead.
    """
    global _cv_users, _cv_saved
    import cv2

    with _cv_lock:
        if _cv_users == 0:
            _cv_saved = cv2.getNumThreads()
            cv2.setNumThreads(0)
        _cv_users += 1
    try:
        yield
    finally:
        with _cv_lock:
            _cv_users -= 1
            if _cv_users == 0:
                cv2.setNumThreads(_cv_saved)


@contextlib.contextmanager
def _stage(trial_id, stage, log_path):
    """Log a stage into the trial's log file, time it, and turn a failure into TrialError."""
    log_path = Path(log_path)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(log_path, encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    handler.addFilter(_ThreadFilter())
    loggers = (logging.getLogger("wingphoto"), _TRIAL_LOG)
    for lg in loggers:
        lg.addHandler(handler)
    timing = {"wall_s": 0.0, "cpu_s": 0.0}
    t0, c0 = time.perf_counter(), time.thread_time()
    _TRIAL_LOG.info("trial %s: %s started (process %d)", trial_id, stage, os.getpid())
    try:
        with _single_threaded_opencv():
            yield timing
    except TrialError:
        raise
    except Exception as exc:
        _TRIAL_LOG.error("trial %s: %s failed:\n%s", trial_id, stage, traceback.format_exc().rstrip())
        raise TrialError(stage, f"{type(exc).__name__}: {exc}", str(log_path)) from None
    else:
        timing["wall_s"] = round(time.perf_counter() - t0, 3)
        timing["cpu_s"] = round(time.thread_time() - c0, 3)
        _TRIAL_LOG.info("trial %s: %s done in %.2f s (%.2f s CPU)", trial_id, stage,
                        timing["wall_s"], timing["cpu_s"])
    finally:
        for lg in loggers:
            lg.removeHandler(handler)
        handler.close()


def _write_json(path, data):
    from ..io import atomic_write

    with atomic_write(path, "w") as f:
        f.write(json.dumps(data, indent=1, sort_keys=True) + "\n")


def _read_json(path):
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


# ----------------------------------------------------------------------------- calibrate
def _content_key(spec):
    """sha256 over the calibration images' names and bytes, the board and the options."""
    from ..io import read_sequence

    h = hashlib.sha256()
    h.update(json.dumps({"pattern_size": spec.pattern_size, "square_size": spec.square_size,
                         "options": spec.options}, sort_keys=True, default=list).encode())
    for side in (spec.left, spec.right):
        seq = read_sequence(side)
        h.update(f"|{side.__class__.__name__}|{len(seq.paths)}".encode())
        for p in seq.paths:
            h.update(Path(p).name.encode())
            with open(p, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
    return h.hexdigest()[:24]


def calibrate_shared(spec, cache_dir):
    """Stereo calibration of one :class:`CalibrationSpec`, cached by content.

    A ``.mat`` calibration is only checked (loaded). Calibration folders are calibrated
    with :func:`wingphoto.pipeline.calibrate_folders` unless ``cache_dir`` already holds the
    result for the same images (bytes), board and options; the key is a sha256 of them.

    Returns
    -------
    dict
        ``mat`` (path of the stereo .mat), ``summary`` (text file or None), ``key``,
        ``cached`` (bool), ``wall_s``, ``cpu_s``.
    """
    from .. import pipeline
    from ..io import atomic_write, load_bouguet_stereo

    cache_dir = Path(cache_dir)
    name = spec.key()
    with _stage("(shared)", "calibrate", cache_dir / f"calibrate-{name}.log") as timing:
        if spec.mat is not None:
            load_bouguet_stereo(spec.mat)  # fails here, with the file named, if unreadable
            return {"mat": spec.mat, "summary": None, "key": name, "cached": True, **timing}
        key = _content_key(spec)
        mat = cache_dir / f"{key}.mat"
        txt = cache_dir / f"{key}.txt"
        if mat.is_file() and txt.is_file():
            _TRIAL_LOG.info("calibration %s from the cache (%s)", key, mat)
            return {"mat": str(mat), "summary": str(txt), "key": key, "cached": True, **timing}
        result = pipeline.calibrate_folders(spec.left, spec.right, spec.pattern_size, spec.square_size,
                                            out=mat, progress=False, **spec.options)
        with atomic_write(txt, "w") as f:
            f.write(result.summary() + "\n")
    return {"mat": str(mat), "summary": str(txt), "key": key, "cached": False, **timing}


# ----------------------------------------------------------------------------- sequences
def _open_sequence(trial, camera):
    """The trial's sequence of one camera, cut to its frame range, and the frame numbers."""
    from ..io import read_sequence

    seq = read_sequence(getattr(trial, camera))
    numbers = np.arange(len(seq), dtype=np.int64)
    if trial.frames is not None:
        start, stop, step = trial.frames
        if stop > len(seq):
            raise ValueError(
                f"frames = [{start}, {stop}] asks for frames up to {stop - 1} but the {camera} sequence "
                f"{getattr(trial, camera)} has {len(seq)} frames (0-{len(seq) - 1}); fix the trial's frames"
            )
        seq = seq[start:stop:step]
        numbers = numbers[start:stop:step]
    return seq, numbers


def check_sequences(left, right, log_dir, calibration=None):
    """Check a left/right pair of recordings (duplicates, blanks, gaps, jumps, offset).

    Uses :func:`wingphoto.integrity.check_stereo_sequences` on the whole recordings, not
    only a trial's frame range: a dropped or doubled frame anywhere before the range puts
    the two views out of step inside it, and the offset estimate needs the motion of many
    frames. Trials cut from the same recordings share one check. With ``calibration``
    (a :func:`calibrate_shared` result) the rig is passed on, so the left/right offset comes
    from epipolar geometry. Skipped, with a note, when ``wingphoto.integrity`` is not
    available.

    Returns
    -------
    dict
        ``ok`` (bool), ``text`` (the report), ``wall_s``, ``cpu_s``. A failed check is
        not raised here: :func:`track_camera` stops the trial unless it sets ``force``.
    """
    rig_key = (calibration or {}).get("key", "")
    key = hashlib.sha256(f"{left}\n{right}\n{rig_key}".encode()).hexdigest()[:16]
    with _stage("(shared)", "check sequences", Path(log_dir) / f"check-{key}.log") as timing:
        try:
            from ..integrity import check_stereo_sequences
        except ImportError:
            text = "sequence check skipped: wingphoto.integrity.check_stereo_sequences is not available"
            ok = True
        else:
            import inspect

            options = {}
            if calibration is not None and "rig" in inspect.signature(check_stereo_sequences).parameters:
                from ..io import load_bouguet_stereo

                options["rig"] = load_bouguet_stereo(calibration["mat"])[0]
            report = check_stereo_sequences(left, right, **options)
            text, ok = report.summary(), bool(report.ok)
        _TRIAL_LOG.info("%s", text)
    return {"ok": ok, "text": text, **timing}


# ----------------------------------------------------------------------------- track
def _trial_picks(trial, camera):
    from .. import pipeline

    table = pipeline.load_picks(trial.picks, camera)
    if trial.points is not None:
        missing = sorted(set(trial.points) - set(table["point"].astype(int)))
        if missing:
            raise ValueError(f"{trial.picks} has no {camera} picks for markers {missing} listed in points; "
                             "pick them or remove them from points")
        table = table[table["point"].isin(trial.points)].reset_index(drop=True)
    if "frame" in table.columns and trial.frames is not None:
        start, stop, step = trial.frames
        rel = (table["frame"].to_numpy(np.int64) - start)
        if np.any(rel % step) or np.any(rel < 0) or np.any(rel >= stop - start):
            raise ValueError(f"{trial.picks}: {camera} picks were made in frames "
                             f"{sorted(set(table['frame'].tolist()))}, not inside frames = "
                             f"[{start}, {stop}, {step}] of the trial")
        table = table.assign(frame=rel // step)
    return table


def _require_check(trial, check, work):
    """Stop the trial on a failed sequence check unless it sets force; record the report."""
    from ..io import atomic_write

    work = Path(work)
    if not check["ok"] and not trial.force:
        with _stage(trial.id, "check sequences", work / "log.txt"):
            _TRIAL_LOG.error("sequence check failed:\n%s", check["text"])
        raise TrialError("check sequences", f"{check['text'].strip().splitlines()[-1]} (see the trial's log; "
                         "fix the sequences, or set force = true for this trial to go on anyway)",
                         str(work / "log.txt"))
    path = work / "sequence_check.txt"
    if not path.is_file():
        with atomic_write(path, "w") as f:
            f.write(check["text"].rstrip() + "\n" + ("" if check["ok"] else "FAILED; going on (force = true)\n"))


def track_camera(trial, camera, work, check):
    """Track one camera's sequence of a trial -> ``tracks_CAMERA.csv`` in the work folder.

    Frames are read here from the trial's paths. The tracker checkpoints into the work
    folder, so a killed worker resumes where it stopped. Frame numbers in the written
    table are the sequence's own (``frames = [30, 60]`` gives frames 30-59).

    Parameters
    ----------
    check : dict
        Result of :func:`check_sequences` for the trial's recordings; a failed check stops
        the trial (stage ``check sequences``) unless ``trial.force``.
    """
    from .. import pipeline
    from ..io import write_tracks_csv

    work = Path(work)
    _require_check(trial, check, work)
    out = work / f"tracks_{camera}.csv"
    if out.is_file():
        return {"path": str(out), "skipped": True, "wall_s": 0.0, "cpu_s": 0.0}
    with _stage(trial.id, f"track {camera}", work / "log.txt") as timing:
        seq, numbers = _open_sequence(trial, camera)
        picks = _trial_picks(trial, camera)
        ckpt = work / f"checkpoint_{camera}.npz"
        tracks = pipeline.track_folder(seq, picks, camera=camera, checkpoint=ckpt, progress=False, **trial.track)
        tracks["frame"] = numbers[tracks["frame"].to_numpy(np.int64)]
        write_tracks_csv(tracks, out)
        counts = tracks["status"].value_counts().to_dict()
        _TRIAL_LOG.info("%s: %d frames x %d markers: %s", camera, len(seq), tracks["point"].nunique(), counts)
        ckpt.unlink(missing_ok=True)
    return {"path": str(out), "skipped": False, **timing}


# ----------------------------------------------------------------------------- finish
def _lengths(points, pairs):
    """Tidy per-frame lengths (frame, i, j, length) of the pairs, mm."""
    from ..analysis import pairwise_distance

    parts = []
    for i, j in pairs:
        d = pairwise_distance(points, i, j)
        parts.append(pd.DataFrame({"frame": d.index.to_numpy(np.int64), "i": np.int64(i), "j": np.int64(j),
                                   "length": d.to_numpy(np.float64)}))
    if not parts:
        return pd.DataFrame({c: pd.Series(dtype=np.int64 if c != "length" else np.float64) for c in LENGTH_COLUMNS})
    return pd.concat(parts, ignore_index=True)


def _analyse(points, tracks, settings, work):
    """The trial's own analysis tables: wingphoto.pipeline.analyse_points when present."""
    from .. import pipeline
    from ..io import atomic_write

    analyse_points = getattr(pipeline, "analyse_points", None)
    if analyse_points is not None:
        with _pyplot_lock:  # its figures go through pyplot, whose state threads share
            tables = analyse_points(points, settings, out=work / "analysis", tracks=tracks)
        return sorted(tables)
    from ..analysis import length_statistics, reference_stillness

    written = []
    if settings.length_pairs:
        stats = length_statistics(points, list(settings.length_pairs))
        with atomic_write(work / "length_statistics.csv", "w", newline="") as f:
            stats.to_csv(f, index=False)
        written.append("length_statistics")
    if settings.reference_ids:
        still = reference_stillness(points, list(settings.reference_ids), tol_mm=settings.reference_tol_mm)
        with atomic_write(work / "reference_stillness.csv", "w", newline="") as f:
            still.table.to_csv(f, index=False)
        written.append("reference_stillness")
        _TRIAL_LOG.info("reference stillness: %s", "valid" if still.valid else "INVALID (references moved)")
    _TRIAL_LOG.info("analysis by wingphoto.analysis (wingphoto.pipeline.analyse_points not available)")
    return written


def _replace_folder(work, final):
    """Move the finished work folder to its final place (replacing a stale one)."""
    final.parent.mkdir(parents=True, exist_ok=True)
    stale = None
    if final.exists():
        stale = work.parent / f"{work.name}.stale-{os.getpid()}-{threading.get_ident()}"
        os.replace(final, stale)
    os.replace(work, final)
    if stale is not None:
        shutil.rmtree(stale, ignore_errors=True)


def finish_trial(trial, work, final, calibration, left, right, check=None):
    """Stereo-check, triangulate and analyse a tracked trial, then publish its folder.

    Writes into ``work``: ``Calib_Results_stereo.mat`` (a copy), ``tracks.csv`` (both
    cameras after :func:`wingphoto.track.check_stereo`), ``points3d.csv``, ``lengths.csv``
    (frame, i, j, length in mm for the ``[analysis] length_pairs``), the analysis tables,
    and last ``trial.json``; then renames ``work`` to ``final``.

    Parameters
    ----------
    calibration, left, right, check : dict
        Results of :func:`calibrate_shared`, :func:`track_camera` (both cameras) and
        :func:`check_sequences` (shared by the trials of the same recordings).

    Returns
    -------
    dict
        The contents of ``trial.json``.
    """
    from ..io import atomic_write, load_bouguet_stereo, read_tracks_csv, write_points_csv, write_tracks_csv
    from ..track import check_stereo
    from ..triangulate import triangulate_tracks

    work, final = Path(work), Path(final)
    with _stage(trial.id, "analyse", work / "log.txt") as timing:
        rig, _ = load_bouguet_stereo(calibration["mat"])
        with atomic_write(work / "Calib_Results_stereo.mat", "wb") as f:
            f.write(Path(calibration["mat"]).read_bytes())
        if calibration.get("summary"):
            with atomic_write(work / "calibration_summary.txt", "w") as f:
                f.write(Path(calibration["summary"]).read_text(encoding="utf-8"))
        tl, tr = check_stereo(read_tracks_csv(left["path"]), read_tracks_csv(right["path"]), rig)
        tracks = pd.concat([tl, tr], ignore_index=True)
        write_tracks_csv(tracks, work / "tracks.csv")
        points = triangulate_tracks(tl, tr, rig)
        write_points_csv(points, work / "points3d.csv")
        settings = trial.settings()
        lengths = _lengths(points, settings.length_pairs)
        with atomic_write(work / "lengths.csv", "w", newline="") as f:
            lengths.to_csv(f, index=False)
        tables = _analyse(points, tracks, settings, work)
        status = tracks["status"].astype(str)
        record = {
            "id": trial.id,
            "fingerprint": trial.fingerprint(),
            "labels": trial.labels,
            "spec": trial.to_dict(),
            "n_frames": int(tracks["frame"].nunique()),
            "n_points": int(tracks["point"].nunique()),
            "n_observations": len(tracks),
            "n_ok": int((status == "ok").sum()),
            "status_counts": {k: int(v) for k, v in status.value_counts().sort_index().items()},
            "calibration": {k: calibration[k] for k in ("mat", "key", "cached")},
            "analysis_tables": tables,
        }
        for p in (left["path"], right["path"], work / "fingerprint.txt"):
            Path(p).unlink(missing_ok=True)  # tracks merged into tracks.csv; fingerprint in trial.json
    record["timing"] = {
        "calibrate": {k: calibration[k] for k in ("wall_s", "cpu_s")},
        "check sequences": {k: (check or {}).get(k, 0.0) for k in ("wall_s", "cpu_s")},
        "track left": {k: left[k] for k in ("wall_s", "cpu_s")},
        "track right": {k: right[k] for k in ("wall_s", "cpu_s")},
        "analyse": dict(timing),
    }
    record["resumed"] = bool(left.get("skipped") or right.get("skipped"))
    _write_json(work / TRIAL_FILE, record)
    _replace_folder(work, final)
    return record
