"""Score a tracks table against the ground truth of a synthetic sequence.

The tracker is validated against truth, not tuned to it: :mod:`wingphoto.synth.scenarios`
renders named scenarios with development and test seeds, :mod:`wingphoto.synth.realdots`
moves real photographs of dots by known warps, and :func:`score_tracks` turns a tracks
table and the sequence it was made from into the numbers the benchmark
``benchmarks/track_sweep.py`` prints: how many visible point-frames the tracker reports
``ok``, how far its ok points are from the truth, how many of them are *confident
errors* (ok but more than 1 px off), and whether its ``sigma`` column is honest.

Conventions: ``docs/conventions.md`` (pixels (x, y), origin at the centre of the
top-left pixel; tracks are tidy, one row per camera, frame and point).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["score_tracks", "point_errors", "summarize_errors", "CONFIDENT_ERROR_PX"]

#: An ok point farther than this from the truth (px) is a confident error.
CONFIDENT_ERROR_PX = 1.0


def _truth(seq, camera):
    try:
        if getattr(seq, "camera", None) == camera and hasattr(seq, "points"):  # one-camera sequence
            pts, vis = seq.points, seq.visible
        else:
            pts, vis = getattr(seq, f"points_{camera}"), getattr(seq, f"visible_{camera}")
        pts = np.asarray(pts, dtype=np.float64)
        vis = np.asarray(vis, dtype=bool)
    except AttributeError:
        raise ValueError(
            f"seq must have points_{camera} (T, N, 2) and visible_{camera} (T, N) arrays "
            f"(a synth.StereoSequence), or be a one-camera sequence with camera == {camera!r}, "
            f"points and visible (synth.realdots), got {type(seq).__name__}"
        ) from None
    if pts.ndim != 3 or pts.shape[2] != 2 or vis.shape != pts.shape[:2]:
        raise ValueError(
            f"seq.points_{camera} must be (T, N, 2) and seq.visible_{camera} (T, N), "
            f"got {pts.shape} and {vis.shape}"
        )
    return pts, vis


def _grid(tracks, camera, shape):
    """Tracks -> x, y, sigma (T, N) float arrays and ok (T, N) bool (missing rows: not ok)."""
    need = {"frame", "point", "x", "y", "status"}
    if not isinstance(tracks, pd.DataFrame) or not need <= set(tracks.columns):
        got = sorted(tracks.columns) if isinstance(tracks, pd.DataFrame) else type(tracks).__name__
        raise ValueError(f"tracks must be a tracks DataFrame with columns {sorted(need)}, got {got}")
    if "camera" in tracks.columns and len(tracks):
        sel = tracks["camera"].astype(str) == str(camera)
        if not sel.any():
            raise ValueError(
                f"tracks has no rows for camera {camera!r} (cameras: {sorted(tracks['camera'].astype(str).unique())})"
            )
        tracks = tracks[sel]
    T, N = shape
    f = tracks["frame"].to_numpy()
    p = tracks["point"].to_numpy()
    inside = (f >= 0) & (f < T) & (p >= 0) & (p < N)
    if not inside.all():
        raise ValueError(
            f"tracks has frames/points outside the sequence ({T} frames, {N} points): "
            f"frames {f.min()}..{f.max()}, points {p.min()}..{p.max()}; score the matching sequence"
        )
    f = f.astype(np.int64)
    p = p.astype(np.int64)
    if len(np.unique(f * N + p)) != len(f):
        raise ValueError("tracks has more than one row for some (frame, point); score one camera at a time")
    x = np.full(shape, np.nan)
    y = np.full(shape, np.nan)
    sigma = np.full(shape, np.nan)
    ok = np.zeros(shape, bool)
    x[f, p] = tracks["x"].to_numpy(dtype=np.float64)
    y[f, p] = tracks["y"].to_numpy(dtype=np.float64)
    if "sigma" in tracks.columns:
        sigma[f, p] = tracks["sigma"].to_numpy(dtype=np.float64)
    ok[f, p] = (tracks["status"].astype(str) == "ok").to_numpy()
    ok &= np.isfinite(x) & np.isfinite(y)
    return x, y, sigma, ok


def score_tracks(tracks, seq, camera, *, points=None):
    """Compare a tracks table with the exact truth of the sequence it was made from.

    Parameters
    ----------
    tracks : pandas.DataFrame
        Tracks of one camera (``docs/conventions.md``): columns ``frame``, ``point``,
        ``x``, ``y`` (px), ``status``, optionally ``camera`` (rows of other cameras are
        ignored) and ``sigma`` (px, the per-axis 1-sigma uncertainty of each position).
        Frame ``k`` and point ``j`` are row ``k, j`` of the truth; a (frame, point) with
        no row counts as not ok.
    seq : synth.StereoSequence or similar
        Anything with ``points_<camera>`` (T, N, 2) px and ``visible_<camera>`` (T, N)
        bool arrays: a :func:`synth.render_flapping`, :func:`synth.scenarios.render_scenario`
        or :func:`synth.realdots.render_realdots` sequence.
    camera : str
        ``'left'`` or ``'right'`` (whatever names ``seq`` uses).
    points : array_like of int, optional
        Score only these points (e.g. the points that had a pick); default all N.

    Returns
    -------
    dict
        ``n_visible``
            visible point-frames (the marker measurable in that frame, as the sequence
            reports it);
        ``n_ok_visible``, ``ok_share``
            how many of them are ``ok``, and that share (NaN when ``n_visible`` is 0);
        ``n_ok``
            all ok point-frames (an ok point in a frame where the truth says not
            visible is still scored for its error);
        ``rms_px``, ``median_px``, ``p95_px``, ``worst_px``
            radial error of the ok points against the truth, px (NaN without ok points);
        ``confident_errors``
            ok points more than :data:`CONFIDENT_ERROR_PX` (1 px) from the truth;
        ``n_sigma``
            ok points with a finite positive ``sigma``;
        ``within_3_sigma``
            share of those whose radial error is at most 3 sigma (NaN without sigma);
        ``median_error_over_sigma``
            median of radial error / sigma (NaN without sigma).

    Raises
    ------
    ValueError
        ``tracks`` is not a tracks table, has no rows for ``camera``, rows outside the
        sequence or duplicate (frame, point) rows; ``seq`` lacks the truth arrays.

    Notes
    -----
    ``sigma`` is the per-axis standard deviation of an isotropic 2-D Gaussian error, so
    the radial error follows a Rayleigh distribution: for an honest ``sigma`` 98.9 % of
    ok points lie within 3 sigma and the median of error / sigma is
    ``sqrt(2 ln 2) = 1.18``. Issue 8 calls ``sigma`` honest when at least 95 % lie
    within 3 sigma and the median ratio lies between 0.5 and 2.

    Examples
    --------
    >>> from wingphoto import synth
    >>> seq = synth.render_flapping(n_frames=2)
    >>> s = score_tracks(seq.truth_tracks("left"), seq, "left")
    >>> s["ok_share"], s["rms_px"], s["confident_errors"]
    (1.0, 0.0, 0)
    """
    a = point_errors(tracks, seq, camera, points=points)
    return summarize_errors(a["error"], a["ok"], a["visible"], a["sigma"])

def point_errors(tracks, seq, camera, *, points=None):
    """Per point-frame arrays behind :func:`score_tracks` (to pool several sequences).

    Parameters are those of :func:`score_tracks`.

    Returns
    -------
    dict of (T, N) ndarray
        ``error`` (radial distance to the truth, px; NaN where the track has no
        position), ``ok`` (status ok with a position, restricted to ``points``),
        ``visible`` (restricted to ``points``) and ``sigma`` (px, NaN where absent).
    """
    truth, vis = _truth(seq, camera)
    x, y, sigma, ok = _grid(tracks, camera, vis.shape)
    if points is not None:
        points = np.unique(np.asarray(points, dtype=np.int64).ravel())
        if points.size and (points.min() < 0 or points.max() >= vis.shape[1]):
            raise ValueError(f"points must index the sequence's {vis.shape[1]} points, got {points.tolist()}")
        keep = np.zeros(vis.shape[1], bool)
        keep[points] = True
        vis = vis & keep
        ok = ok & keep
    err = np.hypot(x - truth[..., 0], y - truth[..., 1])
    return {"error": err, "ok": ok, "visible": vis, "sigma": sigma}


def summarize_errors(error, ok, visible, sigma):
    """The numbers of :func:`score_tracks` from (pooled) :func:`point_errors` arrays.

    Parameters
    ----------
    error, ok, visible, sigma : ndarray
        Same-shaped arrays (any shape, e.g. several sequences' arrays raveled and
        concatenated).

    Returns
    -------
    dict
        The keys of :func:`score_tracks`.
    """
    error, ok, vis, sigma = (np.asarray(a) for a in (error, ok, visible, sigma))
    ok = ok.astype(bool)
    vis = vis.astype(bool)
    e = error[ok]
    n_visible = int(vis.sum())
    n_ok_visible = int((ok & vis).sum())
    nan = float("nan")
    s = sigma[ok]
    has = np.isfinite(s) & (s > 0)
    ratio = e[has] / s[has]
    return {
        "n_visible": n_visible,
        "n_ok_visible": n_ok_visible,
        "ok_share": n_ok_visible / n_visible if n_visible else nan,
        "n_ok": int(ok.sum()),
        "rms_px": float(np.sqrt(np.mean(e**2))) if e.size else nan,
        "median_px": float(np.median(e)) if e.size else nan,
        "p95_px": float(np.percentile(e, 95)) if e.size else nan,
        "worst_px": float(e.max()) if e.size else nan,
        "confident_errors": int((e > CONFIDENT_ERROR_PX).sum()),
        "n_sigma": int(has.sum()),
        "within_3_sigma": float(np.mean(ratio <= 3.0)) if ratio.size else nan,
        "median_error_over_sigma": float(np.median(ratio)) if ratio.size else nan,
    }
