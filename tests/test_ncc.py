"""normxcorr2: parity with MATLAB (golden file and a direct re-statement), properties, errors."""
import numpy as np
import pytest

from wingphoto.ncc import FrameCorrelator, normxcorr2

DTYPES = [np.uint8, np.uint16, np.float32]


def _reference(template, image):
    """MATLAB's formula evaluated window by window (zero padding outside the image)."""
    T = np.asarray(template, dtype=np.float64)
    A = np.asarray(image, dtype=np.float64)
    m, n = T.shape
    H, W = A.shape
    P = np.zeros((H + 2 * (m - 1), W + 2 * (n - 1)))
    P[m - 1: m - 1 + H, n - 1: n - 1 + W] = A
    T0 = T - T.mean()
    tn = np.sqrt((T0**2).sum())
    C = np.zeros((H + m - 1, W + n - 1))
    den = np.zeros_like(C)
    num = np.zeros_like(C)
    for i in range(C.shape[0]):
        for j in range(C.shape[1]):
            w = P[i: i + m, j: j + n]
            num[i, j] = (w * T0).sum()
            den[i, j] = tn * np.sqrt(max((w * w).sum() - w.sum() ** 2 / (m * n), 0.0))
    tol = np.sqrt(np.spacing(den.max()))
    C[den > tol] = num[den > tol] / den[den > tol]
    C[np.abs(C) - 1 > np.sqrt(np.spacing(1.0))] = 0
    return C


def _scaled(rng, shape, dtype):
    if dtype == np.uint8:
        return rng.integers(0, 256, shape).astype(np.uint8)
    if dtype == np.uint16:
        return rng.integers(0, 65536, shape).astype(np.uint16)
    return rng.random(shape).astype(np.float32)


def test_golden_parity(golden_dir):
    d = np.load(golden_dir / "normxcorr2_case.npz")
    C = normxcorr2(d["template"], d["image"])
    assert C.shape == d["C"].shape == (140, 161)
    np.testing.assert_allclose(C, d["C"], rtol=0, atol=1e-9)


@pytest.mark.parametrize("dtype", DTYPES)
def test_matches_direct_formula_non_square(dtype):
    rng = np.random.default_rng(1)
    image = _scaled(rng, (21, 23), dtype)
    template = image[4:9, 10:17].copy()  # 5 x 7
    C = normxcorr2(template, image)
    assert C.shape == (25, 29)
    np.testing.assert_allclose(C, _reference(template, image), rtol=0, atol=1e-9)


@pytest.mark.parametrize("dtype", DTYPES)
def test_self_match_peaks_at_one_where_cut(dtype):
    rng = np.random.default_rng(2)
    image = _scaled(rng, (21, 23), dtype)
    x0, y0, m, n = 11, 3, 6, 5  # template: rows 3..8, cols 11..15
    C = normxcorr2(image[y0: y0 + m, x0: x0 + n], image)
    i, j = np.unravel_index(np.argmax(C), C.shape)
    assert (j - n + 1, i - m + 1) == (x0, y0)
    assert C.max() == pytest.approx(1.0, abs=1e-12)
    assert np.all(np.abs(C) <= 1 + 1e-12)


def test_whole_image_with_itself():
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (21, 23)).astype(np.uint8)
    C = normxcorr2(image, image)
    assert C.shape == (41, 45)
    assert np.unravel_index(np.argmax(C), C.shape) == (20, 22)
    assert C[20, 22] == pytest.approx(1.0, abs=1e-12)


def test_flat_windows_are_zero_not_nan():
    # MATLAB's zeroing rule: where the local image variance vanishes, C = 0
    rng = np.random.default_rng(4)
    image = np.full((30, 34), 7, dtype=np.uint8)
    image[18:27, 20:31] = rng.integers(0, 256, (9, 11))
    template = image[19:24, 22:28].copy()
    C = normxcorr2(template, image)
    assert np.all(np.isfinite(C))
    # the template footprint at full index (i, j) is rows i-4..i, cols j-5..j
    assert np.all(C[4:18, 5:34] == 0)  # footprints inside the image and the flat band
    assert np.all(C[:4, 5:34] != 0)  # partial windows see the zero padding: not flat
    np.testing.assert_allclose(C, _reference(template, image), rtol=0, atol=1e-9)
    assert np.all(normxcorr2(template, np.zeros((30, 34))) == 0)


def test_interior_invariant_to_gain_and_offset():
    rng = np.random.default_rng(5)
    image = rng.random((40, 44))
    template = image[10:19, 20:27].copy()
    C1 = normxcorr2(template, image)
    C2 = normxcorr2(3.0 * template + 1.0, 0.5 * image + 20.0)
    # full-overlap windows only: partial ones see the zero padding
    np.testing.assert_allclose(C1[8:40, 6:44], C2[8:40, 6:44], rtol=0, atol=1e-9)


def test_frame_correlator_matches_and_replaces():
    rng = np.random.default_rng(6)
    frames = rng.integers(0, 4096, (3, 50, 61)).astype(np.uint16)
    temps = [frames[0, 5:16, 7:18], frames[0, 30:39, 40:53], frames[0, 20:27, 3:8]]
    fc = FrameCorrelator(temps, frames.shape[1:])
    for f in frames:
        for k, C in fc.correlate(f):
            np.testing.assert_allclose(C, normxcorr2(temps[k], f), rtol=0, atol=1e-12)
    big = frames[1, 0:40, 0:30]
    fc.replace(1, big)
    (k, C), = list(fc.correlate(frames[2], which=[1]))
    np.testing.assert_allclose(C, normxcorr2(big, frames[2]), rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="same size"):
        next(fc.correlate(frames[0, :40]))


@pytest.mark.parametrize(
    "template, image, match",
    [
        (np.ones((5, 30)), np.zeros((20, 20)), "larger than image"),
        (np.full((4, 4), 3), np.arange(400.0).reshape(20, 20), "constant"),
        (np.ones((1, 1)), np.zeros((20, 20)), "at least 2"),
        (np.eye(3), np.full((20, 20), np.nan), "NaN"),
        (np.eye(3), np.zeros((2, 20, 20)), "2-D"),
    ],
)
def test_bad_input(template, image, match):
    with pytest.raises(ValueError, match=match):
        normxcorr2(template, image)
