"""Calibration checks: the rig covariance, refusals of bad pairs, cross-validation."""
import dataclasses
import functools
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from wingphoto.calibrate import RIG_PARAMETER_NAMES, board_points, calibrate_stereo

synth = pytest.importorskip("wingphoto.synth")

PATTERN = (9, 6)
SQUARE = 8.0


def _poses(rig, n_tilts=3, n_pans=7):
    """Board -> left camera poses of synth's pan-tilt schedule (raster order)."""
    S, axes = synth.scene_frame(rig)
    centre = np.array([(PATTERN[0] - 1) / 2, (PATTERN[1] - 1) / 2, 0.0]) * SQUARE
    out = []
    for tilt, pan in synth.pan_tilt_schedule(n_tilts, n_pans):
        t, p = np.radians(tilt), np.radians(pan)
        Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
        Rx = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
        Rb = axes @ Ry @ Rx
        out.append((Rb, S - Rb @ centre))
    return out


def _corners_of(rig, sigma, seed, n_tilts=3, n_pans=7):
    X = board_points(PATTERN, SQUARE)
    rng = np.random.default_rng(seed)
    cl, cr = [], []
    for Rb, Tb in _poses(rig, n_tilts, n_pans):
        xl, xr = rig.project(X @ Rb.T + Tb)
        cl.append(xl + rng.normal(0, sigma, xl.shape))
        cr.append(xr + rng.normal(0, sigma, xr.shape))
    return cl, cr


def _pan_tilt_corners(seed, sigma=0.1, n_pans=4):
    """Noisy true corners of 3 x n_pans pan-tilt poses of a thesis rig (no rendering)."""
    rig = synth.thesis_rig(seed=seed, jitter=1.0)
    return (rig, *_corners_of(rig, sigma, 500 + seed, 3, n_pans))


@functools.lru_cache(maxsize=None)
def _calibrated(seed):
    rig, cl, cr = _pan_tilt_corners(seed)
    return rig, calibrate_stereo(cl, cr, PATTERN, SQUARE, image_size=(512, 512))


# ------------------------------------------------------------------ covariance
def test_covariance_matches_the_reported_uncertainty_and_names():
    _, st = _calibrated(0)
    C = st.covariance
    assert C.shape == (26, 26) and st.parameter_names == RIG_PARAMETER_NAMES
    assert st.parameter_names[0] == "fc_left[0]" and st.parameter_names[4] == "alpha_c_left"
    assert st.parameter_names[-6:] == ("om[0]", "om[1]", "om[2]", "T[0]", "T[1]", "T[2]")
    np.testing.assert_allclose(C, C.T, atol=0)
    assert np.linalg.eigvalsh(C).min() > -1e-12 * np.abs(C).max()
    three = 3 * np.sqrt(np.diag(C))
    u = st.uncertainty
    reported = np.concatenate(
        [np.ravel(u[f"{k}_{s}"]) for s in ("left", "right") for k in ("fc", "cc", "alpha_c", "kc")]
        + [u["om"], u["T"]]
    )
    np.testing.assert_allclose(three, reported, rtol=1e-12)
    # fixed by default: skew and k3 -> zero rows
    for name in ("alpha_c_left", "kc_left[4]", "alpha_c_right", "kc_right[4]"):
        k = st.parameter_names.index(name)
        assert not C[k].any() and not C[:, k].any()
    sig = st.parameter_sigma()
    assert sig["T[0]"] == pytest.approx(u["T"][0] / 3)


def test_covariance_is_honest_mahalanobis_over_rigs():
    """The joint error of (om, T) against the truth is chi-square with 6 dof under the covariance."""
    d2 = []
    for seed in range(5):
        rig, st = _calibrated(seed)
        k = [st.parameter_names.index(n) for n in ("om[0]", "om[1]", "om[2]", "T[0]", "T[1]", "T[2]")]
        e = np.concatenate([st.rig.om - rig.om, st.rig.T - rig.T])
        d2.append(e @ np.linalg.solve(st.covariance[np.ix_(k, k)], e))
    # mean of chi2(6) is 6; over 5 rigs (30 dof) the mean lies in [2.5, 11] with > 99 % probability
    assert 2.5 < np.mean(d2) < 11.0, d2


def test_covariance_with_fixed_aspect_ratio_repeats_fc0():
    _, cl, cr = _pan_tilt_corners(1)
    st = calibrate_stereo(cl, cr, PATTERN, SQUARE, image_size=(512, 512), estimate_aspect_ratio=False)
    C = st.covariance
    np.testing.assert_array_equal(C[0], C[1])
    np.testing.assert_array_equal(C[10], C[11])
    np.testing.assert_allclose(3 * np.sqrt(C[1, 1]), st.uncertainty["fc_left"][1], rtol=1e-12)


# ------------------------------------------------------------------ refusals of bad pairs
def _sample_corners(sigma=0.05, seed=0):
    """Noisy true corners of 3 x 5 pan-tilt pairs of data-samples' rig (raster order, as data-samples)."""
    rig = synth.load_rig(Path(__file__).resolve().parents[1] / "data-samples" / "rig.json")
    cl, cr = _corners_of(rig, sigma, seed, 3, 5)
    return cl, cr, dict(image_size=(512, 512), names=[f"calib_{i + 1:02d}" for i in range(len(cl))])


@functools.lru_cache(maxsize=None)
def _good_sample_calibration():
    cl, cr, kw = _sample_corners()
    return calibrate_stereo(cl, cr, PATTERN, SQUARE, **kw)


def test_identical_left_and_right_are_refused():
    cl, _, kw = _sample_corners()
    with pytest.raises(ValueError, match="identical in all 15 pairs .*same folder or files given for both cameras"):
        calibrate_stereo(cl, [c.copy() for c in cl], PATTERN, SQUARE, **kw)


def test_single_identical_pair_is_rejected_by_name():
    cl, cr, kw = _sample_corners()
    cr[4] = cl[4].copy()
    st = calibrate_stereo(cl, cr, PATTERN, SQUARE, **kw)
    assert "identical" in st.rejected["calib_05"] and st.used.sum() == 14
    assert not st.mono_right.used[4]  # the copied left view does not spoil the right camera


def test_good_pairs_all_consistent():
    st = _good_sample_calibration()
    chk = st.pair_check
    assert st.used.all() and chk.offset == 0 and chk.message == "" and chk.inconsistent == []
    assert chk.table["error_px"].max() < 0.5 and chk.tolerance_px == pytest.approx(1.0)
    # each pair's own rig pose is the truth's within a few mm
    rig = synth.load_rig(Path(__file__).resolve().parents[1] / "data-samples" / "rig.json")
    T = chk.table[["T0", "T1", "T2"]].to_numpy()
    assert np.abs(T - rig.T).max() < 5.0


@pytest.mark.parametrize("shift, expect", [(1, -1), (-1, 1), (2, -2)])
def test_constant_offset_is_diagnosed_with_the_fix(shift, expect):
    """Right image i+shift named i: most pairs still agree on a wrong rig; the offset is found."""
    cl, cr, kw = _sample_corners()
    cr = cr[shift:] + cr[:shift]
    msg = re.escape(f"out of sync by {expect:+d}: left image i matches right image i{expect:+d}")
    with pytest.raises(ValueError, match=msg + r".*Fix: pair left image i with right image .*force=True"):
        calibrate_stereo(cl, cr, PATTERN, SQUARE, **kw)
    forced = calibrate_stereo(cl, cr, PATTERN, SQUARE, force=True, **kw)
    assert forced.pair_check.offset == expect
    # what the toolbox would have returned: a tiny pixel error but a wrong rig
    good = _good_sample_calibration()
    assert np.all(forced.pixel_error < 0.1)
    assert np.linalg.norm(forced.rig.T - good.rig.T) > 20.0


def test_single_wrong_pair_is_rejected_by_name():
    cl, cr, kw = _sample_corners()
    cr[5] = cr[6]  # the next pose's right image
    st = calibrate_stereo(cl, cr, PATTERN, SQUARE, **kw)
    assert st.pair_check.offset == 0
    assert st.pair_check.inconsistent == ["calib_06"]
    assert "inconsistent with the other pairs" in st.rejected["calib_06"] and st.used.sum() == 14
    assert np.all(np.abs(st.rig.T - _good_sample_calibration().rig.T) < st.uncertainty["T"])


def test_unpaired_images_are_refused():
    cl, cr, kw = _sample_corners()
    rng = np.random.default_rng(3)
    cr = [cr[k] for k in rng.permutation(len(cr))]
    with pytest.raises(ValueError, match="pairs agree on the rig pose|out of sync"):
        calibrate_stereo(cl, cr, PATTERN, SQUARE, **kw)


# ------------------------------------------------------------------ cross-validation
def test_cross_validation_agrees_for_a_good_calibration():
    from wingphoto.calibcheck import cross_validate

    cv = cross_validate(_good_sample_calibration())
    assert len(cv.halves[0]) == 8 and len(cv.halves[1]) == 7
    assert set(cv.halves[0]).isdisjoint(cv.halves[1])
    assert cv.ok and 0.3 < cv.ratio("left") < 2.0 and 0.3 < cv.ratio("right") < 2.0
    assert "agree within their uncertainty" in cv.summary()


def test_cross_validation_flags_halves_that_disagree_beyond_their_uncertainty(monkeypatch):
    """If the halves' uncertainties were 100x smaller, the same differences must be flagged."""
    from wingphoto import calibcheck

    real = calibcheck._projection_covariance

    def shrunk(p, C, XL):
        cl, cr = real(p, C, XL)
        return cl * 1e-4, cr * 1e-4

    monkeypatch.setattr(calibcheck, "_projection_covariance", shrunk)
    cv = calibcheck.cross_validate(_good_sample_calibration(), split="halves")
    assert len(cv.halves[0]) == 8 and cv.halves[0][0] == "calib_01" and cv.halves[1][0] == "calib_09"
    assert not cv.ok and min(cv.ratio("left"), cv.ratio("right")) > 5
    assert "disagree" in cv.summary()
    with pytest.raises(ValueError, match="split must be"):
        calibcheck.cross_validate(_good_sample_calibration(), split="random")


# ------------------------------------------------------------------ the CLI on rendered image folders
@pytest.fixture(scope="module")
def calib_folders(tmp_path_factory):
    """12 rendered pairs (3 tilts x 4 pans, raster order) as PNG folders."""
    import cv2

    root = tmp_path_factory.mktemp("calib")
    cs = synth.render_calibration_set(n_tilts=3, n_pans=4, supersample=1, seed=5)
    for side, imgs in (("left", cs.left_images), ("right", cs.right_images)):
        (root / side).mkdir()
        for k, img in enumerate(imgs):
            cv2.imwrite(str(root / side / f"{side}{k + 1:02d}.png"), img)
    return root, cs


def _run_cli(argv, capsys):
    from wingphoto.cli import main

    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_writes_error_analysis_and_names_the_worst_views(calib_folders, tmp_path, capsys):
    root, cs = calib_folders
    board = tmp_path / "board.json"
    board.write_text('{"pattern_size": [9, 6], "square_size": 8.0}')
    out = tmp_path / "res" / "Calib_Results_stereo.mat"
    code, text, err = _run_cli(["calibrate", "--left", str(root / "left"), "--right", str(root / "right"),
                                "--board", str(board), "--out", str(out), "--suppress", "2,left05.png"], capsys)
    assert code == 0, err
    assert "pair consistency: 10 of 10 pairs agree" in text and "worst views: " in text
    table = pd.read_csv(out.parent / "view_errors.csv")
    assert table.number.tolist() == list(range(1, 13)) and table.pair.iloc[0] == "left01.png"
    assert not table.used.iloc[1] and not table.used.iloc[4] and table.used.sum() == 10
    assert table.reason.iloc[1] == "suppressed by the user"
    assert (table.loc[table.used, "error_left_px"] < 0.2).all()
    for name in ("residuals_left.png", "residuals_right.png", "view_errors.png", "coverage_left.png",
                 "coverage_right.png"):
        assert (out.parent / name).stat().st_size > 5000
    io = pytest.importorskip("wingphoto.io")
    rig, _ = io.load_bouguet_stereo(out)
    assert np.abs(rig.T - cs.rig.T).max() < 1.0


def test_cli_refuses_the_same_folder_twice_and_shifted_pairs(calib_folders, tmp_path, capsys):
    import shutil

    root, _ = calib_folders
    args = ["--pattern", "9x6", "--square", "8", "--out", str(tmp_path / "c.mat")]
    code, _, err = _run_cli(["calibrate", "--left", str(root / "left"), "--right", str(root / "left")] + args, capsys)
    assert code == 1 and "identical in all 12 pairs" in err
    shifted = tmp_path / "shifted"
    shifted.mkdir()
    names = sorted(p.name for p in (root / "right").iterdir())
    for k, name in enumerate(names):  # right image k+2 saved under the name of k (+ the first two at the end)
        shutil.copy(root / "right" / names[(k + 1) % len(names)], shifted / name)
    code, _, err = _run_cli(["calibrate", "--left", str(root / "left"), "--right", str(shifted)] + args, capsys)
    assert code == 1 and "out of sync by -1" in err and "--force" in err
    assert not (tmp_path / "c.mat").exists()
    code, text, err = _run_cli(["calibrate", "--left", str(root / "left"), "--right", str(shifted), "--force"]
                               + args, capsys)
    assert code == 0 and (tmp_path / "c.mat").exists()


def test_cli_partial_board_and_help(calib_folders, tmp_path, capsys):
    root, _ = calib_folders
    code, text, err = _run_cli(["calibrate", "--left", str(root / "left"), "--right", str(root / "right"),
                                "--pattern", "9x6", "--square", "8", "--rows", "0-3", "--estimate-k3",
                                "--out", str(tmp_path / "c.mat")], capsys)
    assert code == 0, err
    assert "kc_left = [" in text
    from wingphoto.cli import build_parser

    help_text = build_parser()._subparsers._group_actions[0].choices["calibrate"].format_help()
    for flag in ("--suppress", "--estimate-k3", "--estimate-skew", "--rows", "--cols", "--board", "--force",
                 "board.json", "view_errors.csv"):
        assert flag in help_text
    code, _, err = _run_cli(["calibrate", "--left", "x", "--right", "y", "--out", str(tmp_path / "c.mat")], capsys)
    assert code == 1 and "give the board" in err
