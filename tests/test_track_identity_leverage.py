"""One gross outlier among few anchors of an affine map (:func:`geometry._robust_affine`).

A runaway anchor (a flagged marker followed onto a far blob) pulls a least-squares affine
fit of five or six neighbours so that every residual is large and the median threshold
rejects none; the map then put a re-acquired marker 33 px off (independent renderer, black
DEV seed 18 left). Leaving each point out in turn (:func:`geometry._one_out`) finds it."""
import numpy as np

from wingphoto.track.geometry import (MAX_POINT_LEVERAGE, _apply_affine, _max_leverage, _neighbour_prediction,
                                       _one_out, _robust_affine)

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


def test_a_dot_alone_on_its_row_does_not_steer_the_map():
    # real dots, dropped, DEV seed 610 cam1, frame 1 (no velocity yet): the six anchors of a
    # wide-searched dot lie on two rows of the grid, four on one and two on the dot's own;
    # one of those two, leaving the view, matched its row neighbour's blob (+19.5, +2.8 px
    # against about (-0.5, -11) for the rest). Leaving out the right one of the two made
    # the other a dot alone on its row, fitted exactly (0.19 px): the map sent two dots
    # along their row onto their neighbours' blobs, ok 25-50 px off. A map resting on one
    # unchecked point (geometry._max_leverage) is not trusted; the group that moved alike is.
    # (the anchors' positions on the picks' frame, and their wide-search matches, whole pixels)
    src = np.array([[239.302, 52.335], [176.458, 10.236], [177.196, 78.363], [197.958, 92.276], [156.354, 64.442],
                    [135.706, 50.700]])
    dst = np.array([[238.0, 40.0], [196.0, 13.0], [177.0, 68.0], [198.0, 81.0], [156.0, 54.0], [135.0, 41.0]])
    p0 = np.array([218.331, 38.432])
    assert _max_leverage(np.delete(src, 0, axis=0)) > MAX_POINT_LEVERAGE  # (the left-out fit)
    q = _neighbour_prediction(p0, src, dst)
    assert q is not None
    assert np.hypot(*(q[0] - (p0 + [-1.4, -12.2]))) < 3.0, q  # (the truth; the old map: 25 px off)


def test_leverage_of_points_off_a_line():
    line = np.column_stack([np.linspace(0, 30, 4), np.linspace(0, 20, 4)])
    assert _max_leverage(np.vstack([line, [[5.0, 40.0]]])) > 0.999  # alone off the line
    rng = np.random.default_rng(3)
    assert _max_leverage(rng.uniform(0, 100, (12, 2))) < 0.6  # spread: each checked by the others
