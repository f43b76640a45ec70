"""The one global-motion detector: estimate_shift, frame_content, static_background."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from wingphoto.motion import estimate_shift, frame_content, static_background

SAMPLES = Path(__file__).resolve().parents[1] / "data-samples" / "flapping"


def textured(shape=(120, 150), seed=0):
    """Smooth texture with sensor-like noise (phase correlation whitens the spectrum: without
    any noise floor, the empty high frequencies of a blurred image are numerical noise)."""
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.random(shape).astype(np.float32), (0, 0), 2.0)
    return img + rng.normal(0, 0.004, shape).astype(np.float32)


@pytest.mark.parametrize("dxy", [(3, -5), (-7, 2), (0, 0)])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_estimate_shift_recovers_integer_shifts(dxy, dtype):
    a = textured()
    scale = {np.uint8: 255, np.uint16: 4095, np.float32: 1.0}[dtype]
    a = (a * scale).astype(dtype)
    b = np.roll(a, (dxy[1], dxy[0]), axis=(0, 1))  # x right, y down
    s = estimate_shift(a, b)
    assert abs(s.dx - dxy[0]) < 0.25 and abs(s.dy - dxy[1]) < 0.25
    assert s.response > 0.3


def test_estimate_shift_downsampled_large_frame_scales_back():
    a = textured((600, 800), seed=3)
    b = np.roll(a, (6, 10), axis=(0, 1))
    s = estimate_shift(a, b, max_size=200)
    assert abs(s.dx - 10) < 1.0 and abs(s.dy - 6) < 1.0  # 0.25 px of the 200-px image


def test_blank_and_bad_input():
    a = textured()
    assert estimate_shift(a, np.zeros_like(a)) == (0.0, 0.0, 0.0)
    assert frame_content(np.full((5, 6), 7)) == 0.0 and frame_content(a) > 0
    with pytest.raises(ValueError, match="differ in shape"):
        estimate_shift(a, a[:-1])
    with pytest.raises(ValueError, match="max_size must be >= 16"):
        estimate_shift(a, a, max_size=4)
    with pytest.raises(ValueError, match="frames is empty"):
        static_background([])


def test_static_background_ignores_the_wing_and_sees_a_bump():
    if not SAMPLES.is_dir():
        pytest.skip("data-samples not available")
    from wingphoto.io import read_sequence

    frames = read_sequence(SAMPLES / "right")[:40].to_array()
    bg = static_background(frames)
    assert bg.n_features > 0
    clean = np.array([bg.offset(f)[:2] for f in frames])
    assert np.abs(np.diff(clean, axis=0)).max() < 1.0  # the wing moves up to ~5 px/frame
    wing_shift = estimate_shift(frames[20], frames[21])  # the whole-image detector follows the wing
    bumped = frames.copy()
    bumped[20:] = np.roll(bumped[20:], (0, -5), axis=(1, 2))
    bg = static_background(bumped)
    off = np.array([bg.offset(f)[:2] for f in bumped])
    step = off[20] - off[19]
    assert abs(step[0] + 5) < 0.8 and abs(step[1]) < 0.8
    others = np.delete(np.abs(np.diff(off, axis=0)), 19, axis=0)
    assert others.max() < 1.2
    assert np.hypot(wing_shift.dx, wing_shift.dy) > 0  # documented contrast, not a claim of failure


def test_static_background_without_features_gives_nan():
    flat = np.full((5, 40, 50), 3.0, np.float32)
    bg = static_background(flat)
    assert bg.n_features == 0 and np.isnan(bg.offset(flat[0]).dx)
