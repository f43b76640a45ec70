"""benchmarks/track_flags.py: flags by view angle, read from a --save folder."""
import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "track_flags.py"


def _module():
    spec = importlib.util.spec_from_file_location("track_flags", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_flags_are_read_with_their_true_error_and_angle(tmp_path, capsys):
    # two frames x three points: a wing point ok, a wing point flagged 0.1 px off (a false
    # flag), a mount point (left out); the second frame's wing point is not visible
    T, N = 2, 3
    points = np.zeros((T, N, 2))
    rows = [(0, 0, 0.0, 0.0, "ok", ""), (0, 1, 0.1, 0.0, "flagged", "jump"), (0, 2, 0.0, 0.0, "ok", ""),
            (1, 0, 5.0, 0.0, "flagged", "merged"), (1, 1, 0.0, 0.0, "ok", ""), (1, 2, 0.0, 0.0, "ok", "")]
    pd.DataFrame(rows, columns=["frame", "point", "x", "y", "status", "reason"]).to_csv(
        tmp_path / "clean_0_left.csv.gz", index=False)
    np.savez_compressed(tmp_path / "clean_0_left.npz", points=points,
                        visible=np.array([[True, True, True], [False, True, True]]),
                        point_kind=np.array(["wing", "wing", "mount"]),
                        view_angle=np.array([[10.0, 50.0, 0.0], [10.0, 50.0, 0.0]]))
    mod = _module()
    d = mod.load(str(tmp_path / "clean_0_left"))
    assert len(d) == 3  # visible wing point-frames only
    jump = d[d["reason"] == "jump"].iloc[0]
    assert jump["error"] == pytest.approx(0.1) and jump["angle"] == 50.0
    assert mod.main([str(tmp_path)]) == 0
    assert "3 visible wing point-frames" in capsys.readouterr().out


def test_an_empty_folder_is_a_clear_error(tmp_path, capsys):
    with pytest.raises(SystemExit):
        _module().main([str(tmp_path)])
    assert "--save" in capsys.readouterr().err
