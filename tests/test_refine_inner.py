"""The inner disk (refine.INNER_BGRES): a marker a few px from the wing's edge, whose full
disk's ring crosses that edge, is measured again with a disk 1.5 px smaller.

Independent renderer, clean DEV seed 2 left, marker 22 at frame 0: a 3.2 px blob about 5 px
from the trailing edge; with the tracker's disk (its blob radius + 3 px) the centre was 1.1
px off and the point flagged imprecise on every frame it was face-on."""
import numpy as np
import pytest

from wingphoto.track import engine, refine
from wingphoto.track.refine import refine_centroids

ENGINES = [pytest.param(True, id="numba"), pytest.param(False, id="numpy")]


@pytest.fixture(scope="module")
def edge_marker():
    from wingphoto.synth.independent import render_independent

    seq = render_independent("clean", seed=2, camera="left", n_frames=2)
    P = seq.points[0]
    d = np.hypot(*(P - P[22]).T)
    d[22] = np.inf
    return seq, P[22], P[np.nanargmin(d)]


def _centre(img, truth, nb, compiled):
    if compiled and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    was = engine.use_numba()
    try:
        engine.try_numba(compiled)
        return refine_centroids(img, [np.rint(truth)], 6.2, neighbours=[nb])[0][0]
    finally:
        engine.try_numba(was)


@pytest.mark.parametrize("compiled", ENGINES)
def test_a_marker_beside_the_wings_edge_is_centred(edge_marker, compiled):
    seq, truth, nb = edge_marker
    assert np.hypot(*(_centre(seq.images[0], truth, nb, compiled) - truth)) < 0.45


def test_without_the_inner_disk_the_edge_pulls_it(edge_marker, monkeypatch):
    seq, truth, nb = edge_marker
    monkeypatch.setattr(refine, "INNER_BGRES", np.inf)  # (the numpy engine reads it at call time)
    assert np.hypot(*(_centre(seq.images[0], truth, nb, False) - truth)) > 0.8


def test_engines_agree_and_the_marker_is_ok(edge_marker):
    # the tracker's compiled refinement (_refine_all_kernel, with the fast frame) and its
    # numpy twin (_refine) take the inner disk alike
    from wingphoto import track_markers

    seq = edge_marker[0]
    out = []
    for compiled in (True, False):
        if compiled and not engine.NUMBA_AVAILABLE:
            continue
        was = engine.use_numba()
        try:
            engine.try_numba(compiled)
            out.append(track_markers(seq.frames(), seq.picks(), camera="left", progress=False))
        finally:
            engine.try_numba(was)
    for a in out[1:]:
        np.testing.assert_allclose(a[["x", "y", "sigma"]].to_numpy(float), out[0][["x", "y", "sigma"]].to_numpy(float),
                                   atol=1e-4)
        assert (a.status == out[0].status).all()
    t = out[0][out[0].point == 22]
    err = np.hypot(t.x.to_numpy() - seq.points[:, 22, 0], t.y.to_numpy() - seq.points[:, 22, 1])
    assert (t.status == "ok").all() and (err < 0.2).all(), (t.status.tolist(), err)
