"""Picks files: where each marker was clicked, per camera, read and written in one place.

A *pick* is the position of one marker in one view, clicked by a person in one frame,
plus the half-size of the subimage (template) rectangle the tracker searches with. The
picker widget, ``wingphoto pick``, the CLI's ``track --picks``, the pipeline and the tracker
all read and write picks through this module. The formats are documented in
``docs/picks.md``:

JSON (``.json``, what the picker saves)::

    {"format": "wingphoto-picks", "version": 2,
     "cameras": ["left", "right"], "image_size": [512, 512], "image_size_right": null,
     "n_points": 26, "half_size": [10.0, 10.0], "camera": "left", "current": 0,
     "picks": {"left": [{"point": 0, "frame": 0, "x": 302.0, "y": 168.0,
                          "half_w": 8.0, "half_h": 8.0}, ...],
               "right": [...]}}

Version 1 files (no per-pick ``frame``; the frame is then 0) still load.

CSV (``.csv``), one row per pick, header required::

    camera,point,frame,x,y,half_w,half_h
    left,0,0,302.0,168.0,8,8
    right,0,0,288.5,170.25,8,8

``frame`` may be omitted (then 0) and so may ``half_w, half_h`` (then
:data:`DEFAULT_HALF_SIZE` px).

Conventions (``docs/conventions.md``): pixel (x, y), x right, y down, (0, 0) the centre of
the top-left pixel; markers numbered from 0, leading edge to trailing edge and tip to root,
with the same number in both views.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from .io import atomic_write

__all__ = [
    "PICKS_FORMAT",
    "PICKS_COLUMNS",
    "DEFAULT_HALF_SIZE",
    "SAME_SPOT_PX",
    "check_picks",
    "load_picks",
    "read_picks",
    "read_picks_document",
    "picks_document",
    "write_picks",
]

PICKS_FORMAT = "wingphoto-picks"
PICKS_VERSION = 2
READ_VERSIONS = (1, 2)
CAMERAS = ("left", "right")
#: columns of :func:`load_picks` (one camera)
PICKS_COLUMNS = ("point", "frame", "x", "y", "half_w", "half_h")
#: columns of :func:`read_picks` (every camera): camera, then :data:`PICKS_COLUMNS`
TABLE_COLUMNS = ("camera",) + PICKS_COLUMNS
#: subimage half size (px) given to picks that do not say
DEFAULT_HALF_SIZE = 10.0
#: two picks of one view closer than this (px) are the same spot, which is refused
SAME_SPOT_PX = 1.0

_HELP = "see docs/picks.md (or `wingphoto pick --help`) for the JSON and CSV picks formats"


def _empty_table():
    return pd.DataFrame({
        "camera": pd.Series(dtype=object),
        "point": pd.Series(dtype=np.int64),
        "frame": pd.Series(dtype=np.int64),
        "x": pd.Series(dtype=np.float64),
        "y": pd.Series(dtype=np.float64),
        "half_w": pd.Series(dtype=np.float64),
        "half_h": pd.Series(dtype=np.float64),
    })


def _as_int(value, what, source):
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{source}: {what} must be a non-negative integer, got {value!r}")
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{source}: {what} must be a non-negative integer, got {value!r}") from None
    if not math.isfinite(f) or not f.is_integer() or f < 0:
        raise ValueError(f"{source}: {what} must be a non-negative integer, got {value!r}")
    return int(f)


def _as_float(value, what, source):
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{source}: {what} must be a number, got {value!r}") from None


def check_picks(table, *, source="picks"):
    """Validate a picks table and return it normalised (types, sorted by camera and point).

    Parameters
    ----------
    table : pandas.DataFrame
        Columns camera (optional), point, x, y and optionally frame (default 0),
        half_w, half_h (default :data:`DEFAULT_HALF_SIZE`).
    source : str
        What the table came from (a file name), for the error messages.

    Returns
    -------
    pandas.DataFrame
        Columns camera (when given), point (int64), frame (int64), x, y, half_w, half_h
        (float64).

    Raises
    ------
    ValueError
        Missing columns; a point or frame that is not a non-negative integer; a NaN or
        infinite coordinate (naming the camera and point); a non-positive half size; a
        point number given twice in one view; two points of one view on the same spot
        (closer than :data:`SAME_SPOT_PX`).
    """
    if not isinstance(table, pd.DataFrame):
        raise ValueError(f"{source}: picks must be a DataFrame with columns point, x, y, got {type(table).__name__}")
    missing = [c for c in ("point", "x", "y") if c not in table.columns]
    if missing:
        raise ValueError(f"{source} lacks columns {missing}; expected camera,point,frame,x,y[,half_w,half_h]; {_HELP}")
    has_camera = "camera" in table.columns
    rows = []
    for i, r in enumerate(table.to_dict("records")):
        cam = str(r["camera"]).strip() if has_camera else None
        where = f"{source} row {i + 1}"
        if has_camera and cam not in CAMERAS:
            raise ValueError(f"{where}: camera must be 'left' or 'right', got {r['camera']!r}")
        point = _as_int(r["point"], "point", where)
        frame = _as_int(r.get("frame", 0) if not _is_missing(r.get("frame", 0)) else 0, "frame", where)
        x = _as_float(r["x"], "x", where)
        y = _as_float(r["y"], "y", where)
        label = f"{cam + ' ' if cam else ''}point {point}"
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(
                f"{source}: {label} has no valid position (x={r['x']!r}, y={r['y']!r}); pick it "
                "or delete its row (a marker not picked in a view is simply left out)"
            )
        hw = r.get("half_w", DEFAULT_HALF_SIZE)
        hh = r.get("half_h", DEFAULT_HALF_SIZE)
        hw = DEFAULT_HALF_SIZE if _is_missing(hw) else _as_float(hw, "half_w", where)
        hh = DEFAULT_HALF_SIZE if _is_missing(hh) else _as_float(hh, "half_h", where)
        if not (math.isfinite(hw) and math.isfinite(hh) and hw > 0 and hh > 0):
            raise ValueError(f"{source}: {label} has half_w={hw!r}, half_h={hh!r}; subimage half sizes must be "
                             "positive pixels")
        rows.append((cam, point, frame, x, y, hw, hh))
    out = _empty_table()
    if rows:
        out = pd.DataFrame(rows, columns=list(TABLE_COLUMNS)).astype(
            {"point": np.int64, "frame": np.int64, "x": np.float64, "y": np.float64,
             "half_w": np.float64, "half_h": np.float64})
    for cam, group in out.groupby(out["camera"].fillna(""), sort=False):
        _check_view(group, cam or None, source)
    if has_camera:
        out = out.sort_values(["camera", "point"], key=_camera_key, kind="stable").reset_index(drop=True)
    else:
        out = out.drop(columns="camera").sort_values("point", kind="stable").reset_index(drop=True)
    return out


def _camera_key(col):
    if col.name == "camera":
        return col.map({c: i for i, c in enumerate(CAMERAS)})
    return col


def _is_missing(value):
    if value is None:
        return True
    if isinstance(value, str):
        return value.strip() == ""
    try:
        return math.isnan(float(value))
    except (TypeError, ValueError):
        return False


def _check_view(group, camera, source):
    view = f"the {camera} view" if camera else "one view"
    points = group["point"].to_numpy(np.int64)
    values, counts = np.unique(points, return_counts=True)
    if (counts > 1).any():
        raise ValueError(f"{source}: {view} gives point(s) {values[counts > 1].tolist()} more than once; "
                         "each marker number appears once per view")
    xy = group[["x", "y"]].to_numpy(np.float64)
    if len(xy) > 1:
        d = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
        d[np.tril_indices(len(xy))] = np.inf
        i, j = np.unravel_index(np.argmin(d), d.shape)
        if d[i, j] < SAME_SPOT_PX:
            raise ValueError(
                f"{source}: points {points[i]} and {points[j]} of {view} are on the same spot "
                f"({xy[i, 0]:.2f}, {xy[i, 1]:.2f}) and ({xy[j, 0]:.2f}, {xy[j, 1]:.2f}), less than "
                f"{SAME_SPOT_PX:g} px apart; each marker is picked once, on its own centre"
            )


# --------------------------------------------------------------------------- JSON
def picks_document(table, **meta):
    """Build the JSON document of a picks table (the saved picks file).

    Parameters
    ----------
    table : pandas.DataFrame
        Columns camera, point, frame, x, y, half_w, half_h (:func:`check_picks`).
    **meta
        Picker state saved alongside: ``cameras`` (default the cameras in ``table``, or
        both), ``image_size``, ``image_size_right``, ``n_points``, ``half_size``,
        ``camera``, ``current``.

    Returns
    -------
    dict
        JSON-ready; ``json.dumps`` it, or use :func:`write_picks`.
    """
    table = check_picks(table, source="picks")
    if "camera" not in table.columns:
        raise ValueError("picks_document needs a camera column (left/right) in the picks table")
    cameras = list(meta.pop("cameras", None) or [c for c in CAMERAS if c in set(table["camera"])] or CAMERAS)
    unknown = sorted(set(table["camera"]) - set(cameras))
    if unknown:
        raise ValueError(f"picks of cameras {unknown} given but cameras is {cameras}")
    half = meta.pop("half_size", None)
    doc = {
        "format": PICKS_FORMAT,
        "version": PICKS_VERSION,
        "cameras": cameras,
        "image_size": _size_or_none(meta.pop("image_size", None)),
        "image_size_right": _size_or_none(meta.pop("image_size_right", None)),
        "n_points": meta.pop("n_points", None),
        "half_size": [float(v) for v in (half if half is not None else (DEFAULT_HALF_SIZE, DEFAULT_HALF_SIZE))],
        "camera": meta.pop("camera", cameras[0]),
        "current": int(meta.pop("current", 0)),
    }
    if meta:
        raise ValueError(f"unknown picks metadata {sorted(meta)}")
    doc["picks"] = {
        cam: [
            {"point": int(r.point), "frame": int(r.frame), "x": float(r.x), "y": float(r.y),
             "half_w": float(r.half_w), "half_h": float(r.half_h)}
            for r in table[table["camera"] == cam].itertuples(index=False)
        ]
        for cam in cameras
    }
    return doc


def _size_or_none(size):
    return None if size is None else [int(v) for v in size]


def read_picks_document(data, *, source="picks"):
    """Parse a picks JSON document (a dict) into a table and the picker metadata.

    Parameters
    ----------
    data : dict
        The parsed JSON of a ``wingphoto-picks`` file, version 1 or 2.
    source : str
        What it came from, for error messages.

    Returns
    -------
    table : pandas.DataFrame
        camera, point, frame, x, y, half_w, half_h (:func:`check_picks`).
    meta : dict
        cameras (tuple), image_size, image_size_right, n_points, half_size, camera, current.

    Raises
    ------
    ValueError
        Not a wingphoto picks document, an unknown version, or malformed content.
    """
    if not isinstance(data, dict) or data.get("format") != PICKS_FORMAT:
        raise ValueError(
            f"{source} is not a wingphoto picks file (expected a JSON object with \"format\": {PICKS_FORMAT!r}, "
            f"or a CSV with columns camera,point,frame,x,y[,half_w,half_h]); {_HELP}"
        )
    if data.get("version") not in READ_VERSIONS:
        raise ValueError(f"{source} has picks format version {data.get('version')!r}; "
                         f"this wingphoto reads versions {list(READ_VERSIONS)}")
    picks = data.get("picks")
    if not isinstance(picks, dict):
        raise ValueError(f"{source} is a malformed picks file: 'picks' must be an object "
                         "{\"left\": [...], \"right\": [...]}")
    cameras = data.get("cameras", list(CAMERAS))
    if not isinstance(cameras, (list, tuple)) or not cameras or any(c not in CAMERAS for c in cameras):
        raise ValueError(f"{source}: cameras must be a list among {list(CAMERAS)}, got {cameras!r}")
    rows = []
    for cam, items in picks.items():
        if cam not in CAMERAS:
            raise ValueError(f"{source}: picks for unknown camera {cam!r}; cameras are 'left' and 'right'")
        if not isinstance(items, list):
            raise ValueError(f"{source}: picks[{cam!r}] must be a list of picks")
        for k, p in enumerate(items):
            if not isinstance(p, dict):
                raise ValueError(f"{source}: pick {k} of the {cam} view must be an object "
                                 "{point, frame, x, y, half_w, half_h}")
            missing = [c for c in ("point", "x", "y") if c not in p]
            if missing:
                raise ValueError(f"{source}: pick {k} of the {cam} view lacks {missing}")
            extra = sorted(set(p) - set(PICKS_COLUMNS))
            if extra:
                raise ValueError(f"{source}: pick {k} of the {cam} view has unknown keys {extra}")
            rows.append({"camera": cam, **{c: p.get(c) for c in PICKS_COLUMNS}})
    table = check_picks(pd.DataFrame(rows, columns=list(TABLE_COLUMNS)) if rows else _empty_table(), source=source)
    meta = {
        "cameras": tuple(cameras),
        "image_size": data.get("image_size"),
        "image_size_right": data.get("image_size_right"),
        "n_points": data.get("n_points"),
        "half_size": tuple(data.get("half_size") or (DEFAULT_HALF_SIZE, DEFAULT_HALF_SIZE)),
        "camera": data.get("camera", cameras[0]),
        "current": data.get("current", 0),
    }
    return table, meta


# --------------------------------------------------------------------------- files
def _read_file(path):
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"picks path {path} is a folder; give the picks file (.json or .csv) in it")
    if not path.is_file():
        raise FileNotFoundError(
            f"picks file {path} not found; make one with `wingphoto pick FRAMES_LEFT FRAMES_RIGHT --out {path}`, "
            f"the picker widget (notebook 04), or by hand as a CSV; {_HELP}"
        )
    suffix = path.suffix.lower()
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"picks file {path} is not text (binary content); {_HELP}") from None
    if suffix == ".csv" or (suffix not in (".json",) and not text.lstrip().startswith("{")):
        return _read_csv_text(text, path), {}
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"picks file {path} is not valid JSON ({exc}); {_HELP}") from None
    return read_picks_document(data, source=f"picks file {path}")


def _read_csv_text(text, path):
    import io

    source = f"picks file {path}"
    if not text.strip():
        raise ValueError(f"{source} is empty; {_HELP}")
    try:
        raw = pd.read_csv(io.StringIO(text), dtype=str, skipinitialspace=True, keep_default_na=False)
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise ValueError(f"{source} is not a valid CSV ({exc}); {_HELP}") from None
    raw.columns = [str(c).strip().lower() for c in raw.columns]
    required = ["camera", "point", "x", "y"]
    missing = [c for c in required if c not in raw.columns]
    if missing:
        raise ValueError(
            f"{source} lacks columns {missing} (it has {list(raw.columns)}); the CSV header is "
            f"camera,point,frame,x,y[,half_w,half_h]; {_HELP}"
        )
    extra = [c for c in raw.columns if c not in TABLE_COLUMNS]
    if extra:
        raise ValueError(f"{source} has unknown columns {extra}; the CSV header is "
                         f"camera,point,frame,x,y[,half_w,half_h]")
    if ("half_w" in raw.columns) != ("half_h" in raw.columns):
        raise ValueError(f"{source}: give both half_w and half_h, or neither (then {DEFAULT_HALF_SIZE:g} px)")
    raw = raw.replace({"": np.nan})
    return check_picks(raw, source=source)


def read_picks(path):
    """Read a picks file (JSON or CSV) as one table for every camera.

    Parameters
    ----------
    path : str or Path
        ``.json`` (``wingphoto-picks``, what the picker saves) or ``.csv`` with columns
        ``camera,point,frame,x,y[,half_w,half_h]``; see ``docs/picks.md``.

    Returns
    -------
    pandas.DataFrame
        camera, point, frame, x, y, half_w, half_h; sorted by camera (left first) and point.

    Raises
    ------
    FileNotFoundError
        When ``path`` does not exist (the message says how to make a picks file).
    ValueError
        When the file is not a picks file or a pick is invalid (NaN position, a number
        given twice, two numbers on the same spot): the file and the point are named.
    """
    table, _ = _read_file(path)
    return table


def load_picks(path, camera):
    """Read the picks of one camera from a picks file, as the table the tracker takes.

    Parameters
    ----------
    path : str or Path
        Picks file, JSON or CSV (:func:`read_picks`, ``docs/picks.md``).
    camera : {"left", "right"}

    Returns
    -------
    pandas.DataFrame
        Columns point (int64, from 0), frame (int64, the frame the marker was picked in),
        x, y (px, float64), half_w, half_h (subimage half sizes, px) and half_size (the
        larger of the two, for trackers that use a square template); one row per
        picked marker, sorted by point.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        ``camera`` is not left/right; the file has no picks for ``camera`` (naming the
        cameras it has); or the file is invalid (:func:`read_picks`).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "p.csv").write_text("camera,point,frame,x,y\\nleft,0,0,10.5,20\\nleft,1,0,30,40\\n")
    >>> load_picks(d / "p.csv", "left")[["point", "frame", "x", "y", "half_w"]].to_numpy().tolist()
    [[0.0, 0.0, 10.5, 20.0, 10.0], [1.0, 0.0, 30.0, 40.0, 10.0]]
    """
    if camera not in CAMERAS:
        raise ValueError(f"camera must be 'left' or 'right', got {camera!r}")
    table, meta = _read_file(path)
    mine = table[table["camera"] == camera]
    if mine.empty:
        has = [c for c in CAMERAS if (table["camera"] == c).any()]
        if has:
            detail = f"it has picks for {' and '.join(has)} only"
        else:
            detail = "it holds no picks at all"
        raise ValueError(
            f"picks file {path} has no picks for the {camera} camera ({detail}); pick the markers in the "
            f"{camera} view too (`wingphoto pick`, or the picker widget) and save again"
        )
    out = mine.drop(columns="camera").reset_index(drop=True)
    out["half_size"] = np.fmax(out["half_w"].to_numpy(), out["half_h"].to_numpy())
    return out


def write_picks(table, path, **meta):
    """Write a picks table atomically as JSON (``.json``) or CSV (``.csv``).

    Parameters
    ----------
    table : pandas.DataFrame
        camera, point, x, y and optionally frame, half_w, half_h.
    path : str or Path
    **meta
        JSON only: picker metadata (see :func:`picks_document`).

    Returns
    -------
    Path
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".json", ".csv"):
        raise ValueError(f"picks file {path} must end in .json or .csv")
    if suffix == ".json":
        text = json.dumps(picks_document(table, **meta), indent=1) + "\n"
    else:
        if meta:
            raise ValueError(f"picks metadata {sorted(meta)} can only be saved in JSON; use a .json path")
        table = check_picks(table, source="picks")
        if "camera" not in table.columns:
            raise ValueError("a picks CSV needs a camera column (left/right)")
        text = table[list(TABLE_COLUMNS)].to_csv(index=False, float_format="%.17g", lineterminator="\n")
    with atomic_write(path, "w", encoding="utf-8") as f:
        f.write(text)
    return path
