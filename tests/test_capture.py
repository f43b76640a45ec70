"""Frame selection from synthetic calibration videos (wingphoto.capture, synth.render_calibration_video)."""
import functools

import numpy as np
import pytest

from wingphoto.capture import estimate_offset, motion_signal, select_calibration_frames
from wingphoto.pantilt import pan_tilt_schedule

synth = pytest.importorskip("wingphoto.synth")

PATTERN = (9, 6)


@functools.lru_cache(maxsize=None)
def _video():
    """3 x 3 pan-tilt steps + neutral, 0.5 s holds, 5 frames rendered per step (50 frames)."""
    sch = pan_tilt_schedule(3, 3, hold_s=0.5)
    return sch, synth.render_calibration_video(schedule=sch, fps=100, frames_per_step=5, move_s=0.2, seed=1)


@functools.lru_cache(maxsize=None)
def _full_rate_video(offset_right):
    """Every frame of a short run (2 x 2 steps of 0.25 s at 40 fps, 0.1 s moves)."""
    sch = pan_tilt_schedule(2, 2, hold_s=0.25, neutral_ms=None)
    return synth.render_calibration_video(schedule=sch, fps=40, move_s=0.1, seed=2, offset_right=offset_right)


def test_video_truth_is_consistent():
    sch, v = _video()
    assert v.left.shape == (50, 512, 512) and v.right.shape == v.left.shape
    assert v.step.tolist() == [s for s in range(1, 11) for _ in range(5)]
    # the first rendered frame of every step after the first is mid-move, motion-blurred
    moving = v.motion_px[5::5]
    assert np.all(moving > 0.3) and not v.still[5::5].any()
    assert v.still[[0, 3, 4, 8, 9]].all()
    # true corners at the poses of the schedule: the truth projects through the rig
    k = 4
    from wingphoto.camera import rodrigues

    X = v.board_points @ rodrigues(v.om[k]).T + v.T[k]
    xl, xr = v.rig.project(X)
    np.testing.assert_allclose(v.corners_left[k], xl, atol=1e-9)
    np.testing.assert_allclose(v.corners_right[k], xr, atol=1e-9)
    tv = v.truth()
    assert list(tv.columns) == ["frame", "time_s", "step", "still", "motion_px", "tilt_deg", "pan_deg"]


def test_selection_with_schedule_one_still_sharp_pair_per_pose():
    sch, v = _video()
    sel = select_calibration_frames(v.left, v.right, PATTERN, schedule=sch, fps=v.fps, frame_numbers=v.frame_index)
    assert len(sel) == 9 and sel.offset == 0
    picked = np.array(sel.frames)
    assert sorted(v.step[picked]) == list(range(1, 10))  # every pose step once, neutral skipped
    assert v.still[picked].all()  # the truth: the board did not move during these exposures
    # the detected corners are the true ones, in the same order, in both views
    for k, f in enumerate(sel.frames):
        assert np.abs(sel.left[k].corners - v.corners_left[f]).max() < 0.15
        assert np.abs(sel.right[k].corners - v.corners_right[f]).max() < 0.15
    c = sel.candidates
    assert (c.loc[~c.selected, "reason"] != "").all() and (c.loc[c.selected, "reason"] == "").all()
    moving = c[~c.still]
    assert moving["reason"].str.startswith("moving").all()
    assert not v.still[moving.frame].all()
    assert (c.loc[c.step == 10, "reason"].isin(["neutral step (a repeat of a pose step)"]) | ~c.loc[c.step == 10,
            "still"]).all()
    assert "moving" in sel.reasons().index
    assert "9 calibration pairs chosen from 50 frames" in sel.summary()


def test_selection_without_schedule_drops_the_repeated_neutral_pose_and_calibrates():
    sch, v = _video()
    sel = select_calibration_frames(v.left, v.right, PATTERN, frame_numbers=v.frame_index)
    assert len(sel) == 9
    assert v.still[list(sel.frames)].all()
    assert sel.candidates["reason"].str.startswith("same pose as frame").sum() == 1
    st = sel.calibrate(v.square_size)
    assert st.used.all()
    assert st.pairs[0] == sel.names[0] and sel.names[0].startswith("frame ")
    z = st.compare(v.rig)
    assert z.loc[z.parameter.str.startswith(("om", "T")), "inside_3sigma"].all()


def test_n_keeps_the_most_diverse_poses():
    sch, v = _video()
    sel = select_calibration_frames(v.left, v.right, PATTERN, n=4, schedule=sch, fps=v.fps,
                                    frame_numbers=v.frame_index)
    assert len(sel) == 4
    ang = v.angles_deg[list(sel.frames)]
    assert np.ptp(ang[:, 1]) >= 59 and np.ptp(ang[:, 0]) >= 39  # corners of the tilt/pan range
    assert sel.candidates["reason"].str.startswith("pose too close").sum() == 5


def test_blurred_and_undetected_frames_are_named():
    sch, v = _video()
    left = v.left.copy()
    import cv2

    left[13] = cv2.GaussianBlur(left[13], (0, 0), 3.0)  # out of focus
    left[14] = cv2.GaussianBlur(left[14], (0, 0), 3.0)
    right = v.right.copy()
    right[17:20] = 80  # board hidden in the right view for the whole still period
    sel = select_calibration_frames(left, right, PATTERN, schedule=sch, fps=v.fps, frame_numbers=v.frame_index)
    c = sel.candidates.set_index("frame")
    assert c.at[13, "reason"].startswith("blurred") or c.at[13, "reason"].startswith("board not fully detected")
    assert c.at[17, "reason"] == "board not fully detected in the right view"
    assert 13 not in sel.frames and 17 not in sel.frames and len(sel) == 7
    axes = sel.plot()
    assert np.asarray(axes).size >= 14


def test_offset_found_from_the_board_motion():
    v1 = _full_rate_video(2)
    est, score = estimate_offset(motion_signal(v1.left), motion_signal(v1.right))
    assert est == -2 and score > 0.8
    assert estimate_offset(motion_signal(v1.left), motion_signal(v1.left))[0] == 0
    sel = select_calibration_frames(v1.left, v1.right, PATTERN)
    assert sel.offset_estimate == -2 and sel.offset == -2
    for k, f in enumerate(sel.frames):  # right frame f - 2 shows the left frame's instant
        assert np.abs(sel.right[k].corners - v1.corners_right[f - 2]).max() < 0.2
    assert "right frame = left frame -2" in sel.summary()


def test_bad_arguments():
    sch, v = _video()
    with pytest.raises(ValueError, match="schedule needs fps"):
        select_calibration_frames(v.left, v.right, PATTERN, schedule=sch)
    with pytest.raises(ValueError, match="n must be at least 3"):
        select_calibration_frames(v.left, v.right, PATTERN, n=2)
    with pytest.raises(ValueError, match="frame_numbers has 3 entries"):
        select_calibration_frames(v.left, v.right, PATTERN, frame_numbers=[0, 1, 2])
    with pytest.raises(ValueError, match="no still frame|not fully detected"):
        rng = np.random.default_rng(0)
        noise = rng.integers(0, 255, (6, 64, 80), dtype=np.uint8)
        select_calibration_frames(noise, noise[::-1], PATTERN)
    with pytest.raises(ValueError, match="left must be"):
        select_calibration_frames(3, v.right, PATTERN)


def test_recordings_read_from_folders(tmp_path):
    """Any wingphoto.read_sequence source: here folders of TIFF frames."""
    tifffile = pytest.importorskip("tifffile")
    sch, v = _video()
    for side, frames in (("left", v.left[:20]), ("right", v.right[:20])):
        (tmp_path / side).mkdir()
        for k, img in enumerate(frames):
            tifffile.imwrite(tmp_path / side / f"frame_{k:04d}.tif", img)
    sel = select_calibration_frames(str(tmp_path / "left"), tmp_path / "right", PATTERN,
                                    frame_numbers=v.frame_index[:20])
    assert sel.frames == (4, 9, 14, 19)
    assert v.still[list(sel.frames)].all()
