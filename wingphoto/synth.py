"""Synthetic stereo photogrammetry with exact ground truth: rig, boards, flapping wing.

This is the library's ground-truth generator. It renders, through the full lens model
of :class:`~wingphoto.camera.Camera` (distortion included), what the thesis' two
high-speed cameras saw, and returns every image together with the truth that made it:

* :func:`thesis_rig` - a 512 x 512 stereo rig like the thesis' (optionally perturbed);
* :func:`render_calibration_set` - checkerboard pairs posed by a pan-tilt schedule;
* :func:`render_flapping` - a flapping, bending, pitching, cambered wing with white
  painted markers, a two-marker mount and six static reference dots, optionally with
  glare and motion blur (``preset="hard"`` switches on everything at once);
* :func:`render_rigid_target` - two markers a known distance apart swept by the pan-tilt;
* :func:`write_samples` - the committed ``data-samples/`` folder.

Frames and units (``docs/conventions.md``)
------------------------------------------
Everything 3D is in millimetres in the **left camera frame** (x right, y down, z
forward); the right camera sees ``X_right = R(om) X_left + T``. Pixels are (x, y) with
(0, 0) the centre of the top-left pixel. Grey levels are quoted on the 8-bit scale
(0-255) whatever the output dtype: ``uint16`` output is the same image times 257,
float output is the unrounded 8-bit-scale image.

The scene
---------
The two optical axes of the thesis rig converge about 407 mm in front of the left
camera. :func:`scene_frame` returns that convergence point ``S`` and an orthonormal
basis ``(a, b, n)``: ``n`` bisects the two viewing directions (pointing away from the
cameras), ``a`` is horizontal (image right) and ``b = n x a`` points image-down. Every
scene (board centre, wing hinge, reference dots) is placed in these coordinates, so it
stays in view of both cameras for perturbed rigs too. At ``S`` the common field of view
is about 108 mm (a) x 100 mm (b); one millimetre is about 4.5 px.

Rendering
---------
Each pixel is supersampled on a regular grid; each sample's viewing ray is obtained by
undistorting the sample position (:meth:`Camera.normalize`, the toolbox's 20-iteration
inverse, evaluated exactly at the pixel centres and interpolated bilinearly between
them, an error below 1e-4 px) and intersected with the object's plane. The edge of a
square or a disc is anti-aliased analytically within each sample (a linear coverage
ramp one sample wide across the edge), which makes the rendered edges unbiased to a
few thousandths of a pixel. The image is then blurred by a Gaussian (optics, in px),
receives additive Gaussian noise (grey levels) drawn from ``np.random.default_rng(seed)``,
and is clipped to 0-255 (sensor saturation) and rounded. Everything is deterministic
for a seed.
"""
from __future__ import annotations

import functools
import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np
import pandas as pd

from .camera import Camera, StereoRig, rodrigues_inverse

__all__ = [
    "CalibrationSet",
    "StereoSequence",
    "thesis_rig",
    "scene_frame",
    "pan_tilt_schedule",
    "flapping_preset",
    "render_calibration_set",
    "render_flapping",
    "render_rigid_target",
    "write_samples",
    "rig_to_dict",
    "rig_from_dict",
    "load_rig",
    "render_discs",
]

log = logging.getLogger(__name__)

IMAGE_SIZE = (512, 512)
#: Grey levels (8-bit scale) of the rendered scenes (read-only).
LEVELS = MappingProxyType({
    "board_black": 35.0,
    "board_white": 215.0,
    "board_surround": 80.0,
    "background": 6.0,
    "membrane": 30.0,
    "paint": 235.0,
})
CAMERAS = ("left", "right")


# =========================================================================== the rig
def thesis_rig(*, seed=None, jitter=0.0):
    """Return a stereo rig like the thesis' two high-speed cameras.

    Parameters
    ----------
    seed : int or None, optional
        Seed of the perturbation; only used when ``jitter > 0`` (then required).
    jitter : float, optional
        Scale of a random perturbation of every parameter (default 0: the nominal rig).
        ``jitter=1`` draws, per camera, ``fc`` +- 12 px, ``cc`` +- 6 px, ``k1`` +- 0.04,
        ``k2`` +- 0.08, ``p1, p2`` +- 3e-4 (one standard deviation each), and for the
        pair ``om`` +- 0.005 rad per component and ``T`` +- 2 mm per component:
        "another rig of the same design". Perturbed rigs keep the scenes of this module
        in view of both cameras for ``jitter <= 1``.

    Returns
    -------
    rig : StereoRig
        512 x 512 cameras (``image_size=(512, 512)``), ``fc`` about 1840 px, small
        radial and tangential distortion (``k3 = 0``, ``alpha_c = 0``, as the toolbox
        estimates by default), ``om = [0.026, 0.733, 0.003]`` (the right camera looks
        about 42 deg to the left of the left camera's axis) and
        ``T = [-272.7, -1.5, 108.7]`` mm.

    Raises
    ------
    ValueError
        If ``jitter`` is negative or ``jitter > 0`` without a ``seed``.

    Examples
    --------
    >>> rig = thesis_rig()
    >>> rig.left.image_size, round(rig.baseline, 1)
    ((512, 512), 293.6)
    >>> thesis_rig(seed=3, jitter=1.0) == thesis_rig(seed=3, jitter=1.0)
    True
    """
    jitter = float(jitter)
    if not np.isfinite(jitter) or jitter < 0:
        raise ValueError(f"jitter must be a non-negative scale, got {jitter}")
    left = dict(fc=[1845.2, 1842.6], cc=[258.4, 251.7], kc=[-0.12, 0.25, 4e-4, -3e-4, 0.0])
    right = dict(fc=[1838.1, 1836.4], cc=[252.6, 259.3], kc=[-0.10, 0.18, -3e-4, 5e-4, 0.0])
    om = np.array([0.026, 0.733, 0.003])
    T = np.array([-272.7, -1.5, 108.7])
    if jitter > 0:
        if seed is None:
            raise ValueError("thesis_rig(jitter>0) needs a seed=... so that the perturbed rig is reproducible")
        rng = np.random.default_rng(seed)
        for cam in (left, right):
            cam["fc"] = np.add(cam["fc"], jitter * 12.0 * rng.standard_normal(2))
            cam["cc"] = np.add(cam["cc"], jitter * 6.0 * rng.standard_normal(2))
            sd = np.array([0.04, 0.08, 3e-4, 3e-4, 0.0])
            cam["kc"] = np.add(cam["kc"], jitter * sd * rng.standard_normal(5))
        om = om + jitter * 0.005 * rng.standard_normal(3)
        T = T + jitter * 2.0 * rng.standard_normal(3)
    return StereoRig(
        Camera(**left, image_size=IMAGE_SIZE), Camera(**right, image_size=IMAGE_SIZE), om=om, T=T
    )


def _optical_axis(camera):
    """Unit direction of the ray through the principal point, in that camera's frame."""
    xn = camera.normalize(camera.cc)
    d = np.array([xn[0], xn[1], 1.0])
    return d / np.linalg.norm(d)


def scene_frame(rig):
    """Return the working point of a rig and the scene basis used by every render.

    Parameters
    ----------
    rig : StereoRig

    Returns
    -------
    origin : (3,) ndarray
        Midpoint of the common perpendicular of the two optical axes (mm, left frame):
        the point both cameras look at (about [0, 5, 407] for :func:`thesis_rig`).
    axes : (3, 3) ndarray
        Columns ``a, b, n``: ``n`` is the unit bisector of the two viewing directions
        pointing away from the cameras, ``a`` the left camera's x axis made orthogonal to
        ``n`` (image right), ``b = n x a`` (image down). A scene point with scene
        coordinates ``q`` is ``origin + axes @ q`` in the left camera frame.

    Examples
    --------
    >>> S, axes = scene_frame(thesis_rig())
    >>> np.round(S).tolist()
    [0.0, 5.0, 407.0]
    """
    R = rig.R
    c_right = -R.T @ rig.T  # right optical centre in the left frame
    dl = _optical_axis(rig.left)
    dr = R.T @ _optical_axis(rig.right)
    # closest points of the lines s*dl and c_right + t*dr
    w0 = -c_right
    a, b, c = dl @ dl, dl @ dr, dr @ dr
    d, e = dl @ w0, dr @ w0
    den = a * c - b * b
    if abs(den) < 1e-12:
        raise ValueError("the rig's optical axes are parallel; scene_frame needs converging cameras")
    s = (b * e - c * d) / den
    t = (a * e - b * d) / den
    origin = 0.5 * (s * dl + c_right + t * dr)
    n = dl + dr
    n /= np.linalg.norm(n)
    ax = np.array([1.0, 0.0, 0.0]) - n[0] * n
    ax /= np.linalg.norm(ax)
    bx = np.cross(n, ax)
    return origin, np.column_stack([ax, bx, n])


def rig_to_dict(rig):
    """Rig parameters under the Bouguet toolbox names (JSON-ready lists).

    Keys ``fc_left, cc_left, kc_left, alpha_c_left, fc_right, ..., om, T`` and
    ``image_size`` ([width, height]).
    """
    out = {}
    for side in CAMERAS:
        cam = getattr(rig, side)
        out[f"fc_{side}"] = cam.fc.tolist()
        out[f"cc_{side}"] = cam.cc.tolist()
        out[f"kc_{side}"] = cam.kc.tolist()
        out[f"alpha_c_{side}"] = float(cam.alpha_c)
    out["om"] = rig.om.tolist()
    out["T"] = rig.T.tolist()
    out["image_size"] = list(rig.left.image_size) if rig.left.image_size else None
    return out


def rig_from_dict(d):
    """Inverse of :func:`rig_to_dict`."""
    size = d.get("image_size")
    cams = [
        Camera(
            fc=d[f"fc_{s}"], cc=d[f"cc_{s}"], kc=d[f"kc_{s}"], alpha_c=d[f"alpha_c_{s}"],
            image_size=None if size is None else tuple(size),
        )
        for s in CAMERAS
    ]
    return StereoRig(cams[0], cams[1], om=d["om"], T=d["T"])


def load_rig(path):
    """Read a rig saved as JSON under the Bouguet names (``data-samples/rig.json``).

    Parameters
    ----------
    path : str or Path
        JSON file written by :func:`write_samples` (see :func:`rig_to_dict`).

    Returns
    -------
    StereoRig

    Raises
    ------
    FileNotFoundError
        When ``path`` does not exist.
    ValueError
        When the file is not valid JSON or lacks a Bouguet name.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"rig file {path} not found")
    try:
        return rig_from_dict(json.loads(path.read_text()))
    except json.JSONDecodeError as exc:
        raise ValueError(f"rig file {path} is not valid JSON: {exc}") from None
    except KeyError as exc:
        raise ValueError(f"rig file {path} lacks {exc.args[0]!r}; expected the Bouguet names fc_left, cc_left, ...") from None


def render_discs(centres, diameters, shape, *, bg=30.0, amp=180.0, noise_std=0.0, rng=None,
                 dtype=np.uint8, ss=8):
    """Bright anti-aliased discs on a flat background: a minimal 2D scene for unit tests.

    Unlike :func:`render_flapping` there is no camera: each disc's area coverage of each
    pixel is estimated by ``ss x ss`` supersampling, so a disc's intensity centroid is its
    centre to ~1e-3 px.

    Parameters
    ----------
    centres : (N, 2) array_like
        Disc centres (x, y) in px; rows with NaN are skipped.
    diameters : (N,) array_like
        Disc diameters in px.
    shape : (H, W)
        Image shape.
    bg, amp : float
        Background level and disc brightness above it (grey levels).
    noise_std : float
        Additive Gaussian noise (grey levels) drawn from ``rng``
        (``np.random.default_rng(0)`` when None).
    dtype : numpy dtype
        Output type; integer types are rounded and clipped.
    ss : int
        Supersampling per axis.

    Returns
    -------
    (H, W) ndarray of ``dtype``
    """
    H, W = shape
    img = np.full(shape, bg, float)
    o = (np.arange(ss) + 0.5) / ss - 0.5
    for (cx, cy), d in zip(centres, diameters):
        if not (np.isfinite(cx) and np.isfinite(cy)):
            continue
        r = d / 2
        x0, x1 = max(int(np.floor(cx - r - 1)), 0), min(int(np.ceil(cx + r + 2)), W)
        y0, y1 = max(int(np.floor(cy - r - 1)), 0), min(int(np.ceil(cy + r + 2)), H)
        if x1 <= x0 or y1 <= y0:
            continue
        xs = (np.arange(x0, x1)[:, None] + o[None, :]).ravel()
        ys = (np.arange(y0, y1)[:, None] + o[None, :]).ravel()
        inside = ((xs[None, :] - cx) ** 2 + (ys[:, None] - cy) ** 2) <= r * r
        img[y0:y1, x0:x1] += amp * inside.reshape(y1 - y0, ss, x1 - x0, ss).mean(axis=(1, 3))
    if noise_std:
        img += (np.random.default_rng(0) if rng is None else rng).normal(0.0, noise_std, shape)
    if np.issubdtype(dtype, np.integer):
        img = np.clip(np.round(img), 0, np.iinfo(dtype).max)
    return img.astype(dtype)


# ====================================================================== ray machinery
def _camera_key(camera):
    return (
        tuple(camera.fc), tuple(camera.cc), tuple(camera.kc), camera.alpha_c, camera.image_size,
    )


def _image_size(camera, name="rig"):
    if camera.image_size is None:
        raise ValueError(f"{name} cameras need an image_size=(width, height) to be rendered")
    return camera.image_size


@functools.lru_cache(maxsize=8)
def _pixel_rays(key):
    """Normalised rays (xn, yn) of every pixel centre, padded by one pixel: (H+2, W+2, 2)."""
    fc, cc, kc, alpha_c, (w, h) = key
    cam = Camera(fc=fc, cc=cc, kc=kc, alpha_c=alpha_c, image_size=(w, h))
    xs, ys = np.meshgrid(np.arange(-1, w + 1, dtype=np.float64), np.arange(-1, h + 1, dtype=np.float64))
    xn = cam.normalize(np.column_stack([xs.ravel(), ys.ravel()]))
    grid = xn.reshape(h + 2, w + 2, 2)
    grid.setflags(write=False)
    return grid


@functools.lru_cache(maxsize=4)
def _supersample_rays(key, ss):
    """Undistorted rays of every supersample of the image: ``(H*ss, W*ss, 2)`` float32.

    Sample ``(i, j)`` sits at pixel ``((j + 0.5) / ss - 0.5, (i + 0.5) / ss - 0.5)``.
    The toolbox's undistortion (:meth:`Camera.normalize`) is evaluated exactly at the
    pixel centres and interpolated bilinearly between them; the undistortion is smooth,
    so this errs by < 1e-7 in normalised units (< 1e-4 px). Cached per camera and ``ss``.
    """
    w, h = key[4]
    padded = _pixel_rays(key).astype(np.float32)  # pixel centres -1 .. w
    # cv2.resize (bilinear) samples the source at (c + 0.5) / ss - 0.5: exactly the
    # supersample centres; the one-pixel padding keeps the border samples interpolated
    big = cv2.resize(padded, ((w + 2) * ss, (h + 2) * ss), interpolation=cv2.INTER_LINEAR)
    out = np.ascontiguousarray(big[ss : ss * (h + 1), ss : ss * (w + 1)])
    out.setflags(write=False)
    return out


def _finish(img, *, blur_sigma, noise_std, rng, dtype):
    """Optics blur, additive noise, saturation and conversion to ``dtype``."""
    img = np.asarray(img, dtype=np.float32)
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), sigmaX=float(blur_sigma), sigmaY=float(blur_sigma),
                               borderType=cv2.BORDER_REPLICATE)
    if noise_std > 0:
        img = img + np.float32(noise_std) * rng.standard_normal(img.shape, dtype=np.float32)
    img = np.clip(img, 0.0, 255.0)
    dtype = np.dtype(dtype)
    if dtype == np.uint8:
        return np.rint(img).astype(np.uint8)
    if dtype == np.uint16:
        return np.rint(img * 257.0).astype(np.uint16)
    if dtype.kind == "f":
        return img.astype(dtype)
    raise ValueError(f"dtype must be uint8, uint16 or a float type, got {dtype}")


def _check_common(noise_std, blur_sigma, dtype):
    for name, v in (("noise_std", noise_std), ("blur_sigma", blur_sigma)):
        if not np.isfinite(v) or v < 0:
            raise ValueError(f"{name} must be a non-negative number (grey levels / px), got {v}")
    dt = np.dtype(dtype)
    if not (dt in (np.uint8, np.uint16) or dt.kind == "f"):
        raise ValueError(f"dtype must be np.uint8, np.uint16 or a float type, got {dt}")


# ====================================================================== checkerboards
def pan_tilt_schedule(n_tilts=3, n_pans=7, *, tilt_deg=20.0, pan_deg=30.0):
    """Tilt and pan angles of the pan-tilt unit, tilt-major (raster) order.

    Parameters
    ----------
    n_tilts, n_pans : int
        Number of tilt and pan stops (the thesis: 3 x 7 = 21 poses).
    tilt_deg, pan_deg : float
        Largest tilt and pan, degrees; the stops are evenly spaced in
        ``[-tilt_deg, tilt_deg]`` and ``[-pan_deg, pan_deg]`` (0 when a single stop).

    Returns
    -------
    angles : (n_tilts * n_pans, 2) ndarray
        Rows ``(tilt, pan)`` in degrees; pose ``k`` has tilt ``k // n_pans``.

    Examples
    --------
    >>> pan_tilt_schedule(1, 3, pan_deg=10).tolist()
    [[0.0, -10.0], [0.0, 0.0], [0.0, 10.0]]
    """
    n_tilts, n_pans = int(n_tilts), int(n_pans)
    if n_tilts < 1 or n_pans < 1:
        raise ValueError(f"n_tilts and n_pans must be >= 1, got {n_tilts}, {n_pans}")
    tilts = np.linspace(-tilt_deg, tilt_deg, n_tilts) if n_tilts > 1 else np.zeros(1)
    pans = np.linspace(-pan_deg, pan_deg, n_pans) if n_pans > 1 else np.zeros(1)
    T, P = np.meshgrid(tilts, pans, indexing="ij")
    return np.column_stack([T.ravel(), P.ravel()])


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


# ============================================================================= discs
def _disc_basis(normals):
    """Orthonormal in-plane axes (e1, e2) for unit normals (M, 3)."""
    ref = np.where(np.abs(normals[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(normals, ref)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(normals, e1)
    return e1, e2


def _disc_geometry(camera, centers, normals, radii):
    """Projected centre, Jacobian and image half-extents of discs (this camera's frame).

    Returns
    -------
    p0 : (M, 2) projected centres, px.
    J : (M, 2, 2) pixels per mm along the disc's in-plane axes ``e1, e2``.
    e1, e2 : (M, 3) in-plane unit axes.
    half : (M, 2) half width and height of the projected disc's bounding box, px.
    """
    e1, e2 = _disc_basis(normals)
    p0 = camera.project(centers)
    d = 1e-3
    J = np.empty((len(centers), 2, 2))
    J[:, :, 0] = (camera.project(centers + d * e1) - camera.project(centers - d * e1)) / (2 * d)
    J[:, :, 1] = (camera.project(centers + d * e2) - camera.project(centers - d * e2)) / (2 * d)
    half = radii[:, None] * np.linalg.norm(J, axis=2)
    return p0, J, e1, e2, half


def _disc_coverage(camera, centers, normals, radii, *, ss=4, geometry=None):
    """Anti-aliased pixel coverage of flat discs, each in a small patch.

    Parameters
    ----------
    camera : Camera
    centers, normals : (M, 3) ndarray
        Disc centres (mm) and unit normals in this camera's frame.
    radii : (M,) ndarray
        Disc radii, mm.
    ss : int
        Samples per pixel along each axis.

    Returns
    -------
    x0, y0 : (M,) int ndarray
        Top-left pixel of each patch.
    cov : (M, B, B) ndarray
        Fraction of each pixel covered by the disc.

    Notes
    -----
    Each sample's viewing ray (undistorted, see :func:`_supersample_rays`) is intersected with
    the disc's plane; the sample's coverage ramps linearly from 1 to 0 across the rim
    over the size of one sample measured along the radial direction in the disc plane
    (``(1/ss) / |J u_r|`` mm), an unbiased estimate of the covered fraction. Discs are
    thus foreshortened by their orientation and distorted by the lens exactly.
    """
    m = len(centers)
    p0, J, e1, e2, half = geometry if geometry is not None else _disc_geometry(camera, centers, normals, radii)
    b = int(np.ceil(2.0 * np.nanmax(half))) + 3 if m else 3
    b = min(b, 96)
    x0 = np.rint(np.nan_to_num(p0[:, 0], nan=-1e6)).astype(np.int64) - b // 2
    y0 = np.rint(np.nan_to_num(p0[:, 1], nan=-1e6)).astype(np.int64) - b // 2
    w, h = camera.image_size
    grid = _supersample_rays(_camera_key(camera), ss)
    # sample rows/columns in the supersampled grid (clamped outside the image: those
    # pixels are cropped away when compositing)
    k = np.arange(b * ss)
    rows = np.clip(y0[:, None] * ss + k, 0, h * ss - 1)
    cols = np.clip(x0[:, None] * ss + k, 0, w * ss - 1)
    rays = grid[rows[:, :, None], cols[:, None, :]]
    xn = rays[..., 0]
    yn = rays[..., 1]
    f32 = np.float32
    # work relative to the disc centre in float32 (sub-micrometre precision at 400 mm)
    nrm = normals.astype(f32)
    ctr = centers.astype(f32)
    n0, n1, n2 = (nrm[:, i, None, None] for i in range(3))
    nd = n0 * xn + n1 * yn + n2
    nc = np.sum(normals * centers, axis=1).astype(f32)[:, None, None]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = nc / nd
        px = t * xn - ctr[:, 0, None, None]
        py = t * yn - ctr[:, 1, None, None]
        pz = t - ctr[:, 2, None, None]
    e1f, e2f = e1.astype(f32), e2.astype(f32)
    with np.errstate(invalid="ignore", over="ignore"):
        u = px * e1f[:, 0, None, None] + py * e1f[:, 1, None, None] + pz * e1f[:, 2, None, None]
        v = px * e2f[:, 0, None, None] + py * e2f[:, 1, None, None] + pz * e2f[:, 2, None, None]
        rho = np.hypot(u, v)
    with np.errstate(divide="ignore", invalid="ignore"):
        ur = np.where(rho > 0, u / rho, f32(1.0))
        vr = np.where(rho > 0, v / rho, f32(0.0))
    Jf = J.astype(f32)
    jx = Jf[:, 0, 0, None, None] * ur + Jf[:, 0, 1, None, None] * vr
    jy = Jf[:, 1, 0, None, None] * ur + Jf[:, 1, 1, None, None] * vr
    width = f32(1.0 / ss) / np.maximum(np.hypot(jx, jy), f32(1e-9))  # one sample, mm, radially
    with np.errstate(invalid="ignore", over="ignore"):
        cov = np.clip((radii.astype(f32)[:, None, None] - rho) / width + f32(0.5), f32(0.0), f32(1.0))
    cov = np.where(np.isfinite(cov) & (t > 0), cov, f32(0.0))
    cov = cov.reshape(m, b, ss, b, ss).mean(axis=(2, 4))
    return x0, y0, cov


def _composite(img, x0, y0, cov, values):
    """Paint patches over ``img`` in order: ``img = img (1 - cov) + value cov``."""
    h, w = img.shape
    b = cov.shape[1]
    for k in range(len(x0)):
        xa, ya = int(x0[k]), int(y0[k])
        xs0, ys0 = max(xa, 0), max(ya, 0)
        xs1, ys1 = min(xa + b, w), min(ya + b, h)
        if xs1 <= xs0 or ys1 <= ys0:
            continue
        c = cov[k, ys0 - ya : ys1 - ya, xs0 - xa : xs1 - xa]
        region = img[ys0:ys1, xs0:xs1]
        region += c * (values[k] - region)


# ============================================================================ the wing
@dataclass(frozen=True)
class _WingModel:
    """Kinematics and geometry of the synthetic wing (scene coordinates, mm, s, deg)."""

    hinge: np.ndarray  # (3,) scene coordinates of the hinge
    span: float = 50.0
    root_chord: float = 22.0
    stroke_amplitude_deg: float = 80.0  # peak to peak
    pitch_deg: float = 25.0
    camber: float = 0.04
    bend_mm: float = 2.0
    flap_hz: float = 30.0
    phase_deg: float = 0.0

    def chord(self, sigma):
        sigma = np.clip(sigma, 0.0, 1.0)
        return self.root_chord * (1.0 - 0.45 * sigma) * np.sqrt(np.clip(1.0 - sigma**8, 0.0, 1.0))

    def angles(self, t):
        """Stroke angle, pitch angle (deg), signed camber and tip bending (mm) at times t."""
        th = 2 * np.pi * self.flap_hz * np.asarray(t, dtype=np.float64) + np.radians(self.phase_deg)
        stroke = -0.5 * self.stroke_amplitude_deg * np.cos(th)
        pitch = self.pitch_deg * np.sin(th)
        camber = self.camber * np.sin(th)
        bend = self.bend_mm * np.sin(th - np.radians(20.0))
        return stroke, pitch, camber, bend

    def surface(self, sigma, xi, t):
        """Scene coordinates of material points (sigma span fraction, xi chord fraction).

        ``sigma, xi`` broadcast together; ``t`` is a scalar time (s).
        """
        stroke, pitch, camber, bend = (float(v) for v in self.angles(t))
        sigma, xi = np.broadcast_arrays(np.asarray(sigma, float), np.asarray(xi, float))
        ch = self.chord(sigma)
        local = np.stack(
            [
                sigma * self.span,
                (xi - 0.25) * ch,
                bend * sigma**2 + camber * ch * 4.0 * xi * (1.0 - xi),
            ],
            axis=-1,
        )
        Rw = _rot_z(np.radians(stroke)) @ _rot_x(pitch)
        return local @ Rw.T + self.hinge

    def normals(self, sigma, xi, t):
        """Unit surface normals (scene coordinates) at material points."""
        e = 1e-4
        ds = self.surface(sigma + e, xi, t) - self.surface(sigma - e, xi, t)
        dx = self.surface(sigma, xi + e, t) - self.surface(sigma, xi - e, t)
        nrm = np.cross(ds, dx)
        return nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)


#: Wing markers: span fractions (tip to root) x chord fractions (leading to trailing edge).
_MARKER_SIGMA = np.array([0.86, 0.72, 0.58, 0.44, 0.30, 0.16])
_MARKER_XI = np.array([0.18, 0.50, 0.82])


def _n_wing_markers():
    """Number of wing markers of :func:`render_flapping` (points ``0 .. n - 1``)."""
    return len(_MARKER_SIGMA) * len(_MARKER_XI)


#: Their painted diameters, mm (numbered leading edge to trailing edge, tip to root).
_MARKER_DIAMETER = np.array(
    [1.5, 1.9, 1.6, 2.1, 1.7, 2.3, 1.8, 2.4, 1.9, 2.2, 1.6, 2.4, 2.0, 1.7, 2.3, 1.4, 2.1, 1.8]
)
_MOUNT = np.array([[-9.0, -2.0, 3.0], [-19.0, 2.0, 3.0]])  # hinge-relative scene coordinates
_MOUNT_DIAMETER = np.array([2.2, 1.8])
_REFERENCE_DIAMETER = 2.6
_WING_HINGE = np.array([-26.0, 0.0, 0.0])  # relative to the scene origin


def _reference_layout():
    """Scene coordinates of the 6 static reference dots on the background panel.

    The panel lies 15 mm behind the wing's hinge plane. The dots (top left, top right,
    middle left, middle right, bottom left, bottom right) were placed where, in both
    views of the nominal rig, they stay at least 29 px from anything the wing sweeps
    (110 deg stroke, 60 deg pitch) and about 48 px from the image border, so that they
    stay in view for perturbed rigs (``thesis_rig(jitter=1)``) too.
    """
    return np.array(
        [
            [-44.0, -44.0, 15.0],
            [44.0, -42.0, 15.0],
            [-44.0, -10.0, 15.0],
            [44.0, 8.0, 15.0],
            [-44.0, 40.0, 15.0],
            [44.0, 44.0, 15.0],
        ]
    )


# ========================================================================= sequences
def _frozen(a, dtype=None):
    a = np.array(a, dtype=dtype)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class StereoSequence:
    """A rendered stereo sequence of markers and its ground truth.

    Attributes
    ----------
    left, right : (T, H, W) ndarray
        The frames of each camera (uint8 by default; see ``dtype`` of the renderers).
    rig : StereoRig
        The true rig.
    points3d : (T, N, 3) ndarray
        Marker centres in mm in the left camera frame.
    points_left, points_right : (T, N, 2) ndarray
        True projections of ``points3d`` (``rig.project``), px, for every point and
        frame (also where the marker is not visible).
    visible_left, visible_right : (T, N) ndarray of bool
        Whether the marker can be measured in that view (see Notes).
    kinds : (N,) ndarray of str
        ``"wing"``, ``"mount"``, ``"reference"`` or ``"target"``.
    marker_diameter_mm : (N,) ndarray
        Painted diameter of each marker, mm.
    fps : float
        Frame rate; frame ``k`` is the image at time ``times[k] = k / fps`` (the middle
        of its exposure).
    times : (T,) ndarray
        Seconds.
    noise_std, blur_sigma : float
        Additive noise (grey levels, 8-bit scale) and optics blur (px).
    stroke_angle_deg, pitch_angle_deg : (T,) ndarray
        True wing stroke and pitch angles (see :func:`render_flapping`); NaN for a
        rigid target.
    params : dict
        Every setting the sequence was rendered with.

    Notes
    -----
    A point is *visible* in a view when (i) its whole projected disc lies at least
    1 px inside the image, (ii) the disc is seen no more obliquely than
    ``params["edge_on_deg"]`` (72 deg by default: the angle between its normal and
    the viewing ray; beyond it the marker is a sliver), (iii) its projected disc is
    at least ``params["merge_gap_px"]`` (1.5 px) away from every other marker's
    (merged blobs have no single centre), and (iv) for static points, the wing
    membrane covers none of its pixels at any time during the exposure.
    """

    left: np.ndarray
    right: np.ndarray
    rig: StereoRig
    points3d: np.ndarray
    points_left: np.ndarray
    points_right: np.ndarray
    visible_left: np.ndarray
    visible_right: np.ndarray
    kinds: np.ndarray
    marker_diameter_mm: np.ndarray
    fps: float
    times: np.ndarray = None
    noise_std: float = 0.0
    blur_sigma: float = 0.0
    stroke_angle_deg: np.ndarray = None
    pitch_angle_deg: np.ndarray = None
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        for name in ("left", "right"):
            getattr(self, name).setflags(write=False)
        for name in ("points3d", "points_left", "points_right", "marker_diameter_mm", "times",
                     "stroke_angle_deg", "pitch_angle_deg"):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, _frozen(v, np.float64))
        for name in ("visible_left", "visible_right"):
            object.__setattr__(self, name, _frozen(getattr(self, name), bool))
        object.__setattr__(self, "kinds", _frozen(self.kinds, str))

    def __len__(self):
        return self.left.shape[0]

    @property
    def n_points(self):
        """Number of markers N."""
        return self.points3d.shape[1]

    def _side(self, camera):
        if camera not in CAMERAS:
            raise ValueError(f"camera must be 'left' or 'right', got {camera!r}")
        return getattr(self, f"points_{camera}"), getattr(self, f"visible_{camera}")

    def frames(self, camera):
        """The (T, H, W) frames of ``camera`` ('left' or 'right')."""
        self._side(camera)
        return getattr(self, camera)

    def picks(self, camera):
        """Frame-0 marker positions as a person clicks them: rounded to the pixel.

        Parameters
        ----------
        camera : {'left', 'right'}

        Returns
        -------
        picks : (N, 2) ndarray
            Row ``k`` is point ``k``; NaN for a point not visible in frame 0.
        """
        pts, vis = self._side(camera)
        out = np.rint(pts[0]).astype(np.float64)
        out[~vis[0]] = np.nan
        return out

    def truth_tracks(self, camera):
        """The ground truth as a tracks DataFrame (one row per frame and point).

        Parameters
        ----------
        camera : {'left', 'right'}

        Returns
        -------
        tracks : pandas.DataFrame
            Columns camera (str), frame (int64), point (int64), x, y (px, float64),
            score (1.0) and status (``"ok"`` where visible, else ``"lost"`` with NaN
            x and y), sorted by frame then point.
        """
        pts, vis = self._side(camera)
        t, n = vis.shape
        xy = np.where(vis[..., None], pts, np.nan).reshape(-1, 2)
        return pd.DataFrame(
            {
                "camera": np.full(t * n, camera, dtype=object),
                "frame": np.repeat(np.arange(t, dtype=np.int64), n),
                "point": np.tile(np.arange(n, dtype=np.int64), t),
                "x": xy[:, 0],
                "y": xy[:, 1],
                "score": np.ones(t * n),
                "status": np.where(vis.reshape(-1), "ok", "lost").astype(object),
            }
        )

    def truth_points(self):
        """The 3D ground truth as a points DataFrame (frame, point, X, Y, Z, reproj_err).

        Every (frame, point) has its true position (``reproj_err`` is 0); the extra
        boolean columns ``visible_left`` and ``visible_right`` say where it was seen.
        """
        t, n = self.visible_left.shape
        X = self.points3d.reshape(-1, 3)
        return pd.DataFrame(
            {
                "frame": np.repeat(np.arange(t, dtype=np.int64), n),
                "point": np.tile(np.arange(n, dtype=np.int64), t),
                "X": X[:, 0],
                "Y": X[:, 1],
                "Z": X[:, 2],
                "reproj_err": np.zeros(t * n),
                "visible_left": self.visible_left.reshape(-1),
                "visible_right": self.visible_right.reshape(-1),
            }
        )

    def summary(self):
        """One-paragraph description of the sequence (str)."""
        t, h, w = self.left.shape
        kinds, counts = np.unique(self.kinds, return_counts=True)
        parts = ", ".join(f"{c} {k}" for k, c in zip(kinds, counts))
        vis = [f"{100 * getattr(self, f'visible_{c}').mean():.1f} % {c}" for c in CAMERAS]
        return (
            f"StereoSequence: {t} frames {w}x{h} {self.left.dtype} at {self.fps:g} fps; "
            f"{self.n_points} markers ({parts}); visible point-frames {', '.join(vis)}; "
            f"noise {self.noise_std:g} grey levels, blur {self.blur_sigma:g} px"
        )


@dataclass
class _Scene:
    """What a sequence renderer needs at each time (all in the left camera frame).

    ``points(t)`` -> centres (N, 3), unit normals (N, 3); ``static`` (N,) marks points
    that never move (rendered once, behind everything else); ``membrane(t)`` -> None or
    (vertices (V, 3), triangles (F, 3) int, normal (3,)); ``glare(t, camera)`` -> None
    or (centre (3,), normal (3,), sigma_mm, peak grey level).
    """

    points: callable
    diameters: np.ndarray
    static: np.ndarray
    paint: float
    light: np.ndarray
    membrane: callable = None
    membrane_level: float = 0.0
    glare: callable = None
    background: float = LEVELS["background"]


def _to_camera(rig, side, X, normals=None):
    if side == "left":
        return X, normals
    R = rig.R
    return X @ R.T + rig.T, (None if normals is None else normals @ R.T)


def _shade(normals, light, lo):
    """Lambertian-like brightness factor in [lo, 1] (two-sided)."""
    return lo + (1.0 - lo) * np.abs(normals @ light)


def _membrane_coverage(camera, Xc, triangles, ss=4):
    """Anti-aliased coverage patch of a triangle mesh: (x0, y0, cov (h, w)) or None."""
    w, h = camera.image_size
    if np.any(Xc[:, 2] <= 0):
        return None
    p = camera.project(Xc)
    x0 = int(max(np.floor(p[:, 0].min()) - 1, 0))
    y0 = int(max(np.floor(p[:, 1].min()) - 1, 0))
    x1 = int(min(np.ceil(p[:, 0].max()) + 2, w))
    y1 = int(min(np.ceil(p[:, 1].max()) + 2, h))
    if x1 <= x0 or y1 <= y0:
        return None
    canvas = np.zeros(((y1 - y0) * ss, (x1 - x0) * ss), np.uint8)
    shift = 4
    # canvas pixel centres are integers: c = (x - (x0 - 0.5)) * ss - 0.5
    q = (p - [x0 - 0.5, y0 - 0.5]) * ss - 0.5
    qi = np.rint(q * (1 << shift)).astype(np.int32)
    big = np.int32(1 << 28)
    qi = np.clip(qi, -big, big)
    for tri in triangles:
        cv2.fillConvexPoly(canvas, qi[tri], 255, lineType=cv2.LINE_8, shift=shift)
    cov = cv2.resize(canvas, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    return x0, y0, cov


def _visibility(rig, side, X, normals, diameters, *, edge_on_deg, merge_gap_px):
    """Visibility rules (i)-(iii) of :class:`StereoSequence` for one frame."""
    cam = getattr(rig, side)
    Xc, nc = _to_camera(rig, side, X, normals)
    radii = 0.5 * diameters
    p0, J, _, _, half = _disc_geometry(cam, Xc, nc, radii)
    w, h = cam.image_size
    inside = (
        (p0[:, 0] - half[:, 0] >= 1.0) & (p0[:, 0] + half[:, 0] <= w - 2.0)
        & (p0[:, 1] - half[:, 1] >= 1.0) & (p0[:, 1] + half[:, 1] <= h - 2.0)
        & (Xc[:, 2] > 0)
    )
    view = Xc / np.linalg.norm(Xc, axis=1, keepdims=True)
    facing = np.abs(np.sum(view * nc, axis=1)) >= np.cos(np.radians(edge_on_deg))
    # separation along the line joining each pair of projected centres
    d = p0[None, :, :] - p0[:, None, :]
    dist = np.linalg.norm(d, axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = d / dist[..., None]
    u = np.nan_to_num(u)
    # support of disc i in direction u: r_i |J_i^T u|
    s_i = radii[:, None] * np.linalg.norm(np.einsum("ikl,ijk->ijl", J, u), axis=2)
    s_j = radii[None, :] * np.linalg.norm(np.einsum("jkl,ijk->ijl", J, u), axis=2)
    gap = dist - s_i - s_j
    np.fill_diagonal(gap, np.inf)
    onscreen = inside | ((p0[:, 0] > -20) & (p0[:, 0] < w + 20) & (p0[:, 1] > -20) & (p0[:, 1] < h + 20))
    gap[:, ~onscreen] = np.inf
    separate = np.all(gap >= merge_gap_px, axis=1)
    return p0, inside & facing & separate


def _render_sequence(rig, scene, times, *, fps, blur_sigma, noise_std, dtype, rng, motion_blur,
                     exposure, supersample, edge_on_deg, merge_gap_px, progress=False):
    """Render both views of a scene at ``times``; returns images, truth and visibility."""
    n_t = len(times)
    static = scene.static
    dyn = ~static
    radii = 0.5 * scene.diameters
    X0, N0 = scene.points(times[0] if n_t else 0.0)
    n = len(X0)
    pts3d = np.empty((n_t, n, 3))
    out = {}
    pts2d = {}
    visible = {}
    for side in CAMERAS:
        cam = getattr(rig, side)
        w, h = _image_size(cam)
        out[side] = np.empty((n_t, h, w), dtype=np.dtype(dtype))
        pts2d[side] = np.empty((n_t, n, 2))
        visible[side] = np.zeros((n_t, n), bool)
    # the static layer: background and static discs, once per camera
    layers = {}
    static_boxes = {}
    for side in CAMERAS:
        cam = getattr(rig, side)
        w, h = cam.image_size
        layer = np.full((h, w), scene.background, np.float32)
        if static.any():
            Xc, nc = _to_camera(rig, side, X0[static], N0[static])
            vals = scene.paint * _shade(N0[static], scene.light, 0.75)
            x0, y0, cov = _disc_coverage(cam, Xc, nc, radii[static], ss=supersample)
            _composite(layer, x0, y0, cov, vals)
            static_boxes[side] = (x0, y0, cov.shape[1])
        layers[side] = layer
    iterator = range(n_t)
    if progress:
        from tqdm.auto import tqdm

        iterator = tqdm(iterator, desc="rendering", unit="frame")
    for k in iterator:
        t = float(times[k])
        X, N = scene.points(t)
        pts3d[k] = X
        # sub-exposure times (motion blur)
        if motion_blur and exposure > 0:
            Xa, _ = scene.points(t - 0.5 * exposure / fps)
            Xb, _ = scene.points(t + 0.5 * exposure / fps)
            disp = 0.0
            for side in CAMERAS:
                cam = getattr(rig, side)
                pa = cam.project(_to_camera(rig, side, Xa[dyn])[0])
                pb = cam.project(_to_camera(rig, side, Xb[dyn])[0])
                disp = max(disp, float(np.nanmax(np.linalg.norm(pb - pa, axis=1), initial=0.0)))
            n_sub = int(np.clip(np.ceil(disp / 0.75) + 1, 2, 32))
            sub = t + ((np.arange(n_sub) + 0.5) / n_sub - 0.5) * exposure / fps
        else:
            sub = np.array([t])
        states = [scene.points(float(s)) for s in sub]
        for side in CAMERAS:
            cam = getattr(rig, side)
            p0, vis = _visibility(rig, side, X, N, scene.diameters, edge_on_deg=edge_on_deg,
                                  merge_gap_px=merge_gap_px)
            pts2d[side][k] = p0
            occluded = np.zeros(n, bool)
            # dynamic discs of every sub-exposure time in one batch
            Xs = np.concatenate([st[0][dyn] for st in states])
            Ns = np.concatenate([st[1][dyn] for st in states])
            Xc, nc = _to_camera(rig, side, Xs, Ns)
            vals = scene.paint * _shade(Ns, scene.light, 0.75)
            m_dyn = int(dyn.sum())
            if m_dyn:
                x0, y0, cov = _disc_coverage(cam, Xc, nc, np.tile(radii[dyn], len(sub)), ss=supersample)
            acc = None
            for j, s in enumerate(sub):
                img = layers[side].copy()
                mem = None
                if scene.membrane is not None:
                    verts, tris, mnormal = scene.membrane(float(s))
                    mem = _membrane_coverage(cam, _to_camera(rig, side, verts)[0], tris)
                    if mem is not None:
                        mx, my, mcov = mem
                        region = img[my : my + mcov.shape[0], mx : mx + mcov.shape[1]]
                        level = scene.membrane_level * float(_shade(mnormal[None], scene.light, 0.5)[0])
                        region += mcov * (level - region)
                        if static.any():
                            sx0, sy0, sb = static_boxes[side]
                            for i, pidx in enumerate(np.flatnonzero(static)):
                                a0, b0 = max(sx0[i], mx), max(sy0[i], my)
                                a1 = min(sx0[i] + sb, mx + mcov.shape[1])
                                b1 = min(sy0[i] + sb, my + mcov.shape[0])
                                if a1 > a0 and b1 > b0 and mcov[b0 - my : b1 - my, a0 - mx : a1 - mx].max() > 0.02:
                                    occluded[pidx] = True
                if m_dyn:
                    sl = slice(j * m_dyn, (j + 1) * m_dyn)
                    _composite(img, x0[sl], y0[sl], cov[sl], vals[sl])
                if scene.glare is not None and mem is not None:
                    g = scene.glare(float(s), side)
                    if g is not None:
                        _add_glare(img, cam, _to_camera(rig, side, g[0][None], g[1][None]), g[2], g[3], mem)
                acc = img if acc is None else acc + img
            img = acc / len(sub) if len(sub) > 1 else acc
            out[side][k] = _finish(img, blur_sigma=blur_sigma, noise_std=noise_std, rng=rng, dtype=dtype)
            visible[side][k] = vis & ~occluded
    return out, pts3d, pts2d, visible


def _add_glare(img, camera, centre_normal, sigma_mm, peak, mem):
    """Add a specular patch (Gaussian of ``sigma_mm`` on the surface) where the membrane is."""
    (Xg, ng) = centre_normal
    if Xg[0, 2] <= 0 or peak <= 0:
        return
    p0, J, _, _, _ = _disc_geometry(camera, Xg, ng, np.array([1.0]))
    cov = sigma_mm**2 * (J[0] @ J[0].T) + 0.25 * np.eye(2)
    icov = np.linalg.inv(cov)
    mx, my, mcov = mem
    hh, ww = mcov.shape
    ys, xs = np.mgrid[my : my + hh, mx : mx + ww]
    dx = xs - p0[0, 0]
    dy = ys - p0[0, 1]
    q = icov[0, 0] * dx * dx + 2 * icov[0, 1] * dx * dy + icov[1, 1] * dy * dy
    img[my : my + hh, mx : mx + ww] += (peak * np.exp(-0.5 * q) * mcov).astype(np.float32)


# ====================================================================== public renders
_PRESETS = {
    "clean": dict(
        stroke_amplitude_deg=80.0, pitch_deg=25.0, camber=0.04, bend_mm=2.0, glare=False,
        motion_blur=False, exposure=0.3, noise_std=1.0, blur_sigma=0.6,
    ),
    "hard": dict(
        stroke_amplitude_deg=110.0, pitch_deg=60.0, camber=0.10, bend_mm=6.0, glare=True,
        motion_blur=True, exposure=0.5, noise_std=2.5, blur_sigma=0.8,
    ),
}
_GLARE_PEAK = 150.0


def flapping_preset(name):
    """Settings of a named :func:`render_flapping` preset (a new dict).

    Parameters
    ----------
    name : {'clean', 'hard'}
        ``'clean'``: 80 deg stroke (peak to peak), 25 deg pitch, 4 % camber, 2 mm tip
        bending, no glare, no motion blur, noise 1 grey level, blur 0.6 px.
        ``'hard'``: 110 deg stroke, 60 deg pitch (around mid-stroke the leading-edge
        markers turn edge-on, about a quarter of their frames, and chordwise neighbours
        come within ~7 px or merge), 10 % camber, 6 mm bending,
        glare (a 150-grey-level specular patch sweeping over the wing), motion blur
        over half the frame interval (markers streak up to ~8 px), noise 2.5 grey
        levels, blur 0.8 px. About 91 % of the wing's point-frames stay visible.

    Returns
    -------
    dict
        Keyword arguments of :func:`render_flapping`.

    Examples
    --------
    >>> flapping_preset("hard")["stroke_amplitude_deg"]
    110.0
    """
    if name not in _PRESETS:
        raise ValueError(f"preset must be one of {sorted(_PRESETS)}, got {name!r}")
    return dict(_PRESETS[name])


def _check_rig(rig):
    rig = thesis_rig() if rig is None else rig
    if not isinstance(rig, StereoRig):
        raise ValueError(f"rig must be a wingphoto.StereoRig (e.g. synth.thesis_rig()), got {type(rig).__name__}")
    for side in CAMERAS:
        _image_size(getattr(rig, side))
    return rig


def render_flapping(
    rig=None,
    *,
    n_frames=100,
    fps=3000.0,
    flap_hz=30.0,
    preset="clean",
    stroke_amplitude_deg=None,
    pitch_deg=None,
    camber=None,
    bend_mm=None,
    glare=None,
    motion_blur=None,
    exposure=None,
    noise_std=None,
    blur_sigma=None,
    phase_deg=0.0,
    membrane_level=LEVELS["membrane"],
    edge_on_deg=72.0,
    merge_gap_px=1.5,
    supersample=4,
    dtype=np.uint8,
    seed=0,
    progress=False,
):
    """Render a flapping, bending wing with painted markers, seen by both cameras.

    Parameters
    ----------
    rig : StereoRig, optional
        Default :func:`thesis_rig`.
    n_frames : int, optional
        Number of frames (default 100: one wing beat at 30 Hz and 3000 fps).
    fps : float, optional
        Frame rate (default 3000, the thesis' cameras).
    flap_hz : float, optional
        Wing-beat frequency (default 30 Hz).
    preset : {'clean', 'hard'}, optional
        Defaults for every setting left at None below (see :func:`flapping_preset`).
    stroke_amplitude_deg : float, optional
        Peak-to-peak stroke angle, deg (0-180; the thesis' wing reached 110).
    pitch_deg : float, optional
        Amplitude of the pitch (feathering) rotation about the span axis, deg.
    camber : float, optional
        Peak camber as a fraction of the local chord.
    bend_mm : float, optional
        Amplitude of the out-of-plane deflection of the wing tip, mm.
    glare : bool or float, optional
        Add a specular patch sweeping over the wing; a number sets its peak (grey
        levels; True means 150).
    motion_blur : bool, optional
        Integrate each frame over its exposure (``exposure`` frame intervals, centred on
        the frame time), with enough sub-exposure renders that markers move < 0.75 px
        between them.
    exposure : float, optional
        Exposure as a fraction of the frame interval (used with ``motion_blur``).
    noise_std : float, optional
        Additive Gaussian noise, grey levels (8-bit scale).
    blur_sigma : float, optional
        Gaussian optics blur, px.
    phase_deg : float, optional
        Wing-beat phase of frame 0 (default 0: the top of the stroke, wing flat).
    membrane_level : float, optional
        Grey level of the (dim) wing membrane, default 30 on a background of 6; set it
        to ``LEVELS["background"]`` to make the membrane invisible.
    edge_on_deg : float, optional
        Markers seen more obliquely than this are not visible (default 72 deg).
    merge_gap_px : float, optional
        Markers whose projected discs are closer than this are not visible (1.5 px).
    supersample : int, optional
        Samples per pixel along each axis inside each marker's patch (default 4).
    dtype : numpy dtype, optional
        ``np.uint8`` (default), ``np.uint16`` (8-bit scale x 257) or a float type.
    seed : int, optional
        Seed of the noise.
    progress : bool, optional
        Show a tqdm progress bar.

    Returns
    -------
    StereoSequence
        26 points: 0-17 wing markers, numbered leading edge to trailing edge (3 per
        spanwise station) and tip to root (6 stations); 18-19 the mount; 20-25 the
        static reference dots.

    Notes
    -----
    **Geometry.** In the scene basis ``(a, b, n)`` of :func:`scene_frame` the hinge is at
    ``(-26, 0, 0)`` mm; the wing (span 50 mm, root chord 22 mm tapering to a rounded
    tip) lies in the stroke plane ``(a, b)`` at rest, its span along ``a`` (image
    right), leading edge towards ``-b`` (image up). A material point at span fraction
    ``s`` and chord fraction ``c`` (0 leading, 1 trailing edge; the pitch axis at
    ``c = 0.25``) sits at ``(50 s, (c - 0.25) chord(s), w)`` in the wing frame with
    out-of-plane offset ``w = bend(t) s^2 + camber(t) chord(s) 4 c (1 - c)``; the wing
    frame is pitched about the span axis and then rotated about ``n`` by the stroke
    angle. With ``th = 2 pi flap_hz t + phase``: stroke ``-A/2 cos(th)`` (negative =
    up), pitch ``pitch_deg sin(th)``, camber ``camber sin(th)``, tip bending
    ``bend_mm sin(th - 20 deg)``. The mount markers sit on the body behind the hinge;
    the reference dots on a black panel 15 mm behind the stroke plane.

    **Rendering.** Markers are flat white discs on the wing's tangent plane at their
    centre, so they foreshorten as the wing turns (see ``_disc_coverage``); their
    brightness and the membrane's follow a two-sided Lambertian shading. The truth
    ``points2d`` is the projection of the disc centre; a disc's projected centroid
    differs from it by perspective by < 0.01 px at these sizes. With motion blur the
    image is the mean of the sub-exposure renders and the truth is the position at the
    frame time (the middle of the exposure). Markers are painted through the thin
    membrane (visible from both sides); self-occlusion of the wing is not modelled.

    Examples
    --------
    >>> seq = render_flapping(n_frames=2)
    >>> seq.left.shape, seq.points3d.shape, seq.kinds[[0, 18, 20]].tolist()
    ((2, 512, 512), (2, 26, 3), ['wing', 'mount', 'reference'])
    """
    rig = _check_rig(rig)
    settings = flapping_preset(preset)
    given = dict(stroke_amplitude_deg=stroke_amplitude_deg, pitch_deg=pitch_deg, camber=camber,
                 bend_mm=bend_mm, glare=glare, motion_blur=motion_blur, exposure=exposure,
                 noise_std=noise_std, blur_sigma=blur_sigma)
    settings.update({k: v for k, v in given.items() if v is not None})
    amp = float(settings["stroke_amplitude_deg"])
    if not 0 <= amp <= 180:
        raise ValueError(f"stroke_amplitude_deg must be a peak-to-peak angle in [0, 180], got {amp}")
    n_frames = int(n_frames)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    if not (fps > 0 and flap_hz >= 0):
        raise ValueError(f"fps must be positive and flap_hz non-negative, got {fps}, {flap_hz}")
    exposure_ = float(settings["exposure"])
    if not 0 <= exposure_ <= 1:
        raise ValueError(f"exposure must be a fraction of the frame interval in [0, 1], got {exposure_}")
    _check_common(settings["noise_std"], settings["blur_sigma"], dtype)
    glare_peak = settings["glare"]
    glare_peak = _GLARE_PEAK if glare_peak is True else float(glare_peak or 0.0)

    S, B = scene_frame(rig)
    wing = _WingModel(
        hinge=_WING_HINGE, stroke_amplitude_deg=amp, pitch_deg=float(settings["pitch_deg"]),
        camber=float(settings["camber"]), bend_mm=float(settings["bend_mm"]), flap_hz=float(flap_hz),
        phase_deg=float(phase_deg),
    )
    sig_m = np.repeat(_MARKER_SIGMA, len(_MARKER_XI))
    xi_m = np.tile(_MARKER_XI, len(_MARKER_SIGMA))
    fixed = np.concatenate([_WING_HINGE + _MOUNT, _reference_layout()])
    fixed_left = S + fixed @ B.T
    toward = np.tile(-B[:, 2], (len(fixed), 1))
    n_wing = len(sig_m)

    def points(t):
        X = S + wing.surface(sig_m, xi_m, t) @ B.T
        N = wing.normals(sig_m, xi_m, t) @ B.T
        return np.concatenate([X, fixed_left]), np.concatenate([N, toward])

    sg, xg = np.meshgrid(np.linspace(0.0, 1.0, 25), np.linspace(0.0, 1.0, 7))
    ns, nc = sg.shape[1], sg.shape[0]
    idx = np.arange(ns * nc).reshape(nc, ns)
    tris = np.concatenate([
        np.stack([idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel()], axis=1),
        np.stack([idx[:-1, :-1].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()], axis=1),
    ])

    def membrane(t):
        verts = S + wing.surface(sg, xg, t).reshape(-1, 3) @ B.T
        normal = B @ wing.normals(0.5, 0.5, t)
        return verts, tris, normal

    def glare_at(t, side):
        th = 2 * np.pi * flap_hz * t + np.radians(phase_deg) + (0.6 if side == "right" else 0.0)
        strength = glare_peak * max(0.0, math.sin(th + 0.3)) ** 2
        if strength <= 0:
            return None
        s = 0.5 + 0.4 * math.sin(th + 0.8)
        c = 0.5 + 0.25 * math.cos(th)
        centre = S + wing.surface(s, c, t) @ B.T
        normal = B @ wing.normals(s, c, t)
        return centre, normal, 4.0, strength

    light = B @ np.array([0.2, -0.4, -1.0])
    light /= np.linalg.norm(light)
    diam = np.concatenate([_MARKER_DIAMETER, _MOUNT_DIAMETER, np.full(6, _REFERENCE_DIAMETER)])
    static = np.zeros(len(diam), bool)
    static[n_wing:] = True
    scene = _Scene(points=points, diameters=diam, static=static, paint=LEVELS["paint"], light=light,
                   membrane=membrane, membrane_level=float(membrane_level),
                   glare=glare_at if glare_peak > 0 else None)
    times = np.arange(n_frames) / float(fps)
    rng = np.random.default_rng(seed)
    imgs, pts3d, pts2d, vis = _render_sequence(
        rig, scene, times, fps=float(fps), blur_sigma=float(settings["blur_sigma"]),
        noise_std=float(settings["noise_std"]), dtype=dtype, rng=rng,
        motion_blur=bool(settings["motion_blur"]), exposure=exposure_, supersample=int(supersample),
        edge_on_deg=float(edge_on_deg), merge_gap_px=float(merge_gap_px), progress=progress,
    )
    stroke, pitch, _, _ = wing.angles(times)
    kinds = np.array(["wing"] * n_wing + ["mount"] * 2 + ["reference"] * 6)
    params = dict(settings, preset=preset, n_frames=n_frames, fps=float(fps), flap_hz=float(flap_hz),
                  phase_deg=float(phase_deg), membrane_level=float(membrane_level),
                  edge_on_deg=float(edge_on_deg), merge_gap_px=float(merge_gap_px),
                  supersample=int(supersample), dtype=np.dtype(dtype).name, seed=seed,
                  glare=glare_peak, hinge_left_mm=(S + B @ _WING_HINGE).tolist(),
                  stroke_axis_left=B[:, 2].tolist())
    return StereoSequence(
        left=imgs["left"], right=imgs["right"], rig=rig, points3d=pts3d,
        points_left=pts2d["left"], points_right=pts2d["right"],
        visible_left=vis["left"], visible_right=vis["right"], kinds=kinds,
        marker_diameter_mm=diam, fps=float(fps), times=times,
        noise_std=float(settings["noise_std"]), blur_sigma=float(settings["blur_sigma"]),
        stroke_angle_deg=stroke, pitch_angle_deg=pitch, params=params,
    )


def render_rigid_target(
    rig=None,
    *,
    n_frames=21,
    distance_mm=53.2,
    marker_diameter_mm=2.5,
    n_tilts=3,
    n_pans=7,
    tilt_deg=20.0,
    pan_deg=30.0,
    noise_std=1.0,
    blur_sigma=0.6,
    supersample=4,
    dtype=np.uint8,
    seed=0,
):
    """Render the rigid-body test: two markers ``distance_mm`` apart on the pan-tilt.

    Parameters
    ----------
    rig : StereoRig, optional
        Default :func:`thesis_rig`.
    n_frames : int, optional
        Number of stereo pairs. With ``n_tilts * n_pans`` frames (default 21) each
        frame is one stop of :func:`pan_tilt_schedule`; otherwise the frames are spread
        evenly along the raster path through the stops (pan sweeping back and forth,
        one tilt row after the other).
    distance_mm : float, optional
        Distance between the two marker centres, mm (the thesis' target: 53.2).
    marker_diameter_mm : float, optional
        Painted diameter of both markers, mm (2.5 mm: about 11 px).
    n_tilts, n_pans, tilt_deg, pan_deg : optional
        The pan-tilt schedule (see :func:`pan_tilt_schedule`).
    noise_std, blur_sigma, supersample, dtype, seed : optional
        As for :func:`render_flapping`.

    Returns
    -------
    StereoSequence
        Two points of kind ``"target"``; ``fps`` is 1 (one frame per stop, no motion);
        ``points3d[:, 1] - points3d[:, 0]`` has length ``distance_mm`` exactly.

    Notes
    -----
    The markers are white discs on a black bar held at the rig's working point
    (:func:`scene_frame`), at ``(-distance/2, 0, 0)`` and ``(+distance/2, 0, 0)`` in
    the bar's frame, which the pan-tilt unit turns like the calibration board.

    Examples
    --------
    >>> seq = render_rigid_target(n_frames=3)
    >>> d = np.linalg.norm(seq.points3d[:, 1] - seq.points3d[:, 0], axis=1)
    >>> np.allclose(d, 53.2)
    True
    """
    rig = _check_rig(rig)
    _check_common(noise_std, blur_sigma, dtype)
    n_frames = int(n_frames)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    if not (distance_mm > 0 and marker_diameter_mm > 0):
        raise ValueError(f"distance_mm and marker_diameter_mm must be positive, got {distance_mm}, {marker_diameter_mm}")
    if marker_diameter_mm >= distance_mm:
        raise ValueError("marker_diameter_mm must be smaller than distance_mm (the markers would overlap)")
    stops = pan_tilt_schedule(n_tilts, n_pans, tilt_deg=tilt_deg, pan_deg=pan_deg)
    # raster path: reverse every other tilt row so the pan sweeps back and forth
    rows = stops.reshape(int(n_tilts), int(n_pans), 2).copy()
    rows[1::2] = rows[1::2, ::-1]
    path = rows.reshape(-1, 2)
    if n_frames == len(stops):
        angles = stops
    elif len(path) == 1:
        angles = np.repeat(path, n_frames, axis=0)
    else:
        seg = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))]
        u = np.linspace(0.0, seg[-1], n_frames)
        angles = np.column_stack([np.interp(u, seg, path[:, 0]), np.interp(u, seg, path[:, 1])])
    S, B = scene_frame(rig)
    local = np.array([[-0.5 * distance_mm, 0.0, 0.0], [0.5 * distance_mm, 0.0, 0.0]])

    def points(t):
        k = int(round(t))
        R = _pan_tilt_rotation(B, *angles[k])
        return S + local @ R.T, np.tile(-R[:, 2], (2, 1))

    light = B @ np.array([0.2, -0.4, -1.0])
    light /= np.linalg.norm(light)
    diam = np.full(2, float(marker_diameter_mm))
    scene = _Scene(points=points, diameters=diam, static=np.zeros(2, bool), paint=LEVELS["paint"], light=light)
    times = np.arange(n_frames, dtype=np.float64)
    rng = np.random.default_rng(seed)
    imgs, pts3d, pts2d, vis = _render_sequence(
        rig, scene, times, fps=1.0, blur_sigma=float(blur_sigma), noise_std=float(noise_std), dtype=dtype,
        rng=rng, motion_blur=False, exposure=0.0, supersample=int(supersample), edge_on_deg=72.0,
        merge_gap_px=1.5,
    )
    params = dict(n_frames=n_frames, distance_mm=float(distance_mm), marker_diameter_mm=float(marker_diameter_mm),
                  n_tilts=int(n_tilts), n_pans=int(n_pans), tilt_deg=float(tilt_deg), pan_deg=float(pan_deg),
                  noise_std=float(noise_std), blur_sigma=float(blur_sigma), supersample=int(supersample),
                  dtype=np.dtype(dtype).name, seed=seed, angles_deg=angles.tolist(),
                  edge_on_deg=72.0, merge_gap_px=1.5)
    return StereoSequence(
        left=imgs["left"], right=imgs["right"], rig=rig, points3d=pts3d,
        points_left=pts2d["left"], points_right=pts2d["right"],
        visible_left=vis["left"], visible_right=vis["right"], kinds=np.array(["target", "target"]),
        marker_diameter_mm=diam, fps=1.0, times=times, noise_std=float(noise_std),
        blur_sigma=float(blur_sigma), stroke_angle_deg=np.full(n_frames, np.nan),
        pitch_angle_deg=np.full(n_frames, np.nan), params=params,
    )


# ======================================================================= data-samples


def _write_tiff(path, image):
    import tifffile

    path.parent.mkdir(parents=True, exist_ok=True)
    tifffile.imwrite(path, image, compression="zlib", metadata=None)


def write_samples(out_dir, *, n_calibration=21, n_frames=60, phase_deg=-36.0, preset="clean",
                  noise_std=0.7, pick_half_size=8, seed=0, progress=False):
    """Write the ``data-samples/`` folder: calibration pairs, a flapping sequence, truth.

    Parameters
    ----------
    out_dir : str or Path
        Destination folder (created; existing sample files are overwritten).
    n_calibration : int, optional
        Calibration pairs: the first ``n_calibration`` stops of the 3 x 7 pan-tilt
        schedule (default all 21).
    n_frames : int, optional
        Frames of the flapping sequence (default 60 at 3000 fps: the end of an
        upstroke, the top reversal at frame 10, then the downstroke).
    phase_deg, preset : optional
        Passed to :func:`render_flapping`.
    noise_std : float, optional
        Noise of the flapping sequence, grey levels (default 0.7, a little below the
        clean preset's 1.0 so that the committed sample stays small; the calibration
        pairs keep the default 1.0).
    pick_half_size : int, optional
        Half size (px) of the subimage rectangle saved with each pick.
    seed : int, optional
        Noise seed (the calibration set uses ``seed``, the sequence ``seed + 1``).
    progress : bool, optional
        Show progress bars.

    Returns
    -------
    files : list of Path
        Everything written.

    Notes
    -----
    Layout (8-bit grayscale TIFF, zlib-compressed, lossless)::

        rig.json                        the true rig, Bouguet names (fc_left, ..., om, T)
        calibration/left/calib_01.tif   ... calib_21.tif, and right/ likewise
        calibration/truth.npz           board_points, corners_left/right (K, M, 2), om, T,
                                        angles_deg, pattern_size, square_size, noise_std
        calibration/corners.csv         camera, image, corner, x, y (true corners, px)
        flapping/left/frame_0000.tif    ... and right/ likewise
        flapping/truth.npz              points3d, points_left/right, visible_left/right,
                                        kinds, marker_diameter_mm, fps, times, angles, rig
        flapping/truth_tracks.csv       both cameras, the tracks-table columns
        flapping/truth_points.csv       frame, point, kind, X, Y, Z, visible_left/right
        flapping/picks.json             frame-0 clicks (the picker's file format)
        manifest.json                   what is where, with the settings a pipeline needs
                                        (pattern size, square size, fps, point kinds)
    """
    import tifffile  # noqa: F401  (fail early with the dependency's own message)

    from .io import atomic_write

    out = Path(out_dir)
    rig = thesis_rig()
    files = []

    def text(path, content):
        with atomic_write(path, "w", encoding="utf-8") as f:
            f.write(content)
        files.append(path)

    def npz(path, **arrays):
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(path, "wb") as f:
            np.savez_compressed(f, **arrays)
        files.append(path)

    rig_dict = rig_to_dict(rig)
    text(out / "rig.json", json.dumps(rig_dict, indent=1) + "\n")

    # ---- calibration pairs
    cs = render_calibration_set(rig, seed=seed)
    k = int(n_calibration)
    if not 1 <= k <= len(cs):
        raise ValueError(f"n_calibration must be in 1..{len(cs)}, got {n_calibration}")
    rows = []
    for i in range(k):
        for side in CAMERAS:
            p = out / "calibration" / side / f"calib_{i + 1:02d}.tif"
            _write_tiff(p, getattr(cs, f"{side}_images")[i])
            files.append(p)
            c = getattr(cs, f"corners_{side}")[i]
            rows.append(pd.DataFrame({"camera": side, "image": f"calib_{i + 1:02d}.tif",
                                      "corner": np.arange(len(c)), "x": c[:, 0], "y": c[:, 1]}))
    corners_csv = out / "calibration" / "corners.csv"
    text(corners_csv, pd.concat(rows).to_csv(index=False, float_format="%.6f"))
    files.pop()  # counted by text(); keep a single entry
    files.append(corners_csv)
    npz(
        out / "calibration" / "truth.npz",
        board_points=cs.board_points,
        corners_left=np.stack(cs.corners_left[:k]),
        corners_right=np.stack(cs.corners_right[:k]),
        om=np.stack([p[0] for p in cs.poses[:k]]),
        T=np.stack([p[1] for p in cs.poses[:k]]),
        angles_deg=cs.angles_deg[:k],
        pattern_size=np.array(cs.pattern_size),
        square_size=cs.square_size,
        noise_std=cs.noise_std,
        blur_sigma=cs.blur_sigma,
    )

    # ---- flapping sequence
    seq = render_flapping(rig, n_frames=n_frames, phase_deg=phase_deg, preset=preset, noise_std=noise_std,
                          seed=seed + 1, progress=progress)
    for i in range(len(seq)):
        for side in CAMERAS:
            p = out / "flapping" / side / f"frame_{i:04d}.tif"
            _write_tiff(p, getattr(seq, side)[i])
            files.append(p)
    rig_arrays = {k_: np.asarray(v) for k_, v in rig_dict.items()}
    npz(
        out / "flapping" / "truth.npz",
        points3d=seq.points3d, points_left=seq.points_left, points_right=seq.points_right,
        visible_left=seq.visible_left, visible_right=seq.visible_right, kinds=seq.kinds,
        marker_diameter_mm=seq.marker_diameter_mm, fps=seq.fps, times=seq.times,
        stroke_angle_deg=seq.stroke_angle_deg, pitch_angle_deg=seq.pitch_angle_deg,
        noise_std=seq.noise_std, blur_sigma=seq.blur_sigma, **rig_arrays,
    )
    tracks = pd.concat([seq.truth_tracks(side) for side in CAMERAS], ignore_index=True)
    text(out / "flapping" / "truth_tracks.csv", tracks.to_csv(index=False, float_format="%.6f"))
    pts = seq.truth_points().drop(columns="reproj_err")
    pts.insert(2, "kind", np.tile(seq.kinds, len(seq)))
    text(out / "flapping" / "truth_points.csv", pts.to_csv(index=False, float_format="%.6f"))
    h = float(pick_half_size)
    picks = {
        side: [
            {"point": int(i), "x": float(x), "y": float(y), "half_w": h, "half_h": h}
            for i, (x, y) in enumerate(seq.picks(side))
            if np.isfinite(x)
        ]
        for side in CAMERAS
    }
    picks_doc = {
        "format": "wingphoto-picks",
        "version": 1,
        "cameras": list(CAMERAS),
        "image_size": list(rig.left.image_size),
        "image_size_right": list(rig.right.image_size),
        "n_points": int(seq.n_points),
        "half_size": [h, h],
        "camera": "left",
        "current": 0,
        "picks": picks,
    }
    text(out / "flapping" / "picks.json", json.dumps(picks_doc, indent=1) + "\n")

    # ---- manifest (keys ending in _dir, _file, _glob are paths relative to out_dir)
    kinds = seq.kinds.tolist()
    manifest = {
        "description": "Synthetic stereo experiment rendered by wingphoto.synth.write_samples",
        "regenerate": "python data-samples/make_samples.py",
        "rig_file": "rig.json",
        "calibration": {
            "left_dir": "calibration/left",
            "right_dir": "calibration/right",
            "left_glob": "calibration/left/calib_*.tif",
            "right_glob": "calibration/right/calib_*.tif",
            "n_pairs": k,
            "pattern_size": list(cs.pattern_size),
            "square_size": cs.square_size,
            "truth_file": "calibration/truth.npz",
            "corners_file": "calibration/corners.csv",
        },
        "flapping": {
            "left_dir": "flapping/left",
            "right_dir": "flapping/right",
            "left_glob": "flapping/left/frame_*.tif",
            "right_glob": "flapping/right/frame_*.tif",
            "n_frames": len(seq),
            "fps": seq.fps,
            "flap_hz": seq.params["flap_hz"],
            "n_points": int(seq.n_points),
            "kinds": kinds,
            "wing_points": [i for i, c in enumerate(kinds) if c == "wing"],
            "leading_edge_points": list(range(0, _n_wing_markers(), len(_MARKER_XI))),
            "mount_points": [i for i, c in enumerate(kinds) if c == "mount"],
            "reference_points": [i for i, c in enumerate(kinds) if c == "reference"],
            "marker_diameter_mm": seq.marker_diameter_mm.tolist(),
            "picks_file": "flapping/picks.json",
            "truth_file": "flapping/truth.npz",
            "truth_tracks_file": "flapping/truth_tracks.csv",
            "truth_points_file": "flapping/truth_points.csv",
        },
    }
    text(out / "manifest.json", json.dumps(manifest, indent=1) + "\n")
    log.info("wrote %d sample files to %s", len(files), out)
    return files


def _main(argv=None):
    """``python -m wingphoto.synth [OUT_DIR]``: regenerate the data samples."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m wingphoto.synth",
        description="Regenerate wingphoto's data-samples/ folder (synthetic images + ground truth).",
    )
    parser.add_argument("out_dir", nargs="?", default="data-samples", help="destination folder (default data-samples)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    files = write_samples(args.out_dir, progress=True)
    total = sum(f.stat().st_size for f in files)
    log.info("%d files, %.1f MB", len(files), total / 1e6)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(_main())
