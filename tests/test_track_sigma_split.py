"""sigma's split term: two blobs whose blurred edges run into each other."""
import numpy as np
import pytest
from scipy import ndimage


def _pair(dist, rng, r1=3.0, r2=4.2, blur=1.3):
    """A 41 x 61 image of two anti-aliased, blurred discs (radii r1 < r2) ``dist`` px apart
    on a row, contrast 100 on 20, noise 1; returns the image and the two true centres."""
    H, W = 41, 61
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    c1 = np.array([26.3 - dist / 2, 20.4])
    c2 = c1 + [dist, 0.0]
    cover = np.zeros((H, W))
    sub = (np.arange(6) + 0.5) / 6 - 0.5
    for c, r in ((c1, r1), (c2, r2)):
        for a in sub:
            for b in sub:
                cover += ((xx + a - c[0]) ** 2 + (yy + b - c[1]) ** 2 <= r * r) / sub.size ** 2
    img = 20 + 100 * ndimage.gaussian_filter(np.minimum(cover, 1.0), blur) + rng.normal(0, 1.0, (H, W))
    return img.astype(np.float32), np.array([c1, c2])


@pytest.mark.parametrize("use_numba", [True, False])
def test_sigma_says_when_a_neighbour_splits_the_blob(use_numba):
    # The mechanism of the dangerous tail on the independent renders (ok points 0.5-1 px
    # off at 3-5 sigma, all on pairs 7-12 px apart, every error along the line joining
    # them): the pixel split between two blobs whose blurred edges meet puts part of the
    # larger blob's edge on the smaller one, which moves towards its neighbour - with a
    # small noise sigma. The split term (the gap's brightness, ``valley``) must make that
    # point imprecise and its sigma honest, and vanish for a pair with a dark gap.
    from wingphoto.track import engine, refine
    from wingphoto.track.options import TrackOptions
    from wingphoto.track.sigma import point_sigma, sigma_numpy

    if use_numba and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    rb = np.array([3.0, 4.2])
    rd = rb + 3.0
    was = engine.use_numba()
    engine.try_numba(use_numba)
    try:
        out = {}
        for dist in (8.5, 16.0):
            img, xy = _pair(dist, np.random.default_rng(5))
            x, y, m, inf = refine._refine(img, np.rint(xy[:, 0]), np.rint(xy[:, 1]), rd, np.ones(2), np.ones(2),
                                          xy[::-1].copy(), 2, rmax=rd, nbr_r=rd[::-1] + 0.5)
            err = np.hypot(x - xy[:, 0], y - xy[:, 1])
            terms = [np.ones(2), inf["spread"], inf["bgres"], inf["peak"], 1.0, rb, inf["dshape"], inf["rim"],
                     inf["tex"]]
            sig = sigma_numpy(*terms, inf["valley"])
            no_split = sigma_numpy(*terms, np.full(2, np.nan))
            for i in range(2):
                one = [t if np.isscalar(t) else t[i] for t in terms]
                assert point_sigma(*one, inf["valley"][i]) == pytest.approx(sig[i], rel=1e-9)
            out[dist] = (err, sig, no_split, inf["valley"], x - xy[:, 0])
    finally:
        engine.try_numba(was)
    max_sigma = TrackOptions().max_sigma
    err, sig, no_split, valley, ex = out[8.5]
    assert err[0] > 0.3 and ex[0] > 0.3, out  # the small blob moves towards its neighbour ...
    assert err[0] > 3 * no_split[0], out  # ... far beyond the other terms of sigma
    assert valley[0] > 0.4, out
    assert sig[0] > max_sigma and err[0] < 3 * sig[0], out  # imprecise, and honest
    err, sig, no_split, valley, ex = out[16.0]
    assert err.max() < 0.05 and np.all(valley < 0.1), out  # a dark gap: no split term
    np.testing.assert_allclose(sig, no_split, rtol=1e-12)
