"""Camera and StereoRig: projection, undistortion, OpenCV interop, epipolar geometry."""
import cv2
import numpy as np
import pytest

from wingphoto.camera import Camera, StereoRig, rodrigues, rodrigues_inverse


def _thesis_like_camera():
    return Camera(
        fc=[1831.8, 1809.0], cc=[257.8, 257.9], kc=[0.124, -0.953, 5e-4, -1.2e-3, 0.0],
        alpha_c=0.0, image_size=(512, 512),
    )


def _random_points(rng, n, z=(500.0, 700.0), half=70.0):
    return np.column_stack([rng.uniform(-half, half, n), rng.uniform(-half, half, n), rng.uniform(*z, n)])


def test_camera_is_frozen_with_readonly_float64_arrays():
    cam = Camera(fc=[1000, 900], cc=[10, 20])
    assert cam.fc.dtype == np.float64 and not cam.fc.flags.writeable
    with pytest.raises(ValueError):
        cam.fc[0] = 3.0
    with pytest.raises(Exception):
        cam.fc = np.array([1.0, 2.0])
    assert cam.replace(alpha_c=0.01).alpha_c == 0.01


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(fc=[1000], cc=[0, 0]), "fc must have shape"),
        (dict(fc=[1000, -5], cc=[0, 0]), "fc must be positive"),
        (dict(fc=[1000, 1000], cc=[0, np.nan]), "cc must be finite"),
        (dict(fc=[1000, 1000], cc=[0, 0], kc=[1, 2, 3]), "kc must have shape"),
    ],
)
def test_camera_rejects_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Camera(**kwargs)


def test_project_matches_opencv_projectpoints():
    rng = np.random.default_rng(1)
    cam = _thesis_like_camera()
    X = _random_points(rng, 200, half=40)
    K, dist, _ = cam.to_opencv()
    ref, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, dist)
    np.testing.assert_allclose(cam.project(X), ref.reshape(-1, 2), atol=1e-9)


def test_skew_shifts_x_by_alpha_c_times_fc_times_yd():
    # OpenCV's projectPoints ignores K[0, 1]; the toolbox model does not.
    X = np.array([[10.0, 30.0, 600.0]])
    cam = _thesis_like_camera()
    skewed = cam.replace(alpha_c=0.002)
    xd = cam.distort(X[:, :2] / X[:, 2:])
    shift = skewed.project(X) - cam.project(X)
    np.testing.assert_allclose(shift, [[0.002 * cam.fc[0] * xd[0, 1], 0.0]], atol=1e-12)
    np.testing.assert_allclose(skewed.normalize(skewed.project(X)), X[:, :2] / X[:, 2:], atol=1e-12)


def test_normalize_inverts_project():
    rng = np.random.default_rng(2)
    cam = _thesis_like_camera()
    X = _random_points(rng, 500)
    xn_true = X[:, :2] / X[:, 2:]
    np.testing.assert_allclose(cam.normalize(cam.project(X)), xn_true, atol=1e-9)


def test_normalize_differs_from_opencv_default_iterations_at_corners():
    # A strongly distorted lens: OpenCV's 5 iterations leave a measurable error at the
    # image corner that the toolbox's 20 iterations remove.
    cam = Camera(fc=[400, 400], cc=[319.5, 239.5], kc=[-0.35, 0.15, 0.001, -0.001, 0.0])
    corner = np.array([[0.0, 0.0]])
    K, dist, _ = cam.to_opencv()
    cv5 = cv2.undistortPoints(corner.reshape(-1, 1, 2), K, dist).reshape(-1, 2)
    ours = cam.normalize(corner)
    back = cam.distort(ours)
    xd = (corner - cam.cc) / cam.fc
    assert np.abs(back - xd).max() * 400 < 1e-4  # ours reprojects to 1e-4 px
    assert np.abs(cv5 - ours).max() * 400 > 0.05  # OpenCV's default is ~0.1 px off


def test_nan_rows_give_nan_rows():
    cam = _thesis_like_camera()
    x = cam.project(np.array([[0, 0, 600.0], [np.nan, np.nan, np.nan]]))
    assert np.isfinite(x[0]).all() and np.isnan(x[1]).all()
    xn = cam.normalize(np.array([[np.nan, np.nan], [100.0, 200.0]]))
    assert np.isnan(xn[0]).all() and np.isfinite(xn[1]).all()


def test_single_point_in_single_point_out():
    cam = _thesis_like_camera()
    assert cam.project([1.0, 2.0, 600.0]).shape == (2,)
    assert cam.normalize([100.0, 200.0]).shape == (2,)
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        cam.project(np.zeros((3, 5)))


def test_opencv_round_trip():
    cam = _thesis_like_camera().replace(alpha_c=0.001)
    back = Camera.from_opencv(*cam.to_opencv())
    np.testing.assert_allclose(back.fc, cam.fc)
    np.testing.assert_allclose(back.cc, cam.cc)
    np.testing.assert_allclose(back.kc, cam.kc)
    assert back.alpha_c == pytest.approx(cam.alpha_c)
    assert back.image_size == (512, 512)
    with pytest.raises(ValueError, match="beyond k3"):
        Camera.from_opencv(cam.K, [0, 0, 0, 0, 0, 0.1, 0, 0])


def test_rodrigues_matches_opencv_and_inverts():
    rng = np.random.default_rng(3)
    for _ in range(20):
        om = rng.normal(size=3)
        R_cv, _ = cv2.Rodrigues(om)
        np.testing.assert_allclose(rodrigues(om), R_cv, atol=1e-12)
        np.testing.assert_allclose(rodrigues(rodrigues_inverse(R_cv)), R_cv, atol=1e-9)
    np.testing.assert_array_equal(rodrigues([0, 0, 0]), np.eye(3))


def _rig():
    cam = _thesis_like_camera()
    right = cam.replace(fc=np.array([1842.3, 1832.0]), kc=np.array([0.236, -1.12, 8e-4, -5e-4, 0]))
    return StereoRig(cam, right, om=[0.026, 0.733, 0.003], T=[-272.7, -1.5, 108.7])


def test_rig_projection_uses_x_right_equals_R_x_left_plus_T():
    rig = _rig()
    X = np.array([[5.0, -3.0, 600.0]])
    xL, xR = rig.project(X)
    np.testing.assert_allclose(xR, rig.right.project(X @ rig.R.T + rig.T))
    np.testing.assert_allclose(rig.to_right(X), (rig.R @ X[0] + rig.T)[None])
    assert rig.baseline == pytest.approx(np.linalg.norm([-272.7, -1.5, 108.7]))


def test_epipolar_distance_zero_for_true_pairs_and_grows_with_offset():
    rng = np.random.default_rng(4)
    rig = _rig()
    X = _random_points(rng, 100, z=(550, 650), half=40)
    xL, xR = rig.project(X)
    assert rig.epipolar_distance(xL, xR).max() < 1e-6
    # move the right point perpendicular to its epipolar line by 3 px (in undistorted pixels)
    uR = rig.right.undistort_points(xR)
    uL = rig.left.undistort_points(xL)
    line = np.column_stack([uL, np.ones(len(uL))]) @ rig.fundamental_matrix.T
    normal = line[:, :2] / np.hypot(line[:, 0], line[:, 1])[:, None]
    uR_off = uR + 3.0 * normal
    xR_off = rig.right.project(
        np.column_stack([(uR_off - rig.right.cc) / rig.right.fc, np.ones(len(uR_off))])
    )
    d = rig.epipolar_distance(xL, xR_off)
    # the symmetric distance averages the right (3 px) and left (about 3 px scaled) views
    assert np.all((d > 2.0) & (d < 4.5))


def test_rig_rejects_non_camera():
    with pytest.raises(ValueError, match="left must be a wingphoto.Camera"):
        StereoRig("cam", _thesis_like_camera(), om=[0, 0, 0], T=[1, 0, 0])
