"""Checkerboards posed by the pan-tilt device: the calibration image pairs."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..camera import StereoRig, rodrigues_inverse
from .raster import _check_common, _finish
from .rig import LEVELS, _camera_key, _image_size, _supersample_rays, scene_frame, thesis_rig




# ====================================================================== checkerboards
def pan_tilt_schedule(n_tilts=3, n_pans=7, *, tilt_deg=20.0, pan_deg=30.0, order="raster"):
    """Board angles of the pan-tilt device's poses (:func:`wingphoto.pantilt.pan_tilt_schedule`).

    Parameters
    ----------
    n_tilts, n_pans : int
        Number of tilt and pan stops (the thesis: 3 x 7 = 21 poses).
    tilt_deg, pan_deg : float
        Largest tilt and pan of the rendered board, degrees; the device's stops, sorted
        by servo angle, become evenly spaced board angles in ``[-tilt_deg, tilt_deg]`` and
        ``[-pan_deg, pan_deg]`` (0 when a single stop).
    order : {"raster", "capture"}, optional
        ``"raster"`` (default): sorted tilt-major, tilt and pan increasing (the order of
        ``data-samples/calibration``); ``"capture"``: the device's order (PanTilt.m's
        serpentine: the pan sweeps forward, back, forward; the neutral step left out).

    Returns
    -------
    angles : (n_tilts * n_pans, 2) ndarray
        Rows ``(tilt, pan)`` in degrees; in raster order pose ``k`` has tilt ``k // n_pans``.

    Notes
    -----
    The one schedule is :func:`wingphoto.pantilt.pan_tilt_schedule` (PanTilt.m's pulse
    widths). Its servo angles (pan +-90 deg at 1.3/1.7 ms on the HS-311; tilt +50, 0,
    -90 deg on the S03N) would turn a board edge-on, so the rendered board takes the
    stops' ranks, not the servo angles: stop ``i`` of ``n`` is at
    ``linspace(-max, max, n)[i]``, the highest tilt pulse (2.0 ms, the device's first
    row) at ``+tilt_deg``.

    Examples
    --------
    >>> pan_tilt_schedule(1, 3, pan_deg=10).tolist()
    [[0.0, -10.0], [0.0, 0.0], [0.0, 10.0]]
    >>> pan_tilt_schedule(3, 2, order="capture").tolist()
    [[20.0, -30.0], [20.0, 30.0], [0.0, 30.0], [0.0, -30.0], [-20.0, -30.0], [-20.0, 30.0]]
    """
    from ..pantilt import pan_tilt_schedule as device_schedule

    n_tilts, n_pans = int(n_tilts), int(n_pans)
    if n_tilts < 1 or n_pans < 1:
        raise ValueError(f"n_tilts and n_pans must be >= 1, got {n_tilts}, {n_pans}")
    if order not in ("raster", "capture"):
        raise ValueError(f"order must be 'raster' or 'capture', got {order!r}")
    steps = device_schedule(n_tilts, n_pans, neutral_ms=None)
    tilts = np.linspace(-tilt_deg, tilt_deg, n_tilts) if n_tilts > 1 else np.zeros(1)
    pans = np.linspace(-pan_deg, pan_deg, n_pans) if n_pans > 1 else np.zeros(1)
    ti, pi = steps["tilt_index"].to_numpy(), steps["pan_index"].to_numpy()
    if order == "raster":
        k = np.lexsort((pi, ti))
        ti, pi = ti[k], pi[k]
    return np.column_stack([tilts[ti], pans[pi]])


def _rot_x(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def _rot_z(rad):
    c, s = math.cos(rad), math.sin(rad)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _pan_tilt_rotation(axes, tilt, pan):
    """Rotation (left frame) of a body held by the pan-tilt unit.

    The unit pans about the scene's vertical axis ``b`` and then tilts about the
    (panned) horizontal axis; at (0, 0) the body's x, y, z axes are ``a, b, n``.
    """
    return axes @ _rot_y(pan) @ _rot_x(tilt)


def _board_colour(u, v, wu, wv, nx, ny, border):
    """Anti-aliased board reflectance in [0, 1] at board coordinates in square units.

    ``u, v`` are board coordinates in squares with the inner corners at integers
    ``0..nx-1`` and ``0..ny-1``; ``wu, wv`` the size of one sample in the same units.
    The pattern's (nx+1) x (ny+1) squares span ``[-1, nx] x [-1, ny]``; the square whose
    corner is the first inner corner, ``[-1, 0) x [-1, 0)``, is black. A white border of
    ``border`` squares surrounds the pattern. Returns (reflectance, board coverage).
    """
    half_u = np.maximum(np.float32(0.5) * wu, np.float32(1e-6))
    half_v = np.maximum(np.float32(0.5) * wv, np.float32(1e-6))

    def signed(t, half, n):
        # +-1 by square parity, ramping to 0 across the interior grid lines 0..n-1 only
        # (the pattern's outline is anti-aliased by ``inside`` below)
        k = np.clip(np.rint(t), 0, n - 1)
        ramp = np.minimum(np.abs(t - k) / half, np.float32(1.0))
        # parity of the square, clamped inside the pattern so that it does not flip on
        # the outline (where the outline's own coverage ramp takes over)
        tc = np.clip(t, -0.999, n - 0.001)
        odd = (np.floor(tc).astype(np.int32) & 1).astype(np.float32)
        return ramp * (np.float32(1.0) - np.float32(2.0) * odd)

    def inside(t, lo, hi, half):
        # coverage of the interval [lo, hi] (wider than a sample), linear across its ends
        return np.clip(np.minimum(t - lo, hi - t) / (np.float32(2.0) * half) + np.float32(0.5), 0, 1)

    gu = signed(u, half_u, nx)
    gv = signed(v, half_v, ny)
    # floor(u) + floor(v) even (as for the (-1, -1) square) -> black
    checker = np.float32(0.5) - np.float32(0.5) * gu * gv
    pattern = inside(u, -1.0, nx, half_u) * inside(v, -1.0, ny, half_v)
    board = inside(u, -1.0 - border, nx + border, half_u) * inside(v, -1.0 - border, ny + border, half_v)
    refl = pattern * checker + (np.float32(1.0) - pattern)
    return refl, board


def _render_board(camera, Rb, Tb, pattern_size, square_size, *, ss, border, levels):
    """Noise-free float image of a board at pose (Rb, Tb) (board -> this camera's frame).

    Only the bounding box of the board's projected outline (plus a margin) is
    evaluated; the rest of the image is the surround level.
    """
    w, h = _image_size(camera)
    nx, ny = pattern_size
    black, white, surround = levels
    img = np.full((h, w), surround, dtype=np.float32)
    # bounding box of the board's outline, sampled along its edges (distortion bends them)
    lo_u, hi_u, lo_v, hi_v = -1.0 - border, nx + border, -1.0 - border, ny + border
    s = np.linspace(0.0, 1.0, 17)
    edge = np.concatenate([
        np.column_stack([lo_u + (hi_u - lo_u) * s, np.full_like(s, lo_v)]),
        np.column_stack([lo_u + (hi_u - lo_u) * s, np.full_like(s, hi_v)]),
        np.column_stack([np.full_like(s, lo_u), lo_v + (hi_v - lo_v) * s]),
        np.column_stack([np.full_like(s, hi_u), lo_v + (hi_v - lo_v) * s]),
    ]) * square_size
    Xe = np.column_stack([edge, np.zeros(len(edge))]) @ Rb.T + Tb
    if np.any(Xe[:, 2] <= 0):  # part of the board behind the camera: evaluate everything
        x0, y0, x1, y1 = 0, 0, w, h
    else:
        xe = camera.project(Xe)
        x0 = int(np.clip(np.floor(xe[:, 0].min()) - 3, 0, w))
        x1 = int(np.clip(np.ceil(xe[:, 0].max()) + 4, 0, w))
        y0 = int(np.clip(np.floor(xe[:, 1].min()) - 3, 0, h))
        y1 = int(np.clip(np.ceil(xe[:, 1].max()) + 4, 0, h))
    if x1 - x0 < 2 or y1 - y0 < 2:
        return img
    rays = _supersample_rays(_camera_key(camera), ss)[y0 * ss : y1 * ss, x0 * ss : x1 * ss]
    xn = rays[..., 0]
    yn = rays[..., 1]
    Rt = Rb.T.astype(np.float32)
    o = (Rb.T @ Tb).astype(np.float32)
    # ray d = (xn, yn, 1) in board coordinates: q = R^T d; point = t q - o with z = 0
    qx = Rt[0, 0] * xn + Rt[0, 1] * yn + Rt[0, 2]
    qy = Rt[1, 0] * xn + Rt[1, 1] * yn + Rt[1, 2]
    qz = Rt[2, 0] * xn + Rt[2, 1] * yn + Rt[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = o[2] / qz
    far = np.float32(1e6)
    inv_sq = np.float32(1.0 / square_size)
    u = np.where(t > 0, (t * qx - o[0]) * inv_sq, far)
    v = np.where(t > 0, (t * qy - o[1]) * inv_sq, far)
    # size of one sample in board units (for the analytic anti-aliasing ramp)
    def step(a, axis):
        d = np.abs(np.diff(a, axis=axis))
        return np.concatenate([d, d.take([-1], axis=axis)], axis=axis)

    refl, board = _board_colour(
        u, v, step(u, 1) + step(u, 0), step(v, 1) + step(v, 0), nx, ny, border
    )
    val = board * (black + (white - black) * refl) + (np.float32(1.0) - board) * np.float32(surround)
    img[y0:y1, x0:x1] = val.reshape(y1 - y0, ss, x1 - x0, ss).mean(axis=(1, 3))
    return img


@dataclass(frozen=True)
class CalibrationSet:
    """Rendered checkerboard pairs and their ground truth (see :func:`render_calibration_set`).

    Attributes
    ----------
    left_images, right_images : list of (H, W) ndarray
        One image per pose (``dtype`` as requested, uint8 by default).
    rig : StereoRig
        The true rig that rendered them.
    board_points : (M, 3) ndarray
        Inner corners in the board frame, mm, ``z = 0``; ``M = nx * ny`` in OpenCV's
        order: row by row (``nx`` corners per row along the board's x axis), first
        corner at the origin.
    corners_left, corners_right : list of (M, 2) ndarray
        True projections of ``board_points`` for each pose (px), in the order above,
        which is also the order ``cv2.findChessboardCorners`` reports them for these
        poses; NaN for a corner outside the image.
    poses : list of (om, T)
        Board -> left camera: ``X_left = R(om) @ X_board + T`` (mm).
    pattern_size : (int, int)
        Inner corners (per row, per column), OpenCV's ``patternSize``.
    square_size : float
        Side of a square, mm.
    noise_std : float
        Standard deviation of the additive noise, grey levels (8-bit scale).
    blur_sigma : float
        Gaussian optics blur, px.
    angles_deg : (K, 2) ndarray
        (tilt, pan) of each pose, degrees.
    """

    left_images: list
    right_images: list
    rig: StereoRig
    board_points: np.ndarray
    corners_left: list
    corners_right: list
    poses: list
    pattern_size: tuple
    square_size: float
    noise_std: float
    blur_sigma: float = 0.0
    angles_deg: np.ndarray = None

    def __post_init__(self):
        bp = np.array(self.board_points, dtype=np.float64)
        bp.setflags(write=False)
        object.__setattr__(self, "board_points", bp)

    def __len__(self):
        return len(self.left_images)

    def summary(self):
        """One-paragraph description of the set (str)."""
        img = self.left_images[0]
        seen = [int(np.isfinite(c[:, 0]).sum()) for c in self.corners_left + self.corners_right]
        return (
            f"CalibrationSet: {len(self)} stereo pairs {img.shape[1]}x{img.shape[0]} {img.dtype}, "
            f"pattern {self.pattern_size[0]}x{self.pattern_size[1]} inner corners, "
            f"squares {self.square_size:g} mm, noise {self.noise_std:g} grey levels, "
            f"blur {self.blur_sigma:g} px; corners in view per image {min(seen)}-{max(seen)}"
        )


def render_calibration_set(
    rig=None,
    *,
    pattern_size=(9, 6),
    square_size=8.0,
    n_tilts=3,
    n_pans=7,
    tilt_deg=20.0,
    pan_deg=30.0,
    noise_std=1.0,
    blur_sigma=0.6,
    supersample=2,
    dtype=np.uint8,
    seed=0,
):
    """Render checkerboard calibration pairs posed by a pan-tilt schedule.

    Parameters
    ----------
    rig : StereoRig, optional
        Cameras to render with (default :func:`thesis_rig`); need ``image_size``.
    pattern_size : (int, int), optional
        Inner corners per row and per column (OpenCV ``patternSize``), default (9, 6).
    square_size : float, optional
        Square side in mm (default 8: the inner corners span about 60 % of the image
        width and the board, white border included, stays inside both images for every
        pose of the default schedule).
    n_tilts, n_pans : int, optional
        Pan-tilt stops (default 3 x 7 = 21 poses); see :func:`pan_tilt_schedule`.
    tilt_deg, pan_deg : float, optional
        Largest tilt and pan (degrees) of the schedule.
    noise_std : float, optional
        Additive Gaussian noise, grey levels on the 8-bit scale (default 1).
    blur_sigma : float, optional
        Gaussian optics blur, px (default 0.6).
    supersample : int, optional
        Samples per pixel along each axis (default 2, with analytic edge coverage).
    dtype : numpy dtype, optional
        ``np.uint8`` (default), ``np.uint16`` (x 257) or a float type (8-bit scale).
    seed : int, optional
        Seed of the noise.

    Returns
    -------
    CalibrationSet

    Notes
    -----
    The board's pattern is (nx + 1) x (ny + 1) squares with a one-square white border,
    on a grey surround (levels in ``LEVELS``). The pan-tilt unit holds the board's centre
    at the rig's working point (:func:`scene_frame`), facing the bisector of the two
    viewing directions at (0, 0), and turns it about the vertical (pan) and then the
    horizontal (tilt) axis. Each sample's viewing ray is intersected with the board
    plane and the square colour evaluated there, so the lens distortion is rendered
    exactly. The board is seen upright in both views (board x to image right, y down),
    which is what makes OpenCV's corner order equal ``board_points``' order.

    Examples
    --------
    >>> cs = render_calibration_set(n_tilts=1, n_pans=2)
    >>> len(cs.left_images), cs.left_images[0].shape, cs.corners_left[0].shape
    (2, (512, 512), (54, 2))
    """
    rig = thesis_rig() if rig is None else rig
    if not isinstance(rig, StereoRig):
        raise ValueError(f"rig must be a wingphoto.StereoRig, got {type(rig).__name__}")
    nx, ny = (int(v) for v in pattern_size)
    if nx < 2 or ny < 2:
        raise ValueError(f"pattern_size must be (inner corners per row, per column) >= 2, got {pattern_size}")
    if not square_size > 0:
        raise ValueError(f"square_size must be positive (mm), got {square_size}")
    _check_common(noise_std, blur_sigma, dtype)
    ss = int(supersample)
    if ss < 1:
        raise ValueError(f"supersample must be >= 1, got {supersample}")
    for cam in (rig.left, rig.right):
        _image_size(cam)
    rng = np.random.default_rng(seed)
    S, axes = scene_frame(rig)
    angles = pan_tilt_schedule(n_tilts, n_pans, tilt_deg=tilt_deg, pan_deg=pan_deg)
    gx, gy = np.meshgrid(np.arange(nx) * float(square_size), np.arange(ny) * float(square_size))
    board_points = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(nx * ny)])
    centre = np.array([(nx - 1) / 2, (ny - 1) / 2, 0.0]) * square_size
    levels = (LEVELS["board_black"], LEVELS["board_white"], LEVELS["board_surround"])
    out = {"left": [], "right": []}
    corners = {"left": [], "right": []}
    poses = []
    for tilt, pan in angles:
        Rb = _pan_tilt_rotation(axes, tilt, pan)
        Tb = S - Rb @ centre
        poses.append((rodrigues_inverse(Rb), Tb.copy()))
        X = board_points @ Rb.T + Tb
        for side, (R_, T_) in (("left", (Rb, Tb)), ("right", (rig.R @ Rb, rig.R @ Tb + rig.T))):
            cam = getattr(rig, side)
            img = _render_board(cam, R_, T_, (nx, ny), square_size, ss=ss, border=1.0, levels=levels)
            out[side].append(_finish(img, blur_sigma=blur_sigma, noise_std=noise_std, rng=rng, dtype=dtype))
            Xc = X if side == "left" else rig.to_right(X)
            x = cam.project(Xc)
            w, h = cam.image_size
            outside = (x[:, 0] < -0.5) | (x[:, 0] > w - 0.5) | (x[:, 1] < -0.5) | (x[:, 1] > h - 0.5)
            x[outside] = np.nan
            x.setflags(write=False)
            corners[side].append(x)
    return CalibrationSet(
        left_images=out["left"],
        right_images=out["right"],
        rig=rig,
        board_points=board_points,
        corners_left=corners["left"],
        corners_right=corners["right"],
        poses=poses,
        pattern_size=(nx, ny),
        square_size=float(square_size),
        noise_std=float(noise_std),
        blur_sigma=float(blur_sigma),
        angles_deg=angles,
    )
