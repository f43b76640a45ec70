"""Wing kinematics, surface, phase and interpolation against synth wings of known kinematics.

Held out: the amplitudes and phases here differ from those the definitions were tuned on
(stroke 100, pitch 35, camber 0.06, bend 3, deviation 6, twist 12).
"""
import json

import numpy as np
import pandas as pd
import pytest

from wingphoto.analysis import stroke_angle
from wingphoto.config import AnalysisSettings
from wingphoto.kinematics import (
    compare_interpolation,
    fit_wing_surface,
    interpolate,
    kinematic_reversals,
    kinematics_wide,
    phase_average,
    resample_phase,
    stroke_phase,
    wing_kinematics,
)
from wingphoto.synth import wing_motion

S = AnalysisSettings.for_synth()
STATION_SIGMA = np.array([0.86, 0.72, 0.58, 0.44, 0.30, 0.16])  # span fraction of each marker station


def _kin(m, points=None, **kw):
    return wing_kinematics(m.points() if points is None else points, leading_edge=S.leading_edge,
                           trailing_edge=S.trailing_edge, chord_rows=S.chord_rows, hinge=m.hinge, **kw)


@pytest.fixture(scope="module")
def known():
    # no bending: the span axis is then the wing's own (bending tilts the root-tip line)
    m = wing_motion(n_frames=200, stroke_amplitude_deg=84, pitch_deg=28, camber=0.05, bend_mm=0.0,
                    deviation_deg=7.5, twist_deg=9.0, phase_deg=37.0)
    k = _kin(m)
    return m, k, kinematics_wide(k)


def test_table_layout(known):
    m, k, w = known
    assert list(k.columns) == ["frame", "quantity", "station", "value", "unit", "sigma"]
    assert set(k["quantity"]) == {"stroke", "deviation", "pitch", "twist", "camber", "bending"}
    assert k.loc[k.quantity == "pitch", "station"].nunique() == 6
    assert k.loc[k.quantity == "stroke", "station"].isna().all()
    assert dict(k.groupby("quantity")["unit"].first()) == {
        "stroke": "deg", "deviation": "deg", "pitch": "deg", "twist": "deg", "camber": "chord", "bending": "mm"}
    # stations: the outermost is 1, the others in proportion of their radius from the hinge
    st = np.sort(k.loc[k.quantity == "pitch", "station"].unique())[::-1]
    np.testing.assert_allclose(st, STATION_SIGMA / STATION_SIGMA[0], atol=0.01)
    assert k["sigma"].isna().all()  # no point sigmas given


def test_stroke_deviation_pitch_twist_camber_match_truth(known):
    m, k, w = known
    tr = m.kinematics
    assert np.abs(w["stroke"] - tr["stroke_deg"]).max() < 0.1  # of +-42 deg
    assert np.abs(w["deviation"] - tr["deviation_deg"]).max() < 0.4  # of +-7.5 deg
    pitch_cols = sorted([c for c in w.columns if c.startswith("pitch@")], key=lambda c: -float(c.split("@")[1]))
    for col, s in zip(pitch_cols, STATION_SIGMA):
        assert np.abs(w[col] - (tr["pitch_deg"] + s * tr["twist_deg"])).max() < 0.15, col
    assert np.abs(w["twist"] - tr["twist_deg"] * (STATION_SIGMA[0] - STATION_SIGMA[-1])).max() < 0.02
    # camber of the marked chord (markers at 18 % and 82 %): the true camber times 0.64
    for col in [c for c in w.columns if c.startswith("camber@")]:
        assert np.abs(w[col] - 0.64 * tr["camber"]).max() < 1e-4
    assert np.abs(w["bending"]).max() < 0.1  # none prescribed (camber on the tapering wing leaks a little)


def test_signs_follow_the_synth_conventions(known):
    m, k, w = known
    tr = m.kinematics
    # where the truth is clearly positive the measurement is too (no sign flips)
    for q, t in (("stroke", "stroke_deg"), ("deviation", "deviation_deg"), ("twist", "twist_deg")):
        big = np.abs(tr[t]) > 0.5 * np.abs(tr[t]).max()
        assert np.all(np.sign(w[q][big]) == np.sign(tr[t][big])), q
    big = np.abs(tr["camber"]) > 0.02
    assert np.all(np.sign(w["camber@1.0"][big]) == np.sign(tr["camber"][big]))


def test_bending_against_truth():
    m = wing_motion(n_frames=60, stroke_amplitude_deg=70, pitch_deg=20, camber=0.0, bend_mm=4.5, phase_deg=11.0)
    w = kinematics_wide(_kin(m))
    true = m.kinematics["bend_mm"] * (STATION_SIGMA[0] - STATION_SIGMA[-1]) ** 2  # from the tangent at the innermost
    assert np.abs(w["bending"] - true).max() < 0.02
    m = wing_motion(n_frames=60, stroke_amplitude_deg=70, pitch_deg=20, camber=0.05, bend_mm=4.5, phase_deg=11.0)
    w = kinematics_wide(_kin(m))
    # camber on a tapering wing leaks a little into the leading edge's curvature
    assert np.abs(w["bending"] - true).max() < 0.25


def test_sigma_matches_monte_carlo():
    m = wing_motion(n_frames=12, stroke_amplitude_deg=90, pitch_deg=30, camber=0.05, bend_mm=2.0, twist_deg=8.0,
                    phase_deg=21.0)
    sd = 0.04
    pts = m.points()
    for a in "XYZ":
        pts[f"sigma_{a}"] = sd
    k = _kin(m, points=pts, stroke_plane=m.stroke_normal)
    base = _kin(m, stroke_plane=m.stroke_normal)
    rng = np.random.default_rng(123)
    draws = []
    for _ in range(40):
        noisy = m.points()
        noisy[["X", "Y", "Z"]] += rng.normal(scale=sd, size=(len(noisy), 3))
        draws.append(_kin(m, points=noisy, stroke_plane=m.stroke_normal)["value"].to_numpy())
    mc = np.std(np.array(draws) - base["value"].to_numpy(), axis=0, ddof=1)
    for q in ("stroke", "deviation", "pitch", "twist", "camber", "bending"):
        sel = (k["quantity"] == q).to_numpy()
        ratio = np.median(mc[sel] / k["sigma"].to_numpy()[sel])
        assert 0.75 < ratio < 1.3, (q, ratio)


def test_reversals_are_sub_frame():
    m = wing_motion(n_frames=160, stroke_amplitude_deg=76, pitch_deg=22, phase_deg=53.0, bend_mm=0.0)
    rev = kinematic_reversals(_kin(m))
    s = rev[rev["quantity"] == "stroke"]
    # stroke = -A/2 cos(th), th = 2 pi t / 100 frames + 53 deg: extrema at th = k * 180 deg
    true = (np.arange(1, 5) * 180.0 - 53.0) / 360.0 * 100.0
    true = true[(true > 2) & (true < 157)]
    np.testing.assert_allclose(s["frame"].to_numpy(), true, atol=0.02)
    assert list(s["kind"]) == ["max", "min", "max"][: len(true)]
    p = rev[(rev["quantity"] == "pitch") & (rev["station"] == 1.0)]
    # pitch = P sin(th): extrema at th = 90 + k 180 deg
    tp = (90.0 + np.arange(0, 4) * 180.0 - 53.0) / 360.0 * 100.0
    tp = tp[(tp > 2) & (tp < 157)]
    np.testing.assert_allclose(p["frame"].to_numpy(), tp, atol=0.05)


def test_stroke_angle_is_the_kinematics_stroke(known):
    m, k, w = known
    s = stroke_angle(m.points(), S.leading_edge, hinge=m.hinge)
    np.testing.assert_allclose(s.angle_deg, w["stroke"].to_numpy(), atol=1e-12)
    np.testing.assert_allclose(s.elevation_deg, w["deviation"].to_numpy(), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(s.direction, axis=1), 1.0, atol=1e-12)
    assert s.normal.tolist() == k.attrs["stroke_plane_normal"]


def test_bad_input():
    m = wing_motion(n_frames=5)
    with pytest.raises(ValueError, match="one trailing-edge marker per leading-edge station"):
        wing_kinematics(m.points(), leading_edge=[0, 3, 6], trailing_edge=[2, 5])
    with pytest.raises(ValueError, match="not both"):
        wing_kinematics(m.points(), leading_edge=[0, 3], root=18, hinge=m.hinge)
    with pytest.raises(ValueError, match=r"leading-edge point 99 is not in the points"):
        wing_kinematics(m.points(), leading_edge=[0, 99])
    with pytest.raises(ValueError, match="sigma must have the points' shape"):
        wing_kinematics(m.points3d, leading_edge=[0, 3], sigma=np.zeros((5, 2, 3)))


# ----------------------------------------------------------------------------- surface
def _distance_to_true_surface(m, frame, V):
    """Distance of each vertex to the true wing surface (Gauss-Newton on (sigma, xi))."""
    sg, xg = np.meshgrid(np.linspace(0, 1, 101), np.linspace(0, 1, 41), indexing="ij")
    grid = m.surface(sg, xg, frame).reshape(-1, 3)
    d = []
    for v in V:
        k = int(np.argmin(np.linalg.norm(grid - v, axis=1)))
        u = np.array([sg.ravel()[k], xg.ravel()[k]])
        for _ in range(8):
            f = m.surface(u[0], u[1], frame) - v
            e = 1e-5
            J = np.column_stack([(m.surface(u[0] + e, u[1], frame) - m.surface(u[0] - e, u[1], frame)) / (2 * e),
                                 (m.surface(u[0], u[1] + e, frame) - m.surface(u[0], u[1] - e, frame)) / (2 * e)])
            u = u - np.linalg.lstsq(J, f, rcond=None)[0]
        d.append(np.linalg.norm(m.surface(u[0], u[1], frame) - v))
    return np.array(d)


@pytest.mark.parametrize("model, tol", [("poly2", 0.35), ("poly3", 0.45), ("tps", 0.25)])
def test_surface_lies_on_the_true_wing(model, tol):
    m = wing_motion(n_frames=30, stroke_amplitude_deg=95, pitch_deg=32, camber=0.07, bend_mm=3.5, phase_deg=70.0)
    surf = fit_wing_surface(m.points(), leading_edge=S.leading_edge, trailing_edge=S.trailing_edge,
                            chord_rows=S.chord_rows, hinge=m.hinge, model=model, mesh_shape=(9, 5))
    assert surf.vertices.shape == (30, 45, 3) and surf.faces.shape == (2 * 8 * 4, 3)
    assert (surf.residuals["n"] == 18).all()
    for frame in (0, 7, 22):
        d = _distance_to_true_surface(m, frame, surf.vertices[frame])
        assert d.max() < tol, (model, frame, d.max())
    if model != "tps":
        assert surf.residuals["rms"].max() < tol
    assert (surf.residuals["loo_rms"] >= surf.residuals["rms"] - 1e-12).all()
    assert "wing surface" in surf.summary()


def test_surface_write_series(tmp_path):
    meshio = pytest.importorskip("meshio")
    m = wing_motion(n_frames=3, phase_deg=15.0)
    pts = m.points()
    pts.loc[(pts.frame == 1) & (pts.point < 18), ["X", "Y", "Z"]] = np.nan  # a frame without the wing
    surf = fit_wing_surface(pts, leading_edge=S.leading_edge, trailing_edge=S.trailing_edge, hinge=m.hinge,
                            mesh_shape=(6, 4))
    assert np.isnan(surf.vertices[1]).all() and surf.residuals.loc[1, "n"] == 0
    idx = surf.write(tmp_path, fmt="vtu")
    files = json.loads(idx.read_text())["files"]
    assert [f["time"] for f in files] == [0.0, 2.0]
    mesh = meshio.read(tmp_path / files[1]["name"])
    np.testing.assert_allclose(mesh.points, surf.vertices[2], atol=1e-9)


# -------------------------------------------------------------------------------- time
def test_stroke_phase_from_partial_view():
    t = np.arange(400)
    angle = 55 * np.cos(2 * np.pi * (t - 23.4) / 100)
    ph = stroke_phase(angle)
    np.testing.assert_allclose(ph[[123, 173]], [1.0 - 0.004, 1.5 - 0.004], atol=0.003)
    # only the upper part of the stroke is seen (the maxima): the phase still follows
    part = np.where(angle > -10, angle, np.nan)
    ph2 = stroke_phase(part)
    assert np.abs(np.mod(ph2 - ph + 0.5, 1.0) - 0.5).max() < 0.01
    with pytest.raises(ValueError, match="only 1 stroke reversal"):
        stroke_phase(angle[:80])


def test_interpolation_methods_on_a_cubic():
    t = np.arange(8.0)
    y = 0.5 * t**3 - t
    q = np.linspace(0, 7, 57)
    np.testing.assert_allclose(interpolate(t, y, q, method="cubic"), 0.5 * q**3 - q, atol=1e-9)
    assert np.isnan(interpolate(t, y, [-0.1, 7.1])).all()
    np.testing.assert_allclose(interpolate(t, y, t, method="cardinal"), y)
    with pytest.raises(ValueError, match="method must be one of"):
        interpolate(t, y, q, method="spline")
    with pytest.raises(ValueError, match="increase strictly"):
        interpolate(t[::-1], y, q)


def test_linear_enough_at_100_frames_per_stroke_splines_needed_at_12():
    m = wing_motion(n_frames=2, stroke_amplitude_deg=104, pitch_deg=41)
    table = compare_interpolation(lambda c: m.model.kinematics(c / m.model.flap_hz)["pitch_deg"])
    e = table.set_index(["samples_per_stroke", "method"])["max_error"]
    assert e[(100, "linear")] < 0.05  # deg, of a 41 deg pitch amplitude
    assert e[(12, "linear")] > 1.0
    assert e[(12, "cardinal")] < e[(12, "linear")] / 5 and e[(12, "cubic")] < e[(12, "linear")] / 5
    assert e[(24, "linear")] < e[(12, "linear")] / 3  # second order: ~1/4


def test_resample_and_phase_average():
    rng = np.random.default_rng(44)
    t = np.arange(500)
    angle = 50 * np.cos(2 * np.pi * (t - 7.7) / 100)
    value = 20 * np.sin(2 * np.pi * (t - 7.7) / 100) + rng.normal(scale=0.5, size=t.size)
    value[230:236] = np.nan
    ph = stroke_phase(angle)
    r = resample_phase(value, ph, bins=50, method="linear")
    assert set(r.columns) == {"cycle", "phase", "frame", "value"}
    assert r["value"].isna().sum() >= 2  # the gap is not bridged
    avg = phase_average(r)
    assert len(avg) == 50 and avg["n"].max() >= 4
    truth = 20 * np.sin(2 * np.pi * avg["phase"].to_numpy())
    assert np.abs(avg["mean"] - truth).max() < 1.2
    assert 0.3 < avg["std"].median() < 0.75  # the noise (0.5)
    with pytest.raises(ValueError, match="phase must increase"):
        resample_phase(value, ph[::-1])
