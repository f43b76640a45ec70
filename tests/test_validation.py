"""wingphoto.validation.score_tracks on hand-made tracks with known answers."""
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from wingphoto.validation import score_tracks


def _seq(T=4, N=3):
    rng = np.random.default_rng(1)
    pts = rng.uniform(10, 50, (T, N, 2))
    vis = np.ones((T, N), bool)
    return SimpleNamespace(points_left=pts, visible_left=vis, points_right=pts + 1.0, visible_right=vis.copy())


def _tracks(seq, camera="left", dx=None, status=None, sigma=None):
    pts = getattr(seq, f"points_{camera}")
    T, N = pts.shape[:2]
    dx = np.zeros((T, N)) if dx is None else dx
    status = np.full((T, N), "ok", dtype=object) if status is None else status
    d = {
        "camera": camera,
        "frame": np.repeat(np.arange(T), N),
        "point": np.tile(np.arange(N), T),
        "x": (pts[..., 0] + dx).ravel(),
        "y": pts[..., 1].ravel(),
        "score": 1.0,
        "status": status.ravel(),
    }
    if sigma is not None:
        d["sigma"] = np.broadcast_to(sigma, (T, N)).ravel()
    return pd.DataFrame(d)


def test_perfect_tracks():
    seq = _seq()
    s = score_tracks(_tracks(seq), seq, "left")
    assert s["n_visible"] == 12 and s["n_ok_visible"] == 12 and s["ok_share"] == 1.0
    assert s["rms_px"] == 0.0 and s["worst_px"] == 0.0 and s["confident_errors"] == 0
    assert np.isnan(s["within_3_sigma"]) and np.isnan(s["median_error_over_sigma"]) and s["n_sigma"] == 0


def test_known_errors_statuses_and_visibility():
    seq = _seq()
    dx = np.zeros((4, 3))
    dx[1, 0] = 0.3
    dx[2, 1] = 1.5  # confident error
    dx[3, 2] = 5.0  # far, but flagged: not counted
    status = np.full((4, 3), "ok", dtype=object)
    status[3, 2] = "flagged"
    status[0, 0] = "lost"
    seq.visible_left[0, 1] = False  # ok point where invisible: scored for error, not in the share
    s = score_tracks(_tracks(seq, dx=dx, status=status), seq, "left")
    assert s["n_visible"] == 11
    assert s["n_ok_visible"] == 9
    assert s["ok_share"] == pytest.approx(9 / 11)
    assert s["n_ok"] == 10
    assert s["worst_px"] == pytest.approx(1.5)
    assert s["rms_px"] == pytest.approx(np.sqrt((0.3**2 + 1.5**2) / 10))
    assert s["confident_errors"] == 1


def test_sigma_honesty():
    seq = _seq(T=10, N=10)
    dx = np.tile(np.linspace(0.05, 0.95, 10), (10, 1))  # 0.05 .. 0.95 px
    s = score_tracks(_tracks(seq, dx=dx, sigma=0.2), seq, "left")
    ratio = np.linspace(0.05, 0.95, 10) / 0.2
    assert s["n_sigma"] == 100
    assert s["within_3_sigma"] == pytest.approx(np.mean(ratio <= 3))  # 0.05 .. 0.55 px: 6 of 10
    assert s["within_3_sigma"] == pytest.approx(0.6)
    assert s["median_error_over_sigma"] == pytest.approx(np.median(ratio))
    # NaN sigma (e.g. manual points of old files) are left out
    sig = np.full((10, 10), 0.2)
    sig[:, 9] = np.nan
    s = score_tracks(_tracks(seq, dx=dx, sigma=sig), seq, "left")
    assert s["n_sigma"] == 90 and s["within_3_sigma"] == pytest.approx(6 / 9)


def test_missing_rows_camera_filter_and_points():
    seq = _seq()
    both = pd.concat([_tracks(seq, "left"), _tracks(seq, "right", dx=np.full((4, 3), 2.0))])
    assert score_tracks(both, seq, "left")["confident_errors"] == 0
    assert score_tracks(both, seq, "right")["confident_errors"] == 12
    part = _tracks(seq).iloc[3:]  # frame 0 missing: not ok
    s = score_tracks(part, seq, "left")
    assert s["n_ok_visible"] == 9 and s["ok_share"] == pytest.approx(0.75)
    s = score_tracks(part, seq, "left", points=[1])
    assert s["n_visible"] == 4 and s["n_ok_visible"] == 3


def test_no_ok_points_gives_nan():
    seq = _seq()
    s = score_tracks(_tracks(seq, status=np.full((4, 3), "lost", dtype=object)), seq, "left")
    assert s["ok_share"] == 0.0 and s["n_ok"] == 0 and np.isnan(s["rms_px"]) and s["confident_errors"] == 0


def test_bad_input():
    seq = _seq()
    with pytest.raises(ValueError, match="tracks must be a tracks DataFrame"):
        score_tracks(np.zeros((3, 2)), seq, "left")
    with pytest.raises(ValueError, match="no rows for camera 'middle'"):
        score_tracks(_tracks(seq), SimpleNamespace(points_middle=seq.points_left, visible_middle=seq.visible_left),
                     "middle")
    with pytest.raises(ValueError, match="outside the sequence"):
        score_tracks(_tracks(_seq(T=5)), seq, "left")
    with pytest.raises(ValueError, match="more than one row"):
        score_tracks(pd.concat([_tracks(seq), _tracks(seq)]), seq, "left")
    with pytest.raises(ValueError, match="points_top"):
        score_tracks(_tracks(seq), seq, "top")


def test_one_camera_sequence_and_pooling():
    from wingphoto.validation import point_errors, summarize_errors

    seq = _seq()
    one = SimpleNamespace(camera="cam1", points=seq.points_left, visible=seq.visible_left)
    dx = np.zeros((4, 3))
    dx[0, 0] = 2.0
    tr = _tracks(seq, dx=dx, sigma=0.5).assign(camera="cam1")
    s = score_tracks(tr, one, "cam1")
    assert s["confident_errors"] == 1 and s["n_ok"] == 12
    # pooling two sequences' arrays gives the numbers of one table holding both
    a = point_errors(tr, one, "cam1")
    b = point_errors(_tracks(seq, sigma=0.5).assign(camera="cam1"), one, "cam1")
    pooled = summarize_errors(*(np.concatenate([a[k].ravel(), b[k].ravel()]) for k in ("error", "ok", "visible", "sigma")))
    assert pooled["n_ok"] == 24 and pooled["confident_errors"] == 1
    assert pooled["rms_px"] == pytest.approx(np.sqrt(4.0 / 24))
    assert pooled["within_3_sigma"] == pytest.approx(23 / 24)
