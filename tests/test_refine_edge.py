"""The centroid of a marker near an edge (the membrane's border): its background is the
bright side, not a plane tilted towards the dark side (background.EDGE_ARCS), and sigma
stays honest where that rule fires (refine.EDGE_CUT)."""
import numpy as np
import pytest
from scipy import ndimage

from wingphoto.track import background, engine, refine
from wingphoto.track.refine import refine_centroids

ENGINES = [pytest.param(True, id="numba"), pytest.param(False, id="numpy")]


def _marker(centre, radius=3.2, edge=None, ramp=(0.0, 0.0), seed=0, ss=8):
    """A bright disk (supersampled, blurred, noisy) on a 100-level background; ``edge``
    (y0): rows below y0 are the dark side (40) of a straight edge tilted by 0.3 px/px."""
    H, W = 41, 41
    o = (np.arange(ss) + 0.5) / ss - 0.5
    ys = (np.arange(H)[:, None] + o).ravel()
    xs = (np.arange(W)[:, None] + o).ravel()
    X, Y = np.meshgrid(xs, ys)
    img = 100.0 + ramp[0] * (X - 20) + ramp[1] * (Y - 20)
    if edge is not None:
        img = np.where(Y > edge + 0.3 * (X - 20), 40.0, img)
    img = np.where((X - centre[0]) ** 2 + (Y - centre[1]) ** 2 <= radius ** 2, 230.0, img)
    img = img.reshape(H, ss, W, ss).mean(axis=(1, 3))
    img = ndimage.gaussian_filter(img, 0.7)
    img += np.random.default_rng(seed).normal(0, 1.5, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _refine(img, start, radius, compiled):
    if compiled and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    try:
        engine.try_numba(compiled)
        return refine_centroids(img, [start], radius)[0][0]
    finally:
        engine.try_numba(True)


@pytest.mark.parametrize("compiled", ENGINES)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_marker_beside_an_edge_is_centred_on_its_shape(compiled, seed):
    truth = np.array([20.3, 19.6]) + np.random.default_rng(seed).uniform(-0.3, 0.3, 2)
    img = _marker(truth, edge=truth[1] + 6.5, seed=seed)
    xy = _refine(img, np.rint(truth), 7.0, compiled)
    assert np.hypot(*(xy - truth)) < 0.06


def test_without_the_edge_rule_the_centre_is_pulled_towards_the_edge(monkeypatch):
    """The failure the rule mends (numpy engine: the compiled one reads its constants once)."""
    truth = np.array([20.3, 19.6])
    img = _marker(truth, edge=truth[1] + 6.5)
    monkeypatch.setattr(background, "EDGE_GAIN", 0.0)  # no candidate arc can win
    monkeypatch.setattr(refine, "INNER_BGRES", np.inf)  # (nor the inner disk: test_refine_inner.py)
    xy = _refine(img, np.rint(truth), 7.0, False)
    assert xy[1] - truth[1] > 0.15


@pytest.mark.parametrize("compiled", ENGINES)
def test_a_linear_glare_ramp_is_not_an_edge(compiled, monkeypatch):
    """A plane fits a ramp: the rule leaves its centre as it was."""
    truth = np.array([20.4, 19.7])
    img = _marker(truth, ramp=(2.5, -1.5))
    xy = _refine(img, np.rint(truth), 7.0, compiled)
    monkeypatch.setattr(background, "EDGE_GAIN", 0.0)
    np.testing.assert_allclose(xy, _refine(img, np.rint(truth), 7.0, False), atol=1e-4)
    assert np.hypot(*(xy - truth)) < 0.08


def test_engines_agree_near_an_edge():
    if not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    for seed in range(6):
        truth = np.array([20.0, 20.0]) + np.random.default_rng(seed).uniform(-0.5, 0.5, 2)
        img = _marker(truth, edge=truth[1] + 5.5 + seed * 0.4, seed=seed)
        a = _refine(img, np.rint(truth), 7.0, True)
        b = _refine(img, np.rint(truth), 7.0, False)
        np.testing.assert_allclose(a, b, atol=1e-3)


@pytest.mark.parametrize("u,v", [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1),
                                 (2, 1), (-3, 2), (5, -4)])
def test_octant_matches_the_angle(u, v):
    ang = np.degrees(np.arctan2(v, u)) % 360
    assert background._octant(u, v) == int(ang // 45)


@pytest.mark.parametrize("compiled", ENGINES)
def test_sigma_stays_honest_where_the_edge_rule_fires(compiled):
    """The rule's centre is trusted only as far as the cut term says (refine.EDGE_CUT):
    a lone marker 8 px from an edge, 0.4 px off without the rule, is centred within 0.05
    px at a sigma below max_sigma that covers its error three times."""
    from test_track_sigma_curved import _edge_pair

    from wingphoto.track import refine
    from wingphoto.track.options import TrackOptions
    from wingphoto.track.sigma import sigma_of

    if compiled and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    try:
        engine.try_numba(compiled)
        for seed in range(3):
            img, c = _edge_pair(8.0, 90.0, np.random.default_rng(seed), gap=60)[:2]
            x, y, _, info = refine._refine(img, np.array([c[0] + 0.4]), np.array([c[1] - 0.3]), np.array([7.0]),
                                           np.array([1.0]), np.array([1.0]))
            err = float(np.hypot(x[0] - c[0], y[0] - c[1]))
            sig = float(sigma_of(np.array([1.0]), info, 1.0, np.array([4.0]))[0])
            assert err < 0.05 and err < 3 * sig and sig < TrackOptions().max_sigma
    finally:
        engine.try_numba(True)


def test_engines_agree_on_every_output_where_the_edge_rule_fires():
    """Positions and every diagnostic, dshape (with its cut term) included."""
    from test_track_sigma_curved import _edge_pair

    from wingphoto.track import refine

    if not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    for seed in range(3):
        img, c = _edge_pair(8.0, 90.0, np.random.default_rng(seed), gap=60)[:2]
        args = (img, np.rint([c[0]]), np.rint([c[1]]), np.array([7.0]), np.ones(1), np.ones(1), None, None, 2,
                np.array([7.5]), 0.2)
        for u, v in zip(refine._refine_core(*args), refine._refine_core_fast(*args)):
            np.testing.assert_allclose(np.asarray(u, float), np.asarray(v, float), rtol=1e-5, atol=1e-5,
                                       equal_nan=True)
