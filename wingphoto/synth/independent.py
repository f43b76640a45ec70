"""A second wing renderer, written apart from :mod:`wingphoto.synth`, to measure the tracker.

The tracker was tuned on :mod:`wingphoto.synth.scenarios`; this module renders the same
kind of footage from its own assumptions (none of ``wing``, ``raster``, ``flapping`` or
``scenarios`` is imported) so that the tracker can be measured on images it was not built
with: a hawkmoth-like wing flapping at 30 Hz filmed at 3000 frames/s by a 512 x 512
perspective camera with lens distortion.

Scene (world frame: mm, z up, hinge at the origin)
--------------------------------------------------
* **Wing**: a flat plate with a straight leading edge along its span axis ``u`` (from the
  hinge) and a half-elliptic chord ``v`` in ``[-c(u), 0]``; it rotates about the vertical
  by the stroke angle ``phi(t) = A/2 sin(psi)``, ``psi = 2 pi f t + psi0``, and pitches
  about its leading edge by ``theta(t) = theta_max sin(psi)|sin(psi)|^3 + theta_mid
  cos(psi)``: near each stroke reversal the plate turns up to ``theta_max`` (60 deg
  "clean", 80 deg "hard"), close to edge-on for one camera. A textured membrane with dark
  veins; ~18 markers painted on its upper face as uniform *disks* (radius 0.8-1.3 mm,
  ~4-8 px across).
* **Glare**: a smooth highlight on the membrane (and the paint) that moves along the span
  and brightens when the plate turns towards the specular direction; an image-space glare
  gradient and an illumination ramp.
* **Static dots**: 2 mount dots on a dark mount block behind the hinge (plane z = -15 mm)
  and 6 reference dots on the textured background plate (z = -40 mm).
* **Cameras**: two pinhole cameras with radial and tangential distortion
  (``cv2.projectPoints``), 500 mm above the wing, tilted +-20 deg about the world x axis.

Image formation
---------------
Every pixel casts a ray (the inverse of the camera's distortion, precomputed once per
pixel, bilinearly interpolated between pixels) onto the plane of each surface; a disk's
coverage is the share of ``supersample`` x ``supersample`` sub-pixel rays that land
inside it on its plane, so a disk seen in perspective is an exact (distorted) ellipse.
Motion blur averages ``n_sub`` sub-frame renders over the 330 us exposure centred on the
frame time; then a Gaussian PSF, the illumination ramp and glare gradient, shot noise
(Poisson in electrons) and read noise, and quantisation to 8 bits (``uint8``) or 12 bits
in ``uint16``.

Truth
-----
The truth of a marker is the **projection (``cv2.projectPoints``, with distortion) of the
3D centre of its disk at the middle of the exposure** - not the centroid of its image
ellipse, which perspective, distortion, blur and glare move by up to a few tenths of a
pixel: that is what the tracker is measured against. A point is *visible* when that
projected centre is inside the image (``-0.5 <= x, y <= size - 0.5``) and its disk faces the
camera (the disk's normal . the view ray < 0); a static dot is also not visible while the
wing covers it. On a black frame nothing is visible.

Glitches (``kind``)
-------------------
``dropped`` (1-3 consecutive frames removed), ``repeated`` (one frame repeated byte for
byte, another repeated with new noise), ``black`` (one all-zero frame), ``bumped`` (from a
frame on, the sensor shifted by a few px: the principal point moves, image and truth
move together). They are applied to the ``hard`` wing motion. ``clean16`` is ``clean``
in 12 bits in ``uint16``.

Seeds: tune on :data:`DEV_SEEDS`, report :data:`TEST_SEEDS` only. A seed chooses the
markers, the phase of frame 0, the textures, the glare, the camera poses' jitter, the
glitch frames and the noise.

Examples
--------
>>> from wingphoto.synth import independent
>>> seq = independent.render_independent("clean", seed=0, camera="left", n_frames=3)
>>> seq.frames().shape, seq.frames().dtype.name, seq.points.shape
((3, 512, 512), 'uint8', (3, 26, 2))
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy import ndimage

__all__ = ["KINDS", "DEV_SEEDS", "TEST_SEEDS", "IndependentSequence", "IndependentCamera", "render_independent"]

#: Seeds to develop on.
DEV_SEEDS = (0, 1, 2)
#: Held-out seeds: report only.
TEST_SEEDS = (1000, 1001, 1002)

#: Sequence kinds and their base motion ("clean" or "hard").
KINDS = {
    "clean": "clean", "hard": "hard", "dropped": "hard", "repeated": "hard",
    "black": "hard", "bumped": "hard", "clean16": "clean",
}
CAMERAS = ("left", "right")

FPS = 3000.0  # frames per second
FLAP_HZ = 30.0  # wing-beat frequency
EXPOSURE_S = 330e-6  # exposure time
FOCAL_PX = 1500.0  # focal length, px
CAMERA_DISTANCE_MM = 500.0
CAMERA_TILT_DEG = 20.0
WING_ROOT_MM, WING_TIP_MM, CHORD_MM, CHORD_CENTRE_MM = 3.0, 51.0, 20.0, 24.0
MOUNT_Z_MM, PLATE_Z_MM = -15.0, -40.0
PSF_SIGMA_PX = 0.7
BLUR_STEP_PX = 0.8  # largest marker travel between two motion-blur sub-frames
_PAD = 16  # px of rays kept around the image (marker patches reach over its border)

_MOTION = {  # stroke amplitude, largest pitch, pitch at mid-stroke (deg); glare peak (0-1)
    "clean": dict(amplitude=50.0, theta_max=60.0, theta_mid=10.0, glare=0.25),
    "hard": dict(amplitude=110.0, theta_max=80.0, theta_mid=15.0, glare=0.40),
}
_REF_DOTS_MM = ((-45.0, -55.0), (-45.0, 55.0), (85.0, -62.0), (85.0, 62.0), (98.0, 0.0), (-52.0, 0.0))
_MOUNT_DOTS_MM = ((-9.0, -3.5), (-9.0, 3.5))


def _look_at(centre, target):
    """World -> camera rotation of a camera at ``centre`` looking at ``target`` (y down ~ world -y)."""
    z = target - centre
    z = z / np.linalg.norm(z)
    down = np.array([0.0, -1.0, 0.0])
    y = down - (down @ z) * z
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    return np.stack([x, y, z])


class IndependentCamera:
    """A pinhole camera with Bouguet/OpenCV distortion and its per-pixel rays.

    Parameters
    ----------
    K : (3, 3) ndarray
        Camera matrix (fc, cc of Bouguet), px.
    dist : (5,) ndarray
        ``[k1, k2, p1, p2, k3]`` (Bouguet's kc, OpenCV's distCoeffs).
    R : (3, 3) ndarray
        World -> camera rotation.
    t : (3,) ndarray
        World -> camera translation, mm (``X_cam = R X + t``).
    size : int
        Image width and height, px.
    """

    def __init__(self, K, dist, R, t, size):
        self.K = np.asarray(K, float)
        self.dist = np.asarray(dist, float)
        self.R = np.asarray(R, float)
        self.t = np.asarray(t, float)
        self.size = int(size)
        self.rvec = cv2.Rodrigues(self.R)[0]
        self._rays = None
        self._sub = {}

    def project(self, X):
        """Project (N, 3) world points (mm) to (N, 2) pixels with distortion."""
        X = np.asarray(X, float).reshape(-1, 3)
        p, _ = cv2.projectPoints(X, self.rvec, self.t, self.K, self.dist)
        return p.reshape(-1, 2)

    def shifted(self, dx, dy):
        """The same camera with its sensor (principal point) moved by (dx, dy) px."""
        K = self.K.copy()
        K[0, 2] += dx
        K[1, 2] += dy
        return IndependentCamera(K, self.dist, self.R, self.t, self.size)

    @property
    def rays(self):
        """(H + 2P, W + 2P, 2) normalised undistorted coordinates of the pixel centres, P = ``_PAD`` px margin."""
        if self._rays is None:
            g = np.arange(-_PAD, self.size + _PAD, dtype=np.float64)
            xx, yy = np.meshgrid(g, g)
            pts = np.stack([xx.ravel(), yy.ravel()], 1).reshape(-1, 1, 2)
            crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 60, 1e-12)
            und = cv2.undistortPoints(pts, self.K, self.dist, criteria=crit)
            self._rays = und.reshape(len(g), len(g), 2)
        return self._rays

    def rays_at(self, x, y):
        """Normalised rays (..., 2) at pixel positions x, y (any float), bilinear between pixels."""
        r = self.rays
        top = self.size + 2 * _PAD - 1
        gx, gy = np.clip(x + _PAD, 0, top - 1e-9), np.clip(y + _PAD, 0, top - 1e-9)
        x0, y0 = np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)
        x1, y1 = np.minimum(x0 + 1, top), np.minimum(y0 + 1, top)
        fx, fy = (gx - x0)[..., None], (gy - y0)[..., None]
        return ((r[y0, x0] * (1 - fx) + r[y0, x1] * fx) * (1 - fy)
                + (r[y1, x0] * (1 - fx) + r[y1, x1] * fx) * fy)

    def sub_rays(self, ss):
        """(ss (H + 2P), ss (W + 2P), 2) rays of the ss x ss sub-pixel samples of every pixel.

        Sample ``(i, j)`` lies at pixel ``x = (j + 0.5) / ss - 0.5 - P`` (likewise y).
        """
        if ss not in self._sub:
            r = self.rays.astype(np.float32)  # cv2.resize samples src at (i + 0.5) / ss - 0.5: bilinear, edges held
            self._sub[ss] = cv2.resize(r, None, fx=ss, fy=ss, interpolation=cv2.INTER_LINEAR)
        return self._sub[ss]


def _on_plane(cam, rays, origin, eu, ev, n):
    """Intersect camera rays with a plane; return (u, v) in mm on the plane's axes and facing.

    ``facing`` is True where the ray meets the side the normal ``n`` points to; (u, v) are
    NaN where the ray misses (parallel or behind the camera).
    """
    o, a, b, nn = (np.asarray(q, rays.dtype) for q in (cam.R @ origin + cam.t, cam.R @ eu, cam.R @ ev, cam.R @ n))
    d = np.concatenate([rays, np.ones(rays.shape[:-1] + (1,), rays.dtype)], axis=-1)
    den = d @ nn.astype(rays.dtype)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (o @ nn) / den
        ok = (np.abs(den) > 1e-7) & (s > 0)
        X = s[..., None] * d - o
    u = np.where(ok, X @ a, np.nan)
    v = np.where(ok, X @ b, np.nan)
    return u, v, den < 0


def _chord(u):
    """Chord length (mm) at span position u: half an ellipse, 0 outside the wing."""
    q = 1.0 - ((u - CHORD_CENTRE_MM) / (WING_TIP_MM - CHORD_CENTRE_MM)) ** 2
    return CHORD_MM * np.sqrt(np.clip(q, 0.0, None)) * (u >= WING_ROOT_MM)


def _outline(n=48):
    """(M, 2) wing outline in (u, v), mm."""
    u = np.linspace(WING_ROOT_MM, WING_TIP_MM, n)
    return np.concatenate([np.stack([u, np.zeros_like(u)], 1), np.stack([u[::-1], -_chord(u[::-1])], 1)])


@dataclass
class _Scene:
    """Everything a seed chooses that both cameras share."""

    markers: np.ndarray  # (M, 3): u, v, radius (mm) of the wing markers
    paint: np.ndarray  # (M,) paint brightness (0-1)
    motion: dict
    psi0: float
    tex: np.ndarray  # (4, 4): membrane texture sinusoids: amplitude, ku, kv, phase
    veins: np.ndarray  # (V, 3): a, b, c of vein lines a u + b v + c = 0 (a^2 + b^2 = 1)
    glare_path: np.ndarray  # (4,): span centre, span swing, chord centre, preferred pitch (deg)
    cams: dict = field(default_factory=dict)
    field_seed: int = 0
    ramp: np.ndarray = None  # (2,): illumination ramp in x, y (relative over the image)
    glare2: np.ndarray = None  # (4,): image-space glare: x, y (px), drift px/frame, peak


def _scene(seed, base):
    rng = np.random.default_rng([seed, 2026])
    markers = []
    for u in (10.0, 18.0, 26.0, 34.0, 42.0):
        for f in (0.2, 0.5, 0.8):
            markers.append((u, -f * _chord(u)))
    markers += [(47.0, -0.3 * _chord(47.0)), (47.0, -0.72 * _chord(47.0)), (6.0, -0.5 * _chord(6.0))]
    mk = np.array(markers)
    mk += rng.uniform(-0.8, 0.8, mk.shape) * [1.0, 0.5]
    radius = rng.uniform(0.8, 1.3, len(mk))
    paint = rng.uniform(0.78, 0.95, len(mk))
    tex = np.stack([rng.uniform(0.01, 0.03, 4), rng.uniform(0.1, 0.6, 4), rng.uniform(0.1, 0.6, 4),
                    rng.uniform(0, 2 * np.pi, 4)], 1)
    ang = np.deg2rad(rng.uniform(-25, 5, 5))
    veins = np.stack([-np.sin(ang), np.cos(ang), rng.uniform(-1.5, 1.5, 5) - 3.0 * np.arange(5)], 1)
    glare_path = np.array([rng.uniform(18, 34), rng.uniform(6, 14), rng.uniform(-12, -6), rng.uniform(-30, 30)])
    sc = _Scene(np.column_stack([mk, radius]), paint, dict(_MOTION[base]), rng.uniform(-0.4, 0.4),
                tex, veins, glare_path, field_seed=int(rng.integers(2**31)),
                ramp=rng.uniform(-0.12, 0.12, 2),
                glare2=np.array([rng.uniform(100, 400), rng.uniform(100, 400), rng.uniform(0.5, 1.5), 0.12]))
    target = np.array([22.0, 0.0, -5.0]) + rng.normal(0, 2.0, 3)
    for i, cam in enumerate(CAMERAS):
        tilt = np.deg2rad(CAMERA_TILT_DEG * (1 if i == 0 else -1) + rng.normal(0, 2.0))
        yaw = np.deg2rad(rng.normal(0, 3.0))
        centre = target + CAMERA_DISTANCE_MM * np.array([np.sin(yaw), np.sin(tilt), np.cos(tilt)])
        R = _look_at(centre, target)
        K = np.array([[FOCAL_PX * (1 + rng.normal(0, 0.01)), 0, 255.5 + rng.normal(0, 4)],
                      [0, FOCAL_PX * (1 + rng.normal(0, 0.01)), 255.5 + rng.normal(0, 4)], [0, 0, 1]])
        dist = np.array([rng.uniform(-0.25, -0.1), rng.uniform(0.0, 0.2), rng.normal(0, 1e-3),
                         rng.normal(0, 1e-3), 0.0])
        sc.cams[cam] = (K, dist, R, -R @ centre)
    return sc


def _pose(sc, t):
    """Wing axes at time t (s): e_u (span), e_v (towards the leading edge), n (upper face), world."""
    m = sc.motion
    psi = 2 * np.pi * FLAP_HZ * t + sc.psi0
    phi = np.deg2rad(m["amplitude"] / 2) * np.sin(psi)
    s = np.sin(psi)
    theta = np.deg2rad(m["theta_max"]) * s * np.abs(s) ** 3 + np.deg2rad(m["theta_mid"]) * np.cos(psi)
    cz, sz, cx, sx = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1.0]])
    Rx = np.array([[1.0, 0, 0], [0, cx, -sx], [0, sx, cx]])
    R = Rz @ Rx
    return R[:, 0], R[:, 1], R[:, 2], theta, psi


def _marker_world(sc, t):
    eu, ev, n, _, _ = _pose(sc, t)
    return sc.markers[:, :1] * eu + sc.markers[:, 1:2] * ev, n


def _static_world():
    mount = np.array([[x, y, MOUNT_Z_MM] for x, y in _MOUNT_DOTS_MM])
    ref = np.array([[x, y, PLATE_Z_MM] for x, y in _REF_DOTS_MM])
    return mount, ref


def _disk_cover(cam, c_px, reach_px, centre, radius, eu, ev, n, ss, shape):
    """Supersampled coverage of a disk on a plane: (rows, cols) slices and the patch (or None)."""
    size = cam.size
    h = int(np.ceil(reach_px)) + 2
    x0, y0 = int(np.floor(c_px[0])) - h, int(np.floor(c_px[1])) - h
    xa, ya, xb, yb = max(x0, 0), max(y0, 0), min(x0 + 2 * h + 2, size), min(y0 + 2 * h + 2, size)
    if xa >= xb or ya >= yb:
        return None
    off = (np.arange(ss) + 0.5) / ss - 0.5
    xs = (np.arange(xa, xb)[:, None] + off[None, :]).ravel()
    ys = (np.arange(ya, yb)[:, None] + off[None, :]).ravel()
    X, Y = np.meshgrid(xs, ys)
    u, v, facing = _on_plane(cam, cam.rays_at(X, Y), centre, eu, ev, n)
    inside = facing & (u * u + v * v <= radius * radius)
    cov = inside.reshape(yb - ya, ss, xb - xa, ss).mean(axis=(1, 3))
    return (slice(ya, yb), slice(xa, xb)), cov


def _static_layer(sc, cam, ss):
    """Background plate texture, mount block and the static dots (float image 0-1)."""
    size = cam.size
    rng = np.random.default_rng([sc.field_seed, 1])
    tex = ndimage.gaussian_filter(rng.normal(0, 1, (size, size)), 6.0)
    tex2 = ndimage.gaussian_filter(rng.normal(0, 1, (size, size)), 1.5)
    img = 0.16 + 0.05 * tex / tex.std() + 0.012 * tex2 / tex2.std()
    # mount block (plane z = MOUNT_Z), antialiased by distance to its edges
    g = np.arange(size, dtype=float)
    X, Y = np.meshgrid(g, g)
    ex, ey, ez = np.eye(3)
    u, v, _ = _on_plane(cam, cam.rays_at(X, Y), np.array([0, 0, MOUNT_Z_MM]), ex, ey, ez)
    dist_in = np.minimum.reduce([u + 16.0, -2.0 - u, v + 8.0, 8.0 - v])
    alpha = np.clip(0.5 + dist_in * FOCAL_PX / CAMERA_DISTANCE_MM, 0, 1)
    img = img * (1 - np.nan_to_num(alpha)) + 0.07 * np.nan_to_num(alpha)
    mount, ref = _static_world()
    for X3, r, val in [(p, 1.1, 0.8) for p in mount] + [(p, 1.3, 0.75) for p in ref]:
        c = cam.project(X3)[0]
        res = _disk_cover(cam, c, r * FOCAL_PX / CAMERA_DISTANCE_MM * 1.3, X3, r, ex, ey, ez, ss, img.shape)
        if res is not None:
            sl, cov = res
            img[sl] = img[sl] * (1 - cov) + val * cov
    return img


def _marker_cover(sc, cam, cpx, cw, eu, ev, n, ss, depth):
    """Supersampled coverage of all wing disks: (H, W) coverage and coverage x paint images.

    All markers lie on the wing's plane, so one ray-plane intersection serves every patch
    (``ss`` x ``ss`` sub-pixel rays per pixel of a square patch around each projected
    centre); a sub-ray counts when it lands inside the disk on the face the normal points to.
    """
    size = cam.size
    reach = sc.markers[:, 2].max() * FOCAL_PX / depth * 1.1 + 0.5
    h = min(int(np.ceil(reach)) + 1, _PAD - 2)
    P = 2 * h + 1
    cov = np.zeros((size + 2 * _PAD, size + 2 * _PAD), np.float32)
    pc = np.zeros_like(cov)
    c0 = np.floor(cpx + 0.5).astype(np.int64)  # nearest pixel
    keep = np.all((c0 >= -_PAD + h + 1) & (c0 < size + _PAD - h - 1), axis=1)
    if keep.any():
        rays = cam.sub_rays(ss)
        ar = np.arange(P * ss)
        rows = (c0[keep, 1, None] - h + _PAD) * ss + ar  # (K, P ss)
        cols = (c0[keep, 0, None] - h + _PAD) * ss + ar
        r = rays[rows[:, :, None], cols[:, None, :]]  # (K, P ss, P ss, 2) float32
        u, v, facing = _on_plane(cam, r, np.zeros(3), eu, ev, n)
        mk = sc.markers[keep].astype(np.float32)
        inside = facing & ((u - mk[:, 0, None, None]) ** 2 + (v - mk[:, 1, None, None]) ** 2
                           <= mk[:, 2, None, None] ** 2)
        c = inside.reshape(-1, P, ss, P, ss).mean(axis=(2, 4))
        for j, (k, (x, y)) in enumerate(zip(np.flatnonzero(keep), c0[keep])):
            sl = (slice(y - h + _PAD, y + h + 1 + _PAD), slice(x - h + _PAD, x + h + 1 + _PAD))
            cov[sl] += c[j]
            pc[sl] += c[j] * sc.paint[k]
    inner = (slice(_PAD, _PAD + size), slice(_PAD, _PAD + size))
    return np.minimum(cov[inner], 1.0), pc[inner]


def _wing_sub(sc, cam, t, ss, bg):
    """The wing at time t composited over ``bg`` inside its bounding box.

    Returns
    -------
    box : tuple of slice or None
        (rows, cols) of the wing's bounding box (None: the wing is outside the image).
    image, alpha : ndarray
        The composited image and the wing's coverage inside ``box``.
    """
    eu, ev, n, theta, psi = _pose(sc, t)
    size = cam.size
    hinge = np.zeros(3)
    out = _outline()
    pts = cam.project(out[:, :1] * eu + out[:, 1:2] * ev)
    xa, ya = np.clip(np.floor(pts.min(0)).astype(int) - 3, 0, size)
    xb, yb = np.clip(np.ceil(pts.max(0)).astype(int) + 4, 0, size)
    if xa >= xb or ya >= yb:
        return None, None, None
    rays = cam.rays[ya + _PAD: yb + _PAD, xa + _PAD: xb + _PAD]
    u, v, facing = _on_plane(cam, rays, hinge, eu, ev, n)
    depth = cam.R[2] @ (hinge) + cam.t[2]
    d = np.concatenate([rays, np.ones(rays.shape[:-1] + (1,))], -1)
    cosg = np.abs(d @ (cam.R @ n)) / np.linalg.norm(d, axis=-1)
    px_per_mm = FOCAL_PX / depth * np.maximum(cosg, 0.05)
    c = _chord(np.nan_to_num(u))
    s_mm = np.minimum.reduce([np.nan_to_num(u, nan=-99) - WING_ROOT_MM, -np.nan_to_num(v, nan=99),
                              np.nan_to_num(v, nan=-99) + c, WING_TIP_MM - np.nan_to_num(u, nan=-99)])
    s_mm = np.where(c > 0, s_mm, -99.0)
    alpha = np.clip(0.5 + s_mm * px_per_mm, 0, 1)
    uu, vv = np.nan_to_num(u), np.nan_to_num(v)
    memb = 0.36 + sum(a * np.sin(ku * uu + kv * vv + ph) for a, ku, kv, ph in sc.tex)
    for a, b, cc in sc.veins:
        memb = memb - 0.07 * np.exp(-0.5 * ((a * uu + b * vv + cc) / 0.25) ** 2) * (uu > 4)
    gp = sc.glare_path
    spec = sc.motion["glare"] * np.exp(-0.5 * ((np.rad2deg(theta) - gp[3]) / 25.0) ** 2)
    glare = spec * np.exp(-0.5 * (((uu - gp[0] - gp[1] * np.sin(psi)) / 9.0) ** 2
                                  + ((vv - gp[2] - 3.0 * np.cos(psi)) / 6.0) ** 2))
    cw, _ = _marker_world(sc, t)
    cov, paint_cov = _marker_cover(sc, cam, cam.project(cw), cw, eu, ev, n, ss, depth)
    c_box, p_box = cov[ya:yb, xa:xb], paint_cov[ya:yb, xa:xb]
    wing = memb * (1 - c_box) + p_box
    wing = np.clip(wing + glare, 0, None)
    box = bg[ya:yb, xa:xb]
    return (slice(ya, yb), slice(xa, xb)), box + alpha * (wing - box), alpha


@dataclass
class IndependentSequence:
    """One camera's rendered sequence and its truth.

    Attributes
    ----------
    camera : str
    kind : str
    seed : int
    images : (T, H, W) ndarray of uint8 or uint16
    points : (T, N, 2) ndarray of float
        Truth (x, y) px: the projected 3D centre of each disk at mid-exposure (NaN never).
        Points 0-1 are the mount dots, 2-7 the reference dots, 8- the wing markers.
    visible : (T, N) ndarray of bool
    time_index : (T,) ndarray of int
        Index of the rendered instant each output frame shows (glitches repeat or skip it).
    glitch : dict
        What was done and where (output frame numbers).
    point_kind : (N,) ndarray of str
    view_angle : (T, N) ndarray of float
        Angle (deg) between each disk's normal and the ray to the camera: 0 face-on, 90
        edge-on, > 90 facing away.
    """

    camera: str
    kind: str
    seed: int
    images: np.ndarray
    points: np.ndarray
    visible: np.ndarray
    time_index: np.ndarray
    glitch: dict
    point_kind: np.ndarray
    view_angle: np.ndarray

    def frames(self, camera=None):
        """The images (T, H, W)."""
        return self.images

    def picks(self, camera=None):
        """Frame-0 picks: the truth of the visible points rounded to the pixel, NaN elsewhere."""
        p = np.round(self.points[0]).astype(float)
        p[~self.visible[0]] = np.nan
        return p


def _finish(img, rng, bits, illum, glare2, noise=True):
    """PSF, illumination and image glare, shot + read noise (unless ``noise`` is False), quantisation."""
    img = cv2.GaussianBlur(img, (0, 0), PSF_SIGMA_PX)
    img = img * illum + glare2
    full = 255 if bits == 8 else 4095
    gain = 20.0 if bits == 8 else 2.0  # electrons per DN
    if not noise:
        return np.clip(np.round(img * full), 0, full).astype(np.uint8 if bits == 8 else np.uint16)
    e = rng.poisson(np.clip(img, 0, None) * full * gain).astype(float)
    dn = e / gain + rng.normal(0, 8.0 / gain, img.shape)
    dn = np.clip(np.round(dn), 0, full)
    return dn.astype(np.uint8 if bits == 8 else np.uint16)


def render_independent(kind, *, seed, camera="left", n_frames=100, size=512, supersample=4, n_sub=12,
                       bits=None, noise=True):
    """Render one camera of an independent validation sequence.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`.
    seed : int
        Scene, glitch and noise seed (:data:`DEV_SEEDS` to tune on, :data:`TEST_SEEDS` to report).
    camera : {"left", "right"}
    n_frames : int
        Frames in the output sequence (one wing beat is 100 frames).
    size : int
        Image width and height, px.
    supersample : int
        Sub-pixel rays per pixel side for the disks.
    n_sub : int
        Most sub-frame renders averaged over the exposure (motion blur): as many as keep
        the fastest marker's step between two below ``BLUR_STEP_PX``, at most ``n_sub``;
        1 renders the mid-exposure instant only.
    bits : {8, 12}, optional
        Output depth (default 12 for ``clean16``, else 8).
    noise : bool
        Shot and read noise (False: the noiseless image, quantised).

    Returns
    -------
    IndependentSequence
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {list(KINDS)}, got {kind!r}")
    if camera not in CAMERAS:
        raise ValueError(f"camera must be one of {CAMERAS}, got {camera!r}")
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    bits = bits or (12 if kind == "clean16" else 8)
    if bits not in (8, 12):
        raise ValueError(f"bits must be 8 or 12, got {bits!r}")
    sc = _scene(seed, KINDS[kind])
    cam_i = CAMERAS.index(camera)
    grng = np.random.default_rng([seed, 77, list(KINDS).index(kind)])
    nrng = np.random.default_rng([seed, 99, list(KINDS).index(kind), cam_i])
    cam0 = IndependentCamera(*sc.cams[camera], size)

    # plan: which rendered instant each output frame shows, and glitches
    k = int(grng.integers(n_frames // 3, max(n_frames // 3 + 1, 2 * n_frames // 3)))
    glitch = {"kind": kind}
    n_render = n_frames
    order = list(range(n_frames))
    renoise = set()
    black = set()
    if kind == "dropped":
        nd = int(grng.integers(1, 4))
        n_render = n_frames + nd
        order = list(range(k)) + list(range(k + nd, n_render))
        glitch.update(dropped_after=k - 1, n_dropped=nd)
    elif kind == "repeated":
        k2 = max(min(k + int(grng.integers(10, 25)), n_frames - 3), k + 1)
        order = list(range(k + 1)) + [k] + list(range(k + 1, k2 + 1)) + [k2] + list(range(k2 + 1, n_frames))
        order = order[:n_frames]
        glitch.update(identical_repeat=k + 1, renoised_repeat=k2 + 2)
        renoise.add(k2 + 2)
    elif kind == "black":
        black.add(k)
        glitch.update(black=k)
    bump = None
    if kind == "bumped":
        bump = grng.choice([-1, 1], 2) * grng.uniform(3, 6, 2)
        glitch.update(bumped_from=k, shift=tuple(np.round(bump, 3)))

    mount, ref = _static_world()
    kinds = np.array(["mount"] * len(mount) + ["reference"] * len(ref) + ["wing"] * len(sc.markers))
    cams_for = {}
    statics = {}

    def cam_at(i):  # i: rendered instant
        key = bump is not None and i >= k
        if key not in cams_for:
            cams_for[key] = cam0.shifted(*bump) if key else cam0
            statics[key] = _static_layer(sc, cams_for[key], supersample)
        return cams_for[key], statics[key]

    t0 = 0.0
    rendered, truth, vis, tilt = {}, {}, {}, {}
    for i in sorted(set(order)):
        cam, bg = cam_at(i)
        t = t0 + i / FPS
        # sub-frames: enough that the fastest marker moves <= BLUR_STEP_PX between two
        ends = [cam.project(_marker_world(sc, t + h * EXPOSURE_S)[0]) for h in (-0.5, 0.5)]
        travel = np.nanmax(np.hypot(*(ends[1] - ends[0]).T))
        m = int(np.clip(np.ceil(travel / BLUR_STEP_PX), 1, n_sub))
        sub = (np.arange(m) + 0.5) / m - 0.5
        acc = bg * len(sub)
        amax = np.zeros_like(bg)
        for s in sub:
            box, img, a = _wing_sub(sc, cam, t + s * EXPOSURE_S, supersample, bg)
            if box is not None:
                acc[box] += img - bg[box]
                np.maximum(amax[box], a, out=amax[box])
        rendered[i] = acc / len(sub)
        cw, nw = _marker_world(sc, t)
        X = np.concatenate([mount, ref, cw])
        p = cam.project(X)
        view = X @ cam.R.T + cam.t  # camera-frame position = the view ray
        normal = np.concatenate([np.tile([0, 0, 1.0], (len(mount) + len(ref), 1)), np.tile(nw, (len(cw), 1))])
        cosv = np.einsum("ij,ij->i", view, normal @ cam.R.T) / np.linalg.norm(view, axis=1)
        facing = cosv < 0
        inside = np.all((p >= -0.5) & (p <= size - 0.5), axis=1)
        v = facing & inside
        for j in range(len(mount) + len(ref)):  # a static dot under the wing is not visible
            if v[j]:
                xi, yi = int(round(p[j, 0])), int(round(p[j, 1]))
                if amax[max(yi - 3, 0): yi + 4, max(xi - 3, 0): xi + 4].max() > 0.02:
                    v[j] = False
        truth[i], vis[i], tilt[i] = p, v, np.rad2deg(np.arccos(np.clip(-cosv, -1, 1)))

    yy, xx = np.mgrid[0:size, 0:size].astype(float)
    illum = 1.0 + sc.ramp[0] * (xx / size - 0.5) + sc.ramp[1] * (yy / size - 0.5)
    frames, pts, visible = [], [], []
    last = None
    for j, i in enumerate(order):
        pts.append(truth[i])
        if j in black:
            frames.append(np.zeros((size, size), np.uint8 if bits == 8 else np.uint16))
            visible.append(np.zeros_like(vis[i]))
            continue
        visible.append(vis[i])
        if j > 0 and order[j - 1] == i and j not in renoise:
            frames.append(frames[-1].copy())  # byte-identical repeat
            continue
        g = sc.glare2
        gx, gy = g[0] + g[2] * j, g[1] + 0.5 * g[2] * j
        glare2 = g[3] * np.exp(-0.5 * ((xx - gx) ** 2 + (yy - gy) ** 2) / 110.0**2)
        frames.append(_finish(rendered[i], nrng, bits, illum, glare2, noise))
    return IndependentSequence(camera, kind, int(seed), np.stack(frames), np.stack(pts), np.stack(visible),
                               np.array(order), glitch, kinds, np.stack([tilt[i] for i in order]))
