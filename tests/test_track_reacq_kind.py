"""Re-acquisition judged by neighbours of the marker's kind (``wingphoto.track.reacquire``)."""
import numpy as np

from wingphoto import track_markers
from wingphoto.track import engine

#: A wing marker M (0), two static dots beside it (1, 2), and five wing markers (3-7) on a
#: row beyond M's neighbourhood, all the wing moving by (1.5, 0.3) px a frame.
_M0 = np.array([60.0, 80.3])
_DOTS = np.array([[44.6, 64.2], [45.3, 97.8]])
_ROW = np.array([[150.2, 74.6], [165.7, 75.4], [180.4, 74.8], [158.1, 87.3], [173.3, 86.6]])
_V = np.array([1.5, 0.3])
_HIDDEN = range(8, 18)  # frames on which M is not in the image


def _disc_frames(n=32, shape=(150, 260), seed=0):
    """Frames of Gaussian-edged discs (radius 4 px) on a flat background; truth (n, 8, 2)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    truth = np.empty((n, 8, 2))
    frames = np.empty((n,) + shape, np.uint8)
    for t in range(n):
        pts = np.vstack([_M0 + t * _V, _DOTS, _ROW + t * _V])
        truth[t] = pts
        img = np.full(shape, 40.0)
        for k, (x, y) in enumerate(pts):
            if k == 0 and t in _HIDDEN:
                continue
            r = np.hypot(xx - x, yy - y)
            img += 150.0 / (1.0 + np.exp((r - 4.0) / 0.6))
        frames[t] = np.clip(img + rng.normal(0, 2.0, shape), 0, 255).astype(np.uint8)
    return frames, truth


def _track(frames, truth):
    tr = track_markers(frames, truth[0], progress=False)
    st = tr.pivot(index="frame", columns="point", values="status").to_numpy()
    rs = tr.pivot(index="frame", columns="point", values="reason").to_numpy()
    x = tr.pivot(index="frame", columns="point", values="x").to_numpy()
    y = tr.pivot(index="frame", columns="point", values="y").to_numpy()
    return st, rs, np.hypot(x - truth[..., 0], y - truth[..., 1])


def test_wing_marker_is_not_judged_by_the_static_dots():
    # M's last ok frame (7) had only the static dots near it, ok then and now; its wing
    # neighbours are far (beyond its neighbourhood) and predict it by their affine map
    # from the reference frame. Judged by the static dots, which say M should not have
    # moved (15 px), the right blob was refused for the rest of the sequence; judged by
    # its kind only, M comes back flagged 'reacquired', then ok, on its own blob.
    frames, truth = _disc_frames()
    st, rs, err = _track(frames, truth)
    m = st[:, 0]
    assert (m[max(_HIDDEN) + 1:] != "lost").any(), "M never re-acquired"
    back = max(_HIDDEN) + 1 + int(np.flatnonzero(m[max(_HIDDEN) + 1:] != "lost")[0])
    assert m[back] == "flagged" and rs[back, 0] == "reacquired"
    assert back <= max(_HIDDEN) + 3  # within two frames of its return
    assert (m[back + 1:] == "ok").sum() >= 8
    # and nowhere a confident error, M or the others
    assert not ((st == "ok") & (err > 1.0)).any()
    assert np.nanmax(err[st == "ok"]) < 0.5


def test_wing_marker_reacquired_alike_in_both_engines():
    frames, truth = _disc_frames(n=24)
    engine.try_numba(False)
    try:
        st0, rs0, e0 = _track(frames, truth)
    finally:
        engine.try_numba(True)
    st1, rs1, e1 = _track(frames, truth)
    np.testing.assert_array_equal(st0, st1)
    np.testing.assert_array_equal(rs0.astype(str), rs1.astype(str))
    np.testing.assert_allclose(e0, e1, atol=1e-6, equal_nan=True)
