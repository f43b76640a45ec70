"""Tests of the tracker's inputs and state: options, picks in any frame, checkpoints, the
engine switch (each compiled kernel against its numpy twin)."""
import numpy as np
import pandas as pd
import pytest

from test_track import errors, moving_discs
from wingphoto.track import TrackOptions, engine, track_markers


@pytest.fixture(scope="module")
def seq():
    frames, truth, _ = moving_discs(7, T=24)
    return frames, truth


# --------------------------------------------------------------------------- options
def test_options_one_place_for_defaults_and_validation():
    o = TrackOptions()
    assert o.max_sigma == 0.25 and o.search_radius == 20 and o.max_mass_ratio is None
    with pytest.raises(ValueError, match="lost_score .* must not exceed min_score"):
        TrackOptions(min_score=0.2, lost_score=0.5)
    with pytest.raises(ValueError, match="max_coast must be >= 0"):
        TrackOptions(max_coast=-1)
    with pytest.raises(ValueError, match="max_sigma must be > 0"):
        TrackOptions(max_sigma=0)
    with pytest.raises(ValueError, match="search_radius must be an integer"):
        TrackOptions(search_radius=2.5)


def test_keywords_override_options(seq):
    frames, truth = seq
    a = track_markers(frames[:6], np.rint(truth[0]), progress=False, options=TrackOptions(max_sigma=1e-6))
    assert (a[a.frame > 0].reason == "imprecise").all()  # every sigma is above 1e-6 px
    b = track_markers(frames[:6], np.rint(truth[0]), progress=False, options=TrackOptions(max_sigma=1e-6),
                      max_sigma=0.25)
    assert (b.status == "ok").all()
    with pytest.raises(TypeError, match="unknown option"):
        track_markers(frames[:3], np.rint(truth[0]), progress=False, min_scroe=0.5)


def test_sigma_column_is_small_and_honest_on_clean_discs(seq):
    frames, truth = seq
    tr = track_markers(frames, np.rint(truth[0]), progress=False)
    err, status = errors(tr, truth)
    sig = tr.sigma.to_numpy().reshape(err.shape)
    ok = status == "ok"
    assert np.isfinite(sig[ok]).all() and (sig[ok] > 0).all() and (sig[ok] < 0.1).all()
    assert np.mean(err[ok] <= 3 * sig[ok]) >= 0.95


# --------------------------------------------------------------------------- picks in any frame
def test_marker_picked_in_a_later_frame_is_tracked_both_ways(seq):
    frames, truth = seq
    k = 9
    picks = pd.DataFrame({"point": np.arange(truth.shape[1]), "frame": 0,
                          "x": np.rint(truth[0, :, 0]), "y": np.rint(truth[0, :, 1])})
    picks.loc[3, ["frame", "x", "y"]] = [k, np.rint(truth[k, 3, 0]), np.rint(truth[k, 3, 1])]
    tr = track_markers(frames, picks, progress=False)
    err, status = errors(tr, truth)
    assert (status == "ok").mean() > 0.97 and err[status == "ok"].max() < 0.3
    assert (status[:, 3] == "ok").all()  # backward to frame 0 and forward to the end


def test_pick_frame_outside_the_sequence_is_refused(seq):
    frames, truth = seq
    picks = pd.DataFrame({"point": [0], "frame": [99], "x": [truth[0, 0, 0]], "y": [truth[0, 0, 1]]})
    with pytest.raises(ValueError, match="point 0 was picked in frame 99 but the sequence has 24 frames"):
        track_markers(frames, picks, progress=False)
    picks["frame"] = [1.5]
    with pytest.raises(ValueError, match="whole number"):
        track_markers(frames, picks, progress=False)


# --------------------------------------------------------------------------- checkpoints
def test_checkpoint_for_other_frames_with_the_same_first_frame_is_refused(seq, tmp_path):
    frames, truth = seq
    ck = tmp_path / "ck.npz"
    track_markers(frames, np.rint(truth[0]), progress=False, checkpoint=ck)
    other = frames.copy()
    other[len(frames) - 1] = other[len(frames) - 2]  # same length, same frame 0, other content
    with pytest.raises(ValueError, match=r"written for other frames, picks or options \(the content of frames .* differs\); delete it"):
        track_markers(other, np.rint(truth[0]), progress=False, checkpoint=ck)


@pytest.mark.parametrize("kind", ["empty", "truncated", "random", "foreign"])
def test_unreadable_checkpoint_gives_a_clear_error(seq, tmp_path, kind):
    frames, truth = seq
    ck = tmp_path / "ck.npz"
    if kind == "empty":
        ck.write_bytes(b"")
    elif kind == "random":
        ck.write_bytes(np.random.default_rng(0).bytes(3000))
    elif kind == "foreign":
        np.savez(ck, a=np.arange(3))
    else:
        track_markers(frames[:8], np.rint(truth[0]), progress=False, checkpoint=ck)
        ck.write_bytes(ck.read_bytes()[:400])
    with pytest.raises(ValueError) as e:
        track_markers(frames[:8], np.rint(truth[0]), progress=False, checkpoint=ck)
    msg = str(e.value)
    assert str(ck) in msg and "delete it or pass another checkpoint path" in msg


def test_cli_checkpoint_every_and_interrupt(tmp_path, monkeypatch, capsys):
    from wingphoto import cli, pipeline

    seen = {}

    def fake(frames, picks, **kw):
        seen.update(kw)
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "track_folder", fake)
    rc = cli.main(["track", "--frames", "f", "--picks", "p.json", "--out", str(tmp_path / "t.csv"),
                   "--checkpoint", str(tmp_path / "ck.npz"), "--checkpoint-every", "7"])
    err = capsys.readouterr().err
    assert rc == 130 and seen["checkpoint_every"] == 7
    assert "interrupted; progress saved in" in err and "Traceback" not in err and err.count("\n") == 1


def test_interrupt_saves_a_checkpoint_that_resumes_identically(seq, tmp_path):
    frames, truth = seq
    ck = tmp_path / "ck.npz"

    class Interrupting:
        def __len__(self):
            return len(frames)

        def __getitem__(self, i):
            if i == 15:
                raise KeyboardInterrupt
            return frames[i]

    with pytest.raises(KeyboardInterrupt):
        track_markers(Interrupting(), np.rint(truth[0]), progress=False, checkpoint=ck, checkpoint_every=1000)
    assert ck.exists()
    resumed = track_markers(frames, np.rint(truth[0]), progress=False, checkpoint=ck)
    fresh = track_markers(frames, np.rint(truth[0]), progress=False)
    pd.testing.assert_frame_equal(resumed, fresh)


# --------------------------------------------------------------------------- engines
needs_numba = pytest.mark.skipif(not engine.NUMBA_AVAILABLE, reason="numba not installed")


@needs_numba
def test_engine_twins_predict_and_update():
    from wingphoto.track import predict

    rng = np.random.default_rng(3)
    n = 12
    hx = rng.uniform(20, 180, (n, 3, 2))
    ht = np.tile([9, 8, 7], (n, 1)).astype(np.int64)
    ht[:3] = [11, 6, 5]
    nh = rng.integers(1, 4, n).astype(np.int64)
    args = (12, hx, ht, nh, rng.uniform(0.05, 1, n), rng.random(n) < 0.2, np.full(n, 11, np.int64),
            rng.uniform(0.8, 1, n), np.arange(n) % 4, np.full(n, 5, np.int64), rng.uniform(3, 5, n), 200, 200, 6, 4,
            20)
    outs = []
    for on in (True, False):
        engine.try_numba(on)
        a = [x.copy() if isinstance(x, np.ndarray) else x for x in args]
        outs.append(predict.start_frame(*a))
    engine.try_numba(True)
    for k in outs[0]:
        np.testing.assert_allclose(outs[0][k], outs[1][k], err_msg=k)


@needs_numba
def test_engine_twins_status_conditions():
    from wingphoto.track import status

    rng = np.random.default_rng(4)
    n = 30
    XP = rng.uniform(0, 100, n)
    XP[::7] = np.nan
    args = (rng.random(n) < 0.9, rng.uniform(0, 1, n), rng.uniform(-1, 1, n), rng.uniform(-5, 50, n),
            np.full(n, 40.0), np.full(n, 40.0), np.full(n, 0.9), rng.uniform(0, 6, n), rng.uniform(0, 1, n),
            rng.integers(1, 4, n), rng.integers(1, 4, n), rng.random(n) < 0.1, rng.random(n) < 0.1, XP,
            rng.uniform(0, 100, n), rng.uniform(0, 100, n), rng.uniform(0, 100, n), rng.random(n) < 0.9,
            rng.integers(-1, n, (n, 2)), rng.uniform(2, 5, n), rng.uniform(0, 1, n), rng.random(n) < 0.1,
            np.array([0.6, 0.3, 0.25, np.inf, np.inf, 0.1, 3.0, 0.5, 0.8]))
    conds = []
    for on in (True, False):
        engine.try_numba(on)
        conds.append(status.rule_conditions(*args))
    engine.try_numba(True)
    np.testing.assert_array_equal(conds[0], conds[1])
    ST = np.zeros(n, np.int8)
    RS = np.zeros(n, np.int8)
    status.apply_rules(conds[0], ST, RS)
    last = [max(np.flatnonzero(r)) if r.any() else -1 for r in conds[0]]
    assert all((ST[i], RS[i]) == ((status._RULE_STATUS[k], status._RULE_REASON[k]) if k >= 0 else (0, 0))
               for i, k in enumerate(last))


@needs_numba
@pytest.mark.parametrize("value", [None, 0])
def test_engine_twins_refine(value):
    from wingphoto.synth import render_discs
    from wingphoto.track import refine

    rng = np.random.default_rng(5)
    c = np.column_stack([rng.uniform(15, 45, 6), rng.uniform(15, 35, 6)])
    img = render_discs(c, rng.uniform(6, 9, 6), (50, 61), noise_std=2.0, rng=rng).astype(np.uint8)
    if value is not None:
        img[:] = value  # a blank frame: no blob, no crash, no position
    args = (img, np.rint(c[:, 0]), np.rint(c[:, 1]), np.full(6, 6.0), np.ones(6), np.full(6, 2.0), None, None, 2,
            np.full(6, 7.5), 0.2)
    a = refine._refine_core(*args)
    b = refine._refine_core_fast(*args)
    for u, v in zip(a, b):
        np.testing.assert_allclose(np.asarray(u, float), np.asarray(v, float), rtol=1e-5, atol=1e-5, equal_nan=True)


def test_cli_track_bidirectional_flag(tmp_path, monkeypatch):
    # `wingphoto track --bidirectional` reaches track_markers, and a real run on the sample
    # with it writes the table (exit 0)
    from pathlib import Path

    from wingphoto import cli, pipeline

    samples = Path(__file__).resolve().parents[1] / "data-samples" / "flapping"
    args = ["track", "--frames", str(samples / "left"), "--picks", str(samples / "picks.json"),
            "--out", str(tmp_path / "t.csv")]
    seen = {}
    real = pipeline.track_folder

    def spy(frames, picks, **kw):
        seen.update(kw)
        return real(frames, picks, **kw)

    monkeypatch.setattr(pipeline, "track_folder", spy)
    assert cli.main(args) == 0 and seen["bidirectional"] is False
    assert cli.main(args + ["--bidirectional"]) == 0 and seen["bidirectional"] is True
    out = pd.read_csv(tmp_path / "t.csv")
    assert (out["status"] == "ok").mean() > 0.95
