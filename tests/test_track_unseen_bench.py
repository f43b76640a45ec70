"""benchmarks/track_unseen.py: each variant changes the frames and, where the image moves,
the truth with them."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from test_track import moving_discs

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "track_unseen.py"


@pytest.fixture(scope="module")
def mod():
    spec = importlib.util.spec_from_file_location("track_unseen", BENCH)
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    return m


@pytest.fixture(scope="module")
def seq():
    frames, truth, _ = moving_discs(3, T=12, speed=4.0)
    return frames, truth, np.ones(truth.shape[:2], bool)


def _centre(img, xy, r=7):
    x, y = np.rint(xy).astype(int)
    w = img[y - r: y + r + 1, x - r: x + r + 1].astype(float)
    w = np.maximum(w - np.median(img), 0)
    yy, xx = np.mgrid[y - r: y + r + 1, x - r: x + r + 1]
    return np.array([(w * xx).sum() / w.sum(), (w * yy).sum() / w.sum()])


@pytest.mark.parametrize("variant", ["bump 5,-3", "bump 4,2,1.5", "vib 2,6", "nup 2"])
def test_the_truth_moves_with_the_image(mod, seq, variant):
    F, T, V = seq
    name, _, arg = variant.partition(" ")
    F2, T2, V2 = mod.apply_variant(F, T, V, name, arg, np.random.default_rng(0), 4)
    t = 8
    moved = np.hypot(*(T2[t, 0] - T[t, 0])) > 1
    assert moved  # (the variant moves the image; the truth follows it)
    assert np.hypot(*(_centre(F2[t], T2[t, 0]) - T2[t, 0])) < 0.3


def test_a_tear_copies_rows_and_keeps_the_truth(mod, seq):
    F, T, V = seq
    F2, T2, V2 = mod.apply_variant(F, T, V, "tear", "", np.random.default_rng(0), 5)
    h = F.shape[1] // 2
    assert np.array_equal(F2[5, h:], F[4, h:]) and np.array_equal(F2[5, :h], F[5, :h])
    assert np.array_equal(T2, T) and np.array_equal(F, seq[0])  # (the input untouched)


def test_dropped_and_black_frames(mod, seq):
    F, T, V = seq
    F2, T2, V2 = mod.apply_variant(F, T, V, "drop", "3", np.random.default_rng(0), 5)
    assert len(F2) == len(T2) == len(V2) == len(F) - 3 and np.array_equal(T2[5], T[8])
    F3, _, V3 = mod.apply_variant(F, T, V, "black", "2", np.random.default_rng(0), 5)
    assert (F3[5:7] == 0).all() and not V3[5:7].any() and V3[7].all()
    with pytest.raises(SystemExit, match="unknown variant"):
        mod.apply_variant(F, T, V, "wobble", "", np.random.default_rng(0), 5)
