"""Picks files (wingphoto.picks): JSON and CSV formats, round trips, refusals."""
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from wingphoto import picks as P


def _table(rng, n=5):
    rows = []
    for cam in ("left", "right"):
        xy = rng.uniform(20, 200, size=(n, 2))
        for k in range(n):
            rows.append((cam, k, int(k % 3), xy[k, 0], xy[k, 1], 6.0 + k, 7.5))
    return pd.DataFrame(rows, columns=list(P.TABLE_COLUMNS))


@pytest.mark.parametrize("suffix", [".json", ".csv"])
def test_round_trip_is_exact(tmp_path, suffix):
    rng = np.random.default_rng(1)
    t = _table(rng)
    path = P.write_picks(t, tmp_path / f"p{suffix}")
    back = P.read_picks(path)
    pd.testing.assert_frame_equal(back, P.check_picks(t))
    # float64 positions survive the text format bit for bit
    assert np.array_equal(back["x"].to_numpy(), t["x"].to_numpy())
    one = P.load_picks(path, "right")
    assert list(one.columns) == list(P.PICKS_COLUMNS) + ["half_size"]
    assert one["frame"].tolist() == [0, 1, 2, 0, 1]
    assert one["half_size"].tolist() == [7.5, 7.5, 8.0, 9.0, 10.0]
    assert one["point"].dtype == np.int64 and one["frame"].dtype == np.int64


def test_version_1_file_without_frame_loads_with_frame_0(tmp_path):
    doc = {"format": "wingphoto-picks", "version": 1, "cameras": ["left", "right"],
           "picks": {"left": [{"point": 0, "x": 10.0, "y": 11.0, "half_w": 5.0, "half_h": 5.0}],
                     "right": [{"point": 0, "x": 12.0, "y": 11.0, "half_w": 5.0, "half_h": 5.0}]}}
    path = tmp_path / "old.json"
    path.write_text(json.dumps(doc))
    t = P.load_picks(path, "left")
    assert t["frame"].tolist() == [0] and t["x"].tolist() == [10.0]


def test_csv_without_frame_and_half_sizes_uses_defaults(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("camera,point,x,y\nleft,1,30,40\nleft,0,10.25,20\nright,0,11,20\n")
    t = P.load_picks(path, "left")
    assert t["point"].tolist() == [0, 1]
    assert t["frame"].tolist() == [0, 0]
    assert t["half_w"].tolist() == [P.DEFAULT_HALF_SIZE] * 2
    assert t["x"].tolist() == [10.25, 30.0]


def test_sample_picks_load():
    path = Path(__file__).resolve().parents[1] / "data-samples" / "flapping" / "picks.json"
    if not path.is_file():
        pytest.skip("data-samples/flapping/picks.json absent")
    doc = json.loads(path.read_text())
    for cam in ("left", "right"):
        t = P.load_picks(path, cam)
        assert t["x"].tolist() == [p["x"] for p in doc["picks"][cam]]


def test_missing_camera_is_named(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("camera,point,frame,x,y\nleft,0,0,10,20\n")
    with pytest.raises(ValueError, match=r"no picks for the right camera \(it has picks for left only\)"):
        P.load_picks(path, "right")


def test_nan_pick_names_file_and_point(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("camera,point,frame,x,y\nleft,0,0,10,20\nleft,3,0,nan,20\n")
    with pytest.raises(ValueError, match=r"p\.csv: left point 3 has no valid position"):
        P.read_picks(path)
    path.write_text("camera,point,frame,x,y\nleft,0,0,10,20\nleft,3,0,,20\n")
    with pytest.raises(ValueError, match=r"left point 3 has no valid position"):
        P.read_picks(path)


def test_two_picks_on_the_same_spot_are_refused(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("camera,point,frame,x,y\nleft,0,0,10,20\nleft,1,0,10.3,20.2\nright,0,0,10,20\n")
    with pytest.raises(ValueError, match=r"points 0 and 1 of the left view are on the same spot"):
        P.read_picks(path)
    # the same spot in different views is fine
    path.write_text("camera,point,frame,x,y\nleft,0,0,10,20\nright,0,0,10,20\n")
    assert len(P.read_picks(path)) == 2


def test_repeated_number_is_refused(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("camera,point,frame,x,y\nleft,2,0,10,20\nleft,2,0,50,20\n")
    with pytest.raises(ValueError, match=r"point\(s\) \[2\] more than once"):
        P.read_picks(path)


@pytest.mark.parametrize("text, match", [
    ("", "is empty"),
    ("point,x,y\n0,1,2\n", r"lacks columns \['camera'\]"),
    ("camera,point,frame,x,y,speed\nleft,0,0,1,2,3\n", r"unknown columns \['speed'\]"),
    ("camera,point,frame,x,y\ntop,0,0,1,2\n", "camera must be 'left' or 'right'"),
    ("camera,point,frame,x,y\nleft,-1,0,1,2\n", "point must be a non-negative integer"),
    ("camera,point,frame,x,y\nleft,0,1.5,1,2\n", "frame must be a non-negative integer"),
    ("camera,point,frame,x,y,half_w,half_h\nleft,0,0,1,2,0,3\n", "half sizes must be positive"),
    ("camera,point,frame,x,y,half_w\nleft,0,0,1,2,3\n", "both half_w and half_h"),
])
def test_bad_csv_is_refused_with_the_reason(tmp_path, text, match):
    path = tmp_path / "p.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        P.load_picks(path, "left")


@pytest.mark.parametrize("doc, match", [
    ({"points": [[1, 2]]}, "not a wingphoto picks file.*docs/picks.md"),
    ({"format": "wingphoto-picks", "version": 9, "picks": {}}, "version 9"),
    ({"format": "wingphoto-picks", "version": 2, "picks": []}, "'picks' must be an object"),
    ({"format": "wingphoto-picks", "version": 2, "picks": {"left": [{"point": 0, "x": 1}]}}, r"lacks \['y'\]"),
    ({"format": "wingphoto-picks", "version": 2, "picks": {"top": []}}, "unknown camera 'top'"),
])
def test_bad_json_is_refused_with_the_reason(tmp_path, doc, match):
    path = tmp_path / "p.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=match):
        P.load_picks(path, "left")


def test_missing_file_says_how_to_make_one(tmp_path):
    with pytest.raises(FileNotFoundError, match="wingphoto pick FRAMES_LEFT FRAMES_RIGHT"):
        P.load_picks(tmp_path / "new.json", "left")


def test_binary_and_folder_are_refused(tmp_path):
    path = tmp_path / "p.json"
    path.write_bytes(b"\xff\xfe\x00\x81" * 10)
    with pytest.raises(ValueError, match="not text"):
        P.read_picks(path)
    with pytest.raises(ValueError, match="is a folder"):
        P.read_picks(tmp_path)


def test_pipeline_load_picks_delegates(tmp_path):
    from wingphoto import pipeline

    path = tmp_path / "p.csv"
    path.write_text("camera,point,frame,x,y\nleft,0,4,10,20\n")
    t = pipeline.load_picks(path, "left")
    assert t["frame"].tolist() == [4]


def test_write_refuses_bad_suffix_and_keeps_old_file(tmp_path):
    rng = np.random.default_rng(2)
    path = P.write_picks(_table(rng), tmp_path / "p.json")
    before = path.read_bytes()
    bad = _table(rng)
    bad.loc[1, "x"] = np.nan
    with pytest.raises(ValueError, match="left point 1 has no valid position"):
        P.write_picks(bad, path)
    assert path.read_bytes() == before
    with pytest.raises(ValueError, match="must end in .json or .csv"):
        P.write_picks(_table(rng), tmp_path / "p.txt")
