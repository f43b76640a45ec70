"""Calibration checks: the rig covariance, refusals of bad pairs, cross-validation."""
import functools

import numpy as np
import pytest

from wingphoto.calibrate import RIG_PARAMETER_NAMES, board_points, calibrate_stereo

synth = pytest.importorskip("wingphoto.synth")

PATTERN = (9, 6)
SQUARE = 8.0


def _pan_tilt_corners(seed, sigma=0.1):
    """Noisy true corners of the 21 pan-tilt poses of a thesis rig (no rendering)."""
    rig = synth.thesis_rig(seed=seed, jitter=1.0)
    S, axes = synth.scene_frame(rig)
    centre = np.array([(PATTERN[0] - 1) / 2, (PATTERN[1] - 1) / 2, 0.0]) * SQUARE
    X = board_points(PATTERN, SQUARE)
    rng = np.random.default_rng(500 + seed)
    cl, cr = [], []
    for tilt, pan in synth.pan_tilt_schedule(3, 7):
        t, p = np.radians(tilt), np.radians(pan)
        Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
        Rx = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
        Rb = axes @ Ry @ Rx
        xl, xr = rig.project(X @ Rb.T + (S - Rb @ centre))
        cl.append(xl + rng.normal(0, sigma, xl.shape))
        cr.append(xr + rng.normal(0, sigma, xr.shape))
    return rig, cl, cr


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
    for seed in range(6):
        rig, st = _calibrated(seed)
        k = [st.parameter_names.index(n) for n in ("om[0]", "om[1]", "om[2]", "T[0]", "T[1]", "T[2]")]
        e = np.concatenate([st.rig.om - rig.om, st.rig.T - rig.T])
        d2.append(e @ np.linalg.solve(st.covariance[np.ix_(k, k)], e))
    # mean of chi2(6) is 6; over 6 rigs (36 dof) the mean lies in [2.5, 11] with > 99 % probability
    assert 2.5 < np.mean(d2) < 11.0, d2


def test_covariance_with_fixed_aspect_ratio_repeats_fc0():
    _, cl, cr = _pan_tilt_corners(1)
    st = calibrate_stereo(cl, cr, PATTERN, SQUARE, image_size=(512, 512), estimate_aspect_ratio=False)
    C = st.covariance
    np.testing.assert_array_equal(C[0], C[1])
    np.testing.assert_array_equal(C[10], C[11])
    np.testing.assert_allclose(3 * np.sqrt(C[1, 1]), st.uncertainty["fc_left"][1], rtol=1e-12)
