"""Manual corrections: one log format (CSV or JSON), shared by the review widget.

A corrections log is a list of (point, frame, x, y) - optionally with the ``camera`` -
in the order the corrections were made: replaying it (:func:`apply_corrections`) gives
the corrected tracks, a later correction of the same point-frame winning. NaN x, y
declares the point lost on that frame. :func:`save_corrections` writes it as CSV
(``camera,point,frame,x,y``) or JSON (``{"format": "wingphoto-corrections", "version": 1,
"corrections": [...]}``); :func:`load_corrections` reads both. The review widget
(:mod:`wingphoto.widgets.state`) logs, saves, loads and replays with these functions.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["CORRECTION_COLUMNS", "apply_corrections", "load_corrections", "save_corrections"]

CORRECTION_COLUMNS = ["point", "frame", "x", "y"]


def _whole(values, name, source):
    """int64 array of whole numbers >= 0 or ValueError naming the first bad row."""
    import pandas as pd

    v = pd.to_numeric(pd.Series(values), errors="coerce").to_numpy(np.float64)
    bad = ~np.isfinite(v) | (v != np.round(v)) | (v < 0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raw = pd.Series(values).iloc[k]
        raw = raw.item() if isinstance(raw, np.generic) else raw
        raise ValueError(f"{source}: correction {k} has {name} {raw!r}; a correction's {name} must be a whole "
                         "number >= 0 (fix or delete that row)")
    return v.astype(np.int64)


def _as_corrections(corrections, source="corrections"):
    import pandas as pd

    if isinstance(corrections, pd.DataFrame):
        c = corrections.copy()
    else:
        rows = list(corrections)
        if rows and hasattr(rows[0], "_asdict"):  # wingphoto.widgets.state.Correction
            rows = [r._asdict() for r in rows]
        elif rows and not isinstance(rows[0], dict):
            # (point, frame, x, y) or, as the review widget logs them, (camera, point, frame, x, y)
            rows = [dict(zip(CORRECTION_COLUMNS if len(r) == 4 else ["camera"] + CORRECTION_COLUMNS, r))
                    for r in rows]
        c = pd.DataFrame(rows, columns=None if rows else CORRECTION_COLUMNS)
    missing = [k for k in CORRECTION_COLUMNS if k not in c.columns]
    if missing:
        raise ValueError(f"{source} lack columns {missing}; each correction is (point, frame, x, y)")
    c["point"] = _whole(c["point"], "point", source)
    c["frame"] = _whole(c["frame"], "frame", source)
    for k in ("x", "y"):
        v = pd.to_numeric(c[k], errors="coerce")
        bad = v.isna() & c[k].notna() & ~c[k].astype(str).str.lower().isin(["nan", "none", ""])
        if bad.any():
            i = int(np.flatnonzero(bad.to_numpy())[0])
            raise ValueError(f"{source}: correction {i} has {k} {c[k].iloc[i]!r}, not a number (px; NaN x and y "
                             "declare the point lost)")
        c[k] = v.astype(np.float64)
    half = np.isfinite(c["x"].to_numpy()) != np.isfinite(c["y"].to_numpy())
    if half.any():
        i = int(np.flatnonzero(half)[0])
        raise ValueError(f"{source}: correction {i} has only one of x, y; give both (or both NaN to declare the "
                         "point lost)")
    if "camera" in c.columns:
        c["camera"] = c["camera"].astype(str)
    return c.reset_index(drop=True)


def save_corrections(corrections, path):
    """Save a corrections log (point, frame, x, y[, camera, ...]) as CSV or JSON, atomically.

    Parameters
    ----------
    corrections : DataFrame or list of dicts / (point, frame, x, y) tuples
        The log, in the order the corrections were made (replaying it in order gives the
        same tracks; a later correction of the same point-frame wins). The review
        widget's ``Correction(camera, point, frame, x, y)`` entries are accepted too.
    path : str or Path
        ``.csv`` or ``.json`` (``{"format": "wingphoto-corrections", "version": 1,
        "corrections": [records]}``, the widget's format). Written via
        :func:`wingphoto.io.atomic_write`, so an interrupted save leaves the previous
        file intact.

    Returns
    -------
    pathlib.Path
    """
    from .io import atomic_write

    path = Path(path)
    c = _as_corrections(corrections)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".json"):
        raise ValueError(f"corrections path must end in .csv or .json, got {path.name!r}")
    if suffix == ".csv":
        text = c.to_csv(index=False, float_format="%.17g")
    else:
        recs = c.to_dict(orient="records")
        for r in recs:
            for k, v in r.items():
                if isinstance(v, float) and not np.isfinite(v):
                    r[k] = None
                elif isinstance(v, np.generic):
                    r[k] = v.item()
        text = json.dumps({"format": "wingphoto-corrections", "version": 1, "corrections": recs}, indent=1)
    with atomic_write(path, "w") as f:
        f.write(text)
    return path


def load_corrections(path):
    """Load a corrections log written by :func:`save_corrections` (CSV or JSON).

    Returns
    -------
    pandas.DataFrame
        Columns point (int64), frame (int64), x, y (float64, NaN marks a point the user
        declared lost), plus any extra columns saved (the review widget's ``camera``).

    Raises
    ------
    FileNotFoundError
        When ``path`` does not exist.
    ValueError
        When the suffix is not .csv/.json, the JSON is not a wingphoto corrections file,
        or columns are missing.
    """
    import pandas as pd

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".json"):
        raise ValueError(f"corrections path must end in .csv or .json, got {path.name!r}")
    if not path.is_file():
        raise FileNotFoundError(f"corrections file {path} not found: it does not exist (check the path)")
    if path.stat().st_size == 0:
        raise ValueError(f"corrections file {path} is empty (0 bytes); save the corrections again or pass "
                         "another file")
    if suffix == ".csv":
        try:
            c = pd.read_csv(path, dtype={"camera": str}, encoding="utf-8")
        except (UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError, ValueError) as exc:
            raise ValueError(f"corrections file {path} is not a readable CSV corrections log "
                             f"(point,frame,x,y[,camera]): {type(exc).__name__}: {exc}") from None
    else:
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"corrections file {path} is not valid JSON: {exc}") from None
        if not (isinstance(data, dict) and data.get("format") == "wingphoto-corrections"
                and isinstance(data.get("corrections"), list)):
            raise ValueError(f"corrections file {path} is not a wingphoto corrections file "
                             "(a JSON object with format 'wingphoto-corrections' and a corrections list)")
        recs = data["corrections"]
        if not all(isinstance(r, dict) for r in recs):
            raise ValueError(f"corrections file {path} is malformed: each correction must be an object")
        c = pd.DataFrame(recs, columns=None if recs else CORRECTION_COLUMNS)
    missing = [k for k in CORRECTION_COLUMNS if k not in c.columns]
    if missing:
        raise ValueError(f"corrections file {path} lacks columns {missing}; each correction is (point, frame, x, y)")
    return _as_corrections(c, f"corrections file {path}")


def apply_corrections(tracks, corrections):
    """Replay a corrections log onto tracks (the one implementation: the review widget's
    :class:`~wingphoto.widgets.state.ReviewState` applies its log with it too).

    Parameters
    ----------
    tracks : pandas.DataFrame
        Tracks (columns frame, point, x, y, status; ``camera``, ``score``, ``reason``,
        ``x_pix``, ``y_pix`` optional); not modified.
    corrections : DataFrame or list
        Log of (point, frame, x, y) - DataFrame rows, dicts, tuples, or the review
        widget's ``Correction(camera, point, frame, x, y)`` - applied in order, so a later
        correction of the same point and frame wins. A correction with NaN x, y declares
        the point lost on that frame. With a ``camera`` column a correction applies to the
        rows of that camera only; without one, to that point and frame in every camera.

    Returns
    -------
    pandas.DataFrame
        A copy whose corrected rows have x, y replaced and status ``manual`` (``lost`` for
        NaN), score NaN (a hand-placed position has no correlation score), reason ``""``
        (``"manual"`` when declared lost), and ``x_pix, y_pix`` the rounded position -
        each column only where ``tracks`` has it. A correction for a point and frame
        without a row adds the row (a point the tracker was not given, a frame beyond the
        tracked ones); the result is then sorted by camera, frame and point. Column
        dtypes are kept.

    Raises
    ------
    ValueError
        Missing columns in ``tracks`` or in the corrections, or a correction without a
        camera for a row to add to tracks of several cameras.

    Examples
    --------
    >>> import pandas as pd
    >>> t = pd.DataFrame({"frame": [0, 1], "point": 0, "x": [5.0, 6.0], "y": 5.0,
    ...                   "score": 0.9, "status": ["ok", "flagged"]})
    >>> row = apply_corrections(t, [(0, 1, 6.5, 5.25)]).iloc[1]
    >>> float(row.x), float(row.y), row.status, bool(np.isnan(row.score))
    (6.5, 5.25, 'manual', True)
    """
    import pandas as pd

    missing = [k for k in ("frame", "point", "x", "y", "status") if k not in tracks.columns]
    if missing:
        raise ValueError(f"tracks lacks columns {missing}; expected a tracks DataFrame (frame, point, x, y, status)")
    c = _as_corrections(corrections)
    out = tracks.copy()
    if len(c) == 0:
        return out
    for col in ("reason", "status"):
        # (read back from a CSV, an all-empty text column is float NaN)
        if col in out.columns and not (pd.api.types.is_object_dtype(out[col]) or pd.api.types.is_string_dtype(out[col])):
            out[col] = out[col].astype(object).where(out[col].notna(), "")
    by_cam = "camera" in out.columns and "camera" in c.columns
    key = ["camera", "frame", "point"] if by_cam else ["frame", "point"]
    c = c.drop_duplicates(subset=key, keep="last").reset_index(drop=True)
    rows = out[key].astype({"frame": np.int64, "point": np.int64}).reset_index().merge(c[key].reset_index(),
                                                                                       on=key, suffixes=("", "_c"))
    lost = ~(np.isfinite(c["x"].to_numpy()) & np.isfinite(c["y"].to_numpy()))

    def fill(frame, at, ci):
        x = np.where(lost[ci], np.nan, c["x"].to_numpy()[ci])
        y = np.where(lost[ci], np.nan, c["y"].to_numpy()[ci])
        frame.loc[at, "x"] = x
        frame.loc[at, "y"] = y
        frame.loc[at, "status"] = np.where(lost[ci], "lost", "manual")
        if "score" in frame.columns:
            frame.loc[at, "score"] = np.nan
        if "reason" in frame.columns:
            frame.loc[at, "reason"] = np.where(lost[ci], "manual", "")
        for pix, v in (("x_pix", x), ("y_pix", y)):
            if pix in frame.columns:
                frame.loc[at, pix] = np.rint(v)

    fill(out, rows["index"].to_numpy(), rows["index_c"].to_numpy())
    absent = np.setdiff1d(np.arange(len(c)), rows["index_c"].to_numpy())
    if absent.size:
        extra = pd.DataFrame({k: c[k].to_numpy()[absent] for k in key})
        if "camera" in out.columns and "camera" not in extra.columns:
            cams = out["camera"].astype(str).unique()
            if len(cams) != 1:
                p0, f0 = int(c["point"].iloc[absent[0]]), int(c["frame"].iloc[absent[0]])
                raise ValueError(
                    f"correction of point {p0} on frame {f0} has no row in tracks of cameras {sorted(cams)}: "
                    "give its camera (a camera column in the corrections) to add the row"
                )
            extra.insert(0, "camera", cams[0])
        for col in out.columns:
            if col not in extra.columns:
                numeric = pd.api.types.is_numeric_dtype(out[col].dtype)
                extra[col] = np.full(absent.size, np.nan) if numeric else np.full(absent.size, "", dtype=object)
        extra = extra[list(out.columns)]
        fill(extra, np.arange(absent.size), absent)
        dtypes = out.dtypes.to_dict()
        extra = extra.astype({k: v for k, v in dtypes.items() if not (pd.api.types.is_integer_dtype(v)
                                                                      and extra[k].isna().any())})
        out = pd.concat([out, extra], ignore_index=True)
        order = [k for k in ("camera", "frame", "point") if k in out.columns]
        out = out.sort_values(order, kind="stable").reset_index(drop=True)
    return out

