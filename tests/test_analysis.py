"""Analysis against analytic ground truth: a rigid bar of known length with noise of known
sigma, still and moving references, a flapping leading edge with a known sine stroke law;
and on wingphoto.synth's truth when the synthetic scenes are available."""
import logging

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from wingphoto import analysis
from wingphoto.analysis import (
    ReferenceStillness,
    find_reversals,
    length_statistics,
    pairwise_distance,
    points_to_array,
    reference_stillness,
    stroke_angle,
)
from wingphoto.plots3d import plot_length_statistics, plot_points_3d, plot_reference_stillness, plot_stroke_angle

NOMINAL = 53.2  # mm, the thesis' rigid body


def _to_frame(P, frames=None, ids=None):
    T, N, _ = P.shape
    frames = np.arange(T) if frames is None else np.asarray(frames)
    ids = np.arange(N) if ids is None else np.asarray(ids)
    f, p = np.meshgrid(frames, ids, indexing="ij")
    X = P.reshape(-1, 3)
    return pd.DataFrame({"frame": f.ravel(), "point": p.ravel(), "X": X[:, 0], "Y": X[:, 1], "Z": X[:, 2],
                         "reproj_err": 0.1})


def _rigid_bar(rng, n_frames, sigma, length=NOMINAL):
    """A bar of known length tumbling in front of the camera, endpoints with N(0, sigma) noise."""
    centre = np.column_stack([rng.uniform(-30, 30, n_frames), rng.uniform(-30, 30, n_frames),
                              rng.uniform(550, 650, n_frames)])
    u = rng.normal(size=(n_frames, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    P = np.stack([centre - 0.5 * length * u, centre + 0.5 * length * u], axis=1)
    return P + rng.normal(0.0, sigma, P.shape)


# --------------------------------------------------------------------------- distances
def test_pairwise_distance_array_and_frame_agree_with_nan():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(6, 4, 3)) * 10
    P[2, 1] = np.nan
    d = pairwise_distance(P, 1, 3)
    np.testing.assert_allclose(d, np.linalg.norm(P[:, 1] - P[:, 3], axis=1))
    assert np.isnan(d[2]) and np.isfinite(np.delete(d, 2)).all()
    df = _to_frame(P, frames=np.arange(10, 16), ids=[5, 6, 7, 8]).drop(index=[0])  # frame 10 lacks point 5
    s = pairwise_distance(df, 6, 8)
    assert isinstance(s, pd.Series) and s.index.tolist() == list(range(10, 16)) and s.name == "distance_6_8"
    np.testing.assert_allclose(s.to_numpy(), d)
    assert np.isnan(pairwise_distance(df, 5, 6).iloc[0])
    with pytest.raises(ValueError, match=r"j 9 is not in the points \(points present: \[5, 6, 7, 8\]\)"):
        pairwise_distance(df, 5, 9)
    with pytest.raises(ValueError, match=r"\(T, N, 3\) array"):
        pairwise_distance(np.zeros((4, 3)), 0, 1)


def test_points_to_array_fills_nan_and_rejects_duplicates():
    df = pd.DataFrame({"frame": [3, 3, 5], "point": [1, 4, 4], "X": [1.0, 2.0, 3.0], "Y": 0.0, "Z": 9.0})
    P, frames, ids = points_to_array(df)
    assert frames.tolist() == [3, 5] and ids.tolist() == [1, 4]
    assert P[1, 1].tolist() == [3.0, 0.0, 9.0] and np.isnan(P[1, 0]).all()
    with pytest.raises(ValueError, match="several rows for frame 3, point 1"):
        points_to_array(pd.concat([df, df.iloc[:1]]))
    with pytest.raises(ValueError, match=r"lacks columns \['Z'\]"):
        points_to_array(df.drop(columns="Z"))


# --------------------------------------------------------------------------- length statistics
SIGMAS = {"still air": 0.03, "flapping 10 Hz": 0.06, "flapping 30 Hz": 0.12}


def test_length_statistics_recovers_length_and_noise_per_condition():
    rng = np.random.default_rng(1)
    T = 3000
    tests = {c: _rigid_bar(rng, T, s) for c, s in SIGMAS.items()}
    stats = length_statistics(tests, (0, 1), nominal=NOMINAL)
    assert stats.columns.tolist() == ["condition", "i", "j", "n", "mean", "std", "min", "max", "range",
                                      "nominal", "bias", "max_error"]
    assert stats["condition"].tolist() == list(SIGMAS)
    for row, sigma in zip(stats.itertuples(), SIGMAS.values()):
        # the length error is the endpoint noise along the bar: sigma * sqrt(2)
        expected_std = sigma * np.sqrt(2)
        assert row.n == T
        assert abs(row.bias) < 4 * expected_std / np.sqrt(T) + 2 * sigma**2 / NOMINAL
        assert row.std == pytest.approx(expected_std, rel=0.05)
        assert 2.5 * expected_std < row.max - row.mean < 5 * expected_std
        assert 2.5 * expected_std < row.mean - row.min < 5 * expected_std
        assert row.range == pytest.approx(row.max - row.min)
        assert row.max_error == pytest.approx(max(row.max - NOMINAL, NOMINAL - row.min))


def test_length_statistics_conditions_as_column_labels_or_dict_agree():
    rng = np.random.default_rng(2)
    tests = {c: _rigid_bar(rng, 200, s) for c, s in SIGMAS.items()}
    from_dict = length_statistics(tests, [(0, 1)])
    # one table with a condition column; every test numbers its frames from 0
    df = pd.concat([_to_frame(P).assign(condition=c) for c, P in tests.items()], ignore_index=True)
    from_column = length_statistics(df, [(0, 1)], condition="condition")
    pd.testing.assert_frame_equal(from_column, from_dict)
    # one array, a label per frame
    labels = np.repeat(list(SIGMAS), 200)
    from_labels = length_statistics(np.concatenate(list(tests.values())), (0, 1), condition=labels)
    pd.testing.assert_frame_equal(from_labels, from_dict)
    single = length_statistics(tests["still air"], (0, 1))
    assert single["condition"].tolist() == ["all"]
    np.testing.assert_allclose(single[["mean", "std"]].to_numpy(), from_dict[["mean", "std"]].to_numpy()[:1])


def test_length_statistics_is_nan_aware():
    rng = np.random.default_rng(3)
    P = _rigid_bar(rng, 50, 0.05)
    P[::5, 0] = np.nan
    stats = length_statistics({"a": P, "lost": np.full((4, 2, 3), np.nan)}, (0, 1))
    assert stats["n"].tolist() == [40, 0]
    d = np.linalg.norm(P[:, 0] - P[:, 1], axis=1)
    assert stats.loc[0, "mean"] == pytest.approx(np.nanmean(d))
    assert stats.loc[0, "std"] == pytest.approx(np.nanstd(d, ddof=1))
    assert stats.loc[1, ["mean", "std", "min", "max", "range"]].isna().all()
    with pytest.raises(ValueError, match="must name a column"):
        length_statistics(_to_frame(P), (0, 1), condition="speed")
    with pytest.raises(ValueError, match="one label per frame"):
        length_statistics(P, (0, 1), condition=["a", "b"])
    with pytest.raises(ValueError, match="pairs must be a pair"):
        length_statistics(P, [0, 1, 2])


# --------------------------------------------------------------------------- reference stillness
def _references(rng, T=120, sigma=0.02):
    rest = np.array([[40.0, -40.0, 640.0], [-40.0, 20.0, 650.0], [0.0, 45.0, 655.0]])
    return np.repeat(rest[None], T, axis=0) + rng.normal(0, sigma, (T, 3, 3)), rest


def test_still_references_are_valid_and_a_moved_one_invalidates_the_test():
    rng = np.random.default_rng(4)
    P, rest = _references(rng)
    still = reference_stillness(P, [0, 1, 2], tol_mm=0.2)
    assert isinstance(still, ReferenceStillness) and still.valid
    assert still.table["valid"].all() and (still.table["max_displacement"] < 0.15).all()
    # rms distance of 3D N(0, sigma) noise from the mean is sigma * sqrt(3)
    np.testing.assert_allclose(still.table["rms_displacement"], 0.02 * np.sqrt(3), rtol=0.15)
    np.testing.assert_allclose(still.rest, rest, atol=0.01)
    assert "test VALID" in still.summary()

    moved = P.copy()
    moved[60:, 1] += [0.0, 1.0, 0.0]  # the mount slipped by 1 mm half way through
    res = reference_stillness(moved, [0, 1, 2], tol_mm=0.2)
    assert not res.valid and res.table["valid"].tolist() == [True, False, True]
    assert res.table.loc[1, "max_displacement"] == pytest.approx(0.5, abs=0.08)  # half the step from the mean
    first = reference_stillness(moved, [0, 1, 2], tol_mm=0.2, relative_to="first")
    assert first.table.loc[1, "max_displacement"] == pytest.approx(1.0, abs=0.1)
    assert res.displacement.shape == (120, 3) and "INVALID" in res.summary()


def test_reference_never_seen_cannot_validate(caplog):
    rng = np.random.default_rng(5)
    P, _ = _references(rng)
    P[:, 2] = np.nan
    P[:10, 0] = np.nan
    with caplog.at_level(logging.WARNING, logger="wingphoto.analysis"):
        res = reference_stillness(_to_frame(P, ids=[20, 21, 22]), [20, 21, 22], tol_mm=0.2)
    assert res.table["n"].tolist() == [110, 120, 0] and res.table["valid"].tolist() == [True, True, False]
    assert not res.valid and "reference point 22 was never seen" in caplog.text
    with pytest.raises(ValueError, match="tol_mm must be a positive"):
        reference_stillness(P, [0], tol_mm=0)
    with pytest.raises(ValueError, match="relative_to must be"):
        reference_stillness(P, [0], relative_to="median")


# --------------------------------------------------------------------------- stroke angle
FPS, FLAP_HZ, AMPLITUDE, T0 = 3000.0, 30.0, 60.0, 0.37
NORMAL = np.array([0.15, -0.95, 0.25]) / np.linalg.norm([0.15, -0.95, 0.25])


def _plane_axes(normal):
    e1 = np.cross(normal, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)


def _flapping_leading_edge(rng, n_frames=400, sigma=0.0, elevation_deg=0.0):
    """Leading edge markers (tip first) of a wing sweeping phi = A sin(w (t - T0)) about a hinge."""
    t = np.arange(n_frames)
    phi = AMPLITUDE * np.sin(2 * np.pi * FLAP_HZ / FPS * (t - T0))
    e1, e2 = _plane_axes(NORMAL)
    ph, el = np.radians(phi)[:, None], np.radians(elevation_deg)
    d = np.cos(el) * (np.cos(ph) * e1 + np.sin(ph) * e2) + np.sin(el) * NORMAL
    hinge = np.array([-20.0, 5.0, 600.0])
    radii = np.array([48.0, 38.0, 28.0, 18.0])  # tip to root
    P = hinge + radii[None, :, None] * d[:, None, :]
    P = np.concatenate([P, np.repeat(hinge[None, None], n_frames, axis=0)], axis=1)  # point 4: root marker
    return P + rng.normal(0.0, sigma, P.shape), phi, hinge


def test_stroke_angle_follows_the_sine_law_in_a_known_plane():
    rng = np.random.default_rng(6)
    P, phi, hinge = _flapping_leading_edge(rng, sigma=0.03)
    s = stroke_angle(P, [0, 1, 2, 3], root_id=4, stroke_plane=(NORMAL, _plane_axes(NORMAL)[0]))
    # 0.03 mm noise on 5 points spread over 48 mm (rms spread 16.6 mm): the line direction
    # has sigma 0.03 / sqrt(sum (r - mean r)^2) = 0.03 / 37 rad = 0.046 deg; 0.25 deg is 5 sigma
    np.testing.assert_allclose(s.angle_deg, phi, atol=0.25)
    np.testing.assert_allclose(s.elevation_deg, 0.0, atol=0.25)
    assert np.all(np.einsum("ij,ij->i", s.direction, P[:, 0] - P[:, 4]) > 0)  # root -> tip
    by_hinge = stroke_angle(P, [0, 1, 2, 3], hinge=hinge, stroke_plane=(NORMAL, _plane_axes(NORMAL)[0]))
    np.testing.assert_allclose(by_hinge.angle_deg, phi, atol=0.25)
    # out of the stroke plane by a known elevation
    Pe, _, _ = _flapping_leading_edge(rng, elevation_deg=7.0)
    se = stroke_angle(Pe, [0, 1, 2, 3], root_id=4, stroke_plane=(NORMAL, _plane_axes(NORMAL)[0]))
    np.testing.assert_allclose(se.elevation_deg, 7.0, atol=1e-9)
    np.testing.assert_allclose(se.angle_deg, phi, atol=1e-9)


def test_stroke_angle_fits_the_plane_and_mid_stroke_axis():
    rng = np.random.default_rng(7)
    P, phi, _ = _flapping_leading_edge(rng, n_frames=300, sigma=0.03)
    s = stroke_angle(_to_frame(P), [0, 1, 2, 3])
    angle_between = np.degrees(np.arccos(min(abs(s.normal @ NORMAL), 1.0)))
    assert angle_between < 0.2
    assert s.normal[np.argmax(np.abs(s.normal))] > 0  # documented sign convention
    # a fitted plane may flip the sign; the zero axis is the mean direction (mid-stroke)
    sign = np.sign(s.normal @ NORMAL)
    mean_offset = np.degrees(np.arctan2(np.mean(np.sin(np.radians(phi))), np.mean(np.cos(np.radians(phi)))))
    np.testing.assert_allclose(sign * s.angle_deg, phi - mean_offset, atol=0.3)
    assert s.to_frame().columns.tolist() == ["frame", "angle_deg", "elevation_deg"]
    assert "peak-to-peak" in s.summary()


def test_stroke_angle_is_nan_aware():
    rng = np.random.default_rng(8)
    P, phi, _ = _flapping_leading_edge(rng, n_frames=100)
    P[10, 0] = np.nan  # tip lost: the other markers still give the direction
    P[20, :4] = np.nan  # the whole edge lost but the root: no direction
    s = stroke_angle(P, [0, 1, 2, 3], root_id=4, stroke_plane=(NORMAL, _plane_axes(NORMAL)[0]))
    assert np.isfinite(s.angle_deg[10]) and s.angle_deg[10] == pytest.approx(phi[10], abs=1e-9)
    assert np.isnan(s.angle_deg[20]) and np.isnan(s.direction[20]).all()
    with pytest.raises(ValueError, match="either root_id .* or hinge"):
        stroke_angle(P, [0, 1], root_id=4, hinge=[0, 0, 0])
    with pytest.raises(ValueError, match="at least two leading_edge_ids"):
        stroke_angle(P, [0])


# --------------------------------------------------------------------------- reversals
def _true_reversals(n_frames):
    half = FPS / FLAP_HZ / 2  # frames between reversals
    k = np.arange(0, 20)
    r = T0 + half / 2 + k * half
    return r[(r > 1) & (r < n_frames - 2)]


@pytest.mark.parametrize("window", [3, 5, 9])
def test_find_reversals_sub_frame_without_noise(window):
    t = np.arange(400)
    phi = AMPLITUDE * np.sin(2 * np.pi * FLAP_HZ / FPS * (t - T0))
    r = find_reversals(phi, window=window)
    truth = _true_reversals(400)
    assert r.columns.tolist() == ["frame", "angle_deg", "kind", "sample"]
    np.testing.assert_allclose(r["frame"], truth, atol=0.01)
    np.testing.assert_allclose(np.abs(r["angle_deg"]), AMPLITUDE, atol=0.01)
    assert r["kind"].tolist() == ["max", "min"] * (len(truth) // 2) + ["max"] * (len(truth) % 2)
    assert (r["sample"] == np.round(truth).astype(int)).all()


def test_find_reversals_with_noise_gaps_and_frame_numbers():
    rng = np.random.default_rng(9)
    P, phi, _ = _flapping_leading_edge(rng, sigma=0.03)
    s = stroke_angle(_to_frame(P, frames=np.arange(1000, 1400)), [0, 1, 2, 3], root_id=4,
                     stroke_plane=(NORMAL, _plane_axes(NORMAL)[0]))
    s.angle_deg[51] = np.nan  # a lost frame next to a reversal (true at 50.37)
    r = find_reversals(s, window=9)
    truth = _true_reversals(400) + 1000
    # angle noise ~0.03 deg -> reversal time to a few hundredths of a frame; 0.25 frame is generous
    np.testing.assert_allclose(r["frame"], truth, atol=0.25)
    series = pd.Series(s.angle_deg, index=s.frames)
    pd.testing.assert_frame_equal(find_reversals(series, window=9), r)
    noisy = phi + rng.normal(0, 0.5, phi.shape)  # wiggles are not reversals
    assert len(find_reversals(noisy, window=9)) == len(truth)
    assert find_reversals(np.full(10, np.nan)).empty and find_reversals(np.ones(30)).empty
    with pytest.raises(ValueError, match="window must be an odd number"):
        find_reversals(phi, window=4)


# --------------------------------------------------------------------------- synthetic scenes
def _synth():
    synth = pytest.importorskip("wingphoto.synth")
    return synth


def test_rigid_target_truth_gives_the_nominal_length_exactly():
    synth = _synth()
    if not hasattr(synth, "render_rigid_target"):
        pytest.skip("wingphoto.synth.render_rigid_target not available yet")
    seq = synth.render_rigid_target(n_frames=5, distance_mm=NOMINAL, seed=0)
    stats = length_statistics(seq.points3d, (0, 1), nominal=NOMINAL)
    assert stats.loc[0, "n"] == 5
    assert abs(stats.loc[0, "bias"]) < 1e-9 and stats.loc[0, "max_error"] < 1e-9


def test_flapping_truth_references_still_and_stroke_amplitude():
    synth = _synth()
    if not hasattr(synth, "render_flapping"):
        pytest.skip("wingphoto.synth.render_flapping not available yet")
    # only the 3D truth is used, and it does not depend on how the images are rendered:
    # noise-free images without supersampling keep the 130 frames cheap (16 s -> 4 s)
    seq = synth.render_flapping(n_frames=130, fps=FPS, flap_hz=FLAP_HZ, stroke_amplitude_deg=80.0, seed=0,
                                supersample=1, noise_std=0.0)
    kinds = np.asarray(seq.kinds)
    refs = np.flatnonzero(kinds == "reference")
    still = reference_stillness(seq.points3d, refs, tol_mm=1e-6)
    assert still.valid and still.table["max_displacement"].max() < 1e-9
    wing = np.flatnonzero(kinds == "wing")
    leading_edge = wing[::3]  # 3 markers per chord, numbered leading edge first, tip to root
    s = stroke_angle(seq.points3d, leading_edge)
    # the leading-edge markers sit near the pitch axis: the swept angle matches the stroke amplitude
    assert np.ptp(s.angle_deg) == pytest.approx(80.0, abs=1.5)
    r = find_reversals(s)
    assert np.diff(r["frame"]).tolist() == pytest.approx([FPS / FLAP_HZ / 2] * (len(r) - 1), abs=0.5)


# --------------------------------------------------------------------------- plots
def test_plots_draw_on_given_or_new_axes():
    rng = np.random.default_rng(10)
    P, phi, _ = _flapping_leading_edge(rng, n_frames=120, sigma=0.03)
    try:
        ax = plot_points_3d(_to_frame(P), frames=[0, 25, 50], connect="sequence", labels=True)
        assert ax.name == "3d" and len(ax.lines) == 3 and ax.get_title() == "frames 0-50"
        fig = plt.figure()
        ax3 = fig.add_subplot(projection="3d")
        assert plot_points_3d(P, frames=0, ax=ax3, connect=2) is ax3 and len(ax3.lines) == 2 + 2 + 1
        with pytest.raises(ValueError, match="3D axes"):
            plot_points_3d(P, ax=plt.figure().add_subplot())
        with pytest.raises(ValueError, match=r"frames \[999\] are not in the points"):
            plot_points_3d(P, frames=999)

        stats = length_statistics({c: _rigid_bar(rng, 100, s) for c, s in SIGMAS.items()}, (0, 1), nominal=NOMINAL)
        ax = plot_length_statistics(stats)
        assert [t.get_text() for t in ax.get_xticklabels()] == list(SIGMAS)
        assert any(line.get_label() == "nominal 53.2 mm" for line in ax.lines)

        s = stroke_angle(P, [0, 1, 2, 3], root_id=4)
        fig2, ax2 = plt.subplots()
        assert plot_stroke_angle(s, find_reversals(s), ax=ax2, fps=FPS) is ax2
        assert ax2.get_xlabel() == "time (ms)"

        still = reference_stillness(_references(rng)[0], [0, 1, 2], tol_mm=0.2)
        ax = plot_reference_stillness(still)
        assert ax.get_title() == "references still: test valid" and len(ax.lines) == 4
        for f in plt.get_fignums():
            plt.figure(f).canvas.draw()
    finally:
        plt.close("all")


def test_module_exports():
    assert set(analysis.__all__) >= {"pairwise_distance", "length_statistics", "reference_stillness",
                                     "stroke_angle", "find_reversals"}
