"""The README's library snippet runs as written (from the repository root, on data-samples)."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _library_snippet():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## The library"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_readme_library_snippet_runs_as_written():
    if not (REPO / "data-samples" / "flapping" / "picks.json").is_file():
        pytest.skip("data-samples absent")
    code = _library_snippet()
    assert "left_paths" not in code and "tracks_r" in code  # every name it uses is defined in it
    # a fresh interpreter, as a reader would run it: nothing from the test session leaks in
    run = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=600,
                         env={"MPLBACKEND": "Agg", "PATH": "/usr/bin:/bin", "HOME": str(Path.home())})
    assert run.returncode == 0, run.stderr[-3000:]
    # the sample's rigid pairs are 10.770 and 88.022 mm long and constant to well under 10 um
    rows = [line.split() for line in run.stdout.splitlines() if re.match(r"\s*\d+\s+18\s+19\s", line)
            or re.match(r"\s*\d+\s+20\s+21\s", line)]
    assert [(r[1], r[2]) for r in rows] == [("18", "19"), ("20", "21")]
    assert abs(float(rows[0][3]) - 10.770) < 0.01 and abs(float(rows[1][3]) - 88.022) < 0.01
    assert float(rows[0][4]) < 0.01 and float(rows[1][4]) < 0.01


def test_readme_your_own_data_uses_existing_commands():
    from wingphoto.cli import COMMANDS

    text = (REPO / "README.md").read_text(encoding="utf-8")
    start = text.index("## Your own data")
    section = text[start:text.index("\n## ", start)]
    used = set(re.findall(r"^wingphoto (\w+)", section, re.M))
    assert used == {"calibrate", "check", "pick", "track", "triangulate", "analyse"}
    assert used <= set(COMMANDS)
