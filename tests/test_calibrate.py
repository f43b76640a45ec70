"""Calibration: corner detection and order, Bouguet parity on real data, synthetic truth, bad input."""
import functools
import hashlib
import logging

import cv2
import numpy as np
import pytest
import scipy.io as sio

from wingphoto.calibrate import (
    CameraCalibration,
    CornerDetection,
    StereoCalibration,
    board_points,
    calibrate_camera,
    calibrate_stereo,
    find_corners,
    suggest_suppress,
)
from wingphoto.camera import Camera, StereoRig, rodrigues

PATTERN = (9, 6)
SQUARE = 30.0


# ------------------------------------------------------------------ a tiny board renderer
def _rot(rx=0.0, ry=0.0, rz=0.0):
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Rx @ Ry


def _pose(rx, ry, rz, z, pattern=PATTERN, sq=SQUARE, shift=(0.0, 0.0)):
    """Board pose with the board centre on the optical axis at distance z (mm)."""
    R = _rot(rx, ry, rz)
    centre = np.array([(pattern[0] - 1) * sq / 2, (pattern[1] - 1) * sq / 2, 0.0])
    return R, np.array([shift[0], shift[1], z]) - R @ centre


def _render(K, R, T, size, *, pattern=PATTERN, sq=SQUARE, ss=4, blur=1.0, whiteout_v=None, noise=0.0, rng=None):
    """Render a checkerboard (square (0, 0) dark) seen by a distortion-free camera.

    Returns the uint8 image and the true (N, 2) corners in the canonical order.
    """
    w, h = size
    H = K @ np.column_stack([R[:, 0], R[:, 1], T])
    Hinv = np.linalg.inv(H)
    off = (np.arange(ss) + 0.5) / ss - 0.5
    xs = (np.arange(w)[:, None] + off[None, :]).ravel()
    ys = (np.arange(h)[:, None] + off[None, :]).ravel()
    X, Y = np.meshgrid(xs, ys)
    p = Hinv @ np.stack([X.ravel(), Y.ravel(), np.ones(X.size)])
    u, v = p[0] / p[2], p[1] / p[2]
    iu, iv = np.floor(u / sq), np.floor(v / sq)
    inside = (u >= -sq) & (u < pattern[0] * sq) & (v >= -sq) & (v < pattern[1] * sq)
    if whiteout_v is not None:
        inside &= v >= whiteout_v
    dark = inside & ((iu + iv) % 2 == 0)
    img = np.where(dark, 30.0, 220.0).reshape(h * ss, w * ss)
    img = img.reshape(h, ss, w, ss).mean(axis=(1, 3))
    if blur:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    if noise:
        img = img + rng.normal(0, noise, img.shape)
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    Xb = board_points(pattern, sq)
    q = (Xb @ R.T + T) @ K.T
    return img, q[:, :2] / q[:, 2:]


K_TEST = np.array([[700.0, 0, 199.5], [0, 700.0, 149.5], [0, 0, 1]])
SIZE_TEST = (400, 300)


def _views(n=6, seed=0, noise=0.0, size=SIZE_TEST, K=K_TEST):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        rx, ry = rng.uniform(-0.35, 0.35, 2)
        rz = rng.uniform(-0.3, 0.3) + (np.pi if k % 3 == 2 else 0.0)
        R, T = _pose(rx, ry, rz, 900.0, shift=rng.uniform(-15, 15, 2))
        out.append(_render(K, R, T, size, noise=noise, rng=rng))
    return out


@functools.lru_cache(maxsize=None)
def _views_cached(n, seed):
    return tuple(_views(n, seed, noise=1.0))


# ------------------------------------------------------------------ corners
def test_board_points_row_major_opencv_layout():
    X = board_points((9, 6), 30.0)
    assert X.shape == (54, 3)
    np.testing.assert_array_equal(X[1], [30, 0, 0])
    np.testing.assert_array_equal(X[9], [0, 30, 0])
    np.testing.assert_array_equal(X[-1], [240, 150, 0])
    np.testing.assert_array_equal(board_points((3, 4), (10.0, 20.0))[-1], [20, 60, 0])


@pytest.mark.parametrize("rz", [0.2, np.pi + 0.2, np.pi / 2 + 0.1, -np.pi / 2 + 0.1])
def test_find_corners_subpixel_and_physical_order(rz):
    """Rotated a quarter or a half turn, corner 0 is still the same physical corner."""
    R, T = _pose(0.25, -0.2, rz, 900.0)
    img, truth = _render(K_TEST, R, T, SIZE_TEST)
    det = find_corners(img, PATTERN)
    assert det.found and bool(det)
    assert det.corners.shape == (54, 2)
    assert det.image_size == SIZE_TEST
    assert "colour" in det.message
    err = np.hypot(*(det.corners - truth).T)  # px, noise-free render
    assert err.mean() < 0.05 and err.max() < 0.15  # includes the renderer's supersampling error


def test_find_corners_same_identity_in_image_rotated_half_turn():
    R, T = _pose(0.2, 0.3, 0.1, 900.0)
    img, _ = _render(K_TEST, R, T, SIZE_TEST)
    a = find_corners(img, PATTERN)
    b = find_corners(np.rot90(img, 2), PATTERN)
    w, h = SIZE_TEST
    # a half turn maps pixel (x, y) to (w - 1 - x, h - 1 - y): identities must follow
    np.testing.assert_allclose(b.corners, [w - 1, h - 1] - a.corners, atol=1e-3)


def test_find_corners_real_image_rotated_half_turn(bouguet_dir):
    img = cv2.imread(str(bouguet_dir / "left01.jpg"), cv2.IMREAD_GRAYSCALE)
    a = find_corners(img, PATTERN)
    b = find_corners(np.rot90(img, 2).copy(), PATTERN)
    h, w = img.shape
    np.testing.assert_allclose(b.corners, [w - 1, h - 1] - a.corners, atol=1e-3)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_find_corners_dtypes_and_colour(dtype):
    R, T = _pose(-0.2, 0.1, 0.05, 900.0)
    img, truth = _render(K_TEST, R, T, SIZE_TEST)
    scale = {np.uint8: 1, np.uint16: 257, np.float32: 1 / 255}[dtype]
    det = find_corners((img.astype(np.float64) * scale).astype(dtype), PATTERN)
    np.testing.assert_allclose(det.corners, truth, atol=0.2)
    rgb = np.repeat(img[..., None], 3, axis=2)
    np.testing.assert_allclose(find_corners(rgb, PATTERN).corners, truth, atol=0.2)


def test_find_corners_not_found_is_a_result_not_an_exception(tmp_path):
    blank = np.full((240, 320), 128, np.uint8)
    det = find_corners(blank, PATTERN, name="blank.png")
    assert not det.found and not det
    assert det.corners is None
    assert "not found in blank.png" in det.message and "pattern_size=(9, 6)" in det.message
    p = tmp_path / "grey.png"
    cv2.imwrite(str(p), blank)
    assert "not found in grey.png" in find_corners(p, PATTERN).message


def test_find_corners_sub_rectangle_when_top_rows_hidden():
    """Thesis 3.4: the top rows hidden; the visible 9 x 4 block keeps its board identities."""
    R, T = _pose(0.15, -0.2, np.pi + 0.1, 900.0)  # upside down, so the colour rule matters
    img, truth = _render(K_TEST, R, T, SIZE_TEST, whiteout_v=SQUARE)  # rows 0-1 hidden
    assert not find_corners(img, PATTERN).found
    det = find_corners(img, PATTERN, rows=range(2, 6))
    assert det.found and "sub-rectangle" in det.message
    c = det.corners.reshape(6, 9, 2)
    assert np.all(np.isnan(c[:2]))
    np.testing.assert_allclose(c[2:], truth.reshape(6, 9, 2)[2:], atol=0.2)


def test_find_corners_restricts_a_whole_board_to_rows_and_cols():
    R, T = _pose(0.1, 0.1, 0.15, 900.0)
    img, truth = _render(K_TEST, R, T, SIZE_TEST)
    det = find_corners(img, PATTERN, rows=slice(0, 3), cols=[2, 3, 4, 5])
    keep = np.zeros((6, 9), bool)
    keep[0:3, 2:6] = True
    assert np.all(np.isnan(det.corners[~keep.ravel()]))
    np.testing.assert_allclose(det.corners[keep.ravel()], truth[keep.ravel()], atol=0.2)


@pytest.mark.parametrize(
    "kwargs, exc, message",
    [
        (dict(pattern_size=(2, 6)), ValueError, "pattern_size must be"),
        (dict(pattern_size=9), ValueError, "pattern_size must be"),
        (dict(pattern_size=(9, 6), rows=[0, 2]), ValueError, "rows must be a contiguous"),
        (dict(pattern_size=(9, 6), cols=range(7, 12)), ValueError, "cols indices must lie in 0..8"),
        (dict(pattern_size=(9, 6), method="fast"), ValueError, "method must be"),
    ],
)
def test_find_corners_bad_arguments(kwargs, exc, message):
    with pytest.raises(exc, match=message):
        find_corners(np.zeros((50, 60), np.uint8), **kwargs)


def test_find_corners_missing_file_and_bad_array(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.png"):
        find_corners(tmp_path / "nope.png", PATTERN)
    with pytest.raises(ValueError, match="2-D grayscale image"):
        find_corners(np.zeros((4, 5, 6, 7)), PATTERN)


def test_corner_detection_is_read_only():
    R, T = _pose(0.1, 0.1, 0.0, 900.0)
    det = find_corners(_render(K_TEST, R, T, SIZE_TEST)[0], PATTERN)
    assert isinstance(det, CornerDetection)
    with pytest.raises(ValueError):
        det.corners[0, 0] = 1.0


# ------------------------------------------------------------------ Bouguet parity (real data)
@functools.lru_cache(maxsize=None)
def _toolbox(path, side):
    m = sio.loadmat(str(path / f"Calib_Results_{side}.mat"))
    n = int(m["n_ima"].item())
    x = [m[f"x_{i}"].T.astype(float) for i in range(1, n + 1)]
    X = [m[f"X_{i}"].T.astype(float) for i in range(1, n + 1)]
    ref = {k: m[k].ravel().astype(float) for k in ("fc", "cc", "kc", "err_std", "fc_error", "cc_error", "kc_error")}
    ref.update({f"omc_{i}": m[f"omc_{i}"].ravel() for i in range(1, n + 1)})
    ref.update({f"Tc_{i}": m[f"Tc_{i}"].ravel() for i in range(1, n + 1)})
    return x, X, ref


@functools.lru_cache(maxsize=None)
def _own(path, side):
    return calibrate_camera(sorted(path.glob(f"{side}*.jpg")), PATTERN, SQUARE)


@pytest.mark.parametrize("side", ["left", "right"])
def test_parity_with_toolbox_from_its_corners(bouguet_dir, side):
    """Same corners, same model: the toolbox's numbers to 1e-4 px (the issue asks ~1e-3)."""
    x, X, ref = _toolbox(bouguet_dir, side)
    cal = calibrate_camera(x, PATTERN, SQUARE, board_points=X, image_size=(640, 480))
    cam = cal.camera
    np.testing.assert_allclose(cam.fc, ref["fc"], atol=1e-4)
    np.testing.assert_allclose(cam.cc, ref["cc"], atol=1e-4)
    np.testing.assert_allclose(cam.kc, ref["kc"], atol=1e-7)
    assert cam.alpha_c == 0.0
    np.testing.assert_allclose(cal.pixel_error, ref["err_std"], atol=1e-6)
    np.testing.assert_allclose(cal.uncertainty["fc"], ref["fc_error"], rtol=1e-5)
    np.testing.assert_allclose(cal.uncertainty["cc"], ref["cc_error"], rtol=1e-5)
    np.testing.assert_allclose(cal.uncertainty["kc"], ref["kc_error"], rtol=1e-5, atol=1e-12)
    np.testing.assert_array_equal(cal.uncertainty["alpha_c"], [0.0])
    for i in (1, 7, 14):
        np.testing.assert_allclose(cal.omc[i - 1], ref[f"omc_{i}"], atol=1e-7)
        np.testing.assert_allclose(cal.Tc[i - 1], ref[f"Tc_{i}"], atol=1e-4)


@pytest.mark.parametrize("side", ["left", "right"])
def test_own_corners_agree_with_toolbox_within_a_third_of_its_uncertainty(bouguet_dir, side):
    _, _, ref = _toolbox(bouguet_dir, side)
    cal = _own(bouguet_dir, side)
    assert cal.used.all() and cal.rejected == {}
    cam = cal.camera
    assert np.all(np.abs(cam.fc - ref["fc"]) < ref["fc_error"] / 3)
    assert np.all(np.abs(cam.cc - ref["cc"]) < ref["cc_error"] / 3)
    assert np.all(np.abs(cam.kc[:4] - ref["kc"][:4]) < ref["kc_error"][:4] / 3)
    assert cam.kc[4] == 0.0
    np.testing.assert_allclose(cal.pixel_error, ref["err_std"], atol=2e-3)


def test_detected_corners_match_toolbox_corners(bouguet_dir):
    """cornerSubPix with a 15 x 15 window lands on the toolbox's cornerfinder corners."""
    x, _, _ = _toolbox(bouguet_dir, "left")
    paths = sorted(bouguet_dir.glob("left*.jpg"))
    raw = calibrate_camera(paths, PATTERN, SQUARE, correct_locking=False)
    assert raw.corner_correction is None
    for path, mine, theirs, used in zip(paths, raw.corners, x, _own(bouguet_dir, "left").corners):
        np.testing.assert_array_equal(mine, find_corners(path, PATTERN).corners)
        d = np.linalg.norm(mine[:, None, :] - theirs[None, :, :], axis=2).min(axis=1)
        assert d.max() < 0.01  # px
        # the default pixel-locking correction is small on these (blurred, JPEG) images
        assert np.abs(used - mine).max() < 0.05


def test_residuals_are_observed_minus_camera_project(bouguet_dir):
    cal = _own(bouguet_dir, "left")
    for i in (0, 5):
        X = cal.board_points[i] @ rodrigues(cal.omc[i]).T + cal.Tc[i]
        np.testing.assert_allclose(cal.residuals[i], cal.corners[i] - cal.camera.project(X), atol=1e-9)
    allres = np.concatenate([r for r in cal.residuals if r is not None])
    np.testing.assert_allclose(cal.pixel_error, np.std(allres, axis=0, ddof=1), rtol=1e-12)
    assert cal.n_points == 14 * 54


def test_summary_has_the_toolbox_layout(bouguet_dir):
    x, X, _ = _toolbox(bouguet_dir, "left")
    text = calibrate_camera(x, PATTERN, SQUARE, board_points=X, image_size=(640, 480)).summary()
    lines = text.splitlines()
    assert "Focal Length:          fc = [ 533.00371   533.15260 ] \u00b1 [ 1.07629   1.10913 ]" in lines
    assert "Principal point:       cc = [ 341.58612   234.25940 ] \u00b1 [ 1.24041   1.33065 ]" in lines
    assert (
        "Skew:             alpha_c = [ 0.00000 ] \u00b1 [ 0.00000  ]   => angle of pixel axes = "
        "90.00000 \u00b1 0.00000 degrees" in lines
    )
    assert (
        "Distortion:            kc = [ -0.28947   0.10326   0.00103   -0.00029  0.00000 ] \u00b1 "
        "[ 0.00596   0.02055   0.00030   0.00037  0.00000 ]" in lines
    )
    assert "Pixel error:          err = [ 0.13404   0.13007 ]" in lines
    ascii_text = calibrate_camera(x, PATTERN, SQUARE, board_points=X, image_size=(640, 480)).summary(ascii=True)
    assert "fc = [ 533.00371   533.15260 ] +/- [ 1.07629   1.10913 ]" in ascii_text


def test_suppress_recalibrates_without_the_views(bouguet_dir):
    cal = _own(bouguet_dir, "left")
    sub = cal.suppress([0, "left05.jpg"])
    assert isinstance(sub, CameraCalibration)
    assert not sub.used[0] and not sub.used[4] and sub.used.sum() == 12
    assert sub.rejected == {"left01.jpg": "suppressed by the user", "left05.jpg": "suppressed by the user"}
    assert sub.residuals[0] is None and np.all(np.isnan(sub.omc[0]))
    assert sub.n_points == 12 * 54
    # a different estimate, but a consistent one
    assert not np.array_equal(sub.camera.fc, cal.camera.fc)
    assert np.all(np.abs(sub.camera.fc - cal.camera.fc) < sub.uncertainty["fc"])
    assert sub.suppress(1).used.sum() == 11  # suppressions accumulate
    with pytest.raises(ValueError, match="view 'nope.jpg' is not one of"):
        cal.suppress("nope.jpg")


# ------------------------------------------------------------------ stereo on real data
@functools.lru_cache(maxsize=None)
def _stereo_own(path):
    return calibrate_stereo(sorted(path.glob("left*.jpg")), sorted(path.glob("right*.jpg")), PATTERN, SQUARE)


@functools.lru_cache(maxsize=None)
def _stereo_toolbox(path):
    xl, X, _ = _toolbox(path, "left")
    xr, Xr, _ = _toolbox(path, "right")
    assert all(np.array_equal(a, b) for a, b in zip(X, Xr))  # the toolbox clicked the same grid
    return calibrate_stereo(xl, xr, PATTERN, SQUARE, board_points=X, image_size=(640, 480))


def test_stereo_from_toolbox_corners_and_from_own_corners_agree(bouguet_dir):
    ref, own = _stereo_toolbox(bouguet_dir), _stereo_own(bouguet_dir)
    assert own.used.all() and own.rejected == {}
    assert own.pairs[0] == "left01.jpg / right01.jpg"
    u = ref.uncertainty
    assert set(u) == {
        "fc_left", "cc_left", "alpha_c_left", "kc_left", "fc_right", "cc_right", "alpha_c_right",
        "kc_right", "om", "T",
    }
    for a, b, side in ((ref.rig.left, own.rig.left, "left"), (ref.rig.right, own.rig.right, "right")):
        assert np.all(np.abs(a.fc - b.fc) < u[f"fc_{side}"] / 3)
        assert np.all(np.abs(a.cc - b.cc) < u[f"cc_{side}"] / 3)
        assert np.all(np.abs(a.kc[:4] - b.kc[:4]) < u[f"kc_{side}"][:4] / 3)
    assert np.all(np.abs(ref.rig.om - own.rig.om) < u["om"] / 3)
    assert np.all(np.abs(ref.rig.T - own.rig.T) < u["T"] / 3)
    # the rig of the toolbox's example: a ~100 mm horizontal baseline, nearly parallel cameras
    np.testing.assert_allclose(ref.rig.T, [-99.80, 1.12, 0.05], atol=0.02)
    assert ref.rig.baseline == pytest.approx(99.81, abs=0.02)
    # joint refinement is at least as good as the separate calibrations at predicting the
    # right image from the left board poses
    assert np.all(ref.pixel_error_left < 0.16) and np.all(ref.pixel_error_right < 0.17)


def test_stereo_residuals_and_uncertainty_definition(bouguet_dir):
    st = _stereo_toolbox(bouguet_dir)
    rig = st.rig
    i = 3
    XL = st.board_points[i] @ rodrigues(st.omc_left[i]).T + st.Tc_left[i]
    xl, xr = rig.project(XL)
    np.testing.assert_allclose(st.residuals_left[i], st.corners_left[i] - xl, atol=1e-9)
    np.testing.assert_allclose(st.residuals_right[i], st.corners_right[i] - xr, atol=1e-9)
    allres = np.concatenate([r for r in st.residuals_left + st.residuals_right if r is not None])
    assert st.sigma == pytest.approx(np.std(allres.ravel(), ddof=1), rel=1e-12)
    assert st.view_errors.shape == (14, 2)


def test_stereo_summary_layout_and_save_round_trip(bouguet_dir, tmp_path):
    st = _stereo_toolbox(bouguet_dir)
    lines = st.summary().splitlines()
    assert lines[0] == "Stereo calibration parameters after optimization:"
    assert any(line.startswith("Focal Length:          fc_left = [ 533.5") for line in lines)
    assert any(line.startswith("Skew:             alpha_c_right = [ 0.00000 ] \u00b1 [ 0.00000  ]") for line in lines)
    om_line = next(line for line in lines if line.startswith("Rotation vector:             om = [ "))
    assert "] \u00b1 [ " in om_line
    assert any(line.startswith("Translation vector:           T = [ -99.80") for line in lines)
    io = pytest.importorskip("wingphoto.io")
    if not hasattr(io, "load_bouguet_stereo"):
        pytest.skip("wingphoto.io.load_bouguet_stereo not available yet")
    path = tmp_path / "Calib_Results_stereo.mat"
    st.save(path)
    rig, unc = io.load_bouguet_stereo(path)
    np.testing.assert_allclose(rig.T, st.rig.T)
    np.testing.assert_allclose(rig.left.fc, st.rig.left.fc)
    for k, v in st.uncertainty.items():
        np.testing.assert_allclose(np.ravel(unc[k]), np.ravel(v), err_msg=k)


def test_stereo_suppress_pairs(bouguet_dir):
    own = _stereo_own(bouguet_dir)
    sub = own.suppress(["left03.jpg / right03.jpg", 5])
    assert isinstance(sub, StereoCalibration)
    assert sub.used.sum() == 12 and not sub.used[2] and not sub.used[5]
    assert sub.rejected == {
        "left03.jpg / right03.jpg": "suppressed by the user",
        "left06.jpg / right06.jpg": "suppressed by the user",
    }
    assert sub.residuals_left[2] is None and np.isnan(sub.omc_left[5]).all()
    assert not sub.mono_left.used[2] and not sub.mono_right.used[5]
    assert np.all(np.abs(sub.rig.T - own.rig.T) < own.uncertainty["T"])
    assert sub.suppress(0).used.sum() == 11


def test_regions_by_file_name_restrict_one_view(bouguet_dir):
    paths = sorted(bouguet_dir.glob("left*.jpg"))[:4]
    cal = calibrate_camera(paths, PATTERN, SQUARE, regions={"left02.jpg": {"rows": range(0, 3)}})
    assert np.isnan(cal.corners[1]).any(axis=1).sum() == 27
    assert not np.isnan(cal.corners[0]).any()
    assert cal.corner_correction is None  # 189 corners: too few to fit the locking bias
    assert cal.n_points == 3 * 54 + 27


def test_stereo_rejects_inconsistent_pair_by_name(bouguet_dir):
    own = _stereo_own(bouguet_dir)
    xr = list(own.corners_right)
    xr[2], xr[5] = xr[5], xr[2]  # two right views swapped: the board "moved" between exposures
    st = calibrate_stereo(list(own.corners_left), xr, PATTERN, SQUARE, image_size=(640, 480),
                          names=[f"pair{i:02d}" for i in range(14)])
    assert not st.used[2] and not st.used[5] and st.used.sum() == 12
    assert "inconsistent" in st.rejected["pair02"] and "inconsistent" in st.rejected["pair05"]
    assert np.all(np.abs(st.rig.T - own.rig.T) < own.uncertainty["T"])


def test_stereo_sub_rectangle_applied_to_both_views(bouguet_dir):
    L = sorted(bouguet_dir.glob("left*.jpg"))[:6]
    R = sorted(bouguet_dir.glob("right*.jpg"))[:6]
    st = calibrate_stereo(L, R, PATTERN, SQUARE, regions={1: {"rows": range(0, 3), "cols": slice(2, 9)}})
    for corners in (st.corners_left[1], st.corners_right[1]):
        g = corners.reshape(6, 9, 2)
        assert np.all(np.isfinite(g[0:3, 2:9])) and np.isnan(g[3:]).all() and np.isnan(g[:, :2]).all()
    assert np.isnan(st.residuals_left[1][-1]).all() and np.isfinite(st.residuals_left[1][2]).all()
    full = calibrate_stereo(L, R, PATTERN, SQUARE)
    assert np.all(np.abs(st.rig.T - full.rig.T) < full.uncertainty["T"])


# ------------------------------------------------------------------ synthetic (no ../shared)
def test_calibrate_camera_synthetic_views_recover_the_camera():
    views = _views_cached(6, 1)
    cal = calibrate_camera([img for img, _ in views], PATTERN, SQUARE, estimate_tangential=False)
    assert cal.used.all()
    # the renderer's true camera: fc 700, cc (199.5, 149.5), no distortion
    err = np.abs(np.concatenate([cal.camera.fc - 700.0, cal.camera.cc - [199.5, 149.5]]))
    unc = np.concatenate([cal.uncertainty["fc"], cal.uncertainty["cc"]])
    assert np.all(err < unc), (err, unc)
    assert np.all(cal.pixel_error < 0.1)
    assert suggest_suppress(cal) == []


def test_calibrate_from_corners_with_missing_points():
    views = _views_cached(6, 1)
    rng = np.random.default_rng(3)
    corners = []
    for _, truth in views:
        c = truth + rng.normal(0, 0.1, truth.shape)
        c[rng.choice(54, 10, replace=False)] = np.nan
        corners.append(c)
    cal = calibrate_camera(corners, PATTERN, SQUARE, image_size=SIZE_TEST, estimate_tangential=False)
    assert cal.n_points == 6 * 44
    for c, r in zip(corners, cal.residuals):
        np.testing.assert_array_equal(np.isnan(c), np.isnan(r))
    assert np.all(np.abs(cal.camera.fc - 700.0) < cal.uncertainty["fc"])
    np.testing.assert_allclose(cal.pixel_error, 0.1, rtol=0.25)


def test_suggest_suppress_names_a_corrupted_view():
    views = _views_cached(6, 1)
    rng = np.random.default_rng(4)
    corners = [t + rng.normal(0, 0.1, t.shape) for _, t in views]
    corners[3] = corners[3] + rng.normal(0, 1.5, (54, 2))
    names = [f"img{i}.png" for i in range(6)]
    cal = calibrate_camera(corners, PATTERN, SQUARE, image_size=SIZE_TEST, names=names)
    assert suggest_suppress(cal) == ["img3.png"]
    better = cal.suppress(suggest_suppress(cal))
    assert better.pixel_error.max() < 0.5 * cal.pixel_error.max()
    with pytest.raises(ValueError, match="factor must be a positive"):
        suggest_suppress(cal, factor=0)


# ------------------------------------------------------------------ bad input
def test_view_without_board_is_reported_by_name_not_dropped(tmp_path, caplog):
    views = _views_cached(6, 1)
    paths = []
    for i, (img, _) in enumerate(views):
        p = tmp_path / f"cam{i}.png"
        cv2.imwrite(str(p), img)
        paths.append(p)
    blank = tmp_path / "cam_blank.png"
    cv2.imwrite(str(blank), np.full(SIZE_TEST[::-1], 200, np.uint8))
    paths.insert(2, blank)
    before = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in tmp_path.iterdir()}
    with caplog.at_level(logging.WARNING, logger="wingphoto.calibrate"):
        cal = calibrate_camera(paths, PATTERN, SQUARE)
    assert cal.views[2] == "cam_blank.png" and not cal.used[2]
    assert "not found in cam_blank.png" in cal.rejected["cam_blank.png"]
    assert "cam_blank.png" in caplog.text
    assert "rejected cam_blank.png" in cal.summary()
    # nothing written over (or next to) the user's images
    after = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in tmp_path.iterdir()}
    assert after == before


def test_fewer_than_three_usable_views_names_them():
    views = _views_cached(6, 1)
    blank = np.full(SIZE_TEST[::-1], 200, np.uint8)
    with pytest.raises(ValueError, match=r"only 2 usable views .*view 1: .*not found in view 1"):
        calibrate_camera([views[0][0], blank, views[1][0]], PATTERN, SQUARE)


def test_wrong_pattern_size_is_explained():
    views = _views_cached(6, 1)
    with pytest.raises(ValueError, match="found in no image: check pattern_size"):
        calibrate_camera([v[0] for v in views[:3]], (8, 6), SQUARE)
    with pytest.raises(ValueError, match="have 54 corners|has 54 corners|but the board has 40"):
        calibrate_camera([v[1] for v in views[:3]], (8, 5), SQUARE, image_size=SIZE_TEST)


def test_images_of_different_sizes_are_rejected():
    views = _views_cached(6, 1)
    R, T = _pose(0.1, 0.2, 0.0, 900.0)
    other, _ = _render(K_TEST, R, T, (420, 300))
    with pytest.raises(ValueError, match=r"differ in size: view 0 is 400x300 but view 3 is 420x300"):
        calibrate_camera([v[0] for v in views[:3]] + [other], PATTERN, SQUARE)


def test_corners_need_image_size_and_matching_length():
    views = _views_cached(6, 1)
    with pytest.raises(ValueError, match=r"image_size=\(width, height\) is required"):
        calibrate_camera([v[1] for v in views], PATTERN, SQUARE)
    with pytest.raises(ValueError, match="looks like corners of shape"):
        calibrate_camera([v[1][:40] for v in views], PATTERN, SQUARE, image_size=SIZE_TEST)


def test_stereo_count_mismatch_and_too_few_pairs():
    views = _views_cached(6, 1)
    imgs = [v[0] for v in views]
    with pytest.raises(ValueError, match="left_images has 3 views but right_images has 2"):
        calibrate_stereo(imgs[:3], imgs[:2], PATTERN, SQUARE)
    blank = np.full(SIZE_TEST[::-1], 200, np.uint8)
    with pytest.raises(ValueError, match="only 2 usable right-camera views .*view 2: .*not found in view 2"):
        calibrate_stereo(imgs[:4], imgs[:2] + [blank, blank], PATTERN, SQUARE)
    # each camera sees the board three times, but only in two pairs together
    with pytest.raises(ValueError, match=r"only 2 usable pairs .*view 2: right image view 2: .*not found"):
        calibrate_stereo(imgs[:3] + [blank] * 3, imgs[:2] + [blank] + imgs[3:6], PATTERN, SQUARE)


# ------------------------------------------------------------------ synthetic rig truth
def test_stereo_synthetic_rig_recovered_within_uncertainty():
    """A distortion-free rig rendered by the test's own renderer, right camera rotated."""
    rng = np.random.default_rng(7)
    Kr = np.array([[720.0, 0, 205.0], [0, 715.0, 145.0], [0, 0, 1]])
    om_true, T_true = np.array([0.02, 0.25, 0.01]), np.array([-150.0, 2.0, 20.0])
    Rs = rodrigues(om_true)
    left, right = [], []
    for k in range(7):
        rx, ry = rng.uniform(-0.3, 0.3, 2)
        R, T = _pose(rx, ry - 0.1, rng.uniform(-0.2, 0.2), 900.0, shift=(-60 + rng.uniform(-10, 10), 0))
        left.append(_render(K_TEST, R, T, SIZE_TEST, noise=1.0, rng=rng))
        right.append(_render(Kr, Rs @ R, Rs @ T + T_true, SIZE_TEST, noise=1.0, rng=rng))
    st = calibrate_stereo([v[0] for v in left], [v[0] for v in right], PATTERN, SQUARE,
                          estimate_tangential=False)
    assert isinstance(st, StereoCalibration) and isinstance(st.rig, StereoRig)
    u = st.uncertainty
    assert np.all(np.abs(st.rig.om - om_true) < u["om"])
    assert np.all(np.abs(st.rig.T - T_true) < u["T"])
    assert np.all(np.abs(st.rig.right.fc - [720, 715]) < u["fc_right"])
    assert np.all(np.abs(st.rig.left.cc - [199.5, 149.5]) < u["cc_left"])
    assert isinstance(st.rig.left, Camera)


# ------------------------------------------------------------------ honest uncertainties (synth)
synth = pytest.importorskip("wingphoto.synth")

_PARAMS = [(k, side, i) for side in ("left", "right") for k, n in (("fc", 2), ("cc", 2), ("kc", 4)) for i in range(n)]


def _normalised_errors(st, rig):
    """|estimate - truth| / reported 3-sigma for fc, cc, kc[:4] of both cameras, om and T."""
    u = st.uncertainty
    z = [
        abs(getattr(getattr(st.rig, side), k)[i] - getattr(getattr(rig, side), k)[i]) / u[f"{k}_{side}"][i]
        for k, side, i in _PARAMS
    ]
    z += list(np.abs(st.rig.om - rig.om) / u["om"]) + list(np.abs(st.rig.T - rig.T) / u["T"])
    return np.array(z)


def _pan_tilt_poses(rig, pattern, square):
    """The pan-tilt board poses of ``synth.render_calibration_set`` (default 3 x 7 schedule)."""
    S, axes = synth.scene_frame(rig)
    centre = np.array([(pattern[0] - 1) / 2, (pattern[1] - 1) / 2, 0.0]) * square
    poses = []
    for tilt, pan in synth.pan_tilt_schedule(3, 7):
        t, p = np.radians(tilt), np.radians(pan)
        Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
        Rx = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
        Rb = axes @ Ry @ Rx
        poses.append((Rb, S - Rb @ centre))
    return poses


def test_pan_tilt_poses_match_synth():
    rig = synth.thesis_rig(seed=3, jitter=1.0)
    cs = synth.render_calibration_set(rig, n_tilts=1, n_pans=1, seed=0)
    Rb, Tb = _pan_tilt_poses(rig, cs.pattern_size, cs.square_size)[10]  # tilt 0, pan 0
    np.testing.assert_allclose(Rb, rodrigues(cs.poses[0][0]), atol=1e-12)
    np.testing.assert_allclose(Tb, cs.poses[0][1], atol=1e-9)


def test_uncertainties_are_honest_over_20_synthetic_rigs():
    """20 rigs of the thesis design, 21 pan-tilt pairs each, corners with 0.1 px noise.

    Every parameter's error lies inside its reported 3-sigma interval in >= 95 % of the
    440 cases, and inside 1 sigma in about 68 % (so the intervals are not inflated).
    """
    sigma = 0.1
    square = 8.0
    X = board_points(PATTERN, square)
    z, pix = [], []
    for seed in range(20):
        rig = synth.thesis_rig(seed=seed, jitter=1.0)
        rng = np.random.default_rng(1000 + seed)
        cl, cr = [], []
        for Rb, Tb in _pan_tilt_poses(rig, PATTERN, square):
            xl, xr = rig.project(X @ Rb.T + Tb)
            cl.append(xl + rng.normal(0, sigma, xl.shape))
            cr.append(xr + rng.normal(0, sigma, xr.shape))
        st = calibrate_stereo(cl, cr, PATTERN, square, image_size=(512, 512))
        assert st.used.all()
        z.append(_normalised_errors(st, rig))
        pix.append(np.concatenate([st.pixel_error_left, st.pixel_error_right]))
    z = np.concatenate(z)
    inside_3 = np.mean(z < 1.0)
    inside_1 = np.mean(z < 1.0 / 3.0)
    assert inside_3 >= 0.95, inside_3
    assert 0.55 <= inside_1 <= 0.85, inside_1
    # the pixel error is the noise level (less the few degrees of freedom of the fit)
    np.testing.assert_allclose(np.mean(pix), sigma, rtol=0.03)


def test_rendered_calibration_set_end_to_end():
    """Images rendered by synth: detection, stereo calibration, truth.

    One rendered rig (a second seed ran the same path again, 11 s on a busy 2-core
    machine); the honesty of the intervals over many rigs is the job of
    test_uncertainties_are_honest_over_20_synthetic_rigs.

    The pixel error equals the corners' error against the true projections, and the
    parameters lie inside their 3-sigma intervals. Without the pixel-locking correction
    (``correct_locking=False``) the detector's periodic bias (~0.04 px, coherent along
    the nearly horizontal rows) is not the independent noise the toolbox's formula
    assumes: over 8 rigs only 82 % of the parameters were inside 3 sigma, against
    99.5 % over 10 rigs with it.
    """
    seed = 100
    rig = synth.thesis_rig(seed=seed, jitter=1.0)
    cs = synth.render_calibration_set(rig, seed=seed)
    st = calibrate_stereo(cs.left_images, cs.right_images, cs.pattern_size, cs.square_size)
    assert st.used.all() and st.rejected == {}
    for mono in (st.mono_left, st.mono_right):  # the bias of cornerSubPix at 0.6 px blur
        assert 0.02 < abs(mono.corner_correction[0, 0]) < 0.06
        assert 0.03 < abs(mono.corner_correction[1, 0]) < 0.08
    # same corner identities as the truth, and the pixel error is the corners' error
    for mine, truth, err in (
        (st.corners_left, cs.corners_left, st.pixel_error_left),
        (st.corners_right, cs.corners_right, st.pixel_error_right),
    ):
        d = np.concatenate([a - b for a, b in zip(mine, truth)])
        assert np.nanmax(np.abs(d)) < 0.1
        noise = np.nanstd(d, axis=0, ddof=1)
        assert np.all(noise < 0.02)  # px, against ~0.035 before the correction
        assert np.all(err > 0.9 * noise) and np.all(err < 1.02 * noise), (err, noise)
    z = _normalised_errors(st, cs.rig)
    assert np.mean(z < 1.0) >= 0.95 and np.all(z < 1.5), z
