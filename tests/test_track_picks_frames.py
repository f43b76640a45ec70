"""Picks in several frames with bidirectional tracking and checkpoints (issue 8, items 4
and 7), and frames read once by track_folder / track_stereo.

A group of markers picked in frame k is tracked forward from k to the end and backward
from k to frame 0; with ``bidirectional=True`` each side is checked by a pass back
towards k. Each side must therefore be exactly the classic frame-0 run on the
sub-sequence that starts at k (forward: ``frames[k:]``; backward: ``frames[k::-1]``).
"""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_track import errors, moving_discs

from wingphoto.track import track_markers

K = 9  # the frame the late markers are picked in


@pytest.fixture(scope="module")
def seq():
    frames, truth, _ = moving_discs(7, T=24)
    return frames, truth


def _picks(truth, frame_of):
    """Picks table: point i clicked (to the pixel) on its true centre in frame ``frame_of[i]``."""
    frame_of = np.asarray(frame_of)
    idx = np.arange(truth.shape[1])
    return pd.DataFrame({"point": idx, "frame": frame_of, "x": np.rint(truth[frame_of, idx, 0]),
                         "y": np.rint(truth[frame_of, idx, 1])})


class FailOnRead:
    """Frames whose ``n``-th read raises ``exc`` (a crash or Ctrl-C anywhere in a run)."""

    def __init__(self, frames, n, exc=RuntimeError):
        self.frames, self.n, self.exc, self.reads = frames, n, exc, 0

    def __len__(self):
        return len(self.frames)

    def __getitem__(self, i):
        self.reads += 1
        if self.reads == self.n:
            raise self.exc("simulated stop")
        return self.frames[i]


class CountReads(FailOnRead):
    def __init__(self, frames):
        super().__init__(frames, -1)


# --------------------------------------------------------------------------- each side is the classic run
@pytest.mark.parametrize("bidirectional", [False, True])
def test_each_side_of_the_pick_frame_is_the_classic_run_on_that_side(bidirectional):
    # noisy, fast discs: the forward and backward passes disagree (by > 1e-3 px) somewhere
    frames, truth, _ = moving_discs(4, T=30, noise_std=25, speed=12)
    k = 14
    # search_every=1: every marker searched on every frame, so no decision depends on the
    # frame's absolute number and a run on a sub-sequence is comparable
    kw = {"progress": False, "bidirectional": bidirectional, "search_every": 1, "fb_tolerance": 1e-3}
    got = track_markers(frames, _picks(truth, np.full(truth.shape[1], k)), **kw).set_index(["frame", "point"])
    fwd = track_markers(frames[k:], np.rint(truth[k]), **kw)
    bwd = track_markers(frames[k::-1], np.rint(truth[k]), **kw)
    cols = ["x", "y", "score", "status", "reason", "sigma", "x_pix", "y_pix"]
    for part, frame_no in ((fwd, k + fwd.frame), (bwd, k - bwd.frame)):
        part = part.assign(frame=frame_no).set_index(["frame", "point"])
        if part is not fwd and bidirectional:
            # the pick frame itself is checked by the forward side's pass only
            part = part.drop(index=k, level="frame")
        pd.testing.assert_frame_equal(got.loc[part.index, cols], part[cols], check_dtype=False)
        # (the comparison means something: the passes disagree on both sides)
        assert (part.reason == "fb_disagree").any() == bidirectional


def test_late_markers_are_ok_both_ways_with_bidirectional(seq):
    frames, truth = seq
    frame_of = np.where(np.arange(truth.shape[1]) % 3 == 1, K, 0)
    frame_of[2] = len(frames) - 1  # one picked in the last frame: tracked backward only
    tr = track_markers(frames, _picks(truth, frame_of), progress=False, bidirectional=True)
    err, status = errors(tr, truth)
    assert (status == "ok").mean() > 0.97 and err[status == "ok"].max() < 0.3
    assert (status[:, frame_of == K] == "ok").all() and (status[:, 2] == "ok").all()


def test_markers_of_different_pick_frames_on_one_blob_are_flagged(seq):
    frames, truth = seq
    picks = _picks(truth, np.zeros(truth.shape[1], int))
    # point 8: a second click on marker 3's disc, made in frame K (a mistake, or the
    # marker it was meant for hidden): its group's tracker cannot see point 3's
    j = truth[K, 3]
    picks.loc[len(picks)] = [8, K, np.rint(j[0]), np.rint(j[1])]
    tr = track_markers(frames, picks, progress=False)
    both = tr[tr.point.isin([3, 8])]
    assert not (both.status == "ok").any()
    assert (both[both.frame != K].reason == "conflict").all()
    others = tr[~tr.point.isin([3, 8])]
    assert (others.status == "ok").all()


# --------------------------------------------------------------------------- checkpoints
@pytest.fixture(scope="module")
def several(seq):
    frames, truth = seq
    frame_of = np.where(np.arange(truth.shape[1]) % 3 == 1, K, 0)
    picks = _picks(truth, frame_of)
    return picks, track_markers(frames, picks, progress=False, bidirectional=True)


# stops spread over the run's reads: group 0 (picked in frame 0): forward, checked
# backward; group 1 (frame 9): forward, checked back, backward, checked forward
@pytest.mark.parametrize("when", [0.01, 0.2, 0.35, 0.5, 0.6, 0.7, 0.8, 0.9, 0.99])
@pytest.mark.parametrize("every", [5, 1000])
def test_resume_with_picks_in_several_frames_and_bidirectional(seq, several, tmp_path, when, every):
    frames, _ = seq
    picks, ref = several
    reads = CountReads(frames)
    track_markers(reads, picks, progress=False, bidirectional=True, checkpoint=tmp_path / "full.npz",
                  checkpoint_every=every)
    ck = tmp_path / "ck.npz"
    with pytest.raises(RuntimeError, match="simulated stop"):
        track_markers(FailOnRead(frames, max(2, round(when * reads.reads))), picks, progress=False,
                      bidirectional=True, checkpoint=ck, checkpoint_every=every)
    resumed = track_markers(frames, picks, progress=False, bidirectional=True, checkpoint=ck,
                            checkpoint_every=every)
    pd.testing.assert_frame_equal(resumed, ref)
    # the finished checkpoint gives the same table again, without tracking a frame
    reads = CountReads(frames)
    pd.testing.assert_frame_equal(track_markers(reads, picks, progress=False, bidirectional=True, checkpoint=ck),
                                  ref)
    assert reads.reads <= 1 + 8 + 1  # frame 0 (checks), the fingerprint's frames, nothing tracked


def test_ctrl_c_with_picks_in_several_frames_resumes_identically(seq, several, tmp_path):
    frames, _ = seq
    picks, ref = several
    ck = tmp_path / "ck.npz"
    with pytest.raises(KeyboardInterrupt):
        track_markers(FailOnRead(frames, 90, KeyboardInterrupt), picks, progress=False, bidirectional=True,
                      checkpoint=ck, checkpoint_every=1000)
    assert ck.is_file()
    pd.testing.assert_frame_equal(
        track_markers(frames, picks, progress=False, bidirectional=True, checkpoint=ck), ref)


def test_checkpoint_for_other_pick_frames_is_refused(seq, several, tmp_path):
    frames, _ = seq
    picks, _ = several
    ck = tmp_path / "ck.npz"
    track_markers(frames, picks, progress=False, checkpoint=ck)
    before = ck.read_bytes()
    other = picks.copy()
    other.loc[1, "frame"] = K + 1  # same click, said to be made one frame later
    with pytest.raises(ValueError) as e:
        track_markers(frames, other, progress=False, checkpoint=ck)
    msg = str(e.value)
    assert "\n" not in msg and str(ck) in msg and "was written for other frames, picks or options" in msg
    with pytest.raises(ValueError, match="was written for other frames, picks or options"):
        track_markers(frames, picks, progress=False, bidirectional=True, checkpoint=ck)
    assert ck.read_bytes() == before  # nothing on disk lost


def test_checkpoint_of_another_version_is_refused(seq, several, tmp_path):
    import json

    frames, _ = seq
    picks, _ = several
    ck = tmp_path / "ck.npz"
    track_markers(frames[:6], picks.assign(frame=0), progress=False, checkpoint=ck)
    with np.load(ck) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(bytes(arrays["meta"]).decode())
    meta["version"] = 3
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    with open(ck, "wb") as f:
        np.savez(f, **arrays)
    with pytest.raises(ValueError, match=r"written by another version of wingphoto \(format 3"):
        track_markers(frames[:6], picks.assign(frame=0), progress=False, checkpoint=ck)


# --------------------------------------------------------------------------- frames read once
SAMPLES = Path(__file__).resolve().parents[1] / "data-samples" / "flapping"
needs_samples = pytest.mark.skipif(not (SAMPLES / "left").is_dir(), reason="data-samples/flapping not present")


class ReadsPerFrame:
    """A lazy sequence (as :func:`wingphoto.io.read_sequence` gives) counting each frame's reads."""

    def __init__(self, frames):
        self.frames = frames
        self.shape = frames.shape
        self.reads = np.zeros(len(frames), int)

    def __len__(self):
        return len(self.frames)

    def __getitem__(self, i):
        self.reads[i] += 1
        return self.frames[i]


def _sample(cam, n=60):
    from wingphoto.io import read_sequence

    return read_sequence(SAMPLES / cam).to_array()[:n]


@needs_samples
def test_track_folder_reads_each_frame_once_and_still_checks_it(caplog):
    import wingphoto as wp

    left = _sample("left")
    left[25] = 0  # a blank frame: logged by the check
    counted = ReadsPerFrame(left)
    tracks = wp.track_folder(counted, SAMPLES / "picks.json", camera="left", progress=False)
    # the check's static background reads up to 31 spread frames first; then the check and
    # the tracker share one read of each frame (frame 0, small, a few more: picks, first step)
    assert counted.reads[1:].max() <= 2 and counted.reads[1:].sum() <= len(left) - 1 + 31
    assert (counted.reads[1:] == 1).sum() >= len(left) - 1 - 31
    assert "blank frame(s) at index 25" in caplog.text
    alone = wp.track_folder(left, SAMPLES / "picks.json", camera="left", progress=False, check=False)
    pd.testing.assert_frame_equal(tracks, alone)
    # a duplicated frame still stops the run (when the tracker reads it)
    dup = left.copy()
    dup[12] = dup[11]
    counted = ReadsPerFrame(dup)
    with pytest.raises(ValueError, match=r"duplicated frame\(s\) at index 12.*force=True \(--force\)"):
        wp.track_folder(counted, SAMPLES / "picks.json", camera="left", progress=False)
    assert counted.reads[13:].sum() <= 31  # stopped there (only the background's frames read after it)


@needs_samples
def test_track_stereo_reads_each_frame_once():
    import wingphoto as wp
    from wingphoto.synth.rig import load_rig

    rig = load_rig(SAMPLES.parent / "rig.json")
    views = [ReadsPerFrame(_sample(cam)) for cam in ("left", "right")]
    tracks, _ = wp.track_stereo(*views, SAMPLES / "picks.json", rig, progress=False)
    # the same work done apart: the check (with its epipolar offset check), then tracking
    apart = [ReadsPerFrame(v.frames) for v in views]
    wp.check_stereo_sequences(*apart, rig=rig)
    alone = wp.track_stereo(*apart, SAMPLES / "picks.json", rig, progress=False, check=False)
    pd.testing.assert_frame_equal(tracks, alone[0])
    for v, a in zip(views, apart):
        # one read of each frame (but frame 0) is shared by the check and the tracker
        assert v.reads[1:].sum() == a.reads[1:].sum() - (len(v) - 1)
    # an offset found only by the full check still stops the run
    with pytest.raises(ValueError, match=r"right view seems offset by \+1 frame"):
        wp.track_stereo(views[0].frames[:30], views[1].frames[1:31], SAMPLES / "picks.json", rig, progress=False)


# (without deferring Ctrl-C to the end of the frame, stops at 5, 15 and 75 resumed with 90,
# 40 and 24 rows different)
@pytest.mark.parametrize("at", [5, 15, 75])
def test_ctrl_c_in_the_middle_of_a_frame_resumes_identically(seq, several, tmp_path, monkeypatch, at):
    import os
    import signal

    from wingphoto.track import tracker as tracker_module

    frames, _ = seq
    picks, ref = several
    # a process started in the background by a non-interactive shell ignores SIGINT (no
    # KeyboardInterrupt at all): give this test Python's own handler, as in a terminal
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        real, calls = tracker_module.update_model, []

        def interrupted(*args, **kw):  # Ctrl-C after the motion model's update, before the rest of the frame
            out = real(*args, **kw)
            calls.append(1)
            if len(calls) == at:
                os.kill(os.getpid(), signal.SIGINT)
            return out

        monkeypatch.setattr(tracker_module, "update_model", interrupted)
        ck = tmp_path / "ck.npz"
        from wingphoto.track import engine
        engine.try_fast_frames(False)  # (the compiled fast frame updates the motion model without update_model)
        try:
            with pytest.raises(KeyboardInterrupt):
                track_markers(frames, picks, progress=False, bidirectional=True, checkpoint=ck, checkpoint_every=1000)
        finally:
            engine.try_fast_frames(True)
        monkeypatch.undo()
        assert len(calls) >= at and signal.getsignal(signal.SIGINT) is signal.default_int_handler
        pd.testing.assert_frame_equal(
            track_markers(frames, picks, progress=False, bidirectional=True, checkpoint=ck), ref)
    finally:
        signal.signal(signal.SIGINT, previous)
