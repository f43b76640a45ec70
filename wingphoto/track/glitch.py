"""Glitches of the sequence: blank, repeated, torn and dropped frames, camera bumps.

Three checks of :meth:`~.tracker.Tracker.step`, as methods of the tracker (a mixin, like the
other stages):

* :meth:`GlitchStage._frame_glitch`, before anything else: a blank (constant, or not
  finite) frame gives lost points; a byte-identical repeat gets the previous frame's rows.
* the constellation check, after a frame's solve: when most markers - or most of the
  moving ones - left their predictions together (:meth:`GlitchStage._broken`), a glitch
  is looked for (:meth:`GlitchStage._recover`): frames dropped, a frame repeated with new
  noise, or a camera bump measured by :func:`wingphoto.motion.estimate_shift` (the one
  detector of global image motion, which the sequence checks use too) and confirmed by
  the still markers. The one that puts most markers where
  predicted is kept; without one the frame's points are flagged ``constellation``.
* :meth:`GlitchStage._flag_copied`, after the constellation check: the moving markers on
  rows copied byte for byte from the frame before (a torn frame) are flagged.

``docs/tracker.md`` (*Glitches*) gives the cases behind each rule.
"""
from __future__ import annotations

import logging
import math

import numpy as np

from ..motion import estimate_shift, frame_content
from .hop import STALL_PX
from .predict import STILL_SPEED, model_speed, shift_history
from .relocate import MIN_INLIERS
from .status import _R, COAST_PX, LOST

logger = logging.getLogger("wingphoto.track")

#: A frame is checked for being blank or repeated on every _SAMPLE-th pixel of every
#: _SAMPLE-th row first (cheap), then in full.
_SAMPLE = 16
#: The constellation is broken when fewer than this share of the markers with a velocity
#: are found where predicted.
_CONSTELLATION = 0.5
#: A marker moving at least this fast (px/frame) votes in the moving markers' constellation
#: check too (:meth:`_broken`): a repeated or dropped frame leaves a slower one
#: within the motion model's limit of 2 px.
_MOVING_PX = 1.0
#: A frame whose markers lie, in the median, further than this (px) from their predictions
#: is checked for a glitch (:meth:`_broken`) however loose each marker's own limit (4
#: times its residual rms) has grown, and stays as predicted unless a glitch explains it
#: better (:meth:`_recover`): on clean real-dot sequences the median is at most 1.9 px
#: (DEV seeds 381-392, 1,187 frames), but after a glitch their rms grew to ~3 px, and a
#: whole grid of dots moved onto the dots behind by three dropped frames (a median 7.5 px
#: off their predictions) passed as where predicted (fresh DEV seed 386 cam2: ok 34 px off).
_MEDIAN_RESID_PX = 3.0
#: A glitch hypothesis that leaves the markers, in the median, further than this (px, plus
#: its ``_DROP_TOL``) from their predictions explains nothing: three dots leaving the view
#: passed as "1 frame dropped" at a median of 7.2 px (fresh DEV seed 430 cam1, repeated:
#: ok 33-66 px off). Winning hypotheses seen in the DEV logs left medians of 1.0-3.9 px.
#: (A first version, 3 px together with flagging every frame broken by its median, cost
#: 4.3 % of the real-dot DEV ok points; the two were not measured apart.)
_HYPOTHESIS_RESID_PX = 5.0
#: After a frame no glitch explained, an explanation of the next - a glitch hypothesis or
#: the motion model itself - must put at least this share of the markers it can check
#: where predicted (:meth:`GlitchStage._recover`), not only most of them.
_AFTER_UNEXPLAINED = 2.0 / 3.0
#: A frame on which most markers moving at least this fast (px/frame) are back where they
#: were is a repeat (:meth:`_stalled`).
_STALL_SPEED = 3.0
#: Dropped-frame hypotheses tried (1 to _MAX_DROPPED frames), and the extra distance (px
#: per frame dropped) a marker may lie from a prediction extrapolated over them.
_MAX_DROPPED, _DROP_TOL = 6, 0.3
#: Counts of frames dropped unseen before the previous frame tried (1 to _MAX_LATE): the
#: motion model's history but its newest point moved that many frames back.
_MAX_LATE = 2
#: A count of dropped frames that puts fewer than this share of the markers where predicted
#: wins only if every other count puts at least two markers fewer there
#: (:func:`_drop_count_in_doubt`).
_DROP_CLEAR = 0.75


def _median_residual(ctx, nh):
    """Median distance (px) of the markers found on a frame from their predictions (those
    with two points of history); inf when there are none."""
    with np.errstate(invalid="ignore"):
        r = ctx.resid[ctx.fits & (nh >= 2)]
    r = r[np.isfinite(r)]
    return float(np.median(r)) if r.size else np.inf


def _copied_rows(a, b):
    """Whether any row of ``a``, not constant, equals the same row of ``b`` byte for byte."""
    return a.size > 0 and bool(((a == b).all(1) & (a.max(1) > a.min(1))).any())


def _drop_count_in_doubt(dt, dropped_good, n):
    """Whether ``dt`` dropped frames, the winning hypothesis, is in doubt: it puts fewer
    than ``_DROP_CLEAR`` of the ``n`` checkable markers where predicted, and another count
    (``dropped_good``: markers where predicted per count) puts within one marker as many,
    or more than half as many.
    On a grid of dots two counts can each land most dots on a dot: real dots, dropped,
    fresh DEV seed 286 cam2, three frames dropped, "5 dropped" won by 4 of 7 markers to 3
    (median residuals 3.65 and 4.24 px) and a dot went ok one spacing ahead, 35 px off;
    with the motion model's history kept as measured across earlier glitches
    (:meth:`GlitchStage._keep_measured`), the same frame gave "5 dropped" 5 of 8 markers
    to 3 of 8, and two dots went ok one spacing ahead."""
    best = dropped_good[dt]
    others = [g for k, g in dropped_good.items() if k != dt]
    rival = max(others, default=0)
    return best < _DROP_CLEAR * n and bool(others) and (rival >= best - 1 or 2 * rival > best)


class GlitchStage:
    """The tracker's glitch checks (mixed into :class:`~.tracker.Tracker`, whose state
    they read and, for a glitch, set: the motion model's history, ``lostflag``,
    ``ref_pos``)."""

    def _frame_glitch(self, frame, t, res, direction):
        """Handle a blank (constant: black, saturated) or repeated (byte-identical) frame.

        A blank frame's points are lost (reason ``blank``) and the motion model coasts;
        a repeated frame gets the previous frame's rows (the same image: the same
        positions) and the motion model's history moves one frame on, as time did not
        advance. Returns True when the frame was handled.

        Reads the previous frame ``_prev``; writes ``pos`` (blank), ``hist_t`` and
        ``last_ok`` (repeated) and rows ``t`` of ``res``."""
        s = frame[:: _SAMPLE, :: _SAMPLE]
        floating = frame.dtype.kind == "f"
        if not (s.max() > s.min()) or (floating and not np.isfinite(s).all()):
            blank = frame_content(frame) == 0 or (floating and not np.isfinite(s).all())
            if blank:
                res.status[t] = LOST
                res.reason[t] = _R["blank"]
                self.pos = np.full((len(self.h), 2), np.nan)
                return True
        prev = self._prev
        if prev is None or prev.shape != frame.shape:
            return False
        if not (np.array_equal(s, prev[:: _SAMPLE, :: _SAMPLE]) and np.array_equal(frame, prev)):
            return False
        tp = t - direction
        if not 0 <= tp < res.x.shape[0]:
            return False
        for k in ("x", "y", "score", "xpix", "ypix", "status", "reason", "sigma"):
            getattr(res, k)[t] = getattr(res, k)[tp]
        self.hist_t += direction  # the past is one frame nearer
        self.last_ok[self.last_ok == tp] = t
        return True

    # ------------------------------------------------------------ constellation
    def _consistent(self, ctx, extra=0.0, among=None):
        """(number of checkable markers, number of them found where predicted).

        Checkable: matched markers with a velocity (two or more reliable points, at most
        one frame coasted), of ``among`` (boolean) if given; found where predicted:
        residual within the motion model's limit (``max(2 px, 4 rms + COAST_PX (gap - 1))``,
        plus ``extra`` px) and a score of at least ``min_score``.
        """
        chk = self._checkable(ctx)
        if among is not None:
            chk &= among
        good = chk & self._where_predicted(ctx, extra)
        return int(chk.sum()), int(good.sum())

    def _checkable(self, ctx):
        """Markers the constellation check can judge on ``ctx`` (boolean): matched, with a
        velocity (two or more reliable points), coasted at most one frame."""
        return ctx.fits & (self.nh >= 2) & (ctx.gap <= 2)

    def _where_predicted(self, ctx, extra=0.0):
        """Markers found where predicted on ``ctx`` (boolean): residual within the motion
        model's limit, ``max(2 px, 4 rms + COAST_PX (gap - 1))`` plus ``extra`` px, and a
        score of at least ``min_score``."""
        lim = np.maximum(2.0, 4.0 * self.resid_rms + COAST_PX * (ctx.gap - 1)) + extra
        with np.errstate(invalid="ignore"):
            return (ctx.resid <= lim) & (ctx.S >= self.p.min_score)

    def _saved_model(self):
        """The motion model and the picks' frame's positions, as :meth:`_set_model` restores them."""
        return self.hist_x.copy(), self.hist_t.copy(), self.lostflag.copy(), self.ref_pos.copy()

    def _broken(self, ctx):
        """True when most markers (and at least 3) left their predictions on this frame,
        or most of the moving ones (:meth:`_moving_now`, at least 3).

        Still markers (the mount, reference dots) are where predicted on a frame repeated
        with new noise or after dropped frames too: outvoting the wing, they let such a
        glitch pass as a frame on which the wing stopped (its markers vouched for by each
        other), and the stall, fed to the motion model, predicted each marker back by a
        frame's motion, onto a neighbour's blob (independent renderer, repeated, extra DEV
        seed 5 left: ok 13 px off after a renoised repeat)."""
        n, good = self._consistent(ctx)
        if n >= 3 and (good < _CONSTELLATION * n or _median_residual(ctx, self.nh) > _MEDIAN_RESID_PX):
            return True
        moving = self._moving_now()
        n, good = self._consistent(ctx, among=moving)
        return (n >= 3 and good < _CONSTELLATION * n) or self._stalled(ctx)

    def _few_to_check(self, ctx):
        """True when only one or two markers are checkable (:meth:`_consistent`: too few
        for the constellation check) and one of them is moving (:meth:`_moving_now`)."""
        chk = self._checkable(ctx)
        return 0 < int(chk.sum()) < 3 and bool((chk & self._moving_now()).any())

    def _few_in_doubt(self, frame, t, direction, ctx):
        """With too few markers for a constellation (:meth:`_few_to_check`), flag each
        checkable one that frames dropped would put on another blob where predicted.

        The frame is solved again for 1 to ``_MAX_DROPPED`` frames dropped (as in
        :meth:`_recover`); a marker found where predicted under one of them (its limit plus
        ``_DROP_TOL`` per frame, or as near as this frame's solve found it; ``min_score``)
        more than half its spacing from where this frame's solve put it has two readings
        that nothing tells apart: its point is flagged ``constellation``
        (``ctx.unexplained``) and, not fed, it coasts. A dot alone on a grid moving a third
        of its spacing a frame is in doubt on every frame: three
        frames dropped unseen put the dot behind where the next step was predicted (real
        dots, dropped: DEV seed 11 cam1, 8 points; fresh seed 145 cam2 and stress seed 573
        cam1, one point each, 33-35 px off; in 573 the dot behind lay 6.0 px from the
        prediction, ok as a lone marker's short jump, and its own dot 3.6 px from that of
        "3 dropped"). Returns the frame's context, solved again as it was."""
        saved = self._saved_model()
        chk = self._checkable(ctx).nonzero()[0]
        X0, Y0, r0 = ctx.X.copy(), ctx.Y.copy(), ctx.resid.copy()
        doubt = np.zeros(len(ctx.X), bool)
        for dt in range(1, _MAX_DROPPED + 1):
            self._set_model(saved, dt, 0.0, 0.0, direction)
            c = self._solve(frame, t, aged=dt)
            with np.errstate(invalid="ignore"):
                there = (self._where_predicted(c, _DROP_TOL * dt) | ((c.resid <= r0) & (c.S >= self.p.min_score)))[chk]
                other = np.hypot(c.X[chk] - X0[chk], c.Y[chk] - Y0[chk]) > 0.5 * self._spacing[chk]
            doubt[chk[there & other]] = True
        self._set_model(saved, 0, 0.0, 0.0, direction)
        ctx = self._solve(frame, t)
        if doubt.any():
            ctx.unexplained |= doubt
            logger.info("frame %d: markers %s, too few for a constellation, fit another blob after dropped frames: "
                        "flagged", t, doubt.nonzero()[0].tolist())
        return ctx

    def _flag_copied(self, frame, ctx, t):
        """Flag (``ctx.unexplained``) the moving markers (:meth:`_moving_now`) any row of
        whose disk, not constant, is byte-identical to the frame before: pixels copied
        from that frame (a marker that moved changes every row it covers).

        A frame that repeats the one before byte for byte is handled by
        :meth:`_frame_glitch`; one that repeats it only in part - a torn frame, whose rows
        from some point on are the previous frame's - shows the markers there an instant
        late, and those across the tear as two half blobs. Taken for a frame "repeated with
        new noise" (:meth:`_recover`), or as found (a tear below most markers), they were
        ok 1-7 px from where they were (the independent renderer's ``hard``, the lower half
        of one frame copied from the frame before: 2-17 ok points per sequence). A frame
        repeated with new noise is not on the same bytes. A copied band narrower than
        ``_SAMPLE`` rows is not looked for (the check runs on every frame the fast frame
        hands over, so it first compares every ``_SAMPLE``-th row)."""
        prev = self._prev
        if prev is None or prev.shape != frame.shape:
            return
        # (cheap first: a copied band of _SAMPLE rows or more holds one of every
        # _SAMPLE-th row, identical and not constant)
        if not _copied_rows(frame[::_SAMPLE], prev[::_SAMPLE]):
            return
        copied = []
        cand = self._moving_now() & ctx.fits & np.isfinite(ctx.XP) & np.isfinite(ctx.YP)
        for i in cand.nonzero()[0].tolist():
            r = int(math.ceil(self.rd[i]))
            x, y = int(round(ctx.XP[i])), int(round(ctx.YP[i]))
            y0, y1, x0, x1 = max(y - r, 0), min(y + r + 1, self.H), max(x - r, 0), min(x + r + 1, self.W)
            if _copied_rows(frame[y0:y1, x0:x1], prev[y0:y1, x0:x1]):
                copied.append(i)
        if copied:
            ctx.unexplained[copied] = True
            logger.info("frame %d: markers %s on rows copied from the frame before (a torn frame): flagged", t, copied)

    def _stalled(self, ctx):
        """True when most of the fast markers (moving >= ``_STALL_SPEED`` px a frame, at
        least 3, fed on the frame before) are back where they were on the frame before
        (within ``STALL_PX``): a frame repeated with new noise. A wing moving that fast does
        not stop dead at once; at a motion model's limit of a few px, the stall passed as
        the whole wing stopping, was fed to the model and predicted a marker back onto its
        neighbour's blob (independent renderer, repeated, extra DEV seed 5 left: ok 13 px
        off). Slower markers do stop within a frame (real dots at 1-1.6 px a frame, at a
        warp's reversal: taken for a repeat, 5 ok points up to 36 px off)."""
        m = (self._moving_now(_STALL_SPEED) & ctx.fits & (ctx.gap == 1)).nonzero()[0]
        if m.size < 3:
            return False
        with np.errstate(invalid="ignore"):
            still = np.hypot(ctx.X[m] - self.hist_x[m, 0, 0], ctx.Y[m] - self.hist_x[m, 0, 1]) < STALL_PX
        return bool(still.sum() > _CONSTELLATION * m.size)

    def _moving_now(self, speed=_MOVING_PX):
        """Markers whose motion model (three reliable points: not one just re-acquired with
        its neighbours' velocity) moves them at least ``speed`` px a frame (boolean)."""
        with np.errstate(invalid="ignore"):
            return (self.nh >= 3) & (model_speed(self.hist_x, self.hist_t) >= speed)

    def _recover(self, frame, t, direction, ctx):
        """Explain a broken constellation by a glitch, or flag the frame.

        Hypotheses, each tried by solving the frame again: 1 to ``_MAX_DROPPED`` frames
        dropped (each marker's history moved that many frames along its own quadratic,
        :func:`~.predict.shift_history`), a frame repeated with new noise (one back), and
        a camera bump - the global shift between the previous and this frame
        (:func:`wingphoto.motion.estimate_shift`) added to the history, confirmed by the
        still markers (:meth:`_bump_holds`) and solved once more with its miss measured on
        them (:meth:`_shift_miss`); and 1 to ``_MAX_LATE`` frames dropped unseen before the
        previous frame (every point of the history but the newest moved that many frames
        back: a motion model fed across a frame it did not see, or told one frame too few
        were dropped, overshoots on the next; real dots, DEV seeds 494 cam2 and 610 cam2).
        A dropped-frames hypothesis extrapolates further, so its markers may be
        ``_DROP_TOL`` px per frame dropped further from their predictions. The hypothesis that puts the most
        markers where predicted (ties: the smaller median residual) wins if it puts most
        of them there, and is kept for the next frames (after frames dropped, behind the
        measured history, :meth:`_keep_measured`; after a repeat, a frame later,
        :meth:`_relabel_repeat`); without one, every point of the frame is flagged
        ``constellation`` and the motion model coasts over it.
        """
        saved = self._saved_model()
        moving = self._moving_now()  # (before a hypothesis moves the histories along)
        fast = self._moving_now(_STALL_SPEED)
        hyps = ([(dt, 0.0, 0.0, 0) for dt in range(1, _MAX_DROPPED + 1)] + [(-1, 0.0, 0.0, 0)]
                + [(0, 0.0, 0.0, k) for k in range(1, _MAX_LATE + 1)])
        repeat_fits = False  # (a repeat explains the frame: see below)
        prev, prev2 = self._prev, self._prev2
        if prev is not None and prev.shape == frame.shape:
            # the image's global shift holds the camera's jump and the wing's own motion:
            # the jump is the change of the global shift from the frame before
            sh = estimate_shift(prev, frame)
            if sh.response > 0.05:
                if prev2 is not None and prev2.shape == frame.shape:
                    s0 = estimate_shift(prev2, prev)
                    if s0.response > 0.05 and math.hypot(sh.dx - s0.dx, sh.dy - s0.dy) > 1.0:
                        hyps.append((0, sh.dx - s0.dx, sh.dy - s0.dy, 0))
                if math.hypot(sh.dx, sh.dy) > 1.0:
                    hyps.append((0, sh.dx, sh.dy, 0))
        n0, good0 = self._consistent(ctx)
        med0 = _median_residual(ctx, self.nh)
        # (a frame broken only by its median residual stays as predicted unless a glitch
        # puts more markers where predicted: after a glitch the motion model misses by a
        # few px for some frames, and no glitch explains that. A smaller median alone did
        # not do: on real dots, whose residual rms had grown so that every hypothesis put
        # 8 of 8 dots "where predicted", a camera shift of 1.8 px won by its median, 4.9
        # px against 5.8, and 4 dots went ok one spacing off - fresh DEV seed 434 cam1,
        # dropped)
        # (after an unexplained frame the motion model coasted over it, and any explanation,
        # the motion model's or a glitch's, must put _AFTER_UNEXPLAINED of the markers it
        # can check where predicted (a hypothesis: besides most of all the checkable ones),
        # not only most, and the motion model too must leave a median residual
        # of at most _HYPOTHESIS_RESID_PX, as a hypothesis must - real dots, fresh DEV
        # seeds 901-940: three dropped frames moved a grid about one spacing and, that
        # frame flagged, the next passed as predicted with 6 of 10 dots within their
        # limits (median 5.1 px), on the dots behind (cam1 931: 335 points ok 33 px off);
        # a bump nothing explained passed on the next frame as "3 frames dropped", 10 of
        # 17 at 3.8 px (cam1 940); 2 of 3 dots at a median of 9.3 px passed as predicted
        # (cam1 919, repeated: ok 33-243 px off))
        after_unexplained = self._prev_unexplained
        share = _AFTER_UNEXPLAINED if after_unexplained else _CONSTELLATION
        as_predicted = (n0 >= 3 and good0 >= share * n0
                        and not (after_unexplained and med0 > _HYPOTHESIS_RESID_PX))
        best, best_key = None, (good0, np.inf if as_predicted else -np.inf)
        logger.debug("frame %d: as predicted: %d of %d markers where predicted (median residual %.2f px)",
                     t, good0, n0, med0)
        refined = set()
        dropped_good = {}  # markers where predicted, per count of dropped frames
        for dt, dx, dy, late in hyps:
            if late and self._prev_unexplained:
                # (as for a repeat, _repeat_holds: no hypothesis placed the markers of the
                # frame before, and nothing says when they were; a camera bump nothing
                # explained on frame 27 passed as "1 frame dropped before the last one" on
                # frame 28 and 2 dots went ok one spacing off - real dots, bumped, DEV
                # seed 474 cam1)
                continue
            if late and repeat_fits:
                # (frames dropped before the last one slow the markers down, never to a
                # stop: on a repeat with new noise, "2 dropped before the last one" won by
                # one marker more, 31 of 32, at a median of 1.34 px against the repeat's
                # 0.04 - real dots, repeated, DEV seed 9 cam2)
                continue
            self._set_model(saved, dt, dx, dy, direction, late)
            c = self._solve(frame, t, aged=dt)
            n, good = self._consistent(c, _DROP_TOL * abs(dt))
            if dt > 0:
                dropped_good[dt] = good
            if dt < 0 and not self._repeat_holds(c, saved[0], fast):
                logger.debug("frame %d: the fast markers came back: not a repeated frame", t)
                continue
            if dt == 0 and not late and not self._bump_holds(c, saved[0], dx, dy):
                logger.debug("frame %d: the still markers did not move by (%.2f, %.2f) px: no camera shift", t, dx, dy)
                continue
            if dt == 0 and not late and (dx, dy) not in refined:
                corr = self._shift_miss(c)
                if corr is not None and all(math.hypot(dx + corr[0] - a, dy + corr[1] - b) > 0.25 for a, b in refined):
                    # (the image's global shift is pulled by the wing's own motion: the
                    # still markers found near their shifted predictions measure its miss)
                    refined.add((float(dx + corr[0]), float(dy + corr[1])))
                    hyps.append((0, float(dx + corr[0]), float(dy + corr[1]), 0))
            med = _median_residual(c, self.nh)
            logger.debug("frame %d: hypothesis %s: %d of %d markers where predicted (median residual %.2f px)",
                         t, (dt, dx, dy, late), good, n, med)
            if dt < 0 and not med <= STALL_PX:
                # a repeat shows every marker where it was, to the centring's noise (a
                # median of 0.04 px on a repeated real-dot frame); markers slow at a stroke
                # reversal stand 1-2 px on, and taken for a repeat, not fed, they left the
                # motion model a stroke behind for the frames after (real dots, dropped, DEV
                # seeds 15 and 494 cam2: the grid lost). A motion model fed across a frame
                # it did not see is the hypothesis of frames dropped before the last one.
                logger.debug("frame %d: the markers moved on: not a repeated frame", t)
                continue
            repeat_fits |= dt < 0 and n >= 3 and good >= _CONSTELLATION * max(n, n0)
            # (most of the markers checkable as predicted, not only of those still found:
            # a hypothesis of many dropped frames sends most predictions off the image or
            # off any blob, and "6 frames dropped" won on 4 of the 7 markers it left
            # checkable of 22, putting a dot ok on the next dot of the grid - real dots,
            # DEV seed 53 cam1, source frames 10-13 dropped: 34 px off)
            # (and at least three markers, a constellation: with three checkable, "3 frames
            # dropped" won on two after a bump no hypothesis tried, and one dot went ok on
            # the dot behind - real dots, fresh DEV seed 964 cam1, bumped: 10 points 33 px off)
            if (good >= 3 and good >= _CONSTELLATION * max(n, n0) and good >= share * n
                    and med <= _HYPOTHESIS_RESID_PX + _DROP_TOL * abs(dt)
                    and (good, -med) > best_key):
                best, best_key, best_n = (dt, dx, dy, late), (good, -med), max(n, n0)
        count_in_doubt = best is not None and best[0] > 0 and _drop_count_in_doubt(best[0], dropped_good, best_n)
        if count_in_doubt:
            logger.info("frame %d: %d or %d frames dropped explain about as many markers: not explained", t,
                        best[0], max((k for k in dropped_good if k != best[0]), key=dropped_good.get))
            best = None
        if best is None and as_predicted and not count_in_doubt:
            self._set_model(saved, 0, 0.0, 0.0, direction)
            logger.debug("frame %d: no glitch explains it better than the motion model", t)
            return self._solve(frame, t)
        if best is None:
            self._set_model(saved, 0, 0.0, 0.0, direction)
            ctx = self._solve(frame, t)
            ctx.glitch = True
            logger.info("frame %d: most markers left their predictions and no glitch explains it: flagged", t)
            # (frames were dropped, how many is not known: coasting over this frame is the
            # one continuation known to be wrong - 286 cam2 resumed on the dots behind)
            self._lose_unchecked(ctx, t, at_once=count_in_doubt)
            return ctx
        self._set_model(saved, *best[:3], direction, best[3])
        logger.info("frame %d: constellation restored by %s", t,
                    f"{best[0]} frame(s) dropped" if best[0] > 0 else "a repeated frame" if best[0] < 0
                    else f"{best[3]} frame(s) dropped before the last one" if best[3]
                    else f"a camera shift of ({best[1]:.1f}, {best[2]:.1f}) px")
        ctx = self._solve(frame, t, aged=best[0])
        ctx.shift = np.array(best[1:3], float)
        if best[0] < 0:
            self._relabel_repeat(saved, direction)
        if best[0] > 0:
            ctx.measured = (saved[0], saved[1] - best[0] * direction)
            self._lose_unmoved(t)
        n_mov, good_mov = self._consistent(ctx, _DROP_TOL * abs(best[0]), among=moving)
        if n_mov >= 3 and good_mov < _CONSTELLATION * n_mov:
            # the still markers are where predicted under every hypothesis of dropped or
            # repeated frames: outnumbering a few wing markers, they choose one that does
            # not explain the wing, whose markers are then not trusted on this frame (fresh
            # DEV seed 226 dropped right, frame 34: 8 still and 3 wing markers, every
            # hypothesis put 9 of the 11 where predicted and 1 of the 3 moving ones; "a
            # repeated frame" won by the still markers' residual, and marker 13, after 3
            # dropped frames, stayed ok on marker 12's blob, 17 px off)
            ctx.unexplained[:] = moving
            logger.info("frame %d: only %d of the %d moving markers where predicted: their points flagged", t,
                        good_mov, n_mov)
            # (for them the frame is unexplained: those not fed on the frame before either
            # are lost, as after two unexplained frames)
            self._lose_unchecked(ctx, t, among=moving)
        if best[0] == 0 and not best[3]:
            # the image's global shift is pulled by the wing's own motion: the markers found
            # where predicted (the still ones exactly) measure what it missed, and the
            # motion model and the reference layout take the shift as measured (else the
            # next frame extrapolates the miss as a velocity)
            good = self._checkable(ctx) & self._where_predicted(ctx)
            if good.sum() >= 3:
                cx = float(np.median(ctx.X[good] - ctx.pred[good, 0]))
                cy = float(np.median(ctx.Y[good] - ctx.pred[good, 1]))
                lost = self.lostflag.copy()  # (as this frame's plan left it)
                self._set_model(saved, 0, best[1] + cx, best[2] + cy, direction)
                self.lostflag[...] = lost
                ctx.shift = np.array([best[1] + cx, best[2] + cy])
                logger.debug("frame %d: camera shift measured on %d markers: (%.2f, %.2f) px", t, int(good.sum()),
                             best[1] + cx, best[2] + cy)
        return ctx

    def _lose_unmoved(self, t):
        """After a dropped-frames hypothesis, declare lost the markers re-acquired or
        restarted with fewer than three points in their motion model since: the hypothesis
        moves each history along its own motion, and theirs is one point, or one step
        borrowed from the neighbours at the re-acquisition, so their prediction lags where
        the frames dropped left them (not a marker in its first frames after its pick: two
        points of its own). Found again by their neighbours, not on that prediction. Real
        dots, dropped, fresh DEV seed 279 cam1:
        a dot re-acquired on frame 19 with a borrowed step of 6 px (its own, 12), three
        frames dropped on frame 20, found on frame 21 on the dot behind - four frames'
        motion less one spacing made its path look smooth - and a neighbour's
        re-acquisition from it ok 34 px off."""
        unmoved = self.restarted & (self.nh < 3) & ~self.lostflag
        if unmoved.any():
            self.lostflag |= unmoved
            logger.info("frame %d: %d markers with fewer than three points across the dropped frames: lost until "
                        "found again", t, int(unmoved.sum()))

    def _lose_unchecked(self, ctx, t, among=None, at_once=False):
        """On an unexplained frame, declare lost the markers not known to be still (the
        wing's, and those restarted with fewer than three points) that were not fed on the
        frame before either (a second unexplained frame in a row, a blank frame, or a
        flagged point).

        The constellation check needs markers coasted at most one frame (:meth:`_consistent`,
        ``gap <= 2``): a marker that coasted over this unexplained frame and the one before
        would resume on the next frame with no check of its identity, vouched for by its
        neighbours, which resume with it. Lost, it is found again by its constellation
        (:func:`~.relocate.relocate_group`, which refuses an ambiguous fit) or by its
        neighbours. Real dots on a regular grid, three frames dropped (DEV seed 31 cam1,
        frames 9-10): the dots moved about one grid spacing, no hypothesis explained it,
        and on frame 11 every dot resumed ok on the dot one spacing behind it, 33 px off,
        for the rest of the sequence (933 confident errors). A dot re-acquired just before
        (fewer than three points: not known to be moving) did the same 72 px off (seed 0
        cam1, marker 61). The still markers (the mount, the reference dots) are where
        predicted under any glitch and stay. With ``among`` (boolean), only those: the
        moving markers a chosen hypothesis did not explain (:meth:`_recover`; real dots,
        bumped, DEV seed 0 cam2: a bump nothing explained on frame 41 was taken on frame 42
        for three dropped frames, which put the slow dots where predicted and not the
        moving ones; flagged on that frame only, the moving dots then followed the grid
        one spacing off, and re-acquisitions from them were ok 35 px off). With
        ``at_once``, on this first unexplained frame already (two counts of dropped frames
        in doubt, :func:`_drop_count_in_doubt`).

        Its cost: a bump that no hypothesis explains (real dots have no still markers to
        confirm one, and their phase correlation is weak) loses the dots too, where before
        they resumed on their own dots - a bump of a few px is far from a grid spacing,
        but nothing on the frame tells it from the dropped frames above (the dots were
        found 4-6 px from their predictions in both). 41 real-dot DEV seeds, bumped, this
        check alone: ok share 40.6 -> 36.7 % (cam1), 27.5 -> 23.6 % (cam2), no confident
        error either way but the highlight points."""
        with np.errstate(invalid="ignore"):
            still = (self.nh >= 3) & (model_speed(self.hist_x, self.hist_t) < STILL_SPEED)
        stale = ~still & (self.nh >= 1) & ((ctx.gap >= 2) | at_once) & ~self.lostflag
        if among is not None:
            stale &= among
        if stale.any():
            self.lostflag |= stale
            logger.info("frame %d: %d markers not known to be still, unexplained on this frame%s: lost until "
                        "found again", t, int(stale.sum()), "" if at_once else " and the one before")

    def _relocated_astray(self, ctx, res):
        """Markers re-acquired together on their last ok frame whose group, on this frame,
        is mostly not where predicted (boolean; groups found of at least
        :data:`~.relocate.MIN_INLIERS`, the fewest a constellation re-acquires: markers
        re-acquired one by one from their neighbours, three on one frame, were 2-4 px off
        their predictions on the next and right; flagged, they coasted and one was later
        followed 16 px off, real dots DEV seed 0 cam2).

        A re-acquired marker's motion model starts from one point and a velocity measured
        against the previous image (:func:`~.relocate.relocate_group`); across frames
        dropped while the group was lost, unseen, that velocity spans them all. Then the
        whole group is predicted too far, most of its markers land off their predictions,
        and one that lands on a neighbour's blob near its own prediction looks right.
        Independent renderer, fresh DEV seed 288 dropped right: 11 wing markers re-acquired
        on frame 38 after three dropped frames, with 4x their velocity; on frame 39, ten
        were 13-20 px from their predictions and flagged, and marker 20 was ok on its
        neighbour's blob, 12.5 px off."""
        out = np.zeros(len(ctx.X), bool)
        cand = (ctx.fits & (self.nh < 3)).nonzero()[0]
        if cand.size < MIN_INLIERS:
            return out
        cand = cand[self._just_reacquired(cand, res)]
        lim = np.maximum(2.0, 2.0 * self.resid_rms)
        for t0 in np.unique(self.last_ok[cand]).tolist():
            grp = cand[self.last_ok[cand] == t0]
            with np.errstate(invalid="ignore"):
                near = ctx.resid[grp] <= lim[grp]
            if grp.size >= MIN_INLIERS and near.sum() < _CONSTELLATION * grp.size:
                out[grp] = True
                logger.info("markers %s re-acquired on frame %d: %d of %d where predicted: flagged", grp.tolist(),
                            t0, int(near.sum()), grp.size)
        return out

    def _still_found(self, c):
        """Markers still by their motion model (speed below ``STILL_SPEED``, three points
        of history; a camera-shift hypothesis moves every point of a history alike, so the
        speed is the one before it) and found on ``c`` with ``min_score`` (indices): the
        mount and the reference dots, which move on the image only when the camera does."""
        with np.errstate(invalid="ignore"):
            m = (self.nh >= 3) & (model_speed(self.hist_x, self.hist_t) < STILL_SPEED) & c.fits & (c.gap == 1) & (c.S >= self.p.min_score)
        return m.nonzero()[0]

    def _repeat_holds(self, c, hx, fast):
        """Whether a repeated-frame hypothesis's solution ``c`` may be one: on a repeat,
        with new noise or not, every marker is where it was on the frame before, so most
        of the ``fast`` markers (boolean, at least 3, found on ``c`` and fed on the frame
        before; with fewer nothing says no) must not lie more than ``STALL_PX`` behind
        their positions then (``hx``), along their last step. Ahead is allowed: a motion
        model fed across a dropped frame it did not see overshoots (a disc 3.2 px on where
        1.5 were predicted, 1.8 px further on the next frame), which the hypothesis of
        frames dropped before the last one explains, and :meth:`_recover` asks a repeat
        for a median residual of at most ``STALL_PX`` besides. Behind is a reversal, which
        no repeat explains: real dots on a grid whose stroke reversed just after three
        unseen dropped frames came back 2.8 px against a prediction 7 px on; "a repeated
        frame" put them within the motion model's limit (median 1.9 px), was kept for two
        frames, and on the next the model, a stroke behind, put 17 dots one grid spacing
        off (DEV seed 13 cam1, source frames 5-7 dropped: ok 35-72 px off)."""
        if self._prev_unexplained:
            # the frame before was unexplained: no hypothesis placed its markers, and
            # nothing says what a repeat of it would show
            return False
        m = (fast & c.fits & (c.gap == 1) & (self.nh >= 2)).nonzero()[0]
        if m.size < 3:
            return True
        step = np.stack([c.X[m] - hx[m, 0, 0], c.Y[m] - hx[m, 0, 1]], axis=1)
        last = hx[m, 0] - hx[m, 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            along = np.sum(step * last, axis=1) / np.hypot(last[:, 0], last[:, 1])
        return not bool((along < -STALL_PX).sum() > _CONSTELLATION * m.size)

    def _bump_holds(self, c, hx, dx, dy):
        """Whether a camera-shift hypothesis's solution ``c`` is one: a bump moves the still
        markers (:meth:`_still_found`, at least 2; with fewer nothing says no) by the
        shift, so they must lie nearer, in the median, to their positions on the frame
        before (``hx``) plus (dx, dy) than to those positions. The search windows and the
        residual limits (2 px and more) are wider than a small shift: a dropped frame had
        been taken for a shift of (-1.4, -0.9) px, which moved the reference layout under
        the still dots and let their affine map re-acquire a wing marker on its
        neighbour's blob (independent renderer, dropped extra DEV seed 15 right: ok 44 px
        off, frames 90-99, with a first version of :meth:`_shift_miss` that measured the
        miss on all markers)."""
        m = self._still_found(c)
        if m.size < 2:
            return True
        ex, ey = c.X[m] - hx[m, 0, 0], c.Y[m] - hx[m, 0, 1]
        return bool(np.median(np.hypot(ex - dx, ey - dy)) < np.median(np.hypot(ex, ey)))

    def _shift_miss(self, c):
        """What a camera-shift hypothesis missed (px, (2,)): the per-axis median of the
        still markers' (:meth:`_still_found`) offsets from their shifted predictions, or
        None when fewer than 2 were found or the miss is below half a pixel. Only the still
        markers measure the camera: on a scene of moving markers alone, the markers' own
        offsets fold the motion model's error into the shift, and frame after frame was
        "explained" by a new shift (a dropped frame on translating discs: markers slid to
        their neighbours, 28 px off)."""
        m = self._still_found(c)
        if m.size < 2:
            return None
        corr = np.array([np.median(c.X[m] - c.pred[m, 0]), np.median(c.Y[m] - c.pred[m, 1])])
        return corr if math.hypot(*corr) > 0.5 else None

    def _keep_measured(self, measured, fed):
        """Behind the new point of each marker ``fed`` (boolean) on a frame after dropped
        frames, put its measured history back at the frames it was measured on
        (``measured``: :attr:`~.tracker.FrameContext.measured`) instead of that history
        moved along its own quadratic (:func:`~.predict.shift_history`, which the frame
        was solved with): the next prediction interpolates across the frames dropped
        instead of through two points extrapolated over them, and a count of frames
        dropped found one short later (:meth:`_recover`'s frames dropped before the last
        one) moves measured points, not extrapolated ones. Real dots on a grid, three
        frames dropped just before a stroke reversal (DEV seed 610 cam2, frame 39, taken
        for two): on the next frame the extrapolated points, past the reversal, put 3 of
        15 dots where predicted (median 4.25 px), the measured ones 15 of 17 (2.85 px)."""
        hx, ht = measured
        self.hist_x[fed, 1:] = hx[fed, :2]
        self.hist_t[fed, 1:] = ht[fed, :2]

    def _relabel_repeat(self, saved, direction):
        """After a repeated frame was solved (its history moved a frame back), give the
        motion model its measured positions back, each a frame later: the same prediction
        for the next frame (a quadratic moved a frame back along itself is the quadratic a
        frame later), but the frame that repeated the last one is no frame without a
        position, as for a byte-identical repeat (:meth:`_frame_glitch`). Left a frame
        back, each repeat added a frame to every marker's gap: its limits widened by
        ``COAST_PX`` and, after two, no marker was checkable by the constellation check
        (``gap <= 2``). Real dots, dropped, DEV seed 610 cam2: two frames taken for
        repeats at a stroke reversal left the model 14 px off on the third, unchecked; the
        wing's dots, flagged ``jump`` there, resumed ok one spacing off with a limit of
        6.9 px (72 points 34-72 px off)."""
        self.hist_x[...] = saved[0]
        self.hist_t[...] = saved[1] + direction

    def _set_model(self, saved, dt, dx, dy, direction, late=0):
        """Restore the motion model and the picks' frame's positions from ``saved``, then
        move the history ``dt`` frames along each marker's motion
        (:func:`~.predict.shift_history`) and shift its positions, and ``ref_pos``, by
        (dx, dy) px: after a camera bump the reference layout is seen in the new pose too
        (the re-acquisition tells still markers from moving ones by their distance to it)."""
        hx, ht, lf, ref = saved
        self.hist_x[...] = shift_history(hx, ht, self.nh, dt * direction) if dt else hx
        self.hist_t[...] = ht
        if late:
            self.hist_t[:, 1:] -= late * direction
        self.lostflag[...] = lf
        # (a new array: a verify pass's tracker is a shallow copy sharing this one)
        self.ref_pos = ref + np.array([dx, dy])
        if dx or dy:
            self.hist_x[..., 0] += dx
            self.hist_x[..., 1] += dy
