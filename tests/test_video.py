"""Tests of wingphoto.video.write_tracking_video: a readable file with the right frames."""
import cv2
import numpy as np
import pandas as pd
import pytest

from wingphoto.track import track_markers
from wingphoto.track import write_tracking_video as reexported
from wingphoto.video import STATUS_COLOURS, write_tracking_video


def _sequence(T=7, dtype=np.uint8):
    yy, xx = np.mgrid[:40, :56]
    frames = np.stack([60 + 150 * (np.hypot(xx - 20 - 1.5 * k, yy - 18.5) < 4) for k in range(T)])
    frames = (frames * (257 if dtype == np.uint16 else 1)).astype(dtype)
    tracks = track_markers(frames, [[20, 18]], progress=False)
    return frames, tracks


def _read(path):
    cap = cv2.VideoCapture(str(path))
    assert cap.isOpened()
    out = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        out.append(img)
    cap.release()
    return out


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_writes_a_readable_video_with_every_frame(tmp_path, dtype):
    frames, tracks = _sequence(dtype=dtype)
    path = write_tracking_video(frames, tracks, tmp_path / "check.mp4", fps=10, scale=3, progress=False)
    assert path.is_file() and path.suffix in (".mp4", ".avi")
    imgs = _read(path)
    assert len(imgs) == len(frames)
    assert imgs[0].shape == (40 * 3, 56 * 3, 3)
    # the blue x sits on the sub-pixel centre: a strongly blue pixel near it (codec blur allowed)
    x, y = tracks.loc[tracks.frame == 3, ["x", "y"]].to_numpy()[0]
    u, v = int(round((x + 0.5) * 3 - 0.5)), int(round((y + 0.5) * 3 - 0.5))
    patch = imgs[3][v - 2: v + 3, u - 2: u + 3].astype(int)
    assert (patch[..., 0] - patch[..., 2]).max() > 60


def test_avi_path_writes_mjpg(tmp_path):
    frames, tracks = _sequence(T=4)
    path = write_tracking_video(frames, tracks, tmp_path / "check.avi", progress=False)
    assert path == tmp_path / "check.avi"
    assert len(_read(path)) == 4


def test_frames_without_rows_and_other_statuses(tmp_path):
    frames, tracks = _sequence(T=5)
    t = tracks[tracks.frame != 2].copy()
    t.loc[t.frame == 3, "status"] = "flagged"
    t.loc[t.frame == 4, ["x", "y"]] = np.nan
    t.loc[t.frame == 4, "status"] = "lost"
    path = write_tracking_video(frames, t.drop(columns=["x_pix", "y_pix"]), tmp_path / "v.mp4", progress=False)
    assert len(_read(path)) == 5
    assert set(STATUS_COLOURS) >= {"ok", "flagged", "lost", "manual", "interpolated"}
    assert reexported is write_tracking_video


def test_bad_input(tmp_path):
    frames, tracks = _sequence(T=3)
    with pytest.raises(ValueError, match="frames is empty"):
        write_tracking_video(frames[:0], tracks, tmp_path / "a.mp4", progress=False)
    with pytest.raises(ValueError, match=r"tracks lacks columns \['status'\]"):
        write_tracking_video(frames, tracks.drop(columns="status"), tmp_path / "a.mp4", progress=False)
    with pytest.raises(ValueError, match="scale must be a positive integer"):
        write_tracking_video(frames, tracks, tmp_path / "a.mp4", scale=0, progress=False)
    mixed = [frames[0], frames[1][:, :-1], frames[2]]
    with pytest.raises(ValueError, match="frame 1 has shape"):
        write_tracking_video(mixed, tracks, tmp_path / "b.mp4", progress=False)
    assert not (tmp_path / "a.mp4").exists()
    assert sorted(q.name for q in tmp_path.iterdir()) == []  # no partial file left behind


def test_failed_write_keeps_the_previous_video(tmp_path):
    frames, tracks = _sequence(T=3)
    path = write_tracking_video(frames, tracks, tmp_path / "v.mp4", progress=False)
    before = path.read_bytes()
    with pytest.raises(ValueError, match="frame 2 has shape"):
        write_tracking_video([frames[0], frames[1], frames[2][:-1]], tracks, path, progress=False)
    assert path.read_bytes() == before
