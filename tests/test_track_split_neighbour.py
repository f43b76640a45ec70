"""A marker's pixels are split against the neighbour matched nearest to it, not only the
nearest by prediction (refine.split_neighbour, both engines)."""
import numpy as np
import pytest


@pytest.mark.parametrize("use_numba", [True, False])
def test_the_nearer_matched_of_the_two_nearest_by_prediction(use_numba):
    from wingphoto.track import engine, refine

    XP = np.array([100.0, 110.0, 104.0, np.nan, 300.0])
    YP = np.array([100.0, 100.0, 101.0, np.nan, 300.0])
    # marker 0: nearest by prediction 1 (matched 10 px away), second 2 (matched 4 px away)
    # marker 3: no match of its own -> its nearest by prediction, whatever is matched
    # marker 4: its second-nearest has no match -> the nearest
    j2 = np.array([[1, 2], [2, 0], [0, 1], [0, 2], [1, 3]])
    prev = engine.use_numba()
    engine.try_numba(use_numba)
    try:
        jn = refine.split_neighbour(XP, YP, j2)
    finally:
        engine.try_numba(prev)
    assert jn.tolist() == [2, 2, 0, 0, 1]


def test_engines_agree_on_random_plans():
    from wingphoto.track import refine

    rng = np.random.default_rng(3)
    for _ in range(50):
        n = 12
        XP, YP = rng.uniform(0, 40, n), rng.uniform(0, 40, n)
        XP[rng.random(n) < 0.2] = np.nan
        YP[np.isnan(XP)] = np.nan
        j2 = rng.integers(-1, n, (n, 2))
        out = np.empty(n, np.int64)
        refine.split_neighbour_kernel(XP, YP, j2, out)
        assert out.tolist() == refine.split_neighbour_numpy(XP, YP, j2).tolist()


def test_splitting_against_the_touching_neighbour_fixes_the_centre():
    # why it matters: a blob 5 px away left unsplit pulls the centre by ~1 px at a small sigma
    from scipy import ndimage

    from wingphoto.track.refine import refine_centroids

    yy, xx = np.mgrid[0:41, 0:41].astype(float)
    a, c = np.array([20.2, 20.4]), np.array([25.4, 21.1])
    cover = sum(((xx - p[0]) ** 2 + (yy - p[1]) ** 2 <= 2.6 ** 2).astype(float) for p in (a, c))
    img = (20 + 120 * ndimage.gaussian_filter(cover, 1.0)).astype(np.float32)
    far = np.array([[20.0, 10.0]])  # the nearest by prediction, matched 10 px away
    alone = refine_centroids(img, a[None], 4, neighbours=far)[0]
    split = refine_centroids(img, a[None], 4, neighbours=c[None])[0]
    assert np.linalg.norm(split - a) < 0.25 < np.linalg.norm(alone - a)
