"""Sub-pixel centring: the background-subtracted, thresholded centroid (both engines).

The background itself (the ring's plane, its curvature, the membrane's edge) is fitted by
:mod:`.background`."""
from __future__ import annotations

import math

import numpy as np

from . import engine
from .background import (QUAD_BGRES, QUAD_MIN, _dark_side, _disk_peak, _edge_plane, _median_inplace, _plane,
                         _ring_plane, _ring_rms, _ring_saddle, _saddle)
from .engine import jit
from .options import _MERGE_VALLEY, _RD_MIN


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
        self.basis5 = np.ascontiguousarray(np.stack([one, gx, gy, gx * gx - gy * gy, gx * gy], axis=1))  # (K, 5)
        self.basis5t = np.ascontiguousarray(self.basis5.T)
        self.basis5f = self.basis5.astype(np.float64)
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


#: Ring outliers (foreign signal) are pixels brighter than the fitted background by this
#: fraction of the marker's peak (and by FOREIGN_NOISE noise sigmas).
FOREIGN_FRACTION = 0.25
FOREIGN_NOISE = 6.0
#: The centroid weighs each disk pixel by its background-subtracted value minus this
#: fraction of the peak (pixels below it get no weight).
WEIGHT_FRACTION = 0.2
#: ... and clipped at this multiple of the blob's median value above that cut: a bright
#: spot on a marker (a specular highlight) then weighs little more than its face (1.0
#: clipped faded, edge-on smears so hard that a re-acquired marker landed on a neighbour;
#: 1.05, with the contrast cut below, gave specular_markers 94 % within 3 sigma instead of
#: 75 % and RMS 0.026 px instead of 0.047, but 14 confident errors on realdots cam2 DEV
#: seed 0, faint dots on a noisy sensor, instead of 0).
CLIP_LEVEL = 1.2
#: ``dshape`` (the blob's uneven brightness, a term of sigma): how far the centre moves when
#: the weights are clipped at SHAPE_CLIP of the way from the cut to the face's median
#: instead (a uniform face, whatever its outline and blur, does not move it).
SHAPE_CLIP = 0.5
#: ... and, added in quadrature, SHAPE_BIN_GAIN times how far beyond SHAPE_BIN_FLOOR px it
#: moves when every pixel above the cut weighs alike (the shape's own centre): a specular
#: spot drawn by motion blur into a streak over much of a dot is above the clip level
#: wherever it lies, and clipping hardly moves the centre, while the shape's centre is
#: where the dot is (real dots cam1, DEV seeds 5, 6, 29, 30: 15 ok points 1.0-1.4 px off
#: at sigma 0.21-0.25)
SHAPE_BIN_GAIN, SHAPE_BIN_FLOOR = 1.0, 0.2
#: ... and, added in quadrature, LOW_CUT_GAIN times how far beyond LOW_CUT_FLOOR px it
#: moves to the centre of the pixels of the disk and its ring (not the ring's outliers)
#: more than LOW_CUT_NOISE noise sigmas and LOW_CUT_CONTRAST of the contrast above the
#: background: the shape the whole face draws, faint parts included. A specular spot
#: streaked by motion blur outshines a dim face at every cut taken from the contrast, so
#: the centroid and the shape above the cut both follow the streak, and the disk, sized
#: on the bright blob, holds only part of the face; the ring holds the rest (real dots
#: cam1, dropped-frame stress seeds 454, 568, 631: 10 ok points 1.0-1.4 px off at sigma
#: 0.17-0.24, the low-cut centre 0.5-1.3 px from theirs). Not where the edge rule chose
#: the background (the membrane beyond an edge is "above" the dark side's plane), and
#: the contrast share keeps a membrane edge or glare that the plane leaves in the ring
#: out (without it, clean_glare DEV lost 1.2 % of its ok points, edge_on 12 %); nor
#: where more than LOW_CUT_OPEN of the ring's outer pixels are above the cut - a face
#: runs out of the ring there, a membrane beyond an edge a few px away (a marker of the
#: independent renderer's clean DEV seed 0 left: 8-15 % of them on its frames, the
#: low-cut centre ~1 px off its good points; stress seed 568's dim face: none). Nor on the inner disk (:data:`INNER_BGRES`),
#: whose ring lies near the structure it was shrunk away from (independent clean DEV
#: seed 2 left, a marker beside the wing's edge: imprecise at sigma 0.26, 0.17 px off).
#: Chosen on the stress seeds: floor 0.6 px left 2 of the 10, 0.5 left 1; 0.4: none.
#: docs/tracker.md has the cost in ok points.
LOW_CUT_NOISE, LOW_CUT_CONTRAST, LOW_CUT_GAIN, LOW_CUT_FLOOR = 3.0, 0.1, 1.0, 0.4
LOW_CUT_OPEN = 0.05
#: The centroid's cut is WEIGHT_FRACTION of the marker's contrast: its peak, but at most
#: CONTRAST_FACE times its face - the median of its disk pixels above CONTRAST_FLOOR of the
#: peak (and 3 noise sigmas). A small bright highlight on a dim face (real dots: a specular
#: spot of ~200 DN on a ~35 DN face) then does not set the cut: a cut at a fifth of the
#: highlight dropped the face and centred the highlight, up to 2 px off the shape's centre
#: (real photographs: 90th percentile of the error 0.61 -> 0.31 px). A smooth blob (a
#: disc; a Gaussian, whose face is ~0.32 of its peak) keeps its peak.
CONTRAST_FLOOR, CONTRAST_FACE = 0.1, 3.0
#: ``rim`` (a term of sigma): the share of the centroid's weight on the disk's pixels more
#: than ``r - RIM_WIDTH`` px from its centre pixel, times one minus the length of their
#: weighted mean direction (both ends of a streak count, one side - a neighbour's tail,
#: which the foreign and merge rules judge - does not). A blob inside its disk puts ~0
#: there (99 % of ok points < 0.03 on motion_blur extra DEV seeds 3-8); a motion streak
#: longer than the disk 0.05-0.09, and its centre along the streak is then where the disk
#: was placed (0.5-1 px off on motion_blur at 27 px/frame).
RIM_WIDTH = 1.0
#: ``tex`` (a term of sigma): the texture of the blob's inner face - the pixels within
#: ``r - TEX_INSET`` px of the disk's centre pixel (the disk is the blob's radius + 3 px):
#: their standard deviation beyond the pixel noise, relative to their mean. Painted
#: stripes and a specular highlight raise it, and bias the centre (painted_markers DEV:
#: median error 0.006 px below tex 0.008, 0.05 px above 0.05); a uniform face gives ~0.
TEX_INSET = 4.5
#: Where the edge rule (:data:`~.background.EDGE_ARCS`) fires, sigma must say how sure that background is: the centre then
#: also enters ``dshape`` by EDGE_CUT_GAIN times how far it moves when the centroid's cut
#: is EDGE_CUT of the contrast instead of WEIGHT_FRACTION. A wrong background is a ramp
#: under the disk, which pulls the faint pixels near the cut more than the face: at the
#: true positions of 7 DEV sequences (and the two sequences where the rule had made
#: confident errors) the full plane's error was 1.06-1.19 times that move (median;
#: correlation 0.99), the edge plane's 0.99 times; no edge-plane centre with a move
#: below 0.15 px was more than 0.26 px off. (Without this term the rule's centres were
#: trusted as the ring fitted its plane, and a wrong plane gave ok points 1-2 px off.)
EDGE_CUT, EDGE_CUT_GAIN = 0.5, 1.5
#: The inner disk: where the background ring is not a plane (``bgres`` above INNER_BGRES
#: of the contrast), the centre is measured again with the disk INNER_SHRINK px smaller
#: (its ring nearer the blob, away from a membrane edge or a glare ridge a few px off),
#: and that centre, with its own precision terms (``bgres``, ``spread``, ``dshape``,
#: ``rim``, ``tex``), is kept where the blob fits the smaller disk (``rim`` at most
#: INNER_RIM: a blur streak or a painted shape longer than it does not) and its ring is
#: nearer a plane. Mass, peak, valley and the foreign flag stay the full disk's (the
#: identity rules read them). The disk margin (:data:`~.options._RD_MARGIN`, 3 px) is for
#: blur tails; on the independent renderer's sharp disks it put the ring of a marker 5 px
#: from the wing's edge across that edge: face-on imprecise points of clean DEV seeds
#: 0-2, median error 0.64 px (at the truth, full disk 0.57 px, inner 0.09). At the truth
#: of every face-on point-frame there, sigma <= 0.5 px 96.1 -> 99.3 %, within 3 sigma
#: 99.8 -> 99.9 %; our own hard_stroke, motion_blur and painted_markers: the inner disk
#: is taken for < 1 % of points (their blobs fill the disk), nothing changes.
INNER_BGRES, INNER_SHRINK, INNER_RIM = 0.05, 1.5, 0.03
#: A second blob in the disk: a local maximum of the background-subtracted disk more than
#: SECOND_MIN px from the centre, above SECOND_PEAK of the peak, with a dark gap (below
#: SECOND_DIP of its value, as ``_MERGE_VALLEY``) half-way to the centre; both above the
#: noise as a ring outlier (FOREIGN_NOISE sigmas). Another marker's
#: blob that no pixel split took off (its marker mis-tracked, so the split was made against
#: another blob): the point is ``foreign``. The ring's outliers miss it when it lies inside
#: the disk (independent renderer, clean, extra DEV seed 5 right, frame 70: marker 25 held
#: part of marker 9's blob, 7 px away at a 66 deg view, ok 1.0 px off). A saturated or
#: elongated blob has no such gap, a painted texture no gap this deep.
SECOND_MIN, SECOND_PEAK, SECOND_DIP = 2.0, 0.5, 0.5
#: ... and at least SECOND_WIDE of its 8 neighbours above half its value: a blob, not a
#: hot pixel (faint_markers DEV: impulse noise 7 px from a faint marker flagged it foreign).
SECOND_WIDE = 2
#: ... and not on the split neighbour's own blob, whose tail crosses the split: within its
#: disk radius + 0.5 (the ``nbr_r`` of the ring's outliers) less SECOND_EXPLAINED px (its
#: blob radius + 1.5 px; converging discs 7-8 px apart were flagged at the split).
SECOND_EXPLAINED = 2.0


def _face(sig, disk, peak, noise):
    """The face of each blob (see :data:`CONTRAST_FACE`): the median of its disk values
    above CONTRAST_FLOOR of the peak and 3 noise sigmas, (n,) float32, NaN where none is.

    sig : (n, K) background-subtracted patch values (0 outside the disk), disk (n, K) bool,
    peak (n,) the largest of them, noise (n,) the noise sigma."""
    floor = np.maximum(CONTRAST_FLOOR * peak, 3.0 * np.asarray(noise, np.float32)).astype(np.float32)
    m = disk & (sig > floor[:, None])
    out = np.full(len(peak), np.nan, np.float32)
    has = m.any(1)
    if has.any():
        out[has] = np.nanmedian(np.where(m[has], sig[has], np.nan), axis=1)
    return out


def _contrast(sig, disk, peak, noise):
    """The contrast of each blob (see :data:`CONTRAST_FACE`): its peak, but at most
    CONTRAST_FACE times its face (:func:`_face`); (n,) float32. Arguments as for
    :func:`_face`."""
    face = _face(sig, disk, peak, noise)
    return np.where(np.isfinite(face), np.minimum(peak, CONTRAST_FACE * face), peak).astype(np.float32)


def _texture(sig, inner, noise):
    """The texture of each blob's inner face (see :data:`TEX_INSET`): (n,) float64.

    sig : (n, K) background-subtracted values, inner (n, K) bool, noise (n,) noise sigma."""
    cnt = inner.sum(1)
    v = np.where(inner, sig, 0.0).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        m1 = v.sum(1) / cnt
        var = (np.where(inner, v - m1[:, None], 0.0) ** 2).sum(1) / cnt
        ex = np.maximum(var - np.asarray(noise, np.float64) ** 2, 0.0)
        return np.where((cnt > 0) & (m1 > 0), np.sqrt(ex) / m1, 0.0)


def _centroid_pass(frame, ix, iy, rd, sign, nb, noise, nbr_r=None, wfrac=WEIGHT_FRACTION, face=True):
    """One background-subtracted centroid pass around integer pixels (ix, iy).

    rd : (n,) disk radius (px); the background plane is fitted on the 2 px ring outside.
    sign : (n,) polarity (+1 bright, -1 dark markers).
    nb : (n, 2) offset of the nearest neighbour from (ix, iy), NaN for none, or None.
    noise : (n,) noise sigma (grey levels) of each marker's neighbourhood.
    nbr_r : (n,) radius of the neighbour's blob (its disk radius): bright ring pixels
        within it are explained by the neighbour, not foreign.
    face : bool, the low-cut part of ``dshape`` (:data:`LOW_CUT_NOISE`; not on the inner
        disk, whose ring is near the structure it was shrunk away from).

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
    dark = _dark_side(patch, rin, disk, coef, res, sig, peak, noise, bgres, grid,
                      np.maximum(FOREIGN_FRACTION * peak, FOREIGN_NOISE * noise))
    if dark.any():
        rin &= ~dark
        with np.errstate(invalid="ignore", divide="ignore"):
            bgres = np.sqrt(np.where(rin, res * res, np.float32(0.0)).sum(1) / rin.sum(1)) / peak
    mass = sig.sum(1)
    if wfrac > 0:
        # weights: the value above the cut, clipped at CLIP_LEVEL times the blob's median
        # value above the cut - a bright spot on the marker (a specular highlight) weighs
        # little more than the rest of its face: the centre is nearer the shape's
        contrast = _contrast(sig, disk, peak, noise)
        cut = (wfrac * contrast)[:, None]
        above = sig > cut
        level = np.full(n, np.inf, np.float32)
        flat = np.full(n, np.inf, np.float32)
        has = above.any(1)
        if has.any():
            med = np.nanmedian(np.where(above[has], sig[has], np.nan), axis=1)
            level[has] = CLIP_LEVEL * med
            flat[has] = cut[has, 0] + SHAPE_CLIP * (med - cut[has, 0])
        wgt = np.maximum(np.minimum(sig, level[:, None]) - cut, np.float32(0.0))
        wflat = np.maximum(np.minimum(sig, flat[:, None]) - cut, np.float32(0.0))
    else:
        wgt = np.maximum(sig, 0)
        wflat = wgt
    with np.errstate(invalid="ignore", divide="ignore"):
        d = (wgt @ grid.gxy) / wgt.sum(1)[:, None]
        # the centroid's sensitivity to pixel noise: per-axis std of the centroid for a
        # unit noise on every pixel that carries weight
        supp = wgt > 0
        ex = grid.gx[None, :] - np.nan_to_num(d[:, 0:1])
        ey = grid.gy[None, :] - np.nan_to_num(d[:, 1:2])
        spread = np.sqrt(0.5 * np.where(supp, ex * ex + ey * ey, 0.0).sum(1)) / wgt.sum(1)
        # how far the centre moves when the weights are flattened (clipped at SHAPE_CLIP of
        # the way from the cut to the face's median): the pull of the blob's uneven
        # brightness (texture, a highlight) - a bias the noise does not tell
        ds = (wflat @ grid.gxy) / wflat.sum(1)[:, None]
        dshape = np.hypot(ds[:, 0] - d[:, 0], ds[:, 1] - d[:, 1])
        # ... and when every weighted pixel weighs alike (the shape's centre)
        db = (supp @ grid.gxy) / supp.sum(1)[:, None]
        mb = np.hypot(db[:, 0] - d[:, 0], db[:, 1] - d[:, 1])
        dshape = np.hypot(dshape, SHAPE_BIN_GAIN * np.maximum(np.nan_to_num(mb) - SHAPE_BIN_FLOOR, 0.0))
        # ... and to the centre of the whole face, faint parts included (LOW_CUT_NOISE)
        if wfrac > 0 and face:
            lcut = np.maximum(LOW_CUT_NOISE * np.asarray(noise, np.float32), LOW_CUT_CONTRAST * contrast)
            low = (disk | (ring & ~out)) & (res > lcut[:, None]) & ~dark.any(1)[:, None]
            # (not a face that runs out of the ring: a membrane, a glare ridge)
            outer = ring & (d2 > (r + 1.0) ** 2)
            low &= ((low & outer).sum(1) <= LOW_CUT_OPEN * outer.sum(1))[:, None]
            dl = (low @ grid.gxy) / low.sum(1)[:, None]
            ml = np.hypot(dl[:, 0] - d[:, 0], dl[:, 1] - d[:, 1])
            dshape = np.hypot(dshape, LOW_CUT_GAIN * np.maximum(np.nan_to_num(ml) - LOW_CUT_FLOOR, 0.0))
        # ... and when the background under the disk is curved (background.QUAD_MIN)
        okq = (rin.sum(1) >= QUAD_MIN) & (bgres > QUAD_BGRES)
        if okq.any():
            sq = np.where(disk[okq], patch[okq] - _saddle(patch[okq], rin[okq], grid) @ grid.basis5t,
                          np.float32(0.0))
            if wfrac > 0:
                wq = np.maximum(np.minimum(sq, level[okq, None]) - cut[okq], np.float32(0.0))
            else:
                wq = np.maximum(sq, 0)
            dq = (wq @ grid.gxy) / wq.sum(1)[:, None]
            mq = np.hypot(dq[:, 0] - d[okq, 0], dq[:, 1] - d[okq, 1])
            dshape[okq] = np.hypot(dshape[okq], np.where(wq.sum(1) > 0, mq, 0.0))
        # ... and, where the edge rule chose the background, when the cut is EDGE_CUT
        e = np.flatnonzero(dark.any(1)) if wfrac > 0 else np.empty(0, np.int64)
        if e.size:
            w5 = np.maximum(np.minimum(sig[e], level[e, None]) - (EDGE_CUT * contrast[e])[:, None], np.float32(0.0))
            d5 = (w5 @ grid.gxy) / w5.sum(1)[:, None]
            m5 = np.hypot(d5[:, 0] - d[e, 0], d5[:, 1] - d[e, 1])
            dshape[e] = np.hypot(dshape[e], np.where(w5.sum(1) > 0, EDGE_CUT_GAIN * m5, 0.0))
        # the share of the weight on the disk's rim (its outer RIM_WIDTH px): a blob the
        # disk cuts (a motion streak longer than the disk), whose centre along the cut is
        # where the disk sits, not where the blob is
        onrim = wgt * (d2 > (r - RIM_WIDTH) ** 2)
        rsum = onrim.sum(1)
        dn = np.sqrt(np.maximum(d2, 1e-12))
        rbal = np.hypot((onrim * (grid.gx / dn)).sum(1), (onrim * (grid.gy / dn)).sum(1))
        rim = np.where(rsum > 0, (rsum - rbal) / wgt.sum(1), 0.0)
        rim[~(wgt.sum(1) > 0)] = np.nan
        tex = _texture(sig, disk & (d2 <= np.maximum(r - TEX_INSET, 1.0) ** 2), noise)
        tex[~(wgt.sum(1) > 0)] = np.nan
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
    second = _second_blob(res, disk, peak, noise, fx, fy, grid, nb, nbr_r)
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
    return dict(d=d, mass=mass, peak=peak, nout=nout, frac=frac, dip=dip, omin=omin, bgres=bgres, valley=valley,
                spread=spread, dshape=dshape, rim=rim, tex=tex, second=second)


def _second_blob(res, disk, peak, noise, fx, fy, grid, nb=None, nbr_r=None):
    """Whether each disk holds a second blob (:data:`SECOND_MIN`), from the (n, K)
    background-subtracted patches ``res``, the disk masks (after the pixel split), the
    peaks, the noise and the centroid offsets ``fx, fy`` ((n, 1)); not within the split
    neighbour's blob (``nb`` its offset, ``nbr_r`` its disk radius + 0.5: its blob reaches
    SECOND_EXPLAINED less, its tail crosses the split). numpy twin of
    :func:`_second_blob_kernel`."""
    n, K = res.shape
    hc = grid.hc
    side = 2 * hc + 1
    img = res.reshape(n, side, side)
    # (a local maximum among the disk's own pixels: the other blob's top may lie beyond
    # the disk or the split, its flank inside)
    pad = np.pad(np.where(disk.reshape(n, side, side), img, -np.inf), ((0, 0), (1, 1), (1, 1)),
                 constant_values=-np.inf)
    full = np.pad(img, ((0, 0), (1, 1), (1, 1)), constant_values=-np.inf)
    top = np.full(img.shape, True)
    wide = np.zeros(img.shape, np.int64)  # (neighbours above half its value: a blob, not a hot pixel)
    for a in (-1, 0, 1):
        for b in (-1, 0, 1):
            if a or b:
                top &= img >= pad[:, 1 + b: 1 + b + side, 1 + a: 1 + a + side]
                wide += full[:, 1 + b: 1 + b + side, 1 + a: 1 + a + side] > 0.5 * img
    ex = grid.gx[None, :] - fx
    ey = grid.gy[None, :] - fy
    with np.errstate(invalid="ignore"):
        lo = np.maximum(SECOND_PEAK * peak, FOREIGN_NOISE * np.asarray(noise, np.float64))
        cand = (disk & top.reshape(n, K) & (wide.reshape(n, K) >= SECOND_WIDE) & (res > lo[:, None])
                & (ex * ex + ey * ey > SECOND_MIN ** 2))
        if nb is not None and nbr_r is not None:
            own = np.asarray(nbr_r, np.float64) - SECOND_EXPLAINED
            qx = grid.gx[None, :] - nb[:, 0:1]
            qy = grid.gy[None, :] - nb[:, 1:2]
            cand &= ~(qx * qx + qy * qy <= (own * own)[:, None])  # (NaN: no neighbour, nothing explained)
    out = np.zeros(n, bool)
    for q, k in zip(*np.nonzero(cand)):
        if out[q]:
            continue
        mu = int(np.rint(0.5 * (float(grid.gx[k]) + float(fx[q, 0]))))
        mv = int(np.rint(0.5 * (float(grid.gy[k]) + float(fy[q, 0]))))
        mid = res[q, (mv + hc) * side + mu + hc]
        out[q] = mid < SECOND_DIP * res[q, k] and res[q, k] - mid > FOREIGN_NOISE * noise[q]
    return out


@jit
def _second_blob_kernel(frame, cx, cy, sg, pa, pb, pc, du, dv, dval, nd, dx, dy, peak, noise_i, r2, near, nx_, ny_,
                        half, rr):
    """Compiled twin of :func:`_second_blob` for one disk (``du, dv, dval``: its pixels'
    offsets and raw values times the polarity ``sg``; plane ``pa + pb u + pc v``; the disk:
    ``u^2 + v^2 <= r2`` and, ``near`` a neighbour at ``nx_, ny_``, ``nx_ u + ny_ v < half``)."""
    H, W = frame.shape
    for k in range(nd):
        u = du[k]
        v = dv[k]
        val = dval[k] - (pa + pb * u + pc * v)
        ex = u - dx
        ey = v - dy
        if not (val > max(SECOND_PEAK * peak, FOREIGN_NOISE * noise_i) and ex * ex + ey * ey > SECOND_MIN * SECOND_MIN):
            continue
        if near and not np.isnan(rr):
            own = rr - SECOND_EXPLAINED
            if (u - nx_) * (u - nx_) + (v - ny_) * (v - ny_) <= own * own:
                continue  # (the split neighbour's own blob, its tail across the split)
        top = True
        wide = 0
        for a in range(-1, 2):
            for b in range(-1, 2):
                if a == 0 and b == 0:
                    continue
                ua = u + a
                vb = v + b
                yy = min(max(cy + int(v) + b, 0), H - 1)
                xx = min(max(cx + int(u) + a, 0), W - 1)
                rab = sg * np.float64(frame[yy, xx]) - (pa + pb * ua + pc * vb)
                if rab > 0.5 * val:
                    wide += 1
                if ua * ua + vb * vb > r2 or (near and not (nx_ * ua + ny_ * vb < half)):
                    continue  # (not a pixel of the disk)
                if rab > val:
                    top = False
        if not (top and wide >= SECOND_WIDE):
            continue
        mu = int(np.rint(0.5 * (u + dx)))
        mv = int(np.rint(0.5 * (v + dy)))
        yy = min(max(cy + mv, 0), H - 1)
        xx = min(max(cx + mu, 0), W - 1)
        mid = sg * np.float64(frame[yy, xx]) - (pa + pb * mu + pc * mv)
        if mid < SECOND_DIP * val and val - mid > FOREIGN_NOISE * noise_i:
            return True
    return False




@jit
def _contrast_kernel(du, dv, dval, nd, pa, pb, pc, peak, noise_i, scratch, lo):
    """Compiled twin of :func:`_contrast` for one marker (``scratch[lo:]``: room for the
    disk's values; reordered)."""
    floor = max(CONTRAST_FLOOR * peak, 3.0 * noise_i)
    nl = 0
    for k in range(nd):
        res = dval[k] - (pa + pb * du[k] + pc * dv[k])
        if res > floor:
            scratch[lo + nl] = res
            nl += 1
    if nl == 0:
        return peak
    return min(peak, CONTRAST_FACE * _median_inplace(scratch, lo, nl))


@jit
def _pass1(frame, cx, cy, r, sg, nx_, ny_, noise_i, rr, wfrac, ff, fn, du, dv, dval, ru, rv, rval, routl, qm, rabs,
           face):
    """One centroid pass of one marker (the compiled twin of :func:`_centroid_pass`).

    Returns dx, dy, mass, peak, nout (not explained by the neighbour), frac, dip, omin,
    bgres, valley, spread, dshape, rim, tex, second (:func:`_second_blob_kernel`)."""
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
        routl[k] = 0
    pa, pb, pc = _ring_plane(ru, rv, rval, routl, nr)
    peak = _disk_peak(du, dv, dval, nd, pa, pb, pc)
    thr = max(ff * peak, fn * noise_i)
    nout = 0
    for k in range(nr):
        if rval[k] - (pa + pb * ru[k] + pc * rv[k]) > thr:
            routl[k] = 1
            nout += 1
    if nout > 0 and nr - nout >= 8:
        pa, pb, pc = _ring_plane(ru, rv, rval, routl, nr)
        peak = _disk_peak(du, dv, dval, nd, pa, pb, pc)
    rms, nbg = _ring_rms(ru, rv, rval, routl, nr, pa, pb, pc)
    bg = rms / peak
    # the dark side of an edge (background.EDGE_ARCS)
    found = False
    if bg > QUAD_BGRES:
        found, pa, pb, pc = _edge_plane(ru, rv, rval, routl, nr, du, dv, dval, nd, pa, pb, pc,
                                        max(ff * peak, fn * noise_i), noise_i, rabs)
        if found:
            peak = _disk_peak(du, dv, dval, nd, pa, pb, pc)
            rms, nbg = _ring_rms(ru, rv, rval, routl, nr, pa, pb, pc)
            bg = rms / peak
    # the curved background (QUAD_MIN, QUAD_BGRES), for dshape
    doq = nbg >= QUAD_MIN and bg > QUAD_BGRES
    qa = qb = qc = qd = qe = 0.0
    if doq:
        qa, qb, qc, qd, qe = _ring_saddle(ru, rv, rval, routl, nr, qm)
    contrast = _contrast_kernel(du, dv, dval, nd, pa, pb, pc, peak, noise_i, rval, nr) if wfrac > 0 else 0.0
    cut = wfrac * contrast
    # the centroid at the cut EDGE_CUT, where the edge rule chose the background (for dshape)
    cut5 = EDGE_CUT * contrast
    do5 = found and wfrac > 0
    # the clip level: CLIP_LEVEL times the blob's median value above the cut
    level = np.inf
    flat = np.inf
    if wfrac > 0:
        nl = 0
        for k in range(nd):
            res = dval[k] - (pa + pb * du[k] + pc * dv[k])
            if res > cut:
                rval[nr + nl] = res  # (scratch: the buffer holds the ring, then room)
                nl += 1
        if nl > 0:
            med = _median_inplace(rval, nr, nl)
            level = CLIP_LEVEL * med
            flat = cut + SHAPE_CLIP * (med - cut)
    lcut = max(LOW_CUT_NOISE * noise_i, LOW_CUT_CONTRAST * contrast) if face and not found else np.inf
    ln = lu = lv = 0.0
    no = nlo = 0.0
    ro2 = (r + 1.0) * (r + 1.0)
    for k in range(nr if lcut < np.inf else 0):
        low = routl[k] == 0 and rval[k] - (pa + pb * ru[k] + pc * rv[k]) > lcut
        if ru[k] * ru[k] + rv[k] * rv[k] > ro2:
            no += 1.0
            if low:
                nlo += 1.0
        if low:
            ln += 1.0
            lu += ru[k]
            lv += rv[k]
    if nlo > LOW_CUT_OPEN * no:
        lcut = np.inf  # (a face that runs out of the ring: a membrane, a glare ridge)
        ln = lu = lv = 0.0
    mass = 0.0
    sw = swx = swy = 0.0
    nw = su = sv = suu = svv = 0.0
    fw = fwx = fwy = 0.0
    qw = qwx = qwy = 0.0
    w5s = w5x = w5y = 0.0
    rw = rwx = rwy = 0.0
    rim2 = (r - RIM_WIDTH) * (r - RIM_WIDTH)
    rin = max(r - TEX_INSET, 1.0)
    rin2 = rin * rin
    tn = ts1 = ts2 = 0.0
    for k in range(nd):
        res = dval[k] - (pa + pb * du[k] + pc * dv[k])
        mass += res
        if res > lcut:
            ln += 1.0
            lu += du[k]
            lv += dv[k]
        if du[k] * du[k] + dv[k] * dv[k] <= rin2:
            tn += 1.0
            ts1 += res
        if doq:
            u = du[k]
            v = dv[k]
            wq = min(dval[k] - (qa + qb * u + qc * v + qd * (u * u - v * v) + qe * (u * v)), level) - cut
            if wq > 0:
                qw += wq
                qwx += wq * u
                qwy += wq * v
        if do5:
            w5 = min(res, level) - cut5
            if w5 > 0:
                w5s += w5
                w5x += w5 * du[k]
                w5y += w5 * dv[k]
        w = min(res, level) - cut
        if w > 0:
            sw += w
            swx += w * du[k]
            swy += w * dv[k]
            nw += 1.0
            su += du[k]
            sv += dv[k]
            suu += du[k] * du[k]
            svv += dv[k] * dv[k]
            wf = min(res, flat) - cut
            fw += wf
            fwx += wf * du[k]
            fwy += wf * dv[k]
            dk2 = du[k] * du[k] + dv[k] * dv[k]
            if dk2 > rim2:
                rw += w
                dk = np.sqrt(max(dk2, 1e-12))
                rwx += w * du[k] / dk
                rwy += w * dv[k] / dk
    dx = swx / sw if sw > 0 else np.nan
    dy = swy / sw if sw > 0 else np.nan
    spread = np.nan
    dshape = np.nan
    rim = (rw - np.hypot(rwx, rwy)) / sw if sw > 0 else np.nan
    if sw > 0 and rw <= 0:
        rim = 0.0
    tex = np.nan
    if sw > 0:
        tex = 0.0
        if tn > 0 and ts1 > 0:
            tm = ts1 / tn
            for k in range(nd):
                if du[k] * du[k] + dv[k] * dv[k] <= rin2:
                    dr = dval[k] - (pa + pb * du[k] + pc * dv[k]) - tm
                    ts2 += dr * dr
            tex = np.sqrt(max(ts2 / tn - noise_i * noise_i, 0.0)) / tm
    if sw > 0:
        q = suu - 2.0 * dx * su + nw * dx * dx + svv - 2.0 * dy * sv + nw * dy * dy
        spread = np.sqrt(0.5 * max(q, 0.0)) / sw
        dshape = np.hypot(fwx / fw - dx, fwy / fw - dy) if fw > 0 else 0.0
        mb = np.hypot(su / nw - dx, sv / nw - dy)
        dshape = np.hypot(dshape, SHAPE_BIN_GAIN * max(mb - SHAPE_BIN_FLOOR, 0.0))
        if ln > 0 and wfrac > 0:
            ml = np.hypot(lu / ln - dx, lv / ln - dy)
            dshape = np.hypot(dshape, LOW_CUT_GAIN * max(ml - LOW_CUT_FLOOR, 0.0))
        if qw > 0:
            dshape = np.hypot(dshape, np.hypot(qwx / qw - dx, qwy / qw - dy))
        if w5s > 0:
            dshape = np.hypot(dshape, EDGE_CUT_GAIN * np.hypot(w5x / w5s - dx, w5y / w5s - dy))
    # ring outliers not on the known neighbour's blob: how one-sided, how near
    fx = dx if sw > 0 else 0.0
    fy = dy if sw > 0 else 0.0
    nexp = 0
    ux = uy = 0.0
    omin2 = np.inf
    if nout > 0:
        for k in range(nr):
            if routl[k] == 1:
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
    second = _second_blob_kernel(frame, cx, cy, sg, pa, pb, pc, du, dv, dval, nd, fx, fy, peak, noise_i, r2, near,
                                 nx_, ny_, half, rr)
    return dx, dy, mass, peak, nexp, frac, dip, omin, bg, valley, spread, dshape, rim, tex, second


@jit
def _buffers(rd):
    cap = 0
    for i in range(rd.shape[0]):
        m = 2 * (int(np.ceil(rd[i])) + 3) + 1
        cap = max(cap, m * m)
    return (np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap),
            np.empty(cap, np.int8), np.empty((5, 7)), np.empty(cap))


@jit
def _refine_kernel(frame, x, y, rd, sign, noise, nbx, nby, nbr_r, iterations, rmax, wfrac, ff, fn, out, face):
    """Compiled twin of :func:`_refine_core` (the iterated centroid of each marker);
    ``out`` (n, 12) receives x, y, mass, peak, foreign, bgres, valley, the disk radius,
    the spread, dshape, rim and tex."""
    H, W = frame.shape
    rgrow = np.empty(rd.shape[0])
    for i in range(rd.shape[0]):
        rgrow[i] = min(rmax[i], rd[i] + 3.0) if rmax[i] > rd[i] else rd[i]
    du, dv, dval, ru, rv, rval, routl, qm, rabs = _buffers(rgrow)
    for i in range(x.shape[0]):
        xi = x[i]
        yi = y[i]
        r = rd[i]
        cx = min(max(int(np.rint(xi)), 0), W - 1)
        cy = min(max(int(np.rint(yi)), 0), H - 1)
        it = 0
        grow = 2
        mass = peak = bg = valley = spread = dshape = rim = tex = np.nan
        foreign = False
        while True:
            nx_ = nbx[i] - cx
            ny_ = nby[i] - cy
            res = _pass1(frame, cx, cy, r, sign[i], nx_, ny_, noise[i], nbr_r[i], wfrac, ff, fn,
                         du, dv, dval, ru, rv, rval, routl, qm, rabs, face)
            dx, dy, m, pk, nout, frac, dip, omin, b, vl, spread, dshape, rim, tex, second = res
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
            foreign = (nout > 0 and (not spill) and omin <= r + 1.0) or second
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
        out[i, 8] = spread
        out[i, 9] = dshape
        out[i, 10] = rim
        out[i, 11] = tex




@jit
def split_neighbour_kernel(XP, YP, j2, out):
    """The neighbour each marker's pixels are split against: of its two nearest markers by
    prediction (``j2``), the one matched nearer to it on this frame (``out``, -1: none).

    The nearest by prediction is not always the nearest blob: on an edge-on wing the
    second-nearest marker can be matched inside this marker's disk while the nearest is
    10 px away, and an unsplit neighbour's blob then pulls the centre by 1-2.5 px at a
    small sigma (independent renders, fresh DEV seeds: hard 19 right f72 p15). A marker
    without a match keeps its nearest by prediction."""
    for i in range(XP.shape[0]):
        best = j2[i, 0]
        if not np.isnan(XP[i]):
            dbest = np.inf
            for k in range(2):
                j = j2[i, k]
                if j >= 0 and not np.isnan(XP[j]):
                    d = np.hypot(XP[j] - XP[i], YP[j] - YP[i])
                    if d < dbest:
                        best, dbest = j, d
        out[i] = best


def split_neighbour_numpy(XP, YP, j2):
    """numpy twin of :func:`split_neighbour_kernel` (returns ``out``)."""
    j = np.maximum(j2, 0)
    d = np.hypot(XP[j] - XP[:, None], YP[j] - YP[:, None])
    d[(j2 < 0) | np.isnan(d)] = np.inf
    second = d[:, 1] < d[:, 0]
    return np.where(second, j2[:, 1], j2[:, 0])


def split_neighbour(XP, YP, j2):
    """:func:`split_neighbour_kernel` or its numpy twin, by the engine switch."""
    if engine.use_numba():
        out = np.empty(len(XP), np.int64)
        split_neighbour_kernel(XP, YP, j2, out)
        return out
    return split_neighbour_numpy(XP, YP, j2)


@jit
def _refine_all_kernel(frame, idx, XP, YP, jn, rd, rb, sign, noise, iterations, wfrac, ff, fn, X, Y, mass,
                       foreign, bgres, peak, valley, spread, dshape, rim, tex, nbr_out):
    """The tracker's refinement of markers ``idx`` in one call: each marker's pixel split
    against its nearest matched neighbour (as :meth:`_Tracker._voronoi`) and its iterated
    centroid (as :func:`_refine_core`, the disk fixed), results written at ``idx``."""
    H, W = frame.shape
    sub = np.empty(idx.shape[0])
    for k in range(idx.shape[0]):
        sub[k] = rd[idx[k]]
    du, dv, dval, ru, rv, rval, routl, qm, rabs = _buffers(sub)
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
            dx, dy, m, pk, nout, frac, dip, omin, b, vl, sp, dsh, rm, tx, sec = _pass1(
                frame, cx, cy, r, sign[i], nxa - cx, nya - cy, noise[i], rr, wfrac, ff, fn,
                du, dv, dval, ru, rv, rval, routl, qm, rabs, True)
            good = m > 0
            if good:
                xi = cx + dx
                yi = cy + dy
            mass[i] = m
            peak[i] = pk
            bgres[i] = b
            valley[i] = vl
            spread[i] = sp
            dshape[i] = dsh
            rim[i] = rm
            tex[i] = tx
            foreign[i] = (nout > 0 and omin <= r + 1.0) or sec
            it += 1
            kx = min(max(int(np.rint(xi)), 0), W - 1)
            ky = min(max(int(np.rint(yi)), 0), H - 1)
            if not (good and (kx != cx or ky != cy) and it < iterations):
                break
            cx = kx
            cy = ky
        if mass[i] > 0 and bgres[i] > INNER_BGRES and r - INNER_SHRINK >= _RD_MIN and not valley[i] >= _MERGE_VALLEY:
            # the inner disk, re-centred as the full one (its first pass starts from the
            # full disk's centre, which the edge may have pulled to another pixel)
            cx = min(max(int(np.rint(xi)), 0), W - 1)
            cy = min(max(int(np.rint(yi)), 0), H - 1)
            for it in range(iterations):
                dx, dy, m, pk, nout, frac, dip, omin, b, vl, sp, dsh, rm, tx, sec = _pass1(
                    frame, cx, cy, r - INNER_SHRINK, sign[i], nxa - cx, nya - cy, noise[i], rr, wfrac, ff, fn,
                    du, dv, dval, ru, rv, rval, routl, qm, rabs, False)
                if not m > 0:
                    break
                kx = min(max(int(np.rint(cx + dx)), 0), W - 1)
                ky = min(max(int(np.rint(cy + dy)), 0), H - 1)
                if (kx == cx and ky == cy) or it == iterations - 1:
                    break
                cx = kx
                cy = ky
            if m > 0 and rm <= INNER_RIM and b < bgres[i]:
                xi = cx + dx
                yi = cy + dy
                bgres[i] = b
                spread[i] = sp
                dshape[i] = dsh
                rim[i] = rm
                tex[i] = tx
        X[i] = xi
        Y[i] = yi




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


def _refine_core(frame, x, y, rd, sign, noise, nbr_xy, nbr_r, iterations, rmax, wfrac, face=True):
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
    spread = np.full(n, np.nan)
    dshape = np.full(n, np.nan)
    rim = np.full(n, np.nan)
    tex = np.full(n, np.nan)
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
                           None if nbr_r is None else nbr_r[todo], wfrac, face)
        d, m = r["d"], r["mass"]
        good = m > 0
        nx = np.where(good, jx + d[:, 0], x[todo])
        ny = np.where(good, jy + d[:, 1], y[todo])
        x[todo], y[todo], mass[todo] = nx, ny, m
        peak[todo], bgres[todo], valley[todo], spread[todo] = r["peak"], r["bgres"], r["valley"], r["spread"]
        dshape[todo], rim[todo], tex[todo] = r["dshape"], r["rim"], r["tex"]
        # own blob larger than the disk: ring outliers all around (not one-sided); the
        # disk grows, and if the ring is still not clean something else is there
        spill = (r["nout"] > 0) & ((r["frac"] > 0.4) | (r["dip"] < 0.5))
        spill &= (rd[todo] + 1.5 <= rmax[todo]) & (grow[todo] > 0)
        foreign[todo] = ((r["nout"] > 0) & ~spill & (r["omin"] <= rd[todo] + 1.0)) | r["second"]
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
    return x, y, mass, rd, peak, foreign, bgres, valley, spread, dshape, rim, tex


def _refine_core_fast(frame, x, y, rd, sign, noise, nbr_xy, nbr_r, iterations, rmax, wfrac, face=True):
    """:func:`_refine_core` by the compiled kernel."""
    n = len(x)
    out = np.empty((n, 12))
    if nbr_xy is None:
        nbx = nby = np.full(n, np.nan)
    else:
        nbx = np.ascontiguousarray(nbr_xy[:, 0], dtype=np.float64)
        nby = np.ascontiguousarray(nbr_xy[:, 1], dtype=np.float64)
    rr = np.full(n, np.nan) if nbr_r is None else np.ascontiguousarray(nbr_r, dtype=np.float64)
    _refine_kernel(frame, np.asarray(x, np.float64), np.asarray(y, np.float64), np.asarray(rd, np.float64),
                   np.asarray(sign, np.float64), np.asarray(noise, np.float64), nbx, nby, rr, int(iterations),
                   np.asarray(rmax, np.float64), float(wfrac), FOREIGN_FRACTION, FOREIGN_NOISE, out, bool(face))
    return out[:, 0], out[:, 1], out[:, 2], out[:, 7], out[:, 3], out[:, 4] > 0, out[:, 5], out[:, 6], out[:, 8], out[:, 9], out[:, 10], out[:, 11]


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
    ``peak``, ``bgres``, ``valley``, ``spread``, ``dshape``, ``rim``, ``tex`` and ``foreign`` (something bright that is not this
    blob lies in the ring, touching the disk: the centroid may be pulled).
    """
    n = len(x)
    rmax = np.asarray(rd, np.float64) if rmax is None else np.broadcast_to(np.asarray(rmax, np.float64), (n,))
    core = _refine_core if not engine.use_numba() else _refine_core_fast
    x, y, mass, rd, peak, foreign, bgres, valley, spread, dshape, rim, tex = core(frame, x, y, rd, sign, noise, nbr_xy, nbr_r, iterations,
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
                bgres[rows], valley[rows], spread[rows], dshape[rows] = r2[6], r2[7], r2[8], r2[9]
                rim[rows], tex[rows] = r2[10], r2[11]
                # a foreign blob split off is only harmless when a dark gap separates them
                foreign[rows] = r2[5] | ~(r2[7] < _MERGE_VALLEY)
    _inner_disk(core, frame, x, y, mass, rd, sign, noise, nbr_xy, nbr_r, wfrac, valley, bgres, spread, dshape, rim,
                tex, max(iterations, 2))
    return x, y, mass, dict(rd=rd, peak=peak, foreign=foreign, bgres=bgres, valley=valley, spread=spread, dshape=dshape,
                            rim=rim, tex=tex)


def _inner_disk(core, frame, x, y, mass, rd, sign, noise, nbr_xy, nbr_r, wfrac, valley, bgres, spread, dshape, rim,
                tex, iterations=2):
    """The inner disk (:data:`INNER_BGRES`): the centroid INNER_SHRINK px smaller where the
    ring is not a plane and no neighbour's blob is joined to this one (``valley`` below
    ``_MERGE_VALLEY``), kept (in place: x, y and the precision terms) where the blob fits
    it and its ring is nearer a plane. As the end of :func:`_refine_all_kernel`."""
    rows = np.flatnonzero((mass > 0) & (bgres > INNER_BGRES) & (rd - INNER_SHRINK >= _RD_MIN)
                          & ~(valley >= _MERGE_VALLEY))
    if not rows.size:
        return
    r2 = core(frame, x[rows], y[rows], rd[rows] - INNER_SHRINK, np.asarray(sign)[rows], np.asarray(noise)[rows],
              None if nbr_xy is None else nbr_xy[rows], None if nbr_r is None else np.asarray(nbr_r)[rows], iterations,
              rd[rows] - INNER_SHRINK, wfrac, face=False)
    keep = (r2[2] > 0) & (r2[10] <= INNER_RIM) & (r2[6] < bgres[rows])
    rows = rows[keep]
    x[rows], y[rows] = r2[0][keep], r2[1][keep]
    bgres[rows], spread[rows], dshape[rows], rim[rows], tex[rows] = (r2[6][keep], r2[8][keep], r2[9][keep],
                                                                    r2[10][keep], r2[11][keep])


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
        times the blob's contrast (its peak, but at most 3 times the median of its face:
        a small highlight does not set the cut; 0: the plain background-subtracted
        centroid), clipped at 1.2 times the blob's median value above that cut, so that a
        specular highlight barely pulls the centre. The default (0.2)
        makes the centre insensitive to what the disk holds besides the blob (a membrane
        edge, glare, the tail of another blob) at the cost of a slight pixel locking on
        blobs with hard edges (< 0.035 px on an unblurred disc, < 0.01 px with the optics'
        blur).

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


