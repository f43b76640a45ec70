"""Exporters and importers: DLTdv8, DLT coefficients, the thesis' .mat files, Parquet, read back independently."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.io

from wingphoto.io import read_points_csv, read_tracks_csv
from wingphoto.io.exchange import (
    dlt_project,
    fit_dlt,
    read_dlt_coefficients,
    read_dltdv,
    read_parquet,
    read_thesis_mat,
    write_dlt_coefficients,
    write_dltdv,
    write_parquet,
    write_thesis_mat,
)

SAMPLES = Path(__file__).resolve().parents[1] / "data-samples"


@pytest.fixture(scope="module")
def sample():
    if not (SAMPLES / "rig.json").is_file():
        pytest.skip("data-samples not available")
    from wingphoto.synth.rig import load_rig

    rig = load_rig(SAMPLES / "rig.json")
    tracks = read_tracks_csv(SAMPLES / "flapping" / "truth_tracks.csv")
    truth = pd.read_csv(SAMPLES / "flapping" / "truth_points.csv")
    points = truth[["frame", "point", "X", "Y", "Z"]].copy()
    points["reproj_err"] = np.random.default_rng(0).random(len(points))
    tracks = tracks[tracks["frame"] < 12].reset_index(drop=True)
    points = points[points["frame"] < 12].reset_index(drop=True)
    tracks.loc[5, ["x", "y"]] = np.nan
    tracks.loc[5, "status"] = "lost"
    return rig, tracks, points


def test_dltdv_round_trip_and_independent_read(tmp_path, sample):
    rig, tracks, points = sample
    paths = write_dltdv(tmp_path, tracks=tracks, points3d=points, prefix="t1-")
    assert sorted(paths) == ["offsets", "xypts", "xyzpts", "xyzres"]
    xy = pd.read_csv(tmp_path / "t1-xypts.csv")
    assert list(xy.columns[:4]) == ["pt1_cam1_X", "pt1_cam1_Y", "pt1_cam2_X", "pt1_cam2_Y"]
    row = tracks[(tracks.camera == "right") & (tracks.frame == 3) & (tracks.point == 2)].iloc[0]
    # DLTdv8: MATLAB pixels, 1-based, y down
    assert xy.loc[3, "pt3_cam2_X"] == pytest.approx(row.x + 1) and xy.loc[3, "pt3_cam2_Y"] == pytest.approx(row.y + 1)
    lost = tracks.loc[5]
    assert np.isnan(xy.loc[lost.frame, f"pt{lost.point + 1}_cam1_X"])
    assert pd.read_csv(tmp_path / "t1-offsets.csv").columns.tolist() == ["cam1_offset", "cam2_offset"]
    back, pts = read_dltdv(tmp_path / "t1-xypts.csv", xyzpts=tmp_path / "t1-xyzpts.csv",
                           xyzres=tmp_path / "t1-xyzres.csv")
    good = tracks[tracks.status == "ok"].set_index(["camera", "frame", "point"]).sort_index()
    got = back.set_index(["camera", "frame", "point"]).loc[good.index]
    np.testing.assert_allclose(got[["x", "y"]].to_numpy(), good[["x", "y"]].to_numpy(), atol=1e-9)
    assert (back.status == "lost").sum() == 1
    merged = points.merge(pts, on=["frame", "point"], suffixes=("", "_b"))
    assert len(merged) == len(points)
    np.testing.assert_allclose(merged[["X_b", "Y_b", "Z_b", "reproj_err_b"]].to_numpy(),
                               merged[["X", "Y", "Z", "reproj_err"]].to_numpy(), atol=1e-9)


def test_argus_y_up_needs_image_heights_and_round_trips(tmp_path, sample):
    _, tracks, _ = sample
    with pytest.raises(ValueError, match="image_heights must give the left image's height"):
        write_dltdv(tmp_path, tracks=tracks, y_axis="up")
    write_dltdv(tmp_path, tracks=tracks, y_axis="up", image_heights=(512, 512))
    xy = pd.read_csv(tmp_path / "xypts.csv")
    row = tracks[(tracks.camera == "left") & (tracks.frame == 2) & (tracks.point == 4)].iloc[0]
    assert xy.loc[2, "pt5_cam1_Y"] == pytest.approx(512 - row.y)  # origin bottom-left, 1-based
    back, _ = read_dltdv(tmp_path / "xypts.csv", y_axis="up", image_heights=(512, 512))
    got = back[(back.camera == "left") & (back.frame == 2) & (back.point == 4)].iloc[0]
    assert got.x == pytest.approx(row.x) and got.y == pytest.approx(row.y)
    with pytest.raises(ValueError, match="y_axis must be 'down'"):
        write_dltdv(tmp_path, tracks=tracks, y_axis="sideways")


def test_dlt_coefficients_fit_rig_and_report_distortion_cost(tmp_path, sample):
    rig, tracks, points = sample
    fit = fit_dlt(rig, points=points[["X", "Y", "Z"]].to_numpy())
    assert fit.coefficients.shape == (11, 2)
    path = write_dlt_coefficients(fit, tmp_path / "cal_dltCoefs.csv")
    coefs = np.loadtxt(path, delimiter=",")  # independent reader
    np.testing.assert_allclose(coefs, fit.coefficients, rtol=1e-15)
    np.testing.assert_array_equal(read_dlt_coefficients(path), coefs)
    # DLT projections of the true 3D points land on the true (distorted) pixels to within the
    # reported distortion residual
    Xw = points[["X", "Y", "Z"]].to_numpy() - fit.origin
    for c, cam in enumerate(("left", "right")):
        tr = tracks[(tracks.camera == cam) & (tracks.status == "ok")].merge(points, on=["frame", "point"])
        u = dlt_project(coefs[:, c], tr[["X", "Y", "Z"]].to_numpy() - fit.origin)
        err = np.hypot(u[:, 0] - (tr.x + 1), u[:, 1] - (tr.y + 1))
        assert err.max() < fit.max_px[c] + 0.05, (cam, err.max(), fit.max_px[c])
    assert np.all(fit.rms_px > 0.01)  # the rig has real distortion: the DLT cannot be exact
    # with distortion removed, the DLT is exact
    import dataclasses

    pin = dataclasses.replace(rig, left=rig.left.replace(kc=np.zeros(5)), right=rig.right.replace(kc=np.zeros(5)))
    exact = fit_dlt(pin)
    assert exact.max_px.max() < 1e-6
    assert np.isfinite(Xw).all()


def test_thesis_mat_files_load_with_scipy_under_thesis_names(tmp_path, sample):
    rig, tracks, points = sample
    written = write_thesis_mat(tmp_path, tracks=tracks, points3d=points, rig=rig)
    assert sorted(written) == ["3dall.mat", "cntrdl.mat", "cntrdr.mat", "xl.mat", "xr.mat"]
    xl = scipy.io.loadmat(tmp_path / "xl.mat")["Pointl"]
    row = tracks[(tracks.camera == "left") & (tracks.frame == 4) & (tracks.point == 3)].iloc[0]
    np.testing.assert_allclose(xl[0, 3]["x"][4], [row.x + 1, row.y + 1])  # Pointl(4).x(5, :)
    img = scipy.io.loadmat(tmp_path / "cntrdr.mat")["Img"]
    row = tracks[(tracks.camera == "right") & (tracks.frame == 2) & (tracks.point == 7)].iloc[0]
    np.testing.assert_allclose(img[0, 2]["cnt"][0, 7]["xr"].ravel(), [row.x + 1, row.y + 1])  # Img(3).cnt(8).xr
    pt = scipy.io.loadmat(tmp_path / "3dall.mat")["PT"]
    p = points[(points.frame == 6) & (points.point == 1)].iloc[0]
    np.testing.assert_allclose(pt[0, 1]["XL"][:, 6], [p.X, p.Y, p.Z])
    np.testing.assert_allclose(pt[0, 1]["XR"][:, 6], rig.to_right([p.X, p.Y, p.Z]))
    back = read_thesis_mat(tmp_path / "xr.mat")
    good = tracks[(tracks.camera == "right") & (tracks.status == "ok")]
    m = good.merge(back, on=["camera", "frame", "point"], suffixes=("", "_b"))
    assert len(m) == len(good)
    np.testing.assert_allclose(m[["x_b", "y_b"]].to_numpy(), m[["x", "y"]].to_numpy(), atol=1e-12)
    cl = read_thesis_mat(tmp_path / "cntrdl.mat")
    assert (cl.status == "lost").sum() == 1
    pts = read_thesis_mat(tmp_path / "3dall.mat")
    m = points.merge(pts, on=["frame", "point"], suffixes=("", "_b"))
    np.testing.assert_allclose(m[["X_b", "Y_b", "Z_b"]].to_numpy(), m[["X", "Y", "Z"]].to_numpy())


def test_parquet_round_trip(tmp_path, sample):
    _, tracks, points = sample
    write_parquet(tracks, tmp_path / "tracks.parquet")
    back = pd.read_parquet(tmp_path / "tracks.parquet")  # independent of our reader
    pd.testing.assert_frame_equal(back, tracks, check_dtype=False)
    assert (back.dtypes == tracks.dtypes).all() or set(back.columns) == set(tracks.columns)
    pd.testing.assert_frame_equal(read_parquet(tmp_path / "tracks.parquet"), back)


def test_cli_export(tmp_path, sample):
    from wingphoto.cli import main
    from wingphoto.io import write_points_csv, write_tracks_csv

    rig, tracks, points = sample
    write_tracks_csv(tracks, tmp_path / "tracks.csv")
    write_points_csv(points, tmp_path / "points.csv")
    assert main(["export", "--tracks", str(tmp_path / "tracks.csv"), "--points", str(tmp_path / "points.csv"),
                 "--format", "dltdv", "--out", str(tmp_path / "dlt")]) == 0
    assert (tmp_path / "dlt" / "xypts.csv").is_file() and (tmp_path / "dlt" / "xyzpts.csv").is_file()
    assert main(["export", "--points", str(tmp_path / "points.csv"), "--format", "parquet",
                 "--out", str(tmp_path / "pq")]) == 0
    back = pd.read_parquet(tmp_path / "pq" / "points3d.parquet")
    np.testing.assert_allclose(back[["X", "Y", "Z"]].to_numpy(), read_points_csv(tmp_path / "points.csv")[["X", "Y", "Z"]].to_numpy())
    assert main(["export", "--format", "thesis-mat", "--out", str(tmp_path / "m")]) == 1  # needs inputs
    meshio = pytest.importorskip("meshio")
    for fmt, ext in (("ply", "ply"), ("vtk", "vtu")):
        assert main(["export", "--points", str(tmp_path / "points.csv"), "--format", fmt,
                     "--out", str(tmp_path / fmt)]) == 0
        m = meshio.read(tmp_path / fmt / f"points_000003.{ext}")
        np.testing.assert_allclose(m.points, points[points.frame == 3][["X", "Y", "Z"]].to_numpy())
        assert (tmp_path / fmt / f"points.{ext}.series").is_file()
    from wingphoto.io import save_bouguet_stereo

    save_bouguet_stereo(rig, tmp_path / "calib.mat")
    assert main(["export", "--calib", str(tmp_path / "calib.mat"), "--format", "dlt-coefs",
                 "--out", str(tmp_path / "dlt")]) == 0
    assert np.loadtxt(tmp_path / "dlt" / "dltCoefs.csv", delimiter=",").shape == (11, 2)
