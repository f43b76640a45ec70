"""Named validation scenarios that mimic what real high-speed footage does to markers.

Each scenario is a :func:`~wingphoto.synth.render_flapping` sequence (exact truth) changed
by the things real footage does: glare and moving glare gradients, lamp flicker,
hand-painted markers (non-circular, textured, of varied contrast), specular highlights on
the markers, faint markers, wing veins as clutter, shot, read and fixed-pattern sensor
noise, vignetting, motion blur, markers turning edge-on, markers entering and leaving
the frame, and the glitches of a recording: dropped, repeated and black frames and a
bumped camera. Every change keeps the truth exact (see Notes).

The seeds are split: tune on :data:`DEV_SEEDS`, report :data:`TEST_SEEDS` only. A seed
chooses the wing-beat phase of frame 0, the noise and every random property of the
scenario (marker shapes, glare paths, glitch frames), so the two sets are different
sequences of the same kinds.

Examples
--------
>>> from wingphoto.synth import scenarios
>>> seq = scenarios.render_scenario("bumped_camera", seed=0, n_frames=4)
>>> seq.left.shape, seq.left.dtype.name, seq.params["scenario"]
((4, 512, 512), 'uint8', 'bumped_camera')
>>> set(scenarios.DEV_SEEDS) & set(scenarios.TEST_SEEDS)
set()
"""
from __future__ import annotations

import dataclasses
import zlib
from dataclasses import dataclass, field

import cv2
import numpy as np

from .flapping import _shade, _to_camera, render_flapping
from .raster import _disc_coverage, _disc_geometry
from .rig import CAMERAS, LEVELS, scene_frame, thesis_rig
from .wing import _MARKER_SIGMA, _MARKER_XI, _WING_HINGE, _WingModel, _n_wing_markers

__all__ = ["SCENARIOS", "DEV_SEEDS", "TEST_SEEDS", "describe", "render_scenario"]

#: Seeds to develop and tune on.
DEV_SEEDS = (0, 1, 2)
#: Held-out seeds: report them, never tune on them.
TEST_SEEDS = (1000, 1001, 1002)


@dataclass(frozen=True)
class _Spec:
    description: str
    render: dict = field(default_factory=dict)  # render_flapping keywords
    n_frames: int = 80
    markers: str = None  # None, "painted", "specular" or "faint"
    veins: bool = False
    glare_field: float = 0.0  # peak of a moving image-space glare gradient, grey levels
    flicker: float = 0.0  # relative amplitude of the lamp flicker
    vignetting: float = 0.0  # relative fall-off at the image corners
    sensor: str = "plain"  # "plain" (read noise 1 DN) or "real" (shot + read + fixed pattern)
    glitch: str = None  # None, "dropped", "repeated", "black", "bumped"
    cc_shift: tuple = None  # principal-point shifts (left, right), px: content leaves the frame
    blur_sigma: float = 0.7


_CLEAN = dict(preset="clean", glare=True)
_FAST = dict(preset="clean", glare=True, stroke_amplitude_deg=100.0, flap_hz=40.0)

_SPECS = {
    "clean_glare": _Spec("clean 80 deg stroke with a specular glare patch sweeping over the wing", _CLEAN),
    "moving_glare": _Spec("glare patch plus a broad glare gradient moving across the image (up to ~90 DN)",
                          _CLEAN, glare_field=90.0),
    "flicker": _Spec("lamp flicker: the whole image's brightness varies +-20 % (100 Hz at 3000 fps) with "
                     "3 % frame-to-frame jitter", _CLEAN, flicker=0.2),
    "painted_markers": _Spec("hand-painted markers: non-circular (a disc with two point-symmetric lobes), "
                             "textured (+-15-35 % stripes), contrast 45-100 %, under a moving glare gradient",
                             dict(preset="clean"), markers="painted", glare_field=40.0),
    "specular_markers": _Spec("a specular highlight on each marker, off its centre (up to +150 DN, "
                              "saturating); the truth is the shape's centre", dict(preset="clean"),
                              markers="specular", glare_field=30.0),
    "faint_markers": _Spec("faint markers (30-75 DN above the membrane) with shot, read and "
                           "fixed-pattern sensor noise", dict(preset="clean"), markers="faint", sensor="real"),
    "vein_clutter": _Spec("wing veins and a bright leading-edge spar drawn on the membrane as clutter "
                          "next to the markers", _CLEAN, veins=True),
    "sensor_noise": _Spec("shot noise, read noise 1.5 DN, fixed-pattern noise (per-pixel offsets and "
                          "gains, column offsets, hot pixels) on the sensor grid", _CLEAN, sensor="real"),
    "vignetting": _Spec("vignetting: brightness falls by ~55 % towards the corners (off-centre)", _CLEAN,
                        vignetting=0.55),
    "motion_blur": _Spec("100 deg stroke at 40 Hz, motion blur over the whole frame interval (333 us)",
                         dict(_FAST, motion_blur=True, exposure=1.0), n_frames=60),
    "edge_on": _Spec("80 deg pitch: markers foreshorten to edge-on and back every half beat",
                     dict(_CLEAN, pitch_deg=80.0, camber=0.06)),
    "enter_leave": _Spec("principal points shifted so that the wing tip leaves and re-enters the frame",
                         dict(_CLEAN, stroke_amplitude_deg=100.0), cc_shift=((0.0, 165.0), (0.0, -150.0))),
    "dropped_frames": _Spec("fast stroke (100 deg, 40 Hz) with 3 single frames and one pair of frames "
                            "dropped by the recorder", _FAST),
    "repeated_frames": _Spec("fast stroke with 3 frames delivered twice (identical bytes)", _FAST),
    "black_frame": _Spec("fast stroke with two all-black frames (no marker visible in them)", _FAST),
    "bumped_camera": _Spec("the left camera is bumped by a few px (3-7, 2-5) mid-sequence; the truth "
                           "shifts with it; the right camera is untouched", _CLEAN, glitch="bumped"),
    "hard_stroke": _Spec("the hard preset: 110 deg stroke, 60 deg pitch, glare, motion blur, "
                         "edge-on and near-merging markers", dict(preset="hard"), n_frames=60),
}
for _name, _g in (("dropped_frames", "dropped"), ("repeated_frames", "repeated"), ("black_frame", "black")):
    _SPECS[_name] = dataclasses.replace(_SPECS[_name], glitch=_g)

#: Names of the scenarios, in the order the benchmark prints them.
SCENARIOS = tuple(_SPECS)


def describe(name):
    """One-line description of scenario ``name`` (str)."""
    return _spec(name).description


def _spec(name):
    if name not in _SPECS:
        raise ValueError(f"name must be one of the scenarios {list(SCENARIOS)}, got {name!r}")
    return _SPECS[name]


# ============================================================== geometry of the markers
def _wing_state(seq):
    """Recreate the wing of a render_flapping sequence: a function t -> wing marker centres
    and normals (left camera frame), the light direction and the vein polylines."""
    p = seq.params
    S, B = scene_frame(seq.rig)
    wing = _WingModel(hinge=_WING_HINGE, stroke_amplitude_deg=p["stroke_amplitude_deg"], pitch_deg=p["pitch_deg"],
                      camber=p["camber"], bend_mm=p["bend_mm"], flap_hz=p["flap_hz"], phase_deg=p["phase_deg"])
    sig_m = np.repeat(_MARKER_SIGMA, len(_MARKER_XI))
    xi_m = np.tile(_MARKER_XI, len(_MARKER_SIGMA))

    def markers(t):
        return S + wing.surface(sig_m, xi_m, t) @ B.T, wing.normals(sig_m, xi_m, t) @ B.T

    def veins(t):
        """Polylines (M, K, 3) on the wing and their brightness (grey levels) and width."""
        s = np.linspace(0.02, 0.99, 60)
        lines, level, width = [], [], []
        for xi, lv, w in ((0.0, 55.0, 2), (0.34, 28.0, 1), (0.66, 22.0, 1)):
            lines.append(S + wing.surface(s, np.full_like(s, xi), t) @ B.T)
            level.append(lv)
            width.append(w)
        c = np.linspace(0.0, 1.0, 60)
        for sv in (0.37, 0.65, 0.93):
            lines.append(S + wing.surface(np.full_like(c, sv), c, t) @ B.T)
            level.append(22.0)
            width.append(1)
        return lines, level, width

    light = B @ np.array([0.2, -0.4, -1.0])
    return markers, veins, light / np.linalg.norm(light)


def _marker_traits(rng, n, kind):
    """Per-marker shape, texture, contrast and highlight (the same in both views)."""
    tr = dict(
        lobe_a=rng.uniform(0.5, 0.8, n), lobe_r=rng.uniform(0.45, 0.7, n), lobe_phi=rng.uniform(0, np.pi, n),
        tex_amp=rng.uniform(0.15, 0.35, n), tex_k=rng.uniform(1.5, 3.0, n), tex_dir=rng.uniform(0, np.pi, n),
        tex_phase=rng.uniform(0, 2 * np.pi, n), contrast=np.ones(n),
        spec_peak=np.zeros(n), spec_off=rng.uniform(0.3, 0.6, n), spec_dir=rng.uniform(0, 2 * np.pi, n),
        spec_size=rng.uniform(0.12, 0.22, n), spec_phase=rng.uniform(0, 2 * np.pi, n),
    )
    if kind == "painted":
        tr["contrast"] = rng.uniform(0.45, 1.0, n)
    elif kind == "faint":
        tr["contrast"] = rng.uniform(0.3, 0.45, n)
    elif kind == "specular":
        tr["contrast"] = rng.uniform(0.55, 0.8, n)  # a diffuse white the highlight can exceed
        tr["spec_peak"] = rng.uniform(60.0, 150.0, n)
    return tr


def _paint_markers(img, cam, side, rig, X, Nrm, radii, light, supersample, traits, kind, k, mask):
    """Repaint the wing markers of one unblurred frame as ``kind`` markers (in place).

    The renderer composited each disc as ``under (1 - c) + v c`` (``c`` its exact coverage,
    ``v`` its shaded paint). This removes that disc and composites the new marker, whose
    shape (the disc, plus two lobes point-symmetric about its centre for painted
    markers) keeps its centroid at the disc's centre; texture, contrast and highlights
    change its brightness only. ``mask`` receives the union of the markers' coverage.
    """
    Xc, nc = _to_camera(rig, side, X, Nrm)
    geom = _disc_geometry(cam, Xc, nc, radii)
    x0, y0, cov = _disc_coverage(cam, Xc, nc, radii, ss=supersample, geometry=geom)
    p0, J = geom[0], geom[1]
    vals = LEVELS["paint"] * _shade(Nrm, light, 0.75)
    m, b = cov.shape[:2]
    ss = 6
    o = (np.arange(ss) + 0.5) / ss - 0.5
    grid = (np.arange(b)[:, None] + o[None, :]).ravel()  # (b * ss,)
    h, w = img.shape
    for i in range(m):
        if not np.all(np.isfinite(p0[i])) or Xc[i, 2] <= 0:
            continue
        qx = x0[i] + grid[None, :] - p0[i, 0]
        qy = y0[i] + grid[:, None] - p0[i, 1]
        try:
            Ji = np.linalg.inv(J[i])
        except np.linalg.LinAlgError:
            continue
        u = (Ji[0, 0] * qx + Ji[0, 1] * qy) / radii[i]  # disc-plane coordinates, in radii
        v = (Ji[1, 0] * qx + Ji[1, 1] * qy) / radii[i]
        rho2 = u * u + v * v
        disc = rho2 <= 1.0
        inside = disc.copy()
        if kind == "painted":
            ca, sa = np.cos(traits["lobe_phi"][i]), np.sin(traits["lobe_phi"][i])
            a, rl = traits["lobe_a"][i], traits["lobe_r"][i]
            for sgn in (1.0, -1.0):
                inside |= (u - sgn * a * ca) ** 2 + (v - sgn * a * sa) ** 2 <= rl * rl
            d = traits["tex_dir"][i]
            g = 1.0 - traits["tex_amp"][i] * (0.5 + 0.5 * np.cos(
                traits["tex_k"][i] * np.pi * (np.cos(d) * u + np.sin(d) * v) + traits["tex_phase"][i]))
        else:
            g = np.ones_like(u)
        value = vals[i] * traits["contrast"][i] * g
        if traits["spec_peak"][i] > 0:
            r0, dr = traits["spec_off"][i], traits["spec_dir"][i]
            s2 = traits["spec_size"][i] ** 2
            flick = 0.6 + 0.4 * np.sin(0.21 * k + traits["spec_phase"][i] + (1.3 if side == "right" else 0.0))
            value = value + traits["spec_peak"][i] * flick * np.exp(
                -((u - r0 * np.cos(dr)) ** 2 + (v - r0 * np.sin(dr)) ** 2) / (2 * s2))

        def pool(a):
            return a.reshape(b, ss, b, ss).mean(axis=(1, 3))

        lobes = pool((inside & ~disc).astype(np.float64))  # coverage of the lobes outside the disc
        n_in = pool(inside.astype(np.float64))
        vmean = np.where(n_in > 0, pool(np.where(inside, value, 0.0)) / np.maximum(n_in, 1e-12),
                         vals[i] * traits["contrast"][i])
        c = cov[i]
        C = 1.0 - (1.0 - c) * (1.0 - lobes)
        xa, ya = int(x0[i]), int(y0[i])
        xs0, ys0, xs1, ys1 = max(xa, 0), max(ya, 0), min(xa + b, w), min(ya + b, h)
        if xs1 <= xs0 or ys1 <= ys0:
            continue
        sl = (slice(ys0 - ya, ys1 - ya), slice(xs0 - xa, xs1 - xa))
        region = img[ys0:ys1, xs0:xs1]
        under = region - vals[i] * c[sl]  # = under (1 - c)
        region[...] = under * (1.0 - lobes[sl]) + vmean[sl] * C[sl]
        mk = mask[ys0:ys1, xs0:xs1]
        mk[...] = 1.0 - (1.0 - mk) * (1.0 - C[sl])


def _marker_mask(cam, side, rig, X, Nrm, radii, supersample):
    """Union of the wing markers' exact coverage in one frame (H, W)."""
    w, h = cam.image_size
    mask = np.zeros((h, w), np.float32)
    Xc, nc = _to_camera(rig, side, X, Nrm)
    x0, y0, cov = _disc_coverage(cam, Xc, nc, radii, ss=supersample)
    b = cov.shape[1]
    for i in range(len(x0)):
        xa, ya = int(x0[i]), int(y0[i])
        xs0, ys0, xs1, ys1 = max(xa, 0), max(ya, 0), min(xa + b, w), min(ya + b, h)
        if xs1 > xs0 and ys1 > ys0:
            mk = mask[ys0:ys1, xs0:xs1]
            mk[...] = 1.0 - (1.0 - mk) * (1.0 - cov[i, ys0 - ya : ys1 - ya, xs0 - xa : xs1 - xa])
    return mask


def _draw_veins(cam, side, rig, lines, levels, widths, shape):
    """Anti-aliased vein lines (float32 image of added grey levels)."""
    out = np.zeros(shape, np.float32)
    for pts, lv, wd in zip(lines, levels, widths):
        Xc = _to_camera(rig, side, pts)[0]
        if np.any(Xc[:, 2] <= 0):
            continue
        p = cam.project(Xc)
        canvas = np.zeros(shape, np.uint8)
        q = np.rint(np.clip(p, -1e4, 1e4) * 16).astype(np.int32)
        cv2.polylines(canvas, [q], False, 255, thickness=wd, lineType=cv2.LINE_AA, shift=4)
        out += canvas.astype(np.float32) * np.float32(lv / 255.0)
    return out


# ====================================================================== image effects
def _glare_field(rng, shape, n, peak):
    """A broad glare blob and gradient moving across the image: (n, H, W) generator."""
    h, w = shape
    a = rng.uniform([0, 0], [w, h])
    z = rng.uniform([0, 0], [w, h])
    sig = rng.uniform(50.0, 110.0)
    slope = rng.normal(0.0, 0.04, 2)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)

    def at(k):
        f = k / max(n - 1, 1)
        c = a + f * (z - a)
        blob = np.exp(-((xs - c[0]) ** 2 + (ys - c[1]) ** 2) / np.float32(2 * sig * sig))
        grad = (slope[0] * (xs - w / 2) + slope[1] * (ys - h / 2)) * np.float32(np.sin(np.pi * f))
        return np.float32(peak) * blob + np.maximum(grad, 0).astype(np.float32) * np.float32(peak / 40.0)

    return at


def _vignette(rng, shape, strength):
    h, w = shape
    c = np.array([w / 2, h / 2]) + rng.uniform(-40, 40, 2)
    ys, xs = np.mgrid[0:h, 0:w]
    r2 = ((xs - c[0]) ** 2 + (ys - c[1]) ** 2) / (0.25 * (w * w + h * h))
    return (1.0 - strength * np.clip(r2, 0, 1.6) / 1.0).clip(0.2, 1.0).astype(np.float32)


@dataclass(frozen=True)
class _Sensor:
    read: float = 1.0
    dn_per_electron: float = 0.0  # shot noise variance per grey level (0: none)
    offset: np.ndarray = None  # (H, W) fixed-pattern offsets, grey levels
    gain: np.ndarray = None  # (H, W) fixed-pattern gains

    def expose(self, img, rng):
        img = np.asarray(img, np.float32)
        if self.gain is not None:
            img = img * self.gain
        if self.dn_per_electron > 0:
            img = img + np.sqrt(np.maximum(img, 0) * np.float32(self.dn_per_electron)) * rng.standard_normal(
                img.shape, dtype=np.float32)
        if self.read > 0:
            img = img + np.float32(self.read) * rng.standard_normal(img.shape, dtype=np.float32)
        if self.offset is not None:
            img = img + self.offset
        return np.rint(np.clip(img, 0.0, 255.0)).astype(np.uint8)


def _sensor(kind, rng, shape):
    if kind == "plain":
        return _Sensor(read=1.0)
    h, w = shape
    offset = rng.normal(0.0, 1.5, shape) + rng.normal(0.0, 1.0, (1, w))  # DSNU + column offsets
    hot = rng.random(shape) < 5e-4
    offset[hot] += rng.uniform(30, 90, hot.sum())
    gain = 1.0 + rng.normal(0.0, 0.015, shape)  # PRNU
    return _Sensor(read=1.5, dn_per_electron=0.15, offset=offset.astype(np.float32), gain=gain.astype(np.float32))


# ============================================================================ glitches
def _glitch_plan(kind, n_out, rng):
    """Source-frame index of each delivered frame, extra frames to render, black frames."""
    if kind == "dropped":
        n_src = n_out + 5
        keep = np.ones(n_src, bool)
        singles = rng.choice(np.arange(5, n_src - 8), 3, replace=False)
        keep[singles] = False
        free = np.flatnonzero(keep[5:-3]) + 5
        start = rng.choice(free[np.isin(free + 1, free)])
        keep[[start, start + 1]] = False
        src = np.flatnonzero(keep)[:n_out]
        return src, n_src, np.zeros(0, int)
    if kind == "repeated":
        n_src = n_out - 3
        rep = np.sort(rng.choice(np.arange(3, n_src - 3), 3, replace=False))
        src = np.sort(np.concatenate([np.arange(n_src), rep]))
        return src, n_src, np.zeros(0, int)
    if kind == "black":
        black = np.sort(rng.choice(np.arange(5, n_out - 5), 2, replace=False))
        return np.arange(n_out), n_out, black
    return np.arange(n_out), n_out, np.zeros(0, int)


def _shift_image(img, dx, dy):
    """Shift an image by whole pixels (content moves by +dx, +dy), edges replicated."""
    M = np.float32([[1, 0, dx], [0, 1, dy]])
    h, w = img.shape
    return cv2.warpAffine(img, M, (w, h), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)


# ============================================================================= public
def render_scenario(name, *, seed, n_frames=None):
    """Render a named validation scenario with exact truth.

    Parameters
    ----------
    name : str
        One of :data:`SCENARIOS` (:func:`describe` says what each does).
    seed : int
        Chooses the wing-beat phase of frame 0, the noise and every random property of the
        scenario. Tune on :data:`DEV_SEEDS`, report :data:`TEST_SEEDS`.
    n_frames : int, optional
        Frames delivered per camera (default 80; 60 for the motion-blurred scenarios,
        whose rendering is slower). At least 20 for the glitch scenarios.

    Returns
    -------
    StereoSequence
        512 x 512 uint8 frames of both cameras, the 26 points of :func:`render_flapping`
        (0-17 wing markers, 18-19 the mount, 20-25 the static reference dots) with their
        exact truth ``points_left/right`` (T, N, 2) and visibility ``visible_left/right``;
        ``params["scenario"]``, ``params["scenario_seed"]`` and the scenario's settings
        (glitch frames, camera shift) are recorded in ``params``.

    Raises
    ------
    ValueError
        Unknown ``name``; ``n_frames`` too small.

    Notes
    -----
    The wing is rendered by :func:`render_flapping` without noise and without optics
    blur (float grey levels). Then, per frame and camera, in this order:

    1. markers (``painted``, ``specular``, ``faint`` scenarios): each wing marker's disc,
       which the renderer composited with its exact anti-aliased coverage, is replaced by
       the scenario's marker, drawn in the disc's own plane (it foreshortens with it):
       its *shape* is the disc or the disc plus two lobes placed point-symmetrically
       about its centre, so the shape's centroid is the disc's centre, which stays the
       truth; texture, contrast and a specular highlight (a Gaussian spot off the
       centre, on the marker only) change brightness, not shape;
    2. veins: anti-aliased lines along material lines of the wing, under the markers;
    3. light: a moving image-space glare gradient (added), vignetting (a fixed gain),
       lamp flicker (a per-frame gain, the same for both cameras);
    4. the bumped camera: from a random frame on, the left image is shifted by whole
       pixels (exact) and its truth by the same amount; markers within 8 px of the
       border after the shift are not visible;
    5. optics blur (0.7 px Gaussian), then the sensor on its own grid: fixed-pattern
       gain, shot noise, read noise, fixed-pattern offsets (fixed per camera for the
       whole sequence), saturation at 255, rounding to uint8.

    Glitches act on the delivered sequence: dropped frames are rendered and removed
    (frames and truth), repeated frames are delivered twice (identical bytes and truth),
    black frames are all zero with no point visible in them. ``times`` keeps each
    delivered frame's true time. Markers leaving the frame (``enter_leave``) come from
    the renderer itself: the principal points are shifted, so its visibility rule (the
    whole disc inside the image) applies.

    The truth of a wing marker is the projection of its centre (a projected disc's
    centroid differs from it by < 0.01 px, see :func:`render_flapping`).
    """
    spec = _spec(name)
    seed = int(seed)
    n_out = spec.n_frames if n_frames is None else int(n_frames)
    if n_out < (20 if spec.glitch in ("dropped", "repeated", "black") else 1):
        raise ValueError(f"n_frames must be >= 20 for {name!r} (its glitches need room), got {n_out}")
    rng = np.random.default_rng([seed, zlib.crc32(name.encode())])
    src, n_src, black = _glitch_plan(spec.glitch, n_out, rng)
    rig = thesis_rig()
    if spec.cc_shift is not None:
        cams = {side: getattr(rig, side).replace(cc=getattr(rig, side).cc + np.asarray(d, float))
                for side, d in zip(CAMERAS, spec.cc_shift)}
        rig = rig.replace(**cams)
    phase = float(rng.uniform(0.0, 360.0))
    kw = dict(spec.render)
    base = render_flapping(rig, n_frames=n_src, phase_deg=phase, noise_std=0.0, blur_sigma=0.0,
                           dtype=np.float32, seed=seed, **kw)
    markers_at, veins_at, light = _wing_state(base)
    n_wing = _n_wing_markers()
    radii = 0.5 * base.marker_diameter_mm[:n_wing]
    supersample = int(base.params["supersample"])
    traits = _marker_traits(rng, n_wing, spec.markers) if spec.markers else None
    shape = base.left.shape[1:]
    flick = np.ones(n_src, np.float32)
    if spec.flicker:
        flick = (1.0 + spec.flicker * np.sin(2 * np.pi * np.arange(n_src) / 30.0 + rng.uniform(0, 2 * np.pi))
                 + 0.03 * rng.standard_normal(n_src)).astype(np.float32)
    bump_at, bump = None, (0, 0)
    if spec.glitch == "bumped":
        bump_at = int(rng.integers(n_out // 3, max(2 * n_out // 3, n_out // 3 + 1)))
        bump = (int(rng.integers(3, 8) * rng.choice([-1, 1])), int(rng.integers(2, 6) * rng.choice([-1, 1])))
    images, points = {}, {}
    visible = {}
    for side in CAMERAS:
        cam = getattr(base.rig, side)
        srng = np.random.default_rng([seed, zlib.crc32(name.encode()), 1 + CAMERAS.index(side)])
        sensor = _sensor(spec.sensor, srng, shape)
        glare = _glare_field(srng, shape, n_src, spec.glare_field) if spec.glare_field else None
        vig = _vignette(srng, shape, spec.vignetting) if spec.vignetting else None
        frames = np.empty((n_src,) + shape, np.uint8)
        for k in range(n_src):
            img = np.array(base.frames(side)[k], dtype=np.float32)
            t = float(base.times[k])
            if spec.markers or spec.veins:
                X, Nrm = markers_at(t)
                mask = np.zeros(shape, np.float32)
                if spec.markers:
                    _paint_markers(img, cam, side, base.rig, X, Nrm, radii, light, supersample, traits,
                                   spec.markers, k, mask)
                else:
                    mask = _marker_mask(cam, side, base.rig, X, Nrm, radii, supersample)
                if spec.veins:
                    lines, levels, widths = veins_at(t)
                    img += _draw_veins(cam, side, base.rig, lines, levels, widths, shape) * (1.0 - mask)
            if glare is not None:
                img += glare(k)
            if vig is not None:
                img *= vig
            img *= flick[k]
            if bump_at is not None and side == "left" and k >= bump_at:
                img = _shift_image(img, *bump)
            if spec.blur_sigma > 0:
                img = cv2.GaussianBlur(img, (0, 0), sigmaX=spec.blur_sigma, sigmaY=spec.blur_sigma,
                                       borderType=cv2.BORDER_REPLICATE)
            frames[k] = sensor.expose(img, srng)
        out = frames[src]
        out[black] = 0
        pts = np.array(getattr(base, f"points_{side}")[src])
        vis = np.array(getattr(base, f"visible_{side}")[src])
        vis[black] = False
        if bump_at is not None and side == "left":
            pts[bump_at:] += bump
            w, h = cam.image_size
            m = 8.0
            inside = (pts[..., 0] >= m) & (pts[..., 0] <= w - 1 - m) & (pts[..., 1] >= m) & (pts[..., 1] <= h - 1 - m)
            vis[bump_at:] &= inside[bump_at:]
        images[side], points[side], visible[side] = out, pts, vis
    params = dict(base.params, scenario=name, scenario_seed=seed, description=spec.description,
                  source_frames=src.tolist(), black_frames=black.tolist(),
                  bump_frame=bump_at, bump_px=list(bump), cc_shift=spec.cc_shift, sensor=spec.sensor,
                  markers=spec.markers, veins=spec.veins, glare_field=spec.glare_field, flicker=spec.flicker,
                  vignetting=spec.vignetting, blur_sigma=spec.blur_sigma)
    return dataclasses.replace(
        base, left=images["left"], right=images["right"], points3d=base.points3d[src],
        points_left=points["left"], points_right=points["right"],
        visible_left=visible["left"], visible_right=visible["right"], times=base.times[src],
        noise_std=1.5 if spec.sensor == "real" else 1.0, blur_sigma=spec.blur_sigma,
        stroke_angle_deg=base.stroke_angle_deg[src], pitch_angle_deg=base.pitch_angle_deg[src], params=params,
    )
