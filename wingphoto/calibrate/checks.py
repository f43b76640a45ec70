"""Argument checks shared by the calibration stages, and the board's object points."""
from __future__ import annotations


import numpy as np





_MIN_VIEWS = 3
_MIN_POINTS = 6  # corners per view (a pose has 6 unknowns; the homography init needs 4)
_PM = "\u00b1"  # the toolbox prints char(177), the plus-minus sign
_NOTE = "Note: The numerical errors are approximately three times the standard deviations (for reference)."



# ============================================================== small validators
def _check_pattern_size(pattern_size):
    try:
        cols, rows = (int(v) for v in pattern_size)
        ok = (cols, rows) == tuple(pattern_size)
    except (TypeError, ValueError):
        ok = False
    if not ok or cols < 3 or rows < 3:
        raise ValueError(
            f"pattern_size must be (inner corners per row, inner corners per column) as two "
            f"integers >= 3, e.g. (9, 6) for a board of 10 x 7 squares; got {pattern_size!r}"
        )
    return cols, rows


def _check_square_size(square_size):
    sq = np.asarray(square_size, dtype=np.float64).reshape(-1)
    if sq.size == 1:
        sq = np.repeat(sq, 2)
    if sq.size != 2 or not np.all(np.isfinite(sq)) or np.any(sq <= 0):
        raise ValueError(
            f"square_size must be the positive side of a square in mm (or (dX, dY)), got {square_size!r}"
        )
    if np.any(sq < 1e-3) or np.any(sq > 1e5):  # 1 um .. 100 m: outside it is a unit mistake
        raise ValueError(
            f"square_size {square_size!r} mm is outside 0.001..100000 mm; give the side of one board square "
            "in mm (e.g. 30)"
        )
    return float(sq[0]), float(sq[1])


def _check_window(window, shape=None):
    """The corner refinement half-window: an integer >= 0 that fits in the image."""
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)):
        if not (isinstance(window, (float, np.floating)) and float(window).is_integer()):
            raise ValueError(f"window must be a whole number of pixels >= 0 (0 skips the refinement), got {window!r}")
    window = int(window)
    limit = None if shape is None else max(0, (min(shape[:2]) - 1) // 4)
    if window < 0 or (limit is not None and window > limit):
        raise ValueError(
            f"window must be a half-size in pixels between 0 and {limit if limit is not None else 'a quarter of the image'}"
            f" (default 7, the toolbox's wintx), got {window}"
        )
    return window


def _index_range(sel, n, name):
    """Normalise a row/column selection to a ``range`` of contiguous board indices."""
    if sel is None:
        return range(n)
    if isinstance(sel, slice):
        r = range(*sel.indices(n))
        if r.step != 1:
            raise ValueError(f"{name} must be a contiguous block (step 1), got {sel!r}")
    else:
        try:
            idx = sorted({int(i) for i in sel})
        except TypeError:
            raise ValueError(
                f"{name} must be a slice, a range or a sequence of board indices, got {sel!r}"
            ) from None
        if not idx:
            raise ValueError(f"{name} selects no corners")
        if idx[0] < 0 or idx[-1] >= n:
            raise ValueError(f"{name} indices must lie in 0..{n - 1}, got {idx[0]}..{idx[-1]}")
        r = range(idx[0], idx[-1] + 1)
        if len(r) != len(idx):
            raise ValueError(f"{name} must be a contiguous block of indices, got {idx}")
    if len(r) == 0:
        raise ValueError(f"{name}={sel!r} selects no corners of the {n} available")
    return r


def board_points(pattern_size, square_size):
    """Return the 3D board coordinates of the inner corners, in the canonical order.

    Parameters
    ----------
    pattern_size : (2,) tuple of int
        (inner corners per row, inner corners per column), as OpenCV's ``patternSize``.
    square_size : float or (2,) array_like
        Side of a square in mm (or ``(dX, dY)`` for rectangular squares).

    Returns
    -------
    X : (N, 3) ndarray of float64
        ``N = n_cols * n_rows`` rows ``(c * dX, r * dY, 0)`` in mm, corner ``k`` at
        row ``r = k // n_cols`` and column ``c = k % n_cols`` (OpenCV's
        ``objectPoints`` layout), as returned by :func:`find_corners`.

    Examples
    --------
    >>> board_points((3, 3), 30.0)[:4].tolist()
    [[0.0, 0.0, 0.0], [30.0, 0.0, 0.0], [60.0, 0.0, 0.0], [0.0, 30.0, 0.0]]
    """
    cols, rows = _check_pattern_size(pattern_size)
    dx, dy = _check_square_size(square_size)
    c, r = np.meshgrid(np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64))
    return np.column_stack([c.ravel() * dx, r.ravel() * dy, np.zeros(cols * rows)])

