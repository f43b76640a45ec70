"""Shared test fixtures: the read-only ../shared material, skipped cleanly when absent, and
the tracker's regression cases on the independent renderer."""
import os
from pathlib import Path

import matplotlib
import numpy as np
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


def _independent_case(kind, seed, camera, n_frames):
    """Render an independent sequence, track it from its frame-0 picks: the (frame, point)
    of every confident error (ok more than 1 px from the truth) and the ok share of
    visible point-frames."""
    from wingphoto import track_markers
    from wingphoto.synth.independent import render_independent

    seq = render_independent(kind, seed=seed, camera=camera, n_frames=n_frames)
    tr = track_markers(seq.frames(), seq.picks(), camera=camera, progress=False)
    T, N = seq.points.shape[:2]
    ok = tr.status.to_numpy().reshape(T, N) == "ok"
    err = np.hypot(tr.x.to_numpy().reshape(T, N) - seq.points[..., 0],
                   tr.y.to_numpy().reshape(T, N) - seq.points[..., 1])
    return np.argwhere(ok & (err > 1.0)).tolist(), (ok & seq.visible).sum() / seq.visible.sum()


@pytest.fixture
def independent_case():
    """``independent_case(kind, seed, camera, n_frames)`` -> (confident errors as
    [frame, point] pairs, ok share of visible point-frames)."""
    return _independent_case
