"""No path makes a point ok whose sigma exceeds ``max_sigma``.

The status rules flag such a point ``imprecise``; the rules after them (a jump the
neighbours vouch for, a marker that stayed on its own blob) and the pick frame must not
make it ok again. Discs in noise (sigma ~0.05-0.1 px) with ``max_sigma=0.05`` put many
points on either side of the limit; the discs move at 5 px/frame and stop dead on frame
12 (jumps for the neighbours to vouch for).
"""
import numpy as np
import pytest

from test_track import errors, render_discs
from wingphoto.track import engine, track_markers


def _stopping_discs(seed, T=40, noise_std=6.0):
    gx, gy = np.meshgrid(np.linspace(30, 100, 4), np.linspace(45, 105, 2))
    base = np.column_stack([gx.ravel(), gy.ravel()])
    t = np.arange(T)
    truth = np.empty((T, len(base), 2))
    truth[..., 0] = base[:, 0] + np.where(t < 12, 5.0 * t, 60.0)[:, None]
    truth[..., 1] = base[:, 1] + 0.3 * t[:, None]
    rng = np.random.default_rng(seed)
    d = np.full(len(base), 6.0)
    frames = np.stack([render_discs(truth[k], d, (160, 200), noise_std=noise_std, rng=rng, dtype=np.uint8)
                       for k in range(T)])
    return frames, truth


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("seed", [2, 7])
def test_no_ok_point_is_imprecise(seed, compiled):
    if compiled and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    frames, truth = _stopping_discs(seed)
    try:
        engine.try_numba(compiled)
        tr = track_markers(frames, np.rint(truth[0]), progress=False, max_sigma=0.05)
    finally:
        engine.try_numba(True)
    err, status = errors(tr, truth)
    sig = tr["sigma"].to_numpy().reshape(status.shape)
    ok = status == "ok"
    assert ok.sum() > 20  # not vacuous: some points are precise enough
    imp = tr["reason"].to_numpy().reshape(status.shape) == "imprecise"
    assert imp.sum() > 20  # and many are not
    bad = np.argwhere(ok & ~(sig <= 0.05))
    assert bad.size == 0, f"ok points with sigma > max_sigma (frame, point): {bad.tolist()}"


def test_imprecise_pick_is_flagged_with_its_position_kept():
    frames, truth = _stopping_discs(0, T=6, noise_std=10.0)
    tr = track_markers(frames, np.rint(truth[0]), progress=False, max_sigma=0.05)
    ref = track_markers(frames, np.rint(truth[0]), progress=False)
    p0 = tr[tr.frame == 0]
    vague = (p0["sigma"] > 0.05).to_numpy()
    assert vague.any()
    assert (p0["status"][vague] == "flagged").all() and (p0["reason"][vague] == "imprecise").all()
    # the position is the refined pick's, as with a looser max_sigma
    r0 = ref[ref.frame == 0]
    np.testing.assert_array_equal(p0[["x", "y"]].to_numpy(), r0[["x", "y"]].to_numpy())
