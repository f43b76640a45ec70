"""Global image motion between two frames: the one detector of camera bumps and frame glitches.

Both the sequence checks (``check_sequence``: a bumped camera shows as a jump of the whole
image) and the tracker's constellation check (did every marker move together because the
camera moved, or was a frame skipped?) ask the same question: by how much did the *whole*
image shift between two frames? This module answers it once, with OpenCV's phase
correlation (:func:`cv2.phaseCorrelate`, Hanning-windowed, sub-pixel), so that the two
callers cannot disagree.

Pixel coordinates follow ``docs/conventions.md``: a shift (dx, dy) > 0 means the content
of ``image`` lies right of / below where it was in ``reference``.
"""
from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

__all__ = ["ImageShift", "estimate_shift", "frame_content"]

#: Frames are compared at most this many pixels on their longer side (area-averaged):
#: phase correlation of a 512 x 512 frame costs ~4 ms, of a 128 x 128 one ~0.2 ms, and a
#: camera bump of a few pixels survives the downsampling as a sub-pixel shift.
DEFAULT_MAX_SIZE = 256


class ImageShift(NamedTuple):
    """Global translation of ``image`` against ``reference``.

    Attributes
    ----------
    dx, dy : float
        Shift in full-resolution pixels (x right, y down).
    response : float
        Phase-correlation peak height in [0, 1]: near 1 for a pure translation of the same
        content, near 0 when the two frames share nothing (a blank or unrelated frame).
    """

    dx: float
    dy: float
    response: float


def _prepared(frame, scale):
    a = np.asarray(frame)
    if a.ndim != 2:
        raise ValueError(f"estimate_shift takes 2-D grey frames, got shape {a.shape}")
    a = a.astype(np.float32, copy=False)
    if scale != 1.0:
        a = cv2.resize(a, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return a


def estimate_shift(reference, image, *, max_size=DEFAULT_MAX_SIZE):
    """Estimate the global translation of ``image`` relative to ``reference``.

    Parameters
    ----------
    reference, image : (H, W) array_like
        Two grey frames of the same shape (any numeric dtype).
    max_size : int, optional
        The frames are area-downsampled so that their longer side is at most this many
        pixels before correlating (the result is scaled back to full resolution).

    Returns
    -------
    ImageShift
        ``dx, dy`` in pixels and the correlation ``response``. A frame without content
        (constant) gives ``(0, 0, 0)``.

    Raises
    ------
    ValueError
        If the frames are not 2-D or differ in shape, or ``max_size`` < 16.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> a = cv2.GaussianBlur(rng.random((128, 160)).astype(np.float32), (0, 0), 2)
    >>> b = np.roll(a, (3, -5), axis=(0, 1))
    >>> s = estimate_shift(a, b)
    >>> round(s.dx), round(s.dy), s.response > 0.3
    (-5, 3, True)
    """
    ref = np.asarray(reference)
    img = np.asarray(image)
    if ref.shape != img.shape:
        raise ValueError(f"estimate_shift: frames differ in shape: {ref.shape} vs {img.shape}")
    if int(max_size) < 16:
        raise ValueError(f"estimate_shift: max_size must be >= 16 px, got {max_size}")
    scale = min(1.0, float(max_size) / max(ref.shape[:2])) if ref.ndim == 2 else 1.0
    a = _prepared(ref, scale)
    b = _prepared(img, scale)
    if not (frame_content(a) > 0 and frame_content(b) > 0):
        return ImageShift(0.0, 0.0, 0.0)
    window = cv2.createHanningWindow(a.shape[::-1], cv2.CV_32F)
    (dx, dy), response = cv2.phaseCorrelate(a - a.mean(), b - b.mean(), window)
    return ImageShift(float(dx) / scale, float(dy) / scale, float(response))


def frame_content(frame):
    """Return the standard deviation of a frame's grey levels (0 for a blank frame).

    A cheap measure of whether a frame carries any image at all: an all-black, all-white
    or constant frame gives 0.
    """
    a = np.asarray(frame)
    if a.size == 0:
        return 0.0
    return float(np.std(a, dtype=np.float64))
