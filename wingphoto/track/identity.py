"""Identity: conflicts, neighbour consensus, vouching and consistency checks."""
from __future__ import annotations

import math

import numpy as np

from .hop import HOP_FRACTION, _frames_since, from_last_reacquisition, hopped
from .geometry import _apply_affine, _fit_affine, _nearest_two, _neighbour_prediction
from . import engine
from .match import _analyse_maps, _climb_kernel
from .predict import STILL_SPEED, model_speed
from .reacquire import _determined
from .relocate import STILL_PX
from .status import _R, FLAGGED, OK

#: Reasons that put a marker's blob in doubt: after one, a marker no neighbour can vouch for
#: does not resume ok on its own prediction (:meth:`IdentityStage._disputed`).
_DISPUTED = (_R["conflict"], _R["jump"])

#: A flagged marker further than this fraction of its spacing (and than the neighbours'
#: tolerance) from where its neighbours put it is astray (:meth:`IdentityStage._astray`).
ASTRAY_FRACTION = 0.4
#: Fewest neighbours that judge whether a flagged marker is astray.
ASTRAY_NEIGHBOURS = 2
#: Fewest neighbours whose affine map, fitted however unlike their moves, may contradict a
#: resuming marker that no agreeing group vouches for (:meth:`IdentityStage._map_verdict`).
CONTRADICT_NEIGHBOURS = 3
#: Largest distance of a resuming marker from its neighbours' line, in units of their
#: spread across it, for their map to contradict it (:meth:`IdentityStage._map_verdict`;
#: twice re-acquisition's :data:`~.reacquire._AMPLIFY`: the map only flags, with a
#: tolerance of ``ASTRAY_FRACTION`` of the spacing, not a pixel).
CONTRADICT_AMPLIFY = 8.0


#: Frames in a row without a position after which a marker found again on its own
#: prediction needs its neighbours to vouch for it (:meth:`IdentityStage._coasted`).
COASTED_FRAMES = 2

#: The wide-search consensus (:meth:`IdentityStage._consensus`) takes only markers with a
#: motion model that moves them as anchors when at least this many lie within a marker's
#: neighbourhood.
_TRACKED_ANCHORS = 3
#: A wide match less than half a spacing from where its marker was is contested when at
#: least this many of the wide-searched neighbours (:meth:`IdentityStage._contested`), and
#: more than agree with it, moved half a spacing or more differently.
_CONTESTED_MIN = 2
#: ... counting only neighbours whose match lies less than this many of their spacings from
#: where they were: one further may be the next look-alike of a small move (the still
#: discs of a mount, 20 px apart, whose ambiguous best peaks are their neighbours' discs).
_CONTESTED_REACH = 0.75

#: :meth:`IdentityStage._off_path`: the previous image must show the marker within this
#: fraction of its move (at least ``_PATH_MIN_PX``) of the point a constant velocity puts
#: it at, with at least this share of its match's score.
_PATH_SLACK = 0.2
_PATH_MIN_PX = 3
_PATH_SCORE = 0.5


class IdentityStage:
    """Identity checks of :class:`~wingphoto.track.tracker.Tracker`.

    The correlation search (:meth:`_search`, with the wide search's :meth:`_consensus`),
    the conflict test (:meth:`_conflicts`) and the neighbour checks after the status rules
    (:meth:`_vouch`, :meth:`_inconsistent`, :meth:`_neighbours_then`; the re-acquisition
    uses the last two too). They write only the frame's results - the
    :class:`~wingphoto.track.tracker.FrameContext` ``ctx`` or the arrays passed in - and
    read the tracker's state without changing it: the motion model (``hist_x``,
    ``hist_t``, ``nh``, ``resid_rms``, ``last_ok``, ``lostflag``), the markers' sizes
    (``h``, ``rb``), the picks' frame's layout (``ref_pos``, ``local``, ``_spacing``), the
    templates (``tz``, and through :meth:`~.templates.TemplateStage._match`), the image
    size (``W``, ``H``), the options ``p`` and the rows already written (``res``).
    """

    def _vouch(self, jmp, chk, ctx, res, t):
        """Neighbour checks after the status rules, on ``ctx.ST, ctx.RS`` of markers
        ``jmp`` (flagged 'jump') and ``chk`` (ok, to be checked).

        A 'jump' from the motion model that the neighbours made too (the whole wing, or
        the rigid target between two stills, stopped or turned at once) is none: the
        neighbours are the ok markers, and the other jumpers too when the jump is too
        short to have landed on another marker's blob (< 40 % of the spacing); a lone
        marker (nothing to compare with) is vouched for by a short jump (< 30 % of the
        spacing) to a strong, unambiguous match. Then a marker resuming after a gap, or
        restarting, must have moved like its neighbours since it was last ok (without
        neighbours that moved alike to vouch for it: only where the map of three or more
        unlike ones does not contradict it, :meth:`_map_verdict`, close to its own
        prediction, and only with three points of its own in the motion model - a prediction from a re-acquisition's
        borrowed velocity, not corrected since, put markers on neighbours' blobs near it:
        independent renderer, dropped, extra DEV seeds 8 and 9 right, 7 ok points 12-14 px
        off)."""
        p = self.p
        X, Y, S, SEC, ST, RS, resid = ctx.X, ctx.Y, ctx.S, ctx.SEC, ctx.ST, ctx.RS, ctx.resid
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
            # no neighbour's verdict: resuming after a gap, it needs three points of its own
            # and to be near its own prediction; on the frame after its re-acquisition, to
            # be near that prediction
            open_ = np.setdiff1d(chk, np.concatenate([bad, good]))
            gap = np.abs(t - self.last_ok[open_]) > 1
            off = resid[open_] > np.maximum(2.0, 2.0 * self.resid_rms[open_])
            unk = open_[gap]
            far = open_[(gap & (off | (self.nh[open_] < 3))) | (~gap & off & self._just_reacquired(open_, res))]
            # (changed blob while not ok, or its blob was disputed: its own prediction may
            # follow the wrong blob)
            other_blob = unk[self._hopped(unk, res, t, now=(X, Y)) | self._disputed(unk, res, t)
                             | self._merged_with_lost(unk, ST, res, t)]
            sure = ST.copy()  # (the map is fitted to vouched neighbours only)
            sure[np.concatenate([bad, unk]).astype(np.int64)] = FLAGGED
            verdict = self._map_verdict(unk, X, Y, sure, res, t)
            # (contradicted by the map; or found again on its own prediction after frames
            # without a position, and not placed by the map either)
            odd = unk[(verdict < 0) | ((verdict == 0) & self._coasted(unk, res, t))]
            bad = np.concatenate([bad, far, other_blob, odd]).astype(np.int64)
            ST[bad] = FLAGGED
            RS[bad] = _R["jump"]


    def _coasted(self, idx, res, t):
        """Whether each marker of ``idx``, since its last ok frame or its last
        re-acquisition if later, went ``COASTED_FRAMES`` frames in a row without a position
        and was then found again on its own prediction (boolean): extrapolated over those
        frames, the prediction may have landed on the next dot of a grid, and the path it
        followed since, consistent with itself, says nothing. Only for markers that no
        neighbour can vouch for. Real dots, black, fresh DEV seed 195 cam2: re-acquired, a
        black frame and two lost ones, found on the dot behind and ok 35 px off."""
        out = np.zeros(idx.size, bool)
        T = res.x.shape[0]
        for k, i in enumerate(idx.tolist()):
            fr = from_last_reacquisition(_frames_since(int(self.last_ok[i]), t, T), res.reason, _R["reacquired"], i)
            none = ~np.isfinite(res.x[fr, i])
            if none.size < COASTED_FRAMES:
                continue
            # a run of COASTED_FRAMES without a position (it has one now)
            run = np.convolve(none.astype(np.int64), np.ones(COASTED_FRAMES, np.int64), "valid")
            out[k] = bool((run == COASTED_FRAMES).any())
        return out

    def _just_reacquired(self, idx, res):
        """Whether each marker of ``idx`` was re-acquired on its last ok frame and has fewer
        than three points in its motion model (boolean): on the frame after its
        re-acquisition, predicted from one point and its neighbours' borrowed velocity,
        without a neighbour's verdict it must be near its prediction (2 px, as a marker
        resuming after a gap). Independent renderer, fresh DEV seed 146 dropped right: the
        whole wing was lost for three frames and re-acquired, three frames were dropped
        right after, and two tip markers, no neighbour ok on both frames to vouch or object,
        turned ok on other markers' blobs 13-16 px off, 2.7 and 3.7 px from their
        predictions. (Judging them fully as resuming after a gap - three points of their
        own - left whole re-acquired wings unvouched: DEV ok 77.8 -> 56.4 %.)"""
        T = res.x.shape[0]
        lo = self.last_ok[idx].astype(np.int64)
        inside = (lo >= 0) & (lo < T)
        out = np.zeros(idx.size, bool)
        out[inside] = res.reason[lo[inside], idx[inside]] == _R["reacquired"]
        return out & (self.nh[idx] < 3)

    def _map_verdict(self, idx, X, Y, ST, res, t):
        """Whether each resuming marker of ``idx`` is far from where its neighbours' affine
        map puts it, though they did not move alike: -1 contradicted, +1 placed there, 0
        no such map (int8).

        :meth:`_inconsistent` compares a marker only with neighbours that agree on one
        motion (an affine map with RMS <= 1.5 px, or a group that moved alike); over a gap
        of a few frames at stroke reversal the wing turns and stretches, three neighbours
        move 23-30 px in different directions, and nothing is compared. The map fitted to
        those ok on the marker's last ok frame and now (at least ``CONTRADICT_NEIGHBOURS``,
        :meth:`_neighbours_then`, and only those away from their reference positions, as a
        moving marker is: a map of a wing marker and two static dots flagged a right marker
        on independent black DEV seed 1 right; by least squares, exact for three; ``ST`` must not call ok
        the markers still to be vouched for: one resumed 13 px off on a neighbour's blob,
        as a neighbour, flagged a right marker on independent bumped DEV seed 2 left) still says where it
        went when it determines the marker (:func:`~.reacquire._determined` with
        ``CONTRADICT_AMPLIFY``); further than
        ``ASTRAY_FRACTION`` of its spacing (and than 2.5 px plus twice the map's RMS) is a
        contradiction. Flags only, and places only a marker found again on its own
        prediction after frames without a position (:meth:`_coasted`): a marker that no
        such map determines is not judged.
        Independent renderer, standard DEV ``dropped`` seed 2 right: marker 21, lost on the
        frame the three dropped frames were found on, resumed next frame on a neighbour's
        blob 1.4 px from its twice-extrapolated prediction, 11 px off; its three
        neighbours' map put it within 0.6 px of the truth."""
        out = np.zeros(idx.size, np.int8)
        okn = (ST == OK).nonzero()[0]
        T = res.x.shape[0]
        for k, i in enumerate(idx.tolist()):
            ti = int(self.last_ok[i])
            if not 0 <= ti < T or ti == t or not np.isfinite(res.x[ti, i]):
                continue
            Pi = np.array([res.x[ti, i], res.y[ti, i]])
            if math.hypot(X[i] - self.ref_pos[i, 0], Y[i] - self.ref_pos[i, 1]) < STILL_PX:
                continue  # (a still marker: its still neighbours agree, or say nothing)
            cand, prev = self._neighbours_then(i, ti, Pi, okn, res)
            wing = np.hypot(X[cand] - self.ref_pos[cand, 0], Y[cand] - self.ref_pos[cand, 1]) >= STILL_PX
            cand, prev = cand[wing], prev[wing]
            if cand.size < CONTRADICT_NEIGHBOURS or not _determined(Pi, prev, CONTRADICT_AMPLIFY):
                continue
            now = np.column_stack([X[cand], Y[cand]])
            M = _fit_affine(prev, now)
            rms = float(np.sqrt(np.mean(np.sum((_apply_affine(M, prev) - now) ** 2, axis=1))))
            q = _apply_affine(M, Pi[None, :])[0]
            lim = max(2.5 + 2.0 * rms, ASTRAY_FRACTION * self._spacing[i])
            out[k] = -1 if math.hypot(X[i] - q[0], Y[i] - q[1]) > lim else 1
        return out

    def _disputed(self, idx, res, t):
        """Whether each marker of ``idx`` was flagged ``conflict`` (another marker took its
        blob) or ``jump`` (it left its prediction, or its neighbours put it elsewhere) since
        its last ok frame (boolean): which blob it then followed is not known, and a marker
        no neighbour can vouch for does not resume ok on its own prediction after it, nor
        do its ``imprecise`` positions feed its motion model unless its neighbours vouch
        for them (:meth:`~.tracker.Tracker._update`). Not ``merged``: counted as a dispute
        it made a pair of markers swap blobs, ok 12 px off (independent repeated DEV seed
        7 left; 5 points of that sequence's ok share), for 2 errors it removed. A
        marker in a merged pair drifted onto its neighbour's blob over five flagged frames
        (conflict on two of them), then resumed ok on it, its neighbours all flagged or
        lost: ok 6-11 px off for five frames until the audit could judge it (independent
        renderer, clean16, fresh DEV seed 43 right). After a jump, flagged ``imprecise``
        positions 21 px off fed the motion model for twelve frames (an imprecise point
        feeds it) and the marker resumed ok on a neighbour's blob, 10-12 px off, its
        neighbours all lost (bumped DEV seed 30 right, with the poor-match margin of
        :meth:`~.tracker.Tracker._poor_match` in an early form)."""
        out = np.zeros(idx.size, bool)
        for k, i in enumerate(idx.tolist()):
            fr = _frames_since(int(self.last_ok[i]), t, res.x.shape[0])
            out[k] = bool(np.isin(res.reason[fr, i], _DISPUTED).any())
        return out

    def _merged_with_lost(self, idx, ST, res, t):
        """Whether each marker of ``idx`` shared a blob (``merged``) since its last ok frame
        with a neighbour that is not ok now and has not been since (boolean): which of
        the two blobs it left the merger on is not known, and the other marker, lost or
        flagged, cannot say. Only for markers that no neighbour can vouch for.

        A merger alone is no dispute (:meth:`_disputed` says why); a merger whose partner
        was then lost is. Independent renderer, clean16, fresh DEV seed 66 right: marker
        18 shared marker 19's blob at an edge-on turn, 19 was lost, and 18 drifted over
        flagged frames onto 19's blob and resumed ok there, 8.6-15.7 px off for 14 frames
        (and misled its neighbour 17's re-acquisition onto its own blob); seed 53 left:
        markers 9 and 10 the same, 6-8 px off.

        So is a ``foreign`` flag (a blob no known marker explains touched it) while one of
        its two nearest markers of the reference frame was, then, lost or misplaced, and
        has not been ok since: the blob may have been that marker's (black, DEV seed 57
        left: marker 21 flagged foreign beside marker 20, mis-tracked and then lost at a
        50-65 deg view, drifted 2 px onto their joined blob and resumed ok there, sigma
        0.17-0.19)."""
        out = np.zeros(idx.size, bool)
        for k, i in enumerate(idx.tolist()):
            fr = _frames_since(int(self.last_ok[i]), t, res.x.shape[0])
            fr = fr[np.isin(res.reason[fr, i], (_R["merged"], _R["foreign"])) & np.isfinite(res.x[fr, i])]
            for f in fr.tolist():
                if res.reason[f, i] == _R["foreign"]:
                    # an unexplained blob: its two nearest markers of the reference frame
                    near = np.zeros(len(ST), bool)
                    jj = self._ref_j2[i][self._ref_j2[i] >= 0]
                    near[jj] = ST[jj] != OK
                else:
                    d = np.hypot(res.x[f] - res.x[f, i], res.y[f] - res.y[f, i])
                    with np.errstate(invalid="ignore"):
                        near = (d <= self.rb[i] + self.rb + 1.0) & (ST != OK)
                near[i] = False
                j = near.nonzero()[0]
                # not ok since the merger (its last ok frame is before it)
                if j.size and (np.abs(self.last_ok[j] - t) > np.abs(f - t)).any():
                    out[k] = True
                    break
        return out

    def _hopped(self, idx, res, t, now=None):
        """Whether each marker of ``idx`` changed blob while it was not ok (boolean).

        Its positions written since its last ok frame, or since its last re-acquisition if
        later (flagged ones; lost frames are skipped), and with ``now`` (X, Y arrays) its
        position on this frame, are followed step by step. (Without this frame's step a
        marker resuming after one flagged frame was not judged: two steps, one
        acceleration - it hopped 10 px onto a runaway neighbour's blob at a 66 deg view
        and resumed ok there, independent renderer, hard, fresh DEV seed 65 left.) A
        one-frame stall (a step < ``STALL_PX`` after which the path resumes, as on a
        repeated frame) is dropped; a step over one or two frames without a position counts
        at its mean velocity (a dot that left the view for a frame came back 35 px off, onto
        the next grid dot, and ran a grid diagonal per frame, ok 105-243 px off: real dots,
        repeated, fresh DEV seed 254 cam2; one lost for two frames was found on the dot
        behind, ok 46 px off: dropped, seed 162 cam1); then a step that differs from the
        step before by more than ``HOP_FRACTION`` of the marker's spacing is a hop onto
        another blob (a neighbour's, or an unpicked marker's), which the motion model then
        follows, so that the marker resumes near its prediction on the wrong blob. Only for
        markers that no neighbour can vouch for."""
        T = res.x.shape[0]
        t0 = self.last_ok[idx].astype(np.int64)
        # (two steps at least: with this frame's, one frame between; without, two)
        judged = (t0 >= 0) & (t0 < T) & (np.abs(t - t0) >= (2 if now is not None else 3))
        out = np.zeros(idx.size, bool)
        out[judged] = hopped(res.x, res.y, res.reason, _R["reacquired"], idx[judged], t0[judged], t, now,
                             HOP_FRACTION * self._spacing[idx[judged]])
        return out

    def _astray(self, idx, X, Y, ST, res, t):
        """Flagged markers of ``idx`` that left the place their neighbours put them (boolean).

        The neighbours ok on the marker's last ok frame and now (:meth:`_neighbours_then`,
        at least ``ASTRAY_NEIGHBOURS``) map its last ok position to now
        (:func:`_neighbour_prediction`; an affine map only where it determines the marker,
        :func:`~.reacquire._determined`: four far neighbours near a line put real dots
        followed on their own blobs 30-60 px away); further than the prediction's
        tolerance and than ``ASTRAY_FRACTION`` of the marker's spacing is astray. Only a
        marker that was ok on that frame is judged (not a pick flagged from the start, as
        real dots often are: the few far neighbours ok then mispredict it). Astray: the
        flagged marker follows another blob (a neighbour's, an unpicked marker's, or a
        smear of the membrane turning edge-on) and, fed to its motion model, would lead
        its prediction there, so that it resumes on that blob near its prediction, and
        serve re-acquisition as an anchor. A marker without such neighbours is not
        judged."""
        out = np.zeros(idx.size, bool)
        okn = (ST == OK).nonzero()[0]
        T = res.x.shape[0]
        for k, i in enumerate(idx.tolist()):
            ti = int(self.last_ok[i])
            if not 0 <= ti < T or ti == t or res.status[ti, i] != OK or not np.isfinite(res.x[ti, i]):
                continue
            Pi = np.array([res.x[ti, i], res.y[ti, i]])
            cand, prev = self._neighbours_then(i, ti, Pi, okn, res)
            if cand.size < ASTRAY_NEIGHBOURS:
                continue
            if cand.size >= 4 and not _determined(Pi, prev):
                cand, prev = cand[:3], prev[:3]  # (their mean move, if they moved alike)
            pq = _neighbour_prediction(Pi, prev, np.column_stack([X[cand], Y[cand]]))
            if pq is None:
                continue
            q, lim = pq
            out[k] = math.hypot(X[i] - q[0], Y[i] - q[1]) > max(lim, ASTRAY_FRACTION * self._spacing[i])
        return out

    def _neighbours_then(self, i, ti, Pi, okn, res, alike_only=False):
        """Up to six neighbours of marker ``i``, nearest first: ok now (``okn``) and on frame
        ``ti``, within ``self.local`` px of its position ``Pi`` then, and - when two or
        more did - those that moved like it then (not the static mount and reference dots
        for a wing marker). With ``alike_only``, only those that moved like it, however few
        (when its motion then is known): a wing marker is not predicted from static dots. Returns
        their indices and positions on frame ``ti``."""
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
                if same.sum() >= 2 or alike_only:
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
        okn = (ST == OK).nonzero()[0]
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
            if since is None and math.hypot(Pi[0] - self.ref_pos[i, 0], Pi[1] - self.ref_pos[i, 1]) >= STILL_PX:
                # a wing marker resuming ok: still markers (the mount, the reference dots)
                # say nothing of where the wing went, even while it is slow at a reversal
                # (bumped DEV seed 0 right: the two mount dots vouched for marker 9 resuming
                # on its lost partner's merged blob, ok 2.4 px off). They still let a
                # flagged point feed the motion model (since=...): two converging discs
                # beside two still ones, merged, coasted and were lost without it
                # (tests/test_track.py::test_converging_markers_are_never_both_ok_on_one_blob)
                wing = np.hypot(X[cand] - self.ref_pos[cand, 0], Y[cand] - self.ref_pos[cand, 1]) >= STILL_PX
                cand, prev = cand[wing], prev[wing]
            if cand.size < min_m:
                continue
            pq = _neighbour_prediction(Pi, prev, np.column_stack([X[cand], Y[cand]]), min_m, reach=True)
            if pq is None:
                continue  # the neighbours do not move together: nothing to compare with
            q, lim, lim_vouch = pq
            if math.hypot(X[i] - q[0], Y[i] - q[1]) > max(lim, min_lim):
                bad.append(i)
            elif lim_vouch <= ASTRAY_FRACTION * self._spacing[i]:
                good.append(i)
            # (else: so unsure a prediction cannot tell its blob from a neighbour's, and
            # vouches for neither; a miss beyond it still condemns - dropped DEV seed 47
            # left: a marker 15 px off, 19 px from where two far neighbours put it with a
            # tolerance of 4.9 px, was otherwise left to its own motion model, which had
            # followed it there)
        if both:
            return np.array(bad, np.int64), np.array(good, np.int64)
        if since is not None:
            return np.array(good, np.int64)
        return np.array(bad, np.int64)

    def _conflicts(self, sidx, ctx):
        """Markers that lost a blob to another marker this frame (boolean, all markers).

        Only a searched marker can land on another's blob (a fast-path marker stays within
        a pixel of its own prediction), so searched markers ``sidx`` are tested against
        all with a pixel-level position (``ctx.XP, ctx.YP``); of two on one blob, the one
        further from its prediction (scaled by its motion model's residual and its gap)
        loses it, unless both are ``ctx.merged``.
        """
        XP, YP, merged = ctx.XP, ctx.YP, ctx.merged
        n = len(XP)
        lose = np.zeros(n, bool)
        si = sidx[np.isfinite(XP[sidx])]
        vi = np.isfinite(XP).nonzero()[0]
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
        cost = np.hypot(XP - ctx.pred[:, 0], YP - ctx.pred[:, 1]) / (self.resid_rms + 0.5 + (ctx.gap - 1))
        for a, b in zip(*np.nonzero(same)):
            i, j = si[a], vi[b]
            if merged[i] and merged[j]:
                continue  # touching blobs: both flagged 'merged' anyway
            lose[i if cost[i] > cost[j] else j] = True
        return lose


    def _search(self, frame, idx, ctx):
        """Windowed NCC around the predictions of markers ``idx``; wide-search consensus.

        Searches the window of radius ``ctx.r`` centred on the rounded prediction
        (``ctx.px, ctx.py``) and writes the best match's pixel and score and the runner-up's
        score to ``ctx.XP, ctx.YP, ctx.S, ctx.SEC``; the wide-searched markers are checked
        by :meth:`_consensus`, which may move their ``ctx.pred``. With numba, a marker
        whose window is small (radius <= 3: moving predictably) is hill-climbed from its
        prediction instead (a window that small has no room for a runner-up peak away
        from the best, so nothing is lost); one whose climb reaches the window's edge gets
        the full search, twice as wide."""
        p = self.p
        pred, px, py, r, wide, j2 = ctx.pred, ctx.px, ctx.py, ctx.r, ctx.wide, ctx.j2
        XP, YP, S, SEC = ctx.XP, ctx.YP, ctx.S, ctx.SEC
        if engine.use_numba():
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
        redo = (border & full & (ri < p.search_radius)).nonzero()[0]
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
            # (the nearest blob only: a best peak further than half the spacing from where the
            # marker was may be a neighbour's, and then so may the neighbours' best peaks)
            near = wsel & (np.hypot(mx - pred[idx, 0], my - pred[idx, 1]) < 0.5 * self._spacing[idx])
            second[near] = self._runner_up_by_matches(idx[near], maps[near], shp[near], origin[near], excl[near],
                                                      idx, mx, my, pred, j2)
            self._consensus(frame, idx, wsel, mx, my, score, second, excl, ctx)
        XP[idx] = mx
        YP[idx] = my
        S[idx] = score
        SEC[idx] = second


    @staticmethod
    def _runner_up_by_matches(widx, maps, shp, origin, excl, idx, mx, my, pred, j2):
        """Runner-up scores of the wide-searched markers ``widx`` (no velocity yet), a peak
        on the blob a neighbour matched on this frame not counted (its best pixel, if it was
        searched: ``idx``, ``mx, my``), nor one at its prediction (as for every search).

        The runner-up search leaves out the neighbours' *predicted* positions; without a
        velocity those are where the neighbours were, and on a wing moving fast at frame 0
        each marker's runner-up was its neighbour's blob a few pixels on: every wing marker
        ``ambiguous`` on frame 1, none fed its motion model, so frame 2 was searched wide
        again, and so on until all were lost (independent renderer, DEV seed 56 left,
        markers 12-14 px apart moving 2-7 px/frame; the best peaks were right). Only for a
        best peak within half the spacing of where the marker was (the caller): on a grid of
        equal still discs a wide search took each disc's neighbour's blob, 20 px off, and
        the neighbours' best peaks, shifted alike, explained each disc's own blob away."""
        at = np.array(pred, dtype=np.float64)
        at[idx, 0], at[idx, 1] = mx, my
        others = []
        for where in (pred, at):  # (as before, and where the neighbours matched)
            for k in range(2):
                jj = j2[widx, k]
                o = where[np.maximum(jj, 0)] - origin
                o[jj < 0] = np.nan
                others.append(o)
        return _analyse_maps(maps, shp, excl, others)[3]

    def _contested(self, idx, wsel, near, pred, mx, my):
        """Which wide matches ``near`` (boolean over ``idx``: unambiguous, less than half a
        spacing from where the marker was) their neighbourhood contests: of the wide-searched
        markers within ``self.local`` px on the reference frame (their best peaks, ambiguous
        or not), at least ``_CONTESTED_MIN``, and more than agree with it, moved half its
        spacing or more differently.

        A regular grid of alike dots moving more than half its spacing on a frame with no
        velocity yet shows each dot the one behind it nearer than its own: real dots,
        fresh DEV seed 780 cam1, frame 1, the grid 19.6 px on at a 33 px spacing - a dot
        matched the dot behind, 14 px back, unambiguous, and the far matches of the
        neighbours that moved with the grid anchor nothing (the rule below), so the near,
        aliased ones agreed with it; flagged only ``imprecise``, it fed its motion model
        and went ok 100.9 px off on frame 3. Contested, it is flagged and not fed."""
        out = np.zeros(len(idx), bool)
        ref = self.ref_pos
        disp = np.column_stack([mx - pred[idx, 0], my - pred[idx, 1]])
        wk = np.flatnonzero(wsel)
        for k in np.flatnonzero(near).tolist():
            i = idx[k]
            o = wk[wk != k]
            o = o[np.hypot(ref[idx[o], 0] - ref[i, 0], ref[idx[o], 1] - ref[i, 1]) <= self.local]
            with np.errstate(invalid="ignore"):
                apart = np.hypot(disp[o, 0] - disp[k, 0], disp[o, 1] - disp[k, 1]) >= 0.5 * self._spacing[i]
                # (a neighbour's match most of a spacing away is more likely the next
                # look-alike than a move that large: no vote against)
                plausible = np.hypot(disp[o, 0], disp[o, 1]) < _CONTESTED_REACH * self._spacing[idx[o]]
            n_apart = int((apart & plausible).sum())
            out[k] = n_apart >= _CONTESTED_MIN and n_apart > int((~apart).sum())
        return out

    def _off_path(self, idx, sel, pred, mx, my, score, ctx):
        """Which wide matches ``sel`` (boolean over ``idx``) of markers last fed two or more
        frames ago the previous image does not show on the way to (boolean over ``idx``).

        A wide search starts from where the marker was last fed, ``ctx.gap`` frames ago;
        moving at a constant velocity to its match, it passed, on the previous image,
        ``(gap - 1) / gap`` of the way there. Where the template matches nothing within
        ``_PATH_SLACK`` of the move (at least ``_PATH_MIN_PX``) of that point - best
        score below ``_PATH_SCORE`` of the match's - the match is no path the marker
        followed: on a regular grid of alike dots that moved more than half its spacing
        since, it is the dot behind (real dots, fresh seed 1011 cam1, black: frame 1 left
        a whole grid ambiguous, unfed; on frame 2 it had moved 24 px at a 28 px spacing,
        and the dots behind, 4 px from where the dots had been, vouched for each other:
        ok 28 px off). Not judged after dropped or repeated frames (``ctx.aged``: the
        previous image is not one frame back) nor without a previous image or after a
        blank one."""
        out = np.zeros(len(idx), bool)
        prev = self._prev
        k = np.flatnonzero(sel & (ctx.gap[idx] >= 2))
        if not k.size or ctx.aged != 0 or prev is None or prev.shape != (self.H, self.W) or not prev.max() > prev.min():
            return out  # (a blank previous image shows nothing)
        i = idx[k]
        g = ctx.gap[i].astype(np.float64)
        d = np.column_stack([mx[k] - pred[i, 0], my[k] - pred[i, 1]])
        via = pred[i] + d * ((g - 1) / g)[:, None]
        rr = np.maximum(_PATH_MIN_PX, np.ceil(_PATH_SLACK * np.hypot(d[:, 0], d[:, 1]))).astype(np.int64)
        ci = np.rint(via).astype(np.int64)
        inside = self._fit_margin(i, ci) >= 0
        k, i, ci, rr = k[inside], i[inside], ci[inside], rr[inside]
        if not k.size:
            return out
        maps, _, _ = self._match(prev, i, ci, rr)
        best = maps.reshape(len(k), -1).max(axis=1)
        out[k] = best < _PATH_SCORE * score[k]
        return out

    def _beyond_view(self, i, at, reach):
        """Whether marker ``i``'s template cannot be centred everywhere within ``reach`` px
        of ``at`` (the image's edge is less than its half-size ``h`` further).

        A wide search (no velocity yet) sees only where the whole template fits. A marker
        near the edge of the view whose own blob moved towards it, or out of it, is not
        seen there, and its best match is the next look-alike the other way: a far match
        that no anchor can check, unambiguous, since its own blob left no rival peak. Real
        dots, fresh seed 946 cam1, frame 1: a dot 8 px from the left edge moving 20 px on a
        32 px grid took the dot behind it 18 px away (score 0.93 against 0.36), all its
        neighbours ambiguous, and was ok one spacing further off on every frame (32-128
        px); fresh seed 1011 cam1: a dot 6 px from the top edge, leaving the view, took the
        dot behind it, ok 28 and 55 px off."""
        return bool(self._fit_margin(np.array([i]), np.asarray(at)[None, :])[0] < reach)

    def _consensus(self, frame, idx, wsel, mx, my, score, second, excl, ctx):
        """Check wide-search matches (no velocity yet) against the wing's local motion.

        Each wide-searched marker's displacement from the reference frame is predicted from
        its nearest anchors (up to six, within ``self.local`` px in the reference frame):
        the other markers with a motion model (at their predictions) and the wide-searched
        markers whose match is unambiguous - only moving markers of the former when at
        least :data:`_TRACKED_ANCHORS` of them are there - (:func:`_neighbour_prediction`: a
        robust affine map, or the mean displacement of a group that moved alike), so that
        static mount and reference dots next to the wing, or a look-alike, do not decide.
        An ambiguous (or low-score) match is replaced by a search of radius 4 at the
        prediction; an unambiguous match that disagrees with the prediction is made
        ambiguous (flagged, not trusted), never moved. Without such a group the match
        stands as it is, but one further than half the marker's spacing from where it was
        while its neighbours did not move together is marked in ``unvouched`` (its point
        is flagged ``ambiguous``). With fewer than two anchors a far match stands, marked
        ``ctx.provisional`` (flagged, fed) where the marker's own blob may lie where no
        template fits (:meth:`_beyond_view`). A match contested by its neighbours
        (:meth:`_contested`) or off the path the previous image shows (:meth:`_off_path`)
        is marked ``ctx.unvouched``, and the latter anchors nothing. Prevents a marker
        starting (or restarting) on its neighbour's or an unpicked marker's blob when its
        own is dim or the two look alike.
        """
        p = self.p
        pred, unvouched, provisional = ctx.pred, ctx.unvouched, ctx.provisional
        n = len(self.h)
        ref = self.ref_pos
        ax = np.full(n, np.nan)
        ay = np.full(n, np.nan)
        tracked = (self.nh >= 2) & ~self.lostflag
        with np.errstate(invalid="ignore"):
            moving = tracked & (model_speed(self.hist_x, self.hist_t) >= STILL_SPEED)
        ax[tracked], ay[tracked] = pred[tracked, 0], pred[tracked, 1]
        amb = (second >= score - p.ambiguity_margin) | (score < p.min_score)
        good = wsel & ~amb
        # a match half a spacing or more from where the marker was may be the next blob of
        # a regular grid: it anchors no other marker, and only anchors that are not such
        # matches vouch for it (real dots, fresh DEV seed 680 cam1, frame 1: dots ~15
        # px/frame on a 29 px grid; those leaving the view took the next dots 19-23 px
        # away, unambiguous, and their neighbours followed them one spacing back: ok 31-92
        # px off)
        far = np.hypot(mx - pred[idx, 0], my - pred[idx, 1]) >= 0.5 * self._spacing[idx]
        unvouched[idx[self._contested(idx, wsel, good & ~far, pred, mx, my)]] = True
        off = self._off_path(idx, good, pred, mx, my, score, ctx)
        unvouched[idx[off]] = True
        anchor = good & ~far & ~off
        ax[idx[anchor]], ay[idx[anchor]] = mx[anchor], my[anchor]
        anchors = np.flatnonzero(np.isfinite(ax))
        redo, qs = [], []
        for k in np.flatnonzero(wsel).tolist():
            i = idx[k]
            cand = anchors[anchors != i]
            d = np.hypot(ref[cand, 0] - ref[i, 0], ref[cand, 1] - ref[i, 1])
            cand, d = cand[d <= self.local], d[d <= self.local]
            if cand.size < 2:
                # nothing to check it against: a far match stands, unless the marker's own
                # blob may have gone where no template fits (:meth:`_beyond_view`)
                if good[k] and far[k] and self._beyond_view(i, pred[i], math.hypot(mx[k] - pred[i, 0], my[k] - pred[i, 1])):
                    provisional[i] = True
                continue
            if moving[cand].sum() >= _TRACKED_ANCHORS:
                # moving markers with a motion model predict better than other wide matches,
                # which may have moved together onto the next blobs of a regular grid (real
                # dots, extra DEV seed 32 cam1, frame 2: four dots of a row leaving the view,
                # with no velocity after a flagged frame 1, took the next dots along their
                # row and vouched for each other: ok 34 px off). (Still ones - the mount,
                # the reference dots - would hold a wing marker still.)
                cand, d = cand[moving[cand]], d[moving[cand]]
            near = cand[np.argsort(d)[:6]]
            pq = _neighbour_prediction(ref[i], ref[near], np.column_stack([ax[near], ay[near]]))
            if pq is None:
                # the neighbours do not move together: no prediction to trust. A match
                # further than half the spacing from where the marker was may be a
                # neighbour's blob, and nothing vouches for it: its point is flagged
                # (``unvouched``; the match and the conflicts stay as they are). Real dots,
                # extra DEV seed 21 cam2, frame 1: a dot leaving the view took its grid
                # neighbour's blob 20 px away, unambiguous, while one of its three
                # neighbours had done the same: ok 30 px off.
                if good[k] and far[k]:
                    unvouched[i] = True
                continue
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
        okq = self._fit_margin(idx[redo], qi) >= 0
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

