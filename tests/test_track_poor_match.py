"""The poor-match margin (``Tracker._poor_match``): a match that fell to a poor score is
reported ok only with a margin on sigma, in every engine; the tracker itself still takes
the point as ok."""
from types import SimpleNamespace

import numpy as np
import pytest

from wingphoto.track import engine, track_markers
from wingphoto.track.options import TrackOptions
from wingphoto.track.tracker import Tracker


def _me(score_ref, max_sigma=0.25):
    return SimpleNamespace(score_ref=np.asarray(score_ref, float), p=TrackOptions(max_sigma=max_sigma))


def test_a_fall_to_a_poor_score_is_held_but_a_chronically_poor_match_is_not():
    me = _me([0.95, 0.95, 0.95, 0.77, 0.95, 0.95])
    S = np.array([0.80, 0.80, 0.90, 0.76, np.nan, 0.80])
    sigma = np.array([0.22, 0.19, 0.22, 0.22, 0.22, np.nan])
    # held: a fall to 0.80 at sigma 0.22 (> 0.8 x 0.25); not: sigma within the margin, a
    # good score, a marker whose score was always poor (blur), no score, no sigma
    np.testing.assert_array_equal(Tracker._poor_match(me, S, sigma), [True, False, False, False, False, False])
    # the margin follows max_sigma
    np.testing.assert_array_equal(Tracker._poor_match(_me([0.95], 0.5), np.array([0.8]), np.array([0.22])), [False])


@pytest.fixture(scope="module")
def merging_pair():
    """Independent renderer, DEV seed 43 (clean, right camera): on frame 66 marker 22 runs
    into its neighbour's blob, matches at 0.79 (its running score ~0.9) and its centre is
    pulled 2.3 px at sigma 0.22 - reported ok by the tracker before the margin."""
    from wingphoto.synth.independent import render_independent

    return render_independent("clean", seed=43, camera="right", n_frames=70)


@pytest.mark.parametrize("numba", [True, False])
def test_the_merging_pair_is_reported_imprecise_in_both_engines(merging_pair, numba):
    if numba and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    seq = merging_pair
    runs = []
    try:
        engine.try_numba(numba)
        for fast in ((True, False) if numba else (False,)):
            engine.try_fast_frames(fast)
            runs.append(track_markers(seq.frames(), seq.picks(), camera="right", progress=False))
    finally:
        engine.try_numba(True)
        engine.try_fast_frames(True)
    for tr in runs:
        r = tr.set_index(["frame", "point"]).loc[(66, 22)]
        assert np.hypot(r.x - seq.points[66, 22, 0], r.y - seq.points[66, 22, 1]) > 1.0  # the case it is for
        # (since session 25 the frame before is flagged imprecise by the low-cut term of
        # sigma and not fed; the match falls to 0.72 here and the merge rule, earlier in
        # the rule order, flags it first; the margin's own logic is the test above)
        assert r.status == "flagged" and r.reason in ("imprecise", "merged")
        assert 0.2 < r.sigma <= 0.25 and r.score < 0.85
        ok = tr[tr.status == "ok"]
        err = np.hypot(ok.x - seq.points[ok.frame, ok.point, 0], ok.y - seq.points[ok.frame, ok.point, 1])
        assert err.max() < 1.0
    if len(runs) == 2:
        assert runs[0][["status", "reason"]].equals(runs[1][["status", "reason"]])


@pytest.mark.parametrize("compiled", [True, False])
def test_peak_analysis_of_no_maps(compiled):
    """No map to analyse (no wide-searched marker near its last place): empty results from
    both engines (the numpy twin's cv2.dilate raised on 0 maps: independent clean DEV seed 2
    left crashed without numba)."""
    from wingphoto.track import engine
    from wingphoto.track.match import _analyse_maps
    if compiled and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    try:
        engine.try_numba(compiled)
        out = _analyse_maps(np.zeros((0, 9, 9), np.float32), np.zeros((0, 2), np.int64), np.zeros(0),
                            [np.zeros((0, 2))])
    finally:
        engine.try_numba(True)
    assert [len(a) for a in out] == [0] * 5
