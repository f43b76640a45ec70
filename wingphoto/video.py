"""Verification video: every frame with the tracker's markings, as the thesis drew them.

A red ``+`` marks the pixel-level match (the correlation peak, columns ``x_pix, y_pix``),
a blue ``x`` the sub-pixel centre (``x, y``), and a circle in the status colour
surrounds each point (green ok, orange flagged, magenta manual, cyan interpolated; a
lost point is drawn at its last known position as a grey dashed circle only when it has
one). The frame number is written in the corner. Watching it is the quickest way to see
where tracking needs a correction.
"""
from __future__ import annotations

import logging
import os
from pathlib import Path

import cv2
import numpy as np

__all__ = ["write_tracking_video", "STATUS_COLOURS"]

logger = logging.getLogger(__name__)

#: BGR colours of the status circles.
STATUS_COLOURS = {
    "ok": (0, 200, 0),
    "flagged": (0, 140, 255),
    "lost": (128, 128, 128),
    "manual": (255, 0, 255),
    "interpolated": (255, 255, 0),
}
_RED = (0, 0, 255)
_BLUE = (255, 0, 0)


def _to_bgr8(frame, lo, hi):
    f = np.asarray(frame)
    if f.ndim == 3 and f.shape[2] == 3:
        g = f
    else:
        if f.ndim != 2:
            raise ValueError(f"frames must be 2D grayscale images, got shape {f.shape}")
        g = f
    if g.dtype != np.uint8:
        scale = 255.0 / max(hi - lo, 1e-12)
        g = np.clip((g.astype(np.float32) - lo) * scale, 0, 255).astype(np.uint8)
    if g.ndim == 2:
        g = cv2.cvtColor(g, cv2.COLOR_GRAY2BGR)
    return g


def _open_writer(path, fps, size):
    """Open an MP4 ('mp4v') writer, or fall back to MJPG in an .avi beside it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tries = [(path, "mp4v")] if path.suffix.lower() in (".mp4", ".m4v", ".mov") else []
    if path.suffix.lower() == ".avi":
        tries.append((path, "MJPG"))
    else:
        tries.append((path.with_suffix(".avi"), "MJPG"))
    for p, code in tries:
        tmp = p.with_name(f".{p.stem}.partial{p.suffix}")
        w = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*code), float(fps), size)
        if w.isOpened():
            if p != path:
                logger.warning("could not write %s with 'mp4v'; wrote MJPG to %s instead", path, p)
            return w, p, tmp
        w.release()
        if tmp.exists():
            tmp.unlink()
    raise ValueError(
        f"OpenCV cannot open a video writer for {path} (tried 'mp4v' and 'MJPG'); "
        "use a path ending in .mp4 or .avi in a writable folder"
    )


def write_tracking_video(frames, tracks, path, *, fps=30, scale=2, camera=None, labels=True,
                         progress=True):
    """Write a video of the frames with the tracked points drawn on them.

    Parameters
    ----------
    frames : (T, H, W) ndarray or sequence
        The frames that were tracked (anything :func:`wingphoto.io.read_sequence`
        returns); uint8, uint16 or float; read one at a time.
    tracks : pandas.DataFrame
        Tracks with columns frame, point, x, y, status (``x_pix, y_pix`` drawn when
        present). Frames without rows are written unmarked.
    path : str or Path
        Output file; ``.mp4`` is written with the 'mp4v' codec. When OpenCV cannot
        write MP4, an MJPG ``.avi`` with the same stem is written instead. The video is
        written to a hidden partial file and renamed when complete, so an interrupted
        run never replaces a good video with a truncated one.
    fps : float
        Playback frame rate (default 30: a 3000 fps sequence plays 100 x slower).
    scale : int
        Integer magnification (nearest neighbour), so 6-px markers stay visible.
    camera : str, optional
        Keep only the rows of this camera when ``tracks`` has a ``camera`` column.
    labels : bool
        Write the point number next to each point.
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    pathlib.Path
        The file written (``path``, or the ``.avi`` fallback).

    Notes
    -----
    Markings as in the thesis' verification plots: red ``+`` at the pixel-level match,
    blue ``x`` at the sub-pixel centre. Positions are scaled as ``(x + 0.5) * scale - 0.5``
    so that the marks sit on the magnified pixel centres (``docs/conventions.md``).
    uint16 and float frames are mapped to 8 bits by the 0.1 and 99.9 percentiles of the
    first frame.
    """
    from tqdm.auto import tqdm

    scale = int(scale)
    if scale < 1:
        raise ValueError(f"scale must be a positive integer, got {scale}")
    if not (fps > 0 and np.isfinite(fps)):
        raise ValueError(f"fps must be positive, got {fps}")
    from .io.atomic import check_output_path

    check_output_path(path)  # a folder, FIFO or device is refused, never replaced
    n = len(frames)
    if n == 0:
        raise ValueError("frames is empty: nothing to write")
    missing = [c for c in ("frame", "point", "x", "y", "status") if c not in tracks.columns]
    if missing:
        raise ValueError(f"tracks lacks columns {missing}; expected a tracks DataFrame")
    t = tracks
    if camera is not None and "camera" in t.columns:
        t = t[t["camera"] == camera]
    fr = t["frame"].to_numpy(np.int64)
    order = np.argsort(fr, kind="stable")
    fr = fr[order]
    cols = {c: t[c].to_numpy()[order] for c in ("point", "x", "y", "status")}
    has_pix = "x_pix" in t.columns and "y_pix" in t.columns
    if has_pix:
        cols["x_pix"] = t["x_pix"].to_numpy(float)[order]
        cols["y_pix"] = t["y_pix"].to_numpy(float)[order]
    starts = np.searchsorted(fr, np.arange(n + 1))

    f0 = np.asarray(frames[0])
    lo, hi = (0.0, 255.0)
    if f0.dtype != np.uint8:
        lo, hi = (float(v) for v in np.percentile(f0, [0.1, 99.9]))
    H, W = f0.shape[:2]
    size = (W * scale, H * scale)
    if max(size) > 16384:
        raise ValueError(f"scale={scale} makes {W}x{H} frames {size[0]}x{size[1]} px, more than video codecs "
                         f"take (16384 px); use scale <= {max(1, 16384 // max(W, H))}")
    writer, out, tmp = _open_writer(path, fps, size)
    arm = max(3, 2 * scale)
    done = False
    try:
        for k in tqdm(range(n), disable=not progress, desc="video", leave=False):
            f = np.asarray(frames[k])
            if f.shape[:2] != (H, W):
                raise ValueError(f"frame {k} has shape {f.shape} but frame 0 has {f0.shape}")
            img = _to_bgr8(f, lo, hi)
            if scale > 1:
                img = cv2.resize(img, size, interpolation=cv2.INTER_NEAREST)
            a, b = starts[k], starts[k + 1]
            for j in range(a, b):
                st = str(cols["status"][j])
                colour = STATUS_COLOURS.get(st, (255, 255, 255))
                x, y = float(cols["x"][j]), float(cols["y"][j])
                if has_pix and np.isfinite(cols["x_pix"][j]) and np.isfinite(cols["y_pix"][j]):
                    c = (int(round((cols["x_pix"][j] + 0.5) * scale - 0.5)), int(round((cols["y_pix"][j] + 0.5) * scale - 0.5)))
                    cv2.drawMarker(img, c, _RED, cv2.MARKER_CROSS, 2 * arm, 1)
                if np.isfinite(x) and np.isfinite(y):
                    c = (int(round((x + 0.5) * scale - 0.5)), int(round((y + 0.5) * scale - 0.5)))
                    cv2.drawMarker(img, c, _BLUE, cv2.MARKER_TILTED_CROSS, 2 * arm, 1)
                    cv2.circle(img, c, 3 * arm, colour, 1)
                    if labels:
                        cv2.putText(img, str(cols["point"][j]), (c[0] + 3 * arm, c[1] - 3 * arm),
                                    cv2.FONT_HERSHEY_SIMPLEX, 0.35, colour, 1, cv2.LINE_AA)
            cv2.putText(img, f"frame {k}", (5, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
            writer.write(img)
        done = True
    finally:
        writer.release()
        if done:
            os.replace(tmp, out)  # written completely: only now replace an older video
        elif tmp.exists():
            tmp.unlink()
    return out
