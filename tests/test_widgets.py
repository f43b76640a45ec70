"""Picker and review widgets: pure state transitions, files, and the views driven headless.

The views are driven through their handlers (display coordinates) and ``Button.click()``
with the Agg backend; no browser is involved.
"""
import json
import os
import sys
import types

import numpy as np
import pandas as pd
import pytest

from wingphoto.widgets import Picker, TrackReview
from wingphoto.widgets.state import (
    Correction,
    Pick,
    PickerState,
    ReviewState,
    Viewport,
    apply_corrections,
    read_corrections,
    replay_corrections,
    write_corrections,
)

W, H = 60, 40  # non-square to catch x/y swaps


# --------------------------------------------------------------------------- PickerState
def _two_view_state():
    s = PickerState(image_size=(W, H), n_points=3, half_size=(4, 3))
    s = s.place("left", 10, 5).place("left", 20, 6).place("left", 30, 7)
    return s.place("right", 12, 5).place("right", 22, 6)


def test_place_numbers_in_order_and_switches_view_at_first_missing():
    s = PickerState(image_size=(W, H), n_points=3)
    s = s.place("left", 10, 5)
    assert s.current == 1 and s.camera == "left"
    s = s.place("left", 20, 6).place("left", 30, 7)
    assert s.numbers("left") == [0, 1, 2]
    s = s.select(camera="right")
    assert s.current == 0  # the right view starts at its first missing number
    s = s.place("right", 12, 5)
    assert s.get("right", 0) == Pick(0, 12.0, 5.0, 10.0, 10.0)
    assert s.missing() == {"left": [], "right": [1, 2]}
    assert not s.is_complete


def test_move_resize_delete_and_undo_return_previous_states():
    s0 = _two_view_state()
    s1 = s0.move("left", 1, 21.5, 6.5)
    assert s1.get("left", 1) == Pick(1, 21.5, 6.5, 4.0, 3.0)
    s2 = s1.resize("left", 1, 7, 2)
    assert s2.get("left", 1).half_w == 7.0 and s2.get("left", 1).half_h == 2.0
    s3 = s2.delete("right", 0)
    assert s3.numbers("right") == [1] and s3.current == 0 and s3.camera == "right"
    assert s3.undo() == s2
    assert s3.undo().undo() == s1
    assert s3.undo().undo().undo() == s0
    # navigation is not an edit: undo skips it
    assert s2.select(2, camera="left").next_point().undo() == s1
    empty = PickerState(image_size=(W, H))
    assert empty.undo() is empty and not empty.can_undo


def test_place_on_a_placed_number_moves_it_and_keeps_its_box():
    s = PickerState(image_size=(W, H)).place("left", 10, 5).resize("left", 0, 6, 6)
    s = s.place("left", 11, 9, point=0)
    assert s.get("left", 0) == Pick(0, 11.0, 9.0, 6.0, 6.0)
    assert s.numbers("left") == [0]


@pytest.mark.parametrize(
    "action, message",
    [
        (lambda s: s.place("left", W - 0.4, 5), r"outside the left image \(width 60, height 40"),
        (lambda s: s.place("left", 5, H), r"y=40.00\) is outside .* y in \[-0.5, 39.5\]"),
        (lambda s: s.place("left", -0.6, 5), "outside the left image"),
        (lambda s: s.place("middle", 5, 5), "camera must be one of"),
        (lambda s: s.place("left", np.nan, 5), "x must be finite"),
        (lambda s: s.move("right", 2, 5, 5), "point 2 is not placed in the right view"),
        (lambda s: s.resize("left", 0, 0, 3), "half_w and half_h must be positive"),
        (lambda s: s.select(3), r"must be in 0..2 \(n_points=3\)"),
        (lambda s: s.select(-1), "non-negative integer"),
        (lambda s: s.delete("right", 2), "not placed"),
    ],
)
def test_invalid_transitions_raise_clear_errors(action, message):
    s = _two_view_state()
    with pytest.raises(ValueError, match=message):
        action(s)


def test_edge_pixels_are_inside():
    s = PickerState(image_size=(W, H)).place("left", -0.5, -0.5).place("left", W - 0.5, H - 0.5)
    assert s.numbers("left") == [0, 1]


def test_picks_table_has_nan_for_a_number_missing_in_one_view():
    s = _two_view_state()
    right = s.to_frame("right")
    assert right.columns.tolist() == ["point", "frame", "x", "y", "half_w", "half_h", "half_size"]
    assert right["point"].dtype == np.int64 and right["x"].dtype == np.float64
    assert right["point"].tolist() == [0, 1, 2]
    np.testing.assert_array_equal(right.loc[2, ["x", "y", "half_w", "half_h"]].to_numpy(float), np.full(4, np.nan))
    np.testing.assert_array_equal(s.to_picks("left"), [[10, 5], [20, 6], [30, 7]])
    assert s.to_frame("left")["half_size"].tolist() == [4.0, 4.0, 4.0]
    assert s.to_frame("right", dropna=True)["point"].tolist() == [0, 1]
    with pytest.raises(ValueError, match=r"incomplete: right view lacks \[2\]"):
        s.check_complete()
    assert s.place("right", 33, 7).check_complete().is_complete
    with pytest.raises(ValueError, match="no markers picked"):
        PickerState().check_complete()


def test_json_round_trip_and_file_round_trip(tmp_path):
    s = _two_view_state().resize("right", 1, 5.25, 2.5)
    back = PickerState.from_json(s.to_json())
    assert back == s and back.history == ()
    data = json.loads(s.to_json())
    assert data["format"] == "wingphoto-picks" and data["picks"]["right"][1]["half_w"] == 5.25
    path = s.save(tmp_path / "sub" / "picks.json")
    assert PickerState.load(path) == s
    pd.testing.assert_frame_equal(PickerState.load(path).to_frame("right"), s.to_frame("right"))


def test_failed_save_keeps_the_previous_file(tmp_path, monkeypatch):
    path = tmp_path / "picks.json"
    old = _two_view_state()
    old.save(path)
    before = path.read_bytes()

    def boom(self):
        raise RuntimeError("disk full")

    monkeypatch.setattr(PickerState, "to_json", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        old.place("right", 33, 7).save(path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["picks.json"]


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="picks file .*nope.json not found"):
        PickerState.load(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="bad.json is not valid JSON"):
        PickerState.load(bad)
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(ValueError, match="not a wingphoto picks file"):
        PickerState.load(other)
    dup = json.loads(_two_view_state().to_json())
    dup["picks"]["left"].append(dup["picks"]["left"][0])
    with pytest.raises(ValueError, match=r"point\(s\) \[0\] more than once"):
        PickerState.from_json(json.dumps(dup))


def test_from_picks_arrays_skip_nan_rows():
    left = np.array([[10.0, 5.0], [20.0, 6.0], [30.0, 7.0]])
    right = np.array([[12.0, 5.0], [np.nan, np.nan], [32.0, 7.0]])
    s = PickerState.from_picks({"left": left, "right": right}, image_size=(W, H), half_size=(5, 5))
    np.testing.assert_array_equal(s.to_picks("left"), left)
    np.testing.assert_array_equal(s.to_picks("right"), right)
    assert s.missing() == {"left": [], "right": [1]}
    s2 = PickerState.from_picks({"left": s.to_frame("left")}, image_size=(W, H))
    assert s2.cameras == ("left",) and s2.picks_of("left") == s.picks_of("left")


# --------------------------------------------------------------------------- Viewport
def test_viewport_identity_at_zoom_one_and_formula_when_zoomed():
    vp = Viewport(W, H)
    assert vp.to_image(12.25, 7.5) == (12.25, 7.5)
    vp = Viewport(W, H, zoom=4.0, cx=20.0, cy=10.0)
    # x = cx + (u - (W - 1) / 2) / zoom
    assert vp.to_image(29.5, 19.5) == (20.0, 10.0)
    assert vp.to_image(33.5, 15.5) == (21.0, 9.0)
    u, v = vp.to_display(np.array([3.0, 25.0]), np.array([8.0, 12.0]))
    np.testing.assert_allclose(vp.to_image(u, v), [[3.0, 25.0], [8.0, 12.0]])
    # the display never leaves the image: the centre is clamped
    corner = Viewport(W, H, zoom=2.0, cx=0.0, cy=1000.0)
    assert (corner.cx, corner.cy) == (-0.5 + W / 4, H - 0.5 - H / 4)
    assert corner.extent[0] == pytest.approx(-0.5) and corner.extent[2] == pytest.approx(H - 0.5)
    with pytest.raises(ValueError, match="zoom must be at least 1"):
        Viewport(W, H, zoom=0.5)


# --------------------------------------------------------------------------- Picker view
def _frames(seed=0):
    rng = np.random.default_rng(seed)
    return rng.integers(0, 255, (3, H, W), dtype=np.uint8), rng.integers(0, 255, (3, H, W), dtype=np.uint8)


def test_picker_clicks_and_camera_toggle_fill_both_views():
    left, right = _frames()
    p = Picker(left, right, n_points=2, half_size=(4, 4))
    p.on_click(10.0, 5.0)
    p.on_click(20.0, 30.0)
    p.camera_toggle.value = "right"  # the ToggleButtons observer switches the view
    assert p.state.camera == "right" and p.state.current == 0
    p.on_click(11.0, 6.0)
    p.on_click(21.0, 31.0)
    assert p.state.is_complete
    np.testing.assert_array_equal(p.state.to_picks("left"), [[10, 5], [20, 30]])
    np.testing.assert_array_equal(p.state.to_picks("right"), [[11, 6], [21, 31]])
    # the figure shows the right view's rectangles at the right pixels (x horizontal)
    rects = [(r.get_x(), r.get_y(), r.get_width(), r.get_height()) for r in p.ax.patches]
    assert rects == [(7.0, 2.0, 8.0, 8.0), (17.0, 27.0, 8.0, 8.0)]
    assert p.ax.images[0].get_array().shape == (H, W)
    p.fig.canvas.draw()  # renders with Agg


def test_picker_click_under_zoom_converts_display_to_image():
    left, right = _frames()
    p = Picker(left, right)
    p.on_click(40.0, 20.0)
    p.select_point(0)
    p.set_zoom(4.0)  # centred on point 0 at (40, 20)
    assert p.zoom_slider.value == 4.0
    vp = p.viewport
    assert (vp.cx, vp.cy) == (40.0, 20.0)
    # display (29.5, 19.5) is the display centre -> the image pixel (40, 20); 4 px right = 1 image px
    p.arm_move()
    p.on_click(33.5, 17.5)
    assert p.state.get("left", 0)[:3] == (0, 41.0, 19.5)
    assert p.to_display(41.0, 19.5) == (33.5, 17.5)


def test_picker_drag_moves_then_resizes_one_undo_each():
    left, right = _frames()
    p = Picker(left, right, half_size=(5, 5))
    p.on_click(20.0, 20.0)
    before = p.state
    p.on_drag(21.0, 19.0, 25.0, 22.0)  # grab inside the rectangle: move by the drag
    assert p.state.get("left", 0)[:3] == (0, 24.0, 23.0)
    assert p.message == "point 0 moved to (24.0, 23.0)"
    assert p.state.undo() == before
    p.on_drag(29.0, 23.0, 31.0, 26.0)  # grab the right edge (x = 24 + 5): widen only
    assert p.state.get("left", 0)[3:5] == (7.0, 5.0)
    p.on_drag(24.0, 28.0, 25.0, 25.0)  # grab the bottom edge (y = 23 + 5): shorten only
    assert p.state.get("left", 0)[3:5] == (7.0, 2.0)
    p.on_drag(31.0, 25.0, 34.0, 28.0)  # the bottom-right corner (31, 25): both
    assert p.state.get("left", 0)[3:5] == (10.0, 5.0)
    for _ in range(4):
        p.undo_button.click()
    assert p.state == before


def test_picker_drag_on_empty_image_pans_when_zoomed():
    left, right = _frames()
    p = Picker(left, right)
    p.set_zoom(2.0)
    cx, cy = p.viewport.cx, p.viewport.cy
    p.on_drag(10.0, 10.0, 16.0, 14.0)
    assert (p.viewport.cx, p.viewport.cy) == (cx - 3.0, cy - 2.0)
    assert p.state.numbers("left") == []


def test_picker_buttons_delete_undo_save_load(tmp_path):
    left, right = _frames()
    path = tmp_path / "picks.json"
    p = Picker(left, right, picks_path=path)
    p.on_click(10.0, 5.0)
    p.on_click(20.0, 6.0)
    p.prev_button.click()
    assert p.state.current == 1 and p.point_box.value == 1
    p.delete_button.click()
    assert p.state.numbers("left") == [0]
    p.undo_button.click()
    assert p.state.numbers("left") == [0, 1]
    p.save_button.click()
    assert "saved 2 markers" in p.message and PickerState.load(path) == p.state
    p.delete(0)
    p.load_button.click()
    assert p.state.numbers("left") == [0, 1] and p.message.startswith("loaded")
    p.undo_button.click()  # loading is undoable
    assert p.state.numbers("left") == [1]
    p.move_button.click()  # point 0 (active after the delete) is no longer placed
    assert "not placed" in p.message


def test_picker_shows_errors_instead_of_raising():
    left, right = _frames()
    p = Picker(left, right, n_points=1)
    p.on_click(-3.0, 5.0)
    assert "outside the left image" in p.message and p.state.numbers("left") == []
    p.path_text.value = ""
    p.save_button.click()
    assert "no picks file" in p.message


def test_load_or_pick_headless_path(tmp_path, monkeypatch):
    left, right = _frames()
    path = tmp_path / "picks.json"
    monkeypatch.setenv("WINGPHOTO_HEADLESS", "1")
    with pytest.raises(FileNotFoundError, match="WINGPHOTO_HEADLESS is set but the picks file"):
        Picker.load_or_pick(left, right, picks_path=path)
    _two_view_state().save(path)
    p = Picker.load_or_pick(left, right, picks_path=path)
    assert p.state == _two_view_state()
    monkeypatch.setenv("WINGPHOTO_HEADLESS", "0")
    # outside a notebook nobody can click: a clear error that says how to make the file
    with pytest.raises(FileNotFoundError, match=r"no notebook to click in; make it with `wingphoto pick"):
        Picker.load_or_pick(left, right, picks_path=tmp_path / "new.json", n_points=4)
    monkeypatch.setattr("wingphoto.widgets.picker._in_kernel", lambda: True)
    fresh = Picker.load_or_pick(left, right, picks_path=tmp_path / "new.json", n_points=4)
    assert fresh.state.n_rows == 4 and fresh.state.numbers("left") == []
    small = np.zeros((2, 30, 30), np.uint8)
    with pytest.raises(ValueError, match=r"picks were made on left images of size \(60, 40\)"):
        Picker.load_or_pick(small, small, picks_path=path)
    with pytest.raises(ValueError, match="pass frames_right exactly"):
        Picker.load_or_pick(left, picks_path=path)


# --------------------------------------------------------------------------- ReviewState
def _tracks(n_frames=8, n_points=3):
    rows = []
    for cam, dx in (("left", 0.0), ("right", 2.0)):
        for f in range(n_frames):
            for p in range(n_points):
                rows.append((cam, f, p, 10.0 + 10 * p + f + dx, 20.0 + p, 0.95, "ok"))
    t = pd.DataFrame(rows, columns=["camera", "frame", "point", "x", "y", "score", "status"])
    t = t.astype({"frame": np.int64, "point": np.int64})
    bad = [("left", 3, 1, "flagged"), ("right", 3, 1, "lost"), ("left", 5, 2, "lost"), ("right", 6, 0, "flagged")]
    for cam, f, p, status in bad:
        m = (t["camera"] == cam) & (t["frame"] == f) & (t["point"] == p)
        t.loc[m, "status"] = status
        t.loc[m, "score"] = 0.2
        if status == "lost":
            t.loc[m, ["x", "y"]] = np.nan
    return t


def test_review_state_problems_navigation_and_correction():
    t = _tracks()
    s = ReviewState(t, image_size=(W, H))
    assert s.problems == ((3, 1), (5, 2), (6, 0))
    s = s.next_problem()
    assert (s.frame, s.point, s.camera) == (3, 1, "left")
    s = s.select(camera="right").next_problem(-1)  # wraps to the last one
    assert (s.frame, s.point, s.camera) == (6, 0, "right")
    s = s.goto(5).select(2, camera="left")
    s2 = s.correct("left", 2, 5, 17.25, 22.5)
    row = s2.tracks.query("camera == 'left' and frame == 5 and point == 2").iloc[0]
    assert (row.x, row.y, row.status) == (17.25, 22.5, "manual") and np.isnan(row.score)
    assert s2.problems == ((3, 1), (6, 0))
    assert s2.corrections == (Correction("left", 2, 5, 17.25, 22.5),)
    # the source is untouched, undo restores the previous state
    assert t.loc[(t["camera"] == "left") & (t["frame"] == 5) & (t["point"] == 2), "status"].item() == "lost"
    back = s2.undo()
    assert back.corrections == () and back.problems == s.problems and (back.frame, back.point) == (5, 2)
    assert ReviewState(t.iloc[:0]).next_problem().problems == ()
    # navigation reuses the corrected tracks instead of re-applying the log
    assert s2.goto(0).select(1).next_problem().tracks is s2.tracks


@pytest.mark.parametrize(
    "action, message",
    [
        (lambda s: s.goto(8), r"frame must be in 0..7"),
        (lambda s: s.correct("left", 0, 2, W + 1.0, 3.0), "outside the left image"),
        (lambda s: s.correct("middle", 0, 2, 1.0, 3.0), "camera must be one of"),
        (lambda s: s.correct("left", 0, -1, 1.0, 3.0), "frame must be a non-negative integer"),
        (lambda s: s.select(camera="top"), "camera must be one of"),
    ],
)
def test_review_state_validation(action, message):
    s = ReviewState(_tracks(), image_size=(W, H))
    with pytest.raises(ValueError, match=message):
        action(s)


def test_review_state_rejects_a_table_without_track_columns():
    with pytest.raises(ValueError, match=r"lacks columns \['status'\]"):
        ReviewState(_tracks().drop(columns="status"))


def test_apply_corrections_last_wins_and_adds_absent_rows():
    t = _tracks()
    log = [("left", 0, 1, 1.0, 2.0), ("left", 0, 1, 3.0, 4.0), ("right", 7, 9, 5.0, 6.0)]
    out = apply_corrections(t, log)
    assert len(out) == len(t) + 1
    assert out.query("camera == 'left' and frame == 1 and point == 0")[["x", "y"]].to_numpy().tolist() == [[3.0, 4.0]]
    new = out.query("point == 7").iloc[0]
    assert (new.camera, new.frame, new.x, new.status) == ("right", 9, 5.0, "manual")
    assert out.dtypes.to_dict() == t.dtypes.to_dict()
    # the tracker's extra columns follow the correction
    t2 = t.assign(x_pix=np.round(t["x"]), y_pix=np.round(t["y"]), reason="")
    row = apply_corrections(t2, [("left", 0, 1, 3.4, 4.6)]).query("camera == 'left' and frame == 1 and point == 0")
    assert row[["x_pix", "y_pix"]].to_numpy().tolist() == [[3.0, 5.0]]


@pytest.mark.parametrize("suffix", [".csv", ".json"])
def test_corrections_file_round_trip(tmp_path, suffix):
    log = (Correction("left", 2, 5, 17.123456789012345, 22.5), Correction("right", 0, 6, 1.0, 0.25))
    path = write_corrections(log, tmp_path / f"log{suffix}")
    assert read_corrections(path) == log
    s = ReviewState(_tracks()).load_corrections(path)
    assert s.corrections == log and s.undo().corrections == ()


def test_corrections_file_errors(tmp_path):
    with pytest.raises(ValueError, match="must end in .csv or .json"):
        write_corrections([], tmp_path / "log.txt")
    with pytest.raises(FileNotFoundError, match="corrections file .*missing.csv not found"):
        read_corrections(tmp_path / "missing.csv")
    (tmp_path / "bad.csv").write_text("camera,frame\nleft,1\n")
    with pytest.raises(ValueError, match="lacks columns"):
        read_corrections(tmp_path / "bad.csv")
    (tmp_path / "bad.json").write_text(json.dumps({"format": "x"}))
    with pytest.raises(ValueError, match="not a wingphoto corrections file"):
        read_corrections(tmp_path / "bad.json")


# --------------------------------------------------------------------------- TrackReview view
def _hold_position(frames, tracks, points, frame):
    """A deterministic stand-in tracker: the corrected position is held for later frames."""
    out = tracks.copy()
    for p in points:
        start = out[(out["frame"] == frame) & (out["point"] == p)].iloc[0]
        later = (out["frame"] > frame) & (out["point"] == p)
        out.loc[later, ["x", "y"]] = (start.x, start.y)
        out.loc[later, "status"] = "ok"
        out.loc[later, "score"] = 1.0
    return out


def _stack():
    rng = np.random.default_rng(3)
    return {c: rng.integers(0, 255, (8, H, W), dtype=np.uint8) for c in ("left", "right")}


def test_review_next_problem_click_corrects_and_retracks_forward():
    t = _tracks()
    calls = []

    def retrack(frames, tracks, points, frame):
        calls.append((frames.shape, set(tracks["camera"]), points, frame))
        return _hold_position(frames, tracks, points, frame)

    r = TrackReview(_stack(), t, retrack=retrack)
    r.next_problem_button.click()
    assert (r.state.frame, r.state.point, r.state.camera) == (3, 1, "left")
    assert r.frame_slider.value == 3 and r.problem_list.value == (3, 1, "left")
    r.on_click(24.0, 21.5)
    assert calls == [((8, H, W), {"left"}, [1], 3)]
    left = r.state.tracks.query("camera == 'left' and point == 1").set_index("frame")
    assert left.loc[3, "status"] == "manual" and (left.loc[3, "x"], left.loc[3, "y"]) == (24.0, 21.5)
    assert (left.loc[4:, ["x", "y"]].to_numpy() == [24.0, 21.5]).all() and (left.loc[4:, "status"] == "ok").all()
    assert (left.loc[:2, "x"].to_numpy() == [20.0, 21.0, 22.0]).all()  # earlier frames untouched
    right = r.state.tracks.query("camera == 'right'")
    pd.testing.assert_frame_equal(right.reset_index(drop=True), t.query("camera == 'right'").reset_index(drop=True))
    r.undo_button.click()  # one undo reverts the correction and its re-tracking
    pd.testing.assert_frame_equal(r.state.tracks, t)


def test_review_log_replays_to_the_same_tracks(tmp_path):
    t = _tracks()
    stack = _stack()
    r = TrackReview(stack, t, retrack=_hold_position, corrections_path=tmp_path / "log.csv")
    r.next_problem()
    r.on_click(24.0, 21.5)
    r.camera_toggle.value = "right"
    r.frame_slider.value = 3
    r.point_box.value = 1
    r.on_click(25.0, 21.0)
    r.problem_list.value = (5, 2, "left")  # choosing an item of the list goes there (and to its camera)
    assert (r.state.frame, r.state.point, r.state.camera) == (5, 2, "left")
    r.correct(2, 25.0, 22.0)
    r.save_button.click()
    assert "saved 3 corrections" in r.message
    log = read_corrections(tmp_path / "log.csv")
    assert log == r.state.corrections
    replayed = replay_corrections(t, log, retrack=_hold_position, frames=stack)
    reviewed = r.state.tracks.sort_values(["camera", "frame", "point"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(replayed, reviewed)
    # without re-tracking, replay gives the corrected positions only
    plain = replay_corrections(t, log)
    assert (plain["status"] == "manual").sum() == 3
    # loading the log into a fresh review applies it
    r2 = TrackReview(stack, t, retrack=False, corrections_path=tmp_path / "log.csv")
    r2.load_button.click()
    assert r2.state.corrections == log and r2.message.startswith("loaded 3")


def test_review_drag_a_point_corrects_it_and_zoom_converts_coordinates():
    t = _tracks()
    r = TrackReview(_stack()["left"], t.query("camera == 'left'"), retrack=False)
    r.goto(2)
    r.select_point(1)
    r.set_zoom(2.0)  # centred on point 1 at frame 2: (22, 21)
    assert (r.viewport.cx, r.viewport.cy) == (22.0, 21.0)
    r.select_point(0)  # point 0 at (12, 20) is near the left edge: the centre is clamped
    assert (r.viewport.cx, r.viewport.cy) == (-0.5 + W / 4, 20.0)
    u, v = r.to_display(32.0, 21.0)  # point 2 is drawn at (32, 21)
    r.on_drag(u, v, u + 4.0, v - 2.0)  # 4 display px = 2 image px at zoom 2
    assert r.state.point == 2
    assert r.state.corrections == (Correction("left", 2, 2, 34.0, 20.0),)
    r.fig.canvas.draw()


def test_review_keeps_the_correction_when_retracking_fails():
    def broken(frames, tracks, points, frame):
        raise RuntimeError("template left the image")

    r = TrackReview(_stack(), _tracks(), retrack=broken)
    r.next_problem()
    r.on_click(24.0, 21.5)
    assert len(r.state.corrections) == 1 and "re-tracking failed: template left the image" in r.message
    r.retrack_check.value = False
    r.on_click(25.0, 21.5)
    assert "re-tracked" not in r.message and len(r.state.corrections) == 2


def test_review_uses_track_retrack_from_when_available(monkeypatch):
    fake = types.ModuleType("wingphoto.track")
    fake.retrack_from = _hold_position
    monkeypatch.setitem(sys.modules, "wingphoto.track", fake)
    r = TrackReview(_stack(), _tracks())
    # the real one, without a progress bar (a bar left in a notebook's output stays at 0 %)
    assert r.retrack.func is _hold_position and r.retrack.keywords == {"progress": False} and r.retrack_check.value
    assert TrackReview(_stack(), _tracks(), retrack=False).retrack is None


def test_review_errors_are_shown_not_raised(tmp_path):
    r = TrackReview(_stack(), _tracks(), retrack=False)
    r.on_click(-5.0, 3.0)
    assert "outside the left image" in r.message and r.state.corrections == ()
    r.save_button.click()
    assert "no corrections file" in r.message
    r.path_text.value = str(tmp_path / "none.json")
    r.load_button.click()
    assert "not found" in r.message
    with pytest.raises(ValueError, match=r"frames lacks cameras \['right'\]"):
        TrackReview({"left": _stack()["left"]}, _tracks())


def test_state_module_imports_no_widget_or_plotting_library():
    import ast
    import pathlib

    import wingphoto.widgets.state as state

    tree = ast.parse(pathlib.Path(state.__file__).read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            names.add(node.module.split(".")[0])
    assert not names & {"ipywidgets", "matplotlib", "IPython", "ipympl"}


def test_review_load_or_review_replays_the_saved_log(tmp_path):
    t = _tracks()
    stack = _stack()
    path = tmp_path / "log.json"
    fresh = TrackReview.load_or_review(stack, t, corrections_path=path, retrack=_hold_position)
    assert fresh.state.corrections == () and fresh.state.problems == ((3, 1), (5, 2), (6, 0))
    r = TrackReview(stack, t, retrack=_hold_position, corrections_path=path)
    r.next_problem()
    r.on_click(24.0, 21.5)
    r.goto(5)
    r.select_point(2)
    r.on_click(30.0, 22.0)
    r.save()
    again = TrackReview.load_or_review(stack, t, corrections_path=path, retrack=_hold_position)
    pd.testing.assert_frame_equal(again.state.tracks, r.state.tracks)
    assert again.message.endswith("replayed")
    plain = TrackReview.load_or_review(stack, t, corrections_path=path, retrack=False)
    pd.testing.assert_frame_equal(plain.state.tracks, apply_corrections(t, r.state.corrections))
    (tmp_path / "bad.json").write_text("[]")
    with pytest.raises(ValueError, match="not a wingphoto corrections file"):
        TrackReview.load_or_review(stack, t, corrections_path=tmp_path / "bad.json")


# --------------------------------------------------------------------------- picker, as a person uses it
def test_click_on_background_never_moves_a_placed_marker():
    left, right = _frames()
    p = Picker(left, right, n_points=2, half_size=(3, 3))
    p.on_click(10.0, 5.0)
    p.on_click(30.0, 20.0)
    placed = p.state
    p.on_click(45.0, 30.0)  # every marker is placed: the click is refused, with a reason
    assert p.state == placed
    assert "all 2 markers are placed in the left view" in p.message
    assert "this click was ignored" in p.status.value
    p.arm_move()
    p.on_click(45.0, 30.0)  # after Move, the same click does move the active marker
    assert p.state.get("left", p.state.current)[1:3] == (45.0, 30.0)


def test_two_markers_on_the_same_spot_are_refused():
    s = PickerState(image_size=(W, H), half_size=(3, 3)).place("left", 10, 5)
    with pytest.raises(ValueError, match=r"point 0 is already at \(10.0, 5.0\) in the left view"):
        s.place("left", 10.4, 5.2)
    s = s.place("left", 20, 5)
    with pytest.raises(ValueError, match="point 0 is already at"):
        s.move("left", 1, 10.0, 5.5)
    assert s.place("right", 10, 5).numbers("right") == [0]  # the same spot in the other view is fine


def test_new_boxes_shrink_so_they_do_not_overlap_neighbours():
    s = PickerState(image_size=(W, H), half_size=(10, 10))
    s = s.place("left", 10, 10).place("left", 22, 12)  # 12 px apart: halves of 6 do not overlap
    assert [(p.half_w, p.half_h) for p in s.left] == [(6.0, 6.0), (6.0, 6.0)]
    s = s.resize("left", 1, 8, 8).place("left", 50, 30)  # a box the user sized is kept
    assert s.get("left", 1)[3:5] == (8.0, 8.0)
    assert s.get("left", 2)[3:5] == (10.0, 10.0)  # far from the others: the default
    s = s.place("left", 12, 11)  # 2 px from point 0: shrunk, but not below MIN_AUTO_HALF
    assert s.get("left", 3)[3:5] == (3.0, 3.0)


def test_coordinate_readout_is_in_image_pixels_when_zoomed():
    left, right = _frames()
    p = Picker(left, right, half_size=(3, 3))
    p.set_zoom(4.0)
    u, v = p.to_display(12.25, 7.5)
    assert p.ax.format_coord(u, v) == "left x=12.25 y=7.50 px (zoom 4)"


def test_status_line_sits_above_the_figure_and_sliders_send_one_event_per_drag():
    left, right = _frames()
    p = Picker(left, right, half_size=(3, 3))
    children = list(p.widget.children)
    assert children.index(p.status) < children.index(p._canvas_widget)
    assert p.box_slider.continuous_update is False and p.zoom_slider.continuous_update is False
    p.on_click(10.0, 10.0)
    p.select_point(0)
    n_undo = len(p.state.history)
    p.box_slider.value = 7  # one release of the slider = one value = one undo step
    assert len(p.state.history) == n_undo + 1
    assert p.state.get("left", 0)[3:5] == (7.0, 7.0)
    assert p.state.undo().get("left", 0)[3:5] == (3.0, 3.0)


def test_numbers_are_written_beside_their_own_centre():
    left, right = _frames()
    p = Picker(left, right, half_size=(8, 8))
    p.on_click(20.0, 20.0)
    p.on_click(40.0, 20.0)
    texts = {t.get_text(): t.xy for t in p.ax.texts}
    assert texts == {"0": (20.0, 20.0), "1": (40.0, 20.0)}  # anchored at the centre, offset a few points


def test_static_image_says_how_to_click(monkeypatch):
    left, right = _frames()
    p = Picker(left, right)
    assert p._png is not None  # Agg in tests: the static fallback
    assert "%matplotlib widget" in p.status.value


def test_headless_display_is_a_figure_of_numbered_picks(monkeypatch):
    from matplotlib.figure import Figure

    left, right = _frames()
    p = Picker(left, right, state=_two_view_state())
    fig = p.static_figure()
    assert isinstance(fig, Figure) and len(fig.axes) == 2
    for ax, cam, n in zip(fig.axes, ("left", "right"), (3, 2)):
        assert ax.get_title() == f"{cam} view, frame 0: {n} markers picked"
        assert sorted(t.get_text() for t in ax.texts) == [str(k) for k in range(n)]
    shown = []
    monkeypatch.setattr("IPython.display.display", lambda obj: shown.append(obj))
    monkeypatch.setenv("WINGPHOTO_HEADLESS", "1")
    p._ipython_display_()
    from IPython.display import Image

    assert isinstance(shown[0], Image) and shown[0].data[:8] == b"\x89PNG\r\n\x1a\n"


def test_picks_remember_the_frame_they_were_picked_in(tmp_path):
    left, right = _frames()
    p = Picker(left, right, frame=2, half_size=(3, 3))
    p.on_click(10.0, 10.0)
    p.set_camera("right")
    p.on_click(12.0, 10.0)
    p.save(tmp_path / "p.json")
    from wingphoto.picks import load_picks

    assert load_picks(tmp_path / "p.json", "right")["frame"].tolist() == [2]
    p.save(tmp_path / "p.csv")
    assert PickerState.load(tmp_path / "p.csv").to_table().equals(p.state.to_table())


def test_review_lost_point_is_ringed_where_last_seen_and_zoom_centres_there():
    t = _tracks()
    lost = (t["camera"] == "left") & (t["point"] == 2) & (t["frame"] >= 4)
    t.loc[lost, ["x", "y"]] = np.nan
    t.loc[lost, "status"] = "lost"
    r = TrackReview(_stack(), t, retrack=False)
    r.goto(6)
    r.select_point(2)
    last = (t.query("camera == 'left' and point == 2 and frame == 3")[["x", "y"]].to_numpy()[0])
    r.set_zoom(4.0)
    assert (r.viewport.cx, r.viewport.cy) == pytest.approx(tuple(last))  # not the image middle
    notes = [a for a in r.ax.texts if a.get_text() == "2 lost: last seen here"]
    assert len(notes) == 1 and notes[0].xy == pytest.approx(r.to_display(*last))


def test_review_problem_list_highlights_only_the_camera_shown():
    t = _tracks()
    only_right = (t["camera"] == "right") & (t["frame"] == 2) & (t["point"] == 0)
    t.loc[only_right, "status"] = "flagged"
    r = TrackReview(_stack(), t, retrack=False)
    labels = [label for label, _ in r.problem_list.options]
    assert any(label.startswith("frame 2, point 0, right: flagged") for label in labels)
    r.goto(2)
    r.select_point(0)
    assert r.state.camera == "left" and r.problem_list.value is None  # a right-view problem
    r.set_camera("right")
    assert r.problem_list.value == (2, 0, "right")
    children = list(r.widget.children)
    assert children.index(r.status) < len(children) - 1  # status above the figure row


# --------------------------------------------------------------------------- wingphoto pick (a matplotlib window)
def _window(tmp_path, **kwargs):
    from matplotlib.figure import Figure
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from wingphoto.widgets.window import WindowPicker

    left, right = _frames()
    fig = Figure(figsize=(8, 4))
    FigureCanvasAgg(fig)
    return WindowPicker({"left": left[0], "right": right[0]}, tmp_path / "picks.json", figure=fig, **kwargs)


def test_window_picker_same_rules_as_the_notebook_picker(tmp_path):
    w = _window(tmp_path, n_points=2, half_size=3)
    w.click("left", 10.0, 5.0)
    w.click("left", 30.0, 20.0)
    w.click("left", 45.0, 30.0)  # all placed: refused, nothing moves
    assert w.state.to_picks("left").tolist() == [[10.0, 5.0], [30.0, 20.0]]
    assert "all 2 markers are placed in the left view" in w.message
    w.click("right", 12.0, 6.0)  # the other panel starts at its first missing number
    w.click("right", 12.2, 6.1)  # the same spot as point 0: refused
    assert "point 0 is already at" in w.message
    w.click("right", 31.0, 21.0)
    assert w.state.is_complete
    texts = sorted((t.get_text(), t.xy) for t in w.axes["right"].texts)
    assert texts == [("0", (12.0, 6.0)), ("1", (31.0, 21.0))]
    w.on_key("s")
    from wingphoto.picks import load_picks

    assert load_picks(tmp_path / "picks.json", "right")[["x", "y"]].to_numpy().tolist() == [[12.0, 6.0], [31.0, 21.0]]


def test_window_picker_drag_moves_and_edge_resizes_one_side(tmp_path):
    w = _window(tmp_path, half_size=5)
    w.click("left", 20.0, 20.0)
    scale = w._screen_per_px("left")
    w.on_press("left", 21.0, 19.0)  # inside the box: move by the drag
    w.on_motion(21.0 + 2, 19.0 + 1)
    w.on_release(21.0 + 4, 19.0 + 3)
    assert w.state.get("left", 0)[1:3] == (24.0, 23.0)
    w.on_press("left", 29.0, 23.0)  # the right edge (x = 24 + 5): widen, height kept
    w.on_release(29.0 + 40 / scale + 2, 23.5)
    hw, hh = w.state.get("left", 0)[3:5]
    assert hw == pytest.approx(5.0 + 40 / scale + 2) and hh == 5.0
    w.on_key("u")
    w.on_key("u")
    assert w.state.get("left", 0)[1:5] == (20.0, 20.0, 5.0, 5.0)


def test_window_picker_keys_and_zoom(tmp_path):
    w = _window(tmp_path, half_size=4)
    w.click("left", 10.0, 10.0)
    w.on_key("p")
    assert w.state.current == 0
    w.on_key("+", camera="left")
    assert w.state.get("left", 0)[3:5] == (5.0, 5.0)
    w.on_key("m", camera="left")
    w.click("left", 40.0, 30.0)
    assert w.state.get("left", 0)[1:3] == (40.0, 30.0)
    w.on_key("d", camera="left")
    assert w.state.numbers("left") == []
    w.zoom("left", 4.0, 40.0, 30.0)
    (x0, x1), (y1, y0) = w.axes["left"].get_xlim(), w.axes["left"].get_ylim()
    assert x1 - x0 == pytest.approx(15.0) and y0 <= 30.0 <= y1


def test_cli_pick_without_display_says_how_to_pick(tmp_path, monkeypatch, capsys):
    import tifffile

    from wingphoto.cli import main

    rng = np.random.default_rng(5)
    for cam in ("left", "right"):
        tifffile.imwrite(tmp_path / f"{cam}.tif", rng.integers(0, 255, (4, H, W), dtype=np.uint8),
                         photometric="minisblack")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = tmp_path / "picks.json"
    code = main(["pick", str(tmp_path / "left.tif"), str(tmp_path / "right.tif"), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1 and not out.exists()
    assert "no display" in err and "camera,point,frame,x,y,half_w,half_h" in err and "04_picking_markers" in err
    assert main(["pick", str(tmp_path / "left.tif"), "--out", str(tmp_path / "p.txt")]) == 1
    assert "must end in .json or .csv" in capsys.readouterr().err
    assert main(["pick", str(tmp_path / "left.tif"), "--out", str(out), "--frame", "9"]) == 1
    assert "--frame 9 is outside" in capsys.readouterr().err


def test_window_picker_routes_real_matplotlib_events(tmp_path):
    """Mouse and key events as a GUI backend delivers them: press/move/release in screen px."""
    from matplotlib.backend_bases import KeyEvent, MouseEvent

    w = _window(tmp_path, n_points=2, half_size=3)
    canvas = w.fig.canvas
    w.fig.canvas.draw()

    def screen(cam, x, y):
        return w.axes[cam].transData.transform((x, y))

    def mouse(kind, cam, x, y):
        u, v = screen(cam, x, y)
        MouseEvent(kind, canvas, u, v, button=1)._process()

    for cam, pts in (("left", [(10.0, 5.0), (30.0, 20.0)]), ("right", [(12.0, 6.0), (31.0, 21.0)])):
        for x, y in pts:
            mouse("button_press_event", cam, x, y)
            mouse("button_release_event", cam, x, y)
    assert w.state.is_complete
    np.testing.assert_allclose(w.state.to_picks("right"), [[12.0, 6.0], [31.0, 21.0]], atol=0.05)
    mouse("button_press_event", "right", 31.5, 21.5)  # drag point 1 by +5 px in x (inside its box)
    for dx in (1.0, 3.0, 5.0):
        mouse("motion_notify_event", "right", 31.5 + dx, 21.5)
    mouse("button_release_event", "right", 36.5, 21.5)
    np.testing.assert_allclose(w.state.get("right", 1)[1:3], (36.0, 21.0), atol=0.05)
    u, v = screen("right", 20.0, 20.0)
    KeyEvent("key_press_event", canvas, "u", u, v)._process()
    np.testing.assert_allclose(w.state.get("right", 1)[1:3], (31.0, 21.0), atol=0.05)
    KeyEvent("key_press_event", canvas, "s", u, v)._process()
    assert (tmp_path / "picks.json").is_file() and "saved 4 picks" in w.message


def test_cli_pick_in_a_real_tk_window(tmp_path):
    """`wingphoto pick` opens a real Tk window (under Xvfb); clicks injected by Tk land on the markers."""
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    samples = repo / "data-samples" / "flapping"
    if shutil.which("xvfb-run") is None:
        pytest.skip("xvfb-run not installed (apt-get install xvfb): no display for a real window")
    if not samples.is_dir():
        pytest.skip("data-samples absent")
    try:
        import tkinter  # noqa: F401
    except ImportError:
        pytest.skip("tkinter absent: no GUI backend for matplotlib")
    out = tmp_path / "picks.json"
    script = tmp_path / "drive.py"
    script.write_text(f'''
import sys
import matplotlib.pyplot as plt
import pandas as pd
from wingphoto.cli import main
truth = pd.read_csv({str(samples / "truth_tracks.csv")!r}).query("frame == 0 and point < 2")
show = plt.show
def drive(*args, **kwargs):
    fig = plt.gcf()
    tk = fig.canvas.get_tk_widget()
    waited = [0]
    def act():
        if not tk.winfo_viewable() and waited[0] < 300:  # a busy machine maps the window late
            waited[0] += 1
            tk.after(200, act)
            return
        for ax, cam in zip(fig.axes, ("left", "right")):
            for r in truth[truth.camera == cam].itertuples():
                tk.update()  # the window may still be settling its size: measure before each click
                fig.canvas.draw()
                u, v = ax.transData.transform((r.x, r.y))
                y = fig.bbox.height - v  # Tk's y points down
                for kind in ("<ButtonPress-1>", "<ButtonRelease-1>"):
                    tk.event_generate(kind, x=int(round(u)), y=int(round(y)))
                tk.update()
        tk.event_generate("<KeyPress>", keysym="q", x=5, y=5)
        tk.update()
    tk.after(2000, act)
    show(*args, **kwargs)
plt.show = drive
sys.exit(main(["pick", {str(samples / "left")!r}, {str(samples / "right")!r}, "--out", {str(out)!r}, "--n-points", "2"]))
''')
    env = {k: v for k, v in os.environ.items() if k not in ("MPLBACKEND", "DISPLAY")}
    run = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", sys.executable, str(script)],
                         capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "wrote" in run.stdout and "2 markers left, 2 markers right" in run.stdout
    import pandas as pd

    from wingphoto.picks import read_picks

    truth = pd.read_csv(samples / "truth_tracks.csv").query("frame == 0 and point < 2")
    got = read_picks(out).merge(truth, on=["camera", "point"], suffixes=("", "_true"))
    assert len(got) == 4
    # one screen pixel of the window is about 0.9 image px: every click within a screen pixel
    assert np.hypot(got["x"] - got["x_true"], got["y"] - got["y_true"]).max() < 1.0
