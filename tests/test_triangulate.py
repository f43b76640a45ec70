"""stereo_triangulation: golden parity with the Bouguet toolbox, round trips, NaN handling."""
import numpy as np
import pandas as pd
import pytest

from wingphoto.camera import Camera, StereoRig
from wingphoto.triangulate import reprojection_error, stereo_triangulation, triangulate_tracks


def _golden_rig(d):
    left = Camera(d["fc_left"], d["cc_left"], d["kc_left"], d["alpha_c_left"])
    right = Camera(d["fc_right"], d["cc_right"], d["kc_right"], d["alpha_c_right"])
    return StereoRig(left, right, d["om"], d["T"])


def test_golden_parity_with_toolbox(golden_dir):
    d = np.load(golden_dir / "stereo_triangulation_case.npz")
    rig = _golden_rig(d)
    XL, XR = stereo_triangulation(d["xL"], d["xR"], rig)
    np.testing.assert_allclose(XL, d["XL"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(XR, d["XR"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(rig.left.normalize(d["xL"]), d["xnL"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(rig.right.normalize(d["xR"]), d["xnR"], rtol=0, atol=1e-12)


def _thesis_rig(skew=0.0):
    left = Camera([1831.8, 1809.0], [257.8, 257.9], [0.124, -0.953, 5e-4, -1.2e-3, 0.0], alpha_c=skew)
    right = Camera([1842.3, 1832.0], [256.6, 253.7], [0.236, -1.12, 8e-4, -5e-4, 0.01], alpha_c=-skew)
    return StereoRig(left, right, om=[0.026, 0.733, 0.003], T=[-272.7, -1.5, 108.7])


@pytest.mark.parametrize("skew", [0.0, 0.003])
def test_project_then_triangulate_round_trip(skew):
    rng = np.random.default_rng(10)
    rig = _thesis_rig(skew)
    X = np.column_stack([rng.uniform(-60, 60, 300), rng.uniform(-60, 60, 300), rng.uniform(520, 680, 300)])
    xL, xR = rig.project(X)
    XL, XR = stereo_triangulation(xL, xR, rig)
    np.testing.assert_allclose(XL, X, atol=1e-6)
    np.testing.assert_allclose(XR, rig.to_right(X), atol=1e-6)
    assert reprojection_error(XL, xL, xR, rig).max() < 1e-6


def test_noise_gives_expected_reprojection_error_scale():
    rng = np.random.default_rng(11)
    rig = _thesis_rig()
    X = np.column_stack([rng.uniform(-40, 40, 2000), rng.uniform(-40, 40, 2000), rng.uniform(560, 640, 2000)])
    xL, xR = rig.project(X)
    sigma = 0.2
    XL, _ = stereo_triangulation(xL + rng.normal(0, sigma, xL.shape), xR + rng.normal(0, sigma, xR.shape), rig)
    err = reprojection_error(XL, xL, xR, rig)
    # the midpoint absorbs part of the noise: error per view is below the 2D noise (~1.25 sigma rms)
    rms = np.sqrt(np.mean(err**2))
    assert 0.2 * sigma < rms < 1.3 * sigma
    # depth error of ~0.1-0.3 mm for 0.2 px at 600 mm with a 290 mm baseline
    assert 0.01 < np.sqrt(np.mean(np.sum((XL - X) ** 2, axis=1))) < 0.5


def test_single_point_and_nan_rows():
    rig = _thesis_rig()
    X = np.array([[3.0, 4.0, 600.0], [np.nan, np.nan, np.nan], [-10.0, 2.0, 590.0]])
    xL, xR = rig.project(X)
    XL, _ = stereo_triangulation(xL, xR, rig)
    assert np.isnan(XL[1]).all()
    np.testing.assert_allclose(XL[[0, 2]], X[[0, 2]], atol=1e-6)
    XL0, XR0 = stereo_triangulation(xL[0], xR[0], rig)
    assert XL0.shape == (3,) and XR0.shape == (3,)
    np.testing.assert_allclose(XL0, X[0], atol=1e-6)


def test_bad_input_messages():
    rig = _thesis_rig()
    with pytest.raises(ValueError, match="same number of rows"):
        stereo_triangulation(np.zeros((3, 2)), np.zeros((4, 2)), rig)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        stereo_triangulation(np.zeros((2, 5)), np.zeros((2, 5)), rig)
    with pytest.raises(ValueError, match="rig must be a wingphoto.StereoRig"):
        stereo_triangulation(np.zeros((1, 2)), np.zeros((1, 2)), None)


def test_triangulate_tracks_uses_only_trusted_statuses():
    rig = _thesis_rig()
    X = np.array([[0.0, 0.0, 600.0], [20.0, 5.0, 610.0]])
    xL, xR = rig.project(X)

    def tracks(x, cam, statuses):
        return pd.DataFrame({"camera": cam, "frame": [0, 0], "point": [0, 1], "x": x[:, 0], "y": x[:, 1],
                             "score": 1.0, "status": statuses})

    pts = triangulate_tracks(tracks(xL, "left", ["ok", "ok"]), tracks(xR, "right", ["ok", "flagged"]), rig)
    assert list(pts.columns) == ["frame", "point", "X", "Y", "Z", "reproj_err"]
    np.testing.assert_allclose(pts.loc[0, ["X", "Y", "Z"]].to_numpy(float), X[0], atol=1e-6)
    assert pts.loc[1, ["X", "Y", "Z"]].isna().all()
    empty = triangulate_tracks(tracks(xL, "left", ["ok", "ok"]).iloc[:0], tracks(xR, "right", ["ok", "ok"]).iloc[:0], rig)
    assert len(empty) == 0 and empty["frame"].dtype == np.int64 and empty["X"].dtype == np.float64
