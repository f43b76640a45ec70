"""The one analysis-settings schema: which markers are what, and how to analyse them.

:class:`AnalysisSettings` says, in the user's own marker numbering, which pairs of points
have rigid lengths, which points are the static references, which lie on the leading and
trailing edges, where the wing root is, and the few options of the kinematics, surface,
time and uncertainty stages. The same schema is read

* from the ``[analysis]`` table of a TOML file by :func:`load_analysis_settings` (the
  ``wingphoto analyse --config analysis.toml`` command), and
* from the ``[analysis]`` table of a batch manifest (the batch command embeds it and calls
  :meth:`AnalysisSettings.from_dict` on that table).

An example file (every key is optional; the defaults are those of the dataclass)::

    [analysis]
    length_pairs = [[18, 19], [20, 21]]          # rigid lengths to check (i, j)
    nominal_lengths = {"18-19" = 10.77}           # known lengths, mm ("i-j" keys)
    reference_ids = [20, 21, 22, 23, 24, 25]      # static reference dots
    leading_edge = [0, 3, 6, 9, 12, 15]           # tip to root
    trailing_edge = [2, 5, 8, 11, 14, 17]         # same stations, tip to root
    chord_rows = [[0, 1, 2], [3, 4, 5]]           # optional: LE..TE per station (camber)
    hinge = [-12.3, 4.5, 401.0]                   # fixed wing-root point, mm (or root = id)
    fps = 3000.0

Marker numbers are the ``point`` numbers of the points table (``docs/conventions.md``).
Kinematic definitions and sign conventions: ``docs/kinematics.md``.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["AnalysisSettings", "load_analysis_settings", "INTERPOLATIONS", "SURFACE_MODELS"]

log = logging.getLogger(__name__)

#: Time interpolation methods of the phase resampling (``docs/kinematics.md``).
INTERPOLATIONS = ("linear", "cubic", "cardinal")
#: Wing-surface models of :func:`wingphoto.kinematics.fit_wing_surface`.
SURFACE_MODELS = ("poly2", "poly3", "tps")


def _int_tuple(value, name, source):
    if value is None:
        return ()
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise ValueError(f"{source}: {name} must be a list of marker numbers (int), got {value!r}")
    out = []
    for v in value:
        if isinstance(v, bool) or not float(v).is_integer():
            raise ValueError(f"{source}: {name} must hold whole marker numbers, got {v!r}")
        if int(v) < 0:
            raise ValueError(f"{source}: {name} holds {v}; marker numbers start at 0")
        out.append(int(v))
    return tuple(out)


def _pair_key(key, source):
    """(i, j) from a tuple/list or an "i-j" / "i,j" string."""
    if isinstance(key, str):
        parts = key.replace(",", "-").split("-")
        try:
            i, j = (int(p.strip()) for p in parts)
        except ValueError:
            raise ValueError(
                f"{source}: nominal_lengths key {key!r} must name a pair as \"i-j\" (e.g. \"18-19\")"
            ) from None
        return i, j
    pair = _int_tuple(key, "nominal_lengths key", source)
    if len(pair) != 2:
        raise ValueError(f"{source}: nominal_lengths key {key!r} must be a pair (i, j)")
    return pair


@dataclass(frozen=True)
class AnalysisSettings:
    """Marker roles and analysis options, in the user's marker numbering.

    Parameters
    ----------
    length_pairs : tuple of (int, int)
        Point pairs whose distance should not change (rigid lengths: mount markers,
        reference dots); :func:`wingphoto.analysis.length_statistics` reports them.
        Default none.
    nominal_lengths : dict {(i, j): float} or None
        Known lengths in mm of some of ``length_pairs`` (bias and maximum error are then
        reported). In TOML a table with ``"i-j"`` keys. Default None.
    reference_ids : tuple of int
        Static reference points (their stillness validates a test; stitching aligns tests
        on them). Default none.
    leading_edge : tuple of int
        Leading-edge markers, tip first. Needed for the stroke angle. Default none.
    trailing_edge : tuple of int
        Trailing-edge markers at the same spanwise stations as ``leading_edge`` (same
        length, tip first); with them the pitch, twist and surface are computed.
    chord_rows : tuple of tuple of int, or None
        Markers of each spanwise station from leading to trailing edge (tip station
        first), for camber; default the (leading, trailing) pairs.
    root : int or None
        A marker at the wing root (moving with the wing's base or fixed at the hinge).
    hinge : (float, float, float) or None
        Fixed wing-root (hinge) position in mm, left camera frame, when no root marker
        exists. ``root`` and ``hinge`` exclude each other; with neither, the root end
        of the leading edge is used.
    stroke_plane : (float, float, float) or None
        Normal of the stroke plane (left camera frame); default fitted.
    reference_tol_mm : float or None
        Largest displacement of a still reference, mm; default None: derived from the
        references' own noise (:func:`wingphoto.analysis.reference_stillness`).
    fps : float or None
        Frame rate (frames per second): the analysis tables gain ``time_s``; default
        None (frames only).
    point_sigma_px : float
        2D positional uncertainty (1 sigma, px, per axis) assumed where tracks carry no
        ``sigma`` (default 0.1 px), when points are triangulated with a calibration
        (``triangulate_tracks(..., point_sigma_px=...)``).
    phase_bins : int
        Samples per stroke of the phase grid (default 100).
    interpolation : {"linear", "cubic", "cardinal"}
        Time interpolation onto the phase grid (default "linear").
    cardinal_tension : float
        Tension of the cardinal spline, 0 = Catmull-Rom (default 0.0).
    surface_model : {"poly2", "poly3", "tps"}
        Wing surface fitted through the markers in the wing's span/chord coordinates
        (default "poly2").
    mesh_shape : (int, int)
        Samples of the surface mesh along the span and along the chord (default (21, 11)).

    Notes
    -----
    The object is frozen; change it with :func:`dataclasses.replace`. Construction
    validates everything and raises ValueError naming the setting.

    Examples
    --------
    >>> s = AnalysisSettings.from_dict({"length_pairs": [[18, 19]], "leading_edge": [0, 3, 6]})
    >>> s.length_pairs, s.leading_edge, s.interpolation
    (((18, 19),), (0, 3, 6), 'linear')
    """

    length_pairs: tuple = ()
    nominal_lengths: dict | None = None
    reference_ids: tuple = ()
    leading_edge: tuple = ()
    trailing_edge: tuple = ()
    chord_rows: tuple | None = None
    root: int | None = None
    hinge: tuple | None = None
    stroke_plane: tuple | None = None
    reference_tol_mm: float | None = None
    fps: float | None = None
    point_sigma_px: float = 0.1
    phase_bins: int = 100
    interpolation: str = "linear"
    cardinal_tension: float = 0.0
    surface_model: str = "poly2"
    mesh_shape: tuple = (21, 11)
    source: str = field(default="AnalysisSettings", compare=False, repr=False)

    def __post_init__(self):
        src = self.source
        put = lambda name, v: object.__setattr__(self, name, v)  # noqa: E731
        pairs = []
        for p in self.length_pairs or ():
            pair = _int_tuple(p, "length_pairs entry", src)
            if len(pair) != 2 or pair[0] == pair[1]:
                raise ValueError(f"{src}: length_pairs entries must be two different markers [i, j], got {p!r}")
            pairs.append(pair)
        put("length_pairs", tuple(pairs))
        if self.nominal_lengths is not None:
            nominal = {}
            for k, v in dict(self.nominal_lengths).items():
                pair = _pair_key(k, src)
                if pair not in self.length_pairs and pair[::-1] not in self.length_pairs:
                    raise ValueError(
                        f"{src}: nominal_lengths gives pair {pair[0]}-{pair[1]}, which is not in length_pairs; "
                        "add it to length_pairs"
                    )
                pair = pair if pair in self.length_pairs else pair[::-1]
                v = float(v)
                if not (math.isfinite(v) and v > 0):
                    raise ValueError(f"{src}: nominal_lengths[{pair[0]}-{pair[1]}] must be a positive length in mm")
                nominal[pair] = v
            put("nominal_lengths", nominal)
        for name in ("reference_ids", "leading_edge", "trailing_edge"):
            put(name, _int_tuple(getattr(self, name), name, src))
        if self.trailing_edge and len(self.trailing_edge) != len(self.leading_edge):
            raise ValueError(
                f"{src}: trailing_edge has {len(self.trailing_edge)} markers but leading_edge has "
                f"{len(self.leading_edge)}; give one trailing-edge marker per leading-edge station (tip first)"
            )
        if self.chord_rows is not None:
            rows = tuple(_int_tuple(r, "chord_rows entry", src) for r in self.chord_rows)
            if any(len(r) < 2 for r in rows):
                raise ValueError(f"{src}: every chord_rows entry needs at least 2 markers (leading to trailing edge)")
            put("chord_rows", rows)
        if self.root is not None:
            put("root", _int_tuple([self.root], "root", src)[0])
        for name in ("hinge", "stroke_plane"):
            v = getattr(self, name)
            if v is not None:
                try:
                    t = tuple(float(x) for x in v)
                except (TypeError, ValueError):
                    raise ValueError(f"{src}: {name} must be three numbers [x, y, z] (mm, left camera frame)") from None
                if len(t) != 3 or not all(math.isfinite(x) for x in t):
                    raise ValueError(f"{src}: {name} must be three finite numbers [x, y, z], got {v!r}")
                put(name, t)
        if self.root is not None and self.hinge is not None:
            raise ValueError(f"{src}: give either root (a marker) or hinge (a fixed point), not both")
        if self.stroke_plane is not None and math.hypot(*self.stroke_plane) < 1e-12:
            raise ValueError(f"{src}: stroke_plane must be a non-zero normal vector")
        for name, lo in (("reference_tol_mm", 0.0), ("point_sigma_px", 0.0)):
            if getattr(self, name) is None and name == "reference_tol_mm":
                continue
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > lo):
                raise ValueError(f"{src}: {name} must be a positive number, got {getattr(self, name)!r}")
            put(name, v)
        if self.fps is not None:
            v = float(self.fps)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{src}: fps must be a positive frame rate, got {self.fps!r}")
            put("fps", v)
        if isinstance(self.phase_bins, bool) or int(self.phase_bins) != self.phase_bins or int(self.phase_bins) < 4:
            raise ValueError(f"{src}: phase_bins must be a whole number >= 4, got {self.phase_bins!r}")
        put("phase_bins", int(self.phase_bins))
        if self.interpolation not in INTERPOLATIONS:
            raise ValueError(f"{src}: interpolation must be one of {list(INTERPOLATIONS)}, got {self.interpolation!r}")
        v = float(self.cardinal_tension)
        if not (-1.0 < v < 1.0):
            raise ValueError(f"{src}: cardinal_tension must lie in (-1, 1) (0 = Catmull-Rom), got {v}")
        put("cardinal_tension", v)
        if self.surface_model not in SURFACE_MODELS:
            raise ValueError(f"{src}: surface_model must be one of {list(SURFACE_MODELS)}, got {self.surface_model!r}")
        shape = _int_tuple(self.mesh_shape, "mesh_shape", src)
        if len(shape) != 2 or min(shape) < 2:
            raise ValueError(f"{src}: mesh_shape must be two sample counts >= 2 [span, chord], got {self.mesh_shape!r}")
        put("mesh_shape", shape)

    # ------------------------------------------------------------------ derived
    @property
    def stations(self):
        """Markers per spanwise station, leading to trailing edge, tip station first.

        ``chord_rows`` when given, else the (leading, trailing) pairs, else empty.
        """
        if self.chord_rows is not None:
            return self.chord_rows
        return tuple(zip(self.leading_edge, self.trailing_edge))

    # ------------------------------------------------------------------ (de)serialise
    @classmethod
    def from_dict(cls, mapping, *, source="analysis settings"):
        """Build the settings from a mapping (the ``[analysis]`` table of a TOML file).

        Parameters
        ----------
        mapping : mapping
            Keys are the field names above; missing keys take their defaults.
        source : str
            Where the mapping came from (a file name), quoted in error messages.

        Returns
        -------
        AnalysisSettings

        Raises
        ------
        ValueError
            An unknown key (with the known ones listed) or an invalid value.
        """
        if mapping is None:
            mapping = {}
        if not hasattr(mapping, "items"):
            raise ValueError(f"{source}: the analysis settings must be a table of key = value, got {type(mapping).__name__}")
        known = [f.name for f in dataclasses.fields(cls) if f.name != "source"]
        unknown = sorted(set(mapping) - set(known))
        if unknown:
            raise ValueError(f"{source}: unknown analysis setting(s) {unknown}; known settings: {known}")
        return cls(**dict(mapping), source=source)

    def to_dict(self):
        """The settings as plain TOML-able values (lists, numbers, strings); None left out.

        ``AnalysisSettings.from_dict(s.to_dict()) == s``.
        """
        out = {}
        for f in dataclasses.fields(self):
            if f.name == "source":
                continue
            v = getattr(self, f.name)
            if v is None:
                continue
            if f.name == "nominal_lengths":
                v = {f"{i}-{j}": float(x) for (i, j), x in v.items()}
            elif isinstance(v, tuple):
                v = [list(x) if isinstance(x, tuple) else x for x in v]
            out[f.name] = v
        return out

    def to_toml(self):
        """The ``[analysis]`` table as TOML text (readable back by :func:`load_analysis_settings`)."""
        lines = ["[analysis]"]
        for k, v in self.to_dict().items():
            lines.append(f"{k} = {_toml_value(v)}")
        return "\n".join(lines) + "\n"

    @classmethod
    def for_synth(cls, *, hinge=None, **changes):
        """Settings for the numbering of :func:`wingphoto.synth.render_flapping` and ``data-samples``.

        18 wing markers (6 stations tip to root, 3 markers leading to trailing edge), the
        2 mount markers 18-19 and the reference dots 20-25: lengths of the mount pair and
        of consecutive reference dots, the references, the edges and the chord rows.

        Parameters
        ----------
        hinge : (3,) array_like, optional
            The wing hinge in mm, left camera frame (``seq.params["hinge_left_mm"]``).
        **changes
            Any other setting.
        """
        rows = tuple(tuple(range(3 * k, 3 * k + 3)) for k in range(6))
        refs = tuple(range(20, 26))
        base = dict(
            length_pairs=((18, 19),) + tuple((refs[k], refs[k + 1]) for k in range(5)),
            reference_ids=refs,
            leading_edge=tuple(r[0] for r in rows),
            trailing_edge=tuple(r[-1] for r in rows),
            chord_rows=rows,
            hinge=None if hinge is None else tuple(float(x) for x in hinge),
        )
        base.update(changes)
        return cls(**base, source="AnalysisSettings.for_synth")


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf"))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_value(str(k))} = {_toml_value(x)}" for k, x in v.items()) + "}"
    return "[" + ", ".join(_toml_value(x) for x in v) + "]"


def load_analysis_settings(path):
    """Read the ``[analysis]`` table of a TOML file.

    Parameters
    ----------
    path : str or Path
        A TOML file with an ``[analysis]`` table (an analysis.toml, or a batch manifest).

    Returns
    -------
    AnalysisSettings

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        The file is not valid TOML, has no ``[analysis]`` table, or a setting is wrong
        (the message names the file and the setting).
    """
    import tomllib

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"analysis settings file {path} does not exist (or is not a file)")
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path} is not valid TOML: {exc}") from None
    if "analysis" not in data:
        raise ValueError(
            f"{path} has no [analysis] table; put the settings under a line [analysis] "
            f"(found tables/keys: {sorted(data)})"
        )
    return AnalysisSettings.from_dict(data["analysis"], source=str(path))
