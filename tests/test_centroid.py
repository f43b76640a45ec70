"""bpass, pkfnd, cntrd: golden parity, the originals' rules stated independently, truth."""
import logging

import numpy as np
import pytest
from scipy.signal import convolve2d

from wingphoto.centroid import bpass, cntrd, matlab_round, pkfnd

DTYPES = [np.uint8, np.uint16, np.float32]


def _blobs(shape, centres, sigma=1.5, amp=200.0):
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    img = np.zeros(shape)
    for x, y in centres:
        img += amp * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * sigma**2))
    return img


# ---------------------------------------------------------------- golden parity
def test_bpass_golden(golden_dir):
    d = np.load(golden_dir / "bpass_cntrd_thesis_params.npz")
    out = bpass(d["image"], int(d["lnoise"]), int(d["lobject"]), int(d["threshold"]))
    np.testing.assert_allclose(out, d["bpass"], rtol=0, atol=1e-9)


def test_cntrd_golden(golden_dir, caplog):
    d = np.load(golden_dir / "bpass_cntrd_thesis_params.npz")
    res = cntrd(d["bpass"], d["peaks"], int(d["sz"]))
    np.testing.assert_array_equal(res.kept, d["kept"])
    assert res.table.shape == d["cntrd"].shape
    np.testing.assert_allclose(res.table, d["cntrd"], rtol=0, atol=1e-9)


def test_bpass_then_cntrd_golden_chain(golden_dir):
    # the thesis' chain from the raw frame, as trackcl.m ran it
    d = np.load(golden_dir / "bpass_cntrd_thesis_params.npz")
    res = cntrd(bpass(d["image"], 1, 10, 20), d["peaks"], 9)
    np.testing.assert_allclose(res.table, d["cntrd"], rtol=0, atol=1e-9)


# ---------------------------------------------------------------- bpass
def _bpass_reference(image, lnoise, lobject, threshold):
    """The original's kernels as one 2-D kernel (its comment: g'g - b'b), zero padding."""
    a = np.asarray(image, dtype=np.float64)
    k = np.arange(-np.ceil(5 * lnoise), np.ceil(5 * lnoise) + 1)
    g = np.exp(-((k / (2 * lnoise)) ** 2))
    g /= g.sum()
    w = int(np.floor(lobject + 0.5))
    b = np.ones(2 * w + 1) / (2 * w + 1)
    out = convolve2d(a, np.outer(g, g), mode="same") - convolve2d(a, np.outer(b, b), mode="same")
    z = int(max(lobject, np.ceil(5 * lnoise)))
    out[:z], out[-z:], out[:, :z], out[:, -z:] = 0, 0, 0, 0
    out[out < threshold] = 0
    return out


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("lnoise, lobject, threshold", [(1, 3, 0), (1.3, 4, 2.5), (0.7, 2, -np.inf)])
def test_bpass_matches_2d_kernel_non_square(dtype, lnoise, lobject, threshold):
    rng = np.random.default_rng(10)
    img = _blobs((21, 23), [(8.3, 9.6), (14.5, 12.2)], amp=100) + 20 * rng.random((21, 23))
    img = img.astype(dtype)
    out = bpass(img, lnoise, lobject, threshold)
    assert out.dtype == np.float64 and out.shape == (21, 23)
    np.testing.assert_allclose(out, _bpass_reference(img, lnoise, lobject, threshold),
                               rtol=0, atol=1e-9)


def test_bpass_border_and_clipping():
    rng = np.random.default_rng(11)
    img = rng.random((40, 47)) * 255
    out = bpass(img, 1, 7)
    # lzero = max(7, ceil(5)) = 7 rows/cols zeroed on every side
    assert np.all(out[:7] == 0) and np.all(out[-7:] == 0)
    assert np.all(out[:, :7] == 0) and np.all(out[:, -7:] == 0)
    assert np.any(out[7:-7, 7:-7] > 0)
    assert out.min() == 0.0
    raw = bpass(img, 1, 7, threshold=-np.inf)
    assert raw.min() < 0
    np.testing.assert_array_equal(out, np.where(raw < 0, 0, raw))


def test_bpass_single_stages():
    rng = np.random.default_rng(12)
    img = rng.random((30, 33)) * 100
    lowpass_only = bpass(img, 1, 0, threshold=-np.inf)  # lobject=0: no background step
    assert lowpass_only.mean() > 10  # a blur keeps the mean level
    highpass_only = bpass(img, 0, 5, threshold=-np.inf)  # lnoise=0: no blur
    assert abs(highpass_only[5:-5, 5:-5].mean()) < 5  # background removed
    with pytest.raises(ValueError, match="lnoise and lobject"):
        bpass(img, -1, 5)
    with pytest.raises(ValueError, match="2-D"):
        bpass(np.zeros((3, 30, 30)), 1, 5)


def test_matlab_round_half_away_from_zero():
    np.testing.assert_array_equal(matlab_round([-1.5, -0.5, 0.5, 1.5, 2.5, 2.4999]),
                                  [-2, -1, 1, 2, 3, 2])
    assert matlab_round(10.5) == 11.0


# ---------------------------------------------------------------- pkfnd
def test_pkfnd_finds_blobs_in_column_major_order():
    img = _blobs((41, 47), [(30, 10), (12, 25), (12, 8)])
    pk = pkfnd(img, 50)
    np.testing.assert_array_equal(pk, [[12, 8], [12, 25], [30, 10]])
    np.testing.assert_array_equal(pkfnd(img, 50, 7), pk)
    assert pkfnd(img, 1000).shape == (0, 2)


def test_pkfnd_plateau_and_sz_rules():
    img = np.zeros((21, 23))
    img[10, 11] = img[10, 12] = 5.0  # flat top: both pixels are >= their neighbours
    assert pkfnd(img, 1).tolist() == [[11, 10], [12, 10]]
    # with sz, the box around a peak keeps one pixel: the first in column-major order
    assert pkfnd(img, 1, 3).tolist() == [[11, 10]]
    # threshold is strict
    assert pkfnd(img, 5).shape == (0, 2)


def test_pkfnd_border_rule_with_sz():
    # 1-based rule: sz < row < nr - sz and sz < col < nc - sz
    img = np.zeros((21, 23))
    img[4, 10] = 9.0  # 1-based row 5: 5 > 4 -> kept
    img[3, 15] = 8.0  # 1-based row 4: not > 4 -> dropped
    img[12, 17] = 7.0  # 1-based col 18 < 23 - 4 = 19 -> kept
    img[15, 18] = 6.0  # 1-based col 19: not < 19 -> dropped
    assert pkfnd(img, 1, 4).tolist() == [[10, 4], [17, 12]]
    assert len(pkfnd(img, 1)) == 4


def test_pkfnd_keeps_brightest_of_close_pair():
    img = _blobs((40, 45), [(20, 20)], amp=100) + _blobs((40, 45), [(25, 21)], amp=60)
    assert len(pkfnd(img, 10)) == 2
    assert pkfnd(img, 10, 9).tolist() == [[20, 20]]


# ---------------------------------------------------------------- cntrd
@pytest.mark.parametrize("dtype", DTYPES)
def test_cntrd_recovers_subpixel_centres(dtype):
    # well inside the window, the centroid of a Gaussian is unbiased
    truth = np.array([[20.3, 18.6], [33.8, 25.45], [18.0, 29.0]])
    img = _blobs((45, 52), truth, sigma=1.2, amp=250).astype(dtype)
    res = cntrd(img, np.ceil(truth), 9)
    assert res.kept.all() and res.table.shape == (3, 4)
    np.testing.assert_allclose(res.xy, truth, atol=0.03)
    ref = cntrd(img.astype(np.float64), np.ceil(truth), 9)
    np.testing.assert_allclose(res.table, ref.table, rtol=1e-12)


def test_cntrd_half_pixel_mask_offset():
    # window for guess (x0, y0) with sz=9 (r=5): columns x0-4 .. x0+5, mask centred at x0+.5
    img = np.zeros((41, 47))
    x0, y0 = 22, 20
    img[y0, x0 + 5] = 1.0  # 4.5 px right of the mask centre: inside
    res = cntrd(img, [[x0, y0]], 9)
    np.testing.assert_allclose(res.table[0], [x0 + 5, y0, 1.0, 4.5**2 + 0.5**2])
    img[:] = 0
    img[y0, x0 - 5] = 1.0  # 5 px left of the guess: outside the window -> 0/0
    assert np.isnan(cntrd(img, [[x0, y0]], 9).table[0, :2]).all()
    img[:] = 0
    img[y0, x0] = 2.0  # squared radius of gyration is taken from the mask centre
    np.testing.assert_allclose(cntrd(img, [[x0, y0]], 9).table[0], [x0, y0, 2.0, 0.5])


def test_cntrd_border_drop_is_reported(caplog):
    img = _blobs((41, 47), [(20, 20)])
    # sz=9: keep when 13.5 < x + 1 < W - 13.5, i.e. 13 <= x <= 32 (W=47), 13 <= y <= 26 (H=41)
    peaks = [[13, 20], [12, 20], [32, 20], [33, 20], [20, 13], [20, 12], [20, 26], [20, 27]]
    with caplog.at_level(logging.WARNING, logger="wingphoto.centroid"):
        res = cntrd(img, peaks, 9)
    np.testing.assert_array_equal(res.kept, [1, 0, 1, 0, 1, 0, 1, 0])
    assert res.table.shape == (4, 4)
    assert "dropped 4 of 8" in caplog.text
    full = res.full()
    assert full.shape == (8, 4) and np.isnan(full[1]).all() and not np.isnan(full[0]).any()
    assert "4 of 8" in res.summary()


def test_cntrd_bad_input(caplog):
    img = np.zeros((41, 47))
    with pytest.raises(ValueError, match="integer pixel"):
        cntrd(img, [[20.5, 20]], 9)
    with pytest.raises(ValueError, match="NaN"):
        cntrd(img, [[np.nan, 20]], 9)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        cntrd(img, [[1, 2, 3]], 9)
    with caplog.at_level(logging.WARNING, logger="wingphoto.centroid"):
        res = cntrd(img, np.zeros((0, 2)), 9)
        assert res.table.shape == (0, 4) and res.kept.shape == (0,)
    assert "no peaks" in caplog.text
    with pytest.raises(ValueError, match="odd"):
        cntrd(img, [[20, 20]], 8)
