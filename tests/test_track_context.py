"""The tracker keeps its state and a frame's results apart (issue 8: a short ``Tracker.step``
with a per-frame context instead of scratch attributes).

A hard render with frames dropped (so that the constellation check solves a frame again
under its hypotheses) is tracked with both engines; a spy around ``Tracker.step`` checks
that no step adds an attribute to the tracker (a per-frame scratch value stored on it),
a spy around ``Tracker._judge`` that each frame's results arrive as a complete
``FrameContext``, and the docstrings are checked to name every attribute and field.
"""
import dataclasses
import re

import numpy as np
import pytest

from wingphoto import synth
from wingphoto.track import engine, track_markers
from wingphoto.track.templates import TemplateStage
from wingphoto.track.tracker import FrameContext, Tracker

#: the only attribute a step may add: the fast frame's cache of its constant arguments
_CACHES = {"_fast_par"}


@pytest.fixture(scope="module")
def dropped():
    """A hard render with frames 9 and 10 dropped (frames, picks)."""
    seq = synth.render_flapping(n_frames=20, preset="hard", seed=2)
    keep = np.r_[0:9, 11:20]
    return np.asarray(seq.frames("left"))[keep], seq.picks("left")


def _spied_run(monkeypatch, frames, picks):
    """Track; return the trackers, the attributes each step added, the contexts judged and
    the number of constellation recoveries."""
    trackers, added, contexts, recovered = [], [], [], []
    step, judge, recover = Tracker.step, Tracker._judge, Tracker._recover

    def spy_step(self, frame, t, res, direction=1):
        if not trackers or trackers[-1] is not self:
            trackers.append(self)
        before = set(vars(self))
        step(self, frame, t, res, direction)
        added.append(set(vars(self)) - before)

    def spy_judge(self, t, res, ctx):
        judge(self, t, res, ctx)
        contexts.append(ctx)

    def spy_recover(self, frame, t, direction, ctx):
        recovered.append(t)
        return recover(self, frame, t, direction, ctx)

    monkeypatch.setattr(Tracker, "step", spy_step)
    monkeypatch.setattr(Tracker, "_judge", spy_judge)
    monkeypatch.setattr(Tracker, "_recover", spy_recover)
    track_markers(frames, picks, progress=False)
    return trackers, added, contexts, recovered


@pytest.mark.parametrize("numba", [True, False], ids=["numba", "numpy"])
def test_step_stores_no_frame_results_on_the_tracker(monkeypatch, dropped, numba):
    if numba and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba is not installed")
    frames, picks = dropped
    try:
        engine.try_numba(numba)
        engine.try_fast_frames(False)  # every frame through the Python stages
        trackers, added, contexts, recovered = _spied_run(monkeypatch, frames, picks)
    finally:
        engine.try_numba(True)
        engine.try_fast_frames(True)
    assert len(added) == len(frames) - 1 and trackers
    extra = set().union(*added) - _CACHES
    assert not extra, f"Tracker.step stored per-frame values on the tracker: {sorted(extra)}"
    assert recovered, "the dropped frames did not reach the constellation check"
    assert len(contexts) == len(frames) - 1
    for ctx in contexts:
        assert type(ctx) is FrameContext
        missing = [f.name for f in dataclasses.fields(ctx) if getattr(ctx, f.name) is None]
        assert not missing, f"fields left unset by the stages: {missing}"
        n = len(ctx.X)
        assert ctx.pred.shape == (n, 2) and ctx.ST.shape == ctx.RS.shape == ctx.sigma.shape == (n,)


def _named(doc, name):
    return re.search(rf"(?<![\w.]){re.escape(name)}(?!\w)", doc) is not None


def test_state_and_context_are_documented(monkeypatch, dropped):
    frames, picks = dropped
    trackers, _, _, _ = _spied_run(monkeypatch, frames[:6], picks)
    doc = Tracker.__doc__ + TemplateStage.__doc__
    undocumented = [k for k in vars(trackers[0]) if not _named(doc, k)]
    assert not undocumented, f"tracker attributes missing from the docstrings: {undocumented}"
    assert set(Tracker._STATE) <= set(vars(trackers[0]))
    fields = [f.name for f in dataclasses.fields(FrameContext)]
    head = FrameContext.__doc__.split("Attributes")[1]
    listed = {n.strip() for line in head.splitlines() if " : " in line for n in line.split(" : ")[0].split(",")}
    assert set(fields) == listed, set(fields) ^ listed
