"""The main job and the command line on data-samples: outputs, accuracy against its truth."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.io

from wingphoto.cli import main
from wingphoto.io import load_bouguet_stereo, read_points_csv, read_tracks_csv
from wingphoto.pipeline import load_sample, run_demo

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "data-samples"


@pytest.fixture(scope="module")
def demo_out(tmp_path_factory):
    out = tmp_path_factory.mktemp("results")
    summary = run_demo(SAMPLES, out=out, progress=False)
    return out, summary


def test_demo_writes_every_result(demo_out):
    out, summary = demo_out
    for name in ["Calib_Results_stereo.mat", "calibration_summary.txt", "tracks.csv", "points3d.csv",
                 "length_statistics.csv", "reference_stillness.csv", "stroke_angle.csv", "summary.txt",
                 "calibration_residuals.png", "points3d.png", "length_statistics.png", "stroke_angle.png"]:
        assert (out / name).is_file(), name
    assert list(out.glob("tracking_left.*")), "verification video missing"
    assert not (out / ".checkpoints").exists(), "checkpoints must be cleaned up after a finished run"
    assert "results in" in summary


def test_demo_calibration_is_toolbox_loadable_and_honest(demo_out):
    out, _ = demo_out
    mat = scipy.io.loadmat(out / "Calib_Results_stereo.mat")
    for name in ["om", "T", "R", "fc_left", "cc_left", "kc_left", "alpha_c_left", "fc_right", "om_error", "T_error"]:
        assert name in mat, name
    rig, unc = load_bouguet_stereo(out / "Calib_Results_stereo.mat")
    truth = load_sample(SAMPLES)["rig"]
    # every stereo parameter inside its reported 3-sigma of the truth
    assert np.all(np.abs(rig.om - truth.om) <= np.ravel(unc["om"]))
    assert np.all(np.abs(rig.T - truth.T) <= np.ravel(unc["T"]))
    for side in ("left", "right"):
        est, tru = getattr(rig, side), getattr(truth, side)
        assert np.all(np.abs(est.fc - tru.fc) <= np.ravel(unc[f"fc_{side}"]))
        assert np.all(np.abs(est.cc - tru.cc) <= np.ravel(unc[f"cc_{side}"]))


def test_demo_tracks_and_points_against_truth(demo_out):
    out, _ = demo_out
    truth = load_sample(SAMPLES)["truth"]
    tracks = read_tracks_csv(out / "tracks.csv")
    assert set(tracks["camera"]) == {"left", "right"}
    for cam in ("left", "right"):
        t = tracks[(tracks["camera"] == cam) & (tracks["status"] == "ok")]
        true_xy = truth[f"points_{cam}"][t["frame"].to_numpy(), t["point"].to_numpy()]
        err = np.hypot(t["x"].to_numpy() - true_xy[:, 0], t["y"].to_numpy() - true_xy[:, 1])
        assert err.max() < 1.0  # no confident wrong position
        assert np.sqrt(np.mean(err**2)) < 0.1
        # the clean sample: every visible point-frame tracked ok
        assert len(t) >= 0.95 * truth[f"visible_{cam}"].sum()
    points = read_points_csv(out / "points3d.csv")
    from wingphoto.analysis import align_rigid

    true3 = truth["points3d"][points["frame"].to_numpy(), points["point"].to_numpy()]
    _, _, rms_shape = align_rigid(points[["X", "Y", "Z"]].to_numpy(), true3)
    assert rms_shape < 0.1  # mm: the wing's shape, independent of the calibration's frame offset


def test_demo_analysis_tables(demo_out):
    out, _ = demo_out
    stats = pd.read_csv(out / "length_statistics.csv")
    assert {"mean", "std", "min", "max", "nominal"} <= set(stats.columns)
    assert (stats["max_error"] < 0.2).all()  # mm, rigid lengths from a calibrated rig
    still = pd.read_csv(out / "reference_stillness.csv")
    assert (still["max_displacement"] < 0.05).all()
    angle = pd.read_csv(out / "stroke_angle.csv")
    assert len(angle) == 60 and angle["stroke_angle_deg"].notna().all()


def test_load_sample_names_what_is_missing(tmp_path):
    with pytest.raises(FileNotFoundError, match="not laid out like data-samples"):
        load_sample(tmp_path)


def test_cli_help_and_errors(capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    assert "calibrate" in capsys.readouterr().out
    assert main(["demo", str(tmp_path), "--out", str(tmp_path / "r")]) == 1
    assert "not laid out like data-samples" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["calibrate", "--left", "a", "--right", "b", "--pattern", "nine", "--square", "30"])
    assert "--pattern must be" in capsys.readouterr().err


def test_cli_stage_by_stage_matches_demo(tmp_path, demo_out):
    out, _ = demo_out
    calib = tmp_path / "calib.mat"
    assert main(["calibrate", "--left", str(SAMPLES / "calibration" / "left"), "--right",
                 str(SAMPLES / "calibration" / "right"), "--pattern", "9x6", "--square", "8", "--out", str(calib)]) == 0
    for cam in ("left", "right"):
        assert main(["track", "--frames", str(SAMPLES / "flapping" / cam), "--picks",
                     str(SAMPLES / "flapping" / "picks.json"), "--camera", cam, "--out", str(tmp_path / f"{cam}.csv")]) == 0
    assert main(["triangulate", "--calib", str(calib), "--left", str(tmp_path / "left.csv"), "--right",
                 str(tmp_path / "right.csv"), "--out", str(tmp_path / "points.csv")]) == 0
    p = read_points_csv(tmp_path / "points.csv")
    q = read_points_csv(out / "points3d.csv")
    # same data, same methods: the stage-by-stage points equal the demo's (stereo check aside);
    # the calibration's least squares is reproducible to ~1e-9 relative (BLAS threading), 1e-6 mm here
    np.testing.assert_allclose(p[["X", "Y", "Z"]].to_numpy(), q[["X", "Y", "Z"]].to_numpy(), atol=1e-4)


def test_python_dash_m_wingphoto_runs():
    # the timeout only stops a hung interpreter: a fresh import took 7.5 s on a loaded 2-core machine
    r = subprocess.run([sys.executable, "-m", "wingphoto", "--help"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "triangulate" in r.stdout
