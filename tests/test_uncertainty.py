"""3D uncertainty: first-order propagation validated by Monte Carlo on synth (held-out seeds)."""
import logging

import numpy as np
import pandas as pd
import pytest

from wingphoto.analysis import length_statistics
from wingphoto.synth import thesis_rig, wing_motion
from wingphoto.triangulate import triangulate_tracks
from wingphoto.uncertainty import (
    add_point_uncertainty,
    calibration_covariance,
    monte_carlo_errors,
    propagate_point_covariance,
    rig_from_parameters,
    rig_parameters,
    triangulation_jacobians,
)

# 1-sigma of the 26 rig parameters as calibrate_stereo estimates them from 8 synth board
# pairs (fc, cc px; alpha_c; kc; om rad; T mm), in RIG_PARAMETER_NAMES order
SIGMA = np.array([0.47, 0.47, 0.99, 0.93, 0.0, 2.4e-3, 3.1e-2, 1.1e-4, 1.2e-4, 0.0] * 2
                 + [4.9e-4, 6.0e-4, 2.1e-4] + [0.09, 0.06, 0.21])


def _covariance(seed):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(26, 26))
    C = A @ A.T
    d = np.sqrt(np.diag(C))
    corr = 0.6 * C / np.outer(d, d) + 0.4 * np.eye(26)
    return corr * np.outer(SIGMA, SIGMA)


def _tracks(xy, camera, sigma=None):
    t, n = xy.shape[:2]
    df = pd.DataFrame({"camera": camera, "frame": np.repeat(np.arange(t), n), "point": np.tile(np.arange(n), t),
                       "x": xy[..., 0].ravel(), "y": xy[..., 1].ravel(), "status": "ok"})
    if sigma is not None:
        df["sigma"] = sigma
    return df


def test_rig_parameters_round_trip():
    rig = thesis_rig(seed=4, jitter=1.0)
    th = rig_parameters(rig)
    assert th.shape == (26,)
    back = rig_from_parameters(rig, th)
    assert back == rig
    th2 = th.copy()
    th2[23] += 1.0  # T[0]
    assert rig_from_parameters(rig, th2).T[0] == pytest.approx(rig.T[0] + 1.0)
    with pytest.raises(ValueError, match="26 rig parameters"):
        rig_from_parameters(rig, th[:5])


def test_pixel_jacobian_is_consistent():
    rig = thesis_rig()
    X = wing_motion(rig, n_frames=1).points3d[0]
    xL, xR = rig.project(X)
    Jx, _ = triangulation_jacobians(xL, xR, rig)
    Jx2, _ = triangulation_jacobians(xL, xR, rig, step_px=2e-2)
    np.testing.assert_allclose(Jx, Jx2, rtol=1e-4, atol=1e-7)
    # depth is the least precise direction: dZ/dpx is the largest row norm
    assert np.all(np.linalg.norm(Jx[:, 2], axis=1) > np.linalg.norm(Jx[:, 1], axis=1))


@pytest.mark.parametrize("seed", [17, 29])
def test_monte_carlo_coverage_on_a_synth_wing(seed):
    rig = thesis_rig(seed=seed, jitter=0.5)
    m = wing_motion(rig, n_frames=6, stroke_amplitude_deg=96, pitch_deg=33, phase_deg=float(seed))
    X = m.points3d.reshape(-1, 3)
    xL, xR = rig.project(X)
    cov = _covariance(seed)
    sigma_px = np.random.default_rng(seed).uniform(0.03, 0.2, size=len(X))  # per-point 2D sigmas
    res = propagate_point_covariance(xL, xR, rig, sigma_left=sigma_px, sigma_right=sigma_px, calibration=cov)
    pred = np.sqrt(np.diagonal(res["cov"], axis1=1, axis2=2))
    E = monte_carlo_errors(X, rig, sigma_px=sigma_px, calibration=cov, n_draws=250, seed=seed + 1)
    inside = (np.abs(E) <= 3 * pred).mean(axis=0)  # (N, 3): share of draws within 3 sigma
    assert np.all(inside.mean(axis=0) >= 0.9)  # >= 90 % per axis (Gaussian: 99.7 %)
    ratio = E.std(axis=0) / pred
    assert np.all((np.median(ratio, axis=0) > 0.8) & (np.median(ratio, axis=0) < 1.2))
    assert ratio.min() > 0.6 and ratio.max() < 1.5


def test_tracking_and_calibration_terms_separately():
    rig = thesis_rig()
    X = wing_motion(rig, n_frames=2).points3d.reshape(-1, 3)
    xL, xR = rig.project(X)
    cov = _covariance(3)
    only_px = propagate_point_covariance(xL, xR, rig, sigma_left=0.1, sigma_right=0.1)
    both = propagate_point_covariance(xL, xR, rig, sigma_left=0.1, sigma_right=0.1, calibration=cov)
    np.testing.assert_allclose(both["cov_track"], only_px["cov"])
    np.testing.assert_allclose(both["cov"], both["cov_track"] + both["cov_calib"])
    assert np.isnan(only_px["cov_calib"]).all()
    # the tracking term scales with the 2D sigma
    double = propagate_point_covariance(xL, xR, rig, sigma_left=0.2, sigma_right=0.2)
    np.testing.assert_allclose(double["cov"], 4 * only_px["cov"], rtol=1e-9)
    # tracking-only Monte Carlo
    E = monte_carlo_errors(X, rig, sigma_px=0.1, n_draws=300, seed=8)
    ratio = E.std(axis=0) / np.sqrt(np.diagonal(only_px["cov"], axis1=1, axis2=2))
    assert 0.85 < np.median(ratio) < 1.15


def test_calibration_sources(caplog):
    cc = calibration_covariance(_covariance(1))
    assert not cc.diagonal and cc.covariance.shape == (26, 26)
    unc = {"fc_left": [1.5, 1.5], "cc_left": [3.0, 3.0], "kc_left": [0.01] * 5, "om": [0.003] * 3, "T": [0.6, 0.3, 0.9]}
    with caplog.at_level(logging.WARNING, logger="wingphoto.uncertainty"):
        d = calibration_covariance((thesis_rig(), unc))
    assert d.diagonal and "diagonal covariance" in caplog.text
    assert d.sigma[0] == pytest.approx(0.5) and d.sigma[25] == pytest.approx(0.3)  # 3-sigma / 3
    assert d.sigma[10] == 0.0  # fc_right not in the file: not propagated
    with pytest.raises(ValueError, match="holds no parameter errors"):
        calibration_covariance({"foo": 1})
    with pytest.raises(ValueError, match="calibration must be a StereoCalibration"):
        calibration_covariance("calib.mat")


def test_triangulate_tracks_adds_sigmas_and_uses_track_sigma():
    rig = thesis_rig()
    m = wing_motion(rig, n_frames=3, phase_deg=50.0)
    xl, xr = rig.project(m.points3d.reshape(-1, 3))
    xl, xr = xl.reshape(3, -1, 2), xr.reshape(3, -1, 2)
    tl, tr = _tracks(xl, "left", sigma=0.05), _tracks(xr, "right", sigma=0.05)
    plain = triangulate_tracks(tl, tr, rig)
    assert "sigma_X" not in plain.columns
    pts = triangulate_tracks(tl, tr, rig, calibration=_covariance(5))
    for c in ["sigma_X", "sigma_Y", "sigma_Z", "sigma_X_track", "sigma_Z_track", "sigma_X_calib", "sigma_Z_calib"]:
        assert c in pts.columns and pts[c].notna().all() and (pts[c] > 0).all()
    np.testing.assert_allclose(pts["sigma_Z"] ** 2, pts["sigma_Z_track"] ** 2 + pts["sigma_Z_calib"] ** 2)
    assert pts.attrs["uncertainty"]["observations_with_assumed_sigma"] == 0
    tl2 = tl.assign(sigma=0.1)
    tr2 = tr.assign(sigma=0.1)
    pts2 = triangulate_tracks(tl2, tr2, rig, calibration=_covariance(5))
    np.testing.assert_allclose(pts2["sigma_Y_track"], 2 * pts["sigma_Y_track"], rtol=1e-6)
    np.testing.assert_allclose(pts2["sigma_Y_calib"], pts["sigma_Y_calib"], rtol=1e-9)
    # tracks without sigma: the stated default, said so
    no_sigma = triangulate_tracks(tl.drop(columns="sigma"), tr.drop(columns="sigma"), rig,
                                  calibration={"T": [0.3, 0.3, 0.3]}, point_sigma_px=0.05)
    np.testing.assert_allclose(no_sigma["sigma_X_track"], pts["sigma_X_track"], rtol=1e-9)
    assert no_sigma.attrs["uncertainty"]["diagonal_calibration_covariance"] is True
    assert no_sigma.attrs["uncertainty"]["assumed_point_sigma_px"] == 0.05


def test_expected_length_std_matches_the_measured_spread():
    rig = thesis_rig()
    m = wing_motion(rig, n_frames=300, phase_deg=12.0)
    rng = np.random.default_rng(61)
    xl, xr = rig.project(m.points3d.reshape(-1, 3))
    sig = 0.12
    xl = xl.reshape(300, -1, 2) + rng.normal(scale=sig, size=(300, 26, 2))
    xr = xr.reshape(300, -1, 2) + rng.normal(scale=sig, size=(300, 26, 2))
    pts = triangulate_tracks(_tracks(xl, "left", sig), _tracks(xr, "right", sig), rig, calibration=_covariance(9),
                             full_covariance=True)
    assert {"cov_XZ", "cov_XZ_track"} <= set(pts.columns)
    stats = length_statistics(pts, [(18, 19), (20, 25), (21, 24)])
    assert "expected_std" in stats.columns
    ratio = stats["std"] / stats["expected_std"]
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio.tolist()
    # per-axis sigmas alone ignore the strong correlation along the viewing rays
    diag = length_statistics(pts.drop(columns=[c for c in pts.columns if c.startswith("cov_")]), [(18, 19)])
    assert diag["expected_std"].iloc[0] > 1.1 * stats["expected_std"].iloc[0]
    # without sigmas the column is absent
    assert "expected_std" not in length_statistics(pts[["frame", "point", "X", "Y", "Z"]], [(18, 19)]).columns


def test_add_point_uncertainty_full_covariance():
    rig = thesis_rig()
    m = wing_motion(rig, n_frames=1)
    xl, xr = rig.project(m.points3d[0])
    tl, tr = _tracks(xl[None], "left"), _tracks(xr[None], "right")
    pts = triangulate_tracks(tl, tr, rig)
    pts.loc[3, ["X", "Y", "Z"]] = np.nan
    out = add_point_uncertainty(pts, tl, tr, rig, full=True)
    np.testing.assert_allclose(out["cov_XX"], out["sigma_X"] ** 2)
    np.testing.assert_allclose(out["cov_YZ"], out["cov_YZ_track"])  # no calibration term
    rho = out["cov_XZ"] / (out["sigma_X"] * out["sigma_Z"])
    assert np.nanmin(np.abs(rho)) > 0.3  # stereo errors are correlated between axes
    assert np.isnan(out.loc[3, "sigma_X"]) and out["sigma_X_calib"].isna().all()
    with pytest.raises(ValueError, match="point_sigma_px must be a positive"):
        add_point_uncertainty(pts, tl, tr, rig, point_sigma_px=0)


def test_triangulate_command_with_uncertainty_from_a_toolbox_mat(tmp_path, capsys, caplog):
    from wingphoto.cli import main
    from wingphoto.io import read_points_csv, save_bouguet_stereo, write_tracks_csv

    rig = thesis_rig()
    m = wing_motion(rig, n_frames=2, phase_deg=80.0)
    save_bouguet_stereo(rig, tmp_path / "Calib_Results_stereo.mat",
                        uncertainty={"fc_left": [3.0, 3.0], "cc_left": [4.0, 4.0], "om": [0.002] * 3, "T": [0.5, 0.2, 1.2]})
    write_tracks_csv(m.tracks(rig, "left", sigma_px=0.05, seed=1), tmp_path / "l.csv")
    write_tracks_csv(m.tracks(rig, "right", sigma_px=0.05, seed=2), tmp_path / "r.csv")
    with caplog.at_level(logging.WARNING, logger="wingphoto.uncertainty"):
        rc = main(["triangulate", "--calib", str(tmp_path / "Calib_Results_stereo.mat"), "--left", str(tmp_path / "l.csv"),
                   "--right", str(tmp_path / "r.csv"), "--out", str(tmp_path / "p.csv"), "--uncertainty"])
    assert rc == 0 and "median 1-sigma" in capsys.readouterr().out
    assert "diagonal covariance" in caplog.text
    pts = read_points_csv(tmp_path / "p.csv")
    assert {"sigma_X", "sigma_Z_calib", "cov_XZ_track"} <= set(pts.columns)
    assert (pts["sigma_Z_calib"] > pts["sigma_Z_track"]).all()
