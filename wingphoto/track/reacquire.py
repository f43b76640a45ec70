"""Re-acquisition of long-lost markers from their neighbours."""
from __future__ import annotations

import logging
import math

import numpy as np

from .geometry import _apply_affine, _neighbour_prediction, _robust_affine
from .hop import _frames_since
from .match import _GRID, _analyse_maps
from .predict import STILL_SPEED
from .refine import _refine
from .relocate import STILL_PX, _moving, _roamed, _was_moving
from .status import _R, _SOFT, FLAGGED, OK

logger = logging.getLogger(__name__)


#: A line prediction (:func:`_line_prediction`) needs its neighbours to fit their line's
#: map within this RMS (px), like the affine maps of :func:`~.geometry._neighbour_prediction`.
_LINE_RMS = 1.5
#: A pair of neighbours (their mean displacement: no turn, no stretch) predicts a lost
#: marker from its last reliable frame only this many frames on: 8 frames on, at stroke
#: reversal, two mid-wing markers put a tip marker 9.5 px off, on its lost neighbour's blob
#: (independent renderer, bumped DEV seed 36 right, marker 23 at frame 29, ok next frame).
_PAIR_FRAMES = 3
#: A mean displacement of neighbours predicts a lost marker from its last reliable frame
#: only if it may miss it (:func:`~.geometry._reach`) by at most this share of the
#: marker's distance to its nearest neighbour.
_REACH_SPACING = 0.25
#: Largest distance of a marker from its neighbours' line, in units of their spread across
#: it, for an affine map from them to predict it (:func:`_determined`).
_AMPLIFY = 4.0


def _determined(p0, src, amplify=_AMPLIFY):
    """True when an affine map fitted on ``src`` (m, 2) determines where ``p0`` (2,) goes.

    A map from neighbours on (or near) a line leaves free where the points off that line
    go: ``p0``'s distance from their line may be at most ``amplify`` (default
    :data:`_AMPLIFY`) times the RMS spread of the neighbours across it (the factor by
    which their position errors grow in the prediction)."""
    if len(src) < 3:
        return False
    c = src.mean(0)
    _, sv, vt = np.linalg.svd(src - c, full_matrices=False)
    across = sv[1] / math.sqrt(len(src))
    return abs(float((p0 - c) @ vt[1])) <= amplify * across


def _hinges(p0, src):
    """Which of four neighbours ``src`` (4, 2) alone make an affine map from them determine
    where ``p0`` goes (boolean, (4,): :func:`_determined` fails without it).

    Four points leave an affine map two coordinates to check itself by: a neighbour on
    the next dot of a grid, the only one on the marker's side of the others, is absorbed
    as a shear that carries the marker one spacing along, and nothing shows it (real
    dots, dropped, fresh DEV seed 1072 cam2: three dots near a line and one beside them,
    followed one spacing off as ``imprecise`` since a dropped-frame glitch; the map of the
    four put a lost dot on the dot behind it, RMS 0.3 px, ok 35 px off for 9 frames).
    With five or more the robust fit can leave such a neighbour out."""
    return np.array([not _determined(p0, np.delete(src, k, axis=0)) for k in range(len(src))])


def _line_prediction(p0, src, dst, max_off):
    """Map ``p0`` by the 1-D map of the line its neighbours form, if it lies on that line.

    Parameters
    ----------
    p0 : (2,) ndarray of float
        The marker's position in the reference frame, px.
    src, dst : (m, 2) ndarray of float
        Its neighbours' positions in the reference frame and now, px; m >= 3.
    max_off : float
        Largest distance (px) of ``p0`` from the neighbours' line in the reference frame.

    Returns
    -------
    (2,) ndarray of float or None
        The predicted position: the neighbours' positions along their line ``s`` map to
        now by ``a + b s`` (least squares, RMS residual at most :data:`_LINE_RMS`); None
        when ``p0`` is off the line, beyond the neighbours' span by more than that span,
        or the neighbours are not nearly on a line or do not fit such a map.

    Notes
    -----
    A planar wing moves by an affine map, but an affine map from neighbours on a line
    leaves free where the points off that line go (the wing's fold about it): only
    ``p0`` on the line is determined. An edge-on wing may leave only such a row of
    markers ok, too few for :func:`~.geometry._robust_affine`: without this, a marker
    lost there is never re-acquired, nor are those that need it as a neighbour.
    """
    c = src.mean(0)
    _, sv, vt = np.linalg.svd(src - c, full_matrices=False)
    if sv[0] <= 0:
        return None
    u, nrm = vt[0], vt[1]
    e = (src - c) @ nrm
    if np.abs(e).max() > max_off:
        return None  # not a line
    s = (src - c) @ u
    s0 = float((p0 - c) @ u)
    span = float(s.max() - s.min())
    if abs(float((p0 - c) @ nrm)) > max_off or not s.min() - span <= s0 <= s.max() + span:
        return None
    A = np.column_stack([np.ones(s.size), s])
    coef, *_ = np.linalg.lstsq(A, dst, rcond=None)
    rms = float(np.sqrt(np.mean(np.sum((A @ coef - dst) ** 2, axis=1))))
    if rms > _LINE_RMS:
        return None
    return coef[0] + coef[1] * s0


def _last_written(res, i, ti, t_ok):
    """The last frame, from ``ti`` back to ``t_ok`` (marker ``i``'s last ok frame), on
    which a position of marker ``i`` is written in ``res`` whose identity was not in doubt
    (ok, ``imprecise`` or ``edge``), or None. (A position flagged ``ambiguous`` one grid
    spacing off, on the frame after the pick, mapped 27 frames later onto the next dot:
    real dots, repeated, fresh DEV seed 236 cam2, ok 34-36 px off.)"""
    T = res.x.shape[0]
    step = 1 if t_ok <= ti else -1
    for tw in range(ti, t_ok - step, -step):
        if 0 <= tw < T and np.isfinite(res.x[tw, i]) and np.isfinite(res.y[tw, i]) and (
                _certain(res.status[tw, i], res.reason[tw, i]) or res.reason[tw, i] == _R["edge"]):
            return tw
    return None


#: Reasons that put a marker's identity in doubt: a hinge of a four-neighbour map
#: (:meth:`ReacquireStage._sure_since`) must not have had one since the lost marker was ok.
_DOUBT = np.array([_R["ambiguous"], _R["conflict"], _R["jump"]], np.int8)

#: A marker flagged ``imprecise`` serves as a neighbour for re-acquisition only if it was
#: ok or imprecise on each of the last _ANCHOR_FRAMES frames.
_ANCHOR_FRAMES = 5


def _certain(status, reason):
    """True where a point's identity is certain: ok, or flagged only for its precision."""
    return (status == OK) | ((status == FLAGGED) & (reason == _R["imprecise"]))


def _restart_velocity(nbrs, X, Y, res, tp):
    """Mean motion (px, (2,)) of neighbours ``nbrs`` from frame ``tp`` to their positions
    (X, Y) now, or None when none has a position on both frames.

    The neighbours certain on ``tp`` are used if any; else every one with a position there
    (a neighbour re-acquired on ``tp`` itself: after a group is lost together its members
    come back a frame apart, and they all share the wing's motion).
    """
    nbrs = np.asarray(nbrs, np.int64)
    if not (0 <= tp < res.x.shape[0]) or not nbrs.size:
        return None
    known = nbrs[np.isfinite(X[nbrs]) & np.isfinite(Y[nbrs]) & np.isfinite(res.x[tp, nbrs])
                 & np.isfinite(res.y[tp, nbrs])]
    if not known.size:
        return None
    sure = known[_certain(res.status[tp, known], res.reason[tp, known])]
    use = sure if sure.size else known
    return np.array([np.mean(X[use] - res.x[tp, use]), np.mean(Y[use] - res.y[tp, use])])


class ReacquireStage:
    """Re-acquisition of :class:`~wingphoto.track.tracker.Tracker`."""

    def _refine_candidate(self, frame, i, mx, my, X, Y):
        """Refine marker ``i`` at a candidate pixel (mx, my), the nearest other marker with
        a position (X, Y) split off when its blob can reach this one's disk; returns
        :func:`~.refine._refine`'s x, y, mass and diagnostics (arrays of one)."""
        nb = None
        oth = np.flatnonzero(np.isfinite(X))
        oth = oth[oth != i]
        if oth.size:
            dj = np.hypot(X[oth] - mx, Y[oth] - my)
            k = int(np.argmin(dj))
            if dj[k] < self.rd[i] + 3.0 + self.rb[oth[k]]:
                nb = np.array([[X[oth[k]], Y[oth[k]]]])
        sel = np.array([i])
        return _refine(frame, [mx], [my], self.rd[sel], self.sign[sel], self.noise[sel], nb, 2, rmax=self.rd[sel])

    def _predict_lost(self, i, okn, X, Y, res, t, moving):
        """Where lost marker ``i`` should be now, from its neighbours.

        Returns (prediction, search radius, minimum score, neighbours used) or None.

        1. From its last reliable frame: the neighbours reliable then and now that moved
           like it then (when its motion then is known) map its last position to now
           (:func:`_neighbour_prediction`: a robust affine map or the mean displacement of
           a group that moved alike; an affine map only where it determines the marker).
           Short intervals keep this accurate on a bending, pitching wing.
        2. Else from the reference frame (the first frame of the pass, where every marker
           is known) by a robust affine map on its nearest reliable neighbours of its kind
           (moving ones for a marker that moved, still ones for one that did not): a planar
           wing seen from afar moves by an affine map however much time has passed. An
           affine map is used only where its neighbours determine it
           (:func:`_determined`: not a marker off the line of neighbours on a row); a
           marker on that line is mapped by the row's 1-D map (:func:`_line_prediction`),
           from three neighbours on.
        3. An isolated marker (fewer than two other markers within ``self.local`` px in
           the reference frame, ok now or not - the two-marker rigid target, a reference
           dot) is searched for in a wide window
           (``search_radius``) at its last position, moved like its one neighbour if it has
           one, and accepted only with a score of at least ``max(reacquire_score, 0.9)``.

        ``moving`` (bool, all markers) says which were moving when last seen
        (:func:`~.relocate._was_moving` with the rows written), as :meth:`_reacquire`
        computed it once for the frame.

        The neighbours (``okn``) are the markers ok now, and those flagged only
        ``imprecise`` that were certain on the last :data:`_ANCHOR_FRAMES` frames
        (:meth:`_reacquire`).
        """
        p = self.p
        ref = self.ref_pos
        if self.nh[i] < 2:
            # a marker whose motion was never seen (lost since its pick), beside both still
            # markers and moving ones: whether it is a static dot or on the wing is not
            # known, and the two kinds of anchors put it apart - it is not predicted (hard
            # DEV seed 82 left: wing marker 8 beside the mount, lost from frame 1, was put
            # at its pick by the mount and reference dots and re-acquired there on another
            # marker's blob 17 px off, ok for 43 frames)
            # (its neighbours on the reference frame, ok now or not: the wing beside it may
            # be lost with it)
            near = np.flatnonzero(np.hypot(ref[:, 0] - ref[i, 0], ref[:, 1] - ref[i, 1]) <= self.local)
            near = near[near != i]
            moves = moving[near]
            if moves.any() and (~moves).any():
                return None
        ti = int(self.hist_t[i, 0])
        Pi = self.hist_x[i, 0]
        # its position on frame ti as written there, to be moved as its neighbours' rows
        # there moved since (the motion model's copy Pi is moved with a measured camera bump
        # or a dropped frame, Tracker._set_model; mixed with the neighbours' rows it put two
        # markers of a row a bump's 7.5 px off, on their neighbours' blobs: bumped DEV seed
        # 93 right, markers 20 and 21, under a looser edge rule not kept)
        # No row written there (it coasted out of the frame, or was lost): the last frame
        # with one, never the model's copy - a repeated frame moves that copy back along
        # its motion while ti stays (GlitchStage._set_model): a dot coasting out of view,
        # moved back three frames by three repeated frames, was mapped 25 frames later to
        # where it had been three frames before it left - onto the next dot of the grid,
        # ok 35 px off and a wrong neighbour for two more (real dots, repeated, DEV seed 6
        # cam1)
        ti = _last_written(res, i, ti, int(self.last_ok[i]))
        Pt = None if ti is None else np.array([res.x[ti, i], res.y[ti, i]])
        cand = okn[okn != i]
        if Pt is not None and cand.size:
            c1, prev = self._neighbours_then(i, ti, Pt, okn, res, alike_only=True)
            if (c1.size >= 3 or (c1.size == 2 and abs(t - ti) <= _PAIR_FRAMES)) and (c1.size < 4 or _determined(Pt, prev)):
                # (a mean displacement that may miss it by a quarter of its spacing
                # predicts nothing: three neighbours 100 px from a dot of a rotating grid,
                # 23 frames on, moved it 34 px from where it was, onto the next dot -
                # real dots, dropped, DEV seed 101 cam1 - which took the next one's)
                pq = _neighbour_prediction(Pt, prev, np.column_stack([X[c1], Y[c1]]),
                                           max_reach=_REACH_SPACING * float(self._spacing[i]))
                if pq is not None:
                    logger.debug("frame %d: marker %d predicted from its neighbours on frame %d %s", t, i, ti,
                                 c1.tolist())
                    return pq[0], p.reacquire_radius, p.reacquire_score, c1
        # 2. from the reference frame
        cur = np.column_stack([X[okn], Y[okn]])
        if okn.size >= 3:
            use = np.ones(okn.size, bool)
            if self.nh[i] >= 2 and self.hist_t[i, 0] != self.hist_t[i, 1]:
                v = np.hypot(*(self.hist_x[i, 0] - self.hist_x[i, 1])) / abs(self.hist_t[i, 0] - self.hist_t[i, 1])
                still = np.hypot(cur[:, 0] - ref[okn, 0], cur[:, 1] - ref[okn, 1]) < STILL_PX
                # (still: slow when last seen and still where it was in the reference frame -
                # a wing marker lost at stroke reversal is slow too)
                group = still if v < STILL_SPEED and math.hypot(*(Pi - ref[i])) < STILL_PX else ~still
                # (a moving marker is not mapped by static dots, nor a static one by the wing)
                use = group
            cidx = np.flatnonzero(use)
            d = np.hypot(ref[okn[cidx], 0] - ref[i, 0], ref[okn[cidx], 1] - ref[i, 1])
            order = cidx[np.argsort(d)]
            for k in (6, 5, 4):
                near = order[:k]
                if near.size < 4:
                    break
                if not _determined(ref[i], ref[okn[near]]):
                    continue  # (the neighbours on a line: 2b below)
                if near.size == 4 and not self._sure_since(okn[near][_hinges(ref[i], ref[okn[near]])], res, t, i):
                    continue
                M, rms, nin = _robust_affine(ref[okn[near]], cur[near], quality=True)
                if M is not None and nin >= 4 and rms <= 1.5:
                    logger.debug("frame %d: marker %d predicted from the reference frame by %s (rms %.2f)", t, i,
                                 okn[near].tolist(), rms)
                    return _apply_affine(M, ref[i][None, :])[0], p.reacquire_radius, p.reacquire_score, okn[near]
            # 2b. too few of its kind for an affine map (a wing turning edge-on may leave
            # only one row of markers ok): a marker on the line they form is still mapped
            near = order[:6]
            if near.size >= 3:
                ql = _line_prediction(ref[i], ref[okn[near]], cur[near], 0.25 * float(self._spacing[i]))
                if ql is not None:
                    logger.debug("frame %d: marker %d predicted on the line of %s", t, i, okn[near].tolist())
                    return ql, p.reacquire_radius, p.reacquire_score, okn[near]
        # 3. an isolated marker: fewer than two other markers near it in the reference
        # frame (not: fewer than two ok now - its neighbours may be lost with it)
        others = np.flatnonzero(np.isfinite(ref[:, 0]))
        others = others[others != i]
        if np.count_nonzero(np.hypot(ref[others, 0] - ref[i, 0], ref[others, 1] - ref[i, 1]) <= self.local) >= 2:
            return None
        nbr = cand[np.hypot(ref[cand, 0] - ref[i, 0], ref[cand, 1] - ref[i, 1]) <= self.local]
        if nbr.size >= 2:
            return None
        q = Pi.copy()
        if nbr.size == 1 and Pt is not None and res.status[ti, nbr[0]] == OK:
            j = nbr[0]
            q = Pt + (X[j] - res.x[ti, j], Y[j] - res.y[ti, j])
        return q, p.search_radius, max(p.reacquire_score, 0.9), nbr

    def _sure_since(self, nbrs, res, t, i):
        """Whether no neighbour of ``nbrs`` had its identity in doubt (:data:`_DOUBT`) on
        any frame since lost marker ``i``'s last ok frame (before ``t``): a hinge of a
        four-neighbour map (:func:`_hinges`) must not have. (Refusing every hinged map cost
        the real-dot DEV 0.9 % of its ok points, re-acquisitions all right; refusing those
        whose hinge was not ok or ``imprecise`` on every frame - lost for a low score,
        re-acquired - cost the dropped stress 0.8 %.)"""
        if not len(nbrs):
            return True
        rows = _frames_since(int(self.last_ok[i]), t, res.x.shape[0])
        return not np.isin(res.reason[np.ix_(rows, nbrs)], _DOUBT).any()

    def _certain_lately(self, res, t, direction):
        """Markers ok or only ``imprecise`` on each of the last :data:`_ANCHOR_FRAMES`
        frames before ``t`` (in the pass's direction; frames before its first count)."""
        T = res.x.shape[0]
        rows = [t - direction * k for k in range(1, _ANCHOR_FRAMES + 1) if 0 <= t - direction * k < T]
        if not rows:
            return np.ones(res.x.shape[1], bool)
        return _certain(res.status[rows], res.reason[rows]).all(0)

    def _reacquire(self, frame, t, res, direction, X, Y, S, XP, YP, ST, RS, pred, step_velocity=None):
        """Search again for long-lost markers where their reliable neighbours put them.

        Each lost marker's position is predicted from its neighbours
        (:meth:`_predict_lost`). A blob found near the prediction is accepted only if it
        correlates well and unambiguously, if no other marker (tracked, or lost and
        predicted the same way) is expected nearer to it, if no uncertain marker is near
        (it could be that marker's blob; two lost markers found on distinct peaks do not
        block each other when their assignment fits their predictions better than the
        swap), if its refinement finds no foreign blob (the other markers found here are
        known blobs), and if the neighbours put its last ok position there. A marker
        that was moving when last seen (:func:`~.relocate._was_moving`) is predicted and
        checked only from anchors that are not still (within 1.5 px of their reference
        positions) and have roamed (:func:`~.relocate._roamed`): the static mount and
        dots, ok beside a wing marker on its last ok frame when its wing neighbours were
        not, kept the right blob refused to the end of the sequence.
        """
        p = self.p
        # the anchors: ok markers, and those flagged only for their precision
        # (``imprecise`` is the first status rule: every identity rule passed)
        # - followed without doubt on the last _ANCHOR_FRAMES frames: a marker just re-acquired
        # (or coasting back) may still be on another's blob, and it would pass that on
        anchor = (ST == OK) | ((ST == FLAGGED) & (RS == _R["imprecise"]) & np.isfinite(X)
                              & self._certain_lately(res, t, direction))
        okn = np.flatnonzero(anchor)
        if okn.size < 1:
            return
        lost = np.flatnonzero(self.lostflag)
        # where every marker is expected: its position, else (tracked but without a
        # position on this frame) its prediction; long-lost ones from the neighbours below
        est_x = X.copy()
        est_y = Y.copy()
        nopos = ~np.isfinite(X) & ~self.lostflag
        est_x[nopos], est_y[nopos] = pred[nopos, 0], pred[nopos, 1]
        # a marker that was moving when last seen (the wing) is predicted and checked from
        # the neighbours that are not still now: the static mount and dots say nothing of
        # where a wing marker went (they would keep it at its last position). One that was
        # still when last seen may be a static dot or a wing marker lost at rest: every
        # anchor may speak for it (its wing neighbours tell it from a static dot).
        # The anchors away from their reference positions must also have roamed
        # (relocate.ROAM_PX): after a camera bump the tracker did not measure, the static
        # dots are away by the bump, and they mapped a wing marker lost with its whole wing
        # to its frame-0 position - on another marker's blob there, 29 px off (bumped DEV
        # seed 3 right, marker 13, with a variant of the edge rule not kept).
        roamed = _roamed(self, res)
        moving = _was_moving(self) | roamed
        anchor_away = _moving(self, X, Y, anchor) & roamed  # (anchors have positions)
        q = {}
        for i in lost.tolist():
            r = self._predict_lost(i, okn[anchor_away[okn]] if moving[i] else okn, X, Y, res, t, moving)
            if r is None:
                logger.debug("frame %d: marker %d: no prediction (%d ok)", t, i, okn.size)
            else:
                q[i] = r
                est_x[i], est_y[i] = r[0]
        valid = np.isfinite(est_x)
        found = {}
        for i, (qi, rad, min_sc, nbrs) in q.items():
            ci = np.rint(qi).astype(np.int64)
            if self._fit_margin(np.array([i]), ci[None, :])[0] < 0:
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
                logger.debug("frame %d: marker %d: score %.2f, second %.2f", t, i, sc, second[0])
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
                    logger.debug("frame %d: marker %d: another prediction nearer (%.1f, %.1f, %.1f px)", t, i, dq, do, dqo)
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
                    apart = math.hypot(mj[0] - mx, mj[1] - my) > max(self.rb[i], self.rb[j]) + 1.0
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
            else:
                logger.debug("frame %d: marker %d at (%.1f, %.1f), predicted (%.1f, %.1f): blocked by %s", t, i, mx, my,
                             q[i][0][0], q[i][0][1], blockers.tolist())
        for i in accept:
            mx, my, sc, _ = found[i]
            nbrs = q[i][3]
            # the blob must also be where the neighbours (those moving, for a marker that was
            # moving) put the marker's last ok position (a long interval: 4 px tolerance, a
            # neighbour's blob is further)
            Xi, Yi = X[i], Y[i]
            X[i], Y[i] = mx, my
            judge = anchor_away if moving[i] else anchor
            wrong = self._inconsistent(np.array([i]), X, Y, np.where(judge, OK, FLAGGED), res, t,
                                       min_lim=4.0).size > 0
            X[i], Y[i] = Xi, Yi
            if wrong:
                logger.debug("frame %d: marker %d: inconsistent with its neighbours", t, i)
                continue
            # the blobs of the other markers found here count as known neighbours (two lost
            # markers side by side would otherwise see each other's blob as foreign)
            ox, oy = X.copy(), Y.copy()
            for j, fj in found.items():
                if j != i and not np.isfinite(ox[j]):
                    ox[j], oy[j] = fj[0], fj[1]
            rx, ry, mass, inf = self._refine_candidate(frame, i, mx, my, ox, oy)
            if not mass[0] > p.min_mass_ratio * self.mass0[i] or inf["foreign"][0]:
                logger.debug("frame %d: marker %d: faint or foreign", t, i)
                continue
            X[i], Y[i], S[i], XP[i], YP[i] = rx[0], ry[0], sc, mx, my
            logger.debug("frame %d: marker %d re-acquired at (%.1f, %.1f), score %.2f", t, i, rx[0], ry[0], sc)
            ST[i] = FLAGGED
            RS[i] = _R["reacquired"]
            est_x[i], est_y[i] = rx[0], ry[0]
            # restart the motion model with the neighbours' velocity; none known: no velocity
            # (one point of history: searched wide next frame) rather than a made-up still one
            tp = t - direction
            vel = _restart_velocity(nbrs, X, Y, res, tp)
            if vel is not None and step_velocity is not None:
                vel = step_velocity(vel)  # (not the camera's bump, over the frames dropped)
            self.hist_x[i] = np.nan
            self.hist_x[i, 0] = (rx[0], ry[0])
            self.hist_t[i] = (t, tp, tp - direction)
            if vel is None:
                self.nh[i] = 1
            else:
                self.hist_x[i, 1] = (rx[0] - vel[0], ry[0] - vel[1])
                self.nh[i] = 2
            self.resid_rms[i] = 1.0
            self.lostflag[i] = False
            self.restarted[i] = True
            self.last_ok[i] = t  # checked against the neighbours: the reference from now on


