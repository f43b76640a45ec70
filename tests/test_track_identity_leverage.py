"""One gross outlier among few anchors of an affine map (:func:`geometry._robust_affine`).

A runaway anchor (a flagged marker followed onto a far blob) pulls a least-squares affine
fit of five or six neighbours so that every residual is large and the median threshold
rejects none; the map then put a re-acquired marker 33 px off (independent renderer, black
DEV seed 18 left). Leaving each point out in turn (:func:`geometry._one_out`) finds it."""
import numpy as np

from wingphoto.track.geometry import _apply_affine, _neighbour_prediction, _one_out, _robust_affine

M_TRUE = np.array([[0.9, -0.3, 12.0], [0.25, 1.1, -40.0]])


def _anchors(n=6, bad=0, off=(60.0, -78.0), seed=0):
    rng = np.random.default_rng(seed)
    src = rng.uniform(100, 200, (n, 2))
    dst = _apply_affine(M_TRUE, src) + rng.normal(0, 0.1, (n, 2))
    dst[bad] += off
    return src, dst


def test_one_runaway_anchor_is_left_out():
    src, dst = _anchors(bad=0)
    assert _one_out(src, dst, 2.0) == 0
    M, rms, nin = _robust_affine(src, dst, quality=True, one_out=True)
    assert nin == 5 and rms < 0.3
    p0 = np.array([150.0, 150.0])
    q = _neighbour_prediction(p0, src, dst)
    assert q is not None and np.hypot(*(q[0] - _apply_affine(M_TRUE, p0[None])[0])) < 1.0


def test_good_anchors_and_too_few_are_kept():
    src, dst = _anchors(off=(0.0, 0.0))
    assert _one_out(src, dst, 2.0) == -1  # (nothing to leave out)
    src, dst = _anchors(n=4, bad=1)
    assert _one_out(src, dst, 2.0) == -1  # (four: the other three always fit)


def test_two_runaways_are_not_hidden():
    src, dst = _anchors(bad=0)
    dst[3] += (-40.0, 55.0)
    assert _one_out(src, dst, 2.0) == -1
