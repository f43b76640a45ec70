"""Static checks of the narrated notebooks in ``notebooks/`` (house style, STYLE.md).

The notebooks themselves are executed by nbmake (``make test`` runs
``pytest --nbmake notebooks``); these tests check what execution cannot: that every
notebook is committed without outputs, that code cells stay thin (no ``def`` or
``class``: a helper a notebook needs belongs in the library), and that each one opens as
a lesson with the "What you'll do / learn / need" headings.
"""
from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import pytest

NOTEBOOK_DIR = Path(__file__).resolve().parents[1] / "notebooks"
EXPECTED = [
    "01_calibration_images",
    "02_single_camera_calibration",
    "03_stereo_calibration",
    "04_picking_markers",
    "05_tracking_and_review",
    "06_subpixel_centring",
    "07_triangulation",
    "08_rigid_body_length",
    "09_reversal_and_stillness",
]
HEADINGS = ("what you'll do", "what you'll learn", "what you'll need")
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))


def _load(path):
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def _source(cell):
    src = cell.get("source", "")
    return "".join(src) if isinstance(src, list) else src


def _python_lines(source):
    """The cell's source with IPython magics and shell escapes blanked (kept line numbers)."""
    return "\n".join("" if line.lstrip().startswith(("%", "!")) else line for line in source.splitlines())


def _definitions(source):
    """Names of functions, lambdas and classes defined in a code cell's source."""
    code = _python_lines(source)
    try:
        tree = ast.parse(code)
    except SyntaxError:  # fall back to a textual check; the cell fails under nbmake anyway
        return re.findall(r"^\s*(?:async\s+)?(?:def|class)\s+(\w+)", code, flags=re.M)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            found.append(node.name)
        elif isinstance(node, ast.Lambda):
            found.append("lambda")
    return found


def _headings(nb):
    out = []
    for cell in nb["cells"]:
        if cell["cell_type"] != "markdown":
            continue
        for line in _source(cell).splitlines():
            m = re.match(r"^\s*#{1,6}\s+(.*?)\s*$", line)
            if m:
                out.append(m.group(1).replace("\u2019", "'").lower())
    return out


def test_every_stage_has_its_notebook():
    names = [p.stem for p in NOTEBOOKS]
    missing = [n for n in EXPECTED if n not in names]
    assert not missing, f"notebooks missing from {NOTEBOOK_DIR}: {missing}"


def test_notebooks_readme_lists_every_notebook():
    readme = (NOTEBOOK_DIR / "README.md").read_text(encoding="utf-8")
    absent = [p.name for p in NOTEBOOKS if p.name not in readme]
    assert not absent, f"notebooks/README.md does not mention {absent}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_committed_without_outputs(path):
    nb = _load(path)
    dirty = [
        i for i, c in enumerate(nb["cells"])
        if c["cell_type"] == "code" and (c.get("outputs") or c.get("execution_count") is not None)
    ]
    assert not dirty, (
        f"{path.name}: code cells {dirty} carry outputs or execution counts; clear them before "
        "committing (Jupyter: Edit > Clear All Outputs, or `jupyter nbconvert --clear-output --inplace`)"
    )


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_code_cells_define_nothing(path):
    nb = _load(path)
    bad = {
        i: names for i, c in enumerate(nb["cells"])
        if c["cell_type"] == "code" and (names := _definitions(_source(c)))
    }
    assert not bad, (
        f"{path.name}: code cells define {bad}; a helper a notebook needs belongs in the "
        "library (wingphoto), the notebook only calls it"
    )


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_opens_as_a_lesson(path):
    nb = _load(path)
    first = nb["cells"][0]
    assert first["cell_type"] == "markdown" and _source(first).lstrip().startswith("# "), (
        f"{path.name}: the first cell must be a markdown title ('# ...')"
    )
    heads = _headings(nb)
    missing = [h for h in HEADINGS if not any(x.startswith(h) for x in heads)]
    assert not missing, f"{path.name}: missing the headings {missing} (numpy-tutorials manner)"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_runs_on_the_project_kernel(path):
    nb = _load(path)
    assert nb.get("nbformat") == 4, f"{path.name}: not an nbformat 4 notebook"
    kernel = nb.get("metadata", {}).get("kernelspec", {}).get("name")
    assert kernel == "python3", f"{path.name}: kernelspec name is {kernel!r}, nbmake expects 'python3'"


def test_definition_check_can_fail():
    """The checker above sees definitions, including under magics and in nested code."""
    assert _definitions("%matplotlib widget\nx = 1") == []
    assert _definitions("def f():\n    pass") == ["f"]
    assert _definitions("for i in range(2):\n    class A: pass") == ["A"]
    assert _definitions("g = lambda t: t") == ["lambda"]
