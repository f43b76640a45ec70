"""The thesis-like stereo rig, the scene frame and the per-pixel viewing rays of a camera."""
from __future__ import annotations

import functools
import json
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np

from ..camera import Camera, StereoRig




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
