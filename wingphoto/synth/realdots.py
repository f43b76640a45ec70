"""Sequences of known motion made from real photographs of white dots.

``../shared/data/real-dots/`` holds two real calibration photographs (``cal1.tif``,
``cal2.tif``: white dots on a black stepped plate, 1280 x 1024, two different cameras)
and a reference centroid for each dot (``camN_cal_points``, MyPTV's, ~0.1 px). Read its
``SOURCE.txt``. :func:`render_realdots` moves the photograph by a known flapping-like
warp - a rotation about a hinge outside the view (peak speed 10-15 px/frame),
foreshortening, a little perspective - adds glare, flicker and motion blur, and then
the sensor's fixed-pattern and read noise *after* warping (on the sensor grid, as in real
video). The truth of a dot is its reference centroid mapped through the same warp, so
the tracker meets real dot texture (faint dots, specular highlights, real noise) with
exactly known motion; the truth is as good as the reference centroids (~0.1-0.15 px).

The folder is looked for in ``$WINGPHOTO_SHARED/data/real-dots`` or ``../shared/data/real-dots``
next to the repository; :func:`render_realdots` raises ``FileNotFoundError`` when it is
absent. The data are not copied into the repository.
"""
from __future__ import annotations

import os
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

__all__ = ["CAMERAS", "DEV_SEEDS", "GLITCHES", "TEST_SEEDS", "RealDotSequence", "default_folder", "render_realdots",
           "with_glitch"]

#: The photographs: camera name -> (image file, reference centroid file).
_FILES = {"cam1": ("cal1.tif", "cam1_cal_points"), "cam2": ("cal2.tif", "cam2_cal_points")}
CAMERAS = tuple(_FILES)
#: Seeds to develop on, and held-out seeds to report.
DEV_SEEDS = (0, 1, 2)
TEST_SEEDS = (1000, 1001, 1002)
#: The glitches :func:`with_glitch` puts into a sequence.
GLITCHES = ("dropped", "repeated", "black", "bumped")
#: Source frames a glitched sequence needs beyond the frames it delivers (the dropped ones).
GLITCH_SPARE = 5


def default_folder():
    """Where the real-dot photographs are expected (Path; it may not exist)."""
    shared = os.environ.get("WINGPHOTO_SHARED")
    base = Path(shared) if shared else Path(__file__).resolve().parents[3] / "shared"
    return base / "data" / "real-dots"


@dataclass(frozen=True)
class RealDotSequence:
    """A one-camera sequence of real dots moved by known warps, with its truth.

    Attributes
    ----------
    camera : str
        ``'cam1'`` or ``'cam2'``: the photograph it was made from.
    images : (T, H, W) ndarray of uint8
        The frames.
    points : (T, N, 2) ndarray
        True dot centres, px (x, y), origin at the centre of the top-left pixel: each
        dot's reference centroid mapped through the frame's warp.
    visible : (T, N) ndarray of bool
        The dot lies at least ``params["margin_px"]`` inside the frame.
    homographies : (T, 3, 3) ndarray
        Photograph pixel -> frame pixel (mid-exposure), same pixel convention.
    params : dict
        Settings (seed, warp amplitudes, noise, ...).
    """

    camera: str
    images: np.ndarray
    points: np.ndarray
    visible: np.ndarray
    homographies: np.ndarray
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        for name in ("images", "points", "visible", "homographies"):
            a = np.array(getattr(self, name))
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def __len__(self):
        return self.images.shape[0]

    def head(self, n_frames):
        """The first ``n_frames`` frames of this sequence, with their truth (a new sequence)."""
        n = int(n_frames)
        if not 1 <= n <= len(self):
            raise ValueError(f"n_frames must be between 1 and {len(self)} (this sequence's length), got {n_frames!r}")
        return RealDotSequence(camera=self.camera, images=self.images[:n], points=self.points[:n],
                               visible=self.visible[:n], homographies=self.homographies[:n], params=dict(self.params))

    def _check(self, camera):
        if camera != self.camera:
            raise ValueError(f"camera must be {self.camera!r} (this sequence's camera), got {camera!r}")

    def frames(self, camera=None):
        """The (T, H, W) frames (``camera``, if given, must be this sequence's)."""
        if camera is not None:
            self._check(camera)
        return self.images

    def picks(self, camera=None):
        """Frame-0 positions as a person clicks them (rounded); NaN where not visible. (N, 2)."""
        if camera is not None:
            self._check(camera)
        out = np.rint(self.points[0]).astype(np.float64)
        out[~self.visible[0]] = np.nan
        return out


def _load(folder, camera):
    if camera not in _FILES:
        raise ValueError(f"camera must be one of {list(CAMERAS)}, got {camera!r}")
    folder = default_folder() if folder is None else Path(folder)
    img_name, pts_name = _FILES[camera]
    img_path, pts_path = folder / img_name, folder / pts_name
    if not (img_path.is_file() and pts_path.is_file()):
        raise FileNotFoundError(
            f"real-dot photographs not found: need {img_path} and {pts_path} "
            f"(set WINGPHOTO_SHARED to the folder holding data/real-dots, or pass folder=)"
        )
    import tifffile

    image = np.asarray(tifffile.imread(img_path))
    if image.ndim == 3:
        image = image[..., 0]
    ref = np.loadtxt(pts_path, ndmin=2)[:, :2]
    return image.astype(np.float32), ref


def _warp_point(H, p):
    q = np.c_[p, np.ones(len(p))] @ H.T
    return q[:, :2] / q[:, 2:3]


def render_realdots(camera, *, seed, n_frames=None, size=256, folder=None, peak_speed=(10.0, 15.0), exposure=0.4):
    """Move a real photograph of dots by known warps: a tracking sequence with exact motion.

    Parameters
    ----------
    camera : {'cam1', 'cam2'}
        Which photograph (cam1's dots carry small specular highlights off their centre).
    seed : int
        Chooses the region, the plate's orientation, the flapping motion (period 50-70
        frames, peak speed 10-15 px/frame at the view's centre), the glare path, the flicker
        and the noise. Tune on :data:`DEV_SEEDS`, report :data:`TEST_SEEDS`.
    n_frames : int, optional
        Frames (default 60).
    size : int, optional
        Width and height of the frames, px (default 256).
    folder : str or Path, optional
        Folder of the photographs (default :func:`default_folder`).
    peak_speed : (float, float), optional
        Range (px/frame) the peak speed at the view's centre is drawn from (default 10-15,
        the validation sweep's; a milder warp, e.g. (3, 5), is a steadier camera rate).
    exposure : float, optional
        Exposure as a share of the frame interval (default 0.4; 0: no motion blur).

    Returns
    -------
    RealDotSequence

    Raises
    ------
    FileNotFoundError
        The photographs are not there.
    ValueError
        Unknown ``camera``; ``n_frames`` < 2, ``size`` < 64, ``peak_speed`` not two
        non-negative numbers in order or ``exposure`` outside [0, 1].

    Notes
    -----
    Frame ``k`` is the photograph warped by the homography
    ``H_k = T(h) R(theta_k) F_k T(-h) H_0`` (``H_0``: the region to the frame's centre,
    turned by a random angle; ``h``: a hinge ~1.3 frame widths to one side;
    ``theta_k = A sin(2 pi k / P + phi)``; ``F_k`` a foreshortening along the arm,
    scale 0.7-1, with a small perspective term), sampled by ``cv2.warpPerspective``
    (bicubic) at twice the resolution and reduced 2 x 2 (area average; the pixel-centre
    convention is kept exactly: frame pixel ``x`` is ``(x2 - 0.5) / 2`` of the doubled
    grid). Motion blur averages seven warps within ``exposure`` frame intervals (the truth is
    at its middle). Then a moving glare blob (up to 40 DN) and a +-15 % flicker, the
    fixed-pattern noise (per-pixel offsets 2.5 DN, column offsets 1.5 DN, fixed for the
    sequence) and read noise (1.2 DN) on the frame's own grid, rounding to uint8. The
    photograph's own noise moves with it (it is part of its texture).
    """
    n_frames = 60 if n_frames is None else int(n_frames)
    size = int(size)
    if n_frames < 2:
        raise ValueError(f"n_frames must be >= 2, got {n_frames}")
    if size < 64:
        raise ValueError(f"size must be >= 64 px, got {size}")
    lo_v, hi_v = (float(v) for v in peak_speed)
    if not 0 <= lo_v <= hi_v:
        raise ValueError(f"peak_speed must be (low, high) px/frame with 0 <= low <= high, got {peak_speed}")
    exposure = float(exposure)
    if not 0 <= exposure <= 1:
        raise ValueError(f"exposure must be a share of the frame interval in [0, 1], got {exposure}")
    image, ref = _load(folder, camera)
    rng = np.random.default_rng([int(seed), zlib.crc32(camera.encode())])
    ih, iw = image.shape
    # region: near the dots' middle, so that the view is full of dots
    lo, hi = ref.min(axis=0) + 0.35 * size, ref.max(axis=0) - 0.35 * size
    centre = rng.uniform(lo, np.maximum(hi, lo + 1))
    c_out = np.array([(size - 1) / 2, (size - 1) / 2])
    a0 = rng.uniform(0, 2 * np.pi)
    ca, sa = np.cos(a0), np.sin(a0)
    H0 = np.array([[1, 0, c_out[0]], [0, 1, c_out[1]], [0, 0, 1.0]]) @ np.array(
        [[ca, -sa, 0], [sa, ca, 0], [0, 0, 1.0]]) @ np.array([[1, 0, -centre[0]], [0, 1, -centre[1]], [0, 0, 1.0]])
    side = rng.choice([-1.0, 1.0])
    arm = 1.3 * size
    hinge = c_out + np.array([side * arm, rng.uniform(-0.3, 0.3) * size])
    period = rng.uniform(50, 70)
    speed = rng.uniform(lo_v, hi_v)  # px/frame at the view's centre, peak
    amp = speed * period / (2 * np.pi * np.linalg.norm(hinge - c_out))
    phi = rng.uniform(0, 2 * np.pi)
    fore = rng.uniform(0.0, 0.3)
    persp = rng.uniform(-1, 1) * 3e-4

    def H_at(t):
        th = amp * np.sin(2 * np.pi * t / period + phi)
        f = 1.0 - fore * (0.5 - 0.5 * np.cos(2 * np.pi * t / period + phi))
        c, s = np.cos(th), np.sin(th)
        u = (hinge - c_out) / np.linalg.norm(hinge - c_out)  # along the arm
        F = np.eye(3)
        F[:2, :2] = np.eye(2) + (f - 1.0) * np.outer(u, u)
        F[2, :2] = persp * np.sin(2 * np.pi * t / period) * np.array([-u[1], u[0]])
        Th = np.array([[1, 0, hinge[0]], [0, 1, hinge[1]], [0, 0, 1.0]])
        Tm = np.array([[1, 0, -hinge[0]], [0, 1, -hinge[1]], [0, 0, 1.0]])
        # foreshorten about the view's centre, then turn about the hinge
        Tc = np.array([[1, 0, c_out[0]], [0, 1, c_out[1]], [0, 0, 1.0]])
        Tcm = np.array([[1, 0, -c_out[0]], [0, 1, -c_out[1]], [0, 0, 1.0]])
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        return Th @ R @ Tm @ Tc @ F @ Tcm @ H0

    S2 = np.array([[2, 0, 0.5], [0, 2, 0.5], [0, 0, 1.0]])
    fill = float(np.median(image))
    offset = (rng.normal(0, 2.5, (size, size)) + rng.normal(0, 1.5, (1, size))).astype(np.float32)
    g_a, g_z = rng.uniform(0, size, 2), rng.uniform(0, size, 2)
    g_sig, g_peak = rng.uniform(30, 70), rng.uniform(15, 40)
    fl_phase = rng.uniform(0, 2 * np.pi)
    ys, xs = np.mgrid[0:size, 0:size].astype(np.float32)
    frames = np.empty((n_frames, size, size), np.uint8)
    Hs = np.empty((n_frames, 3, 3))
    for k in range(n_frames):
        Hs[k] = H_at(float(k))
        acc = np.zeros((size, size), np.float32)
        subs = k + exposure * ((np.arange(7) + 0.5) / 7 - 0.5) if exposure > 0 else [k]
        for t in subs:
            big = cv2.warpPerspective(image, S2 @ H_at(float(t)), (2 * size, 2 * size), flags=cv2.INTER_CUBIC,
                                      borderMode=cv2.BORDER_CONSTANT, borderValue=fill)
            acc += cv2.resize(big, (size, size), interpolation=cv2.INTER_AREA)
        img = acc / len(subs)
        f = k / max(n_frames - 1, 1)
        gc = g_a + f * (g_z - g_a)
        img += np.float32(g_peak) * np.exp(-((xs - gc[0]) ** 2 + (ys - gc[1]) ** 2) / np.float32(2 * g_sig**2))
        img *= np.float32(1.0 + 0.15 * np.sin(2 * np.pi * k / 30.0 + fl_phase))
        img += offset + np.float32(1.2) * rng.standard_normal((size, size), dtype=np.float32)
        frames[k] = np.rint(np.clip(img, 0, 255)).astype(np.uint8)
    pts = np.stack([_warp_point(H, ref) for H in Hs])
    margin = 6.0
    vis = np.all((pts >= margin) & (pts <= size - 1 - margin), axis=2)
    # the photograph's own border must not enter the view around a dot
    inside_src = np.all((ref >= 10) & (ref <= np.array([iw, ih]) - 11), axis=1)
    vis &= inside_src[None, :]
    keep = vis.any(axis=0)
    params = dict(camera=camera, seed=int(seed), size=size, n_frames=n_frames, region_centre=centre.tolist(),
                  rotation_deg=float(np.degrees(a0)), period_frames=float(period), peak_speed_px=float(speed),
                  stroke_amplitude_deg=float(np.degrees(amp)), foreshortening=float(fore), exposure=exposure,
                  glare_peak=float(g_peak), flicker=0.15, fixed_pattern_dn=2.5, read_noise_dn=1.2,
                  margin_px=margin, reference_rows=np.flatnonzero(keep).tolist())
    return RealDotSequence(camera=camera, images=frames, points=pts[:, keep], visible=vis[:, keep],
                           homographies=Hs, params=params)


def with_glitch(seq, kind, *, seed, n_frames=None, dropped_run=None):
    """A copy of a real-dot sequence with a recording glitch in it, the truth following.

    Parameters
    ----------
    seq : RealDotSequence
        Rendered with at least ``n_frames + GLITCH_SPARE`` frames.
    kind : {'dropped', 'repeated', 'black', 'bumped'}
        ``'dropped'``: two single frames and a run of three are left out (the truth
        skips with them); ``'repeated'``: three frames are delivered twice, the first
        repeat byte-identical and the other two with new read noise (1.5 DN);
        ``'black'``: two frames are all zero (their dots not visible); ``'bumped'``:
        from a frame between 15 and 44 on, the image and its truth are shifted by
        3-7 px in x and 2-5 px in y (whole pixels, edges replicated; dots within 6 px of
        the border then not visible).
    seed : int
        Chooses where the glitch falls and the bump's shift.
    n_frames : int, optional
        Frames delivered (default ``len(seq) - GLITCH_SPARE``).
    dropped_run : (int, int), optional
        For ``'dropped'`` only: leave out exactly the source frames ``start`` to
        ``start + length - 1`` instead (``length`` at most ``GLITCH_SPARE``): a stress
        test of where a run falls (before a stroke reversal it passes unseen).

    Returns
    -------
    RealDotSequence
        ``params["glitch"]`` says what was done (frames of the delivered sequence, or of
        the source sequence for ``'dropped'``); ``homographies`` are the source frames'
        (without the bump).

    Raises
    ------
    ValueError
        Unknown ``kind``, ``seq`` too short for ``n_frames``, or a ``dropped_run`` that does
        not fit.
    """
    if kind not in GLITCHES:
        raise ValueError(f"kind must be one of {list(GLITCHES)}, got {kind!r}")
    n_out = len(seq) - GLITCH_SPARE if n_frames is None else int(n_frames)
    if n_out < 20 or len(seq) < n_out + GLITCH_SPARE:
        raise ValueError(f"with_glitch needs n_frames >= 20 and a sequence of n_frames + {GLITCH_SPARE} frames; "
                         f"got n_frames {n_out} from {len(seq)} frames: render more frames")
    rng = np.random.default_rng([int(seed), zlib.crc32(kind.encode())])
    img, pts, vis = np.array(seq.images), np.array(seq.points, float), np.array(seq.visible)
    src = np.arange(n_out)
    info = {"kind": kind}
    if dropped_run is not None:
        start, length = (int(v) for v in dropped_run)
        if kind != "dropped" or not (1 <= start and 1 <= length <= GLITCH_SPARE and start + length <= n_out):
            raise ValueError(f"dropped_run (start, length) needs kind 'dropped', 1 <= start, 1 <= length <= "
                             f"{GLITCH_SPARE} and start + length <= n_frames ({n_out}); got {kind!r}, {dropped_run}")
    if kind == "dropped":
        keep = np.ones(n_out + GLITCH_SPARE, bool)
        if dropped_run is not None:
            keep[start:start + length] = False
        else:
            keep[rng.choice(np.arange(5, n_out - 8), 2, replace=False)] = False
            free = np.flatnonzero(keep[5:-6]) + 5
            start = int(rng.choice(free[np.isin(free + 1, free) & np.isin(free + 2, free)]))
            keep[start:start + 3] = False
        src = np.flatnonzero(keep)[:n_out]
        info["dropped_source_frames"] = np.flatnonzero(~keep).tolist()
    elif kind == "repeated":
        rep = np.sort(rng.choice(np.arange(4, n_out - 6), 3, replace=False))
        src = np.sort(np.concatenate([np.arange(n_out - 3), rep]))
        info["repeated_source_frames"] = rep.tolist()
    img, pts, vis = img[src], pts[src], vis[src]
    if kind == "repeated":
        again = np.flatnonzero(np.r_[False, src[1:] == src[:-1]])  # the second delivery of each
        for i in again[src[again] != rep[0]]:
            noisy = img[i].astype(np.float64) + rng.normal(0.0, 1.5, img[i].shape)
            img[i] = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
    elif kind == "black":
        black = np.sort(rng.choice(np.arange(5, n_out - 5), 2, replace=False))
        img[black] = 0
        vis[black] = False
        info["black_frames"] = black.tolist()
    elif kind == "bumped":
        k = int(rng.integers(15, 45))
        dx, dy = (int(rng.integers(lo, hi)) * int(rng.choice([-1, 1])) for lo, hi in ((3, 8), (2, 6)))
        h, w = img.shape[1:]
        M = np.float32([[1, 0, dx], [0, 1, dy]])
        for t in range(k, n_out):
            img[t] = cv2.warpAffine(img[t], M, (w, h), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)
        pts[k:] += (dx, dy)
        margin = float(seq.params.get("margin_px", 6.0))
        vis[k:] &= np.all((pts[k:] >= margin) & (pts[k:] <= np.array([w, h]) - 1 - margin), axis=2)
        info.update(bumped_from=k, shift=(dx, dy))
    params = dict(seq.params, n_frames=n_out, glitch=info)
    return RealDotSequence(camera=seq.camera, images=img, points=pts, visible=vis,
                           homographies=np.array(seq.homographies)[src], params=params)
