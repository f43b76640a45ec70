"""Checkerboard corner detection: OpenCV's detector, sub-pixel refinement, partial boards, orientation."""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .checks import _check_pattern_size, _check_window, _index_range

logger = logging.getLogger(__name__)


# ============================================================== corner detection
@dataclass(frozen=True)
class CornerDetection:
    """Result of :func:`find_corners` for one image.

    Attributes
    ----------
    found : bool
        Whether the board (or the requested part of it) was found. ``bool(detection)``
        is the same.
    corners : (N, 2) ndarray of float64 or None
        Pixel (x, y) of the ``N = n_cols * n_rows`` inner corners in the canonical order
        (see the module notes), origin at the centre of the top-left pixel; NaN rows for
        corners outside a requested sub-rectangle; None when not found.
    pattern_size : tuple of int
        (n_cols, n_rows) of the whole board.
    image_size : tuple of int
        (width, height) of the image in pixels.
    name : str
        The image's file name or label, used in messages.
    message : str
        What happened, e.g. ``"board not found in left03.jpg"`` or how the corner order
        was decided.
    """

    found: bool
    corners: np.ndarray | None
    pattern_size: tuple
    image_size: tuple
    name: str
    message: str

    def __post_init__(self):
        if self.corners is not None:
            c = np.array(self.corners, dtype=np.float64)
            c.setflags(write=False)
            object.__setattr__(self, "corners", c)

    def __bool__(self):
        return bool(self.found)


def _read_gray(image, name):
    """Return a 2-D grayscale array and a label for an image array or file path."""
    import cv2

    if isinstance(image, (str, os.PathLike)):
        path = Path(image)
        if not path.is_file():
            raise FileNotFoundError(f"{name}: image file {str(path)!r} does not exist; check the path")
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError(f"{name}: could not decode {str(path)!r} as an image (is it a picture file?)")
        if img.ndim == 3:
            code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
            img = cv2.cvtColor(img, code)
        return img, path.name
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] in (3, 4):
        arr = arr[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])  # RGB arrays
    if arr.ndim != 2 or arr.shape[0] < 8 or arr.shape[1] < 8:
        raise ValueError(
            f"{name} must be a 2-D grayscale image (H, W), an (H, W, 3) colour image or a file "
            f"path; got an array of shape {arr.shape}"
        )
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise ValueError(f"{name} must be a numeric image, got dtype {arr.dtype}")
    return arr, None


def _to_uint8(img):
    if img.dtype == np.uint8:
        return np.ascontiguousarray(img)
    f = np.asarray(img, dtype=np.float64)
    finite = np.isfinite(f)
    if not finite.any():
        return np.zeros(f.shape, np.uint8)
    lo, hi = np.min(f[finite]), np.max(f[finite])
    scale = 255.0 / (hi - lo) if hi > lo else 0.0
    out = np.where(finite, (f - lo) * scale, 0.0)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def _detect_grid(gray8, size, method):
    """OpenCV detection of a (cols, rows) pattern -> (rows, cols, 2) grid or None."""
    import cv2

    cols, rows = size
    methods = {"auto": ("classic", "sb"), "classic": ("classic",), "sb": ("sb",)}[method]
    for m in methods:
        try:
            if m == "classic":
                flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
                ok, c = cv2.findChessboardCorners(gray8, (cols, rows), flags=flags)
            else:
                ok, c = cv2.findChessboardCornersSB(gray8, (cols, rows), flags=cv2.CALIB_CB_EXHAUSTIVE)
        except cv2.error as exc:  # pragma: no cover - OpenCV rejects odd inputs
            logger.debug("OpenCV %s detector failed: %s", m, exc)
            continue
        if ok and c is not None and len(c) == cols * rows:
            return np.asarray(c, dtype=np.float64).reshape(rows, cols, 2)
    return None


def _refine_grid(gray, grid, window):
    """cornerSubPix with half-window ``window`` (the toolbox's wintx = winty)."""
    import cv2

    if not window:
        return grid
    img = np.asarray(gray, dtype=np.float32)
    pts = grid.reshape(-1, 1, 2).astype(np.float32)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    pts = cv2.cornerSubPix(img, pts, (int(window), int(window)), (-1, -1), crit)
    return pts.reshape(grid.shape).astype(np.float64)


def _orientation_cross(g):
    dc = np.mean(g[:, 1:] - g[:, :-1], axis=(0, 1))
    dr = np.mean(g[1:, :] - g[:-1, :], axis=(0, 1))
    return dc[0] * dr[1] - dc[1] * dr[0]


def _orient_grid(grid, gray8, r0=0, c0=0):
    """Reorder a detected (rows, cols, 2) grid into the canonical order (module notes).

    ``(r0, c0)`` is the position of the grid's first corner on the whole board (non-zero
    for a sub-rectangle), which decides the expected colour of its first square.
    """
    import cv2

    nr, nc = grid.shape[:2]
    cands = []
    bases = [grid, grid.transpose(1, 0, 2)] if nr == nc else [grid]
    for g0 in bases:
        for fr in (1, -1):
            for fc in (1, -1):
                cands.append(np.ascontiguousarray(g0[::fr, ::fc]))
    cands = [g for g in cands if _orientation_cross(g) > 0]
    blur = cv2.blur(gray8, (3, 3)).astype(np.float64)
    h, w = blur.shape
    q = (r0 + c0) % 2
    scores = []
    for g in cands:
        centres = 0.25 * (g[:-1, :-1] + g[:-1, 1:] + g[1:, :-1] + g[1:, 1:])
        xs = np.clip(np.rint(centres[..., 0]).astype(int), 0, w - 1)
        ys = np.clip(np.rint(centres[..., 1]).astype(int), 0, h - 1)
        vals = blur[ys, xs]
        parity = np.add.outer(np.arange(nr - 1), np.arange(nc - 1)) % 2
        # light squares minus the squares that should be dark: > 0 when this order is right
        scores.append((np.mean(vals[parity != q]) - np.mean(vals[parity == q]), np.ptp(vals)))
    how = "position"
    good = [g for g, (s, span) in zip(cands, scores) if s > max(2.0, 0.2 * span)]
    if good and len(good) < len(cands):
        cands, how = good, "colour"
    if len(cands) > 1:
        cands = sorted(cands, key=lambda g: g[0, 0, 0] + g[0, 0, 1])
        how = how + "+position" if how == "colour" else how
    return cands[0], how


def find_corners(image, pattern_size, *, rows=None, cols=None, window=7, method="auto", name=None):
    """Find the inner corners of a checkerboard with sub-pixel accuracy.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) array_like, or str or Path
        Grayscale (any dtype) or RGB image, or an image file. Never modified.
    pattern_size : (2,) tuple of int
        (inner corners per row, inner corners per column) of the whole board, as
        OpenCV's ``patternSize``, e.g. (9, 6).
    rows, cols : slice, range or sequence of int, optional
        Restrict the result to a contiguous sub-rectangle of the board (board row and
        column indices in the canonical order): corners outside it are NaN. Use it for
        a board partly hidden (the pan-tilt frame) or out of focus. When the whole board
        cannot be found, the sub-rectangle (at least 3 x 3 corners) is detected on its
        own and placed on the board by its square colours, so its corners keep their
        whole-board identities; the sub-rectangle must then be exactly the visible part.
    window : int, optional
        Half-size of the sub-pixel refinement window (``cv2.cornerSubPix`` with
        ``winSize=(window, window)``, a ``2 * window + 1`` square). Default 7, the
        toolbox's ``wintx = winty = 7`` used for the thesis and the toolbox's example.
        0 skips the refinement.
    method : {"auto", "classic", "sb"}, optional
        OpenCV detector: ``findChessboardCorners`` ("classic"),
        ``findChessboardCornersSB`` ("sb"), or the classic one then SB ("auto").
    name : str, optional
        Label for messages (default: the file name, or "image").

    Returns
    -------
    detection : CornerDetection
        ``.found``, ``.corners`` (N, 2) in the canonical order or None, ``.message``.
        A board that is not found is a result with ``found=False``, not an exception.

    Raises
    ------
    FileNotFoundError
        If ``image`` is a path that does not exist.
    ValueError
        For an invalid ``pattern_size``, ``rows``/``cols`` or image array.

    Notes
    -----
    The canonical order (module notes) puts the same physical corner first in every
    view of an odd-by-even board, including a view where the board appears upside
    down, so left and right detections correspond corner by corner.
    """
    import cv2  # noqa: F401  (fail early with a clear ImportError)

    ncols, nrows = _check_pattern_size(pattern_size)
    if method not in ("auto", "classic", "sb"):
        raise ValueError(f"method must be 'auto', 'classic' or 'sb', got {method!r}")
    window = _check_window(window)
    row_idx = _index_range(rows, nrows, "rows")
    col_idx = _index_range(cols, ncols, "cols")
    gray, fname = _read_gray(image, "image")
    window = _check_window(window, gray.shape)
    label = name or fname or "image"
    h, w = gray.shape
    size = (w, h)
    gray8 = _to_uint8(gray)
    restricted = len(row_idx) < nrows or len(col_idx) < ncols

    grid = _detect_grid(gray8, (ncols, nrows), method)
    r0 = c0 = 0
    part = ""
    if grid is None and restricted:
        sub = (len(col_idx), len(row_idx))
        if min(sub) < 3:
            return CornerDetection(
                False, None, (ncols, nrows), size, label,
                f"board not found in {label}, and the sub-rectangle rows {row_idx.start}-"
                f"{row_idx.stop - 1}, cols {col_idx.start}-{col_idx.stop - 1} is too small to be "
                "detected on its own (needs at least 3 x 3 corners)",
            )
        grid = _detect_grid(gray8, sub, method)
        r0, c0 = row_idx.start, col_idx.start
        part = f" (sub-rectangle {sub[0]} x {sub[1]} detected on its own)"
    if grid is None:
        what = f"{ncols} x {nrows} board" if not part and not restricted else "board (or its sub-rectangle)"
        return CornerDetection(
            False, None, (ncols, nrows), size, label,
            f"{what} not found in {label}: check pattern_size=({ncols}, {nrows}) counts inner "
            "corners, and that the board is whole, in focus and not overexposed",
        )
    grid = _refine_grid(gray, grid, window)
    grid, how = _orient_grid(grid, gray8, r0, c0)
    full = np.full((nrows, ncols, 2), np.nan)
    full[r0 : r0 + grid.shape[0], c0 : c0 + grid.shape[1]] = grid
    if restricted:
        keep = np.zeros((nrows, ncols), bool)
        keep[row_idx.start : row_idx.stop, col_idx.start : col_idx.stop] = True
        full[~keep] = np.nan
    n = int(np.isfinite(full[..., 0]).sum())
    msg = f"found {n} corners in {label}{part}; order fixed by {how}"
    if how == "position":
        msg += " (board looks the same after a half turn: first corner nearest the image's top-left)"
    return CornerDetection(True, full.reshape(-1, 2), (ncols, nrows), size, label, msg)

