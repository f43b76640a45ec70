"""Shared test fixtures: the read-only ../shared material, skipped cleanly when absent."""
import os
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("WINGPHOTO_SHARED", REPO.parent / "shared"))
GOLDEN = SHARED / "golden"
BOUGUET_STEREO = SHARED / "data" / "bouguet-stereo"


@pytest.fixture
def golden_dir():
    """Folder of MATLAB golden outputs; skips the test when ../shared is absent."""
    if not GOLDEN.is_dir():
        pytest.skip(f"golden references not found at {GOLDEN}")
    return GOLDEN


@pytest.fixture
def bouguet_dir():
    """Bouguet's real stereo calibration set; skips the test when ../shared is absent."""
    if not (BOUGUET_STEREO / "Calib_Results_left.mat").is_file():
        pytest.skip(f"Bouguet stereo data not found at {BOUGUET_STEREO}")
    return BOUGUET_STEREO
