"""Pick calibration pairs from two synchronized recordings of the pan-tilt board.

The thesis recorded the pan-tilt run (:mod:`wingphoto.pantilt`) with both high-speed
cameras and then picked 10-20 synchronized frames by hand, with the whole board visible
and in focus in both views. :func:`select_calibration_frames` does that picking:

1. **still**: the board must not move (frame-to-frame grey-level change of both views,
   downsampled, against the recording's own noise floor) -- a moving board is
   motion-blurred and, if the cameras are not exactly synchronized, seen at two
   different poses;
2. **offset**: the two recordings' motion signals are cross-correlated; a lag means the
   frames are not paired as numbered, and the lag found is applied (or, if you gave
   ``offset``, reported when it differs);
3. **detected**: the whole board found in both views (:func:`wingphoto.calibrate.find_corners`)
   with the corner order consistent between the views;
4. **sharp**: variance of the Laplacian over the board, not far below the other
   candidates' (focus, residual blur);
5. **diverse**: one pair per pan-tilt step when the schedule is known, else one per
   still period, duplicates of an earlier pose dropped; with ``n``, a greedy
   farthest-point choice over the board's position, size and perspective in the image.

Every frame that is not chosen gets its reason in ``Selection.candidates``.
"""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .calibrate import CornerDetection, find_corners
from .calibrate.checks import _check_pattern_size

__all__ = ["Selection", "select_calibration_frames", "estimate_offset", "motion_signal"]

logger = logging.getLogger(__name__)


# ============================================================== frames and motion
def _as_frames(source, name):
    if isinstance(source, (str, os.PathLike)):
        from .io import read_sequence

        return read_sequence(source)
    if isinstance(source, np.ndarray):
        if source.ndim not in (3, 4):
            raise ValueError(f"{name} must be a (T, H, W) stack, a list of frames or a recording path, "
                             f"got an array of shape {source.shape}")
        return source
    if not hasattr(source, "__len__") or not hasattr(source, "__getitem__"):
        raise ValueError(f"{name} must be a (T, H, W) stack, a list of frames or a recording path "
                         f"(anything wingphoto.read_sequence reads), got {type(source).__name__}")
    return source


def _gray(frame):
    a = np.asarray(frame)
    if a.ndim == 3:
        a = a[..., :3].astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)
    return a.astype(np.float32)


def _small(frame, factor=4):
    g = _gray(frame)
    h, w = (g.shape[0] // factor) * factor, (g.shape[1] // factor) * factor
    return g[:h, :w].reshape(h // factor, factor, w // factor, factor).mean(axis=(1, 3))


def motion_signal(frames, *, factor=4, progress=False):
    """Frame-to-frame change of a recording: mean absolute difference of downsampled frames.

    Parameters
    ----------
    frames : sequence of (H, W) arrays
    factor : int, optional
        Block-averaging factor before differencing (default 4; suppresses noise).
    progress : bool, optional

    Returns
    -------
    d : (T,) ndarray of float
        ``d[i]`` is the change from frame ``i - 1`` to frame ``i`` (grey levels); ``d[0]``
        is NaN.
    """
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        def tqdm(x, **_):
            return x
    d = np.full(len(frames), np.nan)
    prev = None
    for i in tqdm(range(len(frames)), desc="motion", disable=not progress):
        cur = _small(frames[i], factor)
        if prev is not None:
            if cur.shape != prev.shape:
                raise ValueError(f"frame {i} is {cur.shape} after downsampling but frame {i - 1} is {prev.shape}")
            d[i] = float(np.mean(np.abs(cur - prev)))
        prev = cur
    return d


def _still(d, factor, nums=None):
    """Per-frame motion and stillness from the changes to the previous and next frame.

    With consecutive frames, the larger change: a frame is still only when it matches
    both neighbours, which leaves out the first frame of a move (its start is eased, so
    it barely differs from the frame before) as well as the first frame after one. With
    a subsampled recording (``nums`` not consecutive), a neighbour far away in time says
    little about the frame itself: the smaller change then.
    """
    nxt = np.append(d[1:], np.nan)
    m = np.fmax(d, nxt)
    if nums is not None:
        gap = np.diff(np.asarray(nums))
        prev_adj = np.r_[False, gap == 1]
        next_adj = np.r_[gap == 1, False]
        sparse = ~prev_adj & ~next_adj
        m = np.where(prev_adj & ~next_adj, d, m)
        m = np.where(next_adj & ~prev_adj, nxt, m)
        m = np.where(sparse, np.fmin(d, nxt), m)
    finite = m[np.isfinite(m)]
    floor = float(np.percentile(finite, 25)) if finite.size else 0.0
    thr = max(factor * floor, 1e-6)
    return m, m <= thr, thr


def estimate_offset(motion_left, motion_right, *, max_offset=10):
    """Lag between two recordings from their motion signals.

    Parameters
    ----------
    motion_left, motion_right : (T,) ndarray
        From :func:`motion_signal`.
    max_offset : int, optional
        Largest lag tried, frames (default 10).

    Returns
    -------
    offset : int or None
        ``k`` such that right frame ``i + k`` was taken with left frame ``i``; None when
        the recordings hold too little motion to tell (or the peak is not clear).
    score : float
        Correlation at the peak (-1..1).
    """
    a = np.log(np.asarray(motion_left, float) + 1e-3)
    b = np.log(np.asarray(motion_right, float) + 1e-3)
    corr = {}
    for k in range(-int(max_offset), int(max_offset) + 1):
        i0, i1 = max(0, -k), min(len(a), len(b) - k)
        if i1 - i0 < 8:
            continue
        x, y = a[i0:i1], b[i0 + k:i1 + k]
        ok = np.isfinite(x) & np.isfinite(y)
        if ok.sum() < 8 or np.std(x[ok]) == 0 or np.std(y[ok]) == 0:
            continue
        corr[k] = float(np.corrcoef(x[ok], y[ok])[0, 1])
    if not corr:
        return None, np.nan
    best = max(corr, key=corr.get)
    # nearby lags correlate almost as well (a move lasts many frames): only the peak's height counts
    if corr[best] < 0.5:
        return None, corr[best]
    return int(best), corr[best]


# ============================================================== per-candidate checks
def _sharpness(gray, corners):
    """Variance of the Laplacian over the board's bounding box (grey levels^2)."""
    import cv2

    ok = np.all(np.isfinite(corners), axis=1)
    x0, y0 = np.floor(corners[ok].min(axis=0)).astype(int)
    x1, y1 = np.ceil(corners[ok].max(axis=0)).astype(int) + 1
    h, w = gray.shape
    roi = gray[max(y0, 0):min(y1, h), max(x0, 0):min(x1, w)]
    if roi.size < 9:
        return 0.0
    return float(cv2.Laplacian(np.ascontiguousarray(roi, dtype=np.float32), cv2.CV_32F).var())


def _axes_of(corners, pattern_size):
    g = corners.reshape(pattern_size[1], pattern_size[0], 2)
    along_row = np.nanmean(g[:, -1] - g[:, 0], axis=0)
    along_col = np.nanmean(g[-1, :] - g[0, :], axis=0)
    return along_row, along_col


def _same_order(cl, cr, pattern_size):
    """The board's row and column directions agree between the views (no half turn, no mirror)."""
    rl, cl_ = _axes_of(cl, pattern_size)
    rr, cr_ = _axes_of(cr, pattern_size)
    return float(rl @ rr) > 0 and float(cl_ @ cr_) > 0


def _descriptor(corners, pattern_size, size):
    """Board position, size and perspective in the image (for pose diversity)."""
    g = corners.reshape(pattern_size[1], pattern_size[0], 2)
    w, h = size
    c = np.nanmean(corners, axis=0)
    top = np.linalg.norm(g[0, -1] - g[0, 0])
    bottom = np.linalg.norm(g[-1, -1] - g[-1, 0])
    left = np.linalg.norm(g[-1, 0] - g[0, 0])
    right = np.linalg.norm(g[-1, -1] - g[0, -1])
    row = g[:, -1] - g[:, 0]
    ang = np.arctan2(np.mean(row[:, 1]), np.mean(row[:, 0]))
    return np.array([c[0] / w, c[1] / h, np.log(top + bottom), np.log(top / bottom), np.log(left / right),
                     np.sin(ang), np.cos(ang)])


# ============================================================== the result
@dataclass(frozen=True)
class Selection:
    """Calibration pairs chosen from two recordings (:func:`select_calibration_frames`).

    Attributes
    ----------
    frames : tuple of int
        Chosen left frame indices, in order; the right frame is ``frame + offset``.
    offset : int
        Right frame index minus left frame index of a pair.
    offset_estimate : int or None
        The lag found from the board motion (None when it could not be told).
    left, right : tuple of CornerDetection
        The detections of the chosen pairs: pass them to
        :func:`wingphoto.calibrate.calibrate_stereo` (or use :meth:`calibrate`).
    names : tuple of str
        ``"frame 00123"`` per chosen pair (the left frame index).
    images_left, images_right : tuple of (H, W) ndarray
        The chosen frames (for the contact sheet).
    candidates : pandas.DataFrame
        One row per left frame: ``frame``, ``right_frame``, ``motion_left``,
        ``motion_right`` (grey-level change, the larger of those to the previous and
        next frame),
        ``still``, ``run`` (still period, -1 when moving), ``step`` (pan-tilt step when
        the schedule is known, else -1), ``found_left``, ``found_right``,
        ``sharpness_left``, ``sharpness_right`` (NaN when not examined), ``selected``
        and ``reason`` ('' when selected).
    pattern_size : tuple of int
    motion_threshold : float
        Grey-level change below which a frame counts as still.
    """

    frames: tuple
    offset: int
    offset_estimate: int | None
    left: tuple
    right: tuple
    names: tuple
    images_left: tuple
    images_right: tuple
    candidates: pd.DataFrame
    pattern_size: tuple
    motion_threshold: float

    def __len__(self):
        return len(self.frames)

    def calibrate(self, square_size, **kwargs):
        """Calibrate the rig from the chosen pairs: ``calibrate_stereo(self.left, self.right, ...)``."""
        from .calibrate import calibrate_stereo

        return calibrate_stereo(list(self.left), list(self.right), self.pattern_size, square_size,
                                names=list(self.names), **kwargs)

    def reasons(self):
        """Count of frames per rejection reason (the reasons' first words), most frequent first."""
        r = self.candidates.loc[~self.candidates["selected"], "reason"]
        return r.str.replace(r"(:| \().*$", "", regex=True).value_counts()

    def summary(self):
        c = self.candidates
        n_runs = int(c["run"].max() + 1) if (c["run"] >= 0).any() else 0
        lines = [f"{len(self)} calibration pairs chosen from {len(c)} frames "
                 f"({int(c['still'].sum())} still, {n_runs} still periods); right frame = left frame "
                 f"{self.offset:+d}"
                 + (f" (found from the board motion: {self.offset_estimate:+d})"
                    if self.offset_estimate is not None else "")]
        lines.append("  chosen: " + ", ".join(str(f) for f in self.frames))
        for reason, n in self.reasons().items():
            lines.append(f"  {n:5d} frames not chosen: {reason}")
        return "\n".join(lines)

    def plot(self, *, ncols=6, axes=None, size=1.8):
        """Contact sheet of the chosen pairs (left, right, left, right, ...) with the corners."""
        from .plots import plot_contact_sheet

        if not len(self):
            raise ValueError("the selection is empty: nothing to show")
        imgs, titles, corners = [], [], []
        for k, f in enumerate(self.frames):
            imgs += [self.images_left[k], self.images_right[k]]
            titles += [f"L {f}", f"R {f + self.offset}"]
            corners += [self.left[k].corners, self.right[k].corners]
        axes = plot_contact_sheet(imgs, titles=titles, ncols=ncols, axes=axes, size=size)
        for ax, c in zip(np.asarray(axes).reshape(-1), corners):
            ax.plot(c[:, 0], c[:, 1], "-", color="tab:orange", lw=0.5)
            ax.plot(c[0, 0], c[0, 1], "o", color="tab:red", ms=3)
        return axes


# ============================================================== selection
def select_calibration_frames(
    left, right, pattern_size, *, n=None, offset=None, schedule=None, fps=None, frame_numbers=None, start_frame=0,
    still_factor=2.0, sharpness_factor=0.5, per_run=3, duplicate_px=2.0, max_offset=10, window=7, progress=False,
):
    """Pick still, sharp, fully detected and diverse calibration pairs from two recordings.

    Parameters
    ----------
    left, right : sequence of (H, W) arrays, (T, H, W) ndarray, or a path
        The two recordings, frame ``i`` of each taken at the same instant (up to
        ``offset``); a path is read with :func:`wingphoto.read_sequence`.
    pattern_size : (int, int)
        Inner corners per row and per column of the board, e.g. (9, 6).
    n : int, optional
        Number of pairs wanted; default: one per still period (or pan-tilt step).
    offset : int, optional
        Right frame index minus left frame index of a pair. Default: found from the
        board motion (0 when the recordings hold no motion to tell).
    schedule : pandas.DataFrame, optional
        The pan-tilt schedule that was played (:func:`wingphoto.pantilt.pan_tilt_schedule`);
        with ``fps``, one pair is chosen per pose step (the neutral step is skipped).
    fps : float, optional
        Frame rate of the recordings (needed with ``schedule``).
    frame_numbers : sequence of int, optional
        Frame number in the recording of each given frame (default ``0..T-1``), for a
        subsampled recording.
    start_frame : int, optional
        Frame number at which the schedule started (the trigger), default 0.
    still_factor : float, optional
        A frame is still when its changes to both neighbours are at most this factor
        times the recording's noise floor (25th percentile of the changes), in both
        views (for a subsampled recording, see ``frame_numbers``, its change to the
        nearer-looking neighbour). Default 2.
    sharpness_factor : float, optional
        Reject a candidate whose sharpness is below this fraction of the median over the
        detected candidates (default 0.5).
    per_run : int, optional
        Frames examined per still period, latest first (default 3; in a period of more
        than 6 frames the last 2 are skipped, where the next move may have begun
        unseen); the latest that is detected and sharp is chosen (the board has settled
        longest after the move).
    duplicate_px : float, optional
        A still period whose board lies within this mean corner distance of an already
        chosen one is a duplicate pose (default 2 px).
    max_offset : int, optional
        Largest lag tried when estimating the offset (default 10 frames).
    window : int, optional
        Corner refinement half-window (see :func:`~wingphoto.calibrate.find_corners`).
    progress : bool, optional

    Returns
    -------
    Selection
        ``.frames``, ``.left``/``.right`` (CornerDetection, ready for
        :func:`~wingphoto.calibrate.calibrate_stereo`), ``.candidates`` with a reason for
        every frame not chosen, ``.summary()``, ``.plot()``, ``.calibrate(square_size)``.

    Raises
    ------
    ValueError
        Invalid arguments, recordings of different frame sizes, no still frame, or no
        pair with the whole board in both views.
    """
    pattern_size = _check_pattern_size(pattern_size)
    L = _as_frames(left, "left")
    R = _as_frames(right, "right")
    if len(L) < 2 or len(R) < 2:
        raise ValueError(f"left and right need at least 2 frames each, got {len(L)} and {len(R)}")
    if np.shape(L[0])[:2] != np.shape(R[0])[:2]:
        logger.info("left frames are %s, right frames %s", np.shape(L[0]), np.shape(R[0]))
    if schedule is not None and (fps is None or not fps > 0):
        raise ValueError("schedule needs fps=, the recordings' frame rate, to map frames to pan-tilt steps")
    nums = np.arange(len(L)) if frame_numbers is None else np.asarray(frame_numbers, dtype=np.int64)
    if len(nums) != len(L):
        raise ValueError(f"frame_numbers has {len(nums)} entries but left has {len(L)} frames")
    if n is not None and int(n) < 3:
        raise ValueError(f"n must be at least 3 (stereo calibration needs 3 pairs), got {n}")
    # 1. motion and stillness of each view
    dl = motion_signal(L, progress=progress)
    dr = motion_signal(R, progress=progress)
    est, score = estimate_offset(dl, dr, max_offset=max_offset)
    if offset is None:
        offset = 0 if est is None else est
        if est:
            logger.warning("the right recording is offset by %+d frames from the left (found from the board "
                           "motion, correlation %.2f): pairing left frame i with right frame i%+d", est, score, est)
    else:
        offset = int(offset)
        if est is not None and est != offset:
            logger.warning("offset=%d given, but the board motion says %+d (correlation %.2f): check the pairing",
                           offset, est, score)
    ml, sl, thr_l = _still(dl, still_factor, nums)
    mr, sr, thr_r = _still(dr, still_factor, nums)
    T = len(L)
    rows = []
    for i in range(T):
        j = i + offset
        inside = 0 <= j < len(R)
        rows.append(dict(frame=i, frame_number=int(nums[i]), right_frame=j if inside else -1,
                         motion_left=ml[i], motion_right=mr[j] if inside else np.nan,
                         still=bool(inside and sl[i] and sr[j])))
    cand = pd.DataFrame(rows)
    cand["run"] = -1
    cand["step"] = -1
    for col in ("found_left", "found_right", "selected"):
        cand[col] = False
    cand["sharpness_left"] = np.nan
    cand["sharpness_right"] = np.nan
    cand["reason"] = ""
    for i in range(T):
        if cand.at[i, "right_frame"] < 0:
            cand.at[i, "reason"] = f"no right frame {i + offset} (offset {offset:+d})"
        elif not cand.at[i, "still"]:
            cand.at[i, "reason"] = (f"moving: change {ml[i]:.2f} / {mr[i + offset]:.2f} grey levels "
                                    f"(still below {thr_l:.2f} / {thr_r:.2f})")
    # 2. still periods, split by pan-tilt step when the schedule is known
    steps = np.full(T, -1)
    if schedule is not None:
        starts = schedule["start_s"].to_numpy(float) if "start_s" in schedule else np.r_[0, np.cumsum(
            schedule["hold_s"].to_numpy(float))[:-1]]
        t = (nums - int(start_frame)) / float(fps)
        end = starts[-1] + float(schedule["hold_s"].iloc[-1])
        k = np.searchsorted(starts, t, side="right") - 1
        valid = (t >= 0) & (t < end)
        steps = np.where(valid, schedule["step"].to_numpy()[np.clip(k, 0, len(starts) - 1)], -1)
        kinds = dict(zip(schedule["step"], schedule["kind"])) if "kind" in schedule else {}
        cand["step"] = steps
        for i in range(T):
            if cand.at[i, "reason"]:
                continue
            if steps[i] < 0:
                cand.at[i, "reason"] = "outside the pan-tilt schedule"
            elif kinds.get(steps[i]) == "neutral":
                cand.at[i, "reason"] = "neutral step (a repeat of a pose step)"
    run, runs = -1, []
    prev_ok, prev_step = False, None
    for i in range(T):
        ok = cand.at[i, "reason"] == ""
        if ok and not (prev_ok and steps[i] == prev_step):
            run += 1
            runs.append([])
        if ok:
            runs[-1].append(i)
            cand.at[i, "run"] = run
        prev_ok, prev_step = ok, steps[i]
    if not runs:
        raise ValueError(
            f"no still frame in the recordings ({T} frames; change threshold {thr_l:.2f} / {thr_r:.2f} grey "
            "levels): check that the two recordings show the pan-tilt board holding still between moves"
        )
    # 3.-4. detection and sharpness of a few frames per still period
    gray_cache = {}

    def detect(frames, idx, side):
        img = np.asarray(frames[idx])
        det = find_corners(img, pattern_size, window=window, name=f"{side} frame {idx}")
        gray_cache[(side, idx)] = img
        return det

    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        def tqdm(x, **_):
            return x
    examined = {}
    for r, members in enumerate(tqdm(runs, desc="still periods", disable=not progress)):
        # latest first (the board has settled longest after the move), but not the last
        # `guard` frames of a long period: a move's eased start hides below the noise there
        guard = 2 if len(members) > 6 else 0
        order = members[: len(members) - guard][::-1] + members[len(members) - guard:]
        for i in order[per_run:]:
            cand.at[i, "reason"] = "another frame of the same still period examined"
        for i in order[:per_run]:
            j = i + offset
            dl_, dr_ = detect(L, i, "left"), detect(R, j, "right")
            cand.at[i, "found_left"], cand.at[i, "found_right"] = dl_.found, dr_.found
            if not (dl_.found and dr_.found):
                miss = [s for s, d in (("left", dl_), ("right", dr_)) if not d.found]
                cand.at[i, "reason"] = f"board not fully detected in the {' and '.join(miss)} view"
                continue
            if not _same_order(dl_.corners, dr_.corners, pattern_size):
                cand.at[i, "reason"] = ("corner order differs between the views (the board looks the same after "
                                        "a half turn: use a board with an odd and an even count)")
                continue
            cand.at[i, "sharpness_left"] = _sharpness(_gray(L[i]), dl_.corners)
            cand.at[i, "sharpness_right"] = _sharpness(_gray(R[j]), dr_.corners)
            examined[i] = (dl_, dr_)
    if not examined:
        raise ValueError(
            f"the board ({pattern_size[0]} x {pattern_size[1]} inner corners) was not fully detected in both views "
            f"of any still frame; check pattern_size and the focus. Reasons: "
            + "; ".join(f"frame {i}: {cand.at[i, 'reason']}" for i in cand.index[cand['run'] >= 0][:5])
        )
    ex = cand.loc[list(examined)]
    med_l, med_r = ex["sharpness_left"].median(), ex["sharpness_right"].median()
    for i in examined:
        s_l, s_r = cand.at[i, "sharpness_left"], cand.at[i, "sharpness_right"]
        if s_l < sharpness_factor * med_l or s_r < sharpness_factor * med_r:
            cand.at[i, "reason"] = (f"blurred: sharpness {s_l:.0f} / {s_r:.0f}, below {sharpness_factor:g} x the "
                                    f"median {med_l:.0f} / {med_r:.0f}")
    # best frame of each still period: the latest that passed (settled longest after the move)
    best = []
    for r in range(len(runs)):
        ok = [i for i in examined if cand.at[i, "run"] == r and cand.at[i, "reason"] == ""]
        if not ok:
            continue
        b = max(ok)
        for i in ok:
            if i != b:
                cand.at[i, "reason"] = f"a later frame of the same still period chosen (frame {b})"
        best.append(b)
    # 5. duplicates (schedule unknown: the same pose held twice) and diversity
    chosen = []
    size = tuple(np.shape(L[0])[:2][::-1])
    for i in best:
        ci = examined[i][0].corners
        dup = next((c for c in chosen if schedule is None
                    and np.nanmean(np.hypot(*(examined[c][0].corners - ci).T)) < duplicate_px), None)
        if dup is not None:
            cand.at[i, "reason"] = f"same pose as frame {dup} (duplicate)"
        else:
            chosen.append(i)
    if n is not None and len(chosen) > int(n):
        D = np.array([_descriptor(examined[i][0].corners, pattern_size, size) for i in chosen])
        sd = D.std(axis=0)
        D = (D - D.mean(axis=0)) / np.where(sd > 0, sd, 1.0)
        keep = [int(np.argmax(np.linalg.norm(D, axis=1)))]
        dist = np.linalg.norm(D - D[keep[0]], axis=1)
        while len(keep) < int(n):
            k = int(np.argmax(dist))
            keep.append(k)
            dist = np.minimum(dist, np.linalg.norm(D - D[k], axis=1))
        for k, i in enumerate(chosen):
            if k not in keep:
                cand.at[i, "reason"] = f"pose too close to the others (n={int(n)} most diverse kept)"
        chosen = sorted(chosen[k] for k in keep)
    if len(chosen) < 3:
        logger.warning("only %d calibration pairs found (stereo calibration needs 3)", len(chosen))
    for i in chosen:
        cand.at[i, "selected"] = True
        cand.at[i, "reason"] = ""
    chosen = sorted(chosen)
    names = tuple(f"frame {int(nums[i]):05d}" for i in chosen)
    sel_l = tuple(_renamed(examined[i][0], f"{nm} (left)") for i, nm in zip(chosen, names))
    sel_r = tuple(_renamed(examined[i][1], f"{nm} (right)") for i, nm in zip(chosen, names))
    return Selection(
        frames=tuple(int(i) for i in chosen), offset=int(offset), offset_estimate=est, left=sel_l, right=sel_r,
        names=names, images_left=tuple(gray_cache[("left", i)] for i in chosen),
        images_right=tuple(gray_cache[("right", i + offset)] for i in chosen), candidates=cand,
        pattern_size=pattern_size, motion_threshold=float(max(thr_l, thr_r)),
    )


def _renamed(det, name):
    return CornerDetection(det.found, det.corners, det.pattern_size, det.image_size, name, det.message)
