"""The dark side of the membrane's edge left out of a marker's background (background.EDGE_ARCS),
with sigma kept honest by the centre's move between two cuts (refine.EDGE_CUT)."""
import numpy as np
import pytest

from test_track_sigma_curved import _edge_pair


@pytest.fixture
def edge_marker():
    """A lone marker 8 px from the membrane's edge (no neighbour in reach)."""
    return [_edge_pair(8.0, 90.0, np.random.default_rng(seed), gap=60)[:2] for seed in range(3)]


def _centre(img, c):
    from wingphoto.track import refine
    from wingphoto.track.sigma import sigma_of

    x, y, _, info = refine._refine(img, np.array([c[0] + 0.4]), np.array([c[1] - 0.3]), np.array([7.0]),
                                   np.array([1.0]), np.array([1.0]))
    err = float(np.hypot(x[0] - c[0], y[0] - c[1]))
    return err, float(sigma_of(np.array([1.0]), info, 1.0, np.array([4.0]))[0])


@pytest.mark.parametrize("use_numba", [True, False])
def test_the_edge_rule_centres_a_marker_beside_the_edge(edge_marker, use_numba, monkeypatch):
    # The full plane tilts towards the dark side and puts the centre ~0.4 px towards the
    # edge (flagged by its sigma); the edge rule finds the background and the centre, and
    # sigma stays honest
    from wingphoto.track import background, engine
    from wingphoto.track.options import TrackOptions

    if use_numba and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    was = engine.use_numba()
    engine.try_numba(use_numba)
    try:
        for img, c in edge_marker:
            err, sig = _centre(img, c)
            assert err < 0.05 and err < 3 * sig and sig < TrackOptions().max_sigma
        if not use_numba:
            # without the rule (the numpy engine reads EDGE_GAIN at call time)
            monkeypatch.setattr(background, "EDGE_GAIN", 0.0)
            for img, c in edge_marker:
                err, sig = _centre(img, c)
                assert err > 0.3
    finally:
        engine.try_numba(was)


def test_engines_agree_where_the_edge_rule_fires(edge_marker):
    from wingphoto.track import engine, refine

    if not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    for img, c in edge_marker:
        args = (img, np.rint([c[0]]), np.rint([c[1]]), np.array([7.0]), np.ones(1), np.ones(1), None, None, 2,
                np.array([7.5]), 0.2)
        for u, v in zip(refine._refine_core(*args), refine._refine_core_fast(*args)):
            np.testing.assert_allclose(np.asarray(u, float), np.asarray(v, float), rtol=1e-5, atol=1e-5,
                                       equal_nan=True)
