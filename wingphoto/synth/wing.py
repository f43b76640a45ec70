"""The flapping wing model, its markers, the mount, the reference dots and the sequence container."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..camera import StereoRig
from .board import _rot_x, _rot_y, _rot_z
from .rig import CAMERAS, LEVELS




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
    deviation_deg: float = 0.0  # amplitude of the figure-of-eight deviation out of the stroke plane
    twist_deg: float = 0.0  # amplitude of the linear spanwise twist (pitch at the tip minus at the root)

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

    def extra_angles(self, t):
        """Deviation (deg, out of the stroke plane) and spanwise twist (deg, tip minus root) at times t."""
        th = 2 * np.pi * self.flap_hz * np.asarray(t, dtype=np.float64) + np.radians(self.phase_deg)
        return self.deviation_deg * np.sin(2.0 * th), self.twist_deg * np.sin(th)

    def kinematics(self, t):
        """Every prescribed kinematic quantity at times t (a dict of arrays; see docs/kinematics.md).

        ``stroke_deg`` (angle in the stroke plane), ``deviation_deg`` (out of it), ``pitch_deg``
        (at the root; the pitch at span fraction ``s`` is ``pitch_deg + s * twist_deg``),
        ``twist_deg`` (tip minus root), ``camber`` (peak camber as a fraction of the local
        chord, positive towards the wing's normal ``span x chord``) and ``bend_mm`` (tip
        deflection along that normal).
        """
        stroke, pitch, camber, bend = self.angles(t)
        dev, twist = self.extra_angles(t)
        return {"stroke_deg": stroke, "deviation_deg": dev, "pitch_deg": pitch, "twist_deg": twist,
                "camber": camber, "bend_mm": bend}

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
        if not (self.deviation_deg or self.twist_deg):
            Rw = _rot_z(np.radians(stroke)) @ _rot_x(pitch)
            return local @ Rw.T + self.hinge
        dev, twist = (float(v) for v in self.extra_angles(t))
        # pitch (plus the twist, linear along the span) about the span axis, then the
        # deviation out of the stroke plane, then the stroke about the plane's normal
        p = np.radians(pitch + twist * sigma)
        c, s = np.cos(p), np.sin(p)
        y, z = local[..., 1], local[..., 2]
        local = np.stack([local[..., 0], c * y - s * z, s * y + c * z], axis=-1)
        Rw = _rot_z(np.radians(stroke)) @ _rot_y(-dev)
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
    kinematics : dict of (T,) ndarray or None
        Every true kinematic quantity of a flapping wing (``_WingModel.kinematics``:
        stroke, deviation, root pitch, twist, camber, bending; ``docs/kinematics.md``).
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
    kinematics: dict = None

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


# ===================================================================== motion only
@dataclass(frozen=True)
class WingMotion:
    """The synthetic wing's motion without images: markers, normals and true kinematics.

    Attributes
    ----------
    times : (T,) ndarray
        Seconds (frame ``k`` at ``k / fps``).
    points3d, normals : (T, N, 3) ndarray
        Marker centres (mm) and unit marker normals in the left camera frame of ``rig``,
        numbered as :func:`render_flapping`'s (0-17 wing, 18-19 mount, 20-25 references).
    kinds : (N,) ndarray of str
    kinematics : dict of (T,) ndarray
        The true kinematics (:meth:`_WingModel.kinematics`).
    hinge : (3,) ndarray
        Wing hinge, mm, left camera frame.
    stroke_normal : (3,) ndarray
        Normal of the stroke plane (the scene's ``n``), left camera frame.
    marker_sigma, marker_xi : (18,) ndarray
        Span and chord fraction of each wing marker.
    params : dict
        The wing's settings.
    """

    times: np.ndarray
    points3d: np.ndarray = field(repr=False)
    normals: np.ndarray = field(repr=False)
    kinds: np.ndarray = field(repr=False)
    kinematics: dict = field(repr=False)
    hinge: np.ndarray
    stroke_normal: np.ndarray
    marker_sigma: np.ndarray = field(repr=False)
    marker_xi: np.ndarray = field(repr=False)
    params: dict = field(default_factory=dict)
    model: object = field(default=None, repr=False)
    scene: tuple = field(default=None, repr=False)

    def points(self, *, visible=None):
        """The motion as a points DataFrame (frame, point, X, Y, Z, reproj_err 0).

        Parameters
        ----------
        visible : (T, N) array_like of bool, optional
            Points not visible get NaN coordinates.
        """
        t, n = self.points3d.shape[:2]
        X = self.points3d.copy()
        if visible is not None:
            X[~np.asarray(visible, bool)] = np.nan
        X = X.reshape(-1, 3)
        return pd.DataFrame({"frame": np.repeat(np.arange(t, dtype=np.int64), n),
                             "point": np.tile(np.arange(n, dtype=np.int64), t),
                             "X": X[:, 0], "Y": X[:, 1], "Z": X[:, 2], "reproj_err": np.zeros(t * n)})

    def surface(self, sigma, xi, frame):
        """Material points of the wing surface (mm, left camera frame) at a frame."""
        S, B = self.scene
        return S + self.model.surface(sigma, xi, float(self.times[frame])) @ B.T

    def tracks(self, rig, camera, *, sigma_px=0.0, seed=0):
        """The markers' projections as a tracks table, with Gaussian pixel noise.

        Parameters
        ----------
        rig : StereoRig
            The rig the motion was placed for (:func:`wing_motion`'s).
        camera : {'left', 'right'}
        sigma_px : float
            Noise added to x and y (px, 1-sigma); also written in the ``sigma`` column.
        seed : int

        Returns
        -------
        pandas.DataFrame
            The tracks columns (camera, frame, point, x, y, score, status "ok", sigma).
        """
        if camera not in CAMERAS:
            raise ValueError(f"camera must be 'left' or 'right', got {camera!r}")
        t, n = self.points3d.shape[:2]
        xy = rig.project(self.points3d.reshape(-1, 3))[0 if camera == "left" else 1]
        xy = xy + np.random.default_rng(seed).normal(scale=float(sigma_px), size=xy.shape)
        return pd.DataFrame({"camera": camera, "frame": np.repeat(np.arange(t, dtype=np.int64), n),
                             "point": np.tile(np.arange(n, dtype=np.int64), t), "x": xy[:, 0], "y": xy[:, 1],
                             "score": 1.0, "status": "ok", "sigma": float(sigma_px)})

    def signal(self, name):
        """The true kinematic quantity ``name`` as a function of the stroke phase in cycles.

        Parameters
        ----------
        name : str
            A key of :attr:`kinematics` (``"stroke_deg"``, ``"pitch_deg"``, ...).

        Returns
        -------
        callable
            ``f(phase_cycles) -> values`` (phase 0 is frame 0's wing-beat phase), e.g.
            for :func:`wingphoto.kinematics.compare_interpolation`.
        """
        if name not in self.kinematics:
            raise ValueError(f"name must be one of {sorted(self.kinematics)}, got {name!r}")
        hz = self.model.flap_hz

        def f(phase):
            return self.model.kinematics(np.asarray(phase, dtype=np.float64) / hz)[name]

        return f

    def partial_tests(self, windows, *, moves=None, noise_mm=0.0, seed=0):
        """Split the motion into tests that each see the wing only over part of the stroke.

        Each test is the same motion captured by a camera placement that sees the wing
        markers only while the true stroke angle lies in its window (the mount and
        reference dots are always seen), expressed in its own camera frame: the cameras
        moved between tests by a known rigid motion.

        Parameters
        ----------
        windows : sequence of (float, float)
            Stroke-angle window (deg, true stroke angle) of each test.
        moves : sequence of ((3, 3), (3,)), optional
            ``(R_k, t_k)``: test ``k`` sees ``R_k X + t_k``. Default: identity for the
            first test, and for the others a rotation of 2-6 deg about a random axis
            and a 5-20 mm translation drawn from ``seed``.
        noise_mm : float
            Gaussian noise added to every coordinate (mm, 1-sigma).
        seed : int

        Returns
        -------
        tests : list of pandas.DataFrame
            Points tables (frame, point, X, Y, Z, reproj_err), NaN where not seen.
        moves : list of ((3, 3) ndarray, (3,) ndarray)
        """
        rng = np.random.default_rng(seed)
        if moves is None:
            moves = [(np.eye(3), np.zeros(3))]
            for _ in range(len(windows) - 1):
                ax = rng.normal(size=3)
                ax /= np.linalg.norm(ax)
                ang = np.radians(rng.uniform(2.0, 6.0))
                K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
                R = np.eye(3) + np.sin(ang) * K + (1 - np.cos(ang)) * K @ K
                t = rng.normal(size=3)
                t *= rng.uniform(5.0, 20.0) / np.linalg.norm(t)
                moves.append((R, t))
        if len(moves) != len(windows):
            raise ValueError(f"give one move per window ({len(windows)}), got {len(moves)}")
        stroke = self.kinematics["stroke_deg"]
        wing = self.kinds == "wing"
        tests = []
        for (lo, hi), (R, t) in zip(windows, moves):
            seen = np.ones(self.points3d.shape[:2], bool)
            seen[:, wing] = ((stroke >= lo) & (stroke <= hi))[:, None]
            df = self.points(visible=seen)
            X = df[["X", "Y", "Z"]].to_numpy() @ np.asarray(R).T + np.asarray(t)
            if noise_mm > 0:
                X = X + rng.normal(scale=float(noise_mm), size=X.shape)
            df[["X", "Y", "Z"]] = X
            tests.append(df)
        return tests, [(np.asarray(R, float), np.asarray(t, float)) for R, t in moves]


def wing_motion(rig=None, *, n_frames=100, fps=3000.0, flap_hz=30.0, preset="clean", phase_deg=0.0,
                stroke_amplitude_deg=None, pitch_deg=None, camber=None, bend_mm=None, deviation_deg=0.0,
                twist_deg=0.0):
    """The motion of :func:`render_flapping`'s wing without rendering any image.

    The same wing, markers, mount and reference dots, placed in ``rig``'s scene exactly
    as :func:`render_flapping` places them; parameters as there. Used by the
    experiment planner and by tests of the kinematics (fast: no pixels).

    Returns
    -------
    WingMotion

    Examples
    --------
    >>> m = wing_motion(n_frames=4, deviation_deg=5.0)
    >>> m.points3d.shape, sorted(m.kinematics)[:2]
    ((4, 26, 3), ['bend_mm', 'camber'])
    """
    from .flapping import _check_rig, flapping_preset
    from .rig import scene_frame

    rig = _check_rig(rig)
    s = flapping_preset(preset)
    given = dict(stroke_amplitude_deg=stroke_amplitude_deg, pitch_deg=pitch_deg, camber=camber, bend_mm=bend_mm)
    s.update({k: v for k, v in given.items() if v is not None})
    S, B = scene_frame(rig)
    wing = _WingModel(hinge=_WING_HINGE, stroke_amplitude_deg=float(s["stroke_amplitude_deg"]),
                      pitch_deg=float(s["pitch_deg"]), camber=float(s["camber"]), bend_mm=float(s["bend_mm"]),
                      flap_hz=float(flap_hz), phase_deg=float(phase_deg), deviation_deg=float(deviation_deg),
                      twist_deg=float(twist_deg))
    sig_m = np.repeat(_MARKER_SIGMA, len(_MARKER_XI))
    xi_m = np.tile(_MARKER_XI, len(_MARKER_SIGMA))
    fixed = S + np.concatenate([_WING_HINGE + _MOUNT, _reference_layout()]) @ B.T
    times = np.arange(int(n_frames)) / float(fps)
    X = np.empty((len(times), len(sig_m) + len(fixed), 3))
    N = np.empty_like(X)
    for k, t in enumerate(times):
        X[k, : len(sig_m)] = S + wing.surface(sig_m, xi_m, t) @ B.T
        N[k, : len(sig_m)] = wing.normals(sig_m, xi_m, t) @ B.T
        X[k, len(sig_m):] = fixed
        N[k, len(sig_m):] = -B[:, 2]
    kinds = np.array(["wing"] * len(sig_m) + ["mount"] * 2 + ["reference"] * 6)
    params = dict(s, n_frames=int(n_frames), fps=float(fps), flap_hz=float(flap_hz), phase_deg=float(phase_deg),
                  deviation_deg=float(deviation_deg), twist_deg=float(twist_deg))
    return WingMotion(times=times, points3d=X, normals=N, kinds=kinds, kinematics=wing.kinematics(times),
                      hinge=S + B @ _WING_HINGE, stroke_normal=B[:, 2].copy(), marker_sigma=sig_m, marker_xi=xi_m,
                      params=params, model=wing, scene=(S, B))
