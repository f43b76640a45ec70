"""Anti-aliased rasterisation of discs and the finishing of a rendered image (blur, noise, dtype)."""
from __future__ import annotations


import cv2
import numpy as np

from .rig import _camera_key, _supersample_rays




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
