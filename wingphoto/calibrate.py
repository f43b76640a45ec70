"""Checkerboard calibration of one camera or a stereo rig, compatible with Bouguet's toolbox.

The steps follow the Camera Calibration Toolbox for Matlab (Bouguet) that the thesis
used: extract the grid corners (:func:`find_corners`, the toolbox's "Extract grid
corners"), calibrate each camera (:func:`calibrate_camera`, "Calibration"), analyse the
errors and suppress bad views (:meth:`CameraCalibration.suppress`,
:func:`suggest_suppress` and the figures in :mod:`wingphoto.plots`), then calibrate the
rig (:func:`calibrate_stereo`, the toolbox's ``stereo_gui``).

Parameters keep the toolbox's names (``fc, cc, alpha_c, kc``, ``om, T``; see
``docs/conventions.md``) and its definitions of the reported numbers:

* ``pixel_error`` (the toolbox's ``err_std``): per-axis standard deviation of the
  reprojection residuals ``observed - projected`` over every used corner;
* ``uncertainty`` (the toolbox's ``fc_error`` etc.): ``3 * sqrt(diag((J^T J)^-1)) * sigma``
  with ``J`` the Jacobian of the residuals at the solution with respect to every
  estimated parameter (intrinsics and the per-view board poses) and ``sigma`` the
  standard deviation of all residual components (``std(ex(:))``), i.e. about three
  standard deviations.

The refinement is a least-squares fit of the toolbox's camera model
(:meth:`wingphoto.camera.Camera.project`) by :func:`scipy.optimize.least_squares`,
started from OpenCV's Zhang initialisation (``cv2.calibrateCamera``).

Board frame and corner order
----------------------------
``pattern_size = (n_cols, n_rows)`` counts *inner* corners as OpenCV does (e.g. (9, 6)).
Corners are returned row by row, ``n_cols`` per row; corner ``k`` has board coordinates
``(k % n_cols * dX, k // n_cols * dY, 0)`` mm (:func:`board_points`). The order is chosen
from the board itself, so that the same physical corner comes first in every view:

1. the board axes appear right-handed in the image (walking along a row, the next row
   lies clockwise, as image x to image y) -- true of any printed board seen from the
   front, so it removes the mirror ambiguity;
2. the square between corners 0, 1, ``n_cols`` and ``n_cols + 1`` is the *dark* one.
   When ``n_cols + n_rows`` is odd (e.g. 9 x 6) the board's two ends differ in colour
   and this fixes the 180 degree ambiguity, whatever the board's orientation in the
   image;
3. on a board that looks the same after a half turn (``n_cols + n_rows`` even) the
   remaining choice is the one whose first corner is nearest the image's top-left
   corner (smallest x + y). Such boards are only consistent between the two cameras
   of a rig if both see the board in a similar orientation; prefer an odd/even board.
"""
from __future__ import annotations

import dataclasses
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from .camera import Camera, StereoRig, rodrigues

__all__ = [
    "CornerDetection",
    "find_corners",
    "board_points",
    "CameraCalibration",
    "calibrate_camera",
    "StereoCalibration",
    "RIG_PARAMETER_NAMES",
    "calibrate_stereo",
    "suggest_suppress",
]

logger = logging.getLogger(__name__)

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


# ============================================================== projection model
def _rodrigues_batch(om):
    """(V, 3) rotation vectors -> (V, 3, 3) matrices (same formula as ``rodrigues``)."""
    om = np.asarray(om, dtype=np.float64).reshape(-1, 3)
    theta = np.linalg.norm(om, axis=1)
    small = theta < np.finfo(float).eps
    t = np.where(small, 1.0, theta)
    w = om / t[:, None]
    z = np.zeros_like(theta)
    wx = np.stack(
        [
            np.stack([z, -w[:, 2], w[:, 1]], axis=1),
            np.stack([w[:, 2], z, -w[:, 0]], axis=1),
            np.stack([-w[:, 1], w[:, 0], z], axis=1),
        ],
        axis=1,
    )
    c, s = np.cos(theta)[:, None, None], np.sin(theta)[:, None, None]
    R = c * np.eye(3) + s * wx + (1.0 - c) * w[:, :, None] * w[:, None, :]
    R[small] = np.eye(3)
    return R


def _project(intr, Xc):
    """Project camera-frame points with the 10 toolbox intrinsics (as ``Camera.project``)."""
    fc1, fc2, cc1, cc2, alpha, k1, k2, p1, p2, k3 = intr
    x = Xc[:, 0] / Xc[:, 2]
    y = Xc[:, 1] / Xc[:, 2]
    r2 = x * x + y * y
    radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    xd = radial * x + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = radial * y + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.column_stack([fc1 * (xd + alpha * yd) + cc1, fc2 * yd + cc2])


def _transform(R, T, vid, obj):
    """Board points of views ``vid`` into the camera frame: R[v] X + T[v]."""
    return np.einsum("mij,mj->mi", R[vid], obj) + T[vid]


def _intrinsics_vector(cam):
    return np.concatenate([cam.fc, cam.cc, [cam.alpha_c], cam.kc])


def _camera_from_vector(v, image_size):
    return Camera(fc=v[0:2], cc=v[2:4], alpha_c=v[4], kc=v[5:10], image_size=image_size)


@dataclass(frozen=True)
class _Estimate:
    """Which intrinsics are estimated (the toolbox's est_* switches)."""

    skew: bool = False
    k3: bool = False
    tangential: bool = True
    principal_point: bool = True
    aspect_ratio: bool = True

    @property
    def free(self):
        t, c = self.tangential, self.principal_point
        return np.array([True, self.aspect_ratio, c, c, self.skew, True, True, t, t, self.k3])

    def unpack(self, p, base):
        out = base.copy()
        out[self.free] = p
        if not self.aspect_ratio:
            out[1] = out[0]
        return out

    def as_dict(self):
        """The toolbox's switches: est_fc, est_aspect_ratio, center_optim, est_alpha, est_dist."""
        return {
            "est_fc": np.array([1, 1]),
            "est_aspect_ratio": int(self.aspect_ratio),
            "center_optim": int(self.principal_point),
            "est_alpha": int(self.skew),
            "est_dist": np.array([1, 1, int(self.tangential), int(self.tangential), int(self.k3)]),
        }


def _fd_jacobian(fun, x, groups, rows_of, f0_size):
    """Central-difference Jacobian using the block structure of the problem.

    ``groups`` are lists of columns that never affect the same residual (one board pose
    parameter of every view), so each group costs two evaluations of ``fun``;
    ``rows_of[j]`` is the slice of residuals column ``j`` affects.
    """
    J = np.zeros((f0_size, x.size))
    step = np.cbrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x))
    for cols in groups:
        xp = x.copy()
        xm = x.copy()
        xp[cols] += step[cols]
        xm[cols] -= step[cols]
        df = fun(xp) - fun(xm)
        for j in cols:
            r = rows_of[j]
            J[r, j] = df[r] / (xp[j] - xm[j])
    return J


def _solve(fun, x0, groups, rows_of, m):
    def jac(x):
        return _fd_jacobian(fun, x, groups, rows_of, m)

    sol = least_squares(
        fun, x0, jac=jac, method="lm", x_scale="jac", ftol=1e-12, xtol=1e-12, gtol=1e-12,
        max_nfev=200,
    )
    if not sol.success:  # pragma: no cover - ill-posed input
        logger.warning("least-squares refinement stopped: %s", sol.message)
    logger.debug("least_squares: %d parameters, %d evaluations, %d Jacobians, cost %.6g -> %.6g",
                 x0.size, sol.nfev, sol.njev, 0.5 * np.sum(fun(x0) ** 2), sol.cost)
    return sol.x, jac(sol.x)


def _covariance(J):
    """(J^T J)^-1, with column scaling for conditioning."""
    d = np.linalg.norm(J, axis=0)
    d[d == 0] = 1.0
    Js = J / d
    try:
        inv = np.linalg.inv(Js.T @ Js)
    except np.linalg.LinAlgError:
        inv = np.linalg.pinv(Js.T @ Js)
    return inv / np.outer(d, d)


def _std(a, axis=None):
    a = np.asarray(a, dtype=np.float64)
    n = a.size if axis is None else a.shape[axis]
    if n < 2:
        return np.full(() if axis is None else a.shape[1 - axis], np.nan)
    return np.std(a, axis=axis, ddof=1)  # MATLAB's std normalises by n - 1


# ============================================================== gathering the views
@dataclass
class _View:
    name: str
    corners: np.ndarray | None  # (N, 2), NaN for missing
    reason: str | None = None
    image_size: tuple | None = None
    detected: bool = False  # corners from find_corners here (eligible for the locking correction)


def _looks_like_corners(item, n):
    if isinstance(item, (str, os.PathLike, CornerDetection)) or item is None:
        return False
    a = np.asarray(item)
    return a.ndim == 2 and a.shape[1] == 2 and a.shape[0] == n and np.issubdtype(a.dtype, np.floating)


def _region_for(regions, i, name):
    if not regions:
        return None, None
    reg = regions.get(i, regions.get(name)) if isinstance(regions, dict) else None
    if reg is None:
        return None, None
    if isinstance(reg, dict):
        unknown = set(reg) - {"rows", "cols"}
        if unknown:
            raise ValueError(f"regions[{i!r}] keys must be 'rows' and/or 'cols', got {sorted(unknown)}")
        return reg.get("rows"), reg.get("cols")
    rows, cols = reg
    return rows, cols


def _mask_region(corners, pattern_size, rows, cols):
    ncols, nrows = pattern_size
    if corners.shape[0] != ncols * nrows:
        raise ValueError(
            "regions can only restrict corners in the canonical board order "
            f"({ncols * nrows} corners of pattern_size {pattern_size}), got {corners.shape[0]}"
        )
    ri, ci = _index_range(rows, nrows, "rows"), _index_range(cols, ncols, "cols")
    keep = np.zeros((nrows, ncols), bool)
    keep[ri.start : ri.stop, ci.start : ci.stop] = True
    out = corners.copy()
    out[~keep.ravel()] = np.nan
    return out


def _unique_names(names):
    seen = {}
    out = []
    for n in names:
        k = seen.get(n, 0)
        seen[n] = k + 1
        out.append(n if k == 0 else f"{n} #{k + 1}")
    return out


def _gather_views(items, pattern_size, n_points, *, regions, names, window, method, what, progress):
    """Detect or accept the corners of every view -> list of _View (never drops a view)."""
    if isinstance(items, (str, os.PathLike)) or (isinstance(items, np.ndarray) and items.ndim == 2):
        raise ValueError(f"{what} must be a sequence of images, paths or corner arrays, one per view")
    items = list(items)
    if names is not None:
        names = [str(n) for n in names]
        if len(names) != len(items):
            raise ValueError(f"names has {len(names)} entries but {what} has {len(items)} views")
    views = []
    try:
        from tqdm.auto import tqdm

        it = tqdm(items, desc=f"corners ({what})", disable=not progress)
    except ImportError:  # pragma: no cover
        it = items
    for i, item in enumerate(it):
        label = names[i] if names is not None else None
        key = label or (Path(item).name if isinstance(item, (str, os.PathLike)) else None)
        rows, cols = _region_for(regions, i, key)
        if item is None:
            views.append(_View(label or f"view {i}", None, "no image given"))
            continue
        if isinstance(item, CornerDetection):
            lab = label or item.name
            if not item.found:
                views.append(_View(lab, None, item.message, item.image_size))
                continue
            c = np.array(item.corners, dtype=np.float64)
            if rows is not None or cols is not None:
                c = _mask_region(c, item.pattern_size, rows, cols)
            views.append(_View(lab, c, None, item.image_size, detected=True))
            continue
        if _looks_like_corners(item, n_points):
            c = np.array(item, dtype=np.float64)
            if rows is not None or cols is not None:
                c = _mask_region(c, pattern_size, rows, cols)
            views.append(_View(label or f"view {i}", c, None, None))
            continue
        arr = None if isinstance(item, (str, os.PathLike)) else np.asarray(item)
        if (
            arr is not None and arr.ndim == 2 and arr.shape[1] == 2 and arr.shape[0] < 64
            and np.issubdtype(arr.dtype, np.floating)
        ):
            raise ValueError(
                f"{what}[{i}] looks like corners of shape {arr.shape}, but the board has {n_points} "
                f"corners (pattern_size {pattern_size}); pass one (x, y) row per corner, NaN for missing"
            )
        if label is None and not isinstance(item, (str, os.PathLike)):
            label = f"view {i}"
        det = find_corners(item, pattern_size, rows=rows, cols=cols, window=window, method=method, name=label)
        if det.found:
            views.append(_View(det.name, np.array(det.corners), None, det.image_size, detected=True))
        else:
            views.append(_View(det.name, None, det.message, det.image_size))
    for v, n in zip(views, _unique_names([v.name for v in views])):
        v.name = n
    return views


def _image_size_of(views, image_size, what):
    sizes = {}
    for v in views:
        if v.image_size is not None:
            sizes.setdefault(tuple(v.image_size), v.name)
    if len(sizes) > 1:
        (s1, n1), (s2, n2) = list(sizes.items())[:2]
        raise ValueError(
            f"{what} images differ in size: {n1} is {s1[0]}x{s1[1]} but {n2} is {s2[0]}x{s2[1]} "
            "(width x height); calibrate images of one camera at one resolution"
        )
    found = next(iter(sizes), None)
    if image_size is not None:
        image_size = tuple(int(v) for v in image_size)
        if len(image_size) != 2 or min(image_size) <= 0:
            raise ValueError(f"image_size must be (width, height) in pixels, got {image_size!r}")
        if found is not None and found != image_size:
            raise ValueError(f"image_size={image_size} but the {what} images are {found[0]}x{found[1]}")
        return image_size
    if found is None:
        raise ValueError(
            f"image_size=(width, height) is required when the {what} views are given as corners "
            "rather than images"
        )
    return found


def _board_list(board, n_views, pattern_size, square_size):
    if board is None:
        b = board_points(pattern_size, square_size)
        return [b] * n_views
    if isinstance(board, np.ndarray) or (
        isinstance(board, (list, tuple)) and len(board) and np.ndim(board[0]) == 1
    ):
        b = np.asarray(board, dtype=np.float64)
        if b.ndim != 2 or b.shape[1] != 3:
            raise ValueError(f"board_points must be (N, 3) mm or a list of them per view, got shape {b.shape}")
        return [b] * n_views
    out = [None if b is None else np.asarray(b, dtype=np.float64) for b in board]
    if len(out) != n_views:
        raise ValueError(f"board_points has {len(out)} entries but there are {n_views} views")
    for i, b in enumerate(out):
        if b is not None and (b.ndim != 2 or b.shape[1] != 3):
            raise ValueError(f"board_points[{i}] must be (N, 3) mm, got shape {b.shape}")
    return out


def _screen_views(views, boards, suppressed=()):
    """Attach reasons for views that cannot be used; returns indices of usable views."""
    used = []
    for i, (v, b) in enumerate(zip(views, boards)):
        if i in suppressed:
            v.reason = "suppressed by the user"
        if v.reason is not None:
            continue
        if b is None:
            v.reason = "no board points given"
            continue
        if v.corners.shape[0] != b.shape[0]:
            raise ValueError(
                f"view {v.name} has {v.corners.shape[0]} corners but its board has {b.shape[0]} "
                "points; corners and board_points must correspond row by row"
            )
        n = int(np.all(np.isfinite(v.corners), axis=1).sum())
        if n < _MIN_POINTS:
            v.reason = f"only {n} corners (at least {_MIN_POINTS} needed)"
            continue
        used.append(i)
    return used


def _too_few(views, used, what, need=_MIN_VIEWS):
    lines = "; ".join(f"{v.name}: {v.reason}" for v in views if v.reason)
    hint = ""
    if all("not found" in (v.reason or "") for v in views if v.reason) and not used:
        hint = " The board was found in no image: check pattern_size (inner corners per row and column)."
    return ValueError(
        f"only {len(used)} usable {what} (at least {need} needed to calibrate). "
        f"Rejected: {lines or 'none'}.{hint}"
    )


# ============================================================== single-camera core
def _init_opencv(obs, objs, image_size, est):
    """Zhang initialisation by cv2.calibrateCamera -> (intrinsics (10,), om (V,3), T (V,3))."""
    import cv2

    flags = 0
    if not est.k3:
        flags |= cv2.CALIB_FIX_K3
    if not est.tangential:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    if not est.principal_point:
        flags |= cv2.CALIB_FIX_PRINCIPAL_POINT
    if not est.aspect_ratio:
        flags |= cv2.CALIB_FIX_ASPECT_RATIO
    op, ip = [], []
    for x, X in zip(obs, objs):
        ok = np.all(np.isfinite(x), axis=1)
        op.append(X[ok].astype(np.float32).reshape(-1, 1, 3))
        ip.append(x[ok].astype(np.float32).reshape(-1, 1, 2))
    if any(np.ptp(X[..., 2]) > 1e-9 or np.any(X[..., 2] != 0) for X in op):
        raise ValueError("board_points must lie on the board plane z = 0 (mm)")
    try:
        _, K, dist, rvecs, tvecs = cv2.calibrateCamera(op, ip, tuple(image_size), None, None, flags=flags)
    except cv2.error as exc:
        raise ValueError(f"the initial (Zhang) calibration failed: {exc.err}; check the corners") from None
    d = np.zeros(5)
    dd = np.asarray(dist, dtype=np.float64).ravel()
    d[: min(5, dd.size)] = dd[:5]
    intr = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], 0.0, *d])
    if not est.aspect_ratio:
        intr[1] = intr[0]
    om = np.array([np.asarray(r, dtype=np.float64).ravel() for r in rvecs])
    T = np.array([np.asarray(t, dtype=np.float64).ravel() for t in tvecs])
    return intr, om, T


def _stack(obs, objs):
    """Valid points of the views, contiguous per view -> (x (M,2), X (M,3), vid (M,), masks)."""
    xs, Xs, vid, masks = [], [], [], []
    for k, (x, X) in enumerate(zip(obs, objs)):
        ok = np.all(np.isfinite(x), axis=1)
        masks.append(ok)
        xs.append(x[ok])
        Xs.append(X[ok])
        vid.append(np.full(int(ok.sum()), k))
    return np.concatenate(xs), np.concatenate(Xs), np.concatenate(vid), masks


def _mono_core(obs, objs, image_size, est, init=None):
    """Refine one camera over views ``obs`` -> dict of the solution and its uncertainty."""
    intr0, om0, T0 = _init_opencv(obs, objs, image_size, est) if init is None else init
    x_obs, X, vid, masks = _stack(obs, objs)
    V = len(obs)
    free = est.free
    nf = int(free.sum())
    counts = np.bincount(vid, minlength=V)
    starts = np.concatenate([[0], np.cumsum(counts)]) * 2

    def unpack(p):
        return est.unpack(p[:nf], intr0), p[nf:].reshape(V, 6)

    def fun(p):
        intr, E = unpack(p)
        R = _rodrigues_batch(E[:, :3])
        return (_project(intr, _transform(R, E[:, 3:], vid, X)) - x_obs).ravel()

    m = 2 * len(x_obs)
    groups = [[j] for j in range(nf)] + [[nf + 6 * v + k for v in range(V)] for k in range(6)]
    rows_of = {j: slice(None) for j in range(nf)}
    for v in range(V):
        for k in range(6):
            rows_of[nf + 6 * v + k] = slice(starts[v], starts[v + 1])
    p0 = np.concatenate([intr0[free], np.column_stack([om0, T0]).ravel()])
    p, J = _solve(fun, p0, groups, rows_of, m)
    intr, E = unpack(p)
    ex = -fun(p).reshape(-1, 2)  # observed - projected (the toolbox's ex)
    sigma = float(_std(ex.ravel()))
    cov = _covariance(J)
    perr = 3.0 * np.sqrt(np.abs(np.diag(cov))) * sigma
    ierr = np.zeros(10)
    ierr[free] = perr[:nf]
    if not est.aspect_ratio:
        ierr[1] = ierr[0]
    eerr = perr[nf:].reshape(V, 6)
    residuals = []
    for v in range(V):
        r = np.full((len(masks[v]), 2), np.nan)
        r[masks[v]] = ex[starts[v] // 2 : starts[v + 1] // 2]
        residuals.append(r)
    return {
        "intr": intr, "intr_error": ierr, "om": E[:, :3], "T": E[:, 3:], "om_error": eerr[:, :3],
        "T_error": eerr[:, 3:], "ex": ex, "sigma": sigma, "residuals": residuals,
    }


# ============================================================== result formatting
def _f(values, sep="   "):
    return sep.join(f"{v:3.5f}" for v in np.asarray(values, dtype=np.float64).ravel())


def _kc_line(kc):
    kc = np.asarray(kc, dtype=np.float64)
    return f"{_f(kc[:4])}  {kc[4]:5.5f}"


def _intrinsics_block(cam, unc, s, pm):
    """The toolbox's four intrinsic lines; ``s`` is "" or the "_left"/"_right" suffix."""
    fcn, ccn, alp, kcn = f"fc{s}", f"cc{s}", f"alpha_c{s}", f"kc{s}"
    a, ae = cam.alpha_c, float(np.asarray(unc["alpha_c"]).ravel()[0])
    lines = [
        f"Focal Length:          {fcn} = [ {_f(cam.fc)} ] {pm} [ {_f(unc['fc'])} ]",
        f"Principal point:       {ccn} = [ {_f(cam.cc)} ] {pm} [ {_f(unc['cc'])} ]",
        f"Skew:             {alp} = [ {a:3.5f} ] {pm} [ {ae:3.5f}  ]   => angle of pixel axes = "
        f"{90 - np.degrees(np.arctan(a)):3.5f} {pm} {np.degrees(np.arctan(ae)):3.5f} degrees",
        f"Distortion:            {kcn} = [ {_kc_line(cam.kc)} ] {pm} [ {_kc_line(unc['kc'])} ]",
    ]
    return lines


def _select(indices, names, what):
    if indices is None:
        return set()
    if isinstance(indices, (int, np.integer, str)):
        indices = [indices]
    out = set()
    for v in indices:
        if isinstance(v, str):
            if v not in names:
                raise ValueError(f"{what} {v!r} is not one of {list(names)}")
            out.add(names.index(v))
        else:
            k = int(v)
            if not -len(names) <= k < len(names):
                raise ValueError(f"{what} index {k} out of range for {len(names)} views")
            out.add(k % len(names))
    return out


def _frozen(a):
    if a is None:
        return None
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


def _truth_table(entries):
    """DataFrame of (parameter, estimate, truth, three_sigma) rows with error and sigma units."""
    import pandas as pd

    rows = []
    for name, est, true, unc in entries:
        est, true, unc = (np.atleast_1d(np.asarray(v, dtype=np.float64)).ravel() for v in (est, true, unc))
        for k in range(est.size):
            label = name if est.size == 1 else f"{name}[{k}]"
            rows.append((label, est[k], true[k], unc[k] if k < unc.size else np.nan))
    df = pd.DataFrame(rows, columns=["parameter", "estimate", "truth", "three_sigma"])
    df["error"] = df["estimate"] - df["truth"]
    with np.errstate(divide="ignore", invalid="ignore"):
        df["error_in_sigma"] = 3.0 * df["error"] / df["three_sigma"]
    df["inside_3sigma"] = df["error"].abs() <= df["three_sigma"]
    return df[["parameter", "estimate", "truth", "error", "three_sigma", "error_in_sigma", "inside_3sigma"]]


def _camera_entries(cam, true, unc, suffix=""):
    return [
        (f"fc{suffix}", cam.fc, true.fc, unc[f"fc{suffix}"]),
        (f"cc{suffix}", cam.cc, true.cc, unc[f"cc{suffix}"]),
        (f"alpha_c{suffix}", cam.alpha_c, true.alpha_c, unc[f"alpha_c{suffix}"]),
        (f"kc{suffix}", cam.kc, true.kc, unc[f"kc{suffix}"]),
    ]


# ============================================================== single camera
@dataclass(frozen=True)
class CameraCalibration:
    """Calibration of one camera from checkerboard views (the toolbox's Calib_Results).

    Attributes
    ----------
    camera : Camera
        The calibrated intrinsics (``fc, cc, alpha_c, kc``, ``image_size``).
    uncertainty : dict
        Three-sigma uncertainties (the toolbox's ``fc_error`` ...) with keys ``fc`` (2,),
        ``cc`` (2,), ``alpha_c`` (1,), ``kc`` (5,); zero for parameters held fixed.
    pixel_error : (2,) ndarray
        The toolbox's ``err_std``: per-axis standard deviation (x, y) of the residuals in
        pixels over every used corner.
    sigma : float
        Standard deviation of all residual components (``std(ex(:))``), pixels.
    views : tuple of str
        One name per input view (file name or ``"view i"``), including rejected ones.
    used : (V,) ndarray of bool
        Views that entered the calibration.
    rejected : dict
        ``{view name: reason}`` for every view left out (board not found, too few
        corners, suppressed by the user).
    corners : tuple of ((N, 2) ndarray or None)
        Corners of every view as the calibration used them (after the pixel-locking
        correction of detected corners; NaN rows for missing corners; None when not
        found).
    board_points : tuple of ((N, 3) ndarray or None)
        Board coordinates (mm, z = 0) matching ``corners`` row by row.
    residuals : tuple of ((N, 2) ndarray or None)
        Per-point residuals ``observed - projected`` in pixels for used views (NaN for
        missing corners), None for unused views.
    omc, Tc : (V, 3) ndarray
        Board pose in each view (the toolbox's ``omc_i``, ``Tc_i``): a board point ``X``
        (mm) is ``rodrigues(omc[i]) @ X + Tc[i]`` in the camera frame (OpenCV's rvec,
        tvec). NaN rows for unused views.
    omc_error, Tc_error : (V, 3) ndarray
        Their three-sigma uncertainties.
    pattern_size, square_size : tuple
        The board; ``square_size`` is (dX, dY) in mm.
    corner_correction : (2, 4) ndarray or None
        The pixel-locking bias removed from detected corners (see
        :func:`calibrate_camera`): row 0 for x, row 1 for y, coefficients of
        ``[sin 2 pi u, cos 2 pi u, sin 4 pi u, cos 4 pi u]`` with ``u`` the coordinate's
        sub-pixel part, pixels; None when not applied.
    estimated : dict
        The toolbox's switches (``est_fc``, ``est_aspect_ratio``, ``center_optim``,
        ``est_alpha``, ``est_dist``).
    """

    camera: Camera
    uncertainty: dict
    pixel_error: np.ndarray
    sigma: float
    views: tuple
    used: np.ndarray
    rejected: dict
    corners: tuple
    board_points: tuple
    residuals: tuple
    omc: np.ndarray
    Tc: np.ndarray
    omc_error: np.ndarray
    Tc_error: np.ndarray
    pattern_size: tuple
    square_size: tuple
    corner_correction: np.ndarray | None = None
    _estimate: _Estimate = field(repr=False, default=_Estimate())
    _inputs: dict = field(repr=False, default_factory=dict)

    @property
    def estimated(self):
        return self._estimate.as_dict()

    @property
    def image_size(self):
        """(width, height) in pixels."""
        return self.camera.image_size

    @property
    def n_points(self):
        """Number of corners used."""
        return int(sum(np.isfinite(r[:, 0]).sum() for r in self.residuals if r is not None))

    @property
    def view_errors(self):
        """(V,) mean reprojection error (pixel distance) of each view; NaN for unused views."""
        return np.array(
            [np.nan if r is None else float(np.nanmean(np.hypot(r[:, 0], r[:, 1]))) for r in self.residuals]
        )

    def summary(self, *, ascii=False):
        """Return the toolbox's results text ("Calibration results after optimization").

        Parameters
        ----------
        ascii : bool, optional
            Write ``+/-`` instead of the toolbox's ``±``.

        Returns
        -------
        text : str
            The toolbox's lines (``Focal Length:          fc = [ ... ] ± [ ... ]`` ...,
            ``Pixel error:          err = [ ... ]``), then the views used and rejected.
        """
        pm = "+/-" if ascii else _PM
        lines = ["Calibration results after optimization (with uncertainties):", ""]
        lines += _intrinsics_block(self.camera, self.uncertainty, "", pm)
        lines += [f"Pixel error:          err = [ {_f(self.pixel_error)} ]", ""]
        lines += [_NOTE, ""]
        lines.append(f"Views used: {int(self.used.sum())} of {len(self.views)} ({self.n_points} corners)")
        if self.corner_correction is not None:
            amp = np.hypot(self.corner_correction[:, 0], self.corner_correction[:, 1])
            lines.append(f"Corner pixel-locking correction: amplitude x {amp[0]:.4f} px, y {amp[1]:.4f} px")
        for name, why in self.rejected.items():
            lines.append(f"  rejected {name}: {why}")
        return "\n".join(lines)

    def __str__(self):
        return self.summary()

    def compare(self, truth):
        """Table of the estimated intrinsics against known true values (e.g. ``wingphoto.synth``).

        Parameters
        ----------
        truth : Camera
            The true camera.

        Returns
        -------
        pandas.DataFrame
            One row per scalar parameter: parameter, estimate, truth, error, three_sigma,
            error_in_sigma (error / sigma), inside_3sigma. Parameters that were not
            estimated have three_sigma 0 and are inside only when exactly equal.
        """
        return _truth_table(_camera_entries(self.camera, truth, self.uncertainty))

    def suppress(self, views):
        """Recalibrate without some views (the toolbox's "Add/Suppress images").

        Parameters
        ----------
        views : int, str or sequence of them
            View indices (0-based, in input order) or names (``self.views``).

        Returns
        -------
        CameraCalibration
            A new calibration; the suppressed views appear in ``rejected``.
        """
        drop = _select(views, list(self.views), "view") | set(self._inputs.get("suppressed", ()))
        return _calibrate_from_views(
            self._inputs["views"], self._inputs["boards"], self._inputs["image_size"], self._estimate,
            self.pattern_size, self.square_size, suppressed=drop, locking=self._inputs["locking"],
        )


_LOCKING_HARMONICS = 2
_LOCKING_ROUNDS = 2
_LOCKING_MIN_CORNERS = 400


def _locking_design(u):
    """Harmonics of the sub-pixel position: (M, 2 * H) [sin 2 pi k u, cos 2 pi k u]."""
    phase = 2.0 * np.pi * (u - np.floor(u))
    return np.column_stack(
        [f(k * phase) for k in range(1, _LOCKING_HARMONICS + 1) for f in (np.sin, np.cos)]
    )


def _apply_locking(corners, coef):
    """Remove the periodic sub-pixel bias ``coef`` (2, 2H) from raw corners."""
    out = np.array(corners, dtype=np.float64)
    ok = np.all(np.isfinite(out), axis=1)
    for ax in (0, 1):
        out[ok, ax] -= _locking_design(out[ok, ax]) @ coef[ax]
    return out


def _fit_locking(raw, residuals):
    """Least-squares fit of the residuals (observed - projected) on the raw sub-pixel phase."""
    c = np.concatenate(raw)
    r = np.concatenate(residuals)
    ok = np.all(np.isfinite(c), axis=1) & np.all(np.isfinite(r), axis=1)
    return np.array([np.linalg.lstsq(_locking_design(c[ok, ax]), r[ok, ax], rcond=None)[0] for ax in (0, 1)])


def _mono_with_locking(views, used, boards, image_size, est, locking):
    """Calibrate, and remove the corner detector's pixel-locking bias (see calibrate_camera)."""
    obs = [views[i].corners for i in used]
    objs = [boards[i] for i in used]
    sol = _mono_core(obs, objs, image_size, est)
    det = [views[i].detected for i in used]
    n_det = sum(int(np.isfinite(o[:, 0]).sum()) for o, d in zip(obs, det) if d)
    if not locking or n_det < _LOCKING_MIN_CORNERS:
        return sol, obs, None
    raw = [o for o, d in zip(obs, det) if d]
    coef = np.zeros((2, 2 * _LOCKING_HARMONICS))
    for _ in range(_LOCKING_ROUNDS):
        coef = coef + _fit_locking(raw, [r for r, d in zip(sol["residuals"], det) if d])
        if np.max(np.abs(coef)) > 0.25:  # not a sub-pixel bias: leave the corners alone
            logger.warning("corner locking fit implausible (%s px); not applied", np.round(coef, 3))
            return _mono_core(obs, objs, image_size, est), obs, None
        corrected = [_apply_locking(o, coef) if d else o for o, d in zip(obs, det)]
        sol = _mono_core(corrected, objs, image_size, est, init=(sol["intr"], sol["om"], sol["T"]))
    logger.info("pixel-locking correction (x; y rows, [sin cos] x harmonics): %s", np.round(coef, 4))
    return sol, corrected, coef


def _calibrate_from_views(
    views, boards, image_size, est, pattern_size, square_size, suppressed=(), what="views", locking=True,
):
    original = views
    views = [dataclasses.replace(v) for v in views]
    used = _screen_views(views, boards, suppressed)
    if len(used) < _MIN_VIEWS:
        raise _too_few(views, used, what)
    for v in views:
        if v.reason:  # the user's own choice is news, not a warning
            level = logging.INFO if v.reason == "suppressed by the user" else logging.WARNING
            logger.log(level, "view %s not used: %s", v.name, v.reason)
    sol, used_corners, coef = _mono_with_locking(views, used, boards, image_size, est, locking)
    for k, i in enumerate(used):
        views[i].corners = used_corners[k]
    V = len(views)
    om = np.full((V, 3), np.nan)
    T, ome, Te = om.copy(), om.copy(), om.copy()
    om[used], T[used], ome[used], Te[used] = sol["om"], sol["T"], sol["om_error"], sol["T_error"]
    res = [None] * V
    for k, i in enumerate(used):
        res[i] = _frozen(sol["residuals"][k])
    ie = sol["intr_error"]
    cam = _camera_from_vector(sol["intr"], image_size)
    mask = np.zeros(V, bool)
    mask[used] = True
    mask.setflags(write=False)
    unc = {"fc": _frozen(ie[0:2]), "cc": _frozen(ie[2:4]), "alpha_c": _frozen(ie[4:5]), "kc": _frozen(ie[5:10])}
    result = CameraCalibration(
        camera=cam, uncertainty=unc, pixel_error=_frozen(_std(sol["ex"], axis=0)), sigma=sol["sigma"],
        views=tuple(v.name for v in views), used=mask,
        rejected={v.name: v.reason for v in views if v.reason},
        corners=tuple(_frozen(v.corners) for v in views), board_points=tuple(_frozen(b) for b in boards),
        residuals=tuple(res), omc=_frozen(om), Tc=_frozen(T), omc_error=_frozen(ome), Tc_error=_frozen(Te),
        pattern_size=tuple(pattern_size), square_size=tuple(square_size),
        corner_correction=_frozen(coef), _estimate=est,
        _inputs={"views": original, "boards": boards, "image_size": image_size,
                 "suppressed": tuple(suppressed), "locking": locking},
    )
    logger.info("calibrated %s: %s, pixel error %s", cam, len(used), result.pixel_error)
    return result


def calibrate_camera(
    images_or_corners, pattern_size, square_size, *, estimate_skew=False, estimate_k3=False,
    estimate_tangential=True, estimate_principal_point=True, estimate_aspect_ratio=True,
    board_points=None, image_size=None, names=None, regions=None, window=7, method="auto",
    correct_locking=True, suppress=(), progress=False,
):
    """Calibrate one camera from checkerboard views (the toolbox's "Calibration").

    Parameters
    ----------
    images_or_corners : sequence
        One entry per view: an image array, an image file path, a
        :class:`CornerDetection`, or an (N, 2) array of corner pixels in the order of
        ``board_points`` (NaN rows for missing corners). ``None`` marks a missing view.
        Images are only read.
    pattern_size : (2,) tuple of int
        (inner corners per row, inner corners per column), e.g. (9, 6).
    square_size : float or (2,)
        Side of a square in mm (the toolbox's dX = dY).
    estimate_skew : bool, optional
        Estimate ``alpha_c`` (the toolbox's est_alpha, default off).
    estimate_k3 : bool, optional
        Estimate the sixth-order radial term ``kc[4]`` (default off, as the toolbox's
        ``est_dist = [1 1 1 1 0]``).
    estimate_tangential : bool, optional
        Estimate ``kc[2:4]`` (default on).
    estimate_principal_point : bool, optional
        Estimate ``cc`` (the toolbox's center_optim, default on); otherwise it is the
        image centre ``((w - 1) / 2, (h - 1) / 2)``.
    estimate_aspect_ratio : bool, optional
        Estimate ``fc[0]`` and ``fc[1]`` separately (default on); otherwise
        ``fc[0] == fc[1]``.
    board_points : (N, 3) array_like or list of them, optional
        Board coordinates in mm (z = 0) matching the corners row by row, one array for
        every view or one per view (e.g. the toolbox's ``X_i``). Default
        :func:`board_points` ``(pattern_size, square_size)``.
    image_size : (width, height), optional
        Required when only corners are given.
    names : sequence of str, optional
        View names for messages and results (default: file names or ``"view i"``).
    regions : dict, optional
        ``{view index or name: {"rows": ..., "cols": ...}}`` restricting views to a
        sub-rectangle of the board (see :func:`find_corners`).
    window : int, optional
        Sub-pixel window half-size for corner detection (default 7).
    method : {"auto", "classic", "sb"}, optional
        Corner detector (see :func:`find_corners`).
    correct_locking : bool, optional
        Remove the sub-pixel corner detector's periodic bias (pixel locking, see Notes)
        from corners detected here (default True). Corners passed in as arrays are
        always used as given. False keeps the toolbox's corners exactly.
    suppress : sequence of int or str, optional
        Views to leave out from the start (as :meth:`CameraCalibration.suppress`).
    progress : bool, optional
        Show a progress bar while detecting corners.

    Returns
    -------
    CameraCalibration
        ``.camera``, ``.uncertainty`` (3 sigma), ``.pixel_error`` (err_std),
        ``.residuals``, ``.omc``/``.Tc``, ``.used``/``.rejected``, ``.summary()``.

    Raises
    ------
    ValueError
        Fewer than 3 usable views (the message names every rejected view and why),
        images of different sizes, an invalid ``pattern_size`` or corners that do not
        match the board.
    FileNotFoundError
        A path that does not exist.

    Notes
    -----
    Zhang's closed-form initialisation (``cv2.calibrateCamera``, no skew) is refined
    by :func:`scipy.optimize.least_squares` over the estimated intrinsics and every
    view's board pose, minimising the pixel residuals of the toolbox's model
    (:meth:`wingphoto.camera.Camera.project`); uncertainties as the toolbox's
    ``go_calib_optim_iter`` (module notes). A view whose board is not found is never
    silently dropped: it is listed in ``rejected`` with the detector's message, and
    logged.

    Pixel locking: ``cornerSubPix`` (like the toolbox's cornerfinder) pulls each
    coordinate towards a fixed position within its pixel, a bias that is a periodic
    function of the coordinate's sub-pixel part -- up to about 0.05 px on sharp images
    (0.6 px blur), negligible on blurred ones. Corners of nearly horizontal rows share
    their y phase, so the bias is correlated along rows and the toolbox's uncertainty
    formula, which assumes independent corner errors, then understates the errors of
    ``cc[1]``, ``p1`` and the rig's ``om[0]``, ``T[1]``. With ``correct_locking`` the
    bias is modelled per camera as two harmonics of each coordinate's sub-pixel part,
    fitted to the residuals and removed from the detected corners (two rounds of
    fit and recalibration); ``corner_correction`` holds the fitted coefficients. On
    synthetic renders this cuts the corner error about threefold and brings 99 % of
    the parameters inside their 3-sigma intervals (82 % without); on the toolbox's
    example images it changes the result by less than 0.15 sigma. It needs at least
    400 detected corners, and is skipped (with a warning) when the fit exceeds 0.25 px.

    References
    ----------
    Bouguet, J.-Y., Camera Calibration Toolbox for Matlab.
    Zhang, Z. (2000), A flexible new technique for camera calibration, IEEE PAMI 22(11).
    """
    pattern_size = _check_pattern_size(pattern_size)
    square_size = _check_square_size(square_size)
    n = pattern_size[0] * pattern_size[1]
    if board_points is not None and not (isinstance(board_points, np.ndarray) and board_points.ndim == 2):
        first = next((b for b in board_points if b is not None), None)
        if first is not None and np.ndim(first) == 2:
            n = np.shape(first)[0]
    views = _gather_views(
        images_or_corners, pattern_size, n, regions=regions, names=names, window=window,
        method=method, what="images_or_corners", progress=progress,
    )
    size = _image_size_of(views, image_size, "calibration")
    boards = _board_list(board_points, len(views), pattern_size, square_size)
    est = _Estimate(
        skew=bool(estimate_skew), k3=bool(estimate_k3), tangential=bool(estimate_tangential),
        principal_point=bool(estimate_principal_point), aspect_ratio=bool(estimate_aspect_ratio),
    )
    drop = _select(suppress, [v.name for v in views], "view")
    return _calibrate_from_views(
        views, boards, size, est, pattern_size, square_size, suppressed=drop, locking=bool(correct_locking),
    )


# ============================================================== stereo
#: Names of the rows/columns of :attr:`StereoCalibration.covariance`, in order.
RIG_PARAMETER_NAMES = tuple(
    [f"{k}_{s}" if n == 1 else f"{k}_{s}[{i}]" for s in ("left", "right")
     for k, n in (("fc", 2), ("cc", 2), ("alpha_c", 1), ("kc", 5)) for i in range(n)]
    + [f"om[{i}]" for i in range(3)] + [f"T[{i}]" for i in range(3)]
)


@dataclass(frozen=True)
class StereoCalibration:
    """Joint calibration of a stereo rig (the toolbox's Calib_Results_stereo).

    Attributes
    ----------
    rig : StereoRig
        Both cameras and the right camera's pose ``(om, T)``:
        ``X_right = rodrigues(om) @ X_left + T`` (OpenCV ``stereoCalibrate``'s R, T).
    uncertainty : dict
        Three-sigma uncertainties with keys ``fc_left, cc_left, alpha_c_left, kc_left,
        fc_right, cc_right, alpha_c_right, kc_right, om, T`` (the toolbox's
        ``*_error``), ready for ``wingphoto.io.save_bouguet_stereo(rig, path,
        uncertainty=...)``.
    pixel_error : (2,) ndarray
        Per-axis standard deviation of the residuals of both cameras together, pixels.
    pixel_error_left, pixel_error_right : (2,) ndarray
        The same per camera (the toolbox's ``err_std`` of each camera).
    sigma : float
        Standard deviation of all residual components of both cameras.
    pairs : tuple of str
        One name per input pair ("left01.jpg / right01.jpg" or "pair i").
    used : (P,) ndarray of bool
        Pairs used in the joint refinement.
    rejected : dict
        ``{pair name: reason}`` for every pair left out.
    corners_left, corners_right : tuple of ((N, 2) ndarray or None)
        Corners as used (pixel-locking corrected when detected here).
    board_points : tuple of ((N, 3) ndarray or None)
    residuals_left, residuals_right : tuple of ((N, 2) ndarray or None)
        ``observed - projected`` per corner of each used pair, pixels.
    omc_left, Tc_left : (P, 3) ndarray
        Board pose in the left camera for each pair (NaN when unused), with three-sigma
        ``omc_left_error``, ``Tc_left_error``.
    mono_left, mono_right : CameraCalibration
        The single-camera calibrations used as the starting point.
    covariance : (26, 26) ndarray of float64
        One-sigma covariance ``sigma**2 (J^T J)^-1`` (``sigma`` the residual standard
        deviation, px) of the rig parameters of the joint refinement, in the order of
        :attr:`parameter_names`: ``fc_left[0..1], cc_left[0..1], alpha_c_left,
        kc_left[0..4]``, the same for the right camera, ``om[0..2]`` (rad), ``T[0..2]``
        (mm). The per-pair board poses, also estimated, are marginalised out (the
        sub-block of the full inverse). Parameters held fixed (e.g. ``alpha_c``,
        ``kc[4]`` by default) have zero rows and columns; with a fixed aspect ratio the
        ``fc[1]`` row repeats ``fc[0]``'s. ``3 * sqrt(diag(covariance))`` equals
        :attr:`uncertainty` entry by entry. Use it to propagate the calibration's
        uncertainty to 3D points.
    parameter_names : tuple of str
        The 26 names of the rows of :attr:`covariance` (:data:`RIG_PARAMETER_NAMES`),
        e.g. ``"fc_left[0]"``, ``"alpha_c_right"``, ``"om[2]"``, ``"T[0]"`` (the row
        labels of :meth:`compare`).
    pair_check : wingphoto.calibcheck.PairCheck
        Each pair's own rig pose and its consistency with the others, and the pairing
        offset diagnosis (:func:`wingphoto.calibcheck.check_pairs`).
    """

    rig: StereoRig
    uncertainty: dict
    pixel_error: np.ndarray
    pixel_error_left: np.ndarray
    pixel_error_right: np.ndarray
    sigma: float
    pairs: tuple
    used: np.ndarray
    rejected: dict
    corners_left: tuple
    corners_right: tuple
    board_points: tuple
    residuals_left: tuple
    residuals_right: tuple
    omc_left: np.ndarray
    Tc_left: np.ndarray
    omc_left_error: np.ndarray
    Tc_left_error: np.ndarray
    mono_left: CameraCalibration
    mono_right: CameraCalibration
    pattern_size: tuple
    square_size: tuple
    covariance: np.ndarray | None = field(default=None, repr=False)
    parameter_names: tuple = RIG_PARAMETER_NAMES
    pair_check: object = field(default=None, repr=False)
    _inputs: dict = field(repr=False, default_factory=dict)

    def parameter_sigma(self):
        """Return ``{parameter name: 1-sigma}`` from :attr:`covariance` (one third of ``uncertainty``)."""
        if self.covariance is None:
            raise ValueError("this StereoCalibration has no covariance (it was not made by calibrate_stereo)")
        return dict(zip(self.parameter_names, np.sqrt(np.diag(self.covariance))))

    @property
    def camera_uncertainty(self):
        """``{"left": {fc, cc, alpha_c, kc}, "right": {...}}`` (three sigma)."""
        u = self.uncertainty
        return {
            s: {k: u[f"{k}_{s}"] for k in ("fc", "cc", "alpha_c", "kc")} for s in ("left", "right")
        }

    @property
    def view_errors(self):
        """(P, 2) mean reprojection error (pixels) of each pair in the left and right image."""
        out = np.full((len(self.pairs), 2), np.nan)
        for j, res in enumerate((self.residuals_left, self.residuals_right)):
            for i, r in enumerate(res):
                if r is not None:
                    out[i, j] = float(np.nanmean(np.hypot(r[:, 0], r[:, 1])))
        return out

    def summary(self, *, ascii=False):
        """Return the toolbox's stereo results text ("Stereo calibration parameters ...").

        Parameters
        ----------
        ascii : bool, optional
            Write ``+/-`` instead of ``±``.
        """
        pm = "+/-" if ascii else _PM
        cu = self.camera_uncertainty
        u = self.uncertainty
        lines = ["Stereo calibration parameters after optimization:", "", "",
                 "Intrinsic parameters of left camera:", ""]
        lines += _intrinsics_block(self.rig.left, cu["left"], "_left", pm)
        lines += ["", "", "Intrinsic parameters of right camera:", ""]
        lines += _intrinsics_block(self.rig.right, cu["right"], "_right", pm)
        lines += ["", "", "Extrinsic parameters (position of right camera wrt left camera):", ""]
        om, T = self.rig.om, self.rig.T
        lines.append(
            f"Rotation vector:             om = [ {om[0]:3.5f}   {om[1]:3.5f}  {om[2]:3.5f} ] {pm} "
            f"[ {u['om'][0]:3.5f}   {u['om'][1]:3.5f}  {u['om'][2]:3.5f} ]"
        )
        lines.append(
            f"Translation vector:           T = [ {T[0]:3.5f}   {T[1]:3.5f}  {T[2]:3.5f} ] {pm} "
            f"[ {u['T'][0]:3.5f}   {u['T'][1]:3.5f}  {u['T'][2]:3.5f} ]"
        )
        lines += ["", "", _NOTE, ""]
        lines.append(f"Pixel error:     err_left = [ {_f(self.pixel_error_left)} ]")
        lines.append(f"Pixel error:    err_right = [ {_f(self.pixel_error_right)} ]")
        lines.append(f"Pairs used: {int(self.used.sum())} of {len(self.pairs)}")
        for name, why in self.rejected.items():
            lines.append(f"  rejected {name}: {why}")
        return "\n".join(lines)

    def __str__(self):
        return self.summary()

    def compare(self, truth):
        """Table of every estimated stereo parameter against a known true rig.

        Parameters
        ----------
        truth : StereoRig
            The true rig (e.g. ``wingphoto.synth.load_rig("data-samples/rig.json")``).

        Returns
        -------
        pandas.DataFrame
            Rows fc_left[0] ... kc_right[4], om[0..2], T[0..2] with estimate, truth, error,
            three_sigma, error_in_sigma and inside_3sigma (see
            :meth:`CameraCalibration.compare`).
        """
        u = self.uncertainty
        entries = _camera_entries(self.rig.left, truth.left, u, "_left")
        entries += _camera_entries(self.rig.right, truth.right, u, "_right")
        entries += [("om", self.rig.om, truth.om, u["om"]), ("T", self.rig.T, truth.T, u["T"])]
        return _truth_table(entries)

    def suppress(self, pairs):
        """Recalibrate without some pairs.

        Parameters
        ----------
        pairs : int, str or sequence of them
            Pair indices (0-based) or names (``self.pairs``).

        Returns
        -------
        StereoCalibration
        """
        drop = _select(pairs, list(self.pairs), "pair") | set(self._inputs.get("suppressed", ()))
        kw = dict(self._inputs)
        kw["suppressed"] = drop
        return _stereo_from_views(**kw)

    def save(self, path, **kwargs):
        """Write the toolbox's ``Calib_Results_stereo.mat`` with the uncertainties.

        Calls ``wingphoto.io.save_bouguet_stereo(self.rig, path, uncertainty=self.uncertainty)``.
        """
        from . import io

        return io.save_bouguet_stereo(self.rig, path, uncertainty=self.uncertainty, **kwargs)


def _compose_right(R_st, T_st, R_l, T_l):
    """Board pose in the right camera from its pose in the left camera and the rig."""
    return R_st @ R_l, R_st @ T_l + T_st


def _stereo_core(obs_l, obs_r, objs, init_l, init_r, om0, T0, poses0, est_l, est_r):
    P = len(objs)
    xl, Xl, vl, ml = _stack(obs_l, objs)
    xr, Xr, vr, mr = _stack(obs_r, objs)
    nL, nR = len(xl), len(xr)
    # residual order: pair by pair, [left rows of the pair, right rows of the pair]
    cl = np.bincount(vl, minlength=P)
    cr = np.bincount(vr, minlength=P)
    sl = np.concatenate([[0], np.cumsum(cl)])
    sr = np.concatenate([[0], np.cumsum(cr)])
    perm = []
    for p in range(P):
        perm.append(np.arange(2 * sl[p], 2 * sl[p + 1]))
        perm.append(2 * nL + np.arange(2 * sr[p], 2 * sr[p + 1]))
    perm = np.concatenate(perm)
    block = np.concatenate([[0], np.cumsum(2 * (cl + cr))])
    fl, fr = est_l.free, est_r.free
    nl, nr = int(fl.sum()), int(fr.sum())
    g0 = nl + nr  # om, T start
    e0 = g0 + 6  # poses start

    def unpack(p):
        il = est_l.unpack(p[:nl], init_l)
        ir = est_r.unpack(p[nl:g0], init_r)
        return il, ir, p[g0:g0 + 3], p[g0 + 3:e0], p[e0:].reshape(P, 6)

    def both(p):
        il, ir, om, T, E = unpack(p)
        R = _rodrigues_batch(E[:, :3])
        Rs = rodrigues(om)
        el = _project(il, _transform(R, E[:, 3:], vl, Xl)) - xl
        XL = _transform(R, E[:, 3:], vr, Xr)
        er = _project(ir, XL @ Rs.T + T) - xr
        return el, er

    def fun(p):
        el, er = both(p)
        return np.concatenate([el.ravel(), er.ravel()])[perm]

    m = 2 * (nL + nR)
    groups = [[j] for j in range(e0)] + [[e0 + 6 * v + k for v in range(P)] for k in range(6)]
    rows_of = {j: slice(None) for j in range(e0)}
    for v in range(P):
        for k in range(6):
            rows_of[e0 + 6 * v + k] = slice(block[v], block[v + 1])
    p0 = np.concatenate([init_l[fl], init_r[fr], om0, T0, np.asarray(poses0).ravel()])
    p, J = _solve(fun, p0, groups, rows_of, m)
    il, ir, om, T, E = unpack(p)
    el, er = both(p)
    el, er = -el, -er
    allres = np.concatenate([el, er])
    sigma = float(_std(allres.ravel()))
    cov = _covariance(J)
    perr = 3.0 * np.sqrt(np.abs(np.diag(cov))) * sigma
    errl, errr = np.zeros(10), np.zeros(10)
    errl[fl] = perr[:nl]
    errr[fr] = perr[nl:g0]
    if not est_l.aspect_ratio:
        errl[1] = errl[0]
    if not est_r.aspect_ratio:
        errr[1] = errr[0]

    def per_pair(e, masks, starts):
        out = []
        for v in range(P):
            r = np.full((len(masks[v]), 2), np.nan)
            r[masks[v]] = e[starts[v] : starts[v + 1]]
            out.append(r)
        return out

    # 1-sigma covariance of the rig parameters (board poses marginalised out: for a
    # Gaussian that is the sub-block), expanded to all 26 rig parameters, zero for fixed ones
    idx = np.concatenate([np.flatnonzero(fl), 10 + np.flatnonzero(fr), 20 + np.arange(6)])
    rig_cov = np.zeros((26, 26))
    sub = cov[:e0, :e0] * sigma**2
    rig_cov[np.ix_(idx, idx)] = 0.5 * (sub + sub.T)  # exactly symmetric; the diagonal is unchanged
    for off, est in ((0, est_l), (10, est_r)):
        if not est.aspect_ratio:  # fc[1] is fc[0]: fully correlated copy
            rig_cov[off + 1, :] = rig_cov[off, :]
            rig_cov[:, off + 1] = rig_cov[:, off]
    return {
        "il": il, "ir": ir, "om": om, "T": T, "E": E, "errl": errl, "errr": errr, "rig_cov": rig_cov,
        "om_error": perr[g0:g0 + 3], "T_error": perr[g0 + 3:e0], "E_error": perr[e0:].reshape(P, 6),
        "el": el, "er": er, "sigma": sigma, "res_l": per_pair(el, ml, sl), "res_r": per_pair(er, mr, sr),
    }


def _pair_names(views_l, views_r, names=None):
    if names is None:
        names = [f"{a.name} / {b.name}" if a.name != b.name else a.name for a, b in zip(views_l, views_r)]
    return tuple(_unique_names([str(n) for n in names]))


def _refine_rig_pose(om0, T0, mono_l, cam_r, obs_r, objs, used):
    """Fit (om, T) alone to the right images, cameras and left board poses held fixed.

    A cheap 6-parameter start for the joint refinement (fewer of its costly iterations).
    """
    x_obs, X, vid, _ = _stack(obs_r, objs)
    R = _rodrigues_batch(mono_l.omc[used])
    XL = _transform(R, mono_l.Tc[used], vid, X)
    intr = _intrinsics_vector(cam_r)

    def fun(p):
        return (_project(intr, XL @ rodrigues(p[:3]).T + p[3:]) - x_obs).ravel()

    groups = [[j] for j in range(6)]
    rows_of = {j: slice(None) for j in range(6)}
    p, _ = _solve(fun, np.concatenate([om0, T0]), groups, rows_of, 2 * len(x_obs))
    return p[:3], p[3:]


def _stereo_from_views(
    views_l, views_r, boards, size_l, size_r, est_l, est_r, pattern_size, square_size,
    threshold, pair_names, suppressed=(), locking=True, force=False, max_offset=3,
):
    from .calibcheck import check_pairs, identical_pairs

    P = len(boards)
    views_l = [dataclasses.replace(v) for v in views_l]
    views_r = [dataclasses.replace(v) for v in views_r]
    # the same image given as left and right (e.g. one folder passed twice)
    same = [i for i in identical_pairs([v.corners for v in views_l], [v.corners for v in views_r])
            if i not in suppressed]
    both = [i for i in range(P) if i not in suppressed and views_l[i].corners is not None
            and views_r[i].corners is not None]
    if len(both) < _MIN_VIEWS:  # too few pairs anyway: the counting errors below say why
        same = []
    if same and len(same) == len(both):
        raise ValueError(
            f"the left and right images are identical in all {len(same)} pairs with the board in both "
            "(the same folder or files given for both cameras?); give each camera's own images"
        )
    # single-camera calibrations on every view each camera saw (suppressed and identical pairs excluded)
    mono_l = _calibrate_from_views(
        views_l, boards, size_l, est_l, pattern_size, square_size, set(suppressed) | set(same),
        what="left-camera views", locking=locking,
    )
    mono_r = _calibrate_from_views(
        views_r, boards, size_r, est_r, pattern_size, square_size, set(suppressed) | set(same),
        what="right-camera views", locking=locking,
    )
    # the corners as each camera's calibration used them (pixel-locking corrected)
    obs_l, obs_r = mono_l.corners, mono_r.corners
    reasons = {}
    for i in range(P):
        if i in suppressed:
            reasons[i] = "suppressed by the user"
            continue
        if i in same:
            reasons[i] = "left and right images identical (the same image given for both cameras)"
            continue
        bad = []
        for side, mono in (("left", mono_l), ("right", mono_r)):
            if not mono.used[i]:
                bad.append(f"{side} image {mono.views[i]}: {mono.rejected[mono.views[i]]}")
        if bad:
            reasons[i] = "; ".join(bad)
    cand = [i for i in range(P) if i not in reasons]
    if not cand:
        raise ValueError(
            "no pair has the board in both images. Rejected: "
            + "; ".join(f"{pair_names[i]}: {reasons[i]}" for i in range(P))
        )
    # stereo pose from the median of the per-pair relative poses (the toolbox's init), each
    # pair's consistency with it, and the diagnosis of pairs out of sync (wingphoto.calibcheck)
    check = check_pairs(mono_l, mono_r, boards, obs_r, cand, pair_names, max_offset=max_offset)
    if check.offset != 0:
        if not force:
            raise ValueError(check.message + "; or pass force=True (--force) to calibrate the pairs as given")
        logger.warning("%s (calibrating the pairs as given: force=True)", check.message)
    n_ok = int(check.table["consistent"].sum())
    if check.offset == 0 and n_ok < 0.5 * len(cand):
        msg = (f"only {n_ok} of {len(cand)} pairs agree on the rig pose: the left and right images do not look "
               "like simultaneous pairs (wrong order, different sessions, or a moving board)")
        if not force:
            raise ValueError(msg + "; pass force=True (--force) to calibrate the agreeing pairs anyway")
        logger.warning("%s (force=True)", msg)
    om0, T0 = check.om, check.T
    consistent = dict(zip(check.table["pair"], check.table["consistent"]))
    err_px = dict(zip(check.table["pair"], check.table["error_px"]))
    # inconsistent pairs: the toolbox's threshold on the initial errors, then the consistency check
    Rs = rodrigues(om0)
    cam_r = mono_r.camera
    used = []
    for i in cand:
        R, T = _compose_right(Rs, T0, rodrigues(mono_l.omc[i]), mono_l.Tc[i])
        pred = cam_r.project(boards[i] @ R.T + T)
        err = np.nanmax(np.abs(obs_r[i] - pred))
        if err > threshold:
            reasons[i] = (
                f"left and right views inconsistent (initial error {err:.1f} px > threshold "
                f"{threshold:g} px): the board moved between the exposures or the corners differ"
            )
        elif not consistent[pair_names[i]]:
            reasons[i] = (
                f"left and right views inconsistent with the other pairs (right-image RMS error "
                f"{err_px[pair_names[i]]:.2f} px > {check.tolerance_px:.2f} px from the rig pose of the other "
                "pairs): a wrong image in the pair, or the board moved between the two exposures"
            )
        else:
            used.append(i)
    if len(used) < _MIN_VIEWS:
        raise ValueError(
            f"only {len(used)} usable pairs (at least {_MIN_VIEWS} needed for stereo calibration). Rejected: "
            + "; ".join(f"{pair_names[i]}: {reasons[i]}" for i in sorted(reasons))
        )
    for i in sorted(reasons):
        level = logging.INFO if reasons[i] == "suppressed by the user" else logging.WARNING
        logger.log(level, "pair %s not used: %s", pair_names[i], reasons[i])
    om0, T0 = _refine_rig_pose(om0, T0, mono_l, cam_r, [obs_r[i] for i in used], [boards[i] for i in used], used)
    poses0 = np.column_stack([mono_l.omc[used], mono_l.Tc[used]])
    sol = _stereo_core(
        [obs_l[i] for i in used], [obs_r[i] for i in used], [boards[i] for i in used],
        _intrinsics_vector(mono_l.camera), _intrinsics_vector(mono_r.camera), om0, T0, poses0, est_l, est_r,
    )
    left = _camera_from_vector(sol["il"], size_l)
    right = _camera_from_vector(sol["ir"], size_r)
    rig = StereoRig(left, right, sol["om"], sol["T"])
    unc = {}
    for side, e in (("left", sol["errl"]), ("right", sol["errr"])):
        unc[f"fc_{side}"] = _frozen(e[0:2])
        unc[f"cc_{side}"] = _frozen(e[2:4])
        unc[f"alpha_c_{side}"] = _frozen(e[4:5])
        unc[f"kc_{side}"] = _frozen(e[5:10])
    unc["om"] = _frozen(sol["om_error"])
    unc["T"] = _frozen(sol["T_error"])
    om = np.full((P, 3), np.nan)
    T, ome, Te = om.copy(), om.copy(), om.copy()
    om[used], T[used] = sol["E"][:, :3], sol["E"][:, 3:]
    ome[used], Te[used] = sol["E_error"][:, :3], sol["E_error"][:, 3:]
    rl, rr = [None] * P, [None] * P
    for k, i in enumerate(used):
        rl[i], rr[i] = _frozen(sol["res_l"][k]), _frozen(sol["res_r"][k])
    mask = np.zeros(P, bool)
    mask[used] = True
    mask.setflags(write=False)
    allres = np.concatenate([sol["el"], sol["er"]])
    result = StereoCalibration(
        rig=rig, uncertainty=unc, pixel_error=_frozen(_std(allres, axis=0)),
        pixel_error_left=_frozen(_std(sol["el"], axis=0)), pixel_error_right=_frozen(_std(sol["er"], axis=0)),
        sigma=sol["sigma"], pairs=pair_names, used=mask,
        rejected={pair_names[i]: reasons[i] for i in sorted(reasons)},
        corners_left=tuple(obs_l), corners_right=tuple(obs_r),
        board_points=tuple(_frozen(b) for b in boards), residuals_left=tuple(rl), residuals_right=tuple(rr),
        omc_left=_frozen(om), Tc_left=_frozen(T), omc_left_error=_frozen(ome), Tc_left_error=_frozen(Te),
        mono_left=mono_l, mono_right=mono_r, pattern_size=tuple(pattern_size), square_size=tuple(square_size),
        covariance=_frozen(sol["rig_cov"]), parameter_names=RIG_PARAMETER_NAMES, pair_check=check,
        _inputs={
            "views_l": views_l, "views_r": views_r, "boards": boards, "size_l": size_l, "size_r": size_r,
            "est_l": est_l, "est_r": est_r, "pattern_size": pattern_size, "square_size": square_size,
            "threshold": threshold, "pair_names": pair_names, "suppressed": tuple(suppressed),
            "locking": locking, "force": force, "max_offset": max_offset,
        },
    )
    logger.info("stereo calibration: om=%s T=%s over %d pairs", rig.om, rig.T, len(used))
    return result


def calibrate_stereo(
    left_images, right_images, pattern_size, square_size, *, estimate_skew=False, estimate_k3=False,
    estimate_tangential=True, estimate_principal_point=True, estimate_aspect_ratio=True,
    board_points=None, image_size=None, names=None, regions=None, window=7, method="auto",
    correct_locking=True, threshold=50.0, suppress=(), progress=False, force=False, max_offset=3,
):
    """Calibrate a stereo rig from pairs of checkerboard views (the toolbox's stereo_gui).

    Parameters
    ----------
    left_images, right_images : sequence
        One entry per pair, taken at the same instant: image arrays, file paths,
        :class:`CornerDetection` or (N, 2) corner arrays (NaN rows for missing corners),
        as for :func:`calibrate_camera`. Images are only read.
    pattern_size : (2,) tuple of int
        (inner corners per row, inner corners per column), e.g. (9, 6).
    square_size : float or (2,)
        Side of a square in mm.
    estimate_skew, estimate_k3, estimate_tangential, estimate_principal_point, estimate_aspect_ratio : bool
        Which intrinsics are estimated, for both cameras (see :func:`calibrate_camera`).
    board_points : (N, 3) array_like or list of them, optional
        Board coordinates (mm) matching the corners (default from the pattern).
    image_size : (width, height), optional
        Required when only corners are given (both cameras the same size).
    names : sequence of str, optional
        Pair names (default "left01.jpg / right01.jpg" or "pair i").
    regions : dict, optional
        ``{pair index or name: {"rows": ..., "cols": ...}}``: restrict a pair to a
        sub-rectangle of the board, applied identically to both views.
    window, method :
        Corner detection options (see :func:`find_corners`).
    correct_locking : bool, optional
        Remove the corner detector's pixel-locking bias per camera (default True; see
        :func:`calibrate_camera`).
    threshold : float, optional
        A pair whose largest initial right-image error exceeds this many pixels is
        rejected as inconsistent (the toolbox's 50 px).
    suppress : sequence of int or str, optional
        Pairs to leave out.
    progress : bool, optional
        Show progress bars while detecting corners.
    force : bool, optional
        Calibrate even when the pairs look out of sync (a constant pairing offset, or
        fewer than half the pairs agreeing on the rig pose); default False raises.
        Identical left and right images are refused regardless.
    max_offset : int, optional
        Largest pairing offset (in pairs) tried when diagnosing pairs out of sync
        (default 3).

    Returns
    -------
    StereoCalibration
        ``.rig`` (StereoRig), ``.uncertainty`` (3 sigma for every intrinsic and om, T),
        ``.pixel_error``, per-pair residuals, ``.summary()`` in the toolbox's stereo
        layout, ``.save(path)``.

    Raises
    ------
    ValueError
        Different numbers of left and right views, fewer than 3 usable pairs (naming
        every rejected view and why), images of different sizes within a camera, an
        invalid ``pattern_size``; the same images given for both cameras; pairs out of
        sync (the message gives the offset found and how to re-pair the images) unless
        ``force``.

    Notes
    -----
    Each camera is first calibrated alone (:func:`calibrate_camera`, every view where
    it saw the board); the rig's ``(om, T)`` starts at the median of the per-pair
    relative poses; then both cameras' intrinsics, ``om``, ``T`` and the board pose in
    the left camera for every pair are refined together by
    :func:`scipy.optimize.least_squares` (the toolbox's ``go_calib_stereo``), with the
    toolbox's uncertainties ``3 * sqrt(diag((J^T J)^-1)) * std(residuals)``. Only pairs
    with the board in both images enter the joint refinement.

    Bad pairs are refused (:mod:`wingphoto.calibcheck`): identical left and right
    images; a pair whose own rig pose (from its two board poses) disagrees with the
    others (right-image error above ``max(1 px, 8 x`` the median) is rejected and named
    in ``rejected``; a constant offset between the left and right sequences is found by
    re-pairing left ``i`` with right ``i + k`` (``|k| <= max_offset``) and reported with
    the fix. ``result.pair_check`` keeps the per-pair table;
    :func:`wingphoto.calibcheck.cross_validate` compares two halves of the pairs.
    """
    pattern_size = _check_pattern_size(pattern_size)
    square_size = _check_square_size(square_size)
    for nm, seq in (("left_images", left_images), ("right_images", right_images)):
        if isinstance(seq, (str, os.PathLike)) or not hasattr(seq, "__len__"):
            raise ValueError(f"{nm} must be a sequence of images, paths or corner arrays, one per pair")
    if len(left_images) != len(right_images):
        raise ValueError(
            f"left_images has {len(left_images)} views but right_images has {len(right_images)}; "
            "give one left and one right image per board position, in the same order"
        )
    n = pattern_size[0] * pattern_size[1]
    if board_points is not None and not (isinstance(board_points, np.ndarray) and board_points.ndim == 2):
        first = next((b for b in board_points if b is not None), None)
        if first is not None and np.ndim(first) == 2:
            n = np.shape(first)[0]
    if names is not None:
        names = [str(s) for s in names]
        if len(names) != len(left_images):
            raise ValueError(f"names has {len(names)} entries but there are {len(left_images)} pairs")
        if regions:
            regions = {names.index(k) if isinstance(k, str) and k in names else k: v for k, v in regions.items()}
    kw = dict(regions=regions, window=window, method=method, progress=progress)
    views_l = _gather_views(left_images, pattern_size, n, names=None, what="left_images", **kw)
    views_r = _gather_views(right_images, pattern_size, n, names=None, what="right_images", **kw)
    size_l = _image_size_of(views_l, image_size, "left")
    size_r = _image_size_of(views_r, image_size, "right")
    boards = _board_list(board_points, len(views_l), pattern_size, square_size)
    est = _Estimate(
        skew=bool(estimate_skew), k3=bool(estimate_k3), tangential=bool(estimate_tangential),
        principal_point=bool(estimate_principal_point), aspect_ratio=bool(estimate_aspect_ratio),
    )
    pair_names = _pair_names(views_l, views_r, names)
    if names is not None:
        for v, nm in zip(views_l, pair_names):
            v.name = f"{nm} (left)"
        for v, nm in zip(views_r, pair_names):
            v.name = f"{nm} (right)"
    drop = _select(suppress, list(pair_names), "pair")
    return _stereo_from_views(
        views_l, views_r, boards, size_l, size_r, est, est, pattern_size, square_size,
        float(threshold), pair_names, suppressed=drop, locking=bool(correct_locking), force=bool(force),
        max_offset=int(max_offset),
    )


# ============================================================== error analysis
def suggest_suppress(result, *, factor=2.0):
    """Name the views whose reprojection error stands out (candidates to suppress).

    Parameters
    ----------
    result : CameraCalibration or StereoCalibration
    factor : float, optional
        A view is suggested when its mean reprojection error exceeds ``factor`` times
        the median over the used views (for a stereo pair, the worse of its two
        images). Default 2.

    Returns
    -------
    names : list of str
        View (or pair) names, worst first, at most as many as keep 3 views in use; pass
        them to ``result.suppress(names)``. Empty when no view stands out.

    Notes
    -----
    The toolbox leaves this judgement to the user reading the "Analyse error" figure
    (:func:`wingphoto.plots.plot_residuals`, :func:`wingphoto.plots.plot_view_errors`);
    this rule gives the same candidates for a view with a mislocated corner or a
    blurred board.
    """
    if not np.isfinite(factor) or factor <= 0:
        raise ValueError(f"factor must be a positive number, got {factor!r}")
    if isinstance(result, StereoCalibration):
        ve = result.view_errors
        err = np.full(len(ve), np.nan)
        seen = np.isfinite(ve).any(axis=1)
        err[seen] = np.nanmax(ve[seen], axis=1)  # unused pairs stay NaN (no all-NaN warning)
        names = result.pairs
    elif isinstance(result, CameraCalibration):
        err = result.view_errors
        names = result.views
    else:
        raise ValueError(f"result must be a CameraCalibration or StereoCalibration, got {type(result).__name__}")
    used = np.flatnonzero(np.asarray(result.used))
    med = float(np.median(err[used]))
    bad = [i for i in used if err[i] > factor * med]
    bad.sort(key=lambda i: -err[i])
    return [names[i] for i in bad[: max(0, len(used) - _MIN_VIEWS)]]
