"""synth.scenarios: the truth of every scenario is where the markers are in its images."""
import numpy as np
import pytest

from wingphoto import synth
from wingphoto.synth import scenarios as sc
from wingphoto.synth.scenarios import _marker_traits, _paint_markers, _wing_state


def _shape_centroid(img, xy, r=7):
    """Centroid of the pixels above half-way between the local background and the
    marker's level (the median of the pixels within 1.5 px of ``xy``): a shape centroid,
    insensitive to texture and highlights."""
    x0, y0 = int(round(xy[0])), int(round(xy[1]))
    win = img[y0 - r : y0 + r + 1, x0 - r : x0 + r + 1].astype(float)
    ys, xs = np.mgrid[-r : r + 1, -r : r + 1]
    d = np.hypot(xs + x0 - xy[0], ys + y0 - xy[1])
    bg = np.median(win[d > r - 1])
    level = np.median(win[d < 1.5])
    m = win > 0.5 * (bg + level)
    # keep the blob that contains the centre (drop neighbours reaching into the window)
    import cv2

    _, lab = cv2.connectedComponents(m.astype(np.uint8))
    m = lab == lab[r, r]
    return np.array([xs[m].mean() + x0, ys[m].mean() + y0])


def _isolated(pts, k, min_gap=16.0):
    d = np.linalg.norm(pts[k][:, None] - pts[k][None], axis=2)
    np.fill_diagonal(d, np.inf)
    return d.min(axis=1) > min_gap


def _check_truth_on_blobs(seq, tol, frames=None, points=range(18)):
    n_checked = 0
    for cam in ("left", "right"):
        img, pts, vis = seq.frames(cam), getattr(seq, f"points_{cam}"), getattr(seq, f"visible_{cam}")
        H, W = img.shape[1:]
        for k in range(len(seq)) if frames is None else frames:
            iso = _isolated(pts, k)
            for j in points:
                p = pts[k, j]
                if not (vis[k, j] and iso[j] and 10 < p[0] < W - 11 and 10 < p[1] < H - 11):
                    continue
                c = _shape_centroid(img[k], p)
                assert np.hypot(*(c - p)) < tol, (cam, k, j, c, p)
                n_checked += 1
    assert n_checked > 10
    return n_checked


def test_names_seeds_and_errors():
    assert len(sc.SCENARIOS) == len(set(sc.SCENARIOS)) >= 17
    assert not set(sc.DEV_SEEDS) & set(sc.TEST_SEEDS)
    assert all(sc.describe(n) for n in sc.SCENARIOS)
    with pytest.raises(ValueError, match="name must be one of the scenarios"):
        sc.render_scenario("sunny_day", seed=0)
    with pytest.raises(ValueError, match="n_frames must be >= 20"):
        sc.render_scenario("dropped_frames", seed=0, n_frames=5)


def test_wing_reconstruction_matches_the_renderer():
    seq = synth.render_flapping(n_frames=3, phase_deg=40.0, preset="hard", motion_blur=False, noise_std=0)
    markers, _, _ = _wing_state(seq)
    for k in range(3):
        X, N = markers(seq.times[k])
        np.testing.assert_allclose(X, seq.points3d[k, :18], atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-9)


@pytest.mark.parametrize("kind", ["painted", "specular"])
def test_repainted_marker_shapes_keep_their_centre(kind):
    """The union coverage of each repainted marker (disc + point-symmetric lobes) has its
    centroid at the truth: texture and highlights change brightness, not the centre."""
    seq = synth.render_flapping(n_frames=1, phase_deg=70.0, noise_std=0, blur_sigma=0, dtype=np.float32)
    markers, _, light = _wing_state(seq)
    X, N = markers(0.0)
    radii = 0.5 * seq.marker_diameter_mm[:18]
    traits = _marker_traits(np.random.default_rng(3), 18, kind)
    img = np.array(seq.left[0])
    before = img.copy()
    mask = np.zeros(img.shape, np.float32)
    _paint_markers(img, seq.rig.left, "left", seq.rig, X, N, radii, light, 4, traits, kind, 0, mask)
    assert np.abs(img - before).max() > 20  # something changed
    ys, xs = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    pts = seq.points_left[0, :18]
    iso = _isolated(seq.points_left, 0, min_gap=30)[:18]
    for j in np.flatnonzero(iso):
        w = mask * (np.hypot(xs - pts[j, 0], ys - pts[j, 1]) < 14)
        c = np.array([(w * xs).sum(), (w * ys).sum()]) / w.sum()
        assert np.hypot(*(c - pts[j])) < 0.02, (j, c, pts[j])
    # outside the markers nothing moved
    np.testing.assert_array_equal(img[mask == 0], before[mask == 0])


@pytest.mark.parametrize("name", ["clean_glare", "painted_markers", "specular_markers", "enter_leave"])
def test_truth_sits_on_the_markers(name):
    seq = sc.render_scenario(name, seed=5, n_frames=3)
    assert seq.left.dtype == np.uint8 and seq.left.shape == (3, 512, 512)
    _check_truth_on_blobs(seq, tol=0.35)


def test_enter_leave_markers_leave_the_frame():
    seq = sc.render_scenario("enter_leave", seed=1, n_frames=40)
    n_out = 0
    for cam in ("left", "right"):
        pts, vis = getattr(seq, f"points_{cam}")[:, :18], getattr(seq, f"visible_{cam}")[:, :18]
        out = (pts[..., 0] < 0) | (pts[..., 0] > 511) | (pts[..., 1] < 0) | (pts[..., 1] > 511)
        assert not vis[out].any()
        n_out += out.sum()
        # a marker that leaves comes back (or was out first): both states in one track
        assert np.any(out.any(axis=0) & vis.any(axis=0)) or not out.any()
    assert n_out > 20


def test_bumped_camera_truth_moves_with_the_image():
    seq = sc.render_scenario("bumped_camera", seed=0, n_frames=20)
    k0, (dx, dy) = seq.params["bump_frame"], seq.params["bump_px"]
    assert 6 <= k0 < 14 and 3 <= abs(dx) <= 7 and 2 <= abs(dy) <= 5
    ref = slice(20, 26)  # static reference dots: their truth jumps by exactly the bump
    np.testing.assert_allclose(seq.points_left[k0, ref] - seq.points_left[k0 - 1, ref], [[dx, dy]] * 6, atol=1e-9)
    np.testing.assert_allclose(seq.points_right[k0, ref] - seq.points_right[k0 - 1, ref], 0, atol=1e-9)
    _check_truth_on_blobs(seq, tol=0.35, frames=[k0 - 1, k0, k0 + 2], points=range(26))


def test_dropped_repeated_black_frames():
    seq = sc.render_scenario("dropped_frames", seed=2, n_frames=20)
    src = np.array(seq.params["source_frames"])
    assert len(src) == 20 and np.all(np.diff(src) >= 1) and (np.diff(src) > 1).sum() >= 2
    dt = np.diff(seq.times) * seq.fps
    np.testing.assert_allclose(dt, np.diff(src))
    _check_truth_on_blobs(seq, tol=0.35, frames=[int(np.argmax(np.diff(src) > 1)) + 1])

    seq = sc.render_scenario("repeated_frames", seed=2, n_frames=20)
    src = np.array(seq.params["source_frames"])
    rep = np.flatnonzero(np.diff(src) == 0)
    assert len(rep) == 3
    for k in rep:
        np.testing.assert_array_equal(seq.left[k], seq.left[k + 1])
        np.testing.assert_array_equal(seq.points_right[k], seq.points_right[k + 1])

    seq = sc.render_scenario("black_frame", seed=2, n_frames=20)
    black = seq.params["black_frames"]
    assert len(black) == 2
    for k in black:
        assert seq.left[k].max() == 0 and seq.right[k].max() == 0
        assert not seq.visible_left[k].any() and not seq.visible_right[k].any()
    assert seq.visible_left[black[0] - 1].any()


def test_seeds_change_the_sequence_and_are_reproducible():
    a = sc.render_scenario("sensor_noise", seed=0, n_frames=2)
    b = sc.render_scenario("sensor_noise", seed=0, n_frames=2)
    c = sc.render_scenario("sensor_noise", seed=1, n_frames=2)
    np.testing.assert_array_equal(a.left, b.left)
    assert np.abs(a.points_left[0] - c.points_left[0]).max() > 1.0  # another phase
    # fixed-pattern noise: the same pixels are off in every frame (on the sensor grid)
    bg = a.left[:, :40, 200:300].astype(float)
    assert np.corrcoef(bg[0].ravel(), bg[1].ravel())[0, 1] > 0.5
