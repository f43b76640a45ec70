"""A group of markers lost all at once is found again by its constellation (issue 8,
``wingphoto/track/relocate.py``).

A rendered disc sequence: a "wing" of 12 discs turns about a hinge while three static dots
stand still; for 9 frames the wing's discs are gone (edge-on at a stroke reversal), then
they come back turned further and foreshortened. Without the group re-acquisition no wing
marker is ever ok again (no ok neighbour of its kind is left to predict it from); with it
they are, each on its own disc.
"""
import numpy as np
import pytest

from wingphoto.synth.raster import render_discs
from wingphoto.track import engine, relocate, track_markers
from wingphoto.track.relocate import fit_constellation

SHAPE = (230, 261)  # non-square: catches x/y swaps
HINGE = np.array([60.0, 120.0])
GONE = range(8, 17)  # the wing's discs are invisible on these frames
N_FRAMES = 34


def _wing(rng, n=12):
    """An irregular constellation of n disc centres (>= 17 px apart) right of the hinge."""
    pts = []
    while len(pts) < n:
        p = HINGE + rng.uniform([30, -60], [170, 60])
        if all(np.hypot(*(p - q)) >= 17 for q in pts):
            pts.append(p)
    return np.array(pts)


def _scene(seed=3):
    """Frames (uint8), picks (frame-0 positions) and the true positions (T, N, 2)."""
    rng = np.random.default_rng(seed)
    wing0 = _wing(rng)
    static = np.array([[20.0, 20.0], [240.0, 25.0], [230.0, 210.0]])
    truth = np.full((N_FRAMES, len(wing0) + len(static), 2), np.nan)
    frames = []
    for t in range(N_FRAMES):
        # the stroke: 1 deg a frame, +14 deg more across the gap, and foreshortened along
        # the span once back (the wing pitched)
        ang = np.deg2rad(t + (14 if t >= GONE.stop else 0))
        c, s = np.cos(ang), np.sin(ang)
        R = np.array([[c, -s], [s, c]])
        squash = np.diag([0.9, 1.0]) if t >= GONE.stop else np.eye(2)
        w = (wing0 - HINGE) @ (R @ squash).T + HINGE
        truth[t, : len(wing0)] = w
        truth[t, len(wing0):] = static
        vis = np.concatenate([np.full(len(wing0), t not in GONE), np.ones(len(static), bool)])
        cen = np.where(vis[:, None], truth[t], np.nan)
        frames.append(render_discs(cen, np.full(len(cen), 7.0), SHAPE, noise_std=2.0,
                                   rng=np.random.default_rng(100 + t)))
    return np.array(frames), truth[0].copy(), truth, len(wing0)


@pytest.fixture(scope="module")
def scene():
    return _scene()


def _errors(tr, truth):
    """(T, N) error (px) of every ok point-frame, NaN elsewhere."""
    T, N = truth.shape[:2]
    err = np.full((T, N), np.nan)
    ok = tr[tr["status"] == "ok"]
    f, p = ok["frame"].to_numpy(int), ok["point"].to_numpy(int)
    err[f, p] = np.hypot(ok["x"].to_numpy() - truth[f, p, 0], ok["y"].to_numpy() - truth[f, p, 1])
    return err


@pytest.mark.parametrize("numba", [True, False])
def test_group_lost_at_once_comes_back(scene, numba):
    if numba and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    frames, picks, truth, n_wing = scene
    before = engine.use_numba()
    engine.try_numba(numba)
    try:
        tr = track_markers(frames, picks, progress=False)
    finally:
        engine.try_numba(before)
    err = _errors(tr, truth)
    back = slice(GONE.stop + 3, N_FRAMES)
    # every wing marker is ok again on its own disc ...
    assert np.isfinite(err[back, :n_wing]).mean() >= 0.9
    # ... and no ok point anywhere is on the wrong disc or off by more than a pixel
    assert np.nanmax(err) < 0.5
    # the markers came back flagged 'reacquired' first
    first = tr[(tr["frame"] >= GONE.stop) & (tr["point"] < n_wing) & (tr["reason"] == "reacquired")]
    assert first["point"].nunique() >= 0.9 * n_wing


def test_without_the_group_search_the_wing_stays_lost(scene, monkeypatch):
    """The same sequence without the group search: nothing brings the wing back."""
    frames, picks, truth, n_wing = scene
    monkeypatch.setattr(relocate, "MIN_GROUP", 10**6)
    tr = track_markers(frames, picks, progress=False)
    err = _errors(tr, truth)
    assert not np.isfinite(err[GONE.stop:, :n_wing]).any()


def test_fit_finds_identities_among_clutter():
    """Reference constellation turned, scaled, foreshortened, with candidates missing and
    clutter added: every found marker gets its own candidate."""
    rng = np.random.default_rng(7)
    ref = _wing(rng, 15)
    A = np.array([[0.8, -0.45], [0.5, 0.95]])
    now = ref @ A.T + [40.0, -25.0] + rng.normal(0, 0.3, ref.shape)
    keep = np.ones(len(ref), bool)
    keep[[2, 9]] = False  # two markers not found as candidates
    clutter = rng.uniform([0, 0], [300, 300], (12, 2))
    cand = np.concatenate([now[keep], clutter])
    perm = rng.permutation(len(cand))
    cand = cand[perm]
    fit = fit_constellation(ref, cand)
    a = fit["assign"]
    hit = a >= 0
    assert hit.sum() >= 13
    assert np.hypot(*(cand[a[hit]] - now[hit]).T).max() < 1.5
    assert fit["second"] <= relocate.MARGIN * fit["inliers"]


def test_fit_refuses_too_few_candidates():
    ref = _wing(np.random.default_rng(1), 8)
    assert fit_constellation(ref, ref[:2]) is None


def test_fit_of_a_regular_grid_is_ambiguous():
    """A regular grid fits its candidates shifted by one pitch nearly as well as right:
    the margin test must see the second fit (a wrong re-acquisition is worse than none)."""
    g = np.stack(np.meshgrid(np.arange(4) * 20.0, np.arange(4) * 20.0), -1).reshape(-1, 2) + 50
    cand = g + [3.0, -2.0] + np.random.default_rng(2).normal(0, 0.2, g.shape)
    fit = fit_constellation(g, cand)
    assert fit["inliers"] == 16
    assert fit["second"] > relocate.MARGIN * fit["inliers"]


def test_search_backs_off_the_longer_a_group_is_lost():
    from wingphoto.track.relocate import MAX_BACKOFF, RETRY, RETRY_SPAN, _due

    def searched(lost_for):
        return sum(_due(t, lost_for) for t in range(64))

    assert searched(0) == 64 // RETRY  # just lost: every RETRY-th frame
    assert searched(RETRY_SPAN) == 64 // (2 * RETRY)
    assert searched(10_000) == 64 // (RETRY * MAX_BACKOFF)
    assert all(searched(a) >= searched(b) for a, b in zip(range(0, 200, 7), range(7, 207, 7)))
