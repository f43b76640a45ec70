"""retrack_from: re-track some points forward from a corrected frame, and check the rows it
replaced against the others (the audit, conflicts)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd

from .audit import audit_against_picks
from .checkpoint import _run_pass
from .driver import GROUP_CONFLICT_PX, _resolve_options
from .inputs import _Frames
from .results import _Results, _tracks_frame
from .status import FLAGGED, LOST, OK
from .tracker import Tracker as _Tracker

__all__ = ["retrack_from"]


def retrack_from(frames, tracks, points, frame, *, camera=None, stop=None, conflict_px=GROUP_CONFLICT_PX,
                 progress=True, **options):
    """Re-track some points forward from a (corrected) frame.

    Parameters
    ----------
    frames : (T, H, W) ndarray or sequence
        The frames the tracks were made from.
    tracks : pandas.DataFrame
        Tracks, typically after :func:`apply_corrections`; the positions of ``points`` on
        ``frame`` (and on the two frames before, when trusted, for the velocity) seed the
        re-tracking.
    points : int or sequence of int
        Point ids to re-track.
    frame : int
        Frame to start from (its rows are kept as they are).
    camera : str, optional
        Rows of this camera when ``tracks`` holds several.
    stop : int, optional
        Last frame to re-track (default: the last frame).
    conflict_px : float
        A re-tracked ok position closer than this to another (not re-tracked) point's ok or
        manual position on the same frame is flagged ``conflict``.
    **options
        Tracking options of :func:`track_markers` (``min_score``, ``search_radius``...).

    Returns
    -------
    pandas.DataFrame
        A copy of ``tracks`` whose rows for ``points`` on frames ``frame + 1 .. stop`` are
        replaced by the re-tracked ones.
    """
    fr = _Frames(frames)
    pts = np.atleast_1d(np.asarray(points, dtype=np.int64))
    t = tracks
    if camera is not None and "camera" in t.columns:
        t = t[t["camera"] == camera]
    frame = int(frame)
    stop = fr.n - 1 if stop is None else int(stop)
    if not 0 <= frame < fr.n:
        raise ValueError(f"frame must be in [0, {fr.n - 1}], got {frame}")
    if not frame <= stop < fr.n:
        raise ValueError(f"stop must be in [{frame}, {fr.n - 1}], got {stop}")
    sel = t[(t["frame"] == frame) & t["point"].isin(pts)].drop_duplicates("point").set_index("point")
    missing = [int(q) for q in pts if q not in sel.index]
    if missing:
        raise ValueError(f"tracks have no row for points {missing} on frame {frame}")
    seed = sel.loc[pts, ["x", "y"]].to_numpy(float)
    bad = ~np.all(np.isfinite(seed), 1)
    if bad.any():
        raise ValueError(
            f"points {pts[bad].tolist()} have no position on frame {frame}; correct them first "
            "(apply_corrections) and re-track from the corrected frame"
        )
    p = _resolve_options(options.pop("options", None), **options)
    tracker = _seeded_tracker(fr, t, pts, seed, frame, p)
    res = _Results(fr.n, len(pts))
    res.x[frame], res.y[frame] = seed[:, 0], seed[:, 1]
    res.status[frame] = OK
    _run_pass(fr, tracker, res, range(frame + 1, stop + 1), 1, None, progress, "retrack")
    new = _tracks_frame(res, pts, camera if camera is not None else "left")
    new = new[(new["frame"] > frame) & (new["frame"] <= stop)]
    out, idx = _replace_rows(tracks, new, pts, frame, stop, camera)
    _audit_retracked(out, idx, pts, frame, fr.n, camera)
    _flag_on_others(out, idx, pts, frame, stop, camera, conflict_px)
    return out


def _seeded_tracker(fr, t, pts, seed, frame, p):
    """A tracker of points ``pts`` started from their (corrected) positions ``seed`` on
    ``frame``, kept exactly as given, with the trusted rows of ``t`` (ok, manual,
    interpolated) on the two frames before as its motion model's history."""
    tracker = _Tracker.from_picks(fr[frame], seed, np.full(len(pts), -1, np.int64), p, fr.is_u8, pts)
    # the corrected position is the user's: keep it exactly as the seed
    tracker.hist_x[:, 0] = seed
    tracker.hist_t[:, 0] = frame
    tracker.last_ok[:] = frame
    tracker.last_upd[:] = frame
    trusted = ("ok", "manual", "interpolated")
    for k, back in ((1, 1), (2, 2)):
        prev = t[(t["frame"] == frame - back) & t["point"].isin(pts)].drop_duplicates("point").set_index("point")
        for i, q in enumerate(pts):
            if (tracker.nh[i] == k and q in prev.index and prev.at[q, "status"] in trusted
                    and np.isfinite(prev.at[q, "x"])):
                tracker.hist_x[i, k] = (prev.at[q, "x"], prev.at[q, "y"])
                tracker.hist_t[i, k] = frame - back
                tracker.nh[i] = k + 1
    return tracker


def _replace_rows(tracks, new, pts, frame, stop, camera):
    """A copy of ``tracks`` whose rows of ``pts`` (of ``camera``) on frames ``frame + 1 ..
    stop`` take the re-tracked rows ``new``; returns it and the index of those rows."""
    out = tracks.copy()
    if "reason" not in out.columns:
        out["reason"] = ""
    for c in ("x_pix", "y_pix", "sigma"):
        if c not in out.columns:
            out[c] = np.nan
    mask = out["point"].isin(pts) & (out["frame"] > frame) & (out["frame"] <= stop)
    if camera is not None and "camera" in out.columns:
        mask &= out["camera"] == camera
    idx = out.index[mask]
    sub = out.loc[idx, ["frame", "point"]].reset_index()
    sub = sub.merge(new, on=["frame", "point"], how="left")
    for c in ("x", "y", "score", "status", "x_pix", "y_pix", "reason", "sigma"):
        if c in out.columns:
            out.loc[sub["index"].to_numpy(), c] = sub[c].to_numpy()
    return out, idx


def _flag_on_others(out, idx, pts, frame, stop, camera, conflict_px):
    """Flag ``conflict`` (in place) the re-tracked ok rows ``idx`` within ``conflict_px``
    of another point's ok or manual position on the same frame: a re-tracked point must
    not sit on another point."""
    others = out[~out["point"].isin(pts) & out["status"].isin(("ok", "manual")) & (out["frame"] > frame)
                 & (out["frame"] <= stop)]
    if camera is not None and "camera" in others.columns:
        others = others[others["camera"] == camera]
    mine = out.loc[idx]
    mine = mine[mine["status"] == "ok"]
    if len(mine) and len(others):
        m = mine.reset_index().merge(others[["frame", "x", "y"]], on="frame", suffixes=("", "_o"))
        close = np.hypot(m["x"] - m["x_o"], m["y"] - m["y_o"]) < conflict_px
        hit = m.loc[close, "index"].unique()
        out.loc[hit, "status"] = "flagged"
        out.loc[hit, "reason"] = "conflict"



def _audit_retracked(out, idx, pts, frame, T, camera):
    """Audit (:func:`~.audit.audit_against_picks`) the re-tracked rows ``idx`` of ``out``
    (points ``pts``, after ``frame``) against the constellation on ``frame``: the positions
    of every point ok or manual there; a misplaced ok row is flagged in place."""
    rows = out if camera is None or "camera" not in out.columns else out[out["camera"] == camera]
    rows = rows[(rows["frame"] >= 0) & (rows["frame"] < T)]
    ids = np.unique(rows["point"].to_numpy(np.int64))
    col = np.searchsorted(ids, rows["point"].to_numpy(np.int64))
    f = rows["frame"].to_numpy(np.int64)
    res = SimpleNamespace(x=np.full((T, ids.size), np.nan), y=np.full((T, ids.size), np.nan),
                          status=np.full((T, ids.size), LOST, np.int8), reason=np.zeros((T, ids.size), np.int8))
    res.x[f, col], res.y[f, col] = rows["x"].to_numpy(float), rows["y"].to_numpy(float)
    st = rows["status"].to_numpy()
    res.status[f, col] = np.where(st == "ok", OK, FLAGGED)
    on = f == frame
    ref = np.full((ids.size, 2), np.nan)
    keep = on & np.isin(st, ("ok", "manual"))
    ref[col[keep], 0], ref[col[keep], 1] = res.x[frame, col[keep]], res.y[frame, col[keep]]
    judged = np.isin(ids, pts)
    before = res.status.copy()
    if not audit_against_picks(res, ref, np.all(np.isfinite(ref), axis=1), judged):
        return
    tf, tc = np.nonzero((before == OK) & (res.status != OK))
    hit = pd.MultiIndex.from_arrays([tf, ids[tc]])
    sub = out.loc[idx]
    m = pd.MultiIndex.from_arrays([sub["frame"].to_numpy(np.int64), sub["point"].to_numpy(np.int64)]).isin(hit)
    m &= (sub["frame"] > frame).to_numpy()
    out.loc[sub.index[m], "status"] = "flagged"
    out.loc[sub.index[m], "reason"] = "misplaced"
