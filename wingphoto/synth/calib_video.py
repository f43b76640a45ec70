"""A synthetic calibration *video*: the pan-tilt board recorded by both cameras.

The thesis recorded the pan-tilt run (:func:`wingphoto.pantilt.pan_tilt_schedule`) at
100 fps and picked still, sharp pairs from the two recordings afterwards
(:func:`wingphoto.capture.select_calibration_frames`). This renders such a recording
with its truth: still holds with noise, smooth servo moves that motion-blur the board,
a damped wobble after each move, the board's pose and true corners in every frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..camera import StereoRig, rodrigues_inverse
from .board import _pan_tilt_rotation, _render_board
from .raster import _check_common, _finish
from .rig import LEVELS, _image_size, scene_frame, thesis_rig


@dataclass(frozen=True)
class CalibrationVideo:
    """Frames of a rendered pan-tilt calibration recording and their truth.

    Attributes
    ----------
    left, right : (T, H, W) ndarray
        The rendered frames of each camera (``dtype`` as requested).
    frame_index : (T,) ndarray of int
        Frame number of each rendered frame in the full recording at ``fps`` (all
        frames, or a few per step when ``frames_per_step`` was given).
    time_s : (T,) ndarray
        Time of each left frame's mid-exposure from the start of the run, s.
    step : (T,) ndarray of int
        The schedule step (from 1) the device is executing at that time.
    still : (T,) ndarray of bool
        True when the left and right true corners move less than 0.05 px during the
        exposure and since the previous frame of the full recording.
    motion_px : (T,) ndarray
        Largest true corner displacement (both views) over the exposure, px.
    angles_deg : (T, 2) ndarray
        Board (tilt, pan) at mid-exposure, degrees.
    om, T : (T, 3) ndarray
        Board -> left camera pose at mid-exposure (``X_left = R(om) X_board + T``, mm).
    corners_left, corners_right : (T, N, 2) ndarray
        True corner pixels at mid-exposure (OpenCV order); the right ones at the right
        frame's own time when ``offset_right`` is not 0. NaN outside the image.
    rig : StereoRig
    schedule : pandas.DataFrame
        The device schedule that was played.
    fps, exposure_s : float
    offset_right : int
        The right recording is this many frames ahead: right frame ``i`` shows time
        ``i + offset_right`` (0 for synchronized cameras).
    pattern_size, square_size, board_points :
        The board (inner corners, mm, (N, 3) board coordinates).
    """

    left: np.ndarray
    right: np.ndarray
    frame_index: np.ndarray
    time_s: np.ndarray
    step: np.ndarray
    still: np.ndarray
    motion_px: np.ndarray
    angles_deg: np.ndarray
    om: np.ndarray
    T: np.ndarray
    corners_left: np.ndarray
    corners_right: np.ndarray
    rig: StereoRig
    schedule: pd.DataFrame
    fps: float
    exposure_s: float
    offset_right: int
    pattern_size: tuple
    square_size: float
    board_points: np.ndarray

    def __len__(self):
        return len(self.left)

    def truth(self):
        """Tidy table of the per-frame truth: frame, time_s, step, still, motion_px, tilt_deg, pan_deg."""
        return pd.DataFrame({
            "frame": self.frame_index, "time_s": self.time_s, "step": self.step, "still": self.still,
            "motion_px": self.motion_px, "tilt_deg": self.angles_deg[:, 0], "pan_deg": self.angles_deg[:, 1],
        })


def _board_targets(schedule, tilt_deg, pan_deg):
    """Board (tilt, pan) of each step: servo angles mapped by rank to evenly spaced board angles."""
    out = []
    for col, amax in (("tilt_deg", tilt_deg), ("pan_deg", pan_deg)):
        pose = schedule.loc[schedule["kind"] == "pose", col].to_numpy() if "kind" in schedule else schedule[col]
        stops = np.unique(np.round(pose, 9))
        board = np.linspace(-amax, amax, len(stops)) if len(stops) > 1 else np.zeros(1)
        out.append(np.interp(schedule[col].to_numpy(), stops, board))
    return np.column_stack(out)


def _angles_at(t, starts, targets, move_s, wobble_deg, settle_s):
    """Board (tilt, pan) at times t: smooth moves between the step targets, then a damped wobble."""
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
    prev = np.where(k[:, None] > 0, targets[np.maximum(k - 1, 0)], targets[0])
    goal = targets[k]
    u = np.clip((t - starts[k]) / move_s, 0.0, 1.0)
    s = 0.5 - 0.5 * np.cos(np.pi * u)  # cosine ease: zero speed at both ends
    ang = prev + (goal - prev) * s[:, None]
    after = t - starts[k] - move_s
    delta = goal - prev
    norm = np.linalg.norm(delta, axis=1, keepdims=True)
    direction = np.divide(delta, norm, out=np.zeros_like(delta), where=norm > 0)
    wob = np.where(after > 0, wobble_deg * np.exp(-np.maximum(after, 0) / settle_s)
                   * np.sin(2 * np.pi * 6.0 * np.maximum(after, 0)), 0.0)
    return ang + direction * wob[:, None]


def render_calibration_video(
    rig=None, *, schedule=None, fps=100.0, frames_per_step=None, exposure_s=None, move_s=0.3,
    wobble_deg=0.6, settle_s=0.08, pattern_size=(9, 6), square_size=8.0, tilt_deg=20.0, pan_deg=30.0,
    noise_std=1.0, blur_sigma=0.6, supersample=1, n_sub=5, offset_right=0, dtype=np.uint8, seed=0,
    progress=False,
):
    """Render both cameras' recordings of a pan-tilt calibration run, with truth.

    Parameters
    ----------
    rig : StereoRig, optional
        Default :func:`thesis_rig`.
    schedule : pandas.DataFrame, optional
        The device schedule (default :func:`wingphoto.pantilt.pan_tilt_schedule`: 22
        steps of 1 s). The board's angles are the stops' ranks mapped to evenly spaced
        angles in ``[-tilt_deg, tilt_deg]`` x ``[-pan_deg, pan_deg]`` (as
        :func:`render_calibration_set`).
    fps : float, optional
        Frame rate (default 100, the thesis').
    frames_per_step : int, optional
        Render only this many frames per step (the first one mid-move, the others
        spread over the rest of the hold) instead of every frame: a full 22 s recording
        at 100 fps is 2200 pairs and renders in minutes. Default: every frame.
    exposure_s : float, optional
        Exposure time, s (default half the frame interval).
    move_s : float, optional
        Duration of a servo move (cosine-eased), s (default 0.3).
    wobble_deg, settle_s : float, optional
        Amplitude (degrees) and decay time (s) of the 6 Hz wobble after each move.
    pattern_size, square_size : optional
        The board (default 9 x 6 inner corners, 8 mm squares).
    tilt_deg, pan_deg : float, optional
        Largest board tilt and pan, degrees.
    noise_std, blur_sigma, dtype, seed : optional
        As for :func:`render_calibration_set`.
    supersample : int, optional
        Samples per pixel along each axis (default 1: the edges are anti-aliased
        analytically; 2 is about 8 times slower).
    n_sub : int, optional
        Sub-exposures averaged for a frame with motion (default 5).
    offset_right : int, optional
        Make the right recording ``offset_right`` frames ahead (right frame ``i`` shows
        time ``i + offset_right``), to test offset detection. Default 0.
    progress : bool, optional

    Returns
    -------
    CalibrationVideo

    Examples
    --------
    >>> from wingphoto.pantilt import pan_tilt_schedule
    >>> v = render_calibration_video(schedule=pan_tilt_schedule(1, 2, hold_s=0.5), fps=20, frames_per_step=2,
    ...                              move_s=0.1)
    >>> len(v), v.step.tolist(), (v.motion_px > 1).tolist()  # the first frame of a later step is mid-move
    (6, [1, 1, 2, 2, 3, 3], [False, False, True, False, True, False])
    """
    from ..pantilt import pan_tilt_schedule

    rig = thesis_rig() if rig is None else rig
    if not isinstance(rig, StereoRig):
        raise ValueError(f"rig must be a wingphoto.StereoRig, got {type(rig).__name__}")
    schedule = pan_tilt_schedule() if schedule is None else schedule
    for col in ("start_s", "hold_s", "pan_deg", "tilt_deg"):
        if col not in getattr(schedule, "columns", ()):
            raise ValueError(f"schedule must come from wingphoto.pantilt.pan_tilt_schedule (no column {col!r})")
    fps = float(fps)
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    exposure_s = 0.5 / fps if exposure_s is None else float(exposure_s)
    if not 0 <= exposure_s <= 1.0 / fps:
        raise ValueError(f"exposure_s must lie in [0, 1/fps] = [0, {1 / fps:g}] s, got {exposure_s}")
    if not move_s > 0:
        raise ValueError(f"move_s must be positive, got {move_s}")
    _check_common(noise_std, blur_sigma, dtype)
    nx, ny = (int(v) for v in pattern_size)
    starts = schedule["start_s"].to_numpy(dtype=float)
    holds = schedule["hold_s"].to_numpy(dtype=float)
    end = float(starts[-1] + holds[-1])
    targets = _board_targets(schedule, tilt_deg, pan_deg)
    n_all = int(np.floor(end * fps))
    if frames_per_step is None:
        frames = np.arange(n_all)
    else:
        m = int(frames_per_step)
        if m < 1:
            raise ValueError(f"frames_per_step must be >= 1, got {frames_per_step}")
        frames = []
        for s0, h in zip(starts, holds):
            first = int(np.ceil((s0 + 0.5 * move_s) * fps))
            rest = np.linspace(s0 + move_s + 0.5 * (h - move_s) / max(m - 1, 1), s0 + h, m - 1, endpoint=False)
            frames += [first] + [int(np.round(t * fps)) for t in rest]
        frames = np.unique(np.clip(frames, 0, n_all - 1))
    S, axes = scene_frame(rig)
    X = np.column_stack([np.tile(np.arange(nx), ny), np.repeat(np.arange(ny), nx), np.zeros(nx * ny)]) * square_size
    centre = np.array([(nx - 1) / 2, (ny - 1) / 2, 0.0]) * square_size
    levels = (LEVELS["board_black"], LEVELS["board_white"], LEVELS["board_surround"])
    for cam in (rig.left, rig.right):
        _image_size(cam)

    def pose(t):
        a = _angles_at(t, starts, targets, move_s, wobble_deg, settle_s)
        return [(_pan_tilt_rotation(axes, row[0], row[1]), row) for row in a]

    def corners(side, Rb, Tb):
        cam = getattr(rig, side)
        Xc = X @ Rb.T + Tb
        x = cam.project(Xc if side == "left" else rig.to_right(Xc))
        w, h = cam.image_size
        x[(x[:, 0] < -0.5) | (x[:, 0] > w - 0.5) | (x[:, 1] < -0.5) | (x[:, 1] > h - 0.5)] = np.nan
        return x

    rng = np.random.default_rng(seed)
    out = {"left": [], "right": []}
    truth = {k: [] for k in ("cl", "cr", "ang", "om", "T", "motion", "still")}
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        def tqdm(x, **_):
            return x
    for f in tqdm(frames, desc="calibration video", disable=not progress):
        mids = {"left": (f + 0.5) / fps, "right": (f + offset_right + 0.5) / fps}
        motion = 0.0
        still_ok = True
        for side in ("left", "right"):
            t_mid = mids[side]
            t_sub = t_mid + np.linspace(-0.5, 0.5, n_sub) * exposure_s
            edge = pose([t_sub[0], t_sub[-1], t_mid - 1.0 / fps])
            c0 = corners(side, edge[0][0], S - edge[0][0] @ centre)
            c1 = corners(side, edge[1][0], S - edge[1][0] @ centre)
            cp = corners(side, edge[2][0], S - edge[2][0] @ centre)
            blur_px = float(np.nanmax(np.hypot(*(c1 - c0).T))) if np.isfinite(c0).any() else 0.0
            step_px = float(np.nanmax(np.hypot(*(c1 - cp).T))) if np.isfinite(cp).any() else 0.0
            motion = max(motion, blur_px)
            still_ok &= blur_px < 0.05 and step_px < 0.05
            cam = getattr(rig, side)
            subs = pose(t_sub) if blur_px > 0.02 else pose([t_mid])
            acc = None
            for Rb, _ in subs:
                Tb = S - Rb @ centre
                Rc, Tc = (Rb, Tb) if side == "left" else (rig.R @ Rb, rig.R @ Tb + rig.T)
                img = _render_board(cam, Rc, Tc, (nx, ny), square_size, ss=int(supersample), border=1.0,
                                    levels=levels)
                acc = img if acc is None else acc + img
            out[side].append(_finish(acc / len(subs), blur_sigma=blur_sigma, noise_std=noise_std, rng=rng,
                                     dtype=dtype))
            (Rm, am), = pose([t_mid])
            Tm = S - Rm @ centre
            truth["cl" if side == "left" else "cr"].append(corners(side, Rm, Tm))
            if side == "left":
                truth["ang"].append(am)
                truth["om"].append(rodrigues_inverse(Rm))
                truth["T"].append(Tm)
        truth["motion"].append(motion)
        truth["still"].append(still_ok)
    t_left = (frames + 0.5) / fps
    step_idx = np.clip(np.searchsorted(starts, t_left, side="right") - 1, 0, len(starts) - 1)

    def frozen(a, dt=np.float64):
        a = np.asarray(a, dtype=dt)
        a.setflags(write=False)
        return a

    return CalibrationVideo(
        left=np.stack(out["left"]), right=np.stack(out["right"]), frame_index=frozen(frames, np.int64),
        time_s=frozen(t_left), step=frozen(schedule["step"].to_numpy()[step_idx], np.int64),
        still=frozen(truth["still"], bool), motion_px=frozen(truth["motion"]), angles_deg=frozen(truth["ang"]),
        om=frozen(truth["om"]), T=frozen(truth["T"]), corners_left=frozen(truth["cl"]),
        corners_right=frozen(truth["cr"]), rig=rig, schedule=schedule, fps=fps, exposure_s=exposure_s,
        offset_right=int(offset_right), pattern_size=(nx, ny), square_size=float(square_size), board_points=frozen(X),
    )
