"""First frames of a wing that moves fast at frame 0: no velocity yet, so every marker is
searched wide, and its neighbours' blobs lie in its window."""
import numpy as np
import pytest


@pytest.fixture(scope="module")
def fast_start():
    """Independent renderer, DEV seed 56 (hard, left camera), its first 20 frames: wing
    markers 12-14 px apart moving 2-7 px/frame from frame 0."""
    from wingphoto.synth.independent import render_independent

    return render_independent("hard", seed=56, camera="left", n_frames=20)


def _ok_and_error(seq):
    from wingphoto import track_markers

    tr = track_markers(seq.frames(), seq.picks(), camera="left", progress=False)
    T, N = seq.points.shape[:2]
    ok = tr.status.to_numpy().reshape(T, N) == "ok"
    err = np.hypot(tr.x.to_numpy().reshape(T, N) - seq.points[..., 0], tr.y.to_numpy().reshape(T, N) - seq.points[..., 1])
    return ok, err


def test_a_wing_moving_fast_at_frame_0_gets_going(fast_start):
    # Each wing marker's runner-up peak on frame 1 was its neighbour's blob, a few px on from
    # where the neighbour was: counted as a second peak, every wing marker was 'ambiguous'
    # (its best peak right), none got a velocity, every frame was searched wide again, and
    # all were lost by frame 7 (wing ok 0 % on frames 3-19). A peak on the blob a neighbour
    # itself matched is explained (IdentityStage._runner_up_by_matches).
    ok, err = _ok_and_error(fast_start)
    wing = np.asarray(fast_start.point_kind) == "wing"
    assert ok[3:, wing].mean() > 0.5
    assert not (ok & (err > 1.0)).any()
    # (the explanation's limit - a best peak within half the spacing of where the marker
    # was - is guarded by test_track_identity_astray.py's renoised-repeat test: equal still
    # discs whose wide searches took their neighbours' blobs)
