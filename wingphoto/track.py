"""Automatic marker tracking that flags instead of guessing.

:func:`track_markers` follows painted wing markers (6-11 px across, neighbours down to
~10 px apart, up to ~15 px/frame of motion, hard acceleration at stroke reversal, glare,
motion blur, edge-on merging, markers leaving the frame) through a high-speed sequence
and returns the tidy tracks DataFrame of ``docs/conventions.md``. Every point-frame is
``ok``, ``flagged`` (position is a best guess, with a ``reason``) or ``lost`` (x, y NaN).
The thesis' two scripts (NCC.m then trackcl.m, see :mod:`wingphoto.thesis`) needed 162
manual re-clicks out of 2280 point-frames; each design choice below answers one of the
failures the thesis reported, and is named after it.

Design, and the failure each choice prevents
--------------------------------------------
1. **Search only near a motion-predicted position.** The next position is predicted by
   a constant-acceleration (quadratic) extrapolation through the last three *reliable*
   refined positions (Lagrange weights, so gaps are handled; linear with two, constant
   with one). The search radius is ``2 + 3 sigma`` px, ``sigma`` a running RMS of each
   marker's own prediction residual, widened while a marker coasts. Prevents: the
   thesis' whole-image ``normxcorr2`` jumping to a look-alike marker, and its 8-9 px
   ``maxtravel`` limit that forced re-clicks at mid-stroke (15 px/frame): the
   prediction, not the previous position, is the window centre, so speed costs nothing
   and the window stays a few pixels wide (stroke reversal, ~1 px/frame^2 at
   3000 fps, is what the acceleration term absorbs).
2. **``cv2.matchTemplate`` (TM_CCOEFF_NORMED) on a small window per marker** (the
   *fast windowed matcher*, :func:`match_windows`). Prevents: the cost of correlating
   the whole image (``normxcorr2`` on 512x512 is ~4 ms per marker); the score is
   gain/offset invariant, which survives slow glare.
3. **Sub-pixel refinement inside the loop** (the *fast sub-pixel refiner*,
   :func:`refine_centroids`): background-subtracted intensity centroid on the raw
   frame inside a disk of radius ``blob radius + 3 px`` centred on the pixel-level
   match, the background a *plane* fitted to a 2 px ring just outside it (refitted
   without the ring pixels that stand far above it), each pixel weighted by its value
   minus a fifth of the blob's peak, re-centred on the nearest pixel and repeated where
   that pixel changed. The next prediction uses the refined point. Prevents: the
   thesis' two-pass design in which NCC's integer positions drifted off-centre and
   ``cntrd`` was fed stale seeds. The disk must contain the whole blob - its long axis
   and the blur, not the area-equivalent radius: a disk 1.5 px beyond that radius
   pulled the centre of a blob that had grown since frame 0 (foreshortening) up to a
   pixel towards the disk's centre, and on the rigid target 0.4-0.8 px. Weighting by
   the value above a fifth of the peak leaves out what the disk holds besides the blob
   (a membrane edge, glare, the tail of another blob), at the price of a slight pixel
   locking on hard-edged blobs (< 0.03 px unblurred, < 0.01 px with the optics' blur).
   The disk is fixed after frame 0 (grown there if the blob spills out of it): a disk
   that grows in the middle of a sequence swallows a neighbour sooner than it catches a
   growing blob. The plane (not a constant) matters under glare: a gradient of 5 grey
   levels/px across an 8 px marker biases a constant-background centroid by ~0.3 px up
   the gradient.
4. **Pixels are split between close neighbours (Voronoi)** before the centroid: each
   marker only uses pixels nearer to itself than to its nearest neighbour *matched on
   this frame* (one that lost its match to another marker may be anywhere near its
   prediction: a split there would cut this marker's own blob). Prevents: a neighbour 10
   px away pulling the centroid (the thesis' ``cntrd`` window of 9 px straddled two
   markers on a foreshortened wing).
5. **Template update that cannot drift.** A marker's template is re-cut with
   ``cv2.getRectSubPix`` *centred on the refined sub-pixel position*, only when the match
   is confident (score >= ``update_score``) but the appearance has changed (score <
   ``refresh_below``), blended into a running template, and what is matched is always
   ``original_weight * original + (1 - original_weight) * running``. Prevents: the
   fixed frame-0 template of NCC.m failing as markers foreshorten and blur, without the
   classic drift of naive updates (re-cutting at the integer match lets the error of each
   frame accumulate; re-cutting at the refined centre does not, and the original anchors
   the identity).
6. **Two points never claim the same blob.** Pixel-level matches are compared jointly
   per frame; when two markers land on one blob the one closer to its own prediction
   keeps it and the other is flagged ``conflict`` (reported at its prediction).
   Prevents: two tracks silently merging into one after a close pass.
7. **Ambiguous, low-score, merged, pulled and out-of-frame points are flagged or lost,
   never ok.**
   ``ambiguous``: a second local maximum of the correlation, not explained by another
   marker's predicted position, within ``ambiguity_margin`` of the best. ``low_score``:
   score < ``min_score`` (flagged) or < ``lost_score`` (lost). ``merged``: the blob
   touches another marker's - the two are closer than the sum of their radii + 1 px
   and no dark gap (< half the peak) separates them, or a bright bridge (> 0.8 of the
   peak) joins them (the wing is edge-on). ``foreign``: something bright that no known
   marker explains stands in the background ring and touches the disk - a marker
   without a pick or a lost one appearing next to this one, glare: the centroid may be
   pulled (a foreign blob whose centre can be found next to a marker tracked steadily
   is split off like a known neighbour when a dark gap separates the two, and the point
   stays ok). ``background``: the ring departs from a plane by more than 10 % of the
   marker's contrast (4 % for a marker that faded below 60 % of its frame-0 peak or
   correlates below 0.75: turning edge-on, it is a faint smear that a membrane edge or
   glare shifts by up to a pixel). ``jump``: refined point further from the prediction
   than the motion model allows (unless the neighbours vouch for it, see 10), or a
   marker that resumes after a gap and did not move like its neighbours. ``no_signal``:
   the blob's integrated brightness fell below ``min_mass_ratio`` of its frame-0 value.
   ``edge``: the template no longer fits in the image (centroid only, flagged).
   ``out_of_frame``: the prediction left the image (lost). Flagged and lost points do
   not feed the motion model (it coasts on the last reliable points), except an
   ``edge`` point and one flagged ``merged``, ``foreign`` or ``background`` whose move
   since its last reliable position the neighbours confirm. Prevents: the thesis'
   confident wrong positions in glare and when markers ran together at extreme angles,
   and (on hard synthetic sequences started at other stroke phases) ok points up to 2.8
   px off, pulled by a marker without a pick appearing next to them.
8. **Re-acquisition from the neighbours.** A marker lost for more than ``max_coast``
   frames (left the frame, merged, glare) is searched for again where its neighbours
   put it: those reliable on its last reliable frame and now - and, when two or more
   did, those that moved like it then (moving ones for a wing marker, not the static
   mount and reference dots) - map its last position to now by a robust affine map (four
   or more that agree with one, RMS <= 1.5 px), else by the mean displacement of a group
   that moved alike; failing that, a robust affine map from the reference frame (the
   picks): a planar wing seen from afar moves by an affine map however much time has
   passed. An isolated marker (fewer than two neighbours within four neighbour spacings:
   the two-marker rigid target, a reference dot) is searched for in a wide window
   (``search_radius``) at its last position, moved like its one neighbour, and accepted
   only with a score of at least 0.9. The blob found is accepted only with a high,
   unambiguous score, if this marker's prediction is the nearest to it, if no flagged or
   lost marker (which could own it) is nearby - unless that one is itself re-acquired on
   another blob and the two assignments fit the two predictions better than the swap,
   so that two lost neighbours do not block each other for ever - if its refinement
   finds no foreign blob, and if the neighbours put the marker's last *ok* position
   within 4 px of it; the marker is flagged ``reacquired`` on that frame. Prevents: tip
   markers that left the frame being lost for the rest of the sequence (the thesis'
   lost tip markers), marker 0 of the rigid target lost from its 67th still to the end,
   without ever taking a neighbour's blob.
9. **First frames (and restarts).** Without a velocity, frame 1 is searched within
   ``search_radius``; each such match is checked against the motion of its neighbours
   (up to six within four neighbour spacings: the other markers with a motion model and
   the wide-searched ones whose match is unambiguous, their displacement from the
   reference frame mapped as in 8). An ambiguous match is replaced by a small search at
   the neighbours' prediction; an unambiguous one that disagrees with it is flagged
   ``ambiguous`` (not moved: a static dot next to the wing keeps its own match). Without
   a group of neighbours that moved alike the match stands. Prevents: a marker starting
   on its neighbour's, or an unpicked marker's, blob when the wing moves fast at frame 0.
10. **Neighbours vouch for a jump, and check a resumption.** A marker that leaves its
    prediction by more than the motion model allows is not flagged ``jump`` when its
    neighbours made the same move (the whole wing, or the rigid target between two
    stills, stopped or turned at once); a marker with nothing to compare with is vouched
    for by a short move (< 30 % of the spacing to its nearest marker) to a strong,
    unambiguous match. Conversely a marker that resumes after a gap (flagged or lost on
    the previous frames) or restarts is ok only if its move since its last ok position
    agrees with its neighbours' (or, without neighbours to compare with, if it is within
    2 px of its own prediction). Prevents: a dead stop losing every marker of a rigid
    target, and a marker that coasted landing on a neighbour's blob that happens to lie
    near its extrapolated prediction.
11. **Optional backward pass** (``bidirectional=True``): tracking again from the last
    frame to the first; where both passes are ok but disagree by more than
    ``fb_tolerance`` the point is flagged ``fb_disagree``; where only the backward pass
    is ok (forward lost it), its position is used.
12. **Streaming, checkpoints.** Frames are read one at a time (memory independent of the
    sequence length); results go to preallocated arrays and the DataFrame is built at the
    end. With ``checkpoint=path`` the complete state is saved atomically every
    ``checkpoint_every`` frames and when an exception stops the run; the same call
    resumes from it with bit-identical results.

13. **Fast path.** A marker moving predictably (three reliable points, prediction
    residual RMS < 0.35 px), alone (no neighbour within its radius + the neighbour's + 4
    px) and matched with score >= 0.9 on the previous frame gets the full NCC search only
    every ``search_every`` frames (staggered across markers). In between, the centroid
    is computed at the prediction and *verified*: the TM_CCOEFF_NORMED score of its
    template at the refined pixel must be >= 0.85, the refined point within
    ``max(1, 4 sigma)`` px of the prediction, and its brightness above ``min_mass_ratio``;
    any failure runs the full search on that frame. Prevents: spending most of the time
    on ``matchTemplate`` calls that only confirm the prediction (``search_every=1``
    searches everything, every frame).
14. **Points without a pick.** A NaN pick (a marker invisible in frame 0) gives that
    point lost rows (reason ``no_pick``) instead of failing the whole run. Such a marker
    is not known to the tracker: when it appears next to a tracked one, the ``foreign``
    test of 7 keeps it from pulling that one.
15. **Compiled kernels (optional).** With numba installed, the per-frame work runs as
    compiled loops over the markers: the centroid passes, the windowed and single-pixel
    correlation (a small search window - radius <= 3 px, a marker moving predictably -
    is hill-climbed from the prediction: such a window has no room for a runner-up peak
    away from the best, so nothing is lost), the peak analysis, the nearest neighbours,
    the start of a step (predictions, fast path), its status rules and the motion-model
    update. The numpy/OpenCV code computes the same (``WINGPHOTO_NO_NUMBA=1`` before
    the import forces it; OpenCV correlates the template rounded to 8 bits). Compiling
    costs ~6 s on the first call for 8-bit frames (~3 s more per other pixel type),
    cached on disk next to the module for later processes. Prevents: the ~300 small
    numpy calls per frame that held the numpy code at ~700 frames/s.

Speed (``benchmarks/track_bench.py``, 30 markers on 512 x 512 frames, a 2-core machine
shared with other work): ~3200 frames/s over 300 frames and ~3700 over 1000 with numba
(the start - picks and the wide search of frame 1 - costs ~15 ms once), ~700 frames/s
with the numpy/OpenCV code only. ``benchmarks/track_bench.py --sweep`` tracks hard
sequences at ten stroke phases and checks that no ok point is more than 1 px off.
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
from pathlib import Path

import cv2
import numpy as np

from .video import write_tracking_video

__all__ = [
    "track_markers",
    "match_windows",
    "refine_centroids",
    "check_stereo",
    "apply_corrections",
    "save_corrections",
    "load_corrections",
    "retrack_from",
    "write_tracking_video",
    "TRACKER_COLUMNS",
    "REASONS",
]

logger = logging.getLogger(__name__)

#: Columns of :func:`track_markers`' result: :data:`wingphoto.io.TRACK_COLUMNS` plus the
#: pixel-level match and the reason of a flag.
TRACKER_COLUMNS = ["camera", "frame", "point", "x", "y", "score", "status", "x_pix", "y_pix", "reason"]
STATUS = ("ok", "flagged", "lost", "manual")
OK, FLAGGED, LOST, MANUAL = 0, 1, 2, 3
#: Reasons a point is flagged or lost (the ``reason`` column; "" when ok).
REASONS = (
    "",
    "low_score",
    "ambiguous",
    "merged",
    "conflict",
    "edge",
    "out_of_frame",
    "jump",
    "lost_track",
    "reacquired",
    "fb_disagree",
    "stereo",
    "no_signal",
    "appearance",
    "no_pick",
    "pick_moved",
    "foreign",
    "background",
)
_R = {name: i for i, name in enumerate(REASONS)}
_RULE_CODES = np.array([_R[k] for k in ("low_score", "no_signal", "merged", "appearance", "ambiguous", "jump",
                                        "foreign", "background", "conflict")], np.int8)
#: Flags about a point's precision, not its identity.
_SOFT = np.array([_R[k] for k in ("merged", "foreign", "background")], np.int8)
_IS_SOFT = np.isin(np.arange(len(REASONS)), _SOFT)
_CHECKPOINT_VERSION = 2
#: Disk radius of the centroid (px): at least _RD_MIN, at most _RD_MAX, and
#: _RD_MARGIN beyond the blob's measured support (blur tails).
_RD_MIN, _RD_MAX, _RD_MARGIN = 2.5, 14.0, 3.0
#: Flag 'background' when the RMS departure of the ring from a plane exceeds this
#: fraction of the marker's contrast.
_BG_RESIDUAL, _BG_RESIDUAL_FADED, _FADED, _WEAK = 0.1, 0.04, 0.6, 0.75
#: Two markers predicted to touch are not 'merged' when the image between them falls below
#: this fraction of the marker's peak (a visible gap: the pixel split separates them).
_MERGE_VALLEY, _BRIDGE = 0.5, 0.8


# --------------------------------------------------------------------------- inputs
class _Frames:
    """Uniform, validated access to a (T, H, W) array or a lazy sequence (len, [i])."""

    def __init__(self, frames):
        if isinstance(frames, (str, Path)):
            raise ValueError(
                "frames must be image data, got a path; load it first with "
                "wingphoto.io.read_sequence(path)"
            )
        if isinstance(frames, np.ndarray):
            if frames.ndim == 2:
                raise ValueError(
                    f"frames must be a (T, H, W) stack or a sequence of images, got one 2D image "
                    f"of shape {frames.shape}; pass frames[None] for a single frame"
                )
            if frames.ndim != 3:
                raise ValueError(
                    f"frames must be a (T, H, W) array of grayscale images, got shape {frames.shape}; "
                    "convert colour frames to grayscale first"
                )
        elif not (hasattr(frames, "__len__") and hasattr(frames, "__getitem__")):
            raise ValueError(
                f"frames must be a (T, H, W) array or a sequence supporting len() and [i] "
                f"(e.g. wingphoto.io.read_sequence), got {type(frames).__name__}"
            )
        self.src = frames
        self.n = len(frames)
        if self.n == 0:
            raise ValueError("frames is empty: the sequence has no images to track")
        f0 = np.asarray(frames[0])
        if f0.ndim != 2:
            raise ValueError(
                f"frames must be grayscale (H, W) images, frame 0 has shape {f0.shape}; "
                "convert colour frames to grayscale first"
            )
        if f0.dtype not in (np.uint8, np.uint16, np.float32, np.float64):
            raise ValueError(f"frames must be uint8, uint16 or float, frame 0 is {f0.dtype}")
        self.shape = f0.shape
        self.dtype = f0.dtype
        self.is_u8 = f0.dtype == np.uint8

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        f = self.src[i]
        if not isinstance(f, np.ndarray):
            f = np.asarray(f)
        if f.shape != self.shape:
            raise ValueError(
                f"frame {i} has shape {f.shape} but frame 0 has {self.shape}: all frames of a "
                "sequence must have the same size (mixed folders or a cropped file?)"
            )
        if f.dtype != self.dtype:
            raise ValueError(f"frame {i} is {f.dtype} but frame 0 is {self.dtype}: mixed bit depths")
        if f.dtype == np.float64:
            f = f.astype(np.float32)
        return f


def _parse_picks(picks):
    """Return (xy (N, 2) float, point ids (N,) int64, half sizes (N,) int or -1)."""
    import pandas as pd

    half = None
    if isinstance(picks, (list, tuple)) and picks and isinstance(picks[0], dict):
        picks = pd.DataFrame(list(picks))
    if isinstance(picks, pd.DataFrame):
        missing = [c for c in ("x", "y") if c not in picks.columns]
        if missing:
            raise ValueError(
                f"picks lacks columns {missing}; expected point, x, y (and optionally half_size "
                "or rect) as saved by the picker, or an (N, 2) array of (x, y) clicks"
            )
        xy = picks[["x", "y"]].to_numpy(np.float64)
        ids = picks["point"].to_numpy(np.int64) if "point" in picks.columns else np.arange(len(picks))
        if "half_size" in picks.columns:
            half = picks["half_size"].to_numpy(np.float64)
        elif "rect" in picks.columns:
            # rect = (x0, y0, width, height) as MATLAB's imcrop returns it
            rects = np.array([np.asarray(r, float).reshape(4) for r in picks["rect"]])
            half = (np.maximum(rects[:, 2], rects[:, 3]) - 1) / 2
        elif {"rect_w", "rect_h"} <= set(picks.columns):
            half = (np.maximum(picks["rect_w"].to_numpy(float), picks["rect_h"].to_numpy(float)) - 1) / 2
    else:
        xy = np.asarray(picks, dtype=np.float64)
        if xy.ndim == 1 and xy.size == 2:
            xy = xy[None, :]
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(
                f"picks must be an (N, 2) array of (x, y) clicks or the picker's saved picks, "
                f"got shape {np.shape(picks)}"
            )
        ids = np.arange(len(xy), dtype=np.int64)
    if len(xy) == 0:
        raise ValueError("picks is empty: click at least one marker")
    bad = ~np.all(np.isfinite(xy), axis=1)
    if bad.all():
        raise ValueError("picks are all NaN: click at least one marker in frame 0")
    if len(np.unique(ids)) != len(ids):
        raise ValueError("picks has duplicate point ids; each point must be picked once")
    if half is None:
        half = np.full(len(xy), -1.0)
    half = np.where(np.isfinite(half), half, -1.0)
    half = np.where(half < 0, -1, np.maximum(np.round(half), 2)).astype(np.int64)
    return xy, ids, half


# --------------------------------------------------------------------------- refiner
class _Grid:
    """Pixel offsets of a (2 hc + 1)^2 patch and the sums the centroid pass needs."""

    _cache = {}

    @classmethod
    def get(cls, hc):
        g = cls._cache.get(hc)
        if g is None:
            g = cls._cache[hc] = cls(hc)
        return g

    def __init__(self, hc):
        self.hc = hc
        o = np.arange(-hc, hc + 1)
        self.o = o
        gx = np.tile(o, len(o)).astype(np.float32)
        gy = np.repeat(o, len(o)).astype(np.float32)
        self.gx, self.gy = gx, gy
        self.d2 = gx * gx + gy * gy
        self.gxy = np.ascontiguousarray(np.stack([gx, gy], axis=1))  # (K, 2)
        one = np.ones_like(gx)
        self.basis3 = np.ascontiguousarray(np.stack([one, gx, gy], axis=1))  # (K, 3)
        self.basis3t = np.ascontiguousarray(self.basis3.T)
        self.basis6 = np.ascontiguousarray(np.stack([one, gx, gy, gx * gx, gx * gy, gy * gy], axis=1))
        self.sym = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])


_OFFSETS = {}


def _gather(frame, ix, iy, o):
    """(n, len(o)**2) float32 patches of ``frame`` centred on integer pixels (ix, iy).

    Pixels beyond the image edge repeat the edge (callers flag such points)."""
    H, W = frame.shape
    lo, hi = int(o[0]), int(o[-1])
    n = len(ix)
    if iy.min() + lo < 0 or iy.max() + hi > H - 1 or ix.min() + lo < 0 or ix.max() + hi > W - 1:
        rows = np.clip(iy[:, None] + o, 0, H - 1)
        cols = np.clip(ix[:, None] + o, 0, W - 1)
        flat = ((rows * W)[:, :, None] + cols[:, None, :]).reshape(n, -1)
    else:
        key = (W, lo, hi)
        off = _OFFSETS.get(key)
        if off is None:
            off = _OFFSETS[key] = (o[:, None] * W + o[None, :]).ravel()
        flat = (iy * W + ix)[:, None] + off
    return np.take(frame, flat).astype(np.float32)


def _plane(patch, ring, grid):
    """Coefficients (n, 3) of the plane a + b x + c y fitted to ``patch`` on ``ring`` (bool)."""
    w = ring.astype(np.float32)
    mom = w @ grid.basis6  # sums of w, w x, w y, w x^2, w x y, w y^2
    rhs = (w * patch) @ grid.basis3
    A = mom[:, grid.sym].astype(np.float64)
    reg = 1e-3 * A[:, 0, 0] + 1e-6
    A[:, 1, 1] += reg
    A[:, 2, 2] += reg
    A[:, 0, 0] += 1e-6
    return np.linalg.solve(A, rhs[:, :, None].astype(np.float64))[:, :, 0].astype(np.float32)


#: Ring outliers (foreign signal) are pixels brighter than the fitted background by this
#: fraction of the marker's peak (and by FOREIGN_NOISE noise sigmas).
FOREIGN_FRACTION = 0.25
FOREIGN_NOISE = 6.0
#: The centroid weighs each disk pixel by its background-subtracted value minus this
#: fraction of the peak (pixels below it get no weight).
WEIGHT_FRACTION = 0.2


def _centroid_pass(frame, ix, iy, rd, sign, nb, noise, nbr_r=None, wfrac=WEIGHT_FRACTION):
    """One background-subtracted centroid pass around integer pixels (ix, iy).

    rd : (n,) disk radius (px); the background plane is fitted on the 2 px ring outside.
    sign : (n,) polarity (+1 bright, -1 dark markers).
    nb : (n, 2) offset of the nearest neighbour from (ix, iy), NaN for none, or None.
    noise : (n,) noise sigma (grey levels) of each marker's neighbourhood.
    nbr_r : (n,) radius of the neighbour's blob (its disk radius): bright ring pixels
        within it are explained by the neighbour, not foreign.

    Returns a dict: d (n, 2) offset of the centroid from (ix, iy), mass, peak (largest
    background-subtracted value in the disk), rsup (distance from the centroid of the
    furthest disk pixel above a quarter of the peak, + 0.5 px), and the ring outliers
    (pixels of the ring well above the plane: something bright there): nout, their
    fraction of the ring, dip (length of the mean unit vector from the centroid to them:
    ~1 one-sided, ~0 all around) and omin (distance of the nearest one from (ix, iy)).
    """
    n = len(ix)
    hc = int(math.ceil(float(rd.max()))) + 3
    grid = _Grid.get(hc)
    patch = _gather(frame, ix, iy, grid.o)
    if (sign != 1).any():
        patch *= sign[:, None].astype(np.float32)
    r = rd.astype(np.float32)[:, None]
    d2 = grid.d2[None, :]
    disk = d2 <= r * r
    ring = (d2 <= (r + 2.0) ** 2) & ~disk
    near = None
    if nb is not None:
        # Voronoi split: keep pixels nearer to this marker than to its nearest neighbour.
        near = np.isfinite(nb[:, 0])
        if near.any():
            nbf = np.where(near[:, None], nb, 0.0).astype(np.float32)
            half = 0.5 * np.einsum("ij,ij->i", nbf, nbf)
            keep = (nbf @ grid.gxy.T) < half[:, None]
            keep[~near] = True
            disk &= keep
            ring &= keep
    coef = _plane(patch, ring, grid)
    res = patch - coef @ grid.basis3t
    sig = np.where(disk, res, np.float32(0.0))
    peak = sig.max(1)
    thr = np.maximum(FOREIGN_FRACTION * peak, FOREIGN_NOISE * noise).astype(np.float32)
    out = ring & (res > thr[:, None])
    nout = out.sum(1)
    hit = np.flatnonzero(nout)
    expl = None
    if hit.size and near is not None and near[hit].any() and nbr_r is not None:
        # bright ring pixels on the neighbour's blob (its tail crosses the bisector)
        nbh = np.where(near[hit, None], nb[hit], 1e6).astype(np.float32)
        dxn = grid.gx[None, :] - nbh[:, 0:1]
        dyn = grid.gy[None, :] - nbh[:, 1:2]
        rr = np.asarray(nbr_r, np.float32)[hit, None]
        expl = (dxn * dxn + dyn * dyn) <= rr * rr
    if hit.size:
        # robust background: refit the plane without the ring outliers
        ring2 = ring[hit] & ~out[hit]
        ok2 = ring2.sum(1) >= 8
        if ok2.any():
            h2 = hit[ok2]
            c2 = _plane(patch[h2], ring2[ok2], grid)
            coef[h2] = c2
            res[h2] = patch[h2] - c2 @ grid.basis3t
            sig[h2] = np.where(disk[h2], res[h2], np.float32(0.0))
            peak[h2] = sig[h2].max(1)
    # how far the background departs from a plane (glare, the membrane's edge), relative
    # to the marker's contrast
    rin = ring & ~out
    with np.errstate(invalid="ignore", divide="ignore"):
        bgres = np.sqrt(np.where(rin, res * res, np.float32(0.0)).sum(1) / rin.sum(1)) / peak
    mass = sig.sum(1)
    wgt = np.maximum(sig - (wfrac * peak)[:, None], np.float32(0.0)) if wfrac > 0 else np.maximum(sig, 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = (wgt @ grid.gxy) / wgt.sum(1)[:, None]
    fx = np.nan_to_num(d[:, 0:1]).astype(np.float32)
    fy = np.nan_to_num(d[:, 1:2]).astype(np.float32)
    frac = np.zeros(n)
    dip = np.zeros(n)
    omin = np.full(n, np.inf)
    if hit.size:
        o = out[hit]
        if expl is not None:
            o = o & ~expl
            nout[hit] = o.sum(1)
            keep_hit = nout[hit] > 0
            hit, o = hit[keep_hit], o[keep_hit]
    if hit.size:
        ex = grid.gx[None, :] - fx[hit]
        ey = grid.gy[None, :] - fy[hit]
        dn = np.sqrt(np.maximum(ex * ex + ey * ey, 1e-12))
        ux = np.where(o, ex / dn, 0.0).sum(1)
        uy = np.where(o, ey / dn, 0.0).sum(1)
        dip[hit] = np.hypot(ux, uy) / nout[hit]
        frac[hit] = nout[hit] / np.maximum(ring[hit].sum(1), 1)
        omin[hit] = np.sqrt(np.where(o, d2, np.inf).min(1))
    # the valley between this blob and its neighbour: the largest value on the segment
    # between them at 40, 50 and 60 % of the way (a gap between two blobs is dark)
    valley = np.full(n, np.nan)
    if near is not None and near.any():
        w = np.flatnonzero(near)
        H, W = frame.shape
        vals = []
        for f in (0.4, 0.5, 0.6):
            u = np.rint(f * nb[w, 0].astype(np.float64)).astype(np.int64)
            v = np.rint(f * nb[w, 1].astype(np.float64)).astype(np.int64)
            img = frame[np.clip(iy[w] + v, 0, H - 1), np.clip(ix[w] + u, 0, W - 1)].astype(np.float64)
            vals.append(sign[w] * img - (coef[w, 0] + coef[w, 1] * u + coef[w, 2] * v))
        valley[w] = np.min(vals, axis=0) / peak[w]
    return dict(d=d, mass=mass, peak=peak, nout=nout, frac=frac, dip=dip, omin=omin, bgres=bgres, valley=valley)


# --------------------------------------------------------------------------- accelerator
# Optional (design choice 15 in the module docstring): with numba installed, the per-frame
# work runs as compiled loops over the markers - the centroid passes, the windowed and
# single-pixel correlation, the peak analysis, the nearest neighbours, the start of a step
# (predictions, fast path), its status rules and the motion-model update - with the same
# arithmetic as the numpy/OpenCV code, which runs without numba or with
# WINGPHOTO_NO_NUMBA=1 set before the import.
try:  # pragma: no cover - depends on the environment
    import os as _os

    if _os.environ.get("WINGPHOTO_NO_NUMBA"):
        raise ImportError
    import numba as _numba
except ImportError:  # pragma: no cover
    _numba = None


def _solve_plane(s0, sx, sy, sxx, sxy, syy, si, sxi, syi):
    """Solve the regularised 3 x 3 normal equations of the plane (as :func:`_plane`)."""
    reg = 1e-3 * s0 + 1e-6
    a00 = s0 + 1e-6
    a11 = sxx + reg
    a22 = syy + reg
    a01, a02, a12 = sx, sy, sxy
    # Cramer's rule on the symmetric matrix
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    a = (c00 * si + c01 * sxi + c02 * syi) / det
    b = (c01 * si + c11 * sxi + c12 * syi) / det
    c = (c02 * si + c12 * sxi + c22 * syi) / det
    return a, b, c


def _ring_plane(ru, rv, rval, routl, nr):
    """Plane fitted to the ring pixels not marked in ``routl`` (see :func:`_solve_plane`)."""
    s0 = sx = sy = sxx = sxy = syy = si = sxi = syi = 0.0
    for k in range(nr):
        if routl[k]:
            continue
        u = ru[k]
        v = rv[k]
        val = rval[k]
        s0 += 1.0
        sx += u
        sy += v
        sxx += u * u
        sxy += u * v
        syy += v * v
        si += val
        sxi += u * val
        syi += v * val
    return _solve_plane(s0, sx, sy, sxx, sxy, syy, si, sxi, syi)


def _disk_peak(du, dv, dval, nd, pa, pb, pc):
    """Largest value above the plane in the disk (0 for an empty disk)."""
    if nd == 0:
        return 0.0
    peak = -np.inf
    for k in range(nd):
        res = dval[k] - (pa + pb * du[k] + pc * dv[k])
        if res > peak:
            peak = res
    return peak


def _pass1(frame, cx, cy, r, sg, nx_, ny_, noise_i, rr, wfrac, ff, fn, du, dv, dval, ru, rv, rval, routl):
    """One centroid pass of one marker (the compiled twin of :func:`_centroid_pass`).

    Returns dx, dy, mass, peak, nout (not explained by the neighbour), frac, dip, omin,
    bgres, valley."""
    H, W = frame.shape
    hc = int(np.ceil(r)) + 3
    near = not np.isnan(nx_)
    half = 0.5 * (nx_ * nx_ + ny_ * ny_) if near else 0.0
    r2 = r * r
    R2 = (r + 2.0) * (r + 2.0)
    nd = 0
    nr = 0
    inside = cx - hc >= 0 and cy - hc >= 0 and cx + hc <= W - 1 and cy + hc <= H - 1
    for v in range(-hc, hc + 1):
        rem = R2 - v * v
        if rem < 0:
            continue
        yy = min(max(cy + v, 0), H - 1)
        fv = np.float64(v)
        uw = int(np.sqrt(rem))
        # the disk's span on this row
        remd = r2 - v * v
        ud = int(np.sqrt(remd)) if remd >= 0 else -1
        if ud >= 0 and (ud + 1) * (ud + 1) + v * v <= r2:
            ud += 1
        while uw >= 0 and uw * uw + v * v > R2:
            uw -= 1
        while ud >= 0 and ud * ud + v * v > r2:
            ud -= 1
        for u in range(-uw, uw + 1):
            if near and not (nx_ * u + ny_ * v < half):
                continue
            if inside:
                val = sg * np.float64(frame[yy, cx + u])
            else:
                val = sg * np.float64(frame[yy, min(max(cx + u, 0), W - 1)])
            if -ud <= u <= ud:
                du[nd] = u
                dv[nd] = fv
                dval[nd] = val
                nd += 1
            else:
                ru[nr] = u
                rv[nr] = fv
                rval[nr] = val
                nr += 1
    for k in range(nr):
        routl[k] = False
    pa, pb, pc = _ring_plane(ru, rv, rval, routl, nr)
    peak = _disk_peak(du, dv, dval, nd, pa, pb, pc)
    thr = max(ff * peak, fn * noise_i)
    nout = 0
    for k in range(nr):
        if rval[k] - (pa + pb * ru[k] + pc * rv[k]) > thr:
            routl[k] = True
            nout += 1
    if nout > 0 and nr - nout >= 8:
        pa, pb, pc = _ring_plane(ru, rv, rval, routl, nr)
        peak = _disk_peak(du, dv, dval, nd, pa, pb, pc)
    cut = wfrac * peak if wfrac > 0 else 0.0
    mass = 0.0
    sw = swx = swy = 0.0
    for k in range(nd):
        res = dval[k] - (pa + pb * du[k] + pc * dv[k])
        mass += res
        w = res - cut
        if w > 0:
            sw += w
            swx += w * du[k]
            swy += w * dv[k]
    sbg = 0.0
    nbg = 0
    for k in range(nr):
        if not routl[k]:
            res = rval[k] - (pa + pb * ru[k] + pc * rv[k])
            sbg += res * res
            nbg += 1
    dx = swx / sw if sw > 0 else np.nan
    dy = swy / sw if sw > 0 else np.nan
    bg = np.sqrt(sbg / nbg) / peak if nbg > 0 else np.nan
    # ring outliers not on the known neighbour's blob: how one-sided, how near
    fx = dx if sw > 0 else 0.0
    fy = dy if sw > 0 else 0.0
    nexp = 0
    ux = uy = 0.0
    omin2 = np.inf
    if nout > 0:
        for k in range(nr):
            if routl[k]:
                u = ru[k]
                v = rv[k]
                if near and not np.isnan(rr):
                    ex_ = u - nx_
                    ey_ = v - ny_
                    if ex_ * ex_ + ey_ * ey_ <= rr * rr:
                        continue
                nexp += 1
                ex_ = u - fx
                ey_ = v - fy
                dn = np.sqrt(max(ex_ * ex_ + ey_ * ey_, 1e-12))
                ux += ex_ / dn
                uy += ey_ / dn
                d2 = u * u + v * v
                if d2 < omin2:
                    omin2 = d2
    valley = np.nan
    if near:
        vmin = np.inf
        for f in (0.4, 0.5, 0.6):
            iu = int(np.rint(f * nx_))
            iv = int(np.rint(f * ny_))
            yy = min(max(cy + iv, 0), H - 1)
            xx = min(max(cx + iu, 0), W - 1)
            val = sg * np.float64(frame[yy, xx]) - (pa + pb * iu + pc * iv)
            if val < vmin:
                vmin = val
        valley = vmin / peak
    frac = nexp / max(nr, 1) if nexp > 0 else 0.0
    dip = np.hypot(ux, uy) / nexp if nexp > 0 else 0.0
    omin = np.sqrt(omin2) if nexp > 0 else np.inf
    return dx, dy, mass, peak, nexp, frac, dip, omin, bg, valley


def _buffers(rd):
    cap = 0
    for i in range(rd.shape[0]):
        m = 2 * (int(np.ceil(rd[i])) + 3) + 1
        cap = max(cap, m * m)
    return (np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap),
            np.empty(cap, np.bool_))


def _refine_kernel(frame, x, y, rd, sign, noise, nbx, nby, nbr_r, iterations, rmax, wfrac, ff, fn, out):
    """Compiled twin of :func:`_refine_core` (the iterated centroid of each marker);
    ``out`` (n, 8) receives x, y, mass, peak, foreign, bgres, valley and the disk radius."""
    H, W = frame.shape
    rgrow = np.empty(rd.shape[0])
    for i in range(rd.shape[0]):
        rgrow[i] = min(rmax[i], rd[i] + 3.0) if rmax[i] > rd[i] else rd[i]
    du, dv, dval, ru, rv, rval, routl = _buffers(rgrow)
    for i in range(x.shape[0]):
        xi = x[i]
        yi = y[i]
        r = rd[i]
        cx = min(max(int(np.rint(xi)), 0), W - 1)
        cy = min(max(int(np.rint(yi)), 0), H - 1)
        it = 0
        grow = 2
        mass = peak = bg = valley = np.nan
        foreign = False
        while True:
            nx_ = nbx[i] - cx
            ny_ = nby[i] - cy
            res = _pass1(frame, cx, cy, r, sign[i], nx_, ny_, noise[i], nbr_r[i], wfrac, ff, fn,
                         du, dv, dval, ru, rv, rval, routl)
            dx, dy, m, pk, nout, frac, dip, omin, b, vl = res
            good = m > 0
            if good:
                xi = cx + dx
                yi = cy + dy
            mass = m
            peak = pk
            bg = b
            valley = vl
            spill = nout > 0 and (frac > 0.4 or dip < 0.5)
            spill = spill and r + 1.5 <= rmax[i] and grow > 0
            foreign = nout > 0 and (not spill) and omin <= r + 1.0
            it += 1
            kx = min(max(int(np.rint(xi)), 0), W - 1)
            ky = min(max(int(np.rint(yi)), 0), H - 1)
            moved = good and (kx != cx or ky != cy) and it < iterations
            if not (spill or moved):
                break
            if spill:
                r += 1.5
                grow -= 1
            cx = kx
            cy = ky
        out[i, 0] = xi
        out[i, 1] = yi
        out[i, 2] = mass
        out[i, 3] = peak
        out[i, 4] = 1.0 if foreign else 0.0
        out[i, 5] = bg
        out[i, 6] = valley
        out[i, 7] = r


def _ncc_kernel(frame, tz, tid, th, cx, cy, rr, maps, origin, shape):
    """Compiled windowed TM_CCOEFF_NORMED (as :func:`match_windows`) with zero-mean,
    unit-norm templates ``tz[tid]`` (S, S), each (2 th + 1)^2 at the centre of its array."""
    H, W = frame.shape
    n = cx.shape[0]
    c0 = tz.shape[1] // 2
    for i in range(n):
        h = th[i]
        r = rr[i]
        x0 = max(cx[i] - h - r, 0)
        y0 = max(cy[i] - h - r, 0)
        x1 = min(cx[i] + h + r + 1, W)
        y1 = min(cy[i] + h + r + 1, H)
        origin[i, 0] = x0 + h
        origin[i, 1] = y0 + h
        s = 2 * h + 1
        rows = y1 - y0 - 2 * h
        cols = x1 - x0 - 2 * h
        if rows <= 0 or cols <= 0:
            shape[i, 0] = 0
            shape[i, 1] = 0
            continue
        shape[i, 0] = rows
        shape[i, 1] = cols
        wh = y1 - y0
        ww = x1 - x0
        win = np.empty((wh, ww), np.float32)
        ii = np.zeros((wh + 1, ww + 1))
        i2 = np.zeros((wh + 1, ww + 1))
        for a in range(wh):
            run = 0.0
            run2 = 0.0
            for b in range(ww):
                val = np.float64(frame[y0 + a, x0 + b])
                win[a, b] = val
                run += val
                run2 += val * val
                ii[a + 1, b + 1] = ii[a, b + 1] + run
                i2[a + 1, b + 1] = i2[a, b + 1] + run2
        ti = tid[i]
        t0 = c0 - h
        tp = np.empty((s, s), np.float32)
        for p in range(s):
            for q in range(s):
                tp[p, q] = tz[ti, t0 + p, t0 + q]
        N = float(s * s)
        for a in range(rows):
            for b in range(cols):
                acc = np.float32(0.0)
                for p in range(s):
                    for q in range(s):
                        acc += win[a + p, b + q] * tp[p, q]
                s1 = ii[a + s, b + s] - ii[a, b + s] - ii[a + s, b] + ii[a, b]
                s2 = i2[a + s, b + s] - i2[a, b + s] - i2[a + s, b] + i2[a, b]
                var = s2 - s1 * s1 / N
                if var > 1e-6 * (s2 + 1.0):
                    maps[i, a, b] = acc / np.sqrt(var)
                else:
                    maps[i, a, b] = 0.0


def _score1(frame, tz, ti, h, x, y):
    """TM_CCOEFF_NORMED of template ``tz[ti]`` centred at pixel (x, y); -2 off the image."""
    H, W = frame.shape
    c0 = tz.shape[1] // 2
    x0 = x - h
    y0 = y - h
    s = 2 * h + 1
    if x0 < 0 or y0 < 0 or x0 + s > W or y0 + s > H:
        return -2.0
    t0 = c0 - h
    s1 = s2 = num = 0.0
    for p in range(s):
        for q in range(s):
            val = np.float64(frame[y0 + p, x0 + q])
            s1 += val
            s2 += val * val
            num += val * tz[ti, t0 + p, t0 + q]
    var = s2 - s1 * s1 / (s * s)
    return num / np.sqrt(var) if var > 1e-6 * (s2 + 1.0) else 0.0


def _score_kernel(frame, tz, tid, th, cx, cy, out):
    """TM_CCOEFF_NORMED of template ``tz[tid[i]]`` centred at pixel (cx, cy) (0 where it
    does not fit in the image or the window is flat)."""
    for i in range(cx.shape[0]):
        s = _score1(frame, tz, tid[i], th[i], cx[i], cy[i])
        out[i] = 0.0 if s == -2.0 else s


def _climb_kernel(frame, tz, tid, th, cx, cy, rr, out):
    """Hill-climb the correlation from the predicted pixel (cx, cy) within +/- rr px:
    the local maximum nearest the prediction, at a fraction of a full window's cost.
    ``out`` (n, 4): x, y, score, rim (1 where the climb reached the window's edge)."""
    for i in range(cx.shape[0]):
        h = th[i]
        ti = tid[i]
        x = cx[i]
        y = cy[i]
        best = _score1(frame, tz, ti, h, x, y)
        for _ in range(4 * rr[i] + 4):
            bx = x
            by = y
            bs = best
            for a in range(-1, 2):
                for b in range(-1, 2):
                    if a == 0 and b == 0:
                        continue
                    nx = x + b
                    ny = y + a
                    if abs(nx - cx[i]) > rr[i] or abs(ny - cy[i]) > rr[i]:
                        continue
                    sc = _score1(frame, tz, ti, h, nx, ny)
                    if sc > bs:
                        bs = sc
                        bx = nx
                        by = ny
            if bx == x and by == y:
                break
            x = bx
            y = by
            best = bs
        out[i, 0] = x
        out[i, 1] = y
        out[i, 2] = best
        out[i, 3] = 1.0 if (abs(x - cx[i]) == rr[i] or abs(y - cy[i]) == rr[i]) else 0.0


def _refine_all_kernel(frame, idx, XP, YP, jn, rd, rb, sign, noise, iterations, wfrac, ff, fn, X, Y, mass,
                       foreign, bgres, peak, valley, nbr_out):
    """The tracker's refinement of markers ``idx`` in one call: each marker's pixel split
    against its nearest matched neighbour (as :meth:`_Tracker._voronoi`) and its iterated
    centroid (as :func:`_refine_core`, the disk fixed), results written at ``idx``."""
    H, W = frame.shape
    sub = np.empty(idx.shape[0])
    for k in range(idx.shape[0]):
        sub[k] = rd[idx[k]]
    du, dv, dval, ru, rv, rval, routl = _buffers(sub)
    for k in range(idx.shape[0]):
        i = idx[k]
        j = jn[i]
        nxa = nya = np.nan
        rr = np.nan
        if j >= 0:
            rr = rd[j] + 0.5
            if not np.isnan(XP[j]):
                dn = np.hypot(XP[j] - XP[i], YP[j] - YP[i])
                if dn < rd[i] + 3.0 + rb[j] and dn >= 1.5:
                    nxa = XP[j]
                    nya = YP[j]
        nbr_out[i, 0] = nxa
        nbr_out[i, 1] = nya
        xi = XP[i]
        yi = YP[i]
        r = rd[i]
        cx = min(max(int(np.rint(xi)), 0), W - 1)
        cy = min(max(int(np.rint(yi)), 0), H - 1)
        it = 0
        while True:
            dx, dy, m, pk, nout, frac, dip, omin, b, vl = _pass1(
                frame, cx, cy, r, sign[i], nxa - cx, nya - cy, noise[i], rr, wfrac, ff, fn,
                du, dv, dval, ru, rv, rval, routl)
            good = m > 0
            if good:
                xi = cx + dx
                yi = cy + dy
            mass[i] = m
            peak[i] = pk
            bgres[i] = b
            valley[i] = vl
            foreign[i] = nout > 0 and omin <= r + 1.0
            it += 1
            kx = min(max(int(np.rint(xi)), 0), W - 1)
            ky = min(max(int(np.rint(yi)), 0), H - 1)
            if not (good and (kx != cx or ky != cy) and it < iterations):
                break
            cx = kx
            cy = ky
        X[i] = xi
        Y[i] = yi


def _pre_kernel(t, hx, ht, nh, sigma, lostflag, last_ok, last_score, stagger, h, rb, W, H, max_coast, every,
                search_radius, pred, gap, steady, inside, fits, r, F, wide, j2, d2, merged, crowded):
    """Compiled start of :meth:`_Tracker.step`: predictions (as :meth:`_Tracker.predict`),
    gaps, newly lost markers, window fits, nearest neighbours of the predictions, merged
    and crowded markers, the fast path and the search radii (in-place outputs)."""
    n = h.shape[0]
    tf = np.float64(t)
    for i in range(n):
        t0 = ht[i, 0]
        t1 = ht[i, 1]
        t2 = ht[i, 2]
        d = abs(t - t0)
        gap[i] = d
        order = nh[i]
        if d > 3:
            order = min(order, 2)
        if d > 8:
            order = 1
        a0 = np.float64(t0)
        a1 = np.float64(t1)
        a2 = np.float64(t2)
        if order == 3:
            c0 = (tf - a1) * (tf - a2) / ((a0 - a1) * (a0 - a2))
            c1 = (tf - a0) * (tf - a2) / ((a1 - a0) * (a1 - a2))
            c2 = (tf - a0) * (tf - a1) / ((a2 - a0) * (a2 - a1))
            pred[i, 0] = c0 * hx[i, 0, 0] + c1 * hx[i, 1, 0] + c2 * hx[i, 2, 0]
            pred[i, 1] = c0 * hx[i, 0, 1] + c1 * hx[i, 1, 1] + c2 * hx[i, 2, 1]
        elif order == 2:
            c0 = (tf - a1) / (a0 - a1)
            c1 = (tf - a0) / (a1 - a0)
            pred[i, 0] = c0 * hx[i, 0, 0] + c1 * hx[i, 1, 0]
            pred[i, 1] = c0 * hx[i, 0, 1] + c1 * hx[i, 1, 1]
        else:
            pred[i, 0] = hx[i, 0, 0]
            pred[i, 1] = hx[i, 0, 1]
        steady[i] = d == 1 and nh[i] == 3 and abs(t - last_ok[i]) == 1
        if not lostflag[i] and d > max_coast:
            lostflag[i] = True
        x = pred[i, 0]
        y = pred[i, 1]
        ins = (not lostflag[i]) and x >= -0.5 and x <= W - 0.5 and y >= -0.5 and y <= H - 0.5
        inside[i] = ins
        px = np.rint(x) if ins else 0.0
        py = np.rint(y) if ins else 0.0
        fits[i] = ins and px - h[i] >= 0 and py - h[i] >= 0 and px + h[i] <= W - 1 and py + h[i] <= H - 1
    _nearest_kernel(pred[:, 0], pred[:, 1], inside, j2, d2)
    for i in range(n):
        j = j2[i, 0]
        lim = rb[i] + rb[max(j, 0)]
        merged[i] = inside[i] and d2[i, 0] < lim + 1.0
        crowded[i] = d2[i, 0] < lim + 4.0
        F[i] = (fits[i] and nh[i] == 3 and gap[i] == 1 and sigma[i] < 0.35 and last_score[i] >= 0.9
                and not crowded[i] and stagger[i] != t % every)
        ri = np.ceil(2.0 + 3.0 * sigma[i] + (gap[i] - 1))
        ri = min(max(ri, 2.0), np.float64(search_radius))
        wide[i] = fits[i] and nh[i] == 1
        r[i] = search_radius if wide[i] else int(ri)


def _rules_kernel(fits, S, SEC, mass, mass0, mass_ref, score_ref, resid, sigma, gap, nh, foreign, bgres, peak,
                  peak0, XP, YP, prx, pry, inside, j2, rb, valley, lose, par, ST, RS, X, Y, codes):
    """Compiled status rules of :meth:`_Tracker.step` (the last rule that applies wins),
    then a conflict loser is put at its prediction and a lost point's position cleared.
    ``par``: min_score, lost_score, min_mass_ratio, max_mass_ratio, max_score_drop,
    ambiguity_margin, jump_px, bg residual, faded bg residual, faded, weak, merge valley,
    bridge; ``codes``: the reason codes of low_score, no_signal, merged, appearance,
    ambiguous, jump, foreign, background, conflict."""
    n = fits.shape[0]
    for i in range(n):
        if not fits[i]:
            continue
        sc = S[i]
        ms = mass[i]
        st = 0
        rs = 0
        if sc < par[0]:
            st, rs = 1, codes[0]
        if ms < par[2] * mass0[i]:
            st, rs = 1, codes[1]
        if np.isfinite(par[3]) and ms > par[3] * mass_ref[i]:
            st, rs = 1, codes[2]
        if np.isfinite(par[4]) and sc < score_ref[i] - par[4]:
            st, rs = 1, codes[3]
        if SEC[i] >= sc - par[5]:
            st, rs = 1, codes[4]
        lim = max(par[6], 4.0 * sigma[i] + 2.0 * (gap[i] - 1))
        if nh[i] >= 3 and resid[i] > lim:
            st, rs = 1, codes[5]
        if foreign[i]:
            st, rs = 1, codes[6]
        bg = bgres[i]
        faded = peak[i] < par[9] * peak0[i] or sc < par[10]
        if bg > par[7] or (faded and bg > par[8]):
            st, rs = 1, codes[7]
        # blobs touching a neighbour's (matched, or predicted if tracked last frame)
        touch = False
        xi = XP[i] if not np.isnan(XP[i]) else (prx[i] if inside[i] and gap[i] == 1 else np.nan)
        yi = YP[i] if not np.isnan(YP[i]) else (pry[i] if inside[i] and gap[i] == 1 else np.nan)
        for k in range(2):
            j = j2[i, k]
            if j < 0:
                continue
            xj = XP[j] if not np.isnan(XP[j]) else (prx[j] if inside[j] and gap[j] == 1 else np.nan)
            yj = YP[j] if not np.isnan(YP[j]) else (pry[j] if inside[j] and gap[j] == 1 else np.nan)
            if np.hypot(xj - xi, yj - yi) < rb[i] + rb[j] + 1.0:
                touch = True
        vl = valley[i]
        if (touch and not (vl < par[11])) or vl > par[12]:
            st, rs = 1, codes[2]
        if lose[i]:
            st, rs = 1, codes[8]
        if ((sc < par[1]) or not (ms > 0)) and not lose[i]:
            st, rs = 2, codes[0]
        ST[i] = st
        RS[i] = rs
        if lose[i]:
            X[i] = prx[i]
            Y[i] = pry[i]
        if st == 2:
            X[i] = np.nan
            Y[i] = np.nan


def _history_kernel(t, X, Y, S, ST, rel, resid, mass, hx, ht, nh, sigma, last_score, last_ok, mass_ref,
                    score_ref, last_upd, par, upd):
    """Compiled end of :meth:`_Tracker.step`: the motion model fed with the points ``rel``
    (history shift, count, residual RMS), the running values of the ok points, and which
    templates to update (``par``: update_score, refresh_below, update_every)."""
    for i in range(X.shape[0]):
        ok = ST[i] == 0
        if rel[i]:
            if nh[i] >= 2:
                e = resid[i]
                sigma[i] = np.sqrt(0.8 * sigma[i] * sigma[i] + 0.2 * e * e)
            hx[i, 2, 0] = hx[i, 1, 0]
            hx[i, 2, 1] = hx[i, 1, 1]
            hx[i, 1, 0] = hx[i, 0, 0]
            hx[i, 1, 1] = hx[i, 0, 1]
            hx[i, 0, 0] = X[i]
            hx[i, 0, 1] = Y[i]
            ht[i, 2] = ht[i, 1]
            ht[i, 1] = ht[i, 0]
            ht[i, 0] = t
            nh[i] = min(nh[i] + 1, 3)
        last_score[i] = S[i] if ok and not np.isnan(S[i]) else 0.0
        upd[i] = False
        if ok:
            last_ok[i] = t
            mass_ref[i] = 0.9 * mass_ref[i] + 0.1 * mass[i]
            score_ref[i] = 0.7 * score_ref[i] + 0.3 * S[i]
            upd[i] = S[i] >= par[0] and S[i] < par[1] and abs(t - last_upd[i]) >= par[2]


def _analyse_kernel(maps, shape, excl, oth, out):
    """Compiled twin of :func:`_analyse_maps`; ``oth`` (n, K, 2) cells to exclude (NaN
    none); ``out`` (n, 5) receives u, v, score, second, border."""
    n, m, _ = maps.shape
    for i in range(n):
        rows = shape[i, 0]
        cols = shape[i, 1]
        best = -np.inf
        bu = 0
        bv = 0
        for v in range(m):
            for u in range(m):
                if maps[i, v, u] > best:
                    best = maps[i, v, u]
                    bu = u
                    bv = v
        border = bu == 0 or bv == 0 or bu == cols - 1 or bv == rows - 1
        second = -2.0
        if m >= 3:
            ex2 = excl[i] * excl[i]
            lim = excl[i] + m
            for v in range(1, rows - 1):
                for u in range(1, cols - 1):
                    val = maps[i, v, u]
                    if val < second:
                        continue
                    if (u - bu) * (u - bu) + (v - bv) * (v - bv) <= ex2:
                        continue
                    is_max = True
                    for a in range(-1, 2):
                        for b in range(-1, 2):
                            if maps[i, v + a, u + b] > val:
                                is_max = False
                    if not is_max:
                        continue
                    skip = False
                    for k in range(oth.shape[1]):
                        ou = oth[i, k, 0]
                        ov = oth[i, k, 1]
                        if np.isnan(ou) or not (abs(ou - m / 2) < lim and abs(ov - m / 2) < lim):
                            continue
                        if (u - ou) * (u - ou) + (v - ov) * (v - ov) <= ex2:
                            skip = True
                    if not skip:
                        second = val
        out[i, 0] = bu
        out[i, 1] = bv
        out[i, 2] = best
        out[i, 3] = second
        out[i, 4] = 1.0 if border else 0.0


def _nearest_kernel(px, py, valid, j, d):
    """Compiled twin of :func:`_nearest_two` (indices and distances of the two nearest)."""
    n = px.shape[0]
    for i in range(n):
        b0 = b1 = np.inf
        k0 = k1 = -1
        if valid[i] and not (np.isnan(px[i]) or np.isnan(py[i])):
            for q in range(n):
                if q == i or not valid[q] or np.isnan(px[q]) or np.isnan(py[q]):
                    continue
                dx = px[i] - px[q]
                dy = py[i] - py[q]
                e = dx * dx + dy * dy
                if e < b0:
                    b1, k1 = b0, k0
                    b0, k0 = e, q
                elif e < b1:
                    b1, k1 = e, q
        j[i, 0] = k0
        j[i, 1] = k1
        d[i, 0] = np.sqrt(b0)
        d[i, 1] = np.sqrt(b1)


if _numba is not None:  # pragma: no cover - depends on the environment
    _analyse_kernel = _numba.njit(cache=True, nogil=True)(_analyse_kernel)
    _pre_kernel = _numba.njit(cache=True, nogil=True)(_pre_kernel)
    _rules_kernel = _numba.njit(cache=True, nogil=True)(_rules_kernel)
    _history_kernel = _numba.njit(cache=True, nogil=True)(_history_kernel)
    _score_kernel = _numba.njit(cache=True, nogil=True)(_score_kernel)
    _score1 = _numba.njit(cache=True, nogil=True)(_score1)
    _climb_kernel = _numba.njit(cache=True, nogil=True)(_climb_kernel)
    _refine_all_kernel = _numba.njit(cache=True, nogil=True)(_refine_all_kernel)
    _nearest_kernel = _numba.njit(cache=True, nogil=True)(_nearest_kernel)
    _solve_plane = _numba.njit(cache=True, nogil=True)(_solve_plane)
    _ring_plane = _numba.njit(cache=True, nogil=True)(_ring_plane)
    _disk_peak = _numba.njit(cache=True, nogil=True)(_disk_peak)
    _pass1 = _numba.njit(cache=True, nogil=True)(_pass1)
    _buffers = _numba.njit(cache=True, nogil=True)(_buffers)
    _refine_kernel = _numba.njit(cache=True, nogil=True)(_refine_kernel)
    _ncc_kernel = _numba.njit(cache=True, nogil=True, fastmath=True)(_ncc_kernel)


def _find_foreign(frame, ix, iy, rd, sign, peak):
    """Centre (absolute x, y; NaN where none) of a foreign blob next to each disk.

    The brightest pixel outside the disk and away from the patch border, if it stands
    above half the marker's peak over the patch's background (its lower quartile beyond
    the ring) and is a local maximum; its centre is the centroid of the 3 x 3 pixels
    around it above half its value.
    """
    n = len(ix)
    hc = int(math.ceil(float(rd.max()))) + 9
    g = _Grid.get(hc)
    P = _gather(frame, ix, iy, g.o) * sign[:, None].astype(np.float32)
    r = rd.astype(np.float32)[:, None]
    outside = g.d2[None, :] > (r + 2.0) ** 2
    bg = np.nanpercentile(np.where(outside, P, np.nan), 25, axis=1).astype(np.float32)
    S = P - bg[:, None]
    cand = (g.d2[None, :] > r * r) & (g.d2[None, :] <= (hc - 1.5) ** 2)
    Sc = np.where(cand, S, -np.inf)
    k = Sc.argmax(1)
    ar = np.arange(n)
    val = Sc[ar, k]
    side = 2 * hc + 1
    u = k % side
    v = k // side
    out = np.full((n, 2), np.nan)
    for q in np.flatnonzero(val > 0.5 * peak).tolist():
        img = S[q].reshape(side, side)
        w3 = img[v[q] - 1: v[q] + 2, u[q] - 1: u[q] + 2]
        if w3.shape != (3, 3) or w3.max() > img[v[q], u[q]]:
            continue  # not a local maximum
        w = np.maximum(w3 - 0.5 * val[q], 0.0)
        sw = float(w.sum())
        if not sw > 0:
            continue
        o = np.arange(-1, 2)
        out[q, 0] = ix[q] + (u[q] - hc) + float((w.sum(0) * o).sum()) / sw
        out[q, 1] = iy[q] + (v[q] - hc) + float((w.sum(1) * o).sum()) / sw
    return out


def _refine_core(frame, x, y, rd, sign, noise, nbr_xy, nbr_r, iterations, rmax, wfrac):
    """Iterated centroid passes (numpy); see :func:`_refine`. Returns x, y, mass, rd,
    peak, foreign, bgres, valley."""
    x = np.array(x, dtype=np.float64)
    y = np.array(y, dtype=np.float64)
    n = len(x)
    H, W = frame.shape
    rd = np.array(rd, dtype=np.float64)
    ix = np.clip(np.rint(x).astype(np.int64), 0, W - 1)
    iy = np.clip(np.rint(y).astype(np.int64), 0, H - 1)
    mass = np.full(n, np.nan)
    peak = np.full(n, np.nan)
    bgres = np.full(n, np.nan)
    valley = np.full(n, np.nan)
    foreign = np.zeros(n, bool)
    grow = np.full(n, 2)
    todo = np.arange(n)
    it = 0
    while True:
        jx, jy = ix[todo], iy[todo]
        nb = None
        if nbr_xy is not None:
            nb = (nbr_xy[todo] - np.column_stack([jx, jy])).astype(np.float32)
        r = _centroid_pass(frame, jx, jy, rd[todo], sign[todo], nb, noise[todo],
                           None if nbr_r is None else nbr_r[todo], wfrac)
        d, m = r["d"], r["mass"]
        good = m > 0
        nx = np.where(good, jx + d[:, 0], x[todo])
        ny = np.where(good, jy + d[:, 1], y[todo])
        x[todo], y[todo], mass[todo] = nx, ny, m
        peak[todo], bgres[todo], valley[todo] = r["peak"], r["bgres"], r["valley"]
        # own blob larger than the disk: ring outliers all around (not one-sided); the
        # disk grows, and if the ring is still not clean something else is there
        spill = (r["nout"] > 0) & ((r["frac"] > 0.4) | (r["dip"] < 0.5))
        spill &= (rd[todo] + 1.5 <= rmax[todo]) & (grow[todo] > 0)
        foreign[todo] = (r["nout"] > 0) & ~spill & (r["omin"] <= rd[todo] + 1.0)
        it += 1
        kx = np.clip(np.rint(nx).astype(np.int64), 0, W - 1)
        ky = np.clip(np.rint(ny).astype(np.int64), 0, H - 1)
        redo = spill | (good & ((kx != jx) | (ky != jy)) & (it < iterations))
        if not redo.any():
            break
        rd[todo[spill]] += 1.5
        grow[todo[spill]] -= 1
        todo = todo[redo]
        ix[todo], iy[todo] = kx[redo], ky[redo]
    return x, y, mass, rd, peak, foreign, bgres, valley


def _refine_core_fast(frame, x, y, rd, sign, noise, nbr_xy, nbr_r, iterations, rmax, wfrac):
    """:func:`_refine_core` by the compiled kernel."""
    n = len(x)
    out = np.empty((n, 8))
    if nbr_xy is None:
        nbx = nby = np.full(n, np.nan)
    else:
        nbx = np.ascontiguousarray(nbr_xy[:, 0], dtype=np.float64)
        nby = np.ascontiguousarray(nbr_xy[:, 1], dtype=np.float64)
    rr = np.full(n, np.nan) if nbr_r is None else np.ascontiguousarray(nbr_r, dtype=np.float64)
    _refine_kernel(frame, np.asarray(x, np.float64), np.asarray(y, np.float64), np.asarray(rd, np.float64),
                   np.asarray(sign, np.float64), np.asarray(noise, np.float64), nbx, nby, rr, int(iterations),
                   np.asarray(rmax, np.float64), float(wfrac), FOREIGN_FRACTION, FOREIGN_NOISE, out)
    return out[:, 0], out[:, 1], out[:, 2], out[:, 7], out[:, 3], out[:, 4] > 0, out[:, 5], out[:, 6]


def _refine(frame, x, y, rd, sign, noise, nbr_xy=None, iterations=2, rmax=None, nbr_r=None,
            wfrac=WEIGHT_FRACTION, explain=None):
    """Iterated background-subtracted centroid around estimates (x, y).

    The disk is centred on the pixel nearest the estimate; a further pass is made for the
    points whose nearest pixel changed and for those whose own blob spills into the
    background ring all around (the disk then grows by 1.5 px, twice at most, up to
    ``rmax``). Then, for the points (``explain``, (n,) bool: points whose identity is not
    in doubt) with a foreign blob next to them whose centre can be found
    (:func:`_find_foreign`), that blob takes the place of the nearest neighbour in the
    pixel split (unless a known neighbour is nearer) for one more pass, and the point
    stays ``foreign`` unless a dark gap (``_MERGE_VALLEY``) separates the two blobs.

    Returns x, y, mass and a dict of per-point diagnostics: ``rd`` (disk radius used),
    ``peak``, ``bgres``, ``valley`` and ``foreign`` (something bright that is not this
    blob lies in the ring, touching the disk: the centroid may be pulled).
    """
    n = len(x)
    rmax = np.asarray(rd, np.float64) if rmax is None else np.broadcast_to(np.asarray(rmax, np.float64), (n,))
    core = _refine_core if _numba is None else _refine_core_fast
    x, y, mass, rd, peak, foreign, bgres, valley = core(frame, x, y, rd, sign, noise, nbr_xy, nbr_r, iterations,
                                                        rmax, wfrac)
    if explain is not None:
        rows = np.flatnonzero(foreign & (mass > 0) & np.asarray(explain, bool))
        if rows.size:
            H, W = frame.shape
            jx = np.clip(np.rint(x[rows]).astype(np.int64), 0, W - 1)
            jy = np.clip(np.rint(y[rows]).astype(np.int64), 0, H - 1)
            f = _find_foreign(frame, jx, jy, rd[rows], np.asarray(sign, np.float64)[rows], peak[rows])
            use = np.isfinite(f[:, 0])
            if nbr_xy is not None:
                dk = np.hypot(nbr_xy[rows, 0] - jx, nbr_xy[rows, 1] - jy)
                use &= ~(dk <= np.hypot(f[:, 0] - jx, f[:, 1] - jy))
            rows, f = rows[use], f[use]
            if rows.size:
                r2 = core(frame, x[rows], y[rows], rd[rows], np.asarray(sign)[rows], np.asarray(noise)[rows], f,
                          rd[rows], 1, rd[rows], wfrac)
                x[rows], y[rows], mass[rows], rd[rows], peak[rows] = r2[0], r2[1], r2[2], r2[3], r2[4]
                bgres[rows], valley[rows] = r2[6], r2[7]
                # a foreign blob split off is only harmless when a dark gap separates them
                foreign[rows] = r2[5] | ~(r2[7] < _MERGE_VALLEY)
    return x, y, mass, dict(rd=rd, peak=peak, foreign=foreign, bgres=bgres, valley=valley)


def refine_centroids(frame, xy, radius, *, polarity=1, neighbours=None, iterations=2,
                     threshold=WEIGHT_FRACTION):
    """Refine marker centres to sub-pixel precision (the fast sub-pixel refiner).

    Parameters
    ----------
    frame : (H, W) ndarray
        Raw image (uint8, uint16 or float).
    xy : (N, 2) array_like of float
        Starting positions (x, y) in px, origin at the centre of the top-left pixel; within
        about half a pixel of the marker centre.
    radius : float or (N,) array_like
        Radius of the integration disk in px: the blob's half long axis plus ~2-3 px, so
        that the disk contains the whole anti-aliased (and blurred) blob.
    polarity : 1 or -1, or (N,) array_like
        1 for bright markers on a darker background, -1 for dark markers.
    neighbours : (N, 2) array_like, optional
        Position of each marker's nearest other marker (NaN for none); pixels nearer to it
        are ignored (Voronoi split), so a close neighbour does not pull the centroid.
    iterations : int
        Re-centre the disk on the pixel nearest the estimate and repeat (default 2).
    threshold : float
        Each pixel is weighted by its background-subtracted value minus ``threshold``
        times the blob's peak (0: the plain background-subtracted centroid). The default
        (0.2) makes the centre insensitive to what the disk holds besides the blob (a
        membrane edge, glare, the tail of another blob) at the cost of a slight pixel
        locking on blobs with hard edges (< 0.03 px on an unblurred disc, < 0.01 px with
        the optics' blur).

    Returns
    -------
    xy : (N, 2) ndarray
        Refined centres; the start position where the blob has no positive mass.
    mass : (N,) ndarray
        Integrated background-subtracted brightness in the disk.

    Notes
    -----
    The background is a plane fitted to a 2 px ring just outside the disk (refitted
    without the ring pixels that stand far above it). With the disk centred on an integer
    pixel and containing the whole blob, the centroid of the background-subtracted,
    anti-aliased blob (``threshold=0``) is unbiased up to an edge term of order
    ``0.1 / area`` px; there is no pixel locking, unlike parabolic peak fits or the
    hard-masked ``cntrd`` of Crocker & Grier with a mask smaller than the blob. A blob
    that spills into the ring all around (``radius`` too small) gets a disk 1.5 px
    larger, at most twice.

    Examples
    --------
    >>> img = np.zeros((21, 23), np.float32)
    >>> img[9:12, 12:15] = 1.0  # a 3x3 square centred at (13, 10)
    >>> xy, mass = refine_centroids(img, [[12.0, 11.0]], 3.0)
    >>> np.round(xy, 6).tolist(), float(mass[0])
    ([[13.0, 10.0]], 9.0)
    """
    frame = np.asarray(frame)
    if frame.ndim != 2:
        raise ValueError(f"frame must be a 2D image, got shape {frame.shape}")
    pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    n = len(pts)
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,)).copy()
    if np.any(~np.isfinite(radius)) or np.any(radius <= 0):
        raise ValueError(f"radius must be positive, got {radius}")
    sign = np.broadcast_to(np.asarray(polarity, dtype=np.float32), (n,)).copy()
    nbr = None if neighbours is None else np.asarray(neighbours, dtype=np.float64).reshape(-1, 2)
    threshold = float(threshold)
    if not 0.0 <= threshold < 1.0:
        raise ValueError(f"threshold must be in [0, 1), got {threshold}")
    x, y, mass, _ = _refine(frame, pts[:, 0], pts[:, 1], radius, sign, np.zeros(n), nbr, iterations,
                            wfrac=threshold)
    return np.column_stack([x, y]), mass


# --------------------------------------------------------------------------- matcher
def match_windows(frame, templates, centres, radii):
    """Correlate each template in a small window around its predicted centre.

    The fast windowed matcher: one ``cv2.matchTemplate`` (``TM_CCOEFF_NORMED``) per
    marker on a ``(2 h + 2 r + 1)``-pixel window; maps are returned padded in one array
    so that peak finding is vectorised across markers.

    Parameters
    ----------
    frame : (H, W) ndarray of uint8 or float32
        Image (other dtypes are converted to float32 window by window).
    templates : list of (2h+1, 2h+1) ndarrays
        One odd-sized template per marker, its centre pixel on the marker centre; uint8
        for uint8 frames, float32 otherwise.
    centres : (N, 2) array_like of int
        Predicted centre pixel (x, y) of each marker.
    radii : (N,) array_like of int
        Search radius in px (the window holds the centre +/- radius).

    Returns
    -------
    maps : (N, M, M) ndarray of float32
        Correlation maps, ``M = 2 max(radii) + 1``, padded with -2; ``maps[i, v, u]`` is
        the score of centring marker i at pixel ``(origin[i, 0] + u, origin[i, 1] + v)``.
    origin : (N, 2) ndarray of int64
        Pixel (x, y) of each map's cell (0, 0).
    shape : (N, 2) ndarray of int64
        Valid (rows, cols) of each map (smaller where the window is clipped by the image
        edge; 0 where the template does not fit).
    """
    centres = np.asarray(centres, dtype=np.int64).reshape(-1, 2)
    radii = np.asarray(radii, dtype=np.int64).reshape(-1)
    n = len(centres)
    m = 2 * int(radii.max()) + 1 if n else 1
    maps = np.full((n, m, m), -2.0, np.float32)
    origin = np.zeros((n, 2), np.int64)
    shape = np.zeros((n, 2), np.int64)
    H, W = frame.shape
    conv = frame.dtype != np.uint8 and frame.dtype != np.float32
    method = cv2.TM_CCOEFF_NORMED
    mt = cv2.matchTemplate
    cx_l = centres[:, 0].tolist()
    cy_l = centres[:, 1].tolist()
    r_l = radii.tolist()
    for i in range(n):
        tpl = templates[i]
        h = tpl.shape[0] // 2
        r = r_l[i]
        cx, cy = cx_l[i], cy_l[i]
        x0 = cx - h - r
        y0 = cy - h - r
        x1 = cx + h + r + 1
        y1 = cy + h + r + 1
        if x0 < 0:
            x0 = 0
        if y0 < 0:
            y0 = 0
        if x1 > W:
            x1 = W
        if y1 > H:
            y1 = H
        origin[i, 0] = x0 + h
        origin[i, 1] = y0 + h
        if x1 - x0 <= 2 * h or y1 - y0 <= 2 * h:
            continue
        win = frame[y0:y1, x0:x1]
        if conv:
            win = win.astype(np.float32)
        res = mt(win, tpl, method)
        rh, rw = res.shape
        maps[i, :rh, :rw] = res
        shape[i, 0] = rh
        shape[i, 1] = rw
    return maps, origin, shape


# --------------------------------------------------------------------------- peaks
_K3 = np.ones((3, 3), np.uint8)


def _analyse_maps(maps, shape, excl, others=()):
    """Best peak, runner-up local maximum and border test for padded correlation maps.

    others : sequence of (n, 2) float arrays of map cells (u, v) to exclude from the
        runner-up search (other markers' expected positions), NaN for none.
    """
    n, m, _ = maps.shape
    if _numba is not None:
        oth = np.full((n, max(len(others), 1), 2), np.nan)
        for q, o in enumerate(others):
            oth[:, q] = o
        out = np.empty((n, 5))
        _analyse_kernel(maps, shape, np.asarray(excl, np.float64), oth, out)
        return out[:, 0].astype(np.int64), out[:, 1].astype(np.int64), out[:, 2], out[:, 3], out[:, 4] > 0
    flat = maps.reshape(n, -1)
    k = flat.argmax(1)
    score = flat[np.arange(n), k].astype(np.float64)
    v = k // m
    u = k - v * m
    rows = shape[:, 0]
    cols = shape[:, 1]
    border = (u == 0) | (v == 0) | (u == cols - 1) | (v == rows - 1)
    if m < 3:
        return u, v, score, np.full(n, -2.0), border
    pad = np.full((n, m + 1, m), -2.0, np.float32)
    pad[:, :m] = maps
    dil = cv2.dilate(pad.reshape(-1, m), _K3).reshape(n, m + 1, m)[:, :m]
    g = _GRID[:m]
    GU = g[None, None, :]
    GV = g[None, :, None]
    ex2 = (excl * excl)[:, None, None]
    # interior local maxima away from the best peak
    cand = maps >= dil
    cand[:, 0, :] = False
    cand[:, :, 0] = False
    if (rows < m).any() or (cols < m).any():
        cand &= (GU <= (cols - 2)[:, None, None]) & (GV <= (rows - 2)[:, None, None])
    else:
        cand[:, m - 1, :] = False
        cand[:, :, m - 1] = False
    du = GU - u[:, None, None]
    dv = GV - v[:, None, None]
    cand &= (du * du + dv * dv) > ex2
    for o in others:
        lim = excl + m
        use = np.isfinite(o[:, 0]) & (np.abs(o[:, 0] - m / 2) < lim) & (np.abs(o[:, 1] - m / 2) < lim)
        if not use.any():
            continue
        ui = np.flatnonzero(use)
        ou = o[ui, 0][:, None, None]
        ov = o[ui, 1][:, None, None]
        near = ((GU - ou) ** 2 + (GV - ov) ** 2) <= ex2[ui]
        cand[ui] &= ~near
    second = np.where(cand, maps, -2.0).reshape(n, -1).max(1).astype(np.float64)
    return u, v, score, second, border


_GRID = np.arange(256)


def _nearest_two(px, py, valid):
    """Indices of the two nearest other valid points (-1 for none) and their distances."""
    n = len(px)
    if n < 2:
        return np.full((n, 2), -1), np.full((n, 2), np.inf), None
    if _numba is not None:
        j = np.empty((n, 2), np.int64)
        d = np.empty((n, 2))
        _nearest_kernel(np.asarray(px, np.float64), np.asarray(py, np.float64), np.asarray(valid, np.bool_), j, d)
        return j, d, None
    ok = valid & np.isfinite(px) & np.isfinite(py)
    x = np.where(ok, px, 0.0)
    y = np.where(ok, py, 0.0)
    dx = x[:, None] - x
    dy = y[:, None] - y
    d2 = dx * dx + dy * dy
    bad = ~(ok[:, None] & ok)
    bad.flat[:: n + 1] = True
    d2[bad] = np.inf
    ar = np.arange(n)
    j0 = d2.argmin(1)
    d0 = d2[ar, j0]
    saved = d0.copy()
    d2[ar, j0] = np.inf
    j1 = d2.argmin(1)
    d1 = d2[ar, j1]
    d2[ar, j0] = saved
    j = np.column_stack([np.where(np.isfinite(d0), j0, -1), np.where(np.isfinite(d1), j1, -1)])
    return j, np.sqrt(np.column_stack([d0, d1])), d2


def _fit_affine(src, dst):
    """Least-squares 2D affine (or translation with < 3 points) mapping src -> dst."""
    n = len(src)
    if n == 0:
        return None
    if n < 3:
        t = np.mean(dst - src, axis=0)
        return np.array([[1.0, 0.0, t[0]], [0.0, 1.0, t[1]]])
    A = np.column_stack([src, np.ones(n)])
    M, _, rank, _ = np.linalg.lstsq(A, dst, rcond=None)
    if rank < 3:
        t = np.mean(dst - src, axis=0)
        return np.array([[1.0, 0.0, t[0]], [0.0, 1.0, t[1]]])
    return M.T


def _apply_affine(M, p):
    return p @ M[:, :2].T + M[:, 2]


def _robust_affine(src, dst, iters=3, tol=2.0, quality=False):
    """Affine src -> dst with outlier rejection; optionally also the inliers' RMS residual."""
    keep = np.ones(len(src), bool)
    M = None
    for _ in range(iters):
        if keep.sum() == 0:
            break
        M = _fit_affine(src[keep], dst[keep])
        res = np.linalg.norm(_apply_affine(M, src) - dst, axis=1)
        new = res < max(tol, 3.0 * np.median(res[keep]) if keep.any() else tol)
        if new.sum() < min(3, len(src)) or np.array_equal(new, keep):
            break
        keep = new
    if not quality:
        return M
    if M is None:
        return None, np.inf, 0
    res = np.linalg.norm(_apply_affine(M, src[keep]) - dst[keep], axis=1)
    rms = float(np.sqrt(np.mean(res**2))) if keep.sum() > 3 else (0.0 if keep.sum() == 3 else np.inf)
    return M, rms, int(keep.sum())


def _neighbour_prediction(p0, prev, now, min_m=2):
    """Where a marker at ``p0`` moved to, from neighbours that moved from ``prev`` to ``now``.

    ``prev``, ``now`` : (m, 2) positions of up to six nearest neighbours, nearest first.
    A robust affine map when four or more of them agree with one (RMS <= 1.5 px), else
    the mean displacement of the largest group that moved alike (within 2 px + 10 %: all
    of them when there are two or three, at least three otherwise; a single neighbour's
    displacement when ``min_m`` is 1). Returns the predicted position and its tolerance
    (px), or None when the neighbours do not move together.
    """
    m = len(prev)
    if m >= 4:
        M, rms, nin = _robust_affine(prev, now, quality=True)
        if M is not None and nin >= 4 and rms <= 1.5:
            return _apply_affine(M, p0[None, :])[0], 2.5
    if m < max(min_m, 1):
        return None
    D = now - prev
    tol = 2.0 + 0.1 * np.hypot(D[:, 0], D[:, 1])
    dd = np.hypot(D[:, None, 0] - D[None, :, 0], D[:, None, 1] - D[None, :, 1])
    alike = dd <= tol[:, None]
    j = int(np.argmax(alike.sum(1)))
    if alike[j].sum() < min(3, m):
        return None
    dm = D[alike[j]].mean(0)
    return p0 + dm, 2.0 + 0.1 * math.hypot(*dm)


# --------------------------------------------------------------------------- tracker
_PARAM_DEFAULTS = dict(
    search_radius=20,
    min_score=0.6,
    lost_score=0.3,
    ambiguity_margin=0.1,
    update_score=0.88,
    refresh_below=0.93,
    update_rate=0.5,
    original_weight=0.3,
    max_coast=6,
    reacquire_radius=6,
    reacquire_score=0.8,
    min_mass_ratio=0.25,
    max_mass_ratio=np.inf,
    jump_px=3.0,
    max_score_drop=np.inf,
    polarity="auto",
    fb_tolerance=0.5,
    search_every=4,
    update_every=4,
)


class _Results:
    """Preallocated (T, N) result arrays of one pass."""

    names = ("x", "y", "score", "xpix", "ypix")

    def __init__(self, T, N):
        for k in self.names:
            setattr(self, k, np.full((T, N), np.nan))
        self.status = np.full((T, N), LOST, np.int8)
        self.reason = np.zeros((T, N), np.int8)

    def arrays(self, prefix):
        out = {prefix + k: getattr(self, k) for k in self.names}
        out[prefix + "status"] = self.status
        out[prefix + "reason"] = self.reason
        return out

    def load(self, d, prefix):
        for k in self.names + ("status", "reason"):
            getattr(self, k)[...] = d[prefix + k]


class _Tracker:
    """State of one tracking pass; :meth:`step` processes one frame."""

    _STATE = ("hist_x", "hist_t", "nh", "sigma", "lostflag", "last_upd", "h", "rb", "sign", "mass0",
              "pos", "last_score", "stagger", "ref_pos", "mass_ref", "score_ref", "rd", "noise", "peak0", "last_ok")

    def __init__(self, p, is_u8, shape):
        self.p = p
        self.is_u8 = is_u8
        self.H, self.W = shape

    # ------------------------------------------------------------ set-up
    @classmethod
    def from_picks(cls, frame, xy, half, p, is_u8, ids):
        self = cls(p, is_u8, frame.shape)
        H, W = frame.shape
        n = len(xy)
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
        f = frame.astype(np.float32)
        sign = np.ones(n, np.float32)
        rb = np.zeros(n)
        nz = np.zeros(n)
        cx = np.zeros(n)
        cy = np.zeros(n)
        from scipy import ndimage

        for i in range(n):
            g = int(half[i]) + 4 if half[i] > 0 else 12
            ix, iy = int(round(xy[i, 0])), int(round(xy[i, 1]))
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
            if p.polarity == "auto":
                s = 1.0 if core.mean() >= bg else -1.0
            else:
                s = float(p.polarity)
            sig = s * (patch - plane)
            near = sig[max(ly - 2, 0): ly + 3, max(lx - 2, 0): lx + 3]
            peak = float(near.max())
            if not peak > max(4.0 * noise, 1e-3 * (abs(bg) + 1)):
                raise ValueError(
                    f"pick of point {ids[i]} at ({xy[i, 0]:g}, {xy[i, 1]:g}) is not on a marker: no blob "
                    f"stands out of the background there (contrast {peak:.3g}, noise {noise:.3g}); "
                    "click the marker centre"
                )
            ya, xa = max(ly - 2, 0), max(lx - 2, 0)
            kk = int(np.argmax(near))
            py_, px_ = ya + kk // near.shape[1], xa + kk % near.shape[1]
            lab, _ = ndimage.label(sig > 0.5 * peak)
            comp = lab == lab[py_, px_]
            area = float(comp.sum())
            r = math.sqrt(area / math.pi)
            if half[i] > 0:
                r = min(r, float(half[i]))
            w = np.where(comp, sig, 0.0)
            cx[i] = float((w * xx).sum() / w.sum())
            cy[i] = float((w * yy).sum() / w.sum())
            rb[i] = max(r, 1.0)
            nz[i] = noise
            sign[i] = s
        self.sign = sign
        self.sign64 = sign.astype(np.float64)
        self.rb = rb
        self.noise = nz
        self.rd = np.minimum(rb + _RD_MARGIN, _RD_MAX)
        nbr = self._nearest_positions(cx, cy, np.ones(n, bool))
        x, y, mass, info = _refine(frame, cx, cy, self.rd, sign, nz, nbr, iterations=3, rmax=self._rmax())
        # a click is within ~0.7 px of a marker's centre: a refinement that moved further
        # was pulled by something (glare, the membrane's edge, an unpicked neighbour), as
        # is one that saw a foreign blob or a rough background, and the click is the
        # better centre for the template and the motion model
        self.pick_moved = ((np.hypot(x - xy[:, 0], y - xy[:, 1]) > 1.5) | info["foreign"]
                           | (info["bgres"] > _BG_RESIDUAL))
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
        self.sigma = np.ones(n)
        self.lostflag = np.zeros(n, bool)
        self.last_upd = np.zeros(n, np.int64)
        self.last_ok = np.zeros(n, np.int64)
        self.pos = np.column_stack([x, y])
        self.ref_pos = self.pos.copy()
        self._set_local()
        return self

    def _set_local(self):
        """Radius (px) of a marker's neighbourhood: four typical neighbour spacings."""
        _, d, _ = _nearest_two(self.ref_pos[:, 0], self.ref_pos[:, 1], np.ones(len(self.ref_pos), bool))
        self._spacing = np.where(np.isfinite(d[:, 0]), d[:, 0], np.inf)
        d0 = d[:, 0][np.isfinite(d[:, 0])]
        self.local = max(40.0, 4.0 * float(np.median(d0))) if d0.size else 40.0

    def _cut(self, frame, x, y, h):
        """Template of size 2h+1 centred on sub-pixel (x, y), float32."""
        s = 2 * int(h) + 1
        ix, iy = int(round(x)), int(round(y))
        g = int(h) + 2
        y0, x0 = max(iy - g, 0), max(ix - g, 0)
        crop = np.ascontiguousarray(frame[y0: iy + g + 1, x0: ix + g + 1], dtype=np.float32)
        return cv2.getRectSubPix(crop, (s, s), (float(x - x0), float(y - y0)))

    def _as_match(self, t):
        if self.is_u8:
            return np.clip(np.rint(t), 0, 255).astype(np.uint8)
        return np.ascontiguousarray(t, dtype=np.float32)

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

    # ------------------------------------------------------------ prediction
    def predict(self, t):
        """Quadratic/linear/constant extrapolation through the reliable history to frame t."""
        hx, ht, nh = self.hist_x, self.hist_t, self.nh
        t0, t1, t2 = ht[:, 0], ht[:, 1], ht[:, 2]
        d = np.abs(t - t0)
        if np.all((nh == 3) & (d == 1) & (np.abs(t0 - t1) == 1) & (np.abs(t1 - t2) == 1)):
            return 3.0 * hx[:, 0] - 3.0 * hx[:, 1] + hx[:, 2]
        # with long gaps a quadratic explodes: fall back to linear, then constant
        order = np.where(d > 3, np.minimum(nh, 2), nh)
        order = np.where(d > 8, 1, order)
        tf = float(t)
        a0, a1, a2 = t0.astype(float), t1.astype(float), t2.astype(float)
        with np.errstate(divide="ignore", invalid="ignore"):
            q0 = (tf - a1) * (tf - a2) / ((a0 - a1) * (a0 - a2))
            q1 = (tf - a0) * (tf - a2) / ((a1 - a0) * (a1 - a2))
            q2 = (tf - a0) * (tf - a1) / ((a2 - a0) * (a2 - a1))
            l0 = (tf - a1) / (a0 - a1)
            l1 = (tf - a0) / (a1 - a0)
        c0 = np.where(order == 3, q0, np.where(order == 2, l0, 1.0))
        c1 = np.where(order == 3, q1, np.where(order == 2, l1, 0.0))
        c2 = np.where(order == 3, q2, 0.0)
        h1 = np.where(order[:, None] >= 2, hx[:, 1], 0.0)
        h2 = np.where(order[:, None] >= 3, hx[:, 2], 0.0)
        return c0[:, None] * hx[:, 0] + c1[:, None] * h1 + c2[:, None] * h2

    # ------------------------------------------------------------ one frame
    def step(self, frame, t, res, direction=1):
        """Track all markers into frame ``t`` and write row ``t`` of ``res``."""
        p = self.p
        H, W = self.H, self.W
        n = len(self.h)
        h = self.h
        if _numba is not None:
            pred, gap, steady = np.empty((n, 2)), np.empty(n, np.int64), np.empty(n, np.bool_)
            inside, fits, F, wide = (np.empty(n, np.bool_) for _ in range(4))
            merged, crowded = np.empty(n, np.bool_), np.empty(n, np.bool_)
            r = np.empty(n, np.int64)
            j2, d2 = np.empty((n, 2), np.int64), np.empty((n, 2))
            _pre_kernel(t, self.hist_x, self.hist_t, self.nh, self.sigma, self.lostflag, self.last_ok,
                        self.last_score, self.stagger, h, self.rb, W, H, p.max_coast, p.search_every,
                        p.search_radius, pred, gap, steady, inside, fits, r, F, wide, j2, d2, merged, crowded)
            prx, pry = pred[:, 0], pred[:, 1]
            px = np.rint(prx)
            py = np.rint(pry)
            track = ~self.lostflag
        else:
            pred = self.predict(t)
            gap = np.abs(t - self.hist_t[:, 0])
            steady = (gap == 1) & (self.nh == 3) & (np.abs(t - self.last_ok) == 1)
            newly = ~self.lostflag & (gap > p.max_coast)
            if newly.any():
                self.lostflag |= newly
            track = ~self.lostflag
            prx, pry = pred[:, 0], pred[:, 1]
            inside = track & (prx >= -0.5) & (prx <= W - 0.5) & (pry >= -0.5) & (pry <= H - 0.5)
            px = np.rint(prx)
            py = np.rint(pry)
            fits = inside & (px - h >= 0) & (py - h >= 0) & (px + h <= W - 1) & (py + h <= H - 1)
            # neighbours, from one distance matrix of the predictions
            j2, d2 = self._neighbours(prx, pry, inside)
            rb = self.rb
            jn0 = np.maximum(j2[:, 0], 0)
            merged = (d2[:, 0] < rb + rb[jn0] + 1.0) & inside
            crowded = d2[:, 0] < rb + rb[jn0] + 4.0
            # fast path: a marker moving predictably, alone, confidently matched last frame
            # is refined at its prediction and verified, its NCC search skipped this frame
            F = (fits & (self.nh == 3) & (gap == 1) & (self.sigma < 0.35) & (self.last_score >= 0.9)
                 & ~crowded & (self.stagger != t % p.search_every))
            r = np.clip(np.ceil(2.0 + 3.0 * self.sigma + (gap - 1)), 2, p.search_radius).astype(np.int64)
            wide = fits & (self.nh == 1)
            r[wide] = p.search_radius
        edge = inside & ~fits
        self._gap = gap
        self._pred = pred
        self._steady = steady
        self._j2 = j2
        self._merged = merged
        jn = j2[:, 0]

        X = np.full(n, np.nan)
        Y = np.full(n, np.nan)
        S = np.full(n, np.nan)
        SEC = np.full(n, -2.0)
        XP = np.full(n, np.nan)
        YP = np.full(n, np.nan)
        ST = np.full(n, LOST, np.int8)
        RS = np.zeros(n, np.int8)
        RS[track & ~inside] = _R["out_of_frame"]
        RS[self.lostflag] = _R["lost_track"]
        lose = np.zeros(n, bool)

        sidx = np.flatnonzero(fits & ~F)
        if sidx.size:
            self._search(frame, sidx, pred, px, py, r, wide, j2, XP, YP, S, SEC)
            lose = self._conflicts(sidx, XP, YP, prx, pry, merged, jn)
            XP[lose] = np.nan
            YP[lose] = np.nan
        fidx = np.flatnonzero(F)
        XP[fidx] = px[fidx]
        YP[fidx] = py[fidx]
        eidx = np.flatnonzero(edge)
        XP[eidx] = px[eidx]
        YP[eidx] = py[eidx]
        # sub-pixel refinement of everything that has a pixel-level position, jointly
        ridx = np.flatnonzero(np.isfinite(XP))
        mass = np.full(n, np.nan)
        self._info = info = dict(foreign=np.zeros(n, bool), rd=self.rd.copy(), bgres=np.zeros(n),
                                 peak=np.full(n, np.nan), valley=np.full(n, np.nan))
        if ridx.size:
            if _numba is not None:
                nb = self._refine_all(frame, ridx, XP, YP, jn, X, Y, mass)
            else:
                nb = self._voronoi(XP, YP, prx, pry, jn, inside)
                X[ridx], Y[ridx], mass[ridx] = self._refine_at(frame, ridx, XP, YP, nb)
        for i in (eidx.tolist() if edge.any() else ()):
            XP[i] = YP[i] = np.nan  # no correlation match for edge markers
        if fidx.size:
            # verify: NCC at the refined pixel, small residual, blob still there
            S[fidx] = self._score_at(frame, fidx, np.rint(X[fidx]), np.rint(Y[fidx]))
            XP[fidx] = np.rint(X[fidx])
            YP[fidx] = np.rint(Y[fidx])
            resf = np.hypot(X[fidx] - prx[fidx], Y[fidx] - pry[fidx])
            bad = ~((S[fidx] >= 0.85) & (resf < np.maximum(1.0, 4.0 * self.sigma[fidx]))
                    & (mass[fidx] > p.min_mass_ratio * self.mass0[fidx]))
            if bad.any():
                vidx = fidx[bad]
                self._search(frame, vidx, pred, px, py, r, wide, j2, XP, YP, S, SEC)
                sidx = np.concatenate([sidx, vidx])
                lose2 = self._conflicts(sidx, XP, YP, prx, pry, merged, jn)
                XP[lose2 & ~lose] = np.nan
                YP[lose2 & ~lose] = np.nan
                lose = lose2
                # refine again the re-searched markers and those whose neighbour moved
                nb2 = self._voronoi(XP, YP, prx, pry, jn, inside)
                changed = (np.isfinite(nb2[:, 0]) != np.isfinite(nb[:, 0])) | (
                    np.hypot(nb2[:, 0] - nb[:, 0], nb2[:, 1] - nb[:, 1]) > 1.5)
                changed[vidx] = True
                redo = np.flatnonzero(changed & np.isfinite(XP))
                if redo.size:
                    X[redo], Y[redo], mass[redo] = self._refine_at(frame, redo, XP, YP, nb2)
        self._mass = mass
        # status
        midx = np.flatnonzero(fits)
        resid = np.hypot(X - prx, Y - pry)
        if midx.size and _numba is not None:
            par = np.array([p.min_score, p.lost_score, p.min_mass_ratio, p.max_mass_ratio, p.max_score_drop,
                            p.ambiguity_margin, p.jump_px, _BG_RESIDUAL, _BG_RESIDUAL_FADED, _FADED, _WEAK,
                            _MERGE_VALLEY, _BRIDGE])
            _rules_kernel(fits, S, SEC, mass, self.mass0, self.mass_ref, self.score_ref, resid, self.sigma, gap,
                          self.nh, info["foreign"], info["bgres"], info["peak"], self.peak0, XP, YP, prx, pry,
                          inside, j2, self.rb, info["valley"], lose, par, ST, RS, X, Y, _RULE_CODES)
            jmp = np.flatnonzero(RS == _R["jump"])
            chk = np.flatnonzero((ST == OK) & fits & ((np.abs(t - self.last_ok) > 1) | (self.nh < 3)))
            if jmp.size or chk.size:
                self._vouch(jmp, chk, X, Y, S, SEC, ST, RS, resid, res, t)
        elif midx.size:
            sc = S[midx]
            ms = mass[midx]
            res_ = resid[midx]
            lim = np.maximum(p.jump_px, 4.0 * self.sigma[midx] + 2.0 * (gap[midx] - 1))
            lo = lose[midx]
            st = np.zeros(midx.size, np.int8)
            rs = np.zeros(midx.size, np.int8)
            rules = (
                (sc < p.min_score, FLAGGED, "low_score"),
                (ms < p.min_mass_ratio * self.mass0[midx], FLAGGED, "no_signal"),
                (np.isfinite(p.max_mass_ratio) and ms > p.max_mass_ratio * self.mass_ref[midx], FLAGGED,
                 "merged"),
                (np.isfinite(p.max_score_drop) and sc < self.score_ref[midx] - p.max_score_drop, FLAGGED,
                 "appearance"),
                (SEC[midx] >= sc - p.ambiguity_margin, FLAGGED, "ambiguous"),
                ((self.nh[midx] >= 3) & (res_ > lim), FLAGGED, "jump"),
                (info["foreign"][midx], FLAGGED, "foreign"),
                (self._rough(info, midx, sc), FLAGGED, "background"),
                (self._touching(XP, YP, prx, pry, gap, inside, info)[midx], FLAGGED, "merged"),
                (lo, FLAGGED, "conflict"),
                (((sc < p.lost_score) | ~(ms > 0)) & ~lo, LOST, "low_score"),
            )
            for cond, code, why in rules:
                if cond is not False and cond.any():
                    st[cond] = code
                    rs[cond] = _R[why]
            ST[midx] = st
            RS[midx] = rs
            li = midx[lo]
            X[li], Y[li] = prx[li], pry[li]
            lst = midx[st == LOST]
            X[lst] = np.nan
            Y[lst] = np.nan
            jmp = np.flatnonzero(RS == _R["jump"])
            chk = np.flatnonzero((ST == OK) & fits & ((np.abs(t - self.last_ok) > 1) | (self.nh < 3)))
            if jmp.size or chk.size:
                self._vouch(jmp, chk, X, Y, S, SEC, ST, RS, resid, res, t)
        if eidx.size:
            ex, ey = X[eidx], Y[eidx]
            okm = ((mass[eidx] > p.min_mass_ratio * self.mass0[eidx]) & (ex >= -0.5) & (ex <= W - 0.5)
                   & (ey >= -0.5) & (ey <= H - 0.5))
            ST[eidx[okm]] = FLAGGED
            RS[eidx[okm]] = _R["edge"]
            RS[eidx[~okm]] = _R["out_of_frame"]
            X[eidx[~okm]] = np.nan
            Y[eidx[~okm]] = np.nan

        # motion model: reliable points feed it (and edge points), and those flagged for
        # their precision only (merged, foreign, background) if they moved like their
        # neighbours: a marker next to another or in glare keeps being followed instead of
        # coasting, but not onto a neighbour's or an unpicked marker's blob
        okm = ST == OK
        rel = okm | ((ST == FLAGGED) & (RS == _R["edge"]))
        soft = np.flatnonzero((ST == FLAGGED) & _IS_SOFT[RS])
        if soft.size:
            rel[self._inconsistent(soft, X, Y, ST, res, t, since="fed")] = True
        if _numba is not None:
            upd = np.empty(n, np.bool_)
            _history_kernel(t, X, Y, S, ST, rel, resid, mass, self.hist_x, self.hist_t, self.nh, self.sigma,
                            self.last_score, self.last_ok, self.mass_ref, self.score_ref, self.last_upd,
                            np.array([p.update_score, p.refresh_below, p.update_every], np.float64), upd)
            ri = np.zeros(0, np.int64)
        else:
            ri = np.flatnonzero(rel)
        if ri.size:
            hx, ht = self.hist_x, self.hist_t
            us = ri[self.nh[ri] >= 2]
            if ri.size == n:
                hx[:, 1:] = hx[:, :2].copy()
                ht[:, 1:] = ht[:, :2].copy()
                hx[:, 0, 0] = X
                hx[:, 0, 1] = Y
                ht[:, 0] = t
            else:
                hx[ri, 2] = hx[ri, 1]
                hx[ri, 1] = hx[ri, 0]
                hx[ri, 0, 0] = X[ri]
                hx[ri, 0, 1] = Y[ri]
                ht[ri, 2] = ht[ri, 1]
                ht[ri, 1] = ht[ri, 0]
                ht[ri, 0] = t
            np.minimum(self.nh + rel, 3, out=self.nh)
            if us.size:
                e = resid[us]
                self.sigma[us] = np.sqrt(0.8 * self.sigma[us] ** 2 + 0.2 * e * e)
        if _numba is None:
            self.last_score = np.where(okm & np.isfinite(S), S, 0.0)
            self.last_ok[okm] = t
            self.mass_ref[okm] = 0.9 * self.mass_ref[okm] + 0.1 * mass[okm]
            self.score_ref[okm] = 0.7 * self.score_ref[okm] + 0.3 * S[okm]
            # template update: confident match whose appearance has changed
            upd = okm & (S >= p.update_score) & (S < p.refresh_below) & (np.abs(t - self.last_upd) >= p.update_every)
        if upd.any():
            lam = p.update_rate
            for i in np.flatnonzero(upd).tolist():
                cut = self._cut(frame, X[i], Y[i], h[i])
                self.tplr[i] = (1.0 - lam) * self.tplr[i] + lam * cut
                self._set_template(i)
                self.last_upd[i] = t
        if self.lostflag.any():
            self._reacquire(frame, t, res, direction, X, Y, S, XP, YP, ST, RS, pred)
        res.x[t], res.y[t], res.score[t] = X, Y, S
        res.xpix[t], res.ypix[t] = XP, YP
        res.status[t], res.reason[t] = ST, RS
        self.pos = np.column_stack([X, Y])

    def _neighbours(self, x, y, valid):
        """Two nearest valid other markers (indices, -1 none) and distances (inf none)."""
        n = len(x)
        if n < 2:
            return np.full((n, 2), -1), np.full((n, 2), np.inf)
        j, d, _ = _nearest_two(x, y, valid)
        if j.shape[1] < 2:
            j = np.column_stack([j, np.full(n, -1)])
            d = np.column_stack([d, np.full(n, np.inf)])
        return j, d

    def _touching(self, XP, YP, prx, pry, gap, inside, info):
        """Markers whose blob touches another's on this frame (flag 'merged').

        Positions are the pixel-level matches, or for a marker without one its prediction
        if it was tracked on the previous frame (a coasting marker's prediction may have
        drifted onto a neighbour: it does not make that neighbour 'merged'). Two blobs
        touch when closer than the sum of their radii + 1 px, unless the image between
        them falls below ``_MERGE_VALLEY`` of the peak (a visible gap), and whenever it
        stays above ``_BRIDGE`` of the peak (a bright bridge).
        """
        px = np.where(np.isfinite(XP), XP, np.where(inside & (gap == 1), prx, np.nan))
        py = np.where(np.isfinite(YP), YP, np.where(inside & (gap == 1), pry, np.nan))
        # the two nearest by prediction are the candidates (the nearest by match is one)
        j = np.maximum(self._j2, 0)
        d = np.hypot(px[j] - px[:, None], py[j] - py[:, None])
        d[self._j2 < 0] = np.inf
        touch = (d < self.rb[:, None] + self.rb[j] + 1.0).any(1)
        # (and whatever the radii, a bright bridge to the neighbour is a merge)
        return (touch & ~(info["valley"] < _MERGE_VALLEY)) | (info["valley"] > _BRIDGE)

    def _vouch(self, jmp, chk, X, Y, S, SEC, ST, RS, resid, res, t):
        """Neighbour checks after the status rules.

        A 'jump' from the motion model that the neighbours made too (the whole wing, or
        the rigid target between two stills, stopped or turned at once) is none: the
        neighbours are the ok markers, and the other jumpers too when the jump is too
        short to have landed on another marker's blob (< 40 % of the spacing); a lone
        marker (nothing to compare with) is vouched for by a short jump (< 30 % of the
        spacing) to a strong, unambiguous match. Then a marker resuming after a gap, or
        restarting, must have moved like its neighbours since it was last ok (without
        neighbours to vouch for it: only close to its own prediction)."""
        p = self.p
        if jmp.size:
            short = jmp[resid[jmp] < 0.4 * self._spacing[jmp]]
            ST[short] = OK
            bad_j, fine = self._inconsistent(jmp, X, Y, ST, res, t, both=True, min_m=1)
            ST[short] = FLAGGED
            lone = np.setdiff1d(jmp, np.concatenate([bad_j, fine]))
            lone = lone[(resid[lone] < 0.3 * self._spacing[lone]) & (S[lone] >= 0.9)
                        & (SEC[lone] < S[lone] - p.ambiguity_margin)]
            fine = np.concatenate([fine, lone]).astype(np.int64)
            ST[fine] = OK
            RS[fine] = 0
            chk = np.union1d(chk, fine[(np.abs(t - self.last_ok[fine]) > 1) | (self.nh[fine] < 3)])
        if chk.size:
            bad, good = self._inconsistent(chk, X, Y, ST, res, t, both=True)
            unk = np.setdiff1d(chk[np.abs(t - self.last_ok[chk]) > 1], np.concatenate([bad, good]))
            far = unk[resid[unk] > np.maximum(2.0, 2.0 * self.sigma[unk])]
            bad = np.concatenate([bad, far]).astype(np.int64)
            ST[bad] = FLAGGED
            RS[bad] = _R["jump"]

    def _rough(self, info, idx, score):
        """Markers whose background is too far from a plane for their contrast.

        The ring's RMS departure from the fitted plane, relative to the marker's peak,
        above ``_BG_RESIDUAL``; above ``_BG_RESIDUAL_FADED`` for a marker whose peak fell
        below ``_FADED`` of its frame-0 value (turning edge-on: the blob is a faint smear
        that a membrane edge or glare shifts by up to a pixel) or whose correlation is
        weak (below ``_WEAK``: the blob no longer looks like the marker).
        """
        bg = info["bgres"][idx]
        faded = (info["peak"][idx] < _FADED * self.peak0[idx]) | (score < _WEAK)
        return (bg > _BG_RESIDUAL) | (faded & (bg > _BG_RESIDUAL_FADED))

    def _rmax(self):
        """Largest disk radius of each marker (a blob may grow to this by foreshortening)."""
        return np.minimum(self.rb + _RD_MARGIN + 3.0, _RD_MAX)

    def _refine_all(self, frame, idx, XP, YP, jn, X, Y, mass):
        """:meth:`_voronoi` and :meth:`_refine_at` of markers ``idx`` by the compiled
        kernel; returns the neighbour positions used for the split."""
        info = self._info
        n = len(XP)
        nb = np.full((n, 2), np.nan)
        foreign = np.zeros(n, np.bool_)
        _refine_all_kernel(frame, idx, XP, YP, jn, self.rd, self.rb, self.sign64, self.noise, 2, WEIGHT_FRACTION,
                           FOREIGN_FRACTION, FOREIGN_NOISE, X, Y, mass, foreign, info["bgres"], info["peak"],
                           info["valley"], nb)
        info["foreign"] = foreign
        self._nbr_r = self.rd[np.maximum(jn, 0)] + 0.5
        # a foreign blob next to a steady marker: split off like a neighbour (rare)
        cand = idx[foreign[idx] & (mass[idx] > 0)]
        if cand.size:
            steady = self._steady[cand] & (np.hypot(XP[cand] - self._pred[cand, 0], YP[cand] - self._pred[cand, 1])
                                           <= 2.0 + 2.0 * self.sigma[cand])
            cand = cand[steady]
            if cand.size:
                xx, yy, mm, inf = _refine(frame, XP[cand], YP[cand], self.rd[cand], self.sign[cand], self.noise[cand],
                                          nb[cand], 2, rmax=self.rd[cand], nbr_r=self._nbr_r[cand],
                                          explain=np.ones(cand.size, bool))
                X[cand], Y[cand], mass[cand] = xx, yy, mm
                for k in ("foreign", "bgres", "peak", "valley"):
                    info[k][cand] = inf[k]
        return nb

    def _refine_at(self, frame, idx, XP, YP, nb):
        """Refine markers ``idx`` from their pixel-level positions; record diagnostics.

        A foreign blob next to a marker tracked on the previous frame and matched where
        predicted is split off like a known neighbour (:func:`_refine`)."""
        steady = self._steady[idx] & (np.hypot(XP[idx] - self._pred[idx, 0], YP[idx] - self._pred[idx, 1])
                                      <= 2.0 + 2.0 * self.sigma[idx])
        x, y, m, inf = _refine(frame, XP[idx], YP[idx], self.rd[idx], self.sign[idx], self.noise[idx], nb[idx], 2,
                               rmax=self.rd[idx], nbr_r=self._nbr_r[idx], explain=steady)
        info = self._info
        info["foreign"][idx] = inf["foreign"]
        info["bgres"][idx] = inf["bgres"]
        info["peak"][idx] = inf["peak"]
        info["valley"][idx] = inf["valley"]
        info["rd"][idx] = inf["rd"]
        return x, y, m

    def _voronoi(self, XP, YP, prx, pry, jn, inside):
        """Position of each marker's nearest neighbour for the pixel split (NaN: none near)."""
        j = np.maximum(jn, 0)
        # only a neighbour matched on this frame: one that lost its match to another
        # marker (conflict) may be anywhere near its prediction, and a split there could
        # cut this marker's own blob (its blob, if near, is caught as foreign instead)
        nx = XP[j].copy()
        ny = YP[j].copy()
        cx = np.where(np.isfinite(XP), XP, prx)
        cy = np.where(np.isfinite(YP), YP, pry)
        # the neighbour matters when its blob can reach this marker's disk or ring
        reach = self.rd + 3.0 + self.rb[j]
        dn = np.hypot(nx - cx, ny - cy)
        # (a neighbour on the same pixel is a conflict, flagged elsewhere: no split)
        far = (jn < 0) | ~(dn < reach) | (dn < 1.5)
        nx[far] = np.nan
        ny[far] = np.nan
        self._nbr_r = self.rd[j] + 0.5
        return np.column_stack([nx, ny])

    def _neighbours_then(self, i, ti, Pi, okn, res):
        """Up to six neighbours of marker ``i``, nearest first: ok now (``okn``) and on frame
        ``ti``, within ``self.local`` px of its position ``Pi`` then, and - when two or
        more did - those that moved like it then (not the static mount and reference dots
        for a wing marker). Returns their indices and positions on frame ``ti``."""
        T = res.x.shape[0]
        cand = okn[(okn != i) & (res.status[ti, okn] == OK)]
        prev = np.column_stack([res.x[ti, cand], res.y[ti, cand]])
        d = np.hypot(prev[:, 0] - Pi[0], prev[:, 1] - Pi[1])
        keep = d <= self.local
        cand, prev, d = cand[keep], prev[keep], d[keep]
        t1 = int(self.hist_t[i, 1])
        if cand.size >= 2 and self.nh[i] >= 2 and t1 != ti:
            vi = (self.hist_x[i, 0] - self.hist_x[i, 1]) / abs(ti - t1)
            tb = ti - (1 if t1 < ti else -1)
            if 0 <= tb < T:
                vj = prev - np.column_stack([res.x[tb, cand], res.y[tb, cand]])
                same = np.hypot(vj[:, 0] - vi[0], vj[:, 1] - vi[1]) <= 1.0 + 0.3 * math.hypot(*vi)
                if same.sum() >= 2:
                    cand, prev, d = cand[same], prev[same], d[same]
        o = np.argsort(d)[:6]
        return cand[o], prev[o]

    def _inconsistent(self, chk, X, Y, ST, res, t, since=None, both=False, min_lim=0.0, min_m=2):
        """Markers ``chk`` whose displacement since their last ok frame disagrees with that
        of their neighbours (:meth:`_neighbours_then`).

        The neighbours' displacement over the same interval (:func:`_neighbour_prediction`)
        predicts where the marker must be; further than its tolerance (at least
        ``min_lim``) is inconsistent. With ``since`` the interval starts at the marker's
        last position that fed the motion model instead, and the consistent ones are
        returned; with ``both``, (inconsistent, consistent). Prevents a marker that
        coasted, or restarted, from landing on a neighbour's or an unpicked marker's blob
        that happens to lie near its extrapolated prediction.
        """
        okn = np.flatnonzero(ST == OK)
        T = res.x.shape[0]
        bad = []
        good = []
        for i in chk.tolist():
            if since is None:
                ti = int(self.last_ok[i])
                if not 0 <= ti < T or ti == t or not np.isfinite(res.x[ti, i]):
                    continue
                Pi = np.array([res.x[ti, i], res.y[ti, i]])
            else:  # since the last position that fed the motion model
                ti = int(self.hist_t[i, 0])
                if not 0 <= ti < T or ti == t:
                    continue
                Pi = self.hist_x[i, 0]
            cand, prev = self._neighbours_then(i, ti, Pi, okn, res)
            if cand.size < min_m:
                continue
            pq = _neighbour_prediction(Pi, prev, np.column_stack([X[cand], Y[cand]]), min_m)
            if pq is None:
                continue  # the neighbours do not move together: nothing to compare with
            q, lim = pq
            if math.hypot(X[i] - q[0], Y[i] - q[1]) > max(lim, min_lim):
                bad.append(i)
            else:
                good.append(i)
        if both:
            return np.array(bad, np.int64), np.array(good, np.int64)
        if since is not None:
            return np.array(good, np.int64)
        return np.array(bad, np.int64)

    def _conflicts(self, sidx, XP, YP, prx, pry, merged, jn):
        """Markers that lost a blob to another marker this frame (boolean, all markers).

        Only a searched marker can land on another's blob (a fast-path marker stays within
        a pixel of its own prediction), so searched markers are tested against all.
        """
        n = len(XP)
        lose = np.zeros(n, bool)
        si = sidx[np.isfinite(XP[sidx])]
        vi = np.flatnonzero(np.isfinite(XP))
        if si.size == 0 or vi.size < 2:
            return lose
        dx = XP[si][:, None] - XP[vi]
        dy = YP[si][:, None] - YP[vi]
        rr = np.maximum(np.maximum(self.rb[si][:, None], self.rb[vi]), 2.0)
        same = (dx * dx + dy * dy) < rr * rr
        same &= si[:, None] != vi
        if not same.any():
            return lose
        # a marker that coasted has a vaguer prediction: it does not take a blob from one
        # tracked on the previous frame
        cost = np.hypot(XP - prx, YP - pry) / (self.sigma + 0.5 + (self._gap - 1))
        for a, b in zip(*np.nonzero(same)):
            i, j = si[a], vi[b]
            if merged[i] and merged[j]:
                continue  # touching blobs: both flagged 'merged' anyway
            lose[i if cost[i] > cost[j] else j] = True
        return lose

    def _set_template(self, i):
        w = self.p.original_weight
        t = w * self.tpl0[i] + (1.0 - w) * self.tplr[i]
        self.tplu[i] = None  # made when needed (:meth:`_tplu`)
        self._stack_template(i, t)

    def _tplu(self, i):
        """Template of marker ``i`` as matched by OpenCV (uint8 for uint8 frames)."""
        if self.tplu[i] is None:
            w = self.p.original_weight
            self.tplu[i] = self._as_match(w * self.tpl0[i] + (1.0 - w) * self.tplr[i])
        return self.tplu[i]

    def _stack_template(self, i, t):
        s = self.tz.shape[1]
        hi = int(self.h[i])
        a = (s // 2) - hi
        tt = np.asarray(t, np.float64)
        tz = tt - tt.mean()
        nrm = np.sqrt((tz * tz).sum())
        self.tz[i] = 0.0
        self.tz[i, a: a + 2 * hi + 1, a: a + 2 * hi + 1] = tz / max(nrm, 1e-12)

    def _init_stack(self):
        s = 2 * int(self.h.max()) + 1
        n = len(self.h)
        self.tz = np.zeros((n, s, s), np.float32)
        self.tmask = np.zeros((n, s * s), np.float32)
        o = np.arange(s) - s // 2
        for i in range(n):
            hi = int(self.h[i])
            m = (np.abs(o)[:, None] <= hi) & (np.abs(o)[None, :] <= hi)
            self.tmask[i] = m.ravel()
            w = self.p.original_weight
            t = w * self.tpl0[i] + (1.0 - w) * self.tplr[i]
            self.tplu[i] = None
            self._stack_template(i, t)
        self.tzf = self.tz.reshape(n, -1)
        self.to = o
        self.tcount = self.tmask.sum(1)

    def _match(self, frame, idx, centres, radii):
        """Windowed correlation of markers ``idx`` (:func:`match_windows`; compiled when
        numba is available, with the unrounded templates, for windows of radius <= 6 px:
        OpenCV's SIMD code is faster on wider ones)."""
        if _numba is None or np.max(radii) > 6:
            return match_windows(frame, [self._tplu(i) for i in idx], centres, radii)
        centres = np.asarray(centres, np.int64).reshape(-1, 2)
        radii = np.asarray(radii, np.int64).reshape(-1)
        n = len(centres)
        m = 2 * int(radii.max()) + 1 if n else 1
        maps = np.full((n, m, m), -2.0, np.float32)
        origin = np.zeros((n, 2), np.int64)
        shape = np.zeros((n, 2), np.int64)
        if n:
            idx = np.asarray(idx, np.int64)
            _ncc_kernel(frame, self.tz, idx, self.h[idx], np.ascontiguousarray(centres[:, 0]),
                        np.ascontiguousarray(centres[:, 1]), radii, maps, origin, shape)
        return maps, origin, shape

    def _score_at(self, frame, idx, cx, cy):
        """TM_CCOEFF_NORMED of each template centred at integer pixels (cx, cy)."""
        if _numba is not None:
            out = np.empty(len(idx))
            _score_kernel(frame, self.tz, idx, self.h[idx], cx.astype(np.int64), cy.astype(np.int64), out)
            return out
        I = _gather(frame, cx.astype(np.int64), cy.astype(np.int64), self.to)
        m = self.tmask[idx]
        s1 = np.einsum("ij,ij->i", I, m)
        s2 = np.einsum("ij,ij->i", I * I, m)
        num = np.einsum("ij,ij->i", I, self.tzf[idx])
        var = s2 - s1 * s1 / self.tcount[idx]
        with np.errstate(invalid="ignore", divide="ignore"):
            sc = num / np.sqrt(np.maximum(var, 0.0))
        return np.where(var > 1e-6 * (s2 + 1.0), sc, 0.0)

    def _search(self, frame, idx, pred, px, py, r, wide, j2, XP, YP, S, SEC):
        """Windowed NCC around the predictions of markers ``idx``; wide-search consensus.

        With numba, a marker whose window is small (radius <= 3: moving predictably) is
        hill-climbed from its prediction instead (a window that small has no room for a
        runner-up peak away from the best, so nothing is lost); one whose climb reaches
        the window's edge gets the full search, twice as wide."""
        p = self.p
        if _numba is not None:
            small = (r[idx] <= 3) & ~wide[idx]
            if small.any():
                cidx = idx[small]
                out = np.empty((cidx.size, 4))
                _climb_kernel(frame, self.tz, cidx, self.h[cidx], px[cidx].astype(np.int64),
                              py[cidx].astype(np.int64), r[cidx], out)
                rim = out[:, 3] > 0
                ok = ~rim & (out[:, 2] > -2.0)
                XP[cidx[ok]], YP[cidx[ok]], S[cidx[ok]], SEC[cidx[ok]] = out[ok, 0], out[ok, 1], out[ok, 2], -2.0
                idx = np.concatenate([idx[~small], cidx[~ok]])
                if cidx[~ok].size:
                    r = r.copy()
                    r[cidx[~ok]] = np.minimum(2 * r[cidx[~ok]] + 2, p.search_radius)
                if not idx.size:
                    return
        ci = np.column_stack([px[idx], py[idx]]).astype(np.int64)
        ri = r[idx]
        maps, origin, shp = self._match(frame, idx, ci, ri)
        others = []
        for k in range(2):
            jj = j2[idx, k]
            o = pred[np.maximum(jj, 0)] - origin
            o[jj < 0] = np.nan
            others.append(o)
        excl = np.maximum(2.0, self.rb[idx])
        u, v, score, second, border = _analyse_maps(maps, shp, excl, others)
        # a best peak on the rim of an unclipped window: the marker is further than the
        # window reaches -> search once more, twice as wide
        full = (shp[:, 0] == 2 * ri + 1) & (shp[:, 1] == 2 * ri + 1)
        redo = np.flatnonzero(border & full & (ri < p.search_radius))
        if redo.size:
            r2 = np.minimum(2 * ri[redo] + 2, p.search_radius)
            m2, o2, s2 = self._match(frame, idx[redo], ci[redo], r2)
            oth2 = [o[redo] + (origin[redo] - o2) for o in others]
            a = _analyse_maps(m2, s2, excl[redo], oth2)
            u[redo], v[redo], score[redo], second[redo] = a[0], a[1], a[2], a[3]
            origin[redo] = o2
        mx = (origin[:, 0] + u).astype(np.float64)
        my = (origin[:, 1] + v).astype(np.float64)
        wsel = wide[idx]
        if wsel.any():
            self._consensus(frame, idx, wsel, pred, mx, my, score, second, excl)
        XP[idx] = mx
        YP[idx] = my
        S[idx] = score
        SEC[idx] = second

    def _consensus(self, frame, idx, wsel, pred, mx, my, score, second, excl):
        """Check wide-search matches (no velocity yet) against the wing's local motion.

        Each wide-searched marker's displacement from the reference frame is predicted from
        its nearest anchors (up to six, within ``self.local`` px in the reference frame):
        the other markers with a motion model (at their predictions) and the wide-searched
        markers whose match is unambiguous (:func:`_neighbour_prediction`: a robust affine
        map, or the mean displacement of a group that moved alike), so that static mount
        and reference dots next to the wing, or a look-alike, do not decide. An ambiguous
        (or low-score) match is replaced by a search of radius 4 at the prediction; an
        unambiguous match that disagrees with the prediction is made ambiguous (flagged,
        not trusted), never moved. Without such a group the match
        stands as it is. Prevents a marker starting (or restarting) on its neighbour's or
        an unpicked marker's blob when its own is dim or the two look alike.
        """
        p = self.p
        n = len(self.h)
        ref = self.ref_pos
        ax = np.full(n, np.nan)
        ay = np.full(n, np.nan)
        tracked = (self.nh >= 2) & ~self.lostflag
        ax[tracked], ay[tracked] = pred[tracked, 0], pred[tracked, 1]
        amb = (second >= score - p.ambiguity_margin) | (score < p.min_score)
        good = wsel & ~amb
        ax[idx[good]], ay[idx[good]] = mx[good], my[good]
        anchors = np.flatnonzero(np.isfinite(ax))
        redo, qs = [], []
        for k in np.flatnonzero(wsel).tolist():
            i = idx[k]
            cand = anchors[anchors != i]
            d = np.hypot(ref[cand, 0] - ref[i, 0], ref[cand, 1] - ref[i, 1])
            cand, d = cand[d <= self.local], d[d <= self.local]
            if cand.size < 2:
                continue
            near = cand[np.argsort(d)[:6]]
            pq = _neighbour_prediction(ref[i], ref[near], np.column_stack([ax[near], ay[near]]))
            if pq is None:
                continue  # the neighbours do not move together: no prediction to trust
            q, lim = pq
            if good[k]:
                if math.hypot(mx[k] - q[0], my[k] - q[1]) > lim + 1.0:
                    second[k] = score[k]  # match and neighbours disagree: ambiguous
                continue
            redo.append(k)
            qs.append(q)
        if not redo:
            return
        redo = np.array(redo)
        q = np.array(qs)
        qi = np.rint(q).astype(np.int64)
        hb = self.h[idx[redo]]
        okq = ((qi[:, 0] - hb >= 0) & (qi[:, 1] - hb >= 0) & (qi[:, 0] + hb <= self.W - 1)
               & (qi[:, 1] + hb <= self.H - 1))
        redo, q, qi = redo[okq], q[okq], qi[okq]
        if not redo.size:
            return
        cur = np.column_stack([ax, ay])
        cur[idx[redo]] = q
        j3, _, _ = _nearest_two(cur[:, 0], cur[:, 1], np.isfinite(cur[:, 0]))
        m3, o3, s3 = self._match(frame, idx[redo], qi, np.full(redo.size, 4))
        oth3 = []
        for k in range(2):
            jj = j3[idx[redo], k]
            o = cur[np.maximum(jj, 0)] - o3
            o[jj < 0] = np.nan
            oth3.append(o)
        a = _analyse_maps(m3, s3, excl[redo], oth3)
        mx[redo] = o3[:, 0] + a[0]
        my[redo] = o3[:, 1] + a[1]
        score[redo], second[redo] = a[2], a[3]
        pred[idx[redo]] = q

    def _predict_lost(self, i, okn, X, Y, res, t):
        """Where lost marker ``i`` should be now, from its neighbours.

        Returns (prediction, search radius, minimum score, neighbours used) or None.

        1. From its last reliable frame: the neighbours reliable then and now (those that
           moved like it then, when there are enough) map its last position to now
           (:func:`_neighbour_prediction`: a robust affine map or the mean displacement of
           a group that moved alike). Short intervals keep this accurate on a bending,
           pitching wing.
        2. Else from the reference frame (the first frame of the pass, where every marker
           is known) by a robust affine map on its nearest reliable neighbours: a planar
           wing seen from afar moves by an affine map however much time has passed.
        3. An isolated marker (fewer than two neighbours within ``self.local`` px - the
           two-marker rigid target, a reference dot) is searched for in a wide window
           (``search_radius``) at its last position, moved like its one neighbour if it has
           one, and accepted only with a score of at least ``max(reacquire_score, 0.9)``.
        """
        p = self.p
        T = res.x.shape[0]
        ref = self.ref_pos
        ti = int(self.hist_t[i, 0])
        Pi = self.hist_x[i, 0]
        cand = okn[okn != i]
        if 0 <= ti < T and cand.size:
            c1, prev = self._neighbours_then(i, ti, Pi, okn, res)
            if c1.size >= 2:
                pq = _neighbour_prediction(Pi, prev, np.column_stack([X[c1], Y[c1]]))
                if pq is not None:
                    return pq[0], p.reacquire_radius, p.reacquire_score, c1
        # 2. from the reference frame
        cur = np.column_stack([X[okn], Y[okn]])
        if okn.size >= 4:
            use = np.ones(okn.size, bool)
            if self.nh[i] >= 2 and self.hist_t[i, 0] != self.hist_t[i, 1]:
                v = np.hypot(*(self.hist_x[i, 0] - self.hist_x[i, 1])) / abs(self.hist_t[i, 0] - self.hist_t[i, 1])
                still = np.hypot(cur[:, 0] - ref[okn, 0], cur[:, 1] - ref[okn, 1]) < 1.5
                group = still if v < 0.3 else ~still
                if group.sum() >= 4:
                    use = group
            cidx = np.flatnonzero(use)
            d = np.hypot(ref[okn[cidx], 0] - ref[i, 0], ref[okn[cidx], 1] - ref[i, 1])
            order = cidx[np.argsort(d)]
            for k in (6, 5, 4):
                near = order[:k]
                if near.size < 4:
                    break
                M, rms, nin = _robust_affine(ref[okn[near]], cur[near], quality=True)
                if M is not None and nin >= 4 and rms <= 1.5:
                    return _apply_affine(M, ref[i][None, :])[0], p.reacquire_radius, p.reacquire_score, okn[near]
        # 3. an isolated marker
        nbr = cand[np.hypot(ref[cand, 0] - ref[i, 0], ref[cand, 1] - ref[i, 1]) <= self.local]
        if nbr.size >= 2:
            return None
        q = Pi.copy()
        if nbr.size == 1 and 0 <= ti < T and res.status[ti, nbr[0]] == OK:
            j = nbr[0]
            q += (X[j] - res.x[ti, j], Y[j] - res.y[ti, j])
        return q, p.search_radius, max(p.reacquire_score, 0.9), nbr

    def _reacquire(self, frame, t, res, direction, X, Y, S, XP, YP, ST, RS, pred):
        """Search again for long-lost markers where their reliable neighbours put them.

        Each lost marker's position is predicted from its neighbours
        (:meth:`_predict_lost`). A blob found near the prediction is accepted only if it
        correlates well and unambiguously, if no other marker (tracked, or lost and
        predicted the same way) is expected nearer to it, if no uncertain marker is near
        (it could be that marker's blob), and if its refinement finds no foreign blob.
        """
        p = self.p
        okn = np.flatnonzero(ST == OK)
        if okn.size < 1:
            return
        lost = np.flatnonzero(self.lostflag)
        # where every marker is expected: its position, else (tracked but without a
        # position on this frame) its prediction; long-lost ones from the neighbours below
        est_x = X.copy()
        est_y = Y.copy()
        nopos = ~np.isfinite(X) & ~self.lostflag
        est_x[nopos], est_y[nopos] = pred[nopos, 0], pred[nopos, 1]
        q = {}
        for i in lost.tolist():
            r = self._predict_lost(i, okn, X, Y, res, t)
            if r is not None:
                q[i] = r
                est_x[i], est_y[i] = r[0]
        valid = np.isfinite(est_x)
        found = {}
        for i, (qi, rad, min_sc, nbrs) in q.items():
            ci = np.rint(qi).astype(np.int64)
            hh = int(self.h[i])
            if ci[0] - hh < 0 or ci[1] - hh < 0 or ci[0] + hh > self.W - 1 or ci[1] + hh > self.H - 1:
                continue
            maps, origin, shp = self._match(frame, np.array([i]), ci[None, :], [rad])
            m = maps.shape[1]
            ex = max(2.0, float(self.rb[i]))
            g = _GRID[:m]
            # cells on other markers' current positions cannot be this marker
            cur_valid = np.flatnonzero(np.isfinite(X))
            for j in cur_valid.tolist():
                if j == i:
                    continue
                du = X[j] - origin[0, 0]
                dv = Y[j] - origin[0, 1]
                if abs(du - m / 2) > m + ex or abs(dv - m / 2) > m + ex:
                    continue
                nearj = ((g[None, :] - du) ** 2 + (g[:, None] - dv) ** 2) <= (max(ex, float(self.rb[j])) + 1.0) ** 2
                maps[0][nearj] = -2.0
            u, v, score, second, _ = _analyse_maps(maps, shp, np.array([ex]))
            sc = float(score[0])
            if not (sc >= min_sc and second[0] < sc - p.ambiguity_margin):
                continue
            mx, my = float(origin[0, 0] + u[0]), float(origin[0, 1] + v[0])
            # joint test: this marker's prediction must be the nearest to the blob
            dq = math.hypot(mx - qi[0], my - qi[1])
            others = valid.copy()
            others[i] = False
            if others.any():
                do = np.hypot(est_x[others] - mx, est_y[others] - my).min()
                dqo = np.hypot(est_x[others] - qi[0], est_y[others] - qi[1]).min()
                if not (dq < do and dq <= max(3.0, 0.5 * dqo)):
                    continue
            # and no uncertain marker (flagged, or lost) may be near: the blob could be
            # its own, and a wrong re-acquisition would be confident from then on
            unsure = others & (ST != OK)
            block = 2.5 * (self.rb[i] + 1.0) + dq
            blockers = np.flatnonzero(unsure & (np.hypot(est_x - mx, est_y - my) < block))
            found[i] = (mx, my, sc, blockers)
        # a blocker does not block when it is itself re-acquired on another blob and the
        # two assignments fit the two predictions better than the swap (two lost
        # neighbours would otherwise block each other for ever), or when it is a marker
        # flagged for its precision only, matched on another blob
        accept = []
        for i, (mx, my, sc, blockers) in found.items():
            okb = True
            for j in blockers.tolist():
                if j in found:
                    mj = found[j]
                    apart = math.hypot(mj[0] - mx, mj[1] - my) > self.rb[i] + self.rb[j]
                    qi, qj = q[i][0], q[j][0]
                    same = math.hypot(mx - qi[0], my - qi[1]) + math.hypot(mj[0] - qj[0], mj[1] - qj[1])
                    swap = math.hypot(mj[0] - qi[0], mj[1] - qi[1]) + math.hypot(mx - qj[0], my - qj[1])
                    if apart and same + 2.0 < swap:
                        continue
                elif (ST[j] == FLAGGED and RS[j] in _SOFT and np.isfinite(X[j])
                      and math.hypot(X[j] - mx, Y[j] - my) > self.rb[i] + self.rb[j]):
                    continue
                okb = False
                break
            if okb:
                accept.append(i)
        for i in accept:
            mx, my, sc, _ = found[i]
            nbrs = q[i][3]
            # the blob must also be where the neighbours put the marker's last ok position
            # (a long interval: 4 px tolerance, a neighbour's blob is further)
            Xi, Yi = X[i], Y[i]
            X[i], Y[i] = mx, my
            wrong = self._inconsistent(np.array([i]), X, Y, ST, res, t, min_lim=4.0).size > 0
            X[i], Y[i] = Xi, Yi
            if wrong:
                continue
            nb = None
            oth = np.flatnonzero(np.isfinite(X))
            oth = oth[oth != i]
            if oth.size:
                dj = np.hypot(X[oth] - mx, Y[oth] - my)
                k = int(np.argmin(dj))
                if dj[k] < self.rd[i] + 3.0 + self.rb[oth[k]]:
                    nb = np.array([[X[oth[k]], Y[oth[k]]]])
            sel = np.array([i])
            rx, ry, mass, inf = _refine(frame, [mx], [my], self.rd[sel], self.sign[sel], self.noise[sel], nb, 2,
                                        rmax=self.rd[sel])
            if not mass[0] > p.min_mass_ratio * self.mass0[i] or inf["foreign"][0]:
                continue
            X[i], Y[i], S[i], XP[i], YP[i] = rx[0], ry[0], sc, mx, my
            ST[i] = FLAGGED
            RS[i] = _R["reacquired"]
            est_x[i], est_y[i] = rx[0], ry[0]
            # restart the motion model with the neighbours' velocity
            tp = t - direction
            vel = np.zeros(2)
            if 0 <= tp < res.x.shape[0] and len(nbrs):
                both = nbrs[res.status[tp, nbrs] == OK]
                if both.size:
                    vel = np.array([np.mean(X[both] - res.x[tp, both]), np.mean(Y[both] - res.y[tp, both])])
            self.hist_x[i] = np.nan
            self.hist_x[i, 0] = (rx[0], ry[0])
            self.hist_x[i, 1] = (rx[0] - vel[0], ry[0] - vel[1])
            self.hist_t[i] = (t, tp, tp - direction)
            self.nh[i] = 2
            self.sigma[i] = 1.0
            self.lostflag[i] = False
            self.last_ok[i] = t  # checked against the neighbours: the reference from now on


# --------------------------------------------------------------------------- driver
class _Params:
    """Validated tracking options (a plain record; see :func:`track_markers`)."""

    def __init__(self, **kw):
        for k, v in _PARAM_DEFAULTS.items():
            setattr(self, k, kw.pop(k, v))
        if kw:
            raise TypeError(f"unknown option(s) {sorted(kw)}")
        if self.search_radius is None:
            self.search_radius = _PARAM_DEFAULTS["search_radius"]
        self.search_radius = int(self.search_radius)
        if self.search_radius < 2:
            raise ValueError(f"search_radius must be >= 2 px, got {self.search_radius}")
        for k in ("min_score", "lost_score", "update_score", "refresh_below", "reacquire_score"):
            v = float(getattr(self, k))
            if not -1.0 <= v <= 1.0:
                raise ValueError(f"{k} must be a correlation score in [-1, 1], got {v}")
            setattr(self, k, v)
        if self.lost_score > self.min_score:
            raise ValueError(f"lost_score ({self.lost_score}) must not exceed min_score ({self.min_score})")
        for k in ("update_rate", "original_weight"):
            v = float(getattr(self, k))
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{k} must be in [0, 1], got {v}")
            setattr(self, k, v)
        if self.polarity not in ("auto", 1, -1):
            raise ValueError(f"polarity must be 'auto', 1 (bright markers) or -1 (dark), got {self.polarity!r}")
        for k in ("max_mass_ratio", "max_score_drop"):
            v = getattr(self, k)
            setattr(self, k, np.inf if v is None else float(v))
        self.jump_px = float(self.jump_px)
        self.max_coast = int(self.max_coast)
        self.search_every = int(self.search_every)
        self.update_every = max(int(self.update_every), 1)
        if self.search_every < 1:
            raise ValueError(f"search_every must be >= 1 frame, got {self.search_every}")
        self.reacquire_radius = int(self.reacquire_radius)

    def as_dict(self):
        return {k: getattr(self, k) for k in _PARAM_DEFAULTS}


def _fingerprint(fr, xy, ids, half, params, camera, bidirectional):
    hsh = hashlib.sha1()
    hsh.update(np.nan_to_num(np.ascontiguousarray(xy), nan=-1e300).tobytes())
    hsh.update(np.ascontiguousarray(ids).tobytes())
    hsh.update(np.ascontiguousarray(half).tobytes())
    hsh.update(json.dumps([params.as_dict(), camera, bool(bidirectional), fr.n, list(fr.shape), str(fr.dtype)],
                          sort_keys=True, default=str).encode())
    hsh.update(np.ascontiguousarray(fr[0]).tobytes())
    return hsh.hexdigest()


def _save_checkpoint(path, meta, arrays):
    from .io import atomic_write

    payload = dict(arrays)
    payload["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    with atomic_write(path, "wb") as f:
        np.savez(f, **payload)


def _load_checkpoint(path, fingerprint):
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(bytes(z["meta"]).decode())
        if meta.get("version") != _CHECKPOINT_VERSION or meta.get("fingerprint") != fingerprint:
            raise ValueError(
                f"checkpoint {path} was written for other frames, picks or options; delete it or "
                "pass another checkpoint path"
            )
        arrays = {k: z[k] for k in z.files if k != "meta"}
    return meta, arrays


def _run_pass(fr, tracker, res, frames_order, direction, ckpt, progress, desc):
    """Run ``tracker`` over ``frames_order`` (iterable of frame indices), checkpointing."""
    from tqdm.auto import tqdm

    bar = tqdm(total=len(frames_order), disable=not progress, desc=desc, leave=False)
    done = 0
    try:
        for t in frames_order:
            tracker.step(fr[t], t, res, direction)
            done += 1
            if ckpt is not None:
                ckpt.completed(t)
            if done & 255 == 0:
                bar.update(256)
    except BaseException:
        if ckpt is not None:
            ckpt.save()
        raise
    finally:
        bar.update(done & 255)
        bar.close()


class _Checkpointer:
    def __init__(self, path, fingerprint, every, state_fn):
        self.path = Path(path)
        self.fingerprint = fingerprint
        self.every = int(every)
        if self.every < 1:
            raise ValueError(f"checkpoint_every must be >= 1 frame, got {every}")
        self.state_fn = state_fn
        self.since = 0
        self.last = None

    def completed(self, t):
        self.last = t
        self.since += 1
        if self.since >= self.every:
            self.save()

    def save(self):
        meta, arrays = self.state_fn()
        meta["version"] = _CHECKPOINT_VERSION
        meta["fingerprint"] = self.fingerprint
        _save_checkpoint(self.path, meta, arrays)
        self.since = 0


def _tracks_frame(res, ids, camera, frames_idx=None):
    import pandas as pd

    T, N = res.x.shape
    fidx = np.arange(T) if frames_idx is None else np.asarray(frames_idx)
    status_names = np.array(STATUS, dtype=object)
    reason_names = np.array(REASONS, dtype=object)
    df = pd.DataFrame(
        {
            "camera": np.full(T * N, camera, dtype=object),
            "frame": np.repeat(fidx.astype(np.int64), N),
            "point": np.tile(np.asarray(ids, np.int64), T),
            "x": res.x.ravel(),
            "y": res.y.ravel(),
            "score": res.score.ravel(),
            "status": status_names[res.status.ravel()],
            "x_pix": res.xpix.ravel(),
            "y_pix": res.ypix.ravel(),
            "reason": reason_names[res.reason.ravel()],
        }
    )
    df["camera"] = df["camera"].astype(str)
    df["status"] = df["status"].astype(str)
    df["reason"] = df["reason"].astype(str)
    return df


def _merge_backward(fw, bw, tol):
    """Flag forward/backward disagreement; fill forward losses from anchored backward runs.

    A backward position replaces a forward loss only inside a run of consecutive
    backward-ok frames that, later in the sequence, agreed with an ok forward position
    (the run is anchored to a point both passes saw at the same place); an unanchored
    backward run may have started on the wrong blob.
    """
    both = (fw.status == OK) & (bw.status == OK)
    d = np.hypot(fw.x - bw.x, fw.y - bw.y)
    agree = both & (d <= tol)
    dis = both & (d > tol)
    soft = (_R["lost_track"], _R["out_of_frame"], _R["low_score"], _R["no_signal"], _R["edge"], _R["jump"])
    fillable = (fw.status != OK) & (bw.status == OK) & np.isin(fw.reason, soft)
    T, N = fw.x.shape
    fill = np.zeros_like(fillable)
    bok = bw.status == OK
    for i in range(N):
        anchored = False
        for t in range(T - 1, -1, -1):  # the backward pass ran from the end
            if not bok[t, i]:
                anchored = False
                continue
            if agree[t, i]:
                anchored = True
            elif fillable[t, i] and anchored:
                fill[t, i] = True
    fw.status[dis] = FLAGGED
    fw.reason[dis] = _R["fb_disagree"]
    for k in _Results.names:
        getattr(fw, k)[fill] = getattr(bw, k)[fill]
    fw.status[fill] = OK
    fw.reason[fill] = 0


def track_markers(frames, picks, *, camera="left", search_radius=None, min_score=0.6,
                  lost_score=0.3, ambiguity_margin=0.1, update_score=0.88, refresh_below=0.93,
                  update_rate=0.5, original_weight=0.3, update_every=4, max_coast=6,
                  reacquire_radius=6, reacquire_score=0.8, min_mass_ratio=0.25,
                  max_mass_ratio=None, jump_px=3.0, max_score_drop=None, polarity="auto",
                  search_every=4, bidirectional=False, fb_tolerance=0.5, checkpoint=None,
                  checkpoint_every=500, progress=True):
    """Track markers from their frame-0 picks through a sequence, flagging doubtful points.

    Parameters
    ----------
    frames : (T, H, W) ndarray or sequence
        Grayscale frames (uint8, uint16 or float), anything
        :func:`wingphoto.io.read_sequence` returns (``len`` and ``[i]``); read one at a
        time, so memory does not grow with the sequence length.
    picks : (N, 2) array_like, or DataFrame / list of dicts
        Each marker's position in frame 0: (x, y) clicks in px (origin at the centre of the
        top-left pixel; rounding to the pixel is fine), the template size then chosen from
        the blob; or the picker's saved picks with columns ``point, x, y`` and optionally
        ``half_size`` (template half width, px) or ``rect`` (``(x0, y0, width, height)``).
        A NaN pick (a marker not visible in frame 0) gives that point ``lost`` rows with
        reason ``no_pick`` (and a logged warning).
    camera : str
        Value of the ``camera`` column.
    search_radius : int, optional
        Largest search radius in px (default 20): used on frame 1, where no velocity is
        known yet, and as the cap of the prediction-driven radius. Must exceed the largest
        motion between frames 0 and 1.
    min_score, lost_score : float
        Correlation (TM_CCOEFF_NORMED) below ``min_score`` is flagged ``low_score``, below
        ``lost_score`` lost.
    ambiguity_margin : float
        Flag ``ambiguous`` when a second, unexplained correlation peak comes within this
        margin of the best.
    update_score, refresh_below, update_rate, original_weight : float
        Template update: when ``update_score <= score < refresh_below`` the template cut at
        the refined centre is blended into the running template with weight
        ``update_rate``; the matched template is ``original_weight * original +
        (1 - original_weight) * running``.
    max_coast : int
        Frames a marker may go without a reliable position before it is declared lost
        (``lost_track``) and searched for from its neighbours.
    reacquire_radius, reacquire_score : int, float
        Search radius and minimum score to re-acquire a lost marker.
    min_mass_ratio : float
        Flag ``no_signal`` when the blob's integrated brightness drops below this fraction
        of its frame-0 value.
    max_mass_ratio : float, optional
        Flag ``merged`` when the integrated brightness exceeds this multiple of its running
        value (a blob that grew by merging with something). Off by default.
    jump_px : float
        Smallest distance (px) between refined and predicted position flagged ``jump``; the
        limit is ``max(jump_px, 4 sigma + 2 (frames coasted))``.
    max_score_drop : float, optional
        Flag ``appearance`` when the correlation falls by more than this below its running
        value in one frame: catches an *untracked* look-alike (a glare spot, an unpicked
        marker) merging with a marker. Off by default: on wing sequences the glare sweeps
        make it flag good points, which then coast.
    update_every : int
        At most one template update per marker every this many frames.
    search_every : int
        A marker on the fast path (moving predictably, alone, matched with score >= 0.9)
        gets the full windowed NCC search only every ``search_every`` frames (staggered
        across markers); in between it is refined at its prediction and verified by the
        NCC score there (>= 0.85), the residual to the prediction and its brightness; a
        failed verification triggers the full search on the same frame. 1 searches every
        marker on every frame (slower).
    polarity : {"auto", 1, -1}
        Bright (1) or dark (-1) markers; "auto" decides per marker from frame 0.
    bidirectional : bool
        Also track backwards from the last frame; flag ``fb_disagree`` where the passes
        disagree by more than ``fb_tolerance`` px and use the backward position where only
        it is ok. Doubles the run time.
    checkpoint : str or Path, optional
        File (``.npz``) holding the state; saved atomically every ``checkpoint_every``
        frames and when the run stops on an exception. If it exists and was written for
        the same frames, picks and options, tracking resumes from it with identical
        results.
    checkpoint_every : int
        Frames between two checkpoint saves (default 500).
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    tracks : pandas.DataFrame
        One row per (frame, point): camera, frame, point, x, y (sub-pixel centre, px), score
        (correlation peak), status (ok / flagged / lost), x_pix, y_pix (pixel-level match,
        NaN where there was none), reason ("" when ok). x, y are NaN when lost; a flagged
        point carries its best guess. Frame 0 holds the refined picks (score 1). Reasons
        (:data:`REASONS`; module docstring, 7): ``low_score``, ``ambiguous``, ``merged``, ``conflict``,
        ``jump``, ``no_signal``, ``appearance``, ``edge``, ``out_of_frame``,
        ``lost_track`` (coasted longer than ``max_coast``), ``reacquired`` (first frame
        after a re-acquisition), ``fb_disagree``, ``no_pick``, ``pick_moved`` (frame 0:
        the refinement moved the click by more than 1.5 px, or saw a foreign blob or a
        rough background; the click is kept), ``foreign`` (something bright not
        explained by a known marker touches the disk), ``background`` (the background
        around the marker is not flat enough for its contrast); :func:`check_stereo` adds
        ``stereo``.

    Raises
    ------
    ValueError
        Empty sequence, frames of different sizes or bit depths, NaN picks, a pick outside
        the image, not on a marker, or too close to the edge for its template, a template
        larger than the image, a checkpoint written for other inputs.

    Notes
    -----
    The design and the failure each choice prevents are listed in the module docstring
    (:mod:`wingphoto.track`). Conventions: ``docs/conventions.md``.

    Examples
    --------
    >>> yy, xx = np.mgrid[:40, :50]
    >>> frames = np.stack([100 * (np.hypot(xx - 20 - k, yy - 18) < 4) for k in range(5)]).astype(np.uint8)
    >>> t = track_markers(frames, [[20, 18]], progress=False)
    >>> last = t[t.frame == 4].iloc[0]
    >>> float(round(last.x, 3)), float(round(last.y, 3)), last.status
    (24.0, 18.0, 'ok')
    """
    fr = _Frames(frames)
    xy_all, ids_all, half_all = _parse_picks(picks)
    active = np.all(np.isfinite(xy_all), axis=1)
    if not active.all():
        logger.warning("picks of points %s are NaN: those points are reported lost (reason 'no_pick')",
                       ids_all[~active].tolist())
    xy, ids, half = xy_all[active], ids_all[active], half_all[active]
    options = dict(locals())
    p = _Params(**{k: options[k] for k in _PARAM_DEFAULTS})
    T, N = fr.n, len(xy)
    shape = fr.shape
    fw = _Results(T, N)
    bw = _Results(T, N) if bidirectional else None
    box = {}

    def state():
        meta = {"phase": box["phase"], "next": box["next"]}
        arrays = fw.arrays("fw_")
        if bw is not None:
            arrays.update(bw.arrays("bw_"))
        arrays.update({"st_" + k: v for k, v in box["tracker"].state().items()})
        return meta, arrays

    ck = None
    resumed = None
    if checkpoint is not None:
        fp = _fingerprint(fr, xy, ids, half, p, camera, bidirectional)
        ck = _Checkpointer(checkpoint, fp, checkpoint_every, state)
        if Path(checkpoint).exists():
            resumed = _load_checkpoint(checkpoint, fp)
    if resumed is None:
        tracker = _Tracker.from_picks(fr[0], xy, half, p, fr.is_u8, ids)
        fw.x[0], fw.y[0] = tracker.pos[:, 0], tracker.pos[:, 1]
        fw.xpix[0], fw.ypix[0] = np.rint(tracker.pos[:, 0]), np.rint(tracker.pos[:, 1])
        fw.score[0] = 1.0
        fw.status[0] = OK
        # a click is within ~0.7 px of a marker's centre: a refinement that moved further
        # was pulled by something (an unpicked neighbour, glare); the click is kept
        moved = tracker.pick_moved
        fw.status[0, moved] = FLAGGED
        fw.reason[0, moved] = _R["pick_moved"]
        box.update(phase="forward", next=1, tracker=tracker)
    else:
        meta, arrays = resumed
        fw.load(arrays, "fw_")
        if bw is not None and "bw_x" in arrays:
            bw.load(arrays, "bw_")
        st = {k[3:]: v for k, v in arrays.items() if k.startswith("st_")}
        tracker = _Tracker.from_state(st, p, fr.is_u8, shape)
        box.update(phase=meta["phase"], next=int(meta["next"]), tracker=tracker)
        logger.info("resuming %s pass at frame %d from %s", meta["phase"], meta["next"], checkpoint)

    if ck is not None:
        orig_completed = ck.completed

        def completed(t):
            box["next"] = t + (1 if box["phase"] == "forward" else -1)
            orig_completed(t)

        ck.completed = completed

    if box["phase"] == "forward":
        _run_pass(fr, box["tracker"], fw, range(box["next"], T), 1, ck, progress, f"track {camera}")
        if bidirectional:
            box["tracker"] = _backward_tracker(box["tracker"], fw, T)
            box.update(phase="backward", next=T - 2)
            bw.x[T - 1], bw.y[T - 1] = fw.x[T - 1], fw.y[T - 1]
            bw.status[T - 1], bw.reason[T - 1] = fw.status[T - 1], fw.reason[T - 1]
            bw.score[T - 1] = fw.score[T - 1]
            bw.xpix[T - 1], bw.ypix[T - 1] = fw.xpix[T - 1], fw.ypix[T - 1]
    if box["phase"] == "backward":
        _run_pass(fr, box["tracker"], bw, range(box["next"], -1, -1), -1, ck, progress, f"back {camera}")
    if box["phase"] in ("forward", "backward"):
        box["phase"] = "done"
        box["next"] = T
        if ck is not None:
            ck.save()
    if bidirectional:
        fw2 = _Results(T, N)
        for k in _Results.names + ("status", "reason"):
            getattr(fw2, k)[...] = getattr(fw, k)
        _merge_backward(fw2, bw, p.fb_tolerance)
        return _tracks_frame(_expand(fw2, active), ids_all, camera)
    return _tracks_frame(_expand(fw, active), ids_all, camera)


def _expand(res, active):
    """Results of the picked points, with lost rows ('no_pick') for points without a pick."""
    if active.all():
        return res
    T = res.x.shape[0]
    out = _Results(T, len(active))
    for k in _Results.names + ("status", "reason"):
        getattr(out, k)[:, active] = getattr(res, k)
    out.reason[:, ~active] = _R["no_pick"]
    return out


def _backward_tracker(fwd, fw, T):
    """A tracker seeded at the last frame from the forward pass (same templates)."""
    import copy

    b = copy.copy(fwd)
    n = len(fwd.h)
    b.hist_x = np.full((n, 3, 2), np.nan)
    b.hist_t = np.zeros((n, 3), np.int64)
    b.nh = np.ones(n, np.int64)
    b.lostflag = np.zeros(n, bool)
    b.sigma = np.ones(n)
    b.last_upd = np.full(n, T - 1, np.int64)
    b.last_ok = np.full(n, T - 1, np.int64)
    b.tplr = [t.copy() for t in fwd.tpl0]
    b.tplu = [None] * n
    b.last_score = np.ones(n)
    b._init_stack()
    for i in range(n):
        okf = np.flatnonzero(fw.status[:, i] == OK)
        tl = int(okf[-1]) if okf.size else 0
        b.hist_x[i, 0] = (fw.x[tl, i], fw.y[tl, i])
        b.hist_t[i, 0] = tl
        b.last_ok[i] = tl
        b.lostflag[i] = tl < T - 1 - fwd.p.max_coast
    return b


# --------------------------------------------------------------------------- stereo
def check_stereo(tracks_left, tracks_right, rig, *, max_epipolar_px=2.0, max_reproj_px=2.0,
                 trusted=("ok", "manual", "interpolated")):
    """Flag left/right pairs that are not geometrically consistent.

    Parameters
    ----------
    tracks_left, tracks_right : pandas.DataFrame
        Tracks of the two cameras (columns frame, point, x, y, status).
    rig : StereoRig
        The calibrated rig (``docs/conventions.md``).
    max_epipolar_px : float
        Largest symmetric epipolar distance (:meth:`StereoRig.epipolar_distance`, px, lens
        distortion removed) of a consistent pair.
    max_reproj_px : float
        Largest reprojection error (px, the worse of the two views) of the pair's
        triangulated point (:func:`wingphoto.triangulate.stereo_triangulation`).
    trusted : tuple of str
        Statuses whose positions are checked (both views must be trusted).

    Returns
    -------
    tracks_left, tracks_right : pandas.DataFrame
        Copies in which the ``ok`` rows of an inconsistent pair become ``flagged`` with
        reason ``stereo`` (``manual`` and ``interpolated`` rows keep their status: the
        user decided). Two columns are added: ``epipolar_px`` and ``reproj_px`` (NaN where
        the pair was not checked).

    Notes
    -----
    A marker swapped with another in one view (the classic tracking error) leaves the
    pair off the epipolar geometry and is caught, unless the two markers lie on the same
    epipolar line (within the threshold): geometry alone cannot see that swap.

    Examples
    --------
    >>> import pandas as pd
    >>> from wingphoto.camera import Camera, StereoRig
    >>> cam = Camera(fc=[1000, 1000], cc=[255.5, 255.5])
    >>> rig = StereoRig(cam, cam, om=[0, 0, 0], T=[-100, 0, 0])
    >>> xL, xR = rig.project([[10.0, 5.0, 800.0], [-20.0, 30.0, 800.0]])
    >>> tl = pd.DataFrame({"frame": 0, "point": [0, 1], "x": xL[:, 0], "y": xL[:, 1], "status": "ok"})
    >>> tr = pd.DataFrame({"frame": 0, "point": [0, 1], "x": xR[::-1, 0], "y": xR[::-1, 1], "status": "ok"})
    >>> l2, r2 = check_stereo(tl, tr, rig)
    >>> l2.status.tolist(), r2.reason.tolist()
    (['flagged', 'flagged'], ['stereo', 'stereo'])
    """
    from .camera import StereoRig
    from .triangulate import reprojection_error, stereo_triangulation

    if not isinstance(rig, StereoRig):
        raise ValueError(f"rig must be a wingphoto.StereoRig, got {type(rig).__name__}")
    for name, t in (("tracks_left", tracks_left), ("tracks_right", tracks_right)):
        missing = [c for c in ("frame", "point", "x", "y", "status") if c not in t.columns]
        if missing:
            raise ValueError(f"{name} lacks columns {missing}; expected a tracks DataFrame")
    L = tracks_left.copy()
    R = tracks_right.copy()
    for t in (L, R):
        if "reason" not in t.columns:
            t["reason"] = ""
        t["reason"] = t["reason"].fillna("").astype(str)
        t["epipolar_px"] = np.nan
        t["reproj_px"] = np.nan
    key = ["frame", "point"]
    li = L.reset_index()[key + ["index", "x", "y", "status"]]
    ri = R.reset_index()[key + ["index", "x", "y", "status"]]
    m = li.merge(ri, on=key, suffixes=("_l", "_r"))
    m = m[m["status_l"].isin(trusted) & m["status_r"].isin(trusted)]
    xl = m[["x_l", "y_l"]].to_numpy(float)
    xr = m[["x_r", "y_r"]].to_numpy(float)
    fin = np.all(np.isfinite(xl), 1) & np.all(np.isfinite(xr), 1)
    m, xl, xr = m[fin], xl[fin], xr[fin]
    if len(m) == 0:
        return L, R
    epi = np.asarray(rig.epipolar_distance(xl, xr), float).reshape(-1)
    XL, _ = stereo_triangulation(xl, xr, rig)
    rep = reprojection_error(np.asarray(XL).reshape(-1, 3), xl, xr, rig).max(axis=1)
    bad = ~((epi <= max_epipolar_px) & (rep <= max_reproj_px))
    for t, col in ((L, "index_l"), (R, "index_r")):
        idx = m[col].to_numpy()
        t.loc[idx, "epipolar_px"] = epi
        t.loc[idx, "reproj_px"] = rep
        flag = idx[bad]
        flag = flag[(t.loc[flag, "status"] == "ok").to_numpy()]
        t.loc[flag, "status"] = "flagged"
        t.loc[flag, "reason"] = "stereo"
    return L, R


# --------------------------------------------------------------------------- corrections
CORRECTION_COLUMNS = ["point", "frame", "x", "y"]


def _as_corrections(corrections):
    import pandas as pd

    if isinstance(corrections, pd.DataFrame):
        c = corrections.copy()
    else:
        rows = list(corrections)
        if rows and hasattr(rows[0], "_asdict"):  # wingphoto.widgets.state.Correction
            rows = [r._asdict() for r in rows]
        elif rows and not isinstance(rows[0], dict):
            # (point, frame, x, y) or, as the review widget logs them, (camera, point, frame, x, y)
            rows = [dict(zip(CORRECTION_COLUMNS if len(r) == 4 else ["camera"] + CORRECTION_COLUMNS, r))
                    for r in rows]
        c = pd.DataFrame(rows, columns=None if rows else CORRECTION_COLUMNS)
    missing = [k for k in CORRECTION_COLUMNS if k not in c.columns]
    if missing:
        raise ValueError(f"corrections lack columns {missing}; each correction is (point, frame, x, y)")
    c["point"] = c["point"].astype(np.int64)
    c["frame"] = c["frame"].astype(np.int64)
    c["x"] = c["x"].astype(np.float64)
    c["y"] = c["y"].astype(np.float64)
    if "camera" in c.columns:
        c["camera"] = c["camera"].astype(str)
    return c.reset_index(drop=True)


def save_corrections(corrections, path):
    """Save a corrections log (point, frame, x, y[, camera, ...]) as CSV or JSON, atomically.

    Parameters
    ----------
    corrections : DataFrame or list of dicts / (point, frame, x, y) tuples
        The log, in the order the corrections were made (replaying it in order gives the
        same tracks; a later correction of the same point-frame wins). The review
        widget's ``Correction(camera, point, frame, x, y)`` entries are accepted too.
    path : str or Path
        ``.csv`` or ``.json`` (``{"format": "wingphoto-corrections", "version": 1,
        "corrections": [records]}``, the widget's format). Written via
        :func:`wingphoto.io.atomic_write`, so an interrupted save leaves the previous
        file intact.

    Returns
    -------
    pathlib.Path
    """
    from .io import atomic_write

    path = Path(path)
    c = _as_corrections(corrections)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".json"):
        raise ValueError(f"corrections path must end in .csv or .json, got {path.name!r}")
    if suffix == ".csv":
        text = c.to_csv(index=False, float_format="%.17g")
    else:
        recs = c.to_dict(orient="records")
        for r in recs:
            for k, v in r.items():
                if isinstance(v, float) and not np.isfinite(v):
                    r[k] = None
                elif isinstance(v, np.generic):
                    r[k] = v.item()
        text = json.dumps({"format": "wingphoto-corrections", "version": 1, "corrections": recs}, indent=1)
    with atomic_write(path, "w") as f:
        f.write(text)
    return path


def load_corrections(path):
    """Load a corrections log written by :func:`save_corrections` (CSV or JSON).

    Returns
    -------
    pandas.DataFrame
        Columns point (int64), frame (int64), x, y (float64, NaN marks a point the user
        declared lost), plus any extra columns saved (the review widget's ``camera``).

    Raises
    ------
    FileNotFoundError
        When ``path`` does not exist.
    ValueError
        When the suffix is not .csv/.json, the JSON is not a wingphoto corrections file,
        or columns are missing.
    """
    import pandas as pd

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".json"):
        raise ValueError(f"corrections path must end in .csv or .json, got {path.name!r}")
    if not path.is_file():
        raise FileNotFoundError(f"corrections file {path} not found: it does not exist (check the path)")
    if suffix == ".csv":
        c = pd.read_csv(path, dtype={"camera": str})
    else:
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise ValueError(f"corrections file {path} is not valid JSON: {exc}") from None
        if not (isinstance(data, dict) and data.get("format") == "wingphoto-corrections"
                and isinstance(data.get("corrections"), list)):
            raise ValueError(f"corrections file {path} is not a wingphoto corrections file "
                             "(a JSON object with format 'wingphoto-corrections' and a corrections list)")
        recs = data["corrections"]
        if not all(isinstance(r, dict) for r in recs):
            raise ValueError(f"corrections file {path} is malformed: each correction must be an object")
        c = pd.DataFrame(recs, columns=None if recs else CORRECTION_COLUMNS)
    missing = [k for k in CORRECTION_COLUMNS if k not in c.columns]
    if missing:
        raise ValueError(f"corrections file {path} lacks columns {missing}; each correction is (point, frame, x, y)")
    return _as_corrections(c)


def apply_corrections(tracks, corrections):
    """Replay a corrections log onto tracks (the one implementation: the review widget's
    :class:`~wingphoto.widgets.state.ReviewState` applies its log with it too).

    Parameters
    ----------
    tracks : pandas.DataFrame
        Tracks (columns frame, point, x, y, status; ``camera``, ``score``, ``reason``,
        ``x_pix``, ``y_pix`` optional); not modified.
    corrections : DataFrame or list
        Log of (point, frame, x, y) - DataFrame rows, dicts, tuples, or the review
        widget's ``Correction(camera, point, frame, x, y)`` - applied in order, so a later
        correction of the same point and frame wins. A correction with NaN x, y declares
        the point lost on that frame. With a ``camera`` column a correction applies to the
        rows of that camera only; without one, to that point and frame in every camera.

    Returns
    -------
    pandas.DataFrame
        A copy whose corrected rows have x, y replaced and status ``manual`` (``lost`` for
        NaN), score NaN (a hand-placed position has no correlation score), reason ``""``
        (``"manual"`` when declared lost), and ``x_pix, y_pix`` the rounded position -
        each column only where ``tracks`` has it. A correction for a point and frame
        without a row adds the row (a point the tracker was not given, a frame beyond the
        tracked ones); the result is then sorted by camera, frame and point. Column
        dtypes are kept.

    Raises
    ------
    ValueError
        Missing columns in ``tracks`` or in the corrections, or a correction without a
        camera for a row to add to tracks of several cameras.

    Examples
    --------
    >>> import pandas as pd
    >>> t = pd.DataFrame({"frame": [0, 1], "point": 0, "x": [5.0, 6.0], "y": 5.0,
    ...                   "score": 0.9, "status": ["ok", "flagged"]})
    >>> row = apply_corrections(t, [(0, 1, 6.5, 5.25)]).iloc[1]
    >>> float(row.x), float(row.y), row.status, bool(np.isnan(row.score))
    (6.5, 5.25, 'manual', True)
    """
    import pandas as pd

    missing = [k for k in ("frame", "point", "x", "y", "status") if k not in tracks.columns]
    if missing:
        raise ValueError(f"tracks lacks columns {missing}; expected a tracks DataFrame (frame, point, x, y, status)")
    c = _as_corrections(corrections)
    out = tracks.copy()
    if len(c) == 0:
        return out
    by_cam = "camera" in out.columns and "camera" in c.columns
    key = ["camera", "frame", "point"] if by_cam else ["frame", "point"]
    c = c.drop_duplicates(subset=key, keep="last").reset_index(drop=True)
    rows = out[key].astype({"frame": np.int64, "point": np.int64}).reset_index().merge(c[key].reset_index(),
                                                                                       on=key, suffixes=("", "_c"))
    lost = ~(np.isfinite(c["x"].to_numpy()) & np.isfinite(c["y"].to_numpy()))

    def fill(frame, at, ci):
        x = np.where(lost[ci], np.nan, c["x"].to_numpy()[ci])
        y = np.where(lost[ci], np.nan, c["y"].to_numpy()[ci])
        frame.loc[at, "x"] = x
        frame.loc[at, "y"] = y
        frame.loc[at, "status"] = np.where(lost[ci], "lost", "manual")
        if "score" in frame.columns:
            frame.loc[at, "score"] = np.nan
        if "reason" in frame.columns:
            frame.loc[at, "reason"] = np.where(lost[ci], "manual", "")
        for pix, v in (("x_pix", x), ("y_pix", y)):
            if pix in frame.columns:
                frame.loc[at, pix] = np.rint(v)

    fill(out, rows["index"].to_numpy(), rows["index_c"].to_numpy())
    absent = np.setdiff1d(np.arange(len(c)), rows["index_c"].to_numpy())
    if absent.size:
        extra = pd.DataFrame({k: c[k].to_numpy()[absent] for k in key})
        if "camera" in out.columns and "camera" not in extra.columns:
            cams = out["camera"].astype(str).unique()
            if len(cams) != 1:
                p0, f0 = int(c["point"].iloc[absent[0]]), int(c["frame"].iloc[absent[0]])
                raise ValueError(
                    f"correction of point {p0} on frame {f0} has no row in tracks of cameras {sorted(cams)}: "
                    "give its camera (a camera column in the corrections) to add the row"
                )
            extra.insert(0, "camera", cams[0])
        for col in out.columns:
            if col not in extra.columns:
                numeric = pd.api.types.is_numeric_dtype(out[col].dtype)
                extra[col] = np.full(absent.size, np.nan) if numeric else np.full(absent.size, "", dtype=object)
        extra = extra[list(out.columns)]
        fill(extra, np.arange(absent.size), absent)
        dtypes = out.dtypes.to_dict()
        extra = extra.astype({k: v for k, v in dtypes.items() if not (pd.api.types.is_integer_dtype(v)
                                                                      and extra[k].isna().any())})
        out = pd.concat([out, extra], ignore_index=True)
        order = [k for k in ("camera", "frame", "point") if k in out.columns]
        out = out.sort_values(order, kind="stable").reset_index(drop=True)
    return out


def retrack_from(frames, tracks, points, frame, *, camera=None, stop=None, conflict_px=3.0,
                 progress=True, **options):
    """Re-track some points forward from a (corrected) frame.

    Parameters
    ----------
    frames : (T, H, W) ndarray or sequence
        The frames the tracks were made from.
    tracks : pandas.DataFrame
        Tracks, typically after :func:`apply_corrections`; the positions of ``points`` on
        ``frame`` (and on the two frames before, when trusted, for the velocity) seed the
        re-tracking.
    points : int or sequence of int
        Point ids to re-track.
    frame : int
        Frame to start from (its rows are kept as they are).
    camera : str, optional
        Rows of this camera when ``tracks`` holds several.
    stop : int, optional
        Last frame to re-track (default: the last frame).
    conflict_px : float
        A re-tracked ok position closer than this to another (not re-tracked) point's ok or
        manual position on the same frame is flagged ``conflict``.
    **options
        Tracking options of :func:`track_markers` (``min_score``, ``search_radius``...).

    Returns
    -------
    pandas.DataFrame
        A copy of ``tracks`` whose rows for ``points`` on frames ``frame + 1 .. stop`` are
        replaced by the re-tracked ones.
    """
    fr = _Frames(frames)
    pts = np.atleast_1d(np.asarray(points, dtype=np.int64))
    t = tracks
    if camera is not None and "camera" in t.columns:
        t = t[t["camera"] == camera]
    frame = int(frame)
    stop = fr.n - 1 if stop is None else int(stop)
    if not 0 <= frame < fr.n:
        raise ValueError(f"frame must be in [0, {fr.n - 1}], got {frame}")
    if not frame <= stop < fr.n:
        raise ValueError(f"stop must be in [{frame}, {fr.n - 1}], got {stop}")
    sel = t[(t["frame"] == frame) & t["point"].isin(pts)].drop_duplicates("point").set_index("point")
    missing = [int(q) for q in pts if q not in sel.index]
    if missing:
        raise ValueError(f"tracks have no row for points {missing} on frame {frame}")
    seed = sel.loc[pts, ["x", "y"]].to_numpy(float)
    bad = ~np.all(np.isfinite(seed), 1)
    if bad.any():
        raise ValueError(
            f"points {pts[bad].tolist()} have no position on frame {frame}; correct them first "
            "(apply_corrections) and re-track from the corrected frame"
        )
    progress_opt = options.pop("progress", progress)
    opts = {k: options.pop(k) for k in list(options) if k in _PARAM_DEFAULTS}
    if options:
        raise TypeError(f"unknown option(s) {sorted(options)}")
    if "search_radius" in opts and opts["search_radius"] is None:
        opts.pop("search_radius")
    p = _Params(**opts)
    tracker = _Tracker.from_picks(fr[frame], seed, np.full(len(pts), -1, np.int64), p, fr.is_u8, pts)
    # the corrected position is the user's: keep it exactly as the seed
    tracker.hist_x[:, 0] = seed
    tracker.hist_t[:, 0] = frame
    tracker.last_ok[:] = frame
    tracker.last_upd[:] = frame
    trusted = ("ok", "manual", "interpolated")
    for k, back in ((1, 1), (2, 2)):
        prev = t[(t["frame"] == frame - back) & t["point"].isin(pts)].drop_duplicates("point").set_index("point")
        for i, q in enumerate(pts):
            if (tracker.nh[i] == k and q in prev.index and prev.at[q, "status"] in trusted
                    and np.isfinite(prev.at[q, "x"])):
                tracker.hist_x[i, k] = (prev.at[q, "x"], prev.at[q, "y"])
                tracker.hist_t[i, k] = frame - back
                tracker.nh[i] = k + 1
    res = _Results(fr.n, len(pts))
    res.x[frame], res.y[frame] = seed[:, 0], seed[:, 1]
    res.status[frame] = OK
    _run_pass(fr, tracker, res, range(frame + 1, stop + 1), 1, None, progress_opt, "retrack")
    new = _tracks_frame(res, pts, camera if camera is not None else "left")
    new = new[(new["frame"] > frame) & (new["frame"] <= stop)]
    out = tracks.copy()
    if "reason" not in out.columns:
        out["reason"] = ""
    for c in ("x_pix", "y_pix"):
        if c not in out.columns:
            out[c] = np.nan
    mask = out["point"].isin(pts) & (out["frame"] > frame) & (out["frame"] <= stop)
    if camera is not None and "camera" in out.columns:
        mask &= out["camera"] == camera
    idx = out.index[mask]
    sub = out.loc[idx, ["frame", "point"]].reset_index()
    sub = sub.merge(new, on=["frame", "point"], how="left")
    for c in ("x", "y", "score", "status", "x_pix", "y_pix", "reason"):
        if c in out.columns:
            out.loc[sub["index"].to_numpy(), c] = sub[c].to_numpy()
    # a re-tracked point must not sit on another point
    others = out[~out["point"].isin(pts) & out["status"].isin(("ok", "manual")) & (out["frame"] > frame)
                 & (out["frame"] <= stop)]
    if camera is not None and "camera" in others.columns:
        others = others[others["camera"] == camera]
    mine = out.loc[idx]
    mine = mine[mine["status"] == "ok"]
    if len(mine) and len(others):
        m = mine.reset_index().merge(others[["frame", "x", "y"]], on="frame", suffixes=("", "_o"))
        close = np.hypot(m["x"] - m["x_o"], m["y"] - m["y_o"]) < conflict_px
        hit = m.loc[close, "index"].unique()
        out.loc[hit, "status"] = "flagged"
        out.loc[hit, "reason"] = "conflict"
    return out
