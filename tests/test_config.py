"""The analysis-settings schema: defaults, validation, TOML round trip."""
import dataclasses

import pytest

from wingphoto.config import AnalysisSettings, load_analysis_settings


def test_defaults_and_from_dict():
    s = AnalysisSettings()
    assert s.length_pairs == () and s.nominal_lengths is None and s.hinge is None
    assert s.interpolation == "linear" and s.phase_bins == 100 and s.mesh_shape == (21, 11)
    s = AnalysisSettings.from_dict({"length_pairs": [[3, 1], [4, 5]], "nominal_lengths": {"1-3": 10}})
    assert s.length_pairs == ((3, 1), (4, 5))
    assert s.nominal_lengths == {(3, 1): 10.0}  # key order follows length_pairs
    assert s.stations == ()


def test_stations_from_edges_or_rows():
    s = AnalysisSettings(leading_edge=[0, 3], trailing_edge=[2, 5])
    assert s.stations == ((0, 2), (3, 5))
    s = dataclasses.replace(s, chord_rows=[[0, 1, 2], [3, 4, 5]])
    assert s.stations == ((0, 1, 2), (3, 4, 5))


def test_toml_round_trip(tmp_path):
    s = AnalysisSettings.for_synth(hinge=[1.5, -2.0, 400.25], nominal_lengths={"18-19": 10.5}, fps=3000,
                                   interpolation="cardinal", cardinal_tension=0.25)
    p = tmp_path / "analysis.toml"
    p.write_text("# user file\n" + s.to_toml())
    back = load_analysis_settings(p)
    assert back == s
    assert back.hinge == (1.5, -2.0, 400.25) and back.nominal_lengths == {(18, 19): 10.5}
    assert AnalysisSettings.from_dict(s.to_dict()) == s


@pytest.mark.parametrize(
    "mapping, message",
    [
        ({"lenght_pairs": [[1, 2]]}, "unknown analysis setting"),
        ({"length_pairs": [[1, 1]]}, "two different markers"),
        ({"length_pairs": [[1, 2]], "nominal_lengths": {"2-3": 4.0}}, "not in length_pairs"),
        ({"nominal_lengths": {"a-b": 4.0}, "length_pairs": [[1, 2]]}, "\"i-j\""),
        ({"leading_edge": [0, 3], "trailing_edge": [2]}, "one trailing-edge marker per"),
        ({"leading_edge": [-1]}, "start at 0"),
        ({"leading_edge": [1.5]}, "whole marker numbers"),
        ({"root": 4, "hinge": [0, 0, 0]}, "not both"),
        ({"hinge": [0, 0]}, "three finite numbers"),
        ({"interpolation": "spline"}, "interpolation must be one of"),
        ({"surface_model": "nurbs"}, "surface_model must be one of"),
        ({"point_sigma_px": 0}, "point_sigma_px must be a positive"),
        ({"phase_bins": 2}, "phase_bins"),
        ({"mesh_shape": [1, 5]}, "mesh_shape"),
        ({"chord_rows": [[1]]}, "at least 2 markers"),
        ({"stroke_plane": [0, 0, 0]}, "non-zero normal"),
    ],
)
def test_bad_settings_name_the_setting_and_source(mapping, message):
    with pytest.raises(ValueError, match=message) as err:
        AnalysisSettings.from_dict(mapping, source="my.toml")
    assert "my.toml" in str(err.value)


def test_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_analysis_settings(tmp_path / "missing.toml")
    p = tmp_path / "a.toml"
    p.write_text("length_pairs = [[1, 2]]\n")
    with pytest.raises(ValueError, match=r"no \[analysis\] table"):
        load_analysis_settings(p)
    p.write_text("[analysis\n")
    with pytest.raises(ValueError, match="not valid TOML"):
        load_analysis_settings(p)
    p.write_text("[analysis]\nreference_ids = [20, 21, 22]\n[batch]\nx = 1\n")
    assert load_analysis_settings(p).reference_ids == (20, 21, 22)


def test_frozen():
    s = AnalysisSettings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.phase_bins = 3


# ------------------------------------------------------------------ wingphoto analyse
def test_analyse_command_on_a_synth_wing(tmp_path, capsys):
    import numpy as np
    import pandas as pd

    from wingphoto.cli import main
    from wingphoto.io import write_points_csv
    from wingphoto.synth import wing_motion

    # one whole stroke: the zero of the stroke angle is the mean direction (mid-stroke)
    m = wing_motion(n_frames=100, stroke_amplitude_deg=86, pitch_deg=27, deviation_deg=4.0, phase_deg=66.0)
    pts = m.points()
    # the user's own numbering: every marker number shifted by 100
    pts["point"] += 100
    write_points_csv(pts, tmp_path / "points3d.csv")
    s = AnalysisSettings.for_synth(hinge=m.hinge)
    shifted = AnalysisSettings(
        length_pairs=[(i + 100, j + 100) for i, j in s.length_pairs], nominal_lengths={"118-119": 10.0},
        reference_ids=[r + 100 for r in s.reference_ids], leading_edge=[p + 100 for p in s.leading_edge],
        trailing_edge=[p + 100 for p in s.trailing_edge], chord_rows=[[p + 100 for p in r] for r in s.chord_rows],
        hinge=s.hinge, phase_bins=40, mesh_shape=(5, 3), fps=3000.0)
    (tmp_path / "analysis.toml").write_text(shifted.to_toml())
    rc = main(["analyse", str(tmp_path / "points3d.csv"), "--config", str(tmp_path / "analysis.toml"),
               "--out", str(tmp_path / "out")])
    assert rc == 0
    text = capsys.readouterr().out
    assert "references still: test valid" in text and "length 118-119" in text
    out = tmp_path / "out"
    for name in ["kinematics.csv", "reversals.csv", "phase_average.csv", "length_statistics.csv",
                 "reference_stillness.csv", "surface_residuals.csv", "kinematics.png", "analysis.toml",
                 "surface/wing.vtu.series"]:
        assert (out / name).is_file(), name
    kin = pd.read_csv(out / "kinematics.csv")
    np.testing.assert_allclose(kin["time_s"], kin["frame"] / 3000.0)
    stroke = kin[kin["quantity"] == "stroke"].sort_values("frame")["value"].to_numpy()
    assert np.abs(stroke - m.kinematics["stroke_deg"]).max() < 0.75  # 2 mm tip bending tilts the span axis
    stats = pd.read_csv(out / "length_statistics.csv")
    mount = stats[(stats["i"] == 118) & (stats["j"] == 119)].iloc[0]
    assert mount["nominal"] == 10.0 and mount["bias"] == pytest.approx(mount["mean"] - 10.0)
    avg = pd.read_csv(out / "phase_average.csv")
    assert avg["phase"].nunique() == 40
    assert load_analysis_settings(out / "analysis.toml") == shifted


def test_analyse_command_errors(tmp_path, capsys):
    from wingphoto.cli import main

    (tmp_path / "a.toml").write_text("[batch]\nx = 1\n")
    (tmp_path / "p.csv").write_text("frame,point,X,Y,Z,reproj_err\n0,0,1,2,3,0\n")
    rc = main(["analyse", str(tmp_path / "p.csv"), "--config", str(tmp_path / "a.toml"), "--out", str(tmp_path / "o")])
    assert rc == 1 and "no [analysis] table" in capsys.readouterr().err
    (tmp_path / "a.toml").write_text("[analysis]\nleading_edge = [0, 7]\n")
    rc = main(["analyse", str(tmp_path / "p.csv"), "--config", str(tmp_path / "a.toml"), "--out", str(tmp_path / "o")])
    assert rc == 1 and "leading-edge point 7 is not in the points" in capsys.readouterr().err
