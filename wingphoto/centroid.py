"""Sub-pixel marker centres: Crocker & Grier's ``bpass``, ``pkfnd`` and ``cntrd``, ported.

These are faithful ports of the MATLAB particle-tracking routines by Daniel Blair and
Eric Dufresne (after Crocker & Grier's IDL ``bpass.pro`` / ``feature.pro``) that the
thesis used in ``trackcl.m``: ``bpass(I, 1, 10, 20)`` then ``cntrd(filtered, guess, 9)``.
They agree with the MATLAB/Octave originals to ~1e-12 (tested at 1e-9 against
``../shared/golden``), quirks included, but take and return **0-based** pixel coordinates
(``(0, 0)`` is the centre of the top-left pixel, see ``docs/conventions.md``).

References
----------
J. C. Crocker and D. G. Grier, "Methods of digital video microscopy for colloidal
studies", J. Colloid Interface Sci. 179, 298-310 (1996).
D. Blair and E. Dufresne, "The Matlab particle tracking code repository",
http://site.physics.georgetown.edu/matlab/ (``bpass.m``, ``pkfnd.m``, ``cntrd.m``).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

__all__ = ["bpass", "pkfnd", "cntrd", "CntrdResult", "matlab_round"]

logger = logging.getLogger(__name__)


def matlab_round(x):
    """Round half away from zero, as MATLAB's ``round`` (numpy rounds half to even).

    Parameters
    ----------
    x : array_like or float

    Returns
    -------
    ndarray or float
        ``sign(x) * floor(|x| + 0.5)``.

    Examples
    --------
    >>> matlab_round([0.5, 1.5, 2.5, -2.5]).tolist()
    [1.0, 2.0, 3.0, -3.0]
    >>> np.round([0.5, 1.5, 2.5, -2.5]).tolist()
    [0.0, 2.0, 2.0, -2.0]
    """
    a = np.asarray(x, dtype=np.float64)
    out = np.sign(a) * np.floor(np.abs(a) + 0.5)
    return float(out) if out.ndim == 0 else out


def _image2d(image, name="image"):
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array (rows, cols), got shape {arr.shape}")
    if arr.dtype == bool:
        arr = arr.astype(np.uint8)
    if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise ValueError(f"{name} must be a real numeric array, got dtype {arr.dtype}")
    return arr


def bpass(image, lnoise, lobject, threshold=0):
    """Band-pass filter an image for bright markers (Crocker & Grier's ``bpass``).

    Parameters
    ----------
    image : (H, W) array_like
        Image, any integer or float dtype (converted to float64).
    lnoise : float
        Length scale of the pixel noise, px. ``0`` skips the Gaussian (low-pass) step.
    lobject : int
        Integer length a little larger than a marker, px. ``0`` skips the boxcar
        background subtraction (high-pass) step.
    threshold : float, optional
        Pixels of the filtered image below this value are set to 0 (default 0, i.e.
        negative values are clipped; ``-np.inf`` keeps everything).

    Returns
    -------
    filtered : (H, W) ndarray of float64
        ``gauss * image - boxcar * image``, with a border of ``max(lobject,
        ceil(5 * lnoise))`` pixels set to 0 and values below ``threshold`` set to 0.

    Raises
    ------
    ValueError
        ``image`` is not 2-D, or ``lnoise``/``lobject`` are negative.

    Notes
    -----
    Port of Blair & Dufresne's ``bpass.m`` (JWM 6/07 revision, with the ``threshold``
    argument), after Crocker & Grier (1996). Kept as in the original:

    * The Gaussian kernel is ``exp(-(k / (2 lnoise))^2)`` for ``k = -ceil(5 lnoise) ..
      ceil(5 lnoise)``, normalised to unit sum; its standard deviation is therefore
      ``sqrt(2) * lnoise``, not ``lnoise``.
    * The boxcar is ``2 round(lobject) + 1`` pixels wide with weights summing to 1
      (``round`` is MATLAB's, half away from zero: :func:`matlab_round`).
    * Both are applied separably with zero padding (``conv2(..., 'same')``), so values
      near the border are biased; the original hides that by zeroing a border of
      ``lzero = max(lobject, ceil(5 lnoise))`` rows and columns on every side. MATLAB
      would fail on a non-integer ``lzero``; here it is rounded.
    * ``filtered[filtered < threshold] = 0``: with the default ``threshold=0`` this
      clips the negative ringing that would otherwise bias ``cntrd``.

    Examples
    --------
    >>> yy, xx = np.mgrid[:40, :45]
    >>> img = 200 * np.exp(-((xx - 20.3) ** 2 + (yy - 18.6) ** 2) / 8)
    >>> f = bpass(img, 1, 7)
    >>> f.shape, float(f[:7].max()), bool(f[19, 20] > 0)
    ((40, 45), 0.0, True)
    """
    a = _image2d(image).astype(np.float64)
    if not (np.isfinite(lnoise) and np.isfinite(lobject)) or np.isnan(threshold):
        raise ValueError(f"lnoise, lobject must be finite lengths (px) and threshold a number, got {lnoise}, "
                         f"{lobject}, {threshold}")
    if lnoise < 0 or lobject < 0:
        raise ValueError(f"lnoise and lobject must be >= 0, got {lnoise}, {lobject}")
    if lnoise == 0:
        gauss = np.ones(1)
    else:
        half = math.ceil(5 * lnoise)
        k = np.arange(-half, half + 1, dtype=np.float64)
        gauss = np.exp(-((k / (2.0 * lnoise)) ** 2))
        gauss = gauss / gauss.sum()
    # MATLAB: conv2(image', g', 'same') then conv2(gconv', g', 'same'): along x, then y
    gconv = ndimage.correlate1d(a, gauss, axis=1, mode="constant", cval=0.0)
    gconv = ndimage.correlate1d(gconv, gauss, axis=0, mode="constant", cval=0.0)
    if lobject:
        w = int(matlab_round(lobject))
        box = np.ones(2 * w + 1) / (2 * w + 1)
        bconv = ndimage.correlate1d(a, box, axis=1, mode="constant", cval=0.0)
        bconv = ndimage.correlate1d(bconv, box, axis=0, mode="constant", cval=0.0)
        filtered = gconv - bconv
    else:
        filtered = gconv
    lzero = int(matlab_round(max(lobject, math.ceil(5 * lnoise))))
    if lzero > 0:
        filtered[:lzero, :] = 0
        filtered[-lzero:, :] = 0
        filtered[:, :lzero] = 0
        filtered[:, -lzero:] = 0
    filtered[filtered < threshold] = 0
    return filtered


def pkfnd(image, threshold, sz=None):
    """Find local maxima to the pixel (Blair & Dufresne's ``pkfnd``).

    Parameters
    ----------
    image : (H, W) array_like
        Usually the output of :func:`bpass`.
    threshold : float
        Only pixels strictly brighter than this can be peaks.
    sz : int, optional
        A little more than a marker's diameter, px. When given, peaks within ``sz`` of
        the border are dropped and, of peaks closer together than about ``sz / 2``, only
        the brightest is kept. ``None`` skips both steps.

    Returns
    -------
    peaks : (M, 2) ndarray of int64
        ``(x, y)`` pixel positions (0-based), ordered as MATLAB's ``find`` (by column x,
        then row y). ``(0, 2)`` when nothing is found.

    Notes
    -----
    Port of ``pkfnd.m`` (ERD 10/2006 revision), after the ``lmx`` step of Crocker &
    Grier's ``feature.pro``. Rules kept as in the original:

    * A peak is a pixel ``> threshold`` that is ``>=`` all 8 neighbours (so every pixel
      of a flat-topped maximum is a peak before the ``sz`` step); the outermost rows and
      columns are never peaks.
    * With ``sz``: in 1-based coordinates a peak is kept when ``sz < row < H - sz`` and
      ``sz < col < W - sz``. Then, visiting peaks in column-major order, each looks at an
      asymmetric box ``row - floor(sz/2) .. row + floor(sz/2) + 1`` (same for columns)
      of a peaks-only image, keeps the brightest (first in column-major order on ties),
      and zeroes the rest; the survivors with value ``> 0`` are returned.
    * The original fails when ``sz`` is omitted and two or more peaks exist; here
      ``sz=None`` simply returns all local maxima.

    Examples
    --------
    >>> img = np.zeros((21, 23))
    >>> img[5, 7] = 3.0; img[14, 16] = 5.0; img[14, 17] = 4.0
    >>> pkfnd(img, 1).tolist()
    [[7, 5], [16, 14]]
    """
    im = _image2d(image)
    if np.isnan(threshold):
        raise ValueError(f"threshold must be a grey level, got {threshold}")
    if sz is not None and not (np.isfinite(sz) and sz >= 1):
        raise ValueError(f"sz must be a marker size >= 1 px (a little more than its diameter), got {sz}")
    nr, nc = im.shape
    if nr < 3 or nc < 3:
        return np.zeros((0, 2), dtype=np.int64)
    c = im[1:-1, 1:-1]
    is_peak = c > threshold
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                is_peak &= c >= im[1 + dr: nr - 1 + dr, 1 + dc: nc - 1 + dc]
    # column-major order, as MATLAB's find
    cols, rows = np.nonzero(is_peak.T)
    rows = rows + 1
    cols = cols + 1
    if sz is not None and rows.size:
        # 1-based test of the original: sz < r1 < nr - sz, i.e. r0 + 1
        keep = ((rows + 1 > sz) & (rows + 1 < nr - sz)
                & (cols + 1 > sz) & (cols + 1 < nc - sz))
        rows, cols = rows[keep], cols[keep]
    if sz is not None and rows.size > 1:
        h = int(math.floor(sz / 2))
        tmp = np.zeros(im.shape, dtype=np.result_type(im.dtype, np.float64))
        tmp[rows, cols] = im[rows, cols]
        for r, cc in zip(rows.tolist(), cols.tolist()):
            r0, r1 = r - h, r + h + 2
            c0, c1 = cc - h, cc + h + 2
            if r0 < 0 or c0 < 0 or r1 > nr or c1 > nc:
                raise ValueError(
                    f"pkfnd: the sz={sz} box around peak (x={cc}, y={r}) leaves the image; "
                    "MATLAB's pkfnd fails here too: use a smaller sz"
                )
            roi = tmp[r0:r1, c0:c1]
            # MATLAB max(max(roi)) with first-occurrence ties, in column-major order
            flat = roi.T.ravel()
            k = int(np.argmax(flat))
            mv = flat[k]
            jj, ii = divmod(k, roi.shape[0])
            roi[:] = 0
            roi[ii, jj] = mv
        cols, rows = np.nonzero((tmp > 0).T)
    return np.column_stack([cols, rows]).astype(np.int64).reshape(-1, 2)


@dataclass(frozen=True)
class CntrdResult:
    """What :func:`cntrd` returns.

    Attributes
    ----------
    table : (M, 4) ndarray of float64
        One row per kept peak: x, y (px, 0-based), integrated brightness (sum of the
        masked window), squared radius of gyration (px^2).
    kept : (N,) ndarray of bool
        Which input peaks were kept (the rest were within ``1.5 * sz`` of the border).
    """

    table: np.ndarray
    kept: np.ndarray

    @property
    def xy(self):
        """(M, 2) sub-pixel centres of the kept peaks."""
        return self.table[:, :2]

    def full(self):
        """(N, 4) table aligned with the input peaks, NaN rows for dropped peaks."""
        out = np.full((self.kept.size, 4), np.nan)
        out[self.kept] = self.table
        return out

    def summary(self):
        """One-line description."""
        return (f"cntrd: {int(self.kept.sum())} of {self.kept.size} peaks kept "
                f"({int((~self.kept).sum())} dropped near the border)")


_MASKS = {}


def _cntrd_mask(sz):
    """The original's window: 2r x 2r, r = (sz + 1) / 2, disc of radius r centred at r - 1/2."""
    if sz not in _MASKS:
        r = (sz + 1) / 2
        m = int(round(2 * r))
        cent = (m - 1) / 2
        x = np.arange(m) - cent
        dst = np.sqrt(x[:, None] ** 2 + x[None, :] ** 2)
        msk = (dst < r).astype(np.float64)
        dst2 = msk * dst**2
        xl = np.tile(np.arange(1, m + 1, dtype=np.float64), (m, 1))
        for a in (msk, dst2, xl):
            a.setflags(write=False)
        _MASKS[sz] = (r, m, msk, dst2, xl)
    return _MASKS[sz]


def cntrd(image, peaks, sz):
    """Refine integer peak guesses to sub-pixel centroids (Blair & Dufresne's ``cntrd``).

    Parameters
    ----------
    image : (H, W) array_like
        Bright markers on a dark background, usually :func:`bpass` output.
    peaks : (N, 2) array_like of int
        Pixel guesses ``(x, y)``, 0-based (e.g. from :func:`pkfnd`).
    sz : int
        Odd window diameter in px (the thesis used 9; the original recommends the bpass
        ``lobject`` plus 2).

    Returns
    -------
    CntrdResult
        ``.table`` (M, 4): x, y, integrated brightness, squared radius of gyration, for
        the ``M`` kept peaks in input order; ``.kept`` (N,) bool marks which input peaks
        were kept. ``.full()`` gives an (N, 4) table with NaN rows for the dropped ones.

    Raises
    ------
    ValueError
        ``peaks`` not (N, 2), not integer-valued or NaN; ``image`` not 2-D; ``sz`` even
        (the original warns, then fails to index with the half-integer radius).

    Warns
    -----
    A ``logging`` warning (logger ``wingphoto.centroid``) names the peaks dropped near the
    border, and one is issued when ``peaks`` is empty (the original's ``warning``).

    Notes
    -----
    Port of ``cntrd.m`` (ERD, JWM 6/07 revision). Quirks kept from the original:

    * **Silent border drop.** Peaks with (1-based) ``x <= 1.5 sz`` or
      ``x >= W - 1.5 sz`` (same for y with H) are removed without notice; in 0-based
      terms a peak is kept when ``1.5 sz - 1 < x < W - 1.5 sz - 1``. This port reports
      them through ``kept`` and a log warning.
    * **Half-pixel mask offset.** With ``r = (sz + 1) / 2`` the window is an even
      ``2r x 2r`` block covering ``x - r + 1 .. x + r`` (0-based: same, shifted), and the
      circular mask ``dst < r`` is centred in that block, i.e. at ``(x + 1/2, y + 1/2)``
      rather than on the guess. Brightness centred on the guess is reported there
      unbiased, but the mask reaches half a pixel further right/down than left/up, so a
      marker not fully inside the mask is pulled towards ``+x, +y``.
    * The squared radius of gyration is measured from the mask centre
      (``x + 1/2, y + 1/2``), not from the centroid.
    * A window summing to 0 gives NaN x, y (MATLAB's 0/0).
    * MATLAB rounds half away from zero (:func:`matlab_round`), numpy half to even: round
      sub-pixel guesses with :func:`matlab_round` (or ``np.ceil``, as ``trackcl.m`` did)
      before calling, never with ``np.round``, to get the original's windows.

    Examples
    --------
    >>> yy, xx = np.mgrid[:41, :43]
    >>> img = np.exp(-((xx - 20.3) ** 2 + (yy - 18.6) ** 2) / 4)
    >>> res = cntrd(img, [[20, 19]], 9)
    >>> np.round(res.xy, 2).tolist(), res.kept.tolist()   # truth (20.3, 18.6)
    ([[20.3, 18.61]], [True])
    """
    return _cntrd(image, peaks, sz, log=True)


def _cntrd(image, peaks, sz, *, log):
    """:func:`cntrd`; ``log=False`` leaves reporting the border drop to the caller."""
    im = _image2d(image)
    if int(sz) != sz or sz < 1 or sz % 2 == 0:
        # the original warns, then fails indexing with the half-integer r = (sz + 1) / 2
        raise ValueError(f"sz must be a positive odd integer (like bpass), got {sz}")
    pk = np.asarray(peaks, dtype=np.float64)
    if pk.size == 0:
        if log:
            logger.warning("cntrd: no peaks given (check the pkfnd threshold)")
        return CntrdResult(np.zeros((0, 4)), np.zeros(0, dtype=bool))
    if pk.ndim == 1 and pk.shape == (2,):
        pk = pk[None, :]
    if pk.ndim != 2 or pk.shape[1] != 2:
        raise ValueError(f"peaks must be an (N, 2) array of (x, y), got shape {pk.shape}")
    if not np.all(np.isfinite(pk)):
        raise ValueError("peaks contain NaN or Inf; drop those rows before calling cntrd")
    if not np.all(pk == np.floor(pk)):
        raise ValueError(
            "peaks must be integer pixel positions (MATLAB indexes the image with them); "
            "round them first, e.g. np.ceil(xy) as trackcl.m or matlab_round(xy)"
        )
    r, m, msk, dst2, xl = _cntrd_mask(sz)
    yl = xl.T
    nr, nc = im.shape
    x1 = pk[:, 0] + 1  # 1-based, as the original tests them
    y1 = pk[:, 1] + 1
    kept = ((y1 > 1.5 * sz) & (y1 < nr - 1.5 * sz)
            & (x1 > 1.5 * sz) & (x1 < nc - 1.5 * sz))
    if log and not kept.all():
        bad = np.flatnonzero(~kept)
        logger.warning(
            "cntrd dropped %d of %d peaks within 1.5*sz=%.1f px of the image border "
            "(indices %s)", bad.size, kept.size, 1.5 * sz, bad.tolist()[:20])
    ri = int(round(r))
    out = np.empty((int(kept.sum()), 4))
    imf = im if im.dtype == np.float64 else None
    for row, k in enumerate(np.flatnonzero(kept)):
        x0 = int(pk[k, 0])
        y0 = int(pk[k, 1])
        # 1-based mx-r+1 .. mx+r  ->  0-based x0-r+1 .. x0+r (inclusive)
        win = (imf if imf is not None else im)[y0 - ri + 1: y0 + ri + 1,
                                                x0 - ri + 1: x0 + ri + 1]
        tmp = msk * win
        norm = tmp.sum()
        with np.errstate(invalid="ignore", divide="ignore"):
            xavg = (tmp * xl).sum() / norm
            yavg = (tmp * yl).sum() / norm
            rg = (tmp * dst2).sum() / norm
        out[row] = (x0 + xavg - r, y0 + yavg - r, norm, rg)
    return CntrdResult(out, kept)
