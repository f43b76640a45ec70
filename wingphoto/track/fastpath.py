"""The fast frame: a steady frame's whole :meth:`Tracker.step` in one compiled call.

Most frames of a sequence are uneventful: every marker was tracked on the frame before,
moves as predicted, is matched and refined where expected and gets status ``ok`` (or a
flag that needs no look at its neighbours). :func:`fast_step` runs such a frame end to
end in compiled code (:func:`_fast_frame`): the frame check (blank, repeated), the
prediction and search plan (:func:`~.predict._pre_kernel`), the hill-climbed match
(:func:`~.match._climb_kernel`), the joint sub-pixel refinement
(:func:`~.refine._refine_all_kernel`), the fast path's verification
(:func:`~.match._score_kernel`), the constellation count, sigma, the status rules
(:func:`~.status._conditions_kernel` and :data:`~.status.RULES`), the ``stay`` rule and
the motion-model update (:func:`~.predict._history_kernel`). The stage kernels are
called, not rewritten, so a change to one of them reaches both paths.

The kernel decides at the end whether the frame was easy; only then does it commit the
tracker's state and write the frame's row. Otherwise it leaves the state as it was and
the Python :meth:`Tracker.step` runs (it is the numpy twin of this kernel, and what
handles every event: a wide or re-search, a conflict, a foreign blob, a jump to vouch
for, a soft flag to check against the neighbours, a lost marker (re-acquisition), a
broken constellation, a blank or repeated frame). Markers at the image edge (window
clipped) and tracked markers predicted outside the image are handled here, as the
Python step does. Due template updates are done in Python after the kernel (a few per
hundred frames).

The part of :meth:`Tracker.step` that is Python there is mirrored here line for line:
``_frame_glitch`` (its cheap test), ``_solve`` (``_plan``, ``_match_all``,
``_refine_matched``, ``_verify_fast``), ``_conflicts``, ``_consistent``, ``_sigma``,
``_judge`` and ``_update``. Change one and the test
``tests/test_track_fastpath.py`` (identical tracks with the fast frame on and off)
tells whether this mirror must follow.

numba's cache does not notice a change in a kernel of another module that a cached
kernel calls; :func:`_fast_frame` is therefore built as a closure over a hash of those
modules' sources, which numba's cache key includes: an edit of a stage kernel recompiles
it.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from . import engine
from .match import _analyse_kernel, _climb_kernel, _ncc_kernel, _score_kernel
from .predict import FAST_VERIFY_PX, FAST_VERIFY_SCORE, _history_kernel, _pre_kernel
from .refine import FOREIGN_FRACTION, FOREIGN_NOISE, WEIGHT_FRACTION, _refine_all_kernel, split_neighbour_kernel
from .sigma import point_sigma
from .status import (
    _IS_SOFT,
    _R,
    _RULE_REASON,
    _RULE_STATUS,
    COAST_PX,
    COINCIDENT,
    FLAGGED,
    LOST,
    OK,
    STAY_PX,
    STAY_SCORE,
    _conditions_kernel,
)

__all__ = ["fast_step", "BAIL_REASONS", "stats", "reset_stats", "summary"]

#: Why a frame left the fast path (index = the kernel's return code; 0: handled).
BAIL_REASONS = ("handled", "frame_check", "lost_marker", "wide_search", "search", "conflict", "foreign",
                "fast_path_check", "constellation", "jump_or_vouch", "soft_flag", "no_markers", "coincident")
#: Frames per :data:`BAIL_REASONS` code since the import (or the last :func:`reset_stats`).
stats = np.zeros(len(BAIL_REASONS), np.int64)
_JUMP = _R["jump"]
_IMPRECISE = _R["imprecise"]
_EDGE = _R["edge"]
_OUT_OF_FRAME = _R["out_of_frame"]
#: Slots of the fast frame's thresholds ``fpar`` (:func:`_params` fills them).
(_F_MIN_MASS, _F_MIN_SCORE, _F_MAX_SIGMA, _F_FADED, _F_WEAK, _F_BG_FADED, _F_CONSTELLATION, _F_POOR_MATCH,
 _F_POOR_DROP, _F_POOR_MARGIN, _F_MEDIAN_RESID, _F_MOVING) = range(12)

#: Modules whose kernels :func:`_fast_frame` calls (their source is part of its cache key).
_DEPENDENCIES = ("geometry", "predict", "match", "refine", "sigma", "status")


def _dependency_key():
    """A 60-bit hash of the sources of the stage modules the fast frame calls."""
    h = hashlib.sha256()
    here = Path(__file__).parent
    for name in _DEPENDENCIES:
        h.update((here / f"{name}.py").read_bytes())
    return int(h.hexdigest()[:15], 16)



@engine.jit
def _windows(sidx, count, small, h, prx, pry, r):
    """The ``count`` markers of ``sidx`` with a small window (radius <= 3, ``small``) or a
    larger one, and their kernel arguments: indices, template half sizes, rounded
    predictions (x, y) and window radii."""
    idx = np.empty(count, np.int64)
    k = 0
    for i in sidx:
        if (r[i] <= 3) == small:
            idx[k] = i
            k += 1
    hh, xx, yy = _at(idx, h, prx, pry)
    rr = np.empty(count, np.int64)
    for k in range(count):
        rr[k] = r[idx[k]]
    return idx, hh, xx, yy, rr


@engine.jit
def _at(idx, h, x, y):
    """Template half sizes and rounded positions (x, y) of markers ``idx`` (kernel arguments)."""
    count = idx.shape[0]
    hh = np.empty(count, np.int64)
    xx = np.empty(count, np.int64)
    yy = np.empty(count, np.int64)
    for k in range(count):
        i = idx[k]
        hh[k] = h[i]
        xx[k] = np.int64(np.rint(x[i]))
        yy[k] = np.int64(np.rint(y[i]))
    return hh, xx, yy


@engine.jit
def _touch(frame, px, py, half):
    """Read one pixel per cache line of each marker's neighbourhood (``half`` px around
    the rounded prediction ``px, py``, clipped to the frame) and return how many exceed
    the first: the loads are independent, so the memory system serves them together
    before the matching and the refinement read those pixels one dependent step at a
    time (a new frame is not in the cache). Changes nothing but timing."""
    fh, fw = frame.shape
    ref = frame[0, 0]
    step = max(1, 64 // frame.itemsize)
    count = 0
    for i in range(px.shape[0]):
        if not (abs(px[i]) < 1e9 and abs(py[i]) < 1e9):  # (also NaN: not predicted)
            continue
        cx = np.int64(np.rint(px[i]))
        cy = np.int64(np.rint(py[i]))
        a0 = max(cy - half[i], 0)
        a1 = min(cy + half[i], fh - 1)
        b0 = max(cx - half[i], 0)
        b1 = min(cx + half[i], fw - 1)
        for a in range(a0, a1 + 1):
            for b in range(b0, b1 + 1, step):
                if frame[a, b] > ref:
                    count += 1
            if b1 >= b0 and frame[a, b1] > ref:
                count += 1
    return count


def _build(key):
    """Compile :func:`_fast_frame` for the stage kernels whose sources hash to ``key``."""

    def _frame(frame, prev, has_prev, sample, t, hx, ht, nh, rrms, lostflag, last_ok, last_score, stagger, h,
               rb, W, H, max_coast, every, search_radius, tz, rd, sign, noise, mass0, mass_ref, score_ref, peak0,
               last_upd, rule_par, upd_par, fpar, is_soft, rule_status, rule_reason, res_x, res_y, res_score,
               res_xpix, res_ypix, res_status, res_reason, res_sigma, pos, upd):
        """The work of :func:`_fast_frame` (same arguments but ``stats``; its code, uncounted)."""
        if key < 0:  # (never: ties the compiled code to the stage kernels' sources)
            return 11
        n = h.shape[0]
        if n == 0:
            return 11
        # ---- the frame check (Tracker._frame_glitch): a flat or non-finite sample may be
        # a blank frame, an identical sample a repeated frame: Python decides
        fh, fw = frame.shape
        lo = np.inf
        hi = -np.inf
        same = has_prev
        for a in range(0, fh, sample):
            for b in range(0, fw, sample):
                v = np.float64(frame[a, b])
                if not np.isfinite(v):
                    return 1
                lo = min(lo, v)
                hi = max(hi, v)
                if same and prev[a, b] != frame[a, b]:
                    same = False
        if not (hi > lo) or same:
            return 1
        for i in range(n):
            if lostflag[i]:
                return 2
        # ---- prediction and search plan (predict.start_frame)
        pred = np.empty((n, 2))
        gap = np.empty(n, np.int64)
        steady = np.empty(n, np.bool_)
        inside = np.empty(n, np.bool_)
        fits = np.empty(n, np.bool_)
        r = np.empty(n, np.int64)
        F = np.empty(n, np.bool_)
        wide = np.empty(n, np.bool_)
        j2 = np.empty((n, 2), np.int64)
        d2 = np.empty((n, 2))
        merged = np.empty(n, np.bool_)
        crowded = np.empty(n, np.bool_)
        _pre_kernel(t, hx, ht, nh, rrms, lostflag, last_ok, last_score, stagger, h, rb, W, H, max_coast, every,
                    search_radius, pred, gap, steady, inside, fits, r, F, wide, j2, d2, merged, crowded)
        prx = pred[:, 0]
        pry = pred[:, 1]
        ns = 0  # markers searched: hill-climbed (radius <= 3) or in a full window
        nw = 0
        rmax = 0
        for i in range(n):
            if lostflag[i]:
                return 2  # (_pre_kernel's mark is the one Python's step makes again)
            if wide[i]:
                return 3
            if fits[i] and not F[i]:
                ns += 1
                if r[i] > 3:
                    nw += 1
                    rmax = max(rmax, r[i])
        if rmax > 6:
            return 4  # a window that OpenCV matches (TemplateStage._match)
        # the pixels the matching and the refinement will read, fetched together first
        # (a new frame is not in the cache; :func:`_touch`)
        reach = np.empty(n, np.int64)
        for i in range(n):
            reach[i] = max(h[i] + r[i], np.int64(np.ceil(rd[i])) + 3) + 1
        pos[0, 0] = _touch(frame, prx, pry, reach)  # (pos is written again on commit, unused on a bail)
        # ---- matching (IdentityStage._search, numba branch): hill-climb from the prediction
        # where the window is small, correlate the whole window elsewhere
        XP = np.full(n, np.nan)
        YP = np.full(n, np.nan)
        S = np.full(n, np.nan)
        SEC = np.full(n, -2.0)
        sidx = np.empty(ns, np.int64)
        k = 0
        for i in range(n):
            if fits[i] and not F[i]:
                sidx[k] = i
                k += 1
        nc = ns - nw
        if nc:
            cidx, ch, cx, cy, cr = _windows(sidx, nc, True, h, prx, pry, r)
            out = np.empty((nc, 4))
            _climb_kernel(frame, tz, cidx, ch, cx, cy, cr, out)
            for k in range(nc):
                if out[k, 3] > 0 or not out[k, 2] > -2.0:
                    return 4  # the climb reached its window's rim: a wider search
                i = cidx[k]
                XP[i] = out[k, 0]
                YP[i] = out[k, 1]
                S[i] = out[k, 2]
        if nw:
            widx, wh, wx, wy, wr = _windows(sidx, nw, False, h, prx, pry, r)
            m = 2 * rmax + 1
            maps = np.full((nw, m, m), -2.0, np.float32)
            origin = np.zeros((nw, 2), np.int64)
            shape = np.zeros((nw, 2), np.int64)
            _ncc_kernel(frame, tz, widx, wh, wx, wy, wr, maps, origin, shape)
            oth = np.full((nw, 2, 2), np.nan)  # the neighbours' predictions (map cells)
            excl = np.empty(nw)
            for k in range(nw):
                i = widx[k]
                excl[k] = max(2.0, rb[i])
                for q in range(2):
                    j = j2[i, q]
                    if j >= 0:
                        oth[k, q, 0] = pred[j, 0] - origin[k, 0]
                        oth[k, q, 1] = pred[j, 1] - origin[k, 1]
            peaks = np.empty((nw, 5))
            _analyse_kernel(maps, shape, excl, oth, peaks)
            for k in range(nw):
                i = widx[k]
                full = shape[k, 0] == 2 * wr[k] + 1 and shape[k, 1] == 2 * wr[k] + 1
                if peaks[k, 4] > 0 and full and wr[k] < search_radius:
                    return 4  # best peak on the window's rim: a search twice as wide
                XP[i] = np.float64(origin[k, 0] + np.int64(peaks[k, 0]))
                YP[i] = np.float64(origin[k, 1] + np.int64(peaks[k, 1]))
                S[i] = peaks[k, 2]
                SEC[i] = peaks[k, 3]
        if ns:
            # conflicts among the searched markers (IdentityStage._conflicts)
            for a in range(ns):
                i = sidx[a]
                for b in range(ns):
                    j = sidx[b]
                    if i == j:
                        continue
                    dx = XP[i] - XP[j]
                    dy = YP[i] - YP[j]
                    q = max(max(rb[i], rb[j]), 2.0)
                    if dx * dx + dy * dy < q * q:
                        return 5
        nr = 0
        for i in range(n):
            if F[i] or (inside[i] and not fits[i]):  # (an edge marker: refined at its prediction)
                XP[i] = np.rint(prx[i])
                YP[i] = np.rint(pry[i])
            if not np.isnan(XP[i]):
                nr += 1
        # ---- sub-pixel refinement of every matched marker, jointly (Tracker._refine_all)
        idx = np.empty(nr, np.int64)
        k = 0
        for i in range(n):
            if not np.isnan(XP[i]):
                idx[k] = i
                k += 1
        X = np.full(n, np.nan)
        Y = np.full(n, np.nan)
        mass = np.full(n, np.nan)
        foreign = np.zeros(n, np.bool_)
        bgres = np.zeros(n)
        peak = np.full(n, np.nan)
        valley = np.full(n, np.nan)
        spread = np.full(n, np.nan)
        dshape = np.full(n, np.nan)
        rim = np.full(n, np.nan)
        tex = np.full(n, np.nan)
        nb = np.full((n, 2), np.nan)
        jn = np.empty(n, np.int64)
        split_neighbour_kernel(XP, YP, j2, jn)
        _refine_all_kernel(frame, idx, XP, YP, jn, rd, rb, sign, noise, 2, WEIGHT_FRACTION, FOREIGN_FRACTION,
                           FOREIGN_NOISE, X, Y, mass, foreign, bgres, peak, valley, spread, dshape, rim, tex, nb)
        for i in range(n):
            if foreign[i]:
                return 6
            if inside[i] and not fits[i]:
                XP[i] = np.nan  # (no correlation match for an edge marker)
                YP[i] = np.nan
        # ---- verification of the fast-path markers (Tracker._verify_fast)
        nf = 0
        for i in range(n):
            if F[i]:
                nf += 1
        if nf:
            fidx = np.empty(nf, np.int64)
            k = 0
            for i in range(n):
                if F[i]:
                    fidx[k] = i
                    k += 1
            fh_, fx, fy = _at(fidx, h, X, Y)
            sc = np.empty(nf)
            _score_kernel(frame, tz, fidx, fh_, fx, fy, sc)
            for k in range(nf):
                i = fidx[k]
                S[i] = sc[k]
                XP[i] = np.rint(X[i])
                YP[i] = np.rint(Y[i])
                resf = np.hypot(X[i] - prx[i], Y[i] - pry[i])
                if not (S[i] >= FAST_VERIFY_SCORE and resf < max(FAST_VERIFY_PX, 4.0 * rrms[i])
                        and mass[i] > fpar[_F_MIN_MASS] * mass0[i]):
                    return 7
        resid = np.empty(n)
        for i in range(n):
            resid[i] = np.hypot(X[i] - prx[i], Y[i] - pry[i])
        # ---- the constellation (Tracker._consistent / _broken; nothing aged)
        nchk = 0
        ngood = 0
        for i in range(n):
            if fits[i] and nh[i] >= 2 and gap[i] <= 2:
                nchk += 1
                lim = max(2.0, 4.0 * rrms[i] + COAST_PX * (gap[i] - 1))
                if resid[i] <= lim and S[i] >= fpar[_F_MIN_SCORE]:
                    ngood += 1
        if nchk >= 3 and ngood < fpar[_F_CONSTELLATION] * nchk:
            return 8
        # (too few markers for a constellation, one of them moving: the Python step asks
        # whether frames dropped would put it on another blob, GlitchStage._few_in_doubt)
        if 0 < nchk < 3:
            for i in range(n):
                if fits[i] and nh[i] >= 3 and gap[i] <= 2:
                    dtm = abs(ht[i, 0] - ht[i, 1])
                    step = np.hypot(hx[i, 0, 0] - hx[i, 1, 0], hx[i, 0, 1] - hx[i, 1, 1])
                    if dtm > 0 and step >= fpar[_F_MOVING] * dtm:
                        return 8
        # (... or their median residual is too large: glitch._median_residual)
        if nchk >= 3:
            rfit = np.empty(n)
            nfit = 0
            for i in range(n):
                if fits[i] and nh[i] >= 2 and not np.isnan(resid[i]):
                    rfit[nfit] = resid[i]
                    nfit += 1
            if nfit > 0 and np.median(rfit[:nfit]) > fpar[_F_MEDIAN_RESID]:
                return 8
        # ---- sigma (Tracker._sigma) and the status rules (Tracker._judge)
        sig = np.empty(n)
        imprecise = np.empty(n, np.bool_)
        for i in range(n):
            sig[i] = point_sigma(noise[i], spread[i], bgres[i], peak[i], S[i], rb[i], dshape[i], rim[i], tex[i],
                                 valley[i])
            faded = (peak[i] < fpar[_F_FADED] * peak0[i]) or (S[i] < fpar[_F_WEAK])
            imprecise[i] = (not (sig[i] <= fpar[_F_MAX_SIGMA])) or (faded and bgres[i] > fpar[_F_BG_FADED])
        lose = np.zeros(n, np.bool_)
        cond = np.empty((n, rule_status.shape[0]), np.bool_)
        _conditions_kernel(fits, S, SEC, mass, mass0, mass_ref, score_ref, resid, rrms, gap, nh, foreign, imprecise,
                           XP, YP, prx, pry, inside, j2, rb, valley, lose, rule_par, cond)
        ST = np.full(n, LOST, np.int8)
        RS = np.zeros(n, np.int8)
        for i in range(n):
            if not fits[i]:
                if not inside[i]:
                    RS[i] = _OUT_OF_FRAME
                continue
            ST[i] = OK
            for k in range(cond.shape[1] - 1, -1, -1):
                if cond[i, k]:
                    ST[i] = rule_status[k]
                    RS[i] = rule_reason[k]
                    break
        # two markers centred on one blob (Tracker._coincident): the Python step flags them
        for i in range(n):
            if ST[i] != OK or not np.isfinite(X[i]):
                continue
            for j in range(n):
                if j != i and (ST[j] == OK or ST[j] == FLAGGED) and np.isfinite(X[j]):
                    if np.hypot(X[i] - X[j], Y[i] - Y[j]) < COINCIDENT * max(rb[i], rb[j]):
                        return 12
        for i in range(n):
            # (a wide-search 'ambiguous' cannot occur here: no marker is searched wide)
            stay = (resid[i] < STAY_PX and np.hypot(X[i] - hx[i, 0, 0], Y[i] - hx[i, 0, 1]) < STAY_PX
                    and S[i] >= STAY_SCORE and ST[i] == OK)
            if fits[i] and ST[i] == LOST:
                X[i] = np.nan
                Y[i] = np.nan
            if RS[i] == _JUMP:
                return 9
            if ST[i] == FLAGGED and RS[i] == _IMPRECISE and abs(t - last_ok[i]) > 1:
                return 9  # it may have been disputed since (Tracker._update reads the rows)
            if ST[i] == OK and (abs(t - last_ok[i]) > 1 or (nh[i] < 3 and not stay)):
                return 9  # (after a gap even a marker that stayed: was its blob disputed?)
        for i in range(n):
            if inside[i] and not fits[i]:  # an edge marker (Tracker._judge)
                if (mass[i] > fpar[_F_MIN_MASS] * mass0[i] and X[i] >= -0.5 and X[i] <= W - 0.5 and Y[i] >= -0.5
                        and Y[i] <= H - 0.5):
                    ST[i] = FLAGGED
                    RS[i] = _EDGE
                else:
                    RS[i] = _OUT_OF_FRAME
                    X[i] = np.nan
                    Y[i] = np.nan
        # ---- Tracker._update: reliable points (ok; flagged imprecise only: every identity
        # rule passed) feed the motion model; other soft flags are checked against the
        # neighbours in Python
        rel = np.empty(n, np.bool_)
        for i in range(n):
            rel[i] = ST[i] == OK or (ST[i] == FLAGGED and (RS[i] == _IMPRECISE or RS[i] == _EDGE))
            if ST[i] == FLAGGED and is_soft[RS[i]] and not rel[i]:
                return 10
        # ---- easy: commit
        held = np.empty(n, np.bool_)  # (Tracker._poor_match, before the running score moves)
        for i in range(n):
            held[i] = (S[i] < fpar[_F_POOR_MATCH] and S[i] < score_ref[i] - fpar[_F_POOR_DROP]
                       and sig[i] > fpar[_F_POOR_MARGIN] * fpar[_F_MAX_SIGMA])
        _history_kernel(t, X, Y, S, ST, rel, resid, mass, hx, ht, nh, rrms, last_score, last_ok, mass_ref, score_ref,
                        last_upd, upd_par, upd)
        for i in range(n):
            res_x[t, i] = X[i]
            res_y[t, i] = Y[i]
            res_score[t, i] = S[i]
            res_xpix[t, i] = XP[i]
            res_ypix[t, i] = YP[i]
            res_status[t, i] = ST[i]
            res_reason[t, i] = RS[i]
            if ST[i] == OK and held[i]:
                res_status[t, i] = FLAGGED
                res_reason[t, i] = _IMPRECISE
            res_sigma[t, i] = sig[i] if np.isfinite(X[i]) else np.nan
            pos[i, 0] = X[i]
            pos[i, 1] = Y[i]
        return 0

    # (a module global, not a closure cell: numba's cache key pickles the cells, and a
    # compiled function pickles differently in every process)
    global _frame_work
    _frame_work = engine.jit(_frame)

    def _fast_frame(frame, prev, has_prev, sample, t, hx, ht, nh, rrms, lostflag, last_ok, last_score, stagger, h,
                    rb, W, H, max_coast, every, search_radius, tz, rd, sign, noise, mass0, mass_ref, score_ref, peak0,
                    last_upd, rule_par, upd_par, fpar, is_soft, rule_status, rule_reason, res_x, res_y, res_score,
                    res_xpix, res_ypix, res_status, res_reason, res_sigma, pos, upd, stats):
        """One steady frame of :meth:`Tracker.step` (see the module docstring).

        ``fpar``: min_mass_ratio, min_score, max_sigma, _FADED, _WEAK, _BG_RESIDUAL_FADED,
        _CONSTELLATION, _POOR_MATCH, _POOR_DROP, _POOR_MARGIN, _MEDIAN_RESID_PX, _MOVING_PX (the
        slots ``_F_*``). Returns 0 when the frame was handled (state committed, row ``t`` of
        ``res_*`` written, ``pos`` the new positions), -1 when it was handled and templates
        are due for an update (``upd``), else the code of :data:`BAIL_REASONS` that sent it
        back, nothing changed. Counts the outcome in ``stats``.
        """
        if key < 0:  # (never: ties the compiled code to the stage kernels' sources)
            return 11
        code = _frame_work(frame, prev, has_prev, sample, t, hx, ht, nh, rrms, lostflag, last_ok, last_score,
                           stagger, h, rb, W, H, max_coast, every, search_radius, tz, rd, sign, noise, mass0,
                           mass_ref, score_ref, peak0, last_upd, rule_par, upd_par, fpar, is_soft, rule_status,
                           rule_reason, res_x, res_y, res_score, res_xpix, res_ypix, res_status, res_reason,
                           res_sigma, pos, upd)
        stats[code] += 1
        if code == 0:
            for i in range(upd.shape[0]):
                if upd[i]:
                    return -1
        return code

    return engine.jit(_fast_frame)


_fast_frame = _build(_dependency_key())


def _params(tr):
    """The constant arguments of :func:`_fast_frame` for tracker ``tr`` (made once)."""
    from . import glitch as gl
    from . import tracker as tk
    from .options import _BRIDGE, _MERGE_VALLEY

    p = tr.p
    rule_par = np.array([p.min_score, p.lost_score, p.min_mass_ratio, p.mass_ratio_cap, p.score_drop_cap,
                         p.ambiguity_margin, p.jump_px, _MERGE_VALLEY, _BRIDGE])
    upd_par = np.array([p.update_score, p.refresh_below, p.update_every], np.float64)
    fpar = np.array([p.min_mass_ratio, p.min_score, p.max_sigma, tk._FADED, tk._WEAK, tk._BG_RESIDUAL_FADED,
                     gl._CONSTELLATION, tk._POOR_MATCH, tk._POOR_DROP, tk._POOR_MARGIN,
                     gl._MEDIAN_RESID_PX, gl._MOVING_PX])
    return dict(rule_par=rule_par, upd_par=upd_par, fpar=fpar, sample=gl._SAMPLE, p=p)


def fast_step(tr, frame, t, res):
    """Run frame ``t`` through :func:`_fast_frame` when the compiled engine is in use.

    Parameters
    ----------
    tr : Tracker
    frame : (H, W) ndarray
    t : int
        Frame index (row of ``res``).
    res : _Results
        The pass's result arrays; row ``t`` is written when the frame is handled.

    Returns
    -------
    bool
        True when the frame was handled (state, row, templates, ``pos`` and the previous
        frames updated as :meth:`Tracker.step` does); False: nothing changed, run the
        Python step.
    """
    if not engine.use_fast_frames() or frame.ndim != 2:
        return False
    c = tr.__dict__.get("_fast_par")
    if c is None or c["p"] is not tr.p:
        c = tr._fast_par = _params(tr)
    prev = tr._prev
    has_prev = prev is not None and prev.shape == frame.shape and prev.dtype == frame.dtype
    n = len(tr.h)
    pos = np.empty((n, 2))
    upd = np.zeros(n, np.bool_)
    code = _fast_frame(frame, prev if has_prev else frame, has_prev, c["sample"], t, tr.hist_x, tr.hist_t, tr.nh,
                       tr.resid_rms, tr.lostflag, tr.last_ok, tr.last_score, tr.stagger, tr.h, tr.rb, tr.W, tr.H,
                       c["p"].max_coast, c["p"].search_every, c["p"].search_radius, tr.tz, tr.rd, tr.sign64, tr.noise,
                       tr.mass0, tr.mass_ref, tr.score_ref, tr.peak0, tr.last_upd, c["rule_par"], c["upd_par"],
                       c["fpar"], _IS_SOFT, _RULE_STATUS, _RULE_REASON, res.x, res.y, res.score, res.xpix, res.ypix,
                       res.status, res.reason, res.sigma, pos, upd, stats)
    if code > 0:
        return False
    if code < 0:
        tr._refresh_templates(frame, t, pos[:, 0], pos[:, 1], upd)
    tr.pos = pos
    tr._prev2, tr._prev = tr._prev, frame
    return True


def reset_stats():
    """Zero :data:`stats`."""
    stats[:] = 0


def summary():
    """{reason: frames} of :data:`stats` (``handled``: frames the fast frame ran)."""
    return {name: int(k) for name, k in zip(BAIL_REASONS, stats) if k}
