"""The tracker: per-marker state and :meth:`Tracker.step`, which calls the stages in order."""
from __future__ import annotations

import math

import numpy as np

from . import engine
from .geometry import _nearest_two
from .identity import IdentityStage
from .options import _BG_RESIDUAL, _BG_RESIDUAL_FADED, _BRIDGE, _FADED, _MERGE_VALLEY, _RD_MARGIN, _RD_MAX, _WEAK
from .predict import _history_kernel, _pre_kernel
from .reacquire import ReacquireStage
from .refine import FOREIGN_FRACTION, FOREIGN_NOISE, WEIGHT_FRACTION, _refine, _refine_all_kernel
from .status import _IS_SOFT, _R, _RULE_CODES, FLAGGED, LOST, OK, _rules_kernel
from .templates import TemplateStage


class Tracker(TemplateStage, IdentityStage, ReacquireStage):
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
        if engine.use_numba():
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
            if engine.use_numba():
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
        if midx.size and engine.use_numba():
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
        if engine.use_numba():
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
        if not engine.use_numba():
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

