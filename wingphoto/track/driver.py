"""track_markers and retrack_from: passes over a sequence, checkpoints, backward merge."""
from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import numpy as np

from .checkpoint import _Checkpointer, _fingerprint, _load_checkpoint, _run_pass
from .inputs import _Frames, _parse_picks
from .options import TrackOptions
from .results import _Results, _merge_backward, _tracks_frame
from .status import _R, FLAGGED, OK
from .tracker import Tracker as _Tracker

logger = logging.getLogger("wingphoto.track")


def _resolve_options(options, **given):
    """One :class:`TrackOptions` from ``options`` and keyword options (None: not given)."""
    if options is None:
        options = TrackOptions()
    elif isinstance(options, dict):
        options = TrackOptions(**options)
    elif not isinstance(options, TrackOptions):
        raise ValueError(f"options must be a wingphoto.track.TrackOptions (or a dict of its fields), "
                         f"got {type(options).__name__}")
    names = TrackOptions.names()
    unknown = sorted(k for k in given if k not in names)
    if unknown:
        raise TypeError(f"unknown option(s) {unknown}; the options are {list(names)}")
    changes = {k: v for k, v in given.items() if v is not None or k in ("max_mass_ratio", "max_score_drop")}
    return dataclasses.replace(options, **changes) if changes else options


def track_markers(frames, picks, *, camera="left", search_radius=None, max_sigma=None, polarity=None,
                  bidirectional=False, checkpoint=None, checkpoint_every=500, progress=True, options=None,
                  **expert):
    """Track markers from their picks through a sequence, flagging doubtful points.

    Parameters
    ----------
    frames : (T, H, W) ndarray or sequence
        Grayscale frames (uint8, uint16 or float), anything
        :func:`wingphoto.io.read_sequence` returns (``len`` and ``[i]``); read one at a
        time, so memory does not grow with the sequence length.
    picks : (N, 2) array_like, or DataFrame / list of dicts
        Each marker's position: (x, y) clicks in frame 0 in px (origin at the centre of the
        top-left pixel; rounding to the pixel is fine), the template size then chosen from
        the blob; or the picker's saved picks with columns ``point, x, y`` and optionally
        ``frame`` (the frame the marker was picked in, default 0: a marker picked in frame
        k is tracked forward and backward from k), ``half_w``/``half_h``, ``half_size``
        (template half width, px) or ``rect`` (``(x0, y0, width, height)``). A NaN pick (a
        marker not visible) gives that point ``lost`` rows with reason ``no_pick`` (and a
        logged warning).
    camera : str
        Value of the ``camera`` column.
    search_radius : int, optional
        Largest search radius in px (default 20): used on frame 1, where no velocity is
        known yet, and as the cap of the prediction-driven radius. Must exceed the largest
        motion between frames 0 and 1.
    max_sigma : float, optional
        Largest ``sigma`` (px) of an ``ok`` point (default 0.25).
    polarity : {"auto", 1, -1}, optional
        Bright (1) or dark (-1) markers; "auto" (default) decides per marker.
    options : TrackOptions, optional
        All options (:class:`~wingphoto.track.TrackOptions`: the user options above, and
        the expert thresholds with their documentation); the keywords above override it.
    **expert
        Any other field of :class:`~wingphoto.track.TrackOptions` by name (``min_score``,
        ``max_coast``, ``search_every`` ...).
    bidirectional : bool
        Also track backwards from the last frame; flag ``fb_disagree`` where the passes
        disagree by more than ``fb_tolerance`` px and use the backward position where only
        it is ok. Doubles the run time.
    checkpoint : str or Path, optional
        File (``.npz``) holding the state; saved atomically every ``checkpoint_every``
        frames and when the run stops on an exception. If it exists and was written for
        the same frames, picks and options, tracking resumes from it with identical
        results.
    checkpoint_every : int
        Frames between two checkpoint saves (default 500).
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    tracks : pandas.DataFrame
        One row per (frame, point): camera, frame, point, x, y (sub-pixel centre, px), score
        (correlation peak), status (ok / flagged / lost), x_pix, y_pix (pixel-level match,
        NaN where there was none), reason ("" when ok). x, y are NaN when lost; a flagged
        point carries its best guess. Frame 0 holds the refined picks (score 1). Reasons
        (:data:`REASONS`; module docstring, 7): ``low_score``, ``ambiguous``, ``merged``, ``conflict``,
        ``jump``, ``no_signal``, ``appearance``, ``edge``, ``out_of_frame``,
        ``lost_track`` (coasted longer than ``max_coast``), ``reacquired`` (first frame
        after a re-acquisition), ``fb_disagree``, ``no_pick``, ``pick_moved`` (frame 0:
        the refinement moved the click by more than 1.5 px, or saw a foreign blob or a
        rough background; the click is kept), ``foreign`` (something bright not
        explained by a known marker touches the disk), ``imprecise`` (``sigma`` above
        ``max_sigma``), ``blank`` (a blank frame: black, saturated, constant),
        ``constellation`` (most markers left their predictions at once and no glitch - a
        dropped or repeated frame, a camera bump - explains it); :func:`check_stereo` adds
        ``stereo``. ``sigma`` (px) is the per-axis 1-sigma uncertainty of x, y, estimated
        from the image (``docs/tracker.md``), NaN where there is no position.

    Raises
    ------
    ValueError
        Empty sequence, frames of different sizes or bit depths, NaN picks, a pick outside
        the image, not on a marker, or too close to the edge for its template, a template
        larger than the image, a checkpoint written for other inputs.

    Notes
    -----
    The design and the failure each choice prevents are listed in the module docstring
    (:mod:`wingphoto.track`). Conventions: ``docs/conventions.md``.

    Examples
    --------
    >>> yy, xx = np.mgrid[:40, :50]
    >>> frames = np.stack([100 * (np.hypot(xx - 20 - k, yy - 18) < 4) for k in range(5)]).astype(np.uint8)
    >>> t = track_markers(frames, [[20, 18]], progress=False)
    >>> last = t[t.frame == 4].iloc[0]
    >>> float(round(last.x, 3)), float(round(last.y, 3)), last.status
    (24.0, 18.0, 'ok')
    """
    fr = _Frames(frames)
    xy_all, ids_all, half_all, pf_all = _parse_picks(picks)
    active = np.all(np.isfinite(xy_all), axis=1)
    if not active.all():
        logger.warning("picks of points %s are NaN: those points are reported lost (reason 'no_pick')",
                       ids_all[~active].tolist())
    late = active & (pf_all >= fr.n)
    if late.any():
        k = int(np.flatnonzero(late)[0])
        raise ValueError(f"point {ids_all[k]} was picked in frame {pf_all[k]} but the sequence has {fr.n} frames "
                         "(0 to {}); pick it in a frame of this sequence".format(fr.n - 1))
    xy, ids, half = xy_all[active], ids_all[active], half_all[active]
    p = _resolve_options(options, search_radius=search_radius, max_sigma=max_sigma, polarity=polarity, **expert)
    if (pf_all[active] != 0).any():
        if checkpoint is not None:
            raise ValueError("checkpoint= needs every marker picked in frame 0 (these picks were made in frames "
                             f"{sorted(set(pf_all[active].tolist()))}); track without a checkpoint")
        return _track_from_pick_frames(fr, xy_all, ids_all, half_all, pf_all, active, p, camera, progress)
    T, N = fr.n, len(xy)
    shape = fr.shape
    fw = _Results(T, N)
    bw = _Results(T, N) if bidirectional else None
    box = {}

    def state():
        meta = {"phase": box["phase"], "next": box["next"]}
        arrays = fw.arrays("fw_")
        if bw is not None:
            arrays.update(bw.arrays("bw_"))
        arrays.update({"st_" + k: v for k, v in box["tracker"].state().items()})
        return meta, arrays

    ck = None
    resumed = None
    if checkpoint is not None:
        fp = _fingerprint(fr, xy, ids, half, p, camera, bidirectional)
        ck = _Checkpointer(checkpoint, fp, checkpoint_every, state, fr)
        if Path(checkpoint).exists():
            resumed = _load_checkpoint(checkpoint, fp, fr, required=[p_ + k for p_ in ("fw_",)
                                                                 for k in _Results.names + ("status", "reason")])
    if resumed is None:
        tracker = _Tracker.from_picks(fr[0], xy, half, p, fr.is_u8, ids)
        _seed_row(fw, 0, tracker)
        box.update(phase="forward", next=1, tracker=tracker)
    else:
        meta, arrays = resumed
        fw.load(arrays, "fw_")
        if bw is not None and "bw_x" in arrays:
            bw.load(arrays, "bw_")
        st = {k[3:]: v for k, v in arrays.items() if k.startswith("st_")}
        try:
            tracker = _Tracker.from_state(st, p, fr.is_u8, shape)
        except (KeyError, ValueError, IndexError) as exc:
            raise ValueError(f"checkpoint {checkpoint} is incomplete or corrupt ({type(exc).__name__}: {exc}); "
                             "delete it or pass another checkpoint path") from None
        box.update(phase=meta["phase"], next=int(meta["next"]), tracker=tracker)
        logger.info("resuming %s pass at frame %d from %s", meta["phase"], meta["next"], checkpoint)

    if ck is not None:
        orig_completed = ck.completed

        def completed(t):
            box["next"] = t + (1 if box["phase"] == "forward" else -1)
            orig_completed(t)

        ck.completed = completed

    if box["phase"] == "forward":
        _run_pass(fr, box["tracker"], fw, range(box["next"], T), 1, ck, progress, f"track {camera}")
        if bidirectional:
            box["tracker"] = _backward_tracker(box["tracker"], fw, T)
            box.update(phase="backward", next=T - 2)
            bw.x[T - 1], bw.y[T - 1] = fw.x[T - 1], fw.y[T - 1]
            bw.status[T - 1], bw.reason[T - 1] = fw.status[T - 1], fw.reason[T - 1]
            bw.score[T - 1], bw.sigma[T - 1] = fw.score[T - 1], fw.sigma[T - 1]
            bw.xpix[T - 1], bw.ypix[T - 1] = fw.xpix[T - 1], fw.ypix[T - 1]
    if box["phase"] == "backward":
        _run_pass(fr, box["tracker"], bw, range(box["next"], -1, -1), -1, ck, progress, f"back {camera}")
    if box["phase"] in ("forward", "backward"):
        box["phase"] = "done"
        box["next"] = T
        if ck is not None:
            ck.save()
    if bidirectional:
        fw2 = _Results(T, N)
        for k in _Results.names + ("status", "reason"):
            getattr(fw2, k)[...] = getattr(fw, k)
        _merge_backward(fw2, bw, p.fb_tolerance)
        return _tracks_frame(_expand(fw2, active), ids_all, camera)
    return _tracks_frame(_expand(fw, active), ids_all, camera)


def _seed_row(res, k, tracker):
    """Row ``k`` of ``res``: the refined picks (score 1; a click the refinement moved by more
    than 1.5 px, or that saw a foreign blob or a rough background, is kept and flagged
    ``pick_moved``: it was pulled by something - an unpicked neighbour, glare)."""
    res.x[k], res.y[k] = tracker.pos[:, 0], tracker.pos[:, 1]
    res.xpix[k], res.ypix[k] = np.rint(tracker.pos[:, 0]), np.rint(tracker.pos[:, 1])
    res.score[k] = 1.0
    res.sigma[k] = tracker.sigma0
    res.status[k] = OK
    moved = tracker.pick_moved
    res.status[k, moved] = FLAGGED
    res.reason[k, moved] = _R["pick_moved"]


def _track_from_pick_frames(fr, xy_all, ids_all, half_all, pf_all, active, p, camera, progress):
    """Track markers picked in several frames: each group of markers picked in frame k is
    tracked forward from k to the end and backward from k to frame 0."""
    T, N = fr.n, len(ids_all)
    out = _Results(T, N)
    out.reason[:, ~active] = _R["no_pick"]
    for k in np.unique(pf_all[active]).tolist():
        sel = np.flatnonzero(active & (pf_all == k))
        res = _Results(T, sel.size)
        args = (fr[k], xy_all[sel], half_all[sel], p, fr.is_u8, ids_all[sel])

        def start():
            tracker = _Tracker.from_picks(*args)
            tracker.hist_t[:] = k
            tracker.last_ok[:] = k
            tracker.last_upd[:] = k
            return tracker

        tracker = start()
        _seed_row(res, k, tracker)
        if k < T - 1:
            _run_pass(fr, tracker, res, range(k + 1, T), 1, None, progress, f"track {camera} from {k}")
        if k > 0:
            _run_pass(fr, start(), res, range(k - 1, -1, -1), -1, None, progress, f"back {camera} from {k}")
        for name in _Results.names + ("status", "reason"):
            getattr(out, name)[:, sel] = getattr(res, name)
    return _tracks_frame(out, ids_all, camera)


def _expand(res, active):
    """Results of the picked points, with lost rows ('no_pick') for points without a pick."""
    if active.all():
        return res
    T = res.x.shape[0]
    out = _Results(T, len(active))
    for k in _Results.names + ("status", "reason"):
        getattr(out, k)[:, active] = getattr(res, k)
    out.reason[:, ~active] = _R["no_pick"]
    return out


def _backward_tracker(fwd, fw, T):
    """A tracker seeded at the last frame from the forward pass (same templates)."""
    import copy

    b = copy.copy(fwd)
    n = len(fwd.h)
    b.hist_x = np.full((n, 3, 2), np.nan)
    b.hist_t = np.zeros((n, 3), np.int64)
    b.nh = np.ones(n, np.int64)
    b.lostflag = np.zeros(n, bool)
    b.resid_rms = np.ones(n)
    b.last_upd = np.full(n, T - 1, np.int64)
    b.last_ok = np.full(n, T - 1, np.int64)
    b.tplr = [t.copy() for t in fwd.tpl0]
    b.tplu = [None] * n
    b.last_score = np.ones(n)
    b._init_stack()
    for i in range(n):
        okf = np.flatnonzero(fw.status[:, i] == OK)
        tl = int(okf[-1]) if okf.size else 0
        b.hist_x[i, 0] = (fw.x[tl, i], fw.y[tl, i])
        b.hist_t[i, 0] = tl
        b.last_ok[i] = tl
        b.lostflag[i] = tl < T - 1 - fwd.p.max_coast
    return b



def retrack_from(frames, tracks, points, frame, *, camera=None, stop=None, conflict_px=3.0,
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
    progress_opt = options.pop("progress", progress)
    p = _resolve_options(options.pop("options", None), **options)
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
    res = _Results(fr.n, len(pts))
    res.x[frame], res.y[frame] = seed[:, 0], seed[:, 1]
    res.status[frame] = OK
    _run_pass(fr, tracker, res, range(frame + 1, stop + 1), 1, None, progress_opt, "retrack")
    new = _tracks_frame(res, pts, camera if camera is not None else "left")
    new = new[(new["frame"] > frame) & (new["frame"] <= stop)]
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
    # a re-tracked point must not sit on another point
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
    return out

