"""Rendering of a flapping-wing stereo sequence (membrane, markers, glare, motion blur)."""
from __future__ import annotations

import math

import cv2
import numpy as np

from ..camera import StereoRig
from .raster import _check_common, _composite, _disc_coverage, _disc_geometry, _finish
from .rig import CAMERAS, LEVELS, _image_size, scene_frame, thesis_rig
from .wing import StereoSequence, _MARKER_DIAMETER, _MARKER_SIGMA, _MARKER_XI, _MOUNT, _MOUNT_DIAMETER, _REFERENCE_DIAMETER, _Scene, _WING_HINGE, _WingModel, _reference_layout




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
    deviation_deg=0.0,
    twist_deg=0.0,
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
    deviation_deg : float, optional
        Amplitude of the wing's figure-of-eight deviation out of the stroke plane,
        ``deviation_deg sin(2 th)`` (default 0).
    twist_deg : float, optional
        Amplitude of the spanwise twist: the pitch grows linearly along the span by
        ``twist_deg sin(th)`` from root to tip (default 0). Definitions:
        ``docs/kinematics.md``; the true values are in ``seq.kinematics``.
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
        phase_deg=float(phase_deg), deviation_deg=float(deviation_deg), twist_deg=float(twist_deg),
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
                  phase_deg=float(phase_deg), deviation_deg=float(deviation_deg), twist_deg=float(twist_deg),
                  membrane_level=float(membrane_level),
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
        stroke_angle_deg=stroke, pitch_angle_deg=pitch, params=params, kinematics=wing.kinematics(times),
    )
