"""Stitching partial tests moved by known rigid transforms back into one stroke (held-out seeds)."""
import numpy as np
import pandas as pd
import pytest

from wingphoto.config import AnalysisSettings
from wingphoto.stitch import stitch_tests
from wingphoto.synth import wing_motion

S = AnalysisSettings.for_synth()


@pytest.fixture(scope="module")
def motion():
    return wing_motion(n_frames=260, stroke_amplitude_deg=112, pitch_deg=38, bend_mm=0.0, phase_deg=-19.0)


def _error_vs_truth(stitched, m):
    p = stitched.points.merge(m.points(), on=["frame", "point"], suffixes=("", "_t")).dropna(subset=["X"])
    return np.linalg.norm(p[["X", "Y", "Z"]].to_numpy() - p[["X_t", "Y_t", "Z_t"]].to_numpy(), axis=1)


@pytest.mark.parametrize("seed", [71, 88])
def test_three_partial_tests_back_into_one_stroke(motion, seed):
    windows = [(-60, -10), (-25, 25), (10, 60)]
    tests, moves = motion.partial_tests(windows, noise_mm=0.02, seed=seed)
    st = stitch_tests(tests, S.reference_ids, leading_edge=S.leading_edge, hinge=motion.hinge)
    # the recovered motions undo the known ones (test 0 is the reference frame)
    for k, (R, t) in enumerate(moves):
        np.testing.assert_allclose(st.rotations[k] @ R, np.eye(3), atol=2e-4)
        np.testing.assert_allclose(st.rotations[k] @ t + st.translations[k], 0.0, atol=0.05)
    err = _error_vs_truth(st, motion)
    assert np.sqrt(np.mean(err**2)) < 0.06 and err.max() < 0.2  # noise 0.02 mm per axis
    assert (st.residuals["residual"] < 0.05).all() and len(st.residuals) == 3 * 6
    # the three partial views make one stroke: every phase bin of the wing is covered
    pm = st.phase_mean(bins=20, point_ids=range(18))
    assert pm["phase"].nunique() == 20
    covered = st.points.dropna(subset=["X"])
    stroke_seen = motion.kinematics["stroke_deg"][covered.loc[covered["point"] == 0, "frame"].unique()]
    assert np.ptp(stroke_seen) > 110
    # the phase agrees between tests: a frame seen by two tests has the same stroke phase
    ph = st.points.groupby(["test", "frame"])["stroke_phase"].first().unstack(0)
    d = np.abs(((ph[1] - ph[0]) + 0.5) % 1.0 - 0.5)
    assert d.max() < 0.02
    assert "test 2" in st.summary()


def test_given_phase_and_no_phase(motion):
    tests, _ = motion.partial_tests([(-70, 70), (-70, 70)], seed=5)
    ph = np.arange(motion.points3d.shape[0]) / 100.0
    st = stitch_tests(tests, S.reference_ids, phase=[ph, ph])
    np.testing.assert_allclose(st.points.loc[st.points["point"] == 0, "phase"], np.concatenate([ph, ph]))
    st = stitch_tests(tests, S.reference_ids)
    assert st.points["phase"].isna().all()
    with pytest.raises(ValueError, match="one array per test"):
        stitch_tests(tests, S.reference_ids, phase=[ph])


def test_refusals(motion):
    tests, _ = motion.partial_tests([(-70, 10), (-10, 70)], seed=9)
    # fewer than 3 shared references
    few = tests[1][~tests[1]["point"].isin([20, 21, 22, 23])]
    with pytest.raises(ValueError, match=r"test 1 shares 2 reference\(s\).*at least 3"):
        stitch_tests([tests[0], few], S.reference_ids)
    # a reference moved between the tests (the flapper's mount was bumped)
    bumped = tests[1].copy()
    bumped.loc[bumped["point"] == 24, ["X", "Y"]] += 1.5
    with pytest.raises(ValueError, match="test 1: reference .* off after the rigid fit"):
        stitch_tests([tests[0], bumped], S.reference_ids)
    # a reference moved during a test
    moving = tests[1].copy()
    late = (moving["point"] == 22) & (moving["frame"] > 130)
    moving.loc[late, "Z"] += 2.0
    with pytest.raises(ValueError, match="test 1: reference 22 moved by up to"):
        stitch_tests([tests[0], moving], S.reference_ids)
    with pytest.raises(ValueError, match="at least 3 reference_ids"):
        stitch_tests(tests, [20, 21])
    with pytest.raises(ValueError, match="tests is empty"):
        stitch_tests([], S.reference_ids)
    with pytest.raises(ValueError, match=r"tests\[0\] must be a points DataFrame"):
        stitch_tests([np.zeros((3, 3))], S.reference_ids)


def test_phase_needs_reversals(motion):
    tests, _ = motion.partial_tests([(-70, 70)], seed=2)
    short = tests[0][tests[0]["frame"] < 40]
    with pytest.raises(ValueError, match="test 0: only .* stroke reversal"):
        stitch_tests([short], S.reference_ids, leading_edge=S.leading_edge)


def test_extra_columns_survive(motion):
    tests, _ = motion.partial_tests([(-70, 70), (-70, 70)], seed=12)
    tests = [t.assign(sigma_X=0.01) for t in tests]
    st = stitch_tests(tests, S.reference_ids)
    assert "sigma_X" in st.points.columns and isinstance(st.points, pd.DataFrame)
    assert st.points["test"].tolist().count(1) == len(tests[1])
