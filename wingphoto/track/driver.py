"""track_markers: passes over a sequence (one per pick frame, each way), checkpoints, backward merge."""
from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import numpy as np

from .audit import audit_against_picks
from .checkpoint import (
    _WAY_OUT,
    _Checkpointer,
    _fingerprint,
    _load_checkpoint,
    _run_pass,
)
from .inputs import _Frames, _parse_picks
from .options import TrackOptions
from .results import _merge_backward, _Results, _tracks_frame
from .sigma import flag_persistent_imprecision
from .status import _R, FLAGGED, LOST, OK
from .tracker import Tracker as _Tracker

logger = logging.getLogger("wingphoto.track")

#: Two markers of different pick-frame groups closer than this (px) on one frame are on one
#: blob: their ok positions are flagged ``conflict`` (as :func:`retrack_from`'s ``conflict_px``).
GROUP_CONFLICT_PX = 3.0


def _resolve_options(options, **given):
    """One :class:`TrackOptions` from ``options`` and keyword options (None: not given)."""
    if options is None:
        options = TrackOptions()
    elif isinstance(options, dict):
        options = TrackOptions(**options)
    elif not isinstance(options, TrackOptions):
        raise ValueError(f"options must be a wingphoto.track.TrackOptions (or a dict of its fields), "
                         f"got {type(options).__name__}")
    names = TrackOptions.names()
    unknown = sorted(k for k in given if k not in names)
    if unknown:
        raise TypeError(f"unknown option(s) {unknown}; the options are {list(names)}")
    changes = {k: v for k, v in given.items() if v is not None or k in ("max_mass_ratio", "max_score_drop")}
    return dataclasses.replace(options, **changes) if changes else options


def track_markers(frames, picks, *, camera="left", search_radius=None, max_sigma=None, polarity=None,
                  bidirectional=False, checkpoint=None, checkpoint_every=500, progress=True, options=None,
                  **expert):
    """Track markers from their picks through a sequence, flagging doubtful points.

    Parameters
    ----------
    frames : (T, H, W) ndarray or sequence
        Grayscale frames (uint8, uint16 or float), anything
        :func:`wingphoto.io.read_sequence` returns (``len`` and ``[i]``); read one at a
        time, so memory does not grow with the sequence length.
    picks : (N, 2) array_like, or DataFrame / list of dicts
        Each marker's position: (x, y) clicks in frame 0 in px (origin at the centre of the
        top-left pixel; rounding to the pixel is fine), the template size then chosen from
        the blob; or the picker's saved picks with columns ``point, x, y`` and optionally
        ``frame`` (the frame the marker was picked in, default 0: a marker picked in frame
        k is tracked forward and backward from k), ``half_w``/``half_h``, ``half_size``
        (template half width, px) or ``rect`` (``(x0, y0, width, height)``). A NaN pick (a
        marker not visible) gives that point ``lost`` rows with reason ``no_pick`` (and a
        logged warning).
    camera : str
        Value of the ``camera`` column.
    search_radius : int, optional
        Largest search radius in px (default 20): used on frame 1, where no velocity is
        known yet, and as the cap of the prediction-driven radius. Must exceed the largest
        motion between frames 0 and 1.
    max_sigma : float, optional
        Largest ``sigma`` (px) of an ``ok`` point (default 0.25).
    polarity : {"auto", 1, -1}, optional
        Bright (1) or dark (-1) markers; "auto" (default) decides per marker.
    options : TrackOptions, optional
        All options (:class:`~wingphoto.track.TrackOptions`: the user options above, and
        the expert thresholds with their documentation); the keywords above override it.
    **expert
        Any other field of :class:`~wingphoto.track.TrackOptions` by name (``min_score``,
        ``max_coast``, ``search_every`` ...).
    bidirectional : bool
        Check each pass by tracking back over it: from the last frame back to the frame the
        markers were picked in, and (picks in a later frame ``k``) from frame 0 forward to
        ``k``; flag ``fb_disagree`` where the passes disagree by more than ``fb_tolerance``
        px and use the checking pass's position where only it is ok (and it agreed further
        along). Doubles the run time.
    checkpoint : str or Path, optional
        File (``.npz``) holding the state; saved atomically every ``checkpoint_every``
        frames and when the run stops on an exception (a Ctrl-C takes effect at the end of
        the frame under way). If it exists and was written for the same frames, picks
        (with their frames) and options, tracking resumes from it with identical results.
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
        (:data:`REASONS`; ``docs/tracker.md``): ``low_score``, ``ambiguous``, ``merged``, ``conflict``,
        ``jump``, ``no_signal``, ``appearance``, ``edge``, ``out_of_frame``,
        ``lost_track`` (coasted longer than ``max_coast``), ``reacquired`` (first frame
        after a re-acquisition), ``fb_disagree``, ``no_pick``, ``pick_moved`` (frame 0:
        the refinement moved the click by more than 1.5 px, or saw a foreign blob or a
        rough background; the click is kept), ``foreign`` (something bright not
        explained by a known marker touches the disk), ``imprecise`` (``sigma`` above
        ``max_sigma`` on the frame, or on average on the frames around it), ``blank`` (a blank frame: black, saturated, constant),
        ``constellation`` (most markers left their predictions at once and no glitch - a
        dropped or repeated frame, a camera bump - explains it), ``misplaced`` (after
        tracking: away from where its neighbours' affine map from the picks puts it,
        :mod:`~wingphoto.track.audit`); :func:`check_stereo` adds
        ``stereo``. ``sigma`` (px) is the per-axis 1-sigma uncertainty of x, y, estimated
        from the image (``docs/tracker.md``), NaN where there is no position.

    Raises
    ------
    ValueError
        Empty sequence, frames of different sizes or bit depths, NaN picks, a pick outside
        the image, not on a marker (neither its brightest pixel nor its best 3x3 mean
        stands 4 noise sigmas out of the background plane), or too close to the edge for
        its template, a template larger than the image, a checkpoint written for other
        inputs.

    Notes
    -----
    The design and the failure each choice prevents are described in ``docs/tracker.md``. Conventions: ``docs/conventions.md``.

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
    xy, ids, half, pick_frames = _parse_picks(picks)
    active = np.all(np.isfinite(xy), axis=1)
    if not active.all():
        logger.warning("picks of points %s are NaN: those points are reported lost (reason 'no_pick')",
                       ids[~active].tolist())
    late = active & (pick_frames >= fr.n)
    if late.any():
        k = int(np.flatnonzero(late)[0])
        raise ValueError(f"point {ids[k]} was picked in frame {pick_frames[k]} but the sequence has {fr.n} frames "
                         "(0 to {}); pick it in a frame of this sequence".format(fr.n - 1))
    p = _resolve_options(options, search_radius=search_radius, max_sigma=max_sigma, polarity=polarity, **expert)
    run = _Run(fr, xy, ids, half, pick_frames, active, p, bidirectional)
    ck = None
    if checkpoint is not None:
        fp = _fingerprint(fr, xy, ids, half, p, camera, bidirectional, pick_frames)
        ck = _Checkpointer(checkpoint, fp, checkpoint_every, run.state, fr)
        if Path(checkpoint).exists():
            meta, arrays = _load_checkpoint(checkpoint, fp, fr, required=run.required())
            run.resume(meta, arrays, checkpoint)
    run.run(ck, progress, camera)
    return _tracks_frame(run.merged(), ids, camera)


def _seed_row(res, k, tracker):
    """Row ``k`` of ``res``: the refined picks (score 1; a click the refinement moved by more
    than 1.5 px, or that saw a foreign blob or a rough background, is kept and flagged
    ``pick_moved``: it was pulled by something - an unpicked neighbour, glare). A refined
    pick whose sigma exceeds ``max_sigma`` keeps its position and is flagged ``imprecise``,
    as on any other frame: its identity is not in doubt, the click is no precise position
    either (rounded to the pixel, up to 0.7 px off), and the template and the motion model
    start from the same centre as before."""
    res.x[k], res.y[k] = tracker.pos[:, 0], tracker.pos[:, 1]
    res.xpix[k], res.ypix[k] = np.rint(tracker.pos[:, 0]), np.rint(tracker.pos[:, 1])
    res.score[k] = 1.0
    res.sigma[k] = tracker.sigma0
    res.status[k] = OK
    with np.errstate(invalid="ignore"):
        vague = tracker.sigma0 > tracker.p.max_sigma
    res.status[k, vague] = FLAGGED
    res.reason[k, vague] = _R["imprecise"]
    moved = tracker.pick_moved
    res.status[k, moved] = FLAGGED
    res.reason[k, moved] = _R["pick_moved"]


@dataclasses.dataclass(frozen=True)
class _Pass:
    """One pass of a run: frames ``first`` to ``last`` (inclusive) in ``direction`` (+1/-1).

    A ``"track"`` pass follows group ``group`` (the markers picked in one frame ``k``) away
    from its picks: forward from ``k + 1`` to the last frame, or backward from ``k - 1``
    to frame 0. A ``"verify"`` pass (``bidirectional=True``) tracks the same markers back
    towards ``k`` from where the track pass before it ended, seeded from that pass.
    """

    group: int
    kind: str
    first: int
    last: int
    direction: int

    def frames(self, start):
        """The frames still to track from ``start`` on (a range, empty when done)."""
        return range(start, self.last + self.direction, self.direction)


def _plan(pick_frames, T, bidirectional):
    """The passes of a run over ``T`` frames for groups picked in ``pick_frames`` (in order).

    Each group is tracked forward from its pick frame ``k`` to the end and backward to
    frame 0; with ``bidirectional`` each of these is followed by its verify pass (from the
    end back to ``k``; from frame 0 forward to ``k - 1``). A side with no frames to track
    (``k`` the last frame, or frame 0) has no passes. Picks all in frame 0 give the
    classic forward pass and, bidirectional, the backward pass from the last frame.
    """
    plan = []
    for g, k in enumerate(pick_frames):
        if k < T - 1:
            plan.append(_Pass(g, "track", k + 1, T - 1, 1))
            if bidirectional:
                plan.append(_Pass(g, "verify", T - 2, k, -1))
        if k > 0:
            plan.append(_Pass(g, "track", k - 1, 0, -1))
            if bidirectional:
                plan.append(_Pass(g, "verify", 1, k - 1, 1))
    return plan


class _Run:
    """A tracking run: its passes, their result arrays, and where it stands.

    The markers are grouped by the frame they were picked in; each group has its own
    tracker and result arrays (``res``; ``ver`` for the verify passes). The run's state
    (pass index, next frame, the current tracker, every result array) is what a
    checkpoint saves and what :meth:`resume` restores, so a resumed run takes exactly
    the steps an uninterrupted one would.
    """

    def __init__(self, fr, xy, ids, half, pick_frames, active, p, bidirectional):
        self.fr, self.p = fr, p
        self.xy, self.ids, self.half = xy, ids, half
        self.active = active
        self.ks = np.unique(pick_frames[active]).tolist()
        self.sel = [np.flatnonzero(active & (pick_frames == k)) for k in self.ks]
        T = fr.n
        self.res = [_Results(T, s.size) for s in self.sel]
        self.ver = [_Results(T, s.size) for s in self.sel] if bidirectional else None
        self.passes = _plan(self.ks, T, bidirectional)
        self.i = 0  # the pass under way (len(passes): done)
        self.next = None  # its next frame (None: not started)
        self.read = 0  # the highest frame index read so far (the fingerprint samples 0 .. read)
        self.tracker = None
        self.ck = None
        self.resumed = False

    # ------------------------------------------------------------ checkpoint state
    def _prefixes(self):
        for g in range(len(self.sel)):
            yield f"g{g}_", self.res[g]
            if self.ver is not None:
                yield f"v{g}_", self.ver[g]

    def required(self):
        """Names of the arrays a checkpoint of this run must hold."""
        return [pre + k for pre, _ in self._prefixes() for k in _Results.names + ("status", "reason")]

    def state(self):
        """(meta, arrays) of a checkpoint."""
        meta = {"pass": self.i, "next": self.next, "read": self.read, "n_passes": len(self.passes)}
        arrays = {}
        for pre, r in self._prefixes():
            arrays.update(r.arrays(pre))
        if self.tracker is not None:
            arrays.update({"st_" + k: v for k, v in self.tracker.state().items()})
        return meta, arrays

    def resume(self, meta, arrays, path):
        """Restore the state a checkpoint (``path``) saved."""
        i, nxt = meta.get("pass"), meta.get("next")
        if not (meta.get("n_passes") == len(self.passes) and isinstance(i, int) and 0 <= i <= len(self.passes)
                and (nxt is None or isinstance(nxt, int))):
            raise ValueError(f"checkpoint {path} is incomplete or corrupt (pass {i!r} of "
                             f"{meta.get('n_passes')!r}, next frame {nxt!r}); {_WAY_OUT}")
        for pre, r in self._prefixes():
            r.load(arrays, pre)
        self.i, self.next, self.read = i, nxt, int(meta.get("read", 0))
        self.resumed = True
        if i < len(self.passes) and (nxt is not None or "st_h" in arrays):
            st = {k[3:]: v for k, v in arrays.items() if k.startswith("st_")}
            try:
                self.tracker = _Tracker.from_state(st, self.p, self.fr.is_u8, self.fr.shape)
            except (KeyError, ValueError, IndexError) as exc:
                raise ValueError(f"checkpoint {path} is incomplete or corrupt ({type(exc).__name__}: {exc}); "
                                 f"{_WAY_OUT}") from None
        if i < len(self.passes):
            logger.info("resuming pass %d of %d at frame %s from %s", i + 1, len(self.passes), nxt, path)

    def completed(self, t):
        """Frame ``t`` of the current pass was tracked (called by :func:`_run_pass`)."""
        self.next = t + self.passes[self.i].direction
        self.read = max(self.read, t)
        if self.ck is not None:
            self.ck.completed(t)

    def save(self):
        """Save a checkpoint, if the run has one (called by :func:`_run_pass` when it stops)."""
        if self.ck is not None:
            self.ck.save()

    # ------------------------------------------------------------ passes
    def _start(self, ps):
        """The tracker of pass ``ps``, its first row written (the picks, or the seed of a verify)."""
        g = ps.group
        k, sel = self.ks[g], self.sel[g]
        self.read = max(self.read, k)
        if ps.kind == "track":
            tracker = _Tracker.from_picks(self.fr[k], self.xy[sel], self.half[sel], self.p, self.fr.is_u8,
                                          self.ids[sel])
            tracker.hist_t[:] = k
            tracker.last_ok[:] = k
            tracker.last_upd[:] = k
            _seed_row(self.res[g], k, tracker)
            return tracker
        end = ps.first - ps.direction  # where the track pass before it ended (the last frame or 0)
        _copy_row(self.ver[g], self.res[g], end)
        return _reverse_tracker(self.tracker, self.res[g], end, k)

    def run(self, ck, progress, camera):
        """Run (or finish) every pass, saving to the checkpointer ``ck`` (or None)."""
        self.ck = ck
        todo = self.i < len(self.passes) or not self.resumed  # a finished checkpoint is not saved again
        try:
            while self.i < len(self.passes):
                ps = self.passes[self.i]
                if self.next is None:
                    self.tracker = self._start(ps)
                    self.next = ps.first
                out = self.res[ps.group] if ps.kind == "track" else self.ver[ps.group]
                k = self.ks[ps.group]
                desc = (f"{'track' if ps.direction > 0 else 'back'} {camera}" + (f" from {k}" if k else "")
                        + (" (check)" if ps.kind == "verify" else ""))
                _run_pass(self.fr, self.tracker, out, ps.frames(self.next), ps.direction, self, progress, desc)
                self.i += 1
                self.next = None
        except BaseException:
            if self.tracker is not None:  # (also stopped between two passes: the state is whole there too)
                self.save()
            raise
        if todo:
            self.save()

    def merged(self):
        """The (T, N) results of every point: verify passes merged, ``no_pick`` rows for NaN picks."""
        T, N = self.fr.n, len(self.ids)
        out = _Results(T, N)
        out.reason[:, ~self.active] = _R["no_pick"]
        for g, (k, sel) in enumerate(zip(self.ks, self.sel)):
            res = _Results(T, sel.size)
            for name in _Results.names + ("status", "reason"):
                getattr(res, name)[...] = getattr(self.res[g], name)
            if self.ver is not None:
                # each side of k in the verify pass's own order (the backward side reversed)
                _merge_backward(res.rows(slice(k, None)), self.ver[g].rows(slice(k, None)), self.p.fb_tolerance)
                if k > 0:
                    low = slice(k - 1, None, -1)
                    _merge_backward(res.rows(low), self.ver[g].rows(low), self.p.fb_tolerance)
            for name in _Results.names + ("status", "reason"):
                getattr(out, name)[:, sel] = getattr(res, name)
        _flag_across_groups(out, self.sel)
        # the last check: ok points against their neighbours' map from the picks, among the
        # markers picked on one frame (the largest group); then each other group against
        # the constellation on its own pick frame (every marker ok there judges it)
        n = 0
        if self.sel:
            main = max(range(len(self.sel)), key=lambda g: len(self.sel[g]))
            audited = np.zeros(N, bool)
            audited[self.sel[main]] = True
            n = audit_against_picks(out, self.xy, audited)
            for g, (k, sel) in enumerate(zip(self.ks, self.sel)):
                if g != main:
                    n += _audit_group(out, self.xy, k, sel)
        if n:
            logger.info("%d ok point-frames flagged 'misplaced': away from where their neighbours' map from the "
                        "picks puts them", n)
        # (after the audit, whose judges are the ok points as the tracker left them)
        n = flag_persistent_imprecision(out.status, out.reason, out.sigma, self.p.max_sigma)
        if n:
            logger.info("%d ok point-frames flagged 'imprecise': their marker's sigma over the frames around "
                        "exceeds max_sigma", n)
        return out


def _audit_group(res, xy, k, sel):
    """Audit (:func:`~.audit.audit_against_picks`) the markers ``sel`` picked on frame ``k``
    against the constellation on that frame: their picks and the positions of the markers
    ok there; returns how many of their ok point-frames were flagged."""
    ref = np.full((res.x.shape[1], 2), np.nan)
    ok = res.status[k] == OK
    ref[ok, 0], ref[ok, 1] = res.x[k, ok], res.y[k, ok]
    ref[sel] = xy[sel]
    judged = np.zeros(len(ref), bool)
    judged[sel] = True
    return audit_against_picks(res, ref, np.all(np.isfinite(ref), axis=1), judged)


def _flag_across_groups(res, groups, tol=GROUP_CONFLICT_PX):
    """Flag ``conflict`` where markers of different groups sit on one blob.

    The groups' trackers do not see each other, so the tracker's own rule (two points
    never claim one blob) cannot act between them: an ok position within ``tol`` px of a
    position of another group's marker on the same frame is flagged (both, when both were
    ok: which one is right is not known).
    """
    if len(groups) < 2:
        return
    has = np.isfinite(res.x) & (res.status != LOST)
    hit = np.zeros(res.x.shape, bool)
    for a in range(len(groups)):
        for b in range(a + 1, len(groups)):
            for i in groups[a]:
                for j in groups[b]:
                    close = has[:, i] & has[:, j] & (np.hypot(res.x[:, i] - res.x[:, j], res.y[:, i] - res.y[:, j]) < tol)
                    hit[:, i] |= close
                    hit[:, j] |= close
    hit &= res.status == OK
    res.status[hit] = FLAGGED
    res.reason[hit] = _R["conflict"]


def _copy_row(dst, src, t):
    """Row ``t`` of every result array of ``src`` into ``dst``."""
    for name in _Results.names + ("status", "reason"):
        getattr(dst, name)[t] = getattr(src, name)[t]


def _reverse_tracker(tracker, res, end, k):
    """A tracker for the verify pass back from frame ``end`` towards the pick frame ``k``.

    It keeps ``tracker``'s templates (the original ones, without the running updates)
    and restarts the motion model of each marker at its ok position nearest to ``end``
    in ``res`` (on the side of ``k`` that ``end`` is on; the pick itself when none is
    ok), lost when that is more than ``max_coast`` frames from ``end``.
    """
    import copy

    b = copy.copy(tracker)
    n = len(tracker.h)
    b.hist_x = np.full((n, 3, 2), np.nan)
    b.hist_t = np.zeros((n, 3), np.int64)
    b.nh = np.ones(n, np.int64)
    b.lostflag = np.zeros(n, bool)
    b.resid_rms = np.ones(n)
    b.last_upd = np.full(n, end, np.int64)
    b.last_ok = np.full(n, end, np.int64)
    b.tplr = [t.copy() for t in tracker.tpl0]
    b.tplu = [None] * n
    b.last_score = np.ones(n)
    b._init_stack()
    lo, hi = (k, end) if end >= k else (end, k)
    for i in range(n):
        okf = lo + np.flatnonzero(res.status[lo:hi + 1, i] == OK)
        tl = (int(okf[-1]) if end >= k else int(okf[0])) if okf.size else k
        b.hist_x[i, 0] = (res.x[tl, i], res.y[tl, i])
        b.hist_t[i, 0] = tl
        b.last_ok[i] = tl
        b.lostflag[i] = abs(end - tl) > tracker.p.max_coast
    return b
