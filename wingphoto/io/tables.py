"""Tracks and 3D points tables: CSV round trips with exact dtypes, empty tables, the sample folder."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .atomic import atomic_write



TRACK_COLUMNS = ["camera", "frame", "point", "x", "y", "score", "status"]
#: Columns of a 3D points DataFrame, in order (extra columns may follow).
POINT_COLUMNS = ["frame", "point", "X", "Y", "Z", "reproj_err"]
_TRACK_KINDS = {"camera": "str", "frame": "int", "point": "int", "x": "float", "y": "float", "score": "float", "status": "str"}
_POINT_KINDS = {"frame": "int", "point": "int", "X": "float", "Y": "float", "Z": "float", "reproj_err": "float"}
#: Optional tracks columns with a fixed kind when present: ``reason`` is text ("" when there
#: is none, never NaN, so corrections can be applied to tracks read back), the others are
#: floats (px; ``sigma`` the 1-sigma per-axis positional uncertainty, NaN where unknown).
_TRACK_OPTIONAL = {"x_pix": "float", "y_pix": "float", "reason": "text", "sigma": "float"}


def _string_dtype():
    """pandas' default dtype for text: ``str`` (pandas >= 3) or ``object`` (pandas 2)."""
    import pandas as pd

    return pd.Series(["a"]).dtype


def _as_strings(series):
    import pandas as pd

    target = _string_dtype()
    if target != object:
        return series.astype(target)
    values = [v if pd.isna(v) else str(v) for v in series.tolist()]
    return pd.Series(values, index=series.index, dtype=object, name=series.name)


def _empty_table(kinds):
    import pandas as pd

    dtypes = {"str": _string_dtype(), "int": np.int64, "float": np.float64}
    return pd.DataFrame({c: pd.Series([], dtype=dtypes[k]) for c, k in kinds.items()})


def empty_tracks():
    """Return an empty tracks DataFrame with the standard columns and dtypes.

    Returns
    -------
    tracks : pandas.DataFrame
        Columns :data:`TRACK_COLUMNS`: ``camera`` (str), ``frame``, ``point`` (int64),
        ``x``, ``y`` (float64, px), ``score`` (float64), ``status`` (str: ok / flagged /
        lost / manual / interpolated).

    Examples
    --------
    >>> t = empty_tracks()
    >>> list(t.columns) == TRACK_COLUMNS, len(t), str(t["frame"].dtype)
    (True, 0, 'int64')
    """
    return _empty_table(_TRACK_KINDS)


def empty_points():
    """Return an empty 3D points DataFrame with the standard columns and dtypes.

    Returns
    -------
    points : pandas.DataFrame
        Columns :data:`POINT_COLUMNS`: ``frame``, ``point`` (int64), ``X``, ``Y``, ``Z``
        (float64, mm, left camera frame), ``reproj_err`` (float64, px).
    """
    return _empty_table(_POINT_KINDS)


def _looks_like(columns, what):
    """A hint when a table's header shows what the file really is."""
    names = [str(c) for c in columns]
    if len(names) == 1:
        for sep, label in ((";", "semicolons"), ("\t", "tabs"), ("|", "bars")):
            if sep in names[0]:
                return f" (its fields are separated by {label}; wingphoto reads comma-separated files)"
    if what == "tracks" and {"X", "Y", "Z"} <= set(names):
        return " (it looks like a 3D points file, not tracks)"
    if what == "points" and {"x", "y", "status"} <= set(names):
        return " (it looks like a tracks file, not 3D points)"
    return ""


def _coerce_table(df, kinds, what, source, optional=None):
    """Check the standard columns and cast them to their dtypes (extra columns untouched).

    ``optional`` columns are cast when present: ``"text"`` is str with missing values as
    ``""``, the other kinds as in ``kinds``.
    """
    import pandas as pd

    if not isinstance(df, pd.DataFrame):
        raise ValueError(f"{what} must be a pandas DataFrame, got {type(df).__name__}")
    missing = [c for c in kinds if c not in df.columns]
    if missing:
        raise ValueError(f"{source} lacks the column(s) {missing}; a {what} table needs {list(kinds)}"
                         + _looks_like(df.columns, what))
    out = df.copy()
    present = {c: k for c, k in (optional or {}).items() if c in out.columns}
    for col, kind in {**kinds, **present}.items():
        s = out[col]
        if kind == "text":
            out[col] = _as_strings(s.where(s.notna(), ""))
            continue
        if kind == "str":
            out[col] = _as_strings(s)
            continue
        try:
            values = pd.to_numeric(s, errors="raise")
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{source}: column {col!r} must be numeric ({exc})") from exc
        values = np.asarray(values, dtype=np.float64)
        if kind == "int":
            if np.isnan(values).any():
                raise ValueError(
                    f"{source}: column {col!r} has missing values; frame and point numbers must "
                    f"be integers (drop those rows, or mark positions NaN instead)"
                )
            if np.any(values != np.round(values)):
                raise ValueError(f"{source}: column {col!r} must hold whole numbers")
            out[col] = values.astype(np.int64)
        else:
            out[col] = values
    return out


def _write_table(df, path):
    with atomic_write(path, "w", newline="", encoding="utf-8") as f:
        df.to_csv(f, index=False, lineterminator="\n", na_rep="")


def _read_table(path, kinds, what, optional=None):
    import pandas as pd

    path = Path(path)
    if not path.is_file():
        if path.is_dir():
            raise IsADirectoryError(f"{what} file {path} is a folder; give the CSV file inside it")
        raise FileNotFoundError(f"{what} file {path} not found; check the path")
    all_kinds = {**kinds, **(optional or {})}
    try:
        header = pd.read_csv(path, nrows=0, encoding="utf-8").columns
        na_values = {c: {"str": [""], "text": []}.get(all_kinds.get(c), ["", "NaN", "nan"]) for c in header}
        dtype = {c: object for c, k in all_kinds.items() if k in ("str", "text") and c in header}
        # pandas >= 3 parses floats exactly by default and deprecates float_precision
        exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
        df = pd.read_csv(path, dtype=dtype, na_values=na_values, keep_default_na=False, encoding="utf-8", **exact)
    except Exception as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"cannot read {path} as a {what} CSV table ({msg}); check the file") from exc
    return _coerce_table(df, kinds, what, f"{what} file {path}", optional)


def write_tracks_csv(tracks, path):
    """Write a tracks DataFrame to CSV, atomically.

    Parameters
    ----------
    tracks : pandas.DataFrame
        Columns :data:`TRACK_COLUMNS` (extra columns are kept); ``frame`` and ``point``
        must be whole numbers without gaps (NaN).
    path : str or Path
        Destination ``.csv``; the old file survives a failure.

    Notes
    -----
    Floats are written with full round-trip precision; NaN as an empty field.
    :func:`read_tracks_csv` restores the table exactly, dtypes included.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np, pandas as pd
    >>> t = pd.DataFrame({"camera": ["left"], "frame": [0], "point": [3], "x": [10.25],
    ...                   "y": [np.nan], "score": [0.9], "status": ["lost"]})
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "tracks.csv"
    >>> write_tracks_csv(t, p)
    >>> back = read_tracks_csv(p)
    >>> back.equals(t.astype(back.dtypes.to_dict()))
    True
    """
    _write_table(_coerce_table(tracks, _TRACK_KINDS, "tracks", "tracks", _TRACK_OPTIONAL), path)


def read_tracks_csv(path):
    """Read a tracks CSV written by :func:`write_tracks_csv`.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    tracks : pandas.DataFrame
        ``camera`` and ``status`` as str, ``frame`` and ``point`` as int64, ``x``,
        ``y``, ``score`` as float64 (empty fields are NaN); an empty file keeps its
        columns and dtypes. Optional columns when present: ``reason`` as str (an empty
        field is ``""``, so :func:`wingphoto.corrections.apply_corrections` works on the
        table), ``x_pix``, ``y_pix``, ``sigma`` (px) as float64.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Not a CSV, a required column is missing, or frame/point are not whole numbers.
    """
    return _read_table(path, _TRACK_KINDS, "tracks", _TRACK_OPTIONAL)


def write_points_csv(points, path):
    """Write a 3D points DataFrame (frame, point, X, Y, Z, reproj_err) to CSV, atomically.

    Parameters
    ----------
    points : pandas.DataFrame
        Columns :data:`POINT_COLUMNS` (extra columns are kept); X, Y, Z in mm in the
        left camera frame, reproj_err in px.
    path : str or Path
        Destination ``.csv``; the old file survives a failure.
    """
    _write_table(_coerce_table(points, _POINT_KINDS, "points", "points"), path)


def read_points_csv(path):
    """Read a 3D points CSV written by :func:`write_points_csv`.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    points : pandas.DataFrame
        ``frame``, ``point`` as int64; ``X``, ``Y``, ``Z``, ``reproj_err`` as float64
        (empty fields are NaN).

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Not a CSV, a required column is missing, or frame/point are not whole numbers.
    """
    return _read_table(path, _POINT_KINDS, "points")


def find_samples(start=None, name="data-samples"):
    """Find the ``data-samples/`` folder from ``start`` or any of its parents.

    Notebooks run with their own folder as the working directory (nbmake, Jupyter) and
    scripts from the repository root; this finds the sample data from either.

    Parameters
    ----------
    start : str or Path, optional
        Where to start looking (default: the current working directory).
    name : str
        Folder name to look for.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    FileNotFoundError
        When no parent holds the folder.
    """
    start = Path.cwd() if start is None else Path(start)
    for folder in (start, *start.resolve().parents):
        if (folder / name).is_dir():
            return folder / name
    raise FileNotFoundError(
        f"no {name}/ folder in {start} or its parents; run from inside the wingphoto repository "
        "or regenerate the sample with `python data-samples/make_samples.py`"
    )
