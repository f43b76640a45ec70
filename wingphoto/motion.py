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

__all__ = ["ImageShift", "StaticBackground", "estimate_shift", "frame_content", "static_background"]

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
    # the Hanning window is applied here, not passed to phaseCorrelate: OpenCV 5.0's Python
    # binding ignores that argument (same result with and without it, measured)
    window = cv2.createHanningWindow(a.shape[::-1], cv2.CV_32F)
    (dx, dy), response = cv2.phaseCorrelate((a - a.mean()) * window, (b - b.mean()) * window)
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


class StaticBackground(NamedTuple):
    """What stays still in a sequence, for measuring the camera's own motion.

    Made by :func:`static_background`; :meth:`offset` measures one frame against it.

    Attributes
    ----------
    image : (h, w) ndarray of float32
        Temporal median of frames spread over the sequence, downsampled by ``scale``:
        the moving wing averages out, the reference dots, mount and edges stay.
    mask : (h, w) ndarray of float32
        Weight in [0, 1]: the static features, dilated by the largest expected shift.
    scale : float
        Downsampling factor applied to full-resolution frames.
    n_features : int
        Number of downsampled pixels holding static features (0: nothing static to
        follow; :meth:`offset` then returns NaN).
    """

    image: np.ndarray
    mask: np.ndarray
    scale: float
    n_features: int

    def offset(self, frame):
        """Return the :class:`ImageShift` of ``frame``'s static content against the background.

        A camera bump shows as a step in this offset from one frame to the next; the
        wing's own motion does not, because only the static features (masked) take part
        in the phase correlation. NaN shifts when the background has no static features.
        """
        if self.n_features == 0:
            return ImageShift(float("nan"), float("nan"), 0.0)
        b = _prepared(frame, self.scale)
        if b.shape != self.image.shape:
            raise ValueError(f"frame of shape {np.shape(frame)} does not match the background's sequence")
        a = (self.image - self.image.mean()) * self.mask
        b = (b - b.mean()) * self.mask
        # no Hanning window: the static features often sit near the image border (reference
        # dots), where a window would hand the correlation to the wing in the middle; the
        # mask already makes both images fall to zero away from the features
        (dx, dy), response = cv2.phaseCorrelate(a.astype(np.float32), b.astype(np.float32))
        return ImageShift(float(dx) / self.scale, float(dy) / self.scale, float(response))


def static_background(frames, *, max_size=DEFAULT_MAX_SIZE, max_shift=16.0, n_frames=31):
    """Build the :class:`StaticBackground` of a sequence from up to ``n_frames`` frames.

    Parameters
    ----------
    frames : sequence of (H, W) arrays
        Anything with ``len`` and integer indexing (a ``read_sequence`` result, an array).
    max_size : int, optional
        Frames are area-downsampled so their longer side is at most this many pixels.
    max_shift : float, optional
        Largest camera shift (full-resolution px) to be measured: the static features'
        mask is dilated by this much so that shifted features still fall inside it.
    n_frames : int, optional
        Number of frames, evenly spread over the sequence, whose median is the background.

    Returns
    -------
    StaticBackground

    Notes
    -----
    Static features are pixels of the median image whose high-pass value (image minus a
    Gaussian blur of sigma 4 px) exceeds 6 robust standard deviations (1.4826 x MAD) of
    the high-pass image and 1 % of the image's grey range (or, in a scene textured everywhere, the strongest 1 % of them).
    The median assumes the static features are where they are in most of the chosen
    frames; with dense texture and a bump half-way, the median blurs and the step comes
    out too small. On the flapping-wing samples a 5 px bump of one camera moves the
    offset by 5.4 px while the wing's own motion moves it by at most 0.5 px.

    Examples
    --------
    >>> import numpy as np
    >>> scene = np.zeros((96, 128), np.float32)
    >>> for x, y in [(10, 12), (100, 20), (60, 80), (20, 70), (115, 85)]:
    ...     _ = cv2.circle(scene, (x, y), 3, 1.0, -1)
    >>> frames = np.stack([scene] * 7 + [np.roll(scene, 4, axis=1)] * 5)
    >>> bg = static_background(frames)
    >>> steps = [bg.offset(frames[k]).dx - bg.offset(frames[k - 1]).dx for k in range(1, 12)]
    >>> int(np.argmax(np.abs(steps))) + 1, round(max(np.abs(steps)))
    (7, 4)
    """
    n = len(frames)
    if n == 0:
        raise ValueError("static_background: frames is empty; pass at least one frame")
    first = np.asarray(frames[0])
    if first.ndim != 2:
        raise ValueError(f"static_background takes 2-D grey frames, got shape {first.shape}")
    scale = min(1.0, float(max_size) / max(first.shape))
    idx = np.unique(np.linspace(0, n - 1, min(n, int(n_frames))).round().astype(int))
    stack = np.stack([_prepared(frames[int(i)], scale) for i in idx])
    image = np.median(stack, axis=0).astype(np.float32)
    hp = image - cv2.GaussianBlur(image, (0, 0), 4)
    mad = 1.4826 * float(np.median(np.abs(hp - np.median(hp))))
    # significant structure: 6 robust sigmas, and at least 1 % of the image's grey range
    # (a noise-free synthetic background has MAD 0: blur halos must not count)
    features = np.abs(hp) > max(6 * mad, 0.01 * float(np.ptp(image)), 1e-6)
    if features.sum() < 0.002 * features.size:  # texture everywhere: keep its strongest 1 %
        p99 = np.percentile(np.abs(hp), 99)
        features = (np.abs(hp) >= p99) & (p99 > 1e-6 * max(1.0, float(np.abs(image).max())))
    features = features.astype(np.uint8)
    r = int(np.ceil(max_shift * scale)) + 1
    mask = cv2.dilate(features, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)))
    mask = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), 1.5)
    return StaticBackground(image, mask, scale, int(features.sum()))
