"""Tests of wingphoto.corrections: the one corrections log (apply, save, load) and its bad input."""
import numpy as np
import pandas as pd
import pytest

from wingphoto.corrections import apply_corrections, load_corrections, save_corrections
from wingphoto.io import read_tracks_csv, write_tracks_csv


def _tracks():
    return pd.DataFrame({"camera": "left", "frame": np.repeat([0, 1, 2], 2), "point": np.tile([0, 1], 3),
                         "x": [5.0, 9.0, 6.0, 10.0, 7.0, 11.0], "y": 4.0, "score": 0.95, "status": "ok",
                         "x_pix": [5.0, 9.0, 6.0, 10.0, 7.0, 11.0], "y_pix": 4.0, "reason": "", "sigma": 0.02})


@pytest.mark.parametrize("suffix", [".csv", ".json"])
def test_round_trip_and_replay(tmp_path, suffix):
    log = [(0, 1, 6.25, 4.5), (1, 2, np.nan, np.nan), (0, 1, 6.5, 4.75)]
    path = save_corrections(log, tmp_path / f"c{suffix}")
    c = load_corrections(path)
    assert c[["point", "frame"]].to_numpy().tolist() == [[0, 1], [1, 2], [0, 1]]
    out = apply_corrections(_tracks(), c)
    r = out[(out.frame == 1) & (out.point == 0)].iloc[0]
    assert (r.x, r.y, r.status, r.reason) == (6.5, 4.75, "manual", "")  # the later correction wins
    lost = out[(out.frame == 2) & (out.point == 1)].iloc[0]
    assert lost.status == "lost" and np.isnan(lost.x) and lost.reason == "manual"


def test_apply_on_tracks_read_back_from_csv(tmp_path):
    """An all-empty reason column comes back from CSV as float NaN: corrections still apply."""
    write_tracks_csv(_tracks(), tmp_path / "t.csv")
    back = read_tracks_csv(tmp_path / "t.csv")
    out = apply_corrections(back, [(1, 0, 9.5, 4.25)])
    r = out[(out.frame == 0) & (out.point == 1)].iloc[0]
    assert (r.x, r.status) == (9.5, "manual") and r.reason == ""


@pytest.mark.parametrize("content, match", [
    (b"", "is empty"),
    (b"\x00\xff\xfe\x89PNG\x1a\x00\x00garbage", "not a readable CSV"),
    (b"a,b\n1,2\n", r"lacks columns \['point', 'frame', 'x', 'y'\]"),
    (b"point,frame,x,y\nnan,1,2.0,3.0\n", "correction 0 has point"),
    (b"point,frame,x,y\n0,1.5,2.0,3.0\n", "correction 0 has frame 1.5"),
    (b"point,frame,x,y\n0,1,abc,3.0\n", "correction 0 has x 'abc'"),
    (b"point,frame,x,y\n0,1,2.0,\n", "only one of x, y"),
])
def test_load_bad_csv_names_the_file(tmp_path, content, match):
    p = tmp_path / "bad.csv"
    p.write_bytes(content)
    with pytest.raises(ValueError, match=match) as e:
        load_corrections(p)
    assert "bad.csv" in str(e.value)


@pytest.mark.parametrize("content, match", [
    (b"\xff\xfe\x00binary", "not valid JSON"),
    (b'{"format": "other"}', "not a wingphoto corrections file"),
    (b'{"format": "wingphoto-corrections", "version": 1, "corrections": [{"point": 0, "frame": null, '
     b'"x": 1.0, "y": 2.0}]}', "correction 0 has frame None"),
])
def test_load_bad_json(tmp_path, content, match):
    p = tmp_path / "bad.json"
    p.write_bytes(content)
    with pytest.raises(ValueError, match=match):
        load_corrections(p)


def test_missing_file_and_bad_suffix(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        load_corrections(tmp_path / "none.csv")
    with pytest.raises(ValueError, match=r"must end in \.csv or \.json"):
        load_corrections(tmp_path / "c.txt")


def test_widget_log_format_is_the_same(tmp_path):
    """The review widget writes and reads its log through this module."""
    from wingphoto.widgets.state import Correction, read_corrections, write_corrections

    path = write_corrections([Correction("left", 0, 1, 6.5, 4.75)], tmp_path / "w.json")
    c = load_corrections(path)
    assert c.iloc[0][["camera", "point", "frame", "x", "y"]].tolist() == ["left", 0, 1, 6.5, 4.75]
    save_corrections(c, tmp_path / "w2.csv")
    assert read_corrections(tmp_path / "w2.csv") == (Correction("left", 0, 1, 6.5, 4.75),)
