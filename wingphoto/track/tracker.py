"""The tracker: per-marker state and :meth:`Tracker.step`, which calls the stages in order."""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from . import engine
from .fastpath import fast_step
from .geometry import _nearest_two
from .glitch import GlitchStage
from .identity import IdentityStage
from .options import _BG_RESIDUAL, _BRIDGE, _MERGE_VALLEY, _RD_FACE_MARGIN, _RD_MARGIN, _RD_MAX
from .predict import FAST_VERIFY_PX, FAST_VERIFY_SCORE, start_frame, update_model
from .reacquire import ReacquireStage
from .relocate import relocate_group
from .refine import (
    FOREIGN_FRACTION,
    FOREIGN_NOISE,
    WEIGHT_FRACTION,
    _contrast,
    _face,
    _refine,
    _refine_all_kernel,
    split_neighbour,
)
from .sigma import sigma_of
from .status import (_IS_SOFT, _R, COINCIDENT, FLAGGED, LOST, OK, RULES, STAY_PX, STAY_SCORE, apply_rules,
                     rule_conditions)
from .templates import TemplateStage

logger = logging.getLogger("wingphoto.track")

#: a faded blob (peak below _FADED of its frame-0 peak, or score below _WEAK) on a ring this
#: far from a plane (fraction of its contrast) is imprecise whatever its sigma
_FADED, _WEAK, _BG_RESIDUAL_FADED = 0.6, 0.75, 0.04
#: A poor match (score below _POOR_MATCH) that fell more than _POOR_DROP below the
#: marker's running score is reported ok only with a margin, sigma at most _POOR_MARGIN
#: of ``max_sigma`` (:meth:`Tracker._poor_match`): the blob changed, most often as a
#: neighbour's ran into it, and its centre carries a bias the image terms of sigma do not
#: see (independent renderer, DEV seeds 3-52: all 9 ok points more than 1 px off had a score
#: of 0.78-0.84 and sigma 0.21-0.25)
_POOR_MATCH, _POOR_DROP, _POOR_MARGIN = 0.85, 0.03, 0.8
#: An ok point this far (fraction of its spacing) from its prediction is checked against its
#: neighbours' motion even when it was ok on the frame before: the motion model alone does
#: not vouch for so large a step (a prediction from a re-acquisition's made-up velocity, or
#: an RMS inflated by one large residual, let a marker onto a neighbour's blob 9-26 px away).
_VOUCH_STEP = 0.3
#: A marker beside a conflict's loser whose refined centre left its pixel-level match by
#: more than this (px) is not ok (:meth:`Tracker._absorbed`).
ABSORB_PX = 1.0
#: Column of the ``imprecise`` rule in :func:`~.status.rule_conditions`' table.
_IMPRECISE_RULE = [r[0] for r in RULES].index("imprecise")
#: The refiner's per-marker diagnostics kept in ``FrameContext.info`` (:func:`~.refine._refine`).
_DIAGNOSTICS = ("foreign", "bgres", "peak", "valley", "spread", "dshape", "rim", "tex")


@dataclass(eq=False)
class FrameContext:
    """Everything :meth:`Tracker.step` computes for one frame, passed to the stages.

    A context is made by :meth:`Tracker._plan` at the start of each solve of a frame (a
    broken constellation solves the frame again under each hypothesis, each with its own
    context) and dropped with the frame: nothing in it is read on the next frame. What
    persists from frame to frame is the tracker's state (:class:`Tracker`). Arrays have
    one entry per marker (N, in the order of the picks); the stages fill them in place.

    Attributes
    ----------
    pred : (N, 2) ndarray of float
        Predicted position (x, y) px (:func:`~.predict.start_frame`); the wide-search
        consensus (:meth:`~.identity.IdentityStage._consensus`) replaces the prediction of
        a marker it re-searches at its neighbours' prediction.
    gap : (N,) ndarray of int
        Frames since the marker's last position that fed the motion model.
    steady : (N,) ndarray of bool
        Ok on the previous frame, which fed its motion model, with three points in its
        history.
    inside, fits : (N,) ndarray of bool
        The prediction is in the image / its template fits in the image there.
    r : (N,) ndarray of int
        Search radius (px) around the rounded prediction.
    F : (N,) ndarray of bool
        Fast path (moving predictably, strongly matched, not crowded; every
        ``search_every``-th frame searched anyway): refined at the rounded prediction
        without a search, then verified (:meth:`Tracker._verify_fast`).
    wide : (N,) ndarray of bool
        No velocity yet: searched ``search_radius`` wide, checked by the neighbours'
        consensus.
    j2, d2 : (N, 2) ndarray of int / float
        The two nearest other markers by prediction (-1: none) and their distances (px).
    merged, crowded : (N,) ndarray of bool
        The nearest other prediction lies within the two blob radii + 1 px (and the marker
        is inside) / + 4 px.
    px, py : (N,) ndarray of float
        The predictions rounded to pixels, as planned (before the consensus moved any):
        the centres of the search windows and the fast path's start.
    aged : int
        Frames the motion model's history was moved along before this solve: 1 to
        ``_MAX_DROPPED`` for dropped frames, -1 for a repeated frame, 0 otherwise
        (:meth:`Tracker._recover`).
    nbr_r : (N,) ndarray of float
        Disk radius + 0.5 px of each marker's nearest neighbour (the refiner's split).
    XP, YP : (N,) ndarray of float
        Pixel-level position (the correlation match, the rounded prediction of a fast-path
        or edge marker); NaN: none.
    S, SEC : (N,) ndarray of float
        Correlation score of the match (NaN: none) and of the runner-up peak (-2: none).
    lose : (N,) ndarray of bool
        Lost its blob to another marker on this frame (:meth:`~.identity.IdentityStage._conflicts`).
    eidx : (K,) ndarray of int
        Markers predicted inside the image whose template does not fit (the edge).
    X, Y : (N,) ndarray of float
        Refined sub-pixel position (x, y) px; NaN: none.
    mass : (N,) ndarray of float
        Summed signal above the background of the refined blob (NaN: not refined).
    info : dict of (N,) ndarray
        The refiner's diagnostics: ``foreign``, ``rd``, ``bgres``, ``peak``, ``valley``,
        ``spread``, ``dshape``, ``rim``, ``tex`` (:func:`~.refine._refine`).
    ST, RS : (N,) ndarray of int8
        Status and reason code (:mod:`~.status`), set by :meth:`Tracker._judge`.
    resid : (N,) ndarray of float
        Distance (px) of the refined position from the prediction (end of :meth:`Tracker._solve`).
    sigma : (N,) ndarray of float
        Per-axis 1-sigma uncertainty (px), set by :meth:`Tracker._judge`.
    glitch : bool
        No hypothesis explained a broken constellation: every point is flagged.
    unexplained : (N,) ndarray of bool
        The moving markers, when the hypothesis chosen for a broken constellation put
        most markers but not most of the moving ones where predicted (else none): their
        points are flagged (:meth:`Tracker._recover`).
    unvouched : (N,) ndarray of bool
        Wide-searched markers (no velocity yet) matched further than half their spacing
        from where they were, whose neighbours did not move together: nothing vouches for
        the match (:meth:`~.identity.IdentityStage._consensus`); their points are flagged
        ``ambiguous``.
    provisional : (N,) ndarray of bool
        Wide-searched markers matched far from where they were, with nothing to check
        the match against, whose own blob may have gone where no template fits
        (:meth:`~.identity.IdentityStage._beyond_view`): their points are flagged
        ``ambiguous`` but feed the motion model, so that the marker resumes ok only where
        the neighbours vouch for its path (a marker resuming after a gap).
    shift : (2,) ndarray of float
        The camera's shift (px) measured on this frame (:meth:`Tracker._recover`; zero
        without a bump): the image moved by it besides the markers' own motion.
    measured : tuple of ndarray
        After frames dropped (:meth:`Tracker._recover`): the motion model's measured
        history before them, (N, 3, 2) positions and (N, 3) frames moved back by the
        frames dropped; the markers fed on this frame keep it behind their new point
        (:meth:`~.glitch.GlitchStage._keep_measured`). Empty otherwise.
    """

    pred: np.ndarray
    gap: np.ndarray
    steady: np.ndarray
    inside: np.ndarray
    fits: np.ndarray
    r: np.ndarray
    F: np.ndarray
    wide: np.ndarray
    j2: np.ndarray
    d2: np.ndarray
    merged: np.ndarray
    crowded: np.ndarray
    px: np.ndarray
    py: np.ndarray
    aged: int
    nbr_r: np.ndarray
    XP: np.ndarray
    YP: np.ndarray
    S: np.ndarray
    SEC: np.ndarray
    lose: np.ndarray
    eidx: np.ndarray
    X: np.ndarray
    Y: np.ndarray
    mass: np.ndarray
    info: dict
    ST: np.ndarray
    RS: np.ndarray
    resid: np.ndarray = None
    sigma: np.ndarray = None
    glitch: bool = False
    unexplained: np.ndarray = None
    unvouched: np.ndarray = None
    provisional: np.ndarray = None
    shift: np.ndarray = None
    measured: tuple = ()

    def step_velocity(self, disp):
        """Velocity (px per frame, (..., 2)) of markers that moved by ``disp`` px since the
        previous image: less the camera's shift, over the frames dropped in between too."""
        shift = np.zeros(2) if self.shift is None else self.shift
        return (np.asarray(disp, float) - shift) / (1 + max(self.aged, 0))


def _check_picks(xy, half, shape, ids):
    """Raise ValueError naming the first pick outside the image, or whose template
    (``half``, px) is larger than the image."""
    H, W = shape
    out = (xy[:, 0] < -0.5) | (xy[:, 0] > W - 0.5) | (xy[:, 1] < -0.5) | (xy[:, 1] > H - 0.5)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        raise ValueError(
            f"pick of point {ids[i]} at ({xy[i, 0]:g}, {xy[i, 1]:g}) is outside the {W}x{H} image; "
            "picks are (x, y) pixels with (0, 0) the centre of the top-left pixel"
        )
    big = (2 * half + 1 > min(H, W)) & (half > 0)
    if big.any():
        i = int(np.flatnonzero(big)[0])
        raise ValueError(
            f"template of point {ids[i]} ({2 * half[i] + 1} px, half_size {half[i]}) is larger than "
            f"the {W}x{H} image; give a smaller half_size (or rect)"
        )


def _measure_pick(f, xy, half, polarity, point_id):
    """Measure the marker under one pick on the picks' frame ``f`` (float32).

    Returns (sign, blob radius px, noise grey levels, shape centre x, y, face radius px):
    the polarity (``polarity``, or by the 3x3 core against the background for ``"auto"``);
    the noise, a robust spread of the patch's horizontal differences; the blob above half
    its contrast (not half a specular highlight's peak) around the brightest pixel near the
    pick, its radius (at most ``half`` when given) and its weighted centre; the radius of
    the blob above half its face (:func:`~.refine._face`, and 3 noise sigmas), NaN where
    that reaches the patch's border. Raises ValueError when no blob stands out of the
    background at the pick (``point_id`` names it).
    """
    H, W = f.shape
    g = half + 4 if half > 0 else 12
    ix, iy = int(round(xy[0])), int(round(xy[1]))
    x0, x1 = max(ix - g, 0), min(ix + g + 1, W)
    y0, y1 = max(iy - g, 0), min(iy + g + 1, H)
    patch = f[y0:y1, x0:x1]
    # background: a plane fitted to the patch's 2 px border (glare is a gradient)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    bmask = np.zeros(patch.shape, bool)
    bmask[:2], bmask[-2:], bmask[:, :2], bmask[:, -2:] = True, True, True, True
    A = np.column_stack([np.ones(bmask.sum()), xx[bmask] - ix, yy[bmask] - iy])
    coef = np.linalg.lstsq(A, patch[bmask].astype(np.float64), rcond=None)[0]
    plane = coef[0] + coef[1] * (xx - ix) + coef[2] * (yy - iy)
    bg = float(coef[0])
    dif = np.diff(patch, axis=1).ravel()
    noise = 1.4826 * float(np.median(np.abs(dif - np.median(dif)))) / math.sqrt(2) + 1e-6 * (abs(bg) + 1)
    lx, ly = ix - x0, iy - y0
    core = patch[max(ly - 1, 0): ly + 2, max(lx - 1, 0): lx + 2]
    if polarity == "auto":
        s = 1.0 if core.mean() >= bg else -1.0
    else:
        s = float(polarity)
    sig = s * (patch - plane)
    near = sig[max(ly - 2, 0): ly + 3, max(lx - 2, 0): lx + 3]
    peak = float(near.max())
    # a faint dot's brightest pixel may sit within 4 noise of the plane while the dot
    # as a whole stands far out of it: also test the best 3x3 mean (its noise is a third)
    box = ndimage.uniform_filter(sig, 3, mode="nearest")[max(ly - 2, 0): ly + 3, max(lx - 2, 0): lx + 3]
    stands_out = peak > 4.0 * noise or float(box.max()) > 4.0 * noise / 3.0
    if not (stands_out and peak > 1e-3 * (abs(bg) + 1)):
        raise ValueError(
            f"pick of point {point_id} at ({xy[0]:g}, {xy[1]:g}) is not on a marker: no blob "
            f"stands out of the background there (contrast {peak:.3g}, noise {noise:.3g}); "
            "click the marker centre"
        )
    ya, xa = max(ly - 2, 0), max(lx - 2, 0)
    kk = int(np.argmax(near))
    py_, px_ = ya + kk // near.shape[1], xa + kk % near.shape[1]
    # the blob: above half its contrast (not half a specular highlight's peak)
    blob = (sig.reshape(1, -1).astype(np.float32), ~bmask.reshape(1, -1),
            np.array([sig[~bmask].max()], np.float32), np.array([noise]))
    con = float(_contrast(*blob)[0])
    lab, _ = ndimage.label(sig > 0.5 * min(con, peak))
    comp = lab == lab[py_, px_]
    area = float(comp.sum())
    r = math.sqrt(area / math.pi)
    if half > 0:
        r = min(r, float(half))
    w = np.where(comp, sig, 0.0)
    # the face's extent: a bright highlight on a large dim face is the blob above half the
    # contrast, and a disk sized to it leaves the face out (below)
    r_face = np.nan
    face = float(_face(*blob)[0])
    if math.isfinite(face):
        lab, _ = ndimage.label(sig > max(0.5 * face, 3.0 * noise))
        if lab[py_, px_]:
            fc = lab == lab[py_, px_]
            if not (fc & bmask).any():
                r_face = math.sqrt(float(fc.sum()) / math.pi)
    return s, max(r, 1.0), noise, float((w * xx).sum() / w.sum()), float((w * yy).sum() / w.sum()), r_face


class Tracker(TemplateStage, IdentityStage, ReacquireStage, GlitchStage):
    """State of one tracking pass; :meth:`step` processes one frame.

    The tracker holds only what persists from frame to frame; what one frame computes is
    in its :class:`FrameContext`. The stage methods come from the mixins
    (:class:`~.templates.TemplateStage`, :class:`~.identity.IdentityStage`,
    :class:`~.reacquire.ReacquireStage`, :class:`~.glitch.GlitchStage`) and read the
    state below. Arrays have one entry per marker (N, in the order of the picks).

    Attributes
    ----------
    p : TrackOptions
        The pass's options.
    is_u8 : bool
        The frames are 8-bit (OpenCV correlates 8-bit templates).
    H, W : int
        Frame height and width (px).
    hist_x, hist_t, nh : (N, 3, 2), (N, 3), (N,) ndarray
        Motion model: the last three positions (x, y) px that fed it, newest first, their
        frames and how many are known (:mod:`~.predict`).
    resid_rms : (N,) ndarray of float
        Running RMS (px) of the motion model's residual.
    lostflag : (N,) ndarray of bool
        Lost (coasted beyond ``max_coast``), waiting for re-acquisition.
    restarted : (N,) ndarray of bool
        Re-acquired at least once: with fewer than three points in its motion model, its
        velocity may be a step borrowed from its neighbours (``GlitchStage._lose_unmoved``).
    last_ok, last_upd : (N,) ndarray of int
        Frame of the last ``ok`` point / of the last template update.
    last_score, score_ref, mass_ref : (N,) ndarray of float
        Score of the last frame (0 unless ok) and running references of score and mass of
        the ok points (the status rules' drops).
    stagger : (N,) ndarray of int
        Phase of the fast path's periodic full search (``search_every``).
    h, rb, rd : (N,) ndarray
        Template half size (px), blob radius (px) and the refiner's disk radius (px),
        fixed on the picks' frame.
    sign, sign64 : (N,) ndarray of float32 / float64
        Polarity (+1 bright marker, -1 dark).
    noise : (N,) ndarray of float
        Image noise (grey levels) around each marker on the picks' frame.
    mass0, peak0 : (N,) ndarray of float
        Mass and peak contrast on the picks' frame.
    pos : (N, 2) ndarray of float
        Position (x, y) px written on the last frame (NaN: none).
    ref_pos : (N, 2) ndarray of float
        Positions on the picks' frame (the wide search's consensus compares
        displacements from it).
    tpl0, tplr, tplu, tz, ... : templates
        The picks' and the running templates and their correlation stack
        (:class:`~.templates.TemplateStage`).
    local : float
        Radius (px) of a marker's neighbourhood; ``_spacing`` (N,): distance to the
        nearest marker there, ``_ref_j2`` (N, 2): its two nearest markers there, -1 for
        none (:meth:`_set_local`).
    pick_moved, sigma0 : (N,) ndarray
        The picks' frame only: the refinement moved away from the click (the click is
        kept), and the picks' sigma (:meth:`from_picks`).
    _prev, _prev2 : ndarray or None
        The previous two frames (repeated frames, camera bumps).
    _prev_unexplained : bool
        No glitch explained the previous frame: a repeat of it is no hypothesis
        (:meth:`~.glitch.GlitchStage._repeat_holds`). Like the previous frames, not saved
        in a checkpoint (False on resume).

    Notes
    -----
    :attr:`_STATE` lists the arrays a checkpoint saves (with the templates ``tpl0`` and
    ``tplr``); on resume (:meth:`from_state`) the rest is derived from them and the
    previous frames start empty.
    ``_fast_par`` caches the fast frame's constant arguments (:mod:`~.fastpath`).
    """

    _STATE = ("hist_x", "hist_t", "nh", "resid_rms", "lostflag", "last_upd", "h", "rb", "sign", "mass0",
              "pos", "last_score", "stagger", "ref_pos", "mass_ref", "score_ref", "rd", "noise", "peak0", "last_ok",
              "restarted")

    def __init__(self, p, is_u8, shape):
        self._prev = self._prev2 = None
        self._prev_unexplained = False  # (no glitch explained the previous frame)
        self.p = p
        self.is_u8 = is_u8
        self.H, self.W = shape

    # ------------------------------------------------------------ set-up
    @classmethod
    def from_picks(cls, frame, xy, half, p, is_u8, ids):
        """A tracker started from picks on ``frame``.

        Parameters
        ----------
        frame : (H, W) ndarray
            The picks' frame.
        xy : (N, 2) ndarray of float
            The picks (x, y) px, one per marker.
        half : (N,) ndarray of int
            Template half size per marker (0: from the blob's size).
        p : TrackOptions
        is_u8 : bool
            The frames are 8-bit.
        ids : sequence of int
            The markers' point numbers (for the error messages).

        Each pick is measured (:func:`_measure_pick`: polarity, blob radius, noise, shape
        centre), refined, and kept as clicked where the refinement was pulled away
        (``pick_moved``); the templates, the motion model and the reference layout start
        from there.

        Raises
        ------
        ValueError
            A pick outside the image, not on a marker, or too near the edge for its template.
        """
        self = cls(p, is_u8, frame.shape)
        H, W = frame.shape
        n = len(xy)
        _check_picks(xy, half, frame.shape, ids)
        f = frame.astype(np.float32)
        sign = np.ones(n, np.float32)
        rb = np.zeros(n)
        nz = np.zeros(n)
        cx = np.zeros(n)
        cy = np.zeros(n)
        rf = np.zeros(n)
        for i in range(n):
            sign[i], rb[i], nz[i], cx[i], cy[i], rf[i] = _measure_pick(f, xy[i], int(half[i]), p.polarity, ids[i])
        self.sign = sign
        self.sign64 = sign.astype(np.float64)
        self.rb = rb
        self.noise = nz
        # the disk: _RD_MARGIN beyond the blob, and _RD_FACE_MARGIN beyond its face where
        # that is larger (at most the largest disk): a specular highlight on a large dim
        # dot is the blob above half the contrast, and a disk sized to it left the face
        # out and put the centre on the highlight (real dots upsampled 1.5-2x, dots 8-14 px
        # across: ok 1.4-4.0 px off at sigma 0.15-0.24; the face's plane fit in the ring
        # tilted to fit the face's edge, so nothing spilled)
        with np.errstate(invalid="ignore"):
            rd0 = np.fmax(rb + _RD_MARGIN, rf + _RD_FACE_MARGIN)
        self.rd = np.minimum(rd0, self._rmax())
        nbr = self._nearest_positions(cx, cy, np.ones(n, bool))
        x, y, mass, info = _refine(frame, cx, cy, self.rd, sign, nz, nbr, iterations=3, rmax=self._rmax())
        # a click is within ~0.7 px of a marker's centre: a refinement that moved further
        # was pulled by something (glare, the membrane's edge, an unpicked neighbour), as
        # is one that saw a foreign blob or a rough background, and the click is the
        # better centre for the template and the motion model
        self.pick_moved = ((np.hypot(x - xy[:, 0], y - xy[:, 1]) > 1.5) | info["foreign"]
                           | (info["bgres"] > _BG_RESIDUAL))
        self.sigma0 = sigma_of(nz, info, 1.0, rb)
        self.sigma0[self.pick_moved] = np.nan  # the click, kept: its uncertainty is the user's
        x = np.where(self.pick_moved, xy[:, 0], x)
        y = np.where(self.pick_moved, xy[:, 1], y)
        # the disk of each marker: its blob radius + _RD_MARGIN, grown at frame 0 where the
        # blob spilled out of it; fixed from then on (a disk that grows in the middle of a
        # sequence swallows a neighbour sooner than it catches a growing blob)
        self.rd = info["rd"]
        self.peak0 = info["peak"]
        h = np.where(half > 0, half, np.maximum(np.ceil(rb + 1.5), 3)).astype(np.int64)
        px, py = np.rint(x).astype(np.int64), np.rint(y).astype(np.int64)
        edge = (px - h < 0) | (py - h < 0) | (px + h > W - 1) | (py + h > H - 1)
        if edge.any():
            i = int(np.flatnonzero(edge)[0])
            raise ValueError(
                f"pick of point {ids[i]} at ({xy[i, 0]:g}, {xy[i, 1]:g}) is too close to the image edge: "
                f"its {2 * h[i] + 1}x{2 * h[i] + 1} px template does not fit in the {W}x{H} image; "
                "start from a frame where the marker is further inside, or give a smaller half_size"
            )
        self.h = h
        self.mass0 = mass
        self.mass_ref = mass.copy()
        self.score_ref = np.ones(n)
        self.tpl0 = [self._cut(frame, x[i], y[i], h[i]) for i in range(n)]
        self.tplr = [t.copy() for t in self.tpl0]
        self.tplu = [self._as_match(t) for t in self.tpl0]
        self.last_score = np.ones(n)
        self.stagger = np.arange(n) % p.search_every
        self._init_stack()
        self.hist_x = np.full((n, 3, 2), np.nan)
        self.hist_x[:, 0, 0] = x
        self.hist_x[:, 0, 1] = y
        self.hist_t = np.zeros((n, 3), np.int64)
        self.nh = np.ones(n, np.int64)
        self.resid_rms = np.ones(n)
        self.lostflag = np.zeros(n, bool)
        # re-acquired or restarted at least once (its motion model began again, maybe with
        # a step borrowed from its neighbours: GlitchStage._lose_unmoved)
        self.restarted = np.zeros(n, bool)
        self.last_upd = np.zeros(n, np.int64)
        self.last_ok = np.zeros(n, np.int64)
        self.pos = np.column_stack([x, y])
        self.ref_pos = self.pos.copy()
        self._set_local()
        return self

    def _set_local(self):
        """Radius (px) of a marker's neighbourhood: four typical neighbour spacings."""
        j, d, _ = _nearest_two(self.ref_pos[:, 0], self.ref_pos[:, 1], np.ones(len(self.ref_pos), bool))
        self._ref_j2 = j
        self._spacing = np.where(np.isfinite(d[:, 0]), d[:, 0], np.inf)
        d0 = d[:, 0][np.isfinite(d[:, 0])]
        self.local = max(40.0, 4.0 * float(np.median(d0))) if d0.size else 40.0


    def _nearest_positions(self, x, y, valid):
        """(N, 2) position of each marker's nearest valid other marker within reach, NaN else."""
        j, d, _ = _nearest_two(x, y, valid)
        j0 = j[:, 0]
        out = np.column_stack([x[j0], y[j0]])
        far = (j0 < 0) | (d[:, 0] > self.rd + 3.0 + self.rb[np.maximum(j0, 0)])
        out[far] = np.nan
        return out

    # ------------------------------------------------------------ checkpoint state
    def state(self):
        d = {k: getattr(self, k) for k in self._STATE}
        for name in ("tpl0", "tplr"):
            s = 2 * int(self.h.max()) + 1
            a = np.zeros((len(self.h), s, s), np.float32)
            for i, t in enumerate(getattr(self, name)):
                a[i, : t.shape[0], : t.shape[1]] = t
            d[name] = a
        return d

    @classmethod
    def from_state(cls, d, p, is_u8, shape):
        self = cls(p, is_u8, shape)
        for k in self._STATE:
            setattr(self, k, np.array(d[k]))
        s = 2 * self.h + 1
        self.tpl0 = [np.ascontiguousarray(d["tpl0"][i, : s[i], : s[i]]) for i in range(len(s))]
        self.tplr = [np.ascontiguousarray(d["tplr"][i, : s[i], : s[i]]) for i in range(len(s))]
        self.tplu = [None] * len(s)
        self._init_stack()
        self._set_local()
        self.sign64 = np.asarray(self.sign, np.float64)
        return self

    # ------------------------------------------------------------ one frame
    def step(self, frame, t, res, direction=1):
        """Track all markers into frame ``t`` and write row ``t`` of ``res``.

        The stages in order: the frame check (a blank or repeated frame,
        :meth:`_frame_glitch`), prediction and search plan (:func:`~.predict.start_frame`),
        matching and sub-pixel refinement (:meth:`_solve`), the constellation check (when
        most markers left their predictions together: a dropped frame, a bumped camera,
        :meth:`_recover`; with one or two markers to check, whether frames dropped would
        put them on other blobs, :meth:`_few_in_doubt`), the status rules (:meth:`_judge`),
        then the motion-model and template update and the re-acquisition of lost markers (:meth:`_update`). What
        one frame computes travels in its :class:`FrameContext` (``ctx``), passed to each
        stage; the tracker keeps only the state that persists from frame to frame.
        """
        if fast_step(self, frame, t, res):
            self._prev_unexplained = False
            return  # a steady frame, handled end to end by the compiled fast frame
        unexplained = False
        if not self._frame_glitch(frame, t, res, direction):
            ctx = self._solve(frame, t)
            if self._broken(ctx):
                ctx = self._recover(frame, t, direction, ctx)
            elif self._few_to_check(ctx):
                ctx = self._few_in_doubt(frame, t, direction, ctx)
            self._flag_copied(frame, ctx, t)
            self._judge(t, res, ctx)
            self._update(frame, t, res, direction, ctx)
            unexplained = ctx.glitch
        self._prev_unexplained = unexplained
        self._prev2, self._prev = self._prev, frame

    def _solve(self, frame, t, aged=0):
        """Predict, match and refine every marker on frame ``t``; returns its :class:`FrameContext`.

        :meth:`_plan` (predictions, search plan), :meth:`_match_all` (correlation
        search, conflicts), :meth:`_refine_matched` (sub-pixel refinement) and
        :meth:`_verify_fast` (the fast-path markers' check); ``aged``: frames the motion
        model's history was moved along before this solve (:meth:`_recover`)."""
        ctx = self._plan(t, aged)
        sidx, fidx = self._match_all(frame, ctx)
        nb = self._refine_matched(frame, ctx)
        if fidx.size:
            self._verify_fast(frame, ctx, sidx, fidx, nb)
        ctx.resid = np.hypot(ctx.X - ctx.pred[:, 0], ctx.Y - ctx.pred[:, 1])
        return ctx

    def _plan(self, t, aged):
        """The frame's context: predictions and search plan (:func:`~.predict.start_frame`,
        which also marks markers coasted too long in ``lostflag``) and empty results.

        Reads the motion model (``hist_x``, ``hist_t``, ``nh``, ``resid_rms``, ``last_ok``,
        ``last_score``, ``stagger``) and the markers' sizes; writes ``lostflag``."""
        p = self.p
        n = len(self.h)
        plan = start_frame(t, self.hist_x, self.hist_t, self.nh, self.resid_rms, self.lostflag, self.last_ok,
                           self.last_score, self.stagger, self.h, self.rb, self.W, self.H, p.max_coast,
                           p.search_every, p.search_radius)
        pred = plan["pred"]
        RS = np.zeros(n, np.int8)
        RS[~self.lostflag & ~plan["inside"]] = _R["out_of_frame"]
        RS[self.lostflag] = _R["lost_track"]
        return FrameContext(
            **plan, px=np.rint(pred[:, 0]), py=np.rint(pred[:, 1]), aged=aged, shift=np.zeros(2),
            unexplained=np.zeros(n, bool), unvouched=np.zeros(n, bool), provisional=np.zeros(n, bool),
            nbr_r=self.rd[np.maximum(plan["j2"][:, 0], 0)] + 0.5,
            XP=np.full(n, np.nan), YP=np.full(n, np.nan), S=np.full(n, np.nan), SEC=np.full(n, -2.0),
            lose=np.zeros(n, bool), eidx=(plan["inside"] & ~plan["fits"]).nonzero()[0],
            X=np.full(n, np.nan), Y=np.full(n, np.nan), mass=np.full(n, np.nan),
            info=dict(foreign=np.zeros(n, bool), rd=self.rd.copy(), bgres=np.zeros(n), peak=np.full(n, np.nan),
                      valley=np.full(n, np.nan), spread=np.full(n, np.nan), dshape=np.full(n, np.nan),
                      rim=np.full(n, np.nan), tex=np.full(n, np.nan)),
            ST=np.full(n, LOST, np.int8), RS=RS)

    def _match_all(self, frame, ctx):
        """Pixel-level positions ``ctx.XP, ctx.YP``: windowed NCC around the predictions
        (:meth:`~.identity.IdentityStage._search`) of the markers that fit and are not on
        the fast path, which lose a blob taken by another marker (``ctx.lose``); the
        fast-path and edge markers start at their rounded predictions. Returns the
        searched and the fast-path markers (indices)."""
        XP, YP = ctx.XP, ctx.YP
        sidx = (ctx.fits & ~ctx.F).nonzero()[0]
        if sidx.size:
            self._search(frame, sidx, ctx)
            ctx.lose = self._conflicts(sidx, ctx)
            XP[ctx.lose] = np.nan
            YP[ctx.lose] = np.nan
        fidx = ctx.F.nonzero()[0]
        XP[fidx], YP[fidx] = ctx.px[fidx], ctx.py[fidx]
        eidx = ctx.eidx
        XP[eidx], YP[eidx] = ctx.px[eidx], ctx.py[eidx]
        return sidx, fidx

    def _refine_matched(self, frame, ctx):
        """Sub-pixel refinement of every marker with a pixel-level position, jointly
        (``ctx.X, ctx.Y, ctx.mass, ctx.info``); the edge markers' pixel-level positions are
        then cleared (no correlation match). Returns the neighbour positions used for the
        pixel split, (N, 2) NaN where none."""
        n = len(self.h)
        ridx = np.isfinite(ctx.XP).nonzero()[0]
        nb = np.full((n, 2), np.nan)
        if ridx.size:
            if engine.use_numba():
                nb = self._refine_all(frame, ridx, ctx)
            else:
                nb = self._voronoi(ctx)
                ctx.X[ridx], ctx.Y[ridx], ctx.mass[ridx] = self._refine_at(frame, ridx, nb, ctx)
        ctx.XP[ctx.eidx] = ctx.YP[ctx.eidx] = np.nan  # no correlation match for edge markers
        return nb

    def _verify_fast(self, frame, ctx, sidx, fidx, nb):
        """Verify the fast-path markers ``fidx``: NCC at the refined pixel, a small residual,
        the blob still there. The others are searched after all (with ``sidx``, the
        markers searched before, in the conflict test), and re-refined with those whose
        neighbour's split moved (``nb``: the split used)."""
        X, Y, S, XP, YP, mass = ctx.X, ctx.Y, ctx.S, ctx.XP, ctx.YP, ctx.mass
        prx, pry = ctx.pred[:, 0], ctx.pred[:, 1]
        S[fidx] = self._score_at(frame, fidx, np.rint(X[fidx]), np.rint(Y[fidx]))
        XP[fidx], YP[fidx] = np.rint(X[fidx]), np.rint(Y[fidx])
        resf = np.hypot(X[fidx] - prx[fidx], Y[fidx] - pry[fidx])
        bad = ~((S[fidx] >= FAST_VERIFY_SCORE) & (resf < np.maximum(FAST_VERIFY_PX, 4.0 * self.resid_rms[fidx]))
                & (mass[fidx] > self.p.min_mass_ratio * self.mass0[fidx]))
        if not bad.any():
            return
        vidx = fidx[bad]
        self._search(frame, vidx, ctx)
        lose = self._conflicts(np.concatenate([sidx, vidx]), ctx)
        XP[lose & ~ctx.lose] = np.nan
        YP[lose & ~ctx.lose] = np.nan
        ctx.lose = lose
        # refine again the re-searched markers and those whose neighbour moved
        nb2 = self._voronoi(ctx)
        changed = (np.isfinite(nb2[:, 0]) != np.isfinite(nb[:, 0])) | (
            np.hypot(nb2[:, 0] - nb[:, 0], nb2[:, 1] - nb[:, 1]) > 1.5)
        changed[vidx] = True
        redo = (changed & np.isfinite(XP)).nonzero()[0]
        if redo.size:
            X[redo], Y[redo], mass[redo] = self._refine_at(frame, redo, nb2, ctx)

    # ------------------------------------------------------------ status
    def _judge(self, t, res, ctx):
        """Status and reason of every point (:data:`~.status.RULES`), neighbour checks."""
        p = self.p
        X, Y, S, SEC, ST, RS, fits = ctx.X, ctx.Y, ctx.S, ctx.SEC, ctx.ST, ctx.RS, ctx.fits
        info = ctx.info
        prx, pry = ctx.pred[:, 0], ctx.pred[:, 1]
        ctx.sigma = sig = self._sigma(ctx)
        if fits.any():
            with np.errstate(invalid="ignore"):
                # sigma too large; or a faded blob (turning edge-on: below _FADED of its
                # frame-0 peak, or correlating below _WEAK) on a background that is not flat
                # for its contrast - a faint smear that a membrane edge shifts by a pixel or
                # more, which the image terms of sigma under-estimate
                faded = (info["peak"] < _FADED * self.peak0) | (S < _WEAK)
                imprecise = ~(sig <= p.max_sigma) | (faded & (info["bgres"] > _BG_RESIDUAL_FADED))
            par = np.array([p.min_score, p.lost_score, p.min_mass_ratio, p.mass_ratio_cap, p.score_drop_cap,
                            p.ambiguity_margin, p.jump_px, _MERGE_VALLEY, _BRIDGE])
            cond = rule_conditions(fits, S, SEC, ctx.mass, self.mass0, self.mass_ref, self.score_ref, ctx.resid,
                                   self.resid_rms, ctx.gap, self.nh, info["foreign"], imprecise, ctx.XP, ctx.YP,
                                   prx, pry, ctx.inside, ctx.j2, self.rb, info["valley"], ctx.lose, par)
            m = fits.nonzero()[0]
            ST[m] = OK
            RS[m] = 0
            apply_rules(cond, ST, RS)
            # a marker that stayed on its own blob - within half a pixel of its last reliable
            # position and of its prediction, strongly matched - is not in doubt: not for a
            # look-alike far away in a wide search window (no velocity yet), and it needs no
            # neighbours to vouch for it (a static dot next to the moving wing)
            with np.errstate(invalid="ignore"):
                stay = ((ctx.resid < STAY_PX) & (np.hypot(X - self.hist_x[:, 0, 0], Y - self.hist_x[:, 0, 1]) < STAY_PX)
                        & (S >= STAY_SCORE) & (ST <= FLAGGED))
            amb = stay & (RS == _R["ambiguous"]) & ctx.wide & (cond.sum(1) == 1)
            ST[amb] = OK
            RS[amb] = 0
            stay &= ST == OK
            # ... unless its blob was disputed since its last ok frame: the dot one grid
            # spacing behind, moving half a spacing per frame, stands on its place two frames
            # later (real dots, fresh DEV seed 205 cam1: ok 33 px off after a 'conflict')
            back_then = (stay & (np.abs(t - self.last_ok) > 1)).nonzero()[0]
            if back_then.size:
                stay[back_then[self._disputed(back_then, res, t)]] = False
            li = ctx.lose.nonzero()[0]
            X[li], Y[li] = prx[li], pry[li]
            lst = (fits & (ST == LOST)).nonzero()[0]
            X[lst] = Y[lst] = np.nan
            jmp = (RS == _R["jump"]).nonzero()[0]
            # (a marker that stayed on its own blob needs no neighbours to vouch for it: a
            # static dot next to the moving wing)
            chk = self._to_vouch(t, ctx, stay)
            if jmp.size or chk.size:
                self._vouch(jmp, chk, ctx, res, t)
            # the rules after the status rules (the stay rule, the vouching) judge identity:
            # none makes a point ok whose position is imprecise
            back = (ST == OK) & cond[:, _IMPRECISE_RULE]
            ST[back] = FLAGGED
            RS[back] = _R["imprecise"]
            co = self._coincident(ctx) | self._absorbed(ctx)
            ST[co] = FLAGGED
            RS[co] = _R["merged"]
        eidx = ctx.eidx
        if eidx.size:
            ex, ey = X[eidx], Y[eidx]
            okm = ((ctx.mass[eidx] > p.min_mass_ratio * self.mass0[eidx]) & (ex >= -0.5) & (ex <= self.W - 0.5)
                   & (ey >= -0.5) & (ey <= self.H - 0.5))
            ST[eidx[okm]] = FLAGGED
            RS[eidx[okm]] = _R["edge"]
            RS[eidx[~okm]] = _R["out_of_frame"]
            X[eidx[~okm]] = np.nan
            Y[eidx[~okm]] = np.nan
        if ctx.glitch or ctx.unexplained.any():
            g = (ST == OK) & (True if ctx.glitch else ctx.unexplained)
            ST[g] = FLAGGED
            RS[g] = _R["constellation"]
        # (an identity flag: it overrides the precision flag, and the point is not fed)
        passed = (ST == OK) | ((ST == FLAGGED) & (RS == _R["imprecise"]))
        ctx.provisional &= passed & ~ctx.unvouched  # (fed by :meth:`_update`)
        u = passed & (ctx.unvouched | ctx.provisional)
        ST[u] = FLAGGED
        RS[u] = _R["ambiguous"]
        g = (ST == OK) & self._relocated_astray(ctx, res)
        ST[g] = FLAGGED
        RS[g] = _R["constellation"]

    def _coincident(self, ctx):
        """Ok markers (boolean) whose refined centre lies within :data:`~.status.COINCIDENT`
        of a blob radius of another marker's measured centre (ok or flagged; not one that lost its
        blob, placed at its prediction): two markers cannot both be centred on one blob.
        The merged rule misses a pair whose blobs joined without a dark gap when neither is
        the other's split neighbour (independent renderer, fresh DEV seed 129 right, 73 deg
        view: marker 20 ok 2.4 px off, 0.5 px from marker 21, flagged ``merged`` there)."""
        X, Y, ST = ctx.X, ctx.Y, ctx.ST
        meas = (np.isfinite(X) & ((ST == OK) | (ST == FLAGGED)) & ~ctx.lose).nonzero()[0]
        out = np.zeros(len(X), bool)
        if meas.size < 2:
            return out
        d = np.hypot(X[meas][:, None] - X[meas], Y[meas][:, None] - Y[meas])
        np.fill_diagonal(d, np.inf)
        lim = COINCIDENT * np.maximum(self.rb[meas][:, None], self.rb[meas])
        out[meas[(d < lim).any(1)]] = True
        return out & (ST == OK)

    def _absorbed(self, ctx):
        """Ok markers (boolean) beside a neighbour (``ctx.j2``) that lost a conflict on this
        frame, whose refined centre is more than ``ABSORB_PX`` from its own pixel-level
        match: the loser's blob, no longer split off, may have pulled the centroid.
        Independent renderer, fresh DEV seed 169 black left, frame 74: marker 21 matched
        at its truth's pixel, marker 22 lost their conflict, and the refinement ran 2.7 px
        towards 22's blob, ok at sigma 0.20."""
        X, Y, ST, lose = ctx.X, ctx.Y, ctx.ST, ctx.lose
        out = np.zeros(len(X), bool)
        if not lose.any():
            return out
        j2 = ctx.j2
        beside = ((j2 >= 0) & lose[np.maximum(j2, 0)]).any(1)
        with np.errstate(invalid="ignore"):
            moved = np.hypot(X - ctx.XP, Y - ctx.YP) > ABSORB_PX
        return beside & moved & (ST == OK)

    def _to_vouch(self, t, ctx, stay):
        """Ok markers (indices) whose identity the motion model alone does not vouch for:
        resuming after a gap, restarting (fewer than 3 points), or further than
        ``_VOUCH_STEP`` of their spacing from their prediction; not those that stayed on
        their own blob (``stay``). :meth:`~.identity.IdentityStage._vouch` checks them
        against their neighbours' motion."""
        with np.errstate(invalid="ignore"):
            big = ctx.resid > _VOUCH_STEP * self._spacing
        pending = (np.abs(t - self.last_ok) > 1) | (self.nh < 3) | big
        return ((ctx.ST == OK) & ctx.fits & pending & ~stay).nonzero()[0]

    # ------------------------------------------------------------ update
    def _update(self, frame, t, res, direction, ctx):
        """Feed the motion model, update templates, re-acquire lost markers, write row t.

        Reliable points feed the motion model (and edge and imprecise points), and those
        flagged for what may touch their identity (merged, foreign) if they moved like their
        neighbours: a marker next to another or in glare keeps being followed instead of
        coasting, but not onto a neighbour's or an unpicked marker's blob. No flagged point
        feeds it (an imprecise one neither) that its neighbours, ok on its last ok frame and
        now, put elsewhere (:meth:`~.identity.IdentityStage._astray`): it is flagged
        ``jump`` instead, and serves re-acquisition as no anchor. Such runaway markers,
        fed, ran 60-70 frames and up to 250 px across the wing (independent renders, extra
        DEV seeds) and misled re-acquisition onto neighbours' blobs."""
        p = self.p
        X, Y, S, ST, RS = ctx.X, ctx.Y, ctx.S, ctx.ST, ctx.RS
        # an imprecise point passed every identity rule (they override it): only its
        # position is uncertain, and the motion model, which weighs it by its residual,
        # follows it - a whole sheet of faint dots would otherwise coast until lost
        rel = (ST == OK) | ((ST == FLAGGED) & ((RS == _R["edge"]) | (RS == _R["imprecise"]))) | ctx.provisional
        soft = ((ST == FLAGGED) & _IS_SOFT[RS] & ~rel).nonzero()[0]
        if soft.size:
            rel[self._inconsistent(soft, X, Y, ST, res, t, since="fed")] = True
        fl = (rel & (ST == FLAGGED)).nonzero()[0]
        if fl.size:
            # a flagged position the neighbours contradict is on another blob: it neither
            # feeds the motion model nor serves re-acquisition as an anchor ('jump')
            astray = fl[self._astray(fl, X, Y, ST, res, t)]
            rel[astray] = False
            RS[astray] = _R["jump"]
        imp = (rel & (ST == FLAGGED) & (RS == _R["imprecise"])).nonzero()[0]
        if imp.size:
            # an imprecise point of a marker disputed since its last ok frame may be on
            # another blob: it does not feed the model (black DEV seed 61 left: after a
            # jump, a marker ran 68-172 px off for 50 frames, fed by its own imprecise
            # positions, and misled re-acquisition onto a neighbour's blob)
            hop = self._hopped(imp, res, t, now=(X, Y))
            dis = imp[self._disputed(imp, res, t) | hop]
            if dis.size:
                rel[dis] = False
                # unless its neighbours vouch for it: a real dot falsely flagged 'jump'
                # at a reversal then coasted off its dot, lost, and was found 12 px off
                vouched = self._inconsistent(dis, X, Y, ST, res, t, since="fed")
                rel[vouched] = True
                # an imprecise path that hopped onto another blob, unvouched, is no
                # anchor for re-acquisition either ('jump')
                hopped = imp[hop]
                hopped = hopped[~rel[hopped]]
                RS[hopped] = _R["jump"]
        new_image = not ctx.glitch and ctx.aged >= 0  # (not an unexplained frame, nor a repeat of the last one)
        if not new_image:
            rel[:] = False  # nothing new
        held = self._poor_match(S, ctx.sigma)  # (before the model moves the running score)
        upd = update_model(t, X, Y, S, ST, rel, ctx.resid, ctx.mass, self.hist_x, self.hist_t, self.nh,
                           self.resid_rms, self.last_score, self.last_ok, self.mass_ref, self.score_ref,
                           self.last_upd, np.array([p.update_score, p.refresh_below, p.update_every], np.float64))
        if ctx.measured:
            self._keep_measured(ctx.measured, rel)
        if upd.any():
            self._refresh_templates(frame, t, X, Y, upd)
        # (nor is anything re-acquired on a repeat: the marker would borrow its neighbours'
        # step, nil on a repeated image, as its velocity, stand still on the next frames and
        # be found on the dot behind - real dots, repeated, fresh DEV seed 434 cam1: ok 33 px off)
        if self.lostflag.any() and new_image:
            self._reacquire(frame, t, res, direction, X, Y, S, ctx.XP, ctx.YP, ST, RS, ctx.pred, ctx.step_velocity)
        if self.lostflag.any() and new_image:
            relocate_group(self, frame, t, res, direction, ctx)  # a whole group lost at once
        res.x[t], res.y[t], res.score[t] = X, Y, S
        res.xpix[t], res.ypix[t] = ctx.XP, ctx.YP
        res.status[t], res.reason[t] = ST, RS
        held &= ST == OK
        res.status[t, held] = FLAGGED
        res.reason[t, held] = _R["imprecise"]
        res.sigma[t] = np.where(np.isfinite(X), ctx.sigma, np.nan)
        self.pos = np.column_stack([X, Y])

    def _poor_match(self, S, sigma):
        """Markers whose poor match holds them to a margin on sigma (boolean): score below
        ``_POOR_MATCH`` and more than ``_POOR_DROP`` below the running score, sigma above
        ``_POOR_MARGIN`` of ``max_sigma``. Such an ok point is *reported* flagged
        ``imprecise``; the tracker's own state still takes it as ok (it feeds the motion
        model, is the marker's last ok frame, and is not vouched for or searched wide
        again), since its identity passed every rule. Only the written row changes (the
        checks that later read the written rows - a resuming marker's path, the audit - see
        it flagged).

        Only a fall is held, not a chronically poor match: without the fall the margin cost
        our ``hard_stroke`` DEV 0.7 points of ok share (94.8 -> 94.1 %), nearly all of it one
        fast, blurred marker whose template never matches well (seed 0 left, 50 frames at
        score 0.76, 0.08 px off); with it, 0.2."""
        with np.errstate(invalid="ignore"):
            return ((S < _POOR_MATCH) & (S < self.score_ref - _POOR_DROP)
                    & (sigma > _POOR_MARGIN * self.p.max_sigma))

    def _refresh_templates(self, frame, t, X, Y, upd):
        """Blend the patches at (X, Y) into the templates of markers ``upd`` (bool)."""
        lam = self.p.update_rate
        for i in upd.nonzero()[0].tolist():
            cut = self._cut(frame, X[i], Y[i], self.h[i])
            self.tplr[i] = (1.0 - lam) * self.tplr[i] + lam * cut
            self._set_template(i)
            self.last_upd[i] = t


    def _sigma(self, ctx):
        """Per-axis 1-sigma uncertainty (px) of each refined position, from the image
        (:func:`~.sigma.sigma_of`; the terms and their gains are described in :mod:`~.sigma`)."""
        return sigma_of(self.noise, ctx.info, ctx.S, self.rb)

    def _rmax(self):
        """Largest disk radius of each marker (a blob may grow to this by foreshortening)."""
        return np.minimum(self.rb + _RD_MARGIN + 3.0, _RD_MAX)

    def _refine_all(self, frame, idx, ctx):
        """The compiled twin of :meth:`_voronoi` and :meth:`_refine_at` for markers ``idx``
        (one kernel call, ``_refine_all_kernel``; writes ``ctx.X, ctx.Y, ctx.mass,
        ctx.info``); returns the neighbour positions used for the split."""
        XP, YP, X, Y, mass, info = ctx.XP, ctx.YP, ctx.X, ctx.Y, ctx.mass, ctx.info
        jn = self._split_against(ctx)
        n = len(XP)
        nb = np.full((n, 2), np.nan)
        foreign = np.zeros(n, np.bool_)
        _refine_all_kernel(frame, idx, XP, YP, jn, self.rd, self.rb, self.sign64, self.noise, 2, WEIGHT_FRACTION,
                           FOREIGN_FRACTION, FOREIGN_NOISE, X, Y, mass, foreign, info["bgres"], info["peak"],
                           info["valley"], info["spread"], info["dshape"], info["rim"], info["tex"], nb)
        info["foreign"] = foreign
        # a foreign blob next to a steady marker: split off like a neighbour (rare)
        cand = idx[foreign[idx] & (mass[idx] > 0)]
        if cand.size:
            steady = ctx.steady[cand] & (np.hypot(XP[cand] - ctx.pred[cand, 0], YP[cand] - ctx.pred[cand, 1])
                                         <= 2.0 + 2.0 * self.resid_rms[cand])
            cand = cand[steady]
            if cand.size:
                xx, yy, mm, inf = _refine(frame, XP[cand], YP[cand], self.rd[cand], self.sign[cand], self.noise[cand],
                                          nb[cand], 2, rmax=self.rd[cand], nbr_r=ctx.nbr_r[cand],
                                          explain=np.ones(cand.size, bool))
                X[cand], Y[cand], mass[cand] = xx, yy, mm
                for k in _DIAGNOSTICS:
                    info[k][cand] = inf[k]
        return nb

    def _refine_at(self, frame, idx, nb, ctx):
        """Refine markers ``idx`` from their pixel-level positions ``ctx.XP, ctx.YP`` with
        the neighbour positions ``nb`` (:meth:`_voronoi`); record the diagnostics in
        ``ctx.info``; returns x, y and mass of the markers ``idx``.

        A foreign blob next to a marker tracked on the previous frame and matched where
        predicted is split off like a known neighbour (:func:`_refine`)."""
        XP, YP = ctx.XP, ctx.YP
        steady = ctx.steady[idx] & (np.hypot(XP[idx] - ctx.pred[idx, 0], YP[idx] - ctx.pred[idx, 1])
                                    <= 2.0 + 2.0 * self.resid_rms[idx])
        x, y, m, inf = _refine(frame, XP[idx], YP[idx], self.rd[idx], self.sign[idx], self.noise[idx], nb[idx], 2,
                               rmax=self.rd[idx], nbr_r=ctx.nbr_r[idx], explain=steady)
        for k in _DIAGNOSTICS + ("rd",):
            ctx.info[k][idx] = inf[k]
        return x, y, m

    def _split_against(self, ctx):
        """The neighbour each marker is split against (:func:`~.refine.split_neighbour`);
        ``ctx.nbr_r`` follows it."""
        jn = split_neighbour(ctx.XP, ctx.YP, ctx.j2)
        ctx.nbr_r[:] = self.rd[np.maximum(jn, 0)] + 0.5
        return jn

    def _voronoi(self, ctx):
        """Position of each marker's nearest neighbour for the pixel split (NaN: none near)."""
        XP, YP = ctx.XP, ctx.YP
        jn = self._split_against(ctx)
        j = np.maximum(jn, 0)
        # only a neighbour matched on this frame: one that lost its match to another
        # marker (conflict) may be anywhere near its prediction, and a split there could
        # cut this marker's own blob (its blob, if near, is caught as foreign instead)
        nx = XP[j].copy()
        ny = YP[j].copy()
        cx = np.where(np.isfinite(XP), XP, ctx.pred[:, 0])
        cy = np.where(np.isfinite(YP), YP, ctx.pred[:, 1])
        # the neighbour matters when its blob can reach this marker's disk or ring
        reach = self.rd + 3.0 + self.rb[j]
        dn = np.hypot(nx - cx, ny - cy)
        # (a neighbour on the same pixel is a conflict, flagged elsewhere: no split)
        far = (jn < 0) | ~(dn < reach) | (dn < 1.5)
        nx[far] = np.nan
        ny[far] = np.nan
        return np.column_stack([nx, ny])
