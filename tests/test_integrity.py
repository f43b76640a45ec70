"""Sequence checks on glitched copies of data-samples/flapping."""
from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import tifffile

from wingphoto.integrity import SequenceWarning, check_sequence, check_stereo_sequences
from wingphoto.io import read_sequence

SAMPLES = Path(__file__).resolve().parents[1] / "data-samples" / "flapping"


@pytest.fixture(scope="module")
def frames():
    if not (SAMPLES / "left").is_dir():
        pytest.skip("data-samples/flapping not available")
    return read_sequence(SAMPLES / "left").to_array(), read_sequence(SAMPLES / "right").to_array()


def copy_left(tmp_path, n=30):
    out = tmp_path / "left"
    out.mkdir()
    for k in range(n):
        shutil.copy(SAMPLES / "left" / f"frame_{k:04d}.tif", out / f"frame_{k:04d}.tif")
    return out


def test_clean_samples_pass_without_warnings(frames):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        seq = read_sequence(SAMPLES / "left")
    rep = check_sequence(seq)
    assert rep.ok, rep.summary()
    assert rep.n_frames == 60 and rep.frame_numbers.tolist() == list(range(60))
    stereo = check_stereo_sequences(rep, check_sequence(SAMPLES / "right"))
    assert stereo.ok and stereo.offset is None, stereo.summary()  # no rig: no offset claimed
    from wingphoto.synth.rig import load_rig

    stereo = check_stereo_sequences(frames[0][:25], frames[1][:25], rig=load_rig(SAMPLES.parent / "rig.json"))
    assert stereo.ok and stereo.offset == 0, stereo.summary()


def test_duplicated_frame(tmp_path):
    folder = copy_left(tmp_path)
    shutil.copy(folder / "frame_0011.tif", folder / "frame_0012.tif")  # 12 overwritten by 11
    rep = check_sequence(folder)
    assert rep.duplicates.tolist() == [12]
    assert "identical to the previous one at index 12" in rep.summary()


def test_dropped_frame_warns_and_is_a_gap(tmp_path):
    folder = copy_left(tmp_path)
    (folder / "frame_0017.tif").unlink()
    with pytest.warns(SequenceWarning, match=r"1 number\(s\) missing from the file numbering \(17\)"):
        seq = read_sequence(folder)
    assert len(seq) == 29
    rep = check_sequence(folder)
    assert rep.gaps == [17] and not rep.ok


def test_stray_copy_warns_and_can_be_skipped(tmp_path):
    folder = copy_left(tmp_path)
    shutil.copy(folder / "frame_0020.tif", folder / "frame_0020 copy.tif")
    with pytest.warns(SequenceWarning, match=r"'frame_0020 copy\.tif'"):
        seq = read_sequence(folder)
    assert len(seq) == 31 and seq.frame_numbers[21] == 20
    clean = read_sequence(folder, strays="skip")
    assert len(clean) == 30
    with pytest.raises(ValueError, match="do not fit the sequence's numbering"):
        read_sequence(folder, strays="error")
    rep = check_sequence(folder)
    assert [p.name for p in rep.strays] == ["frame_0020 copy.tif"]
    assert rep.duplicates.tolist() == [21]  # the copy also duplicates its original


def test_black_frame(tmp_path, frames):
    folder = copy_left(tmp_path)
    tifffile.imwrite(folder / "frame_0009.tif", np.zeros_like(frames[0][9]))
    rep = check_sequence(folder)
    assert rep.blank.tolist() == [9]
    assert len(rep.jumps) == 0  # a blank frame is not a jump


def test_five_pixel_camera_bump(frames):
    left = frames[0].copy()
    left[25:] = np.roll(left[25:], 5, axis=2)
    rep = check_sequence(left)
    assert rep.jumps["frame"].tolist() == [25], rep.jumps
    assert abs(abs(rep.jumps["dx"].iloc[0]) - 5) < 1.0 and abs(rep.jumps["dy"].iloc[0]) < 1.0
    clean = check_sequence(frames[0])
    assert len(clean.jumps) == 0 and np.abs(np.diff(clean.camera_offset, axis=0)).max() < 1.0
    small = frames[0].copy()
    small[40:] = np.roll(small[40:], (3, -2), axis=(1, 2))  # 3.6 px diagonal bump
    jumps = check_sequence(small).jumps
    assert jumps["frame"].tolist() == [40] and abs(jumps["dy"].iloc[0] - 3) < 1 and abs(jumps["dx"].iloc[0] + 2) < 1


def test_offset_without_a_rig_is_only_a_hint(frames):
    left, right = frames
    rep = check_stereo_sequences(left[:-1], right[1:])
    assert rep.offset is None and rep.ok
    assert any("unreliable" in n for n in rep.notes)


def test_count_mismatch_is_a_problem(frames):
    rep = check_stereo_sequences(frames[0], frames[1][:-3])
    assert not rep.ok and "frame counts differ: left 60, right 57" in rep.summary()


def test_bad_input():
    with pytest.raises(ValueError, match="frames must be"):
        check_sequence(42)
    with pytest.raises(ValueError, match="2-D grey frames"):
        check_sequence(np.zeros((3, 4, 5, 3)))


def test_track_stereo_stops_on_a_mismatch_unless_forced(frames):
    import wingphoto as wp
    from wingphoto.synth.rig import load_rig

    left, right = frames
    rig = load_rig(SAMPLES.parent / "rig.json")
    picks = SAMPLES / "picks.json"
    with pytest.raises(ValueError, match=r"left and right sequences do not match: frame counts differ.*--force"):
        wp.track_stereo(left[:20], right[:19], picks, rig, progress=False)
    with pytest.raises(ValueError, match=r"right view seems offset by \+1 frame"):
        wp.track_stereo(left[:20], right[1:21], picks, rig, progress=False)


def test_cli_check_exit_codes(tmp_path, capsys):
    from wingphoto.cli import main

    folder = copy_left(tmp_path, n=12)
    assert main(["check", str(folder)]) == 0
    assert "no duplicates, blank frames, jumps, gaps or stray files found" in capsys.readouterr().out
    shutil.copy(folder / "frame_0004.tif", folder / "frame_0004 copy.tif")
    assert main(["check", str(folder)]) == 1
    out = capsys.readouterr().out
    assert "1 stray file(s) not fitting the numbering: frame_0004 copy.tif" in out
    assert main(["check", str(folder), "--right", str(SAMPLES / "right")]) == 1
    assert "frame counts differ: left 13, right 60" in capsys.readouterr().out


def test_epipolar_offset_with_a_rig(frames, tmp_path):
    from wingphoto.cli import main
    from wingphoto.io import save_bouguet_stereo
    from wingphoto.synth.rig import load_rig

    left, right = frames
    rig = load_rig(SAMPLES.parent / "rig.json")
    for offset, (lv, rv) in {1: (left[:20], right[1:21]), -2: (left[2:22], right[:20])}.items():
        rep = check_stereo_sequences(lv, rv, rig=rig)
        assert rep.offset == offset and rep.offset_score == 1.0, rep.summary()
        assert rep.ok == (offset == 0)
    save_bouguet_stereo(rig, tmp_path / "calib.mat")
    tifffile.imwrite(tmp_path / "l1.tif", left[1:13])
    tifffile.imwrite(tmp_path / "r.tif", right[:12])
    assert main(["check", str(tmp_path / "l1.tif"), "--right", str(tmp_path / "r.tif"),
                 "--calib", str(tmp_path / "calib.mat")]) == 1


def test_offset_from_camera_image_numbers():
    path = Path(__file__).resolve().parents[2] / "shared" / "data" / "formats" / "phantom-cine" / "packed_12bpp.cine"
    if not path.is_file():
        pytest.skip(f"{path} not available")
    seq = read_sequence(path)
    rep = check_stereo_sequences(seq[0:5], seq[1:6])  # right starts one image number later
    assert rep.offset == 1 and not rep.ok
    assert check_stereo_sequences(seq[0:5], seq[0:5]).offset == 0


def test_track_folder_stops_on_a_duplicated_frame(frames):
    import wingphoto as wp

    left = frames[0][:12].copy()
    left[6] = left[5]
    with pytest.raises(ValueError, match=r"duplicated frame\(s\) at index 6.*force=True \(--force\)"):
        wp.track_folder(left, SAMPLES / "picks.json", camera="left", progress=False)


def test_frame_lost_midway_in_one_view_is_found_with_a_rig(frames):
    from wingphoto.synth.rig import load_rig

    left, right = frames
    rig = load_rig(SAMPLES.parent / "rig.json")
    lost = np.concatenate([right[:14], right[15:29]])  # right frame 14 lost; both views 28 frames
    rep = check_stereo_sequences(left[:28], lost, rig=rig)
    assert not rep.ok and rep.offset is None
    assert any("changes from +0 over the first 7 frames to +1 over the last 7" in p for p in rep.problems), rep.problems
