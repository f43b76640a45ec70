"""Re-acquisition of lost markers on small disc sequences (``wingphoto.track.reacquire``).

Discs (radius 4 px, Gaussian edge) on a flat background: wing markers move by (1.5, 0.3) px
a frame, static dots stay; some markers are not drawn on frames 8-17 (lost after
``max_coast``) and come back on frame 18. A row of five wing markers far from them (beyond
their neighbourhood) predicts them by its affine map from the reference frame.
"""
import numpy as np

from wingphoto import track_markers
from wingphoto.track import engine

_ROW = np.array([[150.2, 74.6], [165.7, 75.4], [180.4, 74.8], [158.1, 87.3], [173.3, 86.6]])
_V = np.array([1.5, 0.3])
_HIDDEN = range(8, 18)
_BACK = max(_HIDDEN) + 1


def _disc_frames(wing, dots, hidden, n=32, shape=(150, 260), seed=0):
    """uint8 frames and truth (n, K, 2): wing markers ``wing`` (moving, then the row),
    static ``dots``; markers ``hidden`` (indices) not drawn on frames :data:`_HIDDEN`."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    wing = np.vstack([wing, _ROW])
    k = len(wing) + len(dots)
    truth = np.empty((n, k, 2))
    frames = np.empty((n,) + shape, np.uint8)
    for t in range(n):
        pts = np.vstack([wing + t * _V, dots]) if len(dots) else wing + t * _V
        truth[t] = pts
        img = np.full(shape, 40.0)
        for j, (x, y) in enumerate(pts):
            if j in hidden and t in _HIDDEN:
                continue
            img += 150.0 / (1.0 + np.exp((np.hypot(xx - x, yy - y) - 4.0) / 0.6))
        frames[t] = np.clip(img + rng.normal(0, 2.0, shape), 0, 255).astype(np.uint8)
    return frames, truth


def _track(frames, truth):
    tr = track_markers(frames, truth[0], progress=False)
    piv = {c: tr.pivot(index="frame", columns="point", values=c).to_numpy() for c in ("status", "reason", "x", "y")}
    return piv["status"], piv["reason"], np.hypot(piv["x"] - truth[..., 0], piv["y"] - truth[..., 1])


def _comes_back(st, rs, i):
    """Marker ``i`` is flagged ``reacquired`` on the frame it is back, then ok."""
    assert st[_BACK, i] == "flagged" and rs[_BACK, i] == "reacquired", (st[_BACK:, i], rs[_BACK:, i])
    assert (st[_BACK + 1:, i] == "ok").sum() >= 8


def test_wing_marker_is_not_judged_by_the_static_dots():
    # M (0)'s last ok frame (7) had only the two static dots near it, ok then and now.
    # Judged by them (they say M should not have moved: 15 px), its own blob was refused
    # for the rest of the sequence; judged by the wing only, M comes back at once.
    frames, truth = _disc_frames([[60.0, 80.3]], np.array([[44.6, 64.2], [45.3, 97.8]]), {0})
    st, rs, err = _track(frames, truth)
    _comes_back(st, rs, 0)
    assert not ((st == "ok") & (err > 1.0)).any()
    assert np.nanmax(err[st == "ok"]) < 0.5


def test_two_lost_neighbours_come_back_together():
    # two wing markers 9.5 px apart, lost together: each one's refinement saw the other's
    # blob as foreign (it had no position yet), and both stayed lost to the end
    frames, truth = _disc_frames([[60.0, 80.3], [67.6, 86.0]], np.zeros((0, 2)), {0, 1})
    st, rs, err = _track(frames, truth)
    _comes_back(st, rs, 0)
    _comes_back(st, rs, 1)
    assert not ((st == "ok") & (err > 1.0)).any()


def test_reacquired_alike_in_both_engines():
    frames, truth = _disc_frames([[60.0, 80.3]], np.array([[44.6, 64.2], [45.3, 97.8]]), {0}, n=24)
    engine.try_numba(False)
    try:
        st0, rs0, e0 = _track(frames, truth)
    finally:
        engine.try_numba(True)
    st1, rs1, e1 = _track(frames, truth)
    np.testing.assert_array_equal(st0, st1)
    np.testing.assert_array_equal(rs0.astype(str), rs1.astype(str))
    np.testing.assert_allclose(e0, e1, atol=1e-6, equal_nan=True)
