"""Identity after a flagged stretch and around glitches: a flagged marker that left its
neighbours' consensus is astray (:meth:`IdentityStage._astray`); still markers do not
outvote the moving ones in the constellation check (:meth:`Tracker._broken`); a restart
velocity leaves out the camera's bump (:meth:`FrameContext.step_velocity`)."""
from types import SimpleNamespace

import numpy as np

from wingphoto.track.identity import ASTRAY_FRACTION, IdentityStage
from wingphoto.track.options import TrackOptions
from wingphoto.track.status import FLAGGED, OK
from wingphoto.track.tracker import FrameContext, Tracker

SPACING = 20.0


def _grid():
    """A 3 x 3 grid of markers, SPACING px apart (marker 4 in the middle)."""
    g = np.arange(3) * SPACING
    return np.array([(100.0 + x, 80.0 + y) for y in g for x in g])


def _state(T, t_ok, move, mid_at):
    """Tracker state and rows ``res`` of a grid that moves by ``move`` px a frame.

    Every marker is ok on every frame but the middle one (4), ok up to frame ``t_ok``
    and flagged after, at ``mid_at(t)``. Returns the stage and the rows."""
    P0 = _grid()
    n = len(P0)
    x = np.empty((T, n))
    y = np.empty((T, n))
    for t in range(T):
        x[t], y[t] = P0[:, 0] + move[0] * t, P0[:, 1] + move[1] * t
        if t > t_ok:
            x[t, 4], y[t, 4] = mid_at(t)
    status = np.full((T, n), OK, np.int8)
    status[t_ok + 1:, 4] = FLAGGED
    res = SimpleNamespace(x=x, y=y, status=status)
    last_ok = np.full(n, T - 2)
    last_ok[4] = t_ok
    hist_t = np.tile(np.array([T - 2, T - 3, T - 4]), (n, 1))
    hist_x = np.stack([np.column_stack([x[T - 2 - k], y[T - 2 - k]]) for k in range(3)], axis=1)
    st = SimpleNamespace(last_ok=last_ok, hist_x=hist_x, hist_t=hist_t, nh=np.full(n, 3),
                         _spacing=np.full(n, SPACING), local=4 * SPACING)
    st._neighbours_then = IdentityStage._neighbours_then.__get__(st)
    return st, res


def _astray(st, res, t):
    return IdentityStage._astray(st, np.array([4]), res.x[t], res.y[t], res.status[t].copy(), res, t)


def test_flagged_marker_running_off_its_blob_is_astray():
    # flagged (imprecise, say) from frame 4 on, its motion model followed a smear sliding
    # 4 px a frame across the wing: 28 px from where its neighbours put it at frame 11
    move = (1.5, 0.5)
    T = 12

    def runaway(t):
        return 100.0 + SPACING + move[0] * t + 4.0 * (t - 4), 80.0 + SPACING + move[1] * t

    st, res = _state(T, 4, move, runaway)
    assert _astray(st, res, T - 1).tolist() == [True]


def test_flagged_marker_on_its_own_blob_is_not_astray():
    move = (1.5, 0.5)
    T = 12

    def own(t):  # flagged, but where its neighbours put it, less than the limit off
        return (100.0 + SPACING + move[0] * t + 0.9 * ASTRAY_FRACTION * SPACING * (t == T - 1),
                80.0 + SPACING + move[1] * t)

    st, res = _state(T, 4, move, own)
    assert _astray(st, res, T - 1).tolist() == [False]


def test_marker_without_neighbours_ok_then_is_not_judged():
    move = (1.5, 0.5)
    T = 12
    st, res = _state(T, 4, move, lambda t: (400.0, 400.0))
    res.status[4, [0, 1, 2, 3, 5, 6, 7, 8]] = FLAGGED  # none ok on its last ok frame
    assert _astray(st, res, T - 1).tolist() == [False]


def _constellation(n_still=10, n_moving=6, speed=6.0, nh_moving=3):
    """Tracker state and frame context of ``n_still`` still markers found where predicted
    and ``n_moving`` markers moving ``speed`` px a frame found where they were on the
    previous frame (a frame repeated with new noise)."""
    n = n_still + n_moving
    hist_x = np.zeros((n, 3, 2))
    hist_x[n_still:, :, 0] = np.array([0.0, -speed, -2 * speed])
    tr = SimpleNamespace(hist_x=hist_x, hist_t=np.tile(np.array([9, 8, 7]), (n, 1)),
                         nh=np.array([3] * n_still + [nh_moving] * n_moving),
                         resid_rms=np.full(n, 0.2), p=TrackOptions())
    tr._consistent = Tracker._consistent.__get__(tr)
    tr._checkable = Tracker._checkable.__get__(tr)
    tr._where_predicted = Tracker._where_predicted.__get__(tr)
    tr._moving_now = Tracker._moving_now.__get__(tr)
    tr._stalled = Tracker._stalled.__get__(tr)
    resid = np.r_[np.full(n_still, 0.1), np.full(n_moving, speed)]
    ctx = SimpleNamespace(fits=np.ones(n, bool), gap=np.ones(n, np.int64), resid=resid, S=np.full(n, 0.95),
                          X=hist_x[:, 0, 0] + 0.05, Y=hist_x[:, 0, 1] - 0.05)
    return tr, ctx


def test_still_markers_do_not_hide_a_repeated_frame():
    # 10 still dots where predicted outvote 6 wing markers that all stalled: the frame
    # must still be checked for a glitch (it was taken for the wing stopping)
    tr, ctx = _constellation()
    assert Tracker._broken(tr, ctx)


def test_a_stall_within_the_motion_models_limit_is_a_glitch():
    # a loose motion model (rms 2 px: limit 8 px) accepts the 6 px stall of every moving
    # marker; that most of them are back where they were still breaks the constellation
    tr, ctx = _constellation()
    tr.resid_rms[:] = 2.0
    assert Tracker._consistent(tr, ctx) == (16, 16)
    assert Tracker._broken(tr, ctx)
    ctx.X[10:] += 6.0  # they moved on (where predicted): no glitch
    ctx.resid[10:] = 0.1
    assert not Tracker._broken(tr, ctx)
    tr, ctx = _constellation(speed=1.5)  # slow markers may stop within a frame
    tr.resid_rms[:] = 2.0
    assert not Tracker._broken(tr, ctx)


def test_slow_or_just_reacquired_markers_do_not_vote_alone():
    # a wing marker re-acquired on this or the previous frame (two points, a velocity
    # borrowed from its neighbours) is no witness of a glitch; nor is a slow one
    tr, ctx = _constellation(nh_moving=2)
    assert not Tracker._broken(tr, ctx)
    tr, ctx = _constellation(speed=0.8)
    ctx.resid[10:] = 0.8 * 3  # (beyond the 2 px limit, but slower than _MOVING_PX)
    assert not Tracker._broken(tr, ctx)


def test_restart_velocity_leaves_out_the_bump_and_spans_dropped_frames():
    ctx = SimpleNamespace(shift=np.array([-5.5, -6.0]), aged=0)
    disp = np.array([[-2.5, 1.0], [-3.5, -1.0]])  # the neighbours' move across the bump
    v = FrameContext.step_velocity(ctx, disp)
    np.testing.assert_allclose(v, [[3.0, 7.0], [2.0, 5.0]])
    ctx = SimpleNamespace(shift=None, aged=2)  # two frames dropped: three frames' motion
    np.testing.assert_allclose(FrameContext.step_velocity(ctx, np.array([9.0, -3.0])), [3.0, -1.0])
    ctx = SimpleNamespace(shift=None, aged=-1)  # (a repeat: the image's own motion)
    np.testing.assert_allclose(FrameContext.step_velocity(ctx, np.array([1.0, 2.0])), [1.0, 2.0])


def _still_and_moving(T=30, k=18, seed=3):
    """Ten still discs (a mount, reference dots) and five moving 6 px a frame, frame ``k``
    repeated with new noise (a recorder's renoised repeat). Returns frames and truth."""
    from wingphoto.synth import render_discs

    rng = np.random.default_rng(seed)
    still = np.column_stack([np.linspace(20, 200, 10), np.full(10, 15.0)])
    moving = np.column_stack([np.full(5, 40.0), np.linspace(70, 150, 5)])
    t = np.arange(T, dtype=float)
    t[k + 1:] -= 1  # frame k+1 shows the wing where frame k did
    truth = np.empty((T, 15, 2))
    truth[:, :10] = still
    truth[:, 10:, 0] = moving[:, 0] + 6.0 * t[:, None]
    truth[:, 10:, 1] = moving[:, 1]
    d = np.full(15, 8.0)
    frames = np.stack([render_discs(truth[f], d, (175, 230), noise_std=2.0, rng=rng, dtype=np.uint8)
                       for f in range(T)])
    return frames, truth


def test_renoised_repeat_is_found_among_still_markers(caplog):
    # the still discs, where predicted, outvoted the moving ones: the repeat passed as the
    # wing stopping, and the stall fed to the motion model predicted it going back
    import logging

    from wingphoto.track import track_markers

    frames, truth = _still_and_moving()
    with caplog.at_level(logging.INFO, logger="wingphoto.track"):
        tr = track_markers(frames, np.rint(truth[0]), progress=False)
    assert "constellation restored by a repeated frame" in caplog.text
    x = tr["x"].to_numpy().reshape(truth.shape[:2])
    y = tr["y"].to_numpy().reshape(truth.shape[:2])
    ok = tr["status"].to_numpy().reshape(truth.shape[:2]) == "ok"
    err = np.hypot(x - truth[..., 0], y - truth[..., 1])
    assert (err[ok] <= 1.0).all()
    assert ok[20:, 10:].mean() > 0.95  # the wing followed on after the repeat


def test_neighbours_near_a_line_do_not_judge_a_marker_far_off_it():
    # four neighbours on a row (a real-dot sheet's ok ones, say), their positions off by
    # half a pixel: an affine map from them, extrapolated 90 px off their line, is not
    # determined (here it puts the marker 84 px from its own blob) and put real dots
    # followed on their own blobs 30-60 px away; their mean move judges instead
    T, t, t_ok = 8, 7, 0
    row = np.column_stack([np.linspace(100, 190, 4), [100.5, 99.6, 100.3, 99.7]])
    P0 = np.vstack([row, [[150.0, 190.0]]])
    move = np.array([2.0, 9.0])
    x = np.empty((T, 5))
    y = np.empty((T, 5))
    for f in range(T):
        x[f], y[f] = (P0 + move * f).T
    x[t, :4] += [0.3, -0.3, 0.4, -0.3]
    y[t, :4] += [-0.4, 0.4, 0.3, -0.4]
    status = np.full((T, 5), OK, np.int8)
    status[t_ok + 1:, 4] = FLAGGED
    res = SimpleNamespace(x=x, y=y, status=status)
    hist_t = np.tile(np.array([t - 1, t - 2, t - 3]), (5, 1))
    hist_x = np.stack([np.column_stack([x[t - 1 - k], y[t - 1 - k]]) for k in range(3)], axis=1)
    st = SimpleNamespace(last_ok=np.array([t - 1] * 4 + [t_ok]), hist_x=hist_x, hist_t=hist_t, nh=np.full(5, 3),
                         _spacing=np.full(5, 30.0), local=120.0)
    st._neighbours_then = IdentityStage._neighbours_then.__get__(st)
    out = IdentityStage._astray(st, np.array([4]), x[t], y[t], status[t].copy(), res, t)
    assert out.tolist() == [False]
    x[t, 4] += 30.0  # on a neighbour's blob, a spacing off: astray
    out = IdentityStage._astray(st, np.array([4]), x[t], y[t], status[t].copy(), res, t)
    assert out.tolist() == [True]


def test_a_large_step_is_vouched_for_even_after_an_ok_frame():
    # ok on the frame before, three points: the motion model vouches for a small step but
    # not for one of 0.3 spacing or more (an inflated limit let a marker onto a neighbour's
    # blob 9-26 px from a correct prediction)
    n = 4
    tr = SimpleNamespace(last_ok=np.full(n, 9), nh=np.array([3, 3, 3, 2]), _spacing=np.full(n, 15.0))
    ctx = SimpleNamespace(ST=np.zeros(n, np.int8), fits=np.ones(n, bool), resid=np.array([0.5, 4.4, 4.6, 0.5]))
    stay = np.zeros(n, bool)
    assert Tracker._to_vouch(tr, 10, ctx, stay).tolist() == [2, 3]
    tr.last_ok[0] = 7  # resuming after a gap
    assert Tracker._to_vouch(tr, 10, ctx, stay).tolist() == [0, 2, 3]
    stay[2] = True
    assert Tracker._to_vouch(tr, 10, ctx, stay).tolist() == [0, 3]


def test_own_prediction_vouches_only_with_a_history_of_its_own():
    # two markers resume 3 frames after their last ok frame with no neighbour to judge
    # them, both 1 px from their predictions: the one with three points of its own passes,
    # the one predicted from a re-acquisition's borrowed velocity (two points) does not
    n, t = 2, 20
    empty = np.zeros(0, np.int64)
    tr = SimpleNamespace(p=TrackOptions(), last_ok=np.full(n, t - 3), nh=np.array([3, 2]),
                         resid_rms=np.full(n, 0.5), _spacing=np.full(n, 15.0),
                         _inconsistent=lambda *a, **k: (empty, empty),
                         _hopped=lambda idx, res, t, now=None: np.zeros(idx.size, bool),
                         _disputed=lambda idx, res, t: np.zeros(idx.size, bool),
                         _merged_with_lost=lambda idx, ST, res, t: np.zeros(idx.size, bool),
                         _coasted=lambda idx, res, t: np.zeros(idx.size, bool),
                         _map_verdict=lambda idx, *a: np.zeros(idx.size, np.int8),
                         _just_reacquired=lambda idx, res: np.zeros(idx.size, bool))
    ctx = SimpleNamespace(X=np.zeros(n), Y=np.zeros(n), S=np.full(n, 0.95), SEC=np.full(n, -2.0),
                          ST=np.full(n, OK, np.int8), RS=np.zeros(n, np.int8), resid=np.full(n, 1.0))
    IdentityStage._vouch(tr, empty, np.arange(n), ctx, None, t)
    assert ctx.ST.tolist() == [OK, FLAGGED]


def test_the_frame_after_a_reacquisition_needs_its_prediction():
    # (fresh DEV seed 146 dropped right) markers re-acquired on the frame before, two points
    # of their own, no neighbour to judge them: the one 3 px from its prediction is flagged,
    # the one 1 px from it passes, and one not re-acquired (ok on the frame before) is not
    # judged by its prediction
    from wingphoto.track.status import _R

    n, t = 3, 20
    empty = np.zeros(0, np.int64)
    res = SimpleNamespace(x=np.zeros((30, n)), reason=np.zeros((30, n), np.int8))
    res.reason[t - 1, :2] = _R["reacquired"]
    tr = SimpleNamespace(p=TrackOptions(), last_ok=np.full(n, t - 1), nh=np.array([2, 2, 2]),
                         resid_rms=np.full(n, 0.5), _spacing=np.full(n, 15.0),
                         _inconsistent=lambda *a, **k: (empty, empty),
                         _hopped=lambda idx, res, t, now=None: np.zeros(idx.size, bool),
                         _disputed=lambda idx, res, t: np.zeros(idx.size, bool),
                         _merged_with_lost=lambda idx, ST, res, t: np.zeros(idx.size, bool),
                         _coasted=lambda idx, res, t: np.zeros(idx.size, bool),
                         _map_verdict=lambda idx, *a: np.zeros(idx.size, np.int8))
    tr._just_reacquired = lambda idx, res: IdentityStage._just_reacquired(tr, idx, res)
    ctx = SimpleNamespace(X=np.zeros(n), Y=np.zeros(n), S=np.full(n, 0.95), SEC=np.full(n, -2.0),
                          ST=np.full(n, OK, np.int8), RS=np.zeros(n, np.int8), resid=np.array([3.0, 1.0, 3.0]))
    IdentityStage._vouch(tr, empty, np.arange(n), ctx, res, t)
    assert ctx.ST.tolist() == [FLAGGED, OK, OK]
    assert ctx.RS[0] == _R["jump"]


def test_a_marker_whose_blob_was_disputed_does_not_resume_on_its_own_prediction():
    # _disputed: flagged 'conflict' since its last ok frame (either direction of the pass)
    from wingphoto.track.status import _R

    T, N = 20, 3
    res = SimpleNamespace(x=np.zeros((T, N)), reason=np.zeros((T, N), np.int8))
    res.reason[8, 0] = _R["conflict"]
    res.reason[8, 1] = _R["merged"]  # no dispute (a dispute, it swapped a pair: repeated DEV seed 7 left)
    res.reason[3, 2] = _R["conflict"]  # before its last ok frame: forgotten
    me = SimpleNamespace(last_ok=np.array([5, 5, 5]))
    np.testing.assert_array_equal(IdentityStage._disputed(me, np.arange(N), res, 12), [True, False, False])
    back = SimpleNamespace(last_ok=np.array([15, 15, 15]))  # a backward pass
    res.reason[12, 1] = _R["conflict"]
    np.testing.assert_array_equal(IdentityStage._disputed(back, np.arange(N), res, 10), [False, True, False])


def test_a_marker_flagged_jump_since_its_last_ok_frame_is_disputed_too():
    # after a jump its own prediction may follow another blob (bumped DEV seed 30 right)
    from wingphoto.track.status import _R

    T, N = 20, 3
    res = SimpleNamespace(x=np.zeros((T, N)), reason=np.zeros((T, N), np.int8))
    res.reason[7, 0] = _R["jump"]
    res.reason[7, 1] = _R["imprecise"]  # a precision flag: no dispute
    res.reason[12, 2] = _R["jump"]  # on the frame being judged: not yet written, not read
    me = SimpleNamespace(last_ok=np.array([5, 5, 5]))
    np.testing.assert_array_equal(IdentityStage._disputed(me, np.arange(N), res, 12), [True, False, False])


def test_a_marker_merged_with_a_neighbour_since_lost_is_in_doubt():
    # _merged_with_lost: marker 0 shared marker 1's blob on frame 8, and 1 has not been ok
    # since (clean16 fresh DEV seed 66 right: 0 resumed ok on 1's blob, 8-16 px off)
    from wingphoto.track.status import LOST, _R

    T, N = 20, 4
    res = SimpleNamespace(x=np.full((T, N), np.nan), y=np.full((T, N), np.nan),
                          reason=np.zeros((T, N), np.int8))
    res.x[:, :], res.y[:, :] = np.array([0.0, 1.0, 40.0, 80.0]), 0.0
    res.reason[8, 0] = _R["merged"]
    st = SimpleNamespace(last_ok=np.array([5, 7, 5, 5]), rb=np.full(N, 3.0))
    ST = np.array([OK, LOST, OK, OK], np.int8)
    idx = np.array([0, 2])
    np.testing.assert_array_equal(IdentityStage._merged_with_lost(st, idx, ST, res, 12), [True, False])
    ST[1] = OK  # the partner is ok again now: both blobs are known
    assert not IdentityStage._merged_with_lost(st, idx, ST, res, 12).any()
    ST[1] = FLAGGED
    st.last_ok[1] = 10  # ok after the merger: the two were told apart then
    assert not IdentityStage._merged_with_lost(st, idx, ST, res, 12).any()
    st.last_ok[1] = 7
    res.x[8, 1] = 9.0  # the merged flag was for another blob, 9 px away
    assert not IdentityStage._merged_with_lost(st, idx, ST, res, 12).any()
    res.x[8, 1] = 1.0
    back = SimpleNamespace(last_ok=np.array([15, 15, 15, 15]), rb=np.full(N, 3.0))  # a backward pass
    res.reason[:] = 0
    res.reason[11, 0] = _R["merged"]
    np.testing.assert_array_equal(IdentityStage._merged_with_lost(back, idx, ST, res, 10), [True, False])
