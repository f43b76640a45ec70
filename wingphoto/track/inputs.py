"""Validated access to frames and picks."""
from __future__ import annotations

from pathlib import Path

import numpy as np


# --------------------------------------------------------------------------- inputs
class _Frames:
    """Uniform, validated access to a (T, H, W) array or a lazy sequence (len, [i])."""

    def __init__(self, frames):
        if isinstance(frames, (str, Path)):
            raise ValueError(
                "frames must be image data, got a path; load it first with "
                "wingphoto.io.read_sequence(path)"
            )
        if isinstance(frames, np.ndarray):
            if frames.ndim == 2:
                raise ValueError(
                    f"frames must be a (T, H, W) stack or a sequence of images, got one 2D image "
                    f"of shape {frames.shape}; pass frames[None] for a single frame"
                )
            if frames.ndim != 3:
                raise ValueError(
                    f"frames must be a (T, H, W) array of grayscale images, got shape {frames.shape}; "
                    "convert colour frames to grayscale first"
                )
        elif not (hasattr(frames, "__len__") and hasattr(frames, "__getitem__")):
            raise ValueError(
                f"frames must be a (T, H, W) array or a sequence supporting len() and [i] "
                f"(e.g. wingphoto.io.read_sequence), got {type(frames).__name__}"
            )
        self.src = frames
        self.n = len(frames)
        if self.n == 0:
            raise ValueError("frames is empty: the sequence has no images to track")
        f0 = np.asarray(frames[0])
        if f0.ndim != 2:
            raise ValueError(
                f"frames must be grayscale (H, W) images, frame 0 has shape {f0.shape}; "
                "convert colour frames to grayscale first"
            )
        if f0.dtype not in (np.uint8, np.uint16, np.float32, np.float64):
            raise ValueError(f"frames must be uint8, uint16 or float, frame 0 is {f0.dtype}")
        self.shape = f0.shape
        self.dtype = f0.dtype
        self.is_u8 = f0.dtype == np.uint8

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        f = self.src[i]
        if not isinstance(f, np.ndarray):
            f = np.asarray(f)
        if f.shape != self.shape:
            raise ValueError(
                f"frame {i} has shape {f.shape} but frame 0 has {self.shape}: all frames of a "
                "sequence must have the same size (mixed folders or a cropped file?)"
            )
        if f.dtype != self.dtype:
            raise ValueError(f"frame {i} is {f.dtype} but frame 0 is {self.dtype}: mixed bit depths")
        if f.dtype == np.float64:
            f = f.astype(np.float32)
        return f


def _parse_picks(picks):
    """Return (xy (N, 2) float, point ids (N,) int64, half sizes (N,) int or -1, the frame
    each marker was picked in (N,) int64, 0 by default)."""
    import pandas as pd

    half = None
    frames = None
    if isinstance(picks, (list, tuple)) and picks and isinstance(picks[0], dict):
        picks = pd.DataFrame(list(picks))
    if isinstance(picks, pd.DataFrame):
        missing = [c for c in ("x", "y") if c not in picks.columns]
        if missing:
            raise ValueError(
                f"picks lacks columns {missing}; expected point, x, y (and optionally half_size "
                "or rect) as saved by the picker, or an (N, 2) array of (x, y) clicks"
            )
        xy = picks[["x", "y"]].to_numpy(np.float64)
        ids = picks["point"].to_numpy(np.int64) if "point" in picks.columns else np.arange(len(picks))
        if "frame" in picks.columns:
            fv = pd.to_numeric(picks["frame"], errors="coerce").to_numpy(np.float64)
            bad_f = ~np.isfinite(fv) | (fv != np.round(fv)) | (fv < 0)
            if bad_f.any():
                k = int(np.flatnonzero(bad_f)[0])
                raise ValueError(f"pick of point {ids[k]} has frame {picks['frame'].iloc[k]!r}: the frame a "
                                 "marker was picked in must be a whole number >= 0")
            frames = fv.astype(np.int64)
        if "half_size" in picks.columns:
            half = picks["half_size"].to_numpy(np.float64)
        elif "rect" in picks.columns:
            # rect = (x0, y0, width, height) as MATLAB's imcrop returns it
            rects = np.array([np.asarray(r, float).reshape(4) for r in picks["rect"]])
            half = (np.maximum(rects[:, 2], rects[:, 3]) - 1) / 2
        elif {"rect_w", "rect_h"} <= set(picks.columns):
            half = (np.maximum(picks["rect_w"].to_numpy(float), picks["rect_h"].to_numpy(float)) - 1) / 2
        elif {"half_w", "half_h"} <= set(picks.columns):
            half = np.maximum(picks["half_w"].to_numpy(float), picks["half_h"].to_numpy(float))
    else:
        xy = np.asarray(picks, dtype=np.float64)
        if xy.ndim == 1 and xy.size == 2:
            xy = xy[None, :]
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(
                f"picks must be an (N, 2) array of (x, y) clicks or the picker's saved picks, "
                f"got shape {np.shape(picks)}"
            )
        ids = np.arange(len(xy), dtype=np.int64)
    if len(xy) == 0:
        raise ValueError("picks is empty: click at least one marker")
    bad = ~np.all(np.isfinite(xy), axis=1)
    if bad.all():
        raise ValueError("picks are all NaN: click at least one marker")
    if len(np.unique(ids)) != len(ids):
        raise ValueError("picks has duplicate point ids; each point must be picked once")
    if half is None:
        half = np.full(len(xy), -1.0)
    half = np.where(np.isfinite(half), half, -1.0)
    half = np.where(half < 0, -1, np.maximum(np.round(half), 2)).astype(np.int64)
    if frames is None:
        frames = np.zeros(len(xy), np.int64)
    return xy, ids, half, frames

