"""What may confirm and complete a camera-shift hypothesis (:meth:`Tracker._recover`):
the still markers (the mount, the reference dots), which move on the image only when the
camera does."""
from types import SimpleNamespace

import numpy as np

from test_track import moving_discs
from wingphoto.track.options import TrackOptions
from wingphoto.track.tracker import Tracker


def _tracker(n_still):
    """A tracker with three frames of history: the first ``n_still`` markers still, the
    others moving 2 px a frame along x."""
    frames, truth, _ = moving_discs(1, T=2)
    picks = np.rint(truth[0])
    n = len(picks)
    tk = Tracker.from_picks(frames[0], picks, np.full(n, -1, np.int64), TrackOptions(), True, np.arange(n))
    v = np.where(np.arange(n) < n_still, 0.0, 2.0)
    for k in range(3):  # positions on frames 9, 8, 7
        tk.hist_x[:, k, 0] = picks[:, 0] - k * v
        tk.hist_x[:, k, 1] = picks[:, 1]
        tk.hist_t[:, k] = 9 - k
    tk.nh[:] = 3
    return tk, picks, v


def _solution(found, pred):
    n = len(found)
    return SimpleNamespace(X=found[:, 0].copy(), Y=found[:, 1].copy(), pred=pred, fits=np.ones(n, bool),
                           gap=np.ones(n, np.int64), S=np.full(n, 0.95))


def test_a_camera_shift_must_move_the_still_markers():
    tk, picks, v = _tracker(3)
    shift = np.array([1.4, -0.9])
    moved = picks + [[vx, 0] for vx in v]  # the wing moved on, its markers where predicted
    # a real bump: the still markers moved by it too (the wing as well)
    bumped = moved + shift
    assert tk._bump_holds(_solution(bumped, bumped), tk.hist_x, *shift)
    # a dropped frame read as a shift: the still markers stayed where they were
    dropped = moved.copy()
    dropped[3:] += shift + [[2.0, 0.0]]
    assert not tk._bump_holds(_solution(dropped, dropped), tk.hist_x, *shift)


def test_without_two_still_markers_nothing_says_no():
    tk, picks, v = _tracker(1)
    moved = picks + [[vx, 0] for vx in v]
    assert tk._bump_holds(_solution(moved, moved), tk.hist_x, 3.0, 3.0)
    assert tk._shift_miss(_solution(moved + 2.5, moved)) is None


def test_the_miss_is_measured_on_the_still_markers_alone():
    tk, picks, v = _tracker(3)
    pred = picks + [[vx, 0] for vx in v] + [4.4, -3.3]  # the global shift's estimate
    found = picks + [[vx, 0] for vx in v] + [5.6, -5.1]  # the true bump
    found[3:, 0] += 1.7  # the wing's own miss (the motion model's error) must not count
    miss = tk._shift_miss(_solution(found, pred))
    np.testing.assert_allclose(miss, [1.2, -1.8], atol=1e-9)
    # a miss below half a pixel is no miss
    assert tk._shift_miss(_solution(pred + [0.3, 0.2], pred)) is None


def test_a_count_of_dropped_frames_is_in_doubt_only_when_weak_and_matched():
    from wingphoto.track.glitch import _drop_count_in_doubt

    # 4 of 7 where predicted, another count 3: in doubt; another count 2: clear
    assert _drop_count_in_doubt(5, {1: 0, 3: 3, 5: 4}, 7)
    assert not _drop_count_in_doubt(5, {1: 0, 3: 2, 5: 4}, 7)
    # 5 of 8, another count 3 (more than half as many): in doubt (real dots, dropped, DEV
    # seed 286 cam2 with the measured history kept: "5 dropped" put two dots one spacing ahead)
    assert _drop_count_in_doubt(5, {3: 3, 4: 0, 5: 5}, 8)
    # most markers where predicted: clear, whatever the others
    assert not _drop_count_in_doubt(3, {2: 5, 3: 6, 4: 5}, 7)
    # no other count tried
    assert not _drop_count_in_doubt(1, {1: 2}, 7)
