"""Normalised cross-correlation: MATLAB's ``normxcorr2``, ported faithfully.

The thesis located each marker in every frame with ``normxcorr2(template, frame)`` over the
whole image (``NCC.m``); :func:`normxcorr2` reproduces MATLAB's result, full output size
and zeroing rules included, in 0-based coordinates (``docs/conventions.md``).

The correlation is computed in the Fourier domain against the zero-mean template, and the
local image energy with summed-area tables (exact integer arithmetic for integer images),
the scheme of Lewis (1995). :class:`FrameCorrelator` reuses one image transform for many
fixed templates, which is what the thesis baseline (:func:`wingphoto.thesis.track_thesis`)
needs to search a whole frame for every marker.
"""
from __future__ import annotations

import numpy as np
from scipy import fft as _fft

from .centroid import _image2d

__all__ = ["normxcorr2", "FrameCorrelator"]

_SQRT_EPS1 = float(np.sqrt(np.spacing(1.0)))


def _as_image(a, name):
    """Return a 2-D float64 copy-free view of ``a`` (validated), plus its integer flag."""
    arr = _image2d(a, name)
    is_int = np.issubdtype(arr.dtype, np.integer)
    if not is_int and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or Inf; replace them (e.g. np.nan_to_num) first")
    return arr, is_int


def _check_template(tmpl, image_shape):
    if tmpl.size < 2:
        raise ValueError("template must contain at least 2 pixels (MATLAB normxcorr2 rule)")
    if tmpl.shape[0] > image_shape[0] or tmpl.shape[1] > image_shape[1]:
        raise ValueError(
            f"template {tmpl.shape} is larger than image {tuple(image_shape)} in at least "
            "one dimension; crop a smaller template or pass a larger image"
        )


def _centred_template(tmpl):
    """Zero-mean float64 template and its norm ``sqrt(sum((T - mean T)^2))``."""
    t = np.asarray(tmpl, dtype=np.float64)
    t0 = t - t.mean()
    norm = float(np.sqrt(np.sum(t0 * t0)))
    # MATLAB: "The values of TEMPLATE cannot all be the same." (std(T(:)) == 0)
    if np.all(t == t.flat[0]):
        raise ValueError(
            "template is constant (all pixels equal), so its correlation is undefined; "
            "crop a template that contains the marker"
        )
    return t0, norm


def _integral(a):
    """Summed-area table with a leading zero row and column."""
    s = np.zeros((a.shape[0] + 1, a.shape[1] + 1), dtype=a.dtype)
    np.cumsum(a, axis=0, out=s[1:, 1:])
    np.cumsum(s[1:, 1:], axis=1, out=s[1:, 1:])
    return s


def _box_full(s, m, n, shape):
    """Full-size local sums (MATLAB ``local_sum``) of an m x n box from integral image ``s``.

    Output ``[i, j]`` sums image rows ``i-m+1 .. i`` and columns ``j-n+1 .. j`` (clipped to
    the image), the footprint of the template at full-correlation index ``(i, j)``.
    """
    H, W = shape
    i = np.arange(H + m - 1)
    j = np.arange(W + n - 1)
    r1 = np.clip(i + 1, 0, H)
    r0 = np.clip(i - m + 1, 0, H)
    c1 = np.clip(j + 1, 0, W)
    c0 = np.clip(j - n + 1, 0, W)
    return s[np.ix_(r1, c1)] - s[np.ix_(r0, c1)] - s[np.ix_(r1, c0)] + s[np.ix_(r0, c0)]


class _LocalEnergy:
    """Per-image sums needed for the denominator, cached per template size."""

    def __init__(self, image, is_int):
        self.shape = image.shape
        self.is_int = is_int
        # no centring: partial (border) windows see the zero padding, as in MATLAB
        if is_int:
            a = image.astype(np.int64)
            self._maxabs = int(np.abs(a).max()) if a.size else 0
        else:
            a = image.astype(np.float64)
        self.s1 = _integral(a)
        self.s2 = _integral(a * a)
        self._cache = {}

    def get(self, m, n):
        """Return ``(denom_A, 1 / denom_A (0 where denom_A == 0), max denom_A, low)``.

        ``denom_A = sqrt(max(local_sum(A^2) - local_sum(A)^2 / mn, 0))`` at every full
        index; ``low`` holds the flat indices of its smallest values (candidates for
        MATLAB's tolerance rule).
        """
        key = (m, n)
        if key not in self._cache:
            mn = m * n
            ls1 = _box_full(self.s1, m, n, self.shape)
            ls2 = _box_full(self.s2, m, n, self.shape)
            if self.is_int and float(mn) * self._maxabs < 2.0**31:
                # exact: mn * sum(A^2) - sum(A)^2 fits in int64
                var = (mn * ls2 - ls1 * ls1).astype(np.float64) / mn
            else:
                ls1 = ls1.astype(np.float64)
                var = ls2.astype(np.float64) - ls1 * ls1 / mn
            da = np.sqrt(np.maximum(var, 0.0))
            dmax = float(da.max())
            inv = np.zeros_like(da)
            np.divide(1.0, da, out=inv, where=da > 0)
            # candidates for the tolerance rule; a template whose tolerance exceeds
            # ``cut`` falls back to a full comparison in _finish
            cut = 1e-6 * dmax
            low = np.flatnonzero(da <= cut)
            self._cache[key] = (da, inv, dmax, low, cut)
        return self._cache[key]


def _finish(numerator, tnorm, energy):
    """Divide and apply MATLAB's zeroing rules, in place on ``numerator``."""
    da, inv, dmax, low, cut = energy
    c = numerator
    c *= inv
    c *= 1.0 / tnorm
    # MATLAB: C = 0 where denom <= tol = sqrt(eps(max(abs(denom(:)))))
    tol = np.sqrt(np.spacing(tnorm * dmax)) / tnorm
    if tol > cut:
        c[da <= tol] = 0.0
    elif low.size:
        flat = c.reshape(-1)
        flat[low[da.reshape(-1)[low] <= tol]] = 0.0
    # MATLAB's numerical backstop: coefficients outside [-1, 1] by more than sqrt(eps(1))
    lim = 1.0 + _SQRT_EPS1
    if c.max() > lim or c.min() < -lim:
        c[np.abs(c) - 1.0 > _SQRT_EPS1] = 0.0
    return c


class FrameCorrelator:
    """Full-size ``normxcorr2`` of several fixed templates against one image at a time.

    The templates are transformed once; each call of :meth:`correlate` transforms the
    image once and reuses it for every template (the local energy is shared by templates
    of equal size). Results equal :func:`normxcorr2` to rounding (~1e-12).

    Parameters
    ----------
    templates : sequence of 2-D array_like
        Templates (any real dtype), each no larger than the images that will follow.
    image_shape : (2,) tuple of int
        ``(rows, cols)`` of the images that :meth:`correlate` will receive.

    Raises
    ------
    ValueError
        A template is constant, has fewer than 2 pixels or is larger than the image.
    """

    def __init__(self, templates, image_shape):
        self.image_shape = (int(image_shape[0]), int(image_shape[1]))
        self._t = []
        mmax = nmax = 1
        for k, t in enumerate(templates):
            arr, _ = _as_image(t, f"templates[{k}]")
            _check_template(arr, self.image_shape)
            t0, tnorm = _centred_template(arr)
            self._t.append((t0, tnorm))
            mmax = max(mmax, arr.shape[0])
            nmax = max(nmax, arr.shape[1])
        H, W = self.image_shape
        self.fshape = (_fft.next_fast_len(H + mmax - 1, real=True),
                       _fft.next_fast_len(W + nmax - 1, real=True))
        # correlation = convolution with the template rotated by 180 degrees
        self._tf = [_fft.rfft2(t0[::-1, ::-1], self.fshape) for t0, _ in self._t]

    def __len__(self):
        return len(self._t)

    def template_shape(self, k):
        """``(m, n)`` of template ``k``: ``C[i, j]`` puts its centre at
        ``(x, y) = (j - (n - 1) / 2, i - (m - 1) / 2)``."""
        return self._t[k][0].shape

    def replace(self, k, template):
        """Swap template ``k`` for a new one (e.g. a re-crop); sizes may change."""
        arr, _ = _as_image(template, "template")
        _check_template(arr, self.image_shape)
        t0, tnorm = _centred_template(arr)
        H, W = self.image_shape
        if H + arr.shape[0] - 1 > self.fshape[0] or W + arr.shape[1] - 1 > self.fshape[1]:
            self.fshape = (_fft.next_fast_len(max(self.fshape[0], H + arr.shape[0] - 1), True),
                           _fft.next_fast_len(max(self.fshape[1], W + arr.shape[1] - 1), True))
            self._tf = [_fft.rfft2(t[::-1, ::-1], self.fshape) for t, _ in self._t]
        self._t[k] = (t0, tnorm)
        self._tf[k] = _fft.rfft2(t0[::-1, ::-1], self.fshape)

    def correlate(self, image, which=None):
        """Yield ``(k, C)`` for each template ``k`` in ``which`` (default all).

        ``C`` is the full ``(rows + m - 1, cols + n - 1)`` normalised correlation.
        """
        img, is_int = _as_image(image, "image")
        if img.shape != self.image_shape:
            raise ValueError(
                f"image has shape {img.shape} but the correlator was built for "
                f"{self.image_shape}; all frames must have the same size"
            )
        # not centred: partial (border) windows see the zero padding, as in MATLAB
        af = _fft.rfft2(img.astype(np.float64), self.fshape)
        energy = _LocalEnergy(img, is_int)
        H, W = self.image_shape
        idx = range(len(self._t)) if which is None else which
        for k in idx:
            t0, tnorm = self._t[k]
            m, n = t0.shape
            num = _fft.irfft2(af * self._tf[k], self.fshape)[: H + m - 1, : W + n - 1]
            yield k, _finish(np.ascontiguousarray(num), tnorm, energy.get(m, n))


def normxcorr2(template, image):
    """Normalise-cross-correlate a template with an image, as MATLAB's ``normxcorr2``.

    Parameters
    ----------
    template : (m, n) array_like, real
        Template; any integer or float dtype. Must not be constant and must be no larger
        than ``image`` in either dimension.
    image : (M, N) array_like, real
        Image to search; any integer or float dtype (converted to float64).

    Returns
    -------
    C : (M + m - 1, N + n - 1) ndarray of float64
        Correlation coefficients in [-1, 1]. ``C[i, j]`` correlates the template with the
        image window whose bottom-right pixel is ``image[i, j]`` (rows ``i - m + 1 .. i``,
        columns ``j - n + 1 .. j``, zero-padded outside the image), exactly MATLAB's
        full-size layout shifted to 0-based indices. The template's top-left pixel therefore
        sits at ``(x, y) = (j - n + 1, i - m + 1)`` and its centre at
        ``(j - (n - 1) / 2, i - (m - 1) / 2)``.

    Raises
    ------
    ValueError
        Template larger than the image, constant, or with fewer than 2 pixels; inputs not
        2-D, not real, or with NaN/Inf (MATLAB's input checks).

    Notes
    -----
    Follows MATLAB's ``normxcorr2`` (Image Processing Toolbox), which implements Lewis'
    fast normalised cross-correlation [1]_::

        numerator = xcorr(A, T) - local_sum(A) * sum(T) / mn
        denom     = sqrt(sum((T - mean T)^2)) * sqrt(max(local_sum(A^2) - local_sum(A)^2 / mn, 0))
        C         = numerator / denom   where denom > sqrt(eps(max|denom|)), else 0
        C[|C| - 1 > sqrt(eps(1))] = 0   (numerical backstop)

    Quirks kept from MATLAB: windows of (near-)constant image, i.e. local variance below
    the relative tolerance ``sqrt(eps(max|denom|))``, give 0 rather than NaN, and the
    output covers every partial overlap (size ``image + template - 1``), where windows
    hanging over the border are padded with zeros, so coefficients near the border are
    not those of the visible pixels alone.

    Here the numerator is the FFT correlation of the image with the mean-free template
    (algebraically equal to MATLAB's numerator, with less cancellation), and the
    local sums come from summed-area tables, exact in int64 for integer images. Agreement
    with MATLAB/Octave output is ~1e-12 (tested at 1e-9 on ``../shared/golden``).

    References
    ----------
    .. [1] J. P. Lewis, "Fast normalized cross-correlation", Vision Interface, 1995.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> image = rng.integers(0, 255, size=(21, 23)).astype(np.uint8)
    >>> C = normxcorr2(image[5:12, 8:17], image)
    >>> C.shape
    (27, 31)
    >>> i, j = np.unravel_index(np.argmax(C), C.shape)
    >>> (int(j) - 9 + 1, int(i) - 7 + 1)   # (x, y) of the template's top-left pixel
    (8, 5)
    >>> round(float(C.max()), 12)
    1.0
    """
    tmpl, _ = _as_image(template, "template")
    img, _ = _as_image(image, "image")
    corr = FrameCorrelator([tmpl], img.shape)
    return next(corr.correlate(img))[1]
