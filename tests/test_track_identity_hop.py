"""The hop test of a marker resuming after a gap (:meth:`IdentityStage._hopped`)."""
from types import SimpleNamespace

import numpy as np

from wingphoto.track.identity import HOP_FRACTION, IdentityStage
from wingphoto.track.status import _R


def _stage(last_ok, spacing=10.0):
    """The tracker state ``_hopped`` reads: last ok frame and spacing per marker."""
    return SimpleNamespace(last_ok=np.asarray(last_ok), _spacing=np.full(len(last_ok), spacing))


def _rows(paths):
    """Rows ``res.x, res.y`` (frames x markers) from a list of (T, 2) paths."""
    P = np.stack(paths, axis=1)
    return SimpleNamespace(x=P[..., 0].copy(), y=P[..., 1].copy(),
                           reason=np.zeros(P.shape[:2], np.int8))


def _path(T=12, v=(1.5, -0.5)):
    return np.column_stack([100 + v[0] * np.arange(T), 50 + v[1] * np.arange(T)])


def test_smooth_path_through_a_gap_is_no_hop():
    res = _rows([_path()])
    assert not IdentityStage._hopped(_stage([3]), np.array([0]), res, 10).any()


def test_step_onto_the_neighbour_blob_is_a_hop():
    p = _path()
    p[7:] += [6.0, 8.0]  # one step of 10 px = a spacing: onto the neighbour's blob
    res = _rows([p, _path()])
    hop = IdentityStage._hopped(_stage([3, 3]), np.array([0, 1]), res, 10)
    assert hop.tolist() == [True, False]


def test_hop_threshold_and_lost_frames():
    p = _path()
    p[7:] += [0.0, 0.9 * HOP_FRACTION * 10.0]  # just below the threshold
    q = _path()
    q[7:] += [0.0, 1.1 * HOP_FRACTION * 10.0]  # just above
    q[5] = np.nan  # a lost frame in between: skipped, the hop is still seen
    res = _rows([p, q])
    hop = IdentityStage._hopped(_stage([3, 3]), np.array([0, 1]), res, 10)
    assert hop.tolist() == [False, True]


def test_hop_before_the_last_ok_frame_is_not_counted():
    p = _path()
    p[2:] += [8.0, 0.0]
    res = _rows([p])
    assert not IdentityStage._hopped(_stage([4]), np.array([0]), res, 10).any()


def test_hop_before_a_reacquisition_is_not_counted():
    p = _path()
    p[6:] += [8.0, 0.0]  # the re-acquisition at frame 6 put it back on its blob
    res = _rows([p, p.copy()])
    res.reason[6, 0] = _R["reacquired"]
    hop = IdentityStage._hopped(_stage([3, 3]), np.array([0, 1]), res, 10)
    assert hop.tolist() == [False, True]


def test_one_frame_stall_is_no_hop():
    p = _path(v=(4.0, 3.0))  # 5 px a frame: a stall is a step change of a half spacing
    p[7] = p[6]  # a repeated frame: the marker stands still for one frame, then resumes
    res = _rows([p])
    assert not IdentityStage._hopped(_stage([3]), np.array([0]), res, 10).any()


def test_repeated_frame_that_delays_the_rest_is_no_hop():
    p = _path(v=(4.0, 3.0))
    p[7:] = p[6:-1].copy()  # frame 7 repeats frame 6 and the motion resumes a frame late
    res = _rows([p])
    assert not IdentityStage._hopped(_stage([3]), np.array([0]), res, 10).any()


def test_a_hop_on_the_resuming_frame_itself():
    # last ok at 8, flagged at 9, resuming at 10 with a step of a spacing: the step onto
    # this frame's position is part of the path (hard DEV seed 65 left: ok 9.5 px off)
    p = _path()
    res = _rows([p])
    now = (np.array([p[10, 0] + 6.0]), np.array([p[10, 1] - 8.0]))
    assert not IdentityStage._hopped(_stage([8]), np.array([0]), res, 10).any()  # (two positions: not judged)
    assert IdentityStage._hopped(_stage([8]), np.array([0]), res, 10, now=now).tolist() == [True]
    smooth = (np.array([p[10, 0]]), np.array([p[10, 1]]))
    assert not IdentityStage._hopped(_stage([8]), np.array([0]), res, 10, now=smooth).any()
