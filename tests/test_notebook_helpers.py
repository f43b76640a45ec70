"""Helpers the notebooks use: align_rigid, tracking_error, find_samples, synth.load_rig, min_frames."""
import numpy as np
import pandas as pd
import pytest

from wingphoto.analysis import align_rigid, tracking_error
from wingphoto.camera import rodrigues
from wingphoto.io import find_samples
from wingphoto.synth import load_rig, rig_to_dict, thesis_rig


def test_align_rigid_recovers_a_known_motion_and_ignores_nan():
    rng = np.random.default_rng(5)
    P = rng.normal(scale=50, size=(40, 3))
    R = rodrigues([0.1, -0.3, 0.2])
    t = np.array([5.0, -2.0, 30.0])
    Q = P @ R.T + t + rng.normal(scale=0.01, size=P.shape)
    Q[3] = np.nan
    R_est, t_est, rms = align_rigid(P, Q)
    np.testing.assert_allclose(R_est, R, atol=1e-3)
    np.testing.assert_allclose(t_est, t, atol=0.02)
    assert 0.01 < rms < 0.03  # sqrt(3) * 0.01 mm noise, less the 6 fitted dof
    with pytest.raises(ValueError, match="at least 3"):
        align_rigid(P[:2], Q[:2])


def test_tracking_error_merges_on_camera_frame_point():
    tracks = pd.DataFrame({"camera": ["left", "left", "right"], "frame": [0, 1, 0], "point": [0, 0, 0],
                           "x": [1.0, np.nan, 5.0], "y": [1.0, 2.0, 5.0], "status": ["ok", "lost", "ok"]})
    truth = pd.DataFrame({"camera": ["left", "left", "right"], "frame": [0, 1, 0], "point": [0, 0, 0],
                          "x": [4.0, 2.0, 5.0], "y": [5.0, 2.0, 6.0]})
    e = tracking_error(tracks, truth)
    np.testing.assert_allclose(e["error_px"].to_numpy(), [5.0, np.nan, 1.0])
    assert list(e.columns[-3:]) == ["x_true", "y_true", "error_px"]
    with pytest.raises(ValueError, match="truth lacks"):
        tracking_error(tracks, truth.drop(columns="y"))


def test_find_samples_walks_up_and_names_the_folder(tmp_path):
    (tmp_path / "data-samples").mkdir()
    deep = tmp_path / "a" / "b"
    deep.mkdir(parents=True)
    assert find_samples(deep).resolve() == (tmp_path / "data-samples").resolve()
    with pytest.raises(FileNotFoundError, match="no nothing-here/ folder"):
        find_samples(deep, name="nothing-here")


def test_load_rig_round_trip_and_errors(tmp_path):
    import json

    rig = thesis_rig()
    p = tmp_path / "rig.json"
    p.write_text(json.dumps(rig_to_dict(rig)))
    back = load_rig(p)
    np.testing.assert_allclose(back.T, rig.T)
    np.testing.assert_allclose(back.left.fc, rig.left.fc)
    with pytest.raises(FileNotFoundError, match="not found"):
        load_rig(tmp_path / "nope.json")
    p.write_text("{}")
    with pytest.raises(ValueError, match="lacks"):
        load_rig(p)


def test_reference_stillness_needs_min_frames():
    from wingphoto.analysis import reference_stillness

    P = np.full((30, 2, 3), 600.0)
    P[1:, 1] = np.nan  # reference 1 seen in frame 0 only
    res = reference_stillness(P, [0, 1], tol_mm=0.1)
    assert not res.valid
    assert res.table.set_index("point").loc[1, "n"] == 1
    assert not res.table.set_index("point").loc[1, "valid"]
    assert res.table.set_index("point").loc[0, "valid"]
    assert reference_stillness(P, [0, 1], tol_mm=0.1, min_frames=1).valid
    with pytest.raises(ValueError, match="min_frames"):
        reference_stillness(P, [0], min_frames=0)
