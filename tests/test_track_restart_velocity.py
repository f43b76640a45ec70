"""Restart velocity of a re-acquired marker (``wingphoto.track.reacquire._restart_velocity``)."""
from types import SimpleNamespace

import numpy as np

from wingphoto.track.reacquire import _restart_velocity
from wingphoto.track.status import _R, FLAGGED, LOST, OK


def _result(T, N):
    return SimpleNamespace(x=np.full((T, N), np.nan), y=np.full((T, N), np.nan),
                           status=np.full((T, N), LOST, np.int8), reason=np.zeros((T, N), np.int8))


def test_neighbours_re_acquired_on_the_previous_frame_give_their_motion():
    # hard extra DEV seed 3 left, marker 21: its neighbours came back (flagged ``reacquired``)
    # on frame 40, it on 41 - no neighbour was certain on 40, and the marker restarted with a
    # zero velocity on a wing moving ~5 px/frame (slipped to a neighbour's blob on 42)
    res = _result(3, 4)
    prev = np.array([[100.0, 50.0], [120.0, 50.0], [110.0, 70.0], [0.0, 0.0]])
    res.x[1], res.y[1] = prev[:, 0], prev[:, 1]
    res.status[1] = FLAGGED
    res.reason[1] = _R["reacquired"]
    move = np.array([3.5, 5.0])
    X, Y = prev[:, 0] + move[0], prev[:, 1] + move[1]
    X[3] = Y[3] = np.nan  # the lost marker itself
    np.testing.assert_allclose(_restart_velocity(np.array([0, 1, 2]), X, Y, res, 1), move)


def test_certain_neighbours_are_preferred():
    res = _result(3, 3)
    res.x[1], res.y[1] = (100.0, 120.0, 0.0), (50.0, 50.0, 0.0)
    res.status[1] = (OK, FLAGGED, LOST)
    res.reason[1] = (0, _R["reacquired"], 0)
    X, Y = np.array([104.0, 150.0, np.nan]), np.array([53.0, 80.0, np.nan])
    np.testing.assert_allclose(_restart_velocity(np.array([0, 1]), X, Y, res, 1), (4.0, 3.0))


def test_no_neighbour_known_on_both_frames_gives_no_velocity():
    # not a made-up still history: the caller keeps one point (searched wide)
    res = _result(3, 3)
    res.x[1, 0], res.y[1, 0], res.status[1, 0] = 100.0, 50.0, OK  # on tp but not now
    X, Y = np.array([np.nan, 130.0, np.nan]), np.array([np.nan, 60.0, np.nan])  # 1 now, not on tp
    assert _restart_velocity(np.array([0, 1]), X, Y, res, 1) is None
    assert _restart_velocity(np.array([], np.int64), X, Y, res, 1) is None
    assert _restart_velocity(np.array([1]), X, Y, res, -1) is None  # no previous frame
