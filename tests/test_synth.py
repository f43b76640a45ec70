"""Tests of wingphoto.synth: the ground truth must agree with its own images.

Tolerances: projected truth vs ``rig.project`` 1e-9 px; rendered blob centroids vs the
projected marker centres 0.1 px (noise-free; measured ~0.012 px); OpenCV's checkerboard
corners vs the true corners 0.15 px (measured max ~0.09 px with noise 1); the rigid
target's marker distance 1e-9 mm.
"""
import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from wingphoto import synth
from wingphoto.camera import StereoRig, rodrigues

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "data-samples"


# ----------------------------------------------------------------------------- helpers
def blob_centroids(img, pts, visible, *, half=7, background=None):
    """Background-subtracted, intensity-weighted centroid in a (2 half + 1)^2 window."""
    out = np.full(pts.shape, np.nan)
    for i, (x, y) in enumerate(pts):
        if not visible[i]:
            continue
        xi, yi = int(round(x)), int(round(y))
        win = img[yi - half : yi + half + 1, xi - half : xi + half + 1].astype(np.float64)
        if background is None:
            ring = np.r_[win[0], win[-1], win[:, 0], win[:, -1]]
            background = np.median(ring)
        w = np.clip(win - background, 0, None)
        ys, xs = np.mgrid[yi - half : yi + half + 1, xi - half : xi + half + 1]
        out[i] = (w * xs).sum() / w.sum(), (w * ys).sum() / w.sum()
    return out


def isolated(points, visible, min_dist):
    d = np.linalg.norm(points[:, None] - points[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return visible & (d.min(axis=1) > min_dist)


# ---------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def rig():
    return synth.thesis_rig()


@pytest.fixture(scope="module")
def calib(rig):
    return synth.render_calibration_set(rig, seed=3)


@pytest.fixture(scope="module")
def clean_noise_free(rig):
    # membrane at the background level so that a window's background is flat
    return synth.render_flapping(rig, n_frames=12, phase_deg=-60.0, noise_std=0.0,
                                 membrane_level=synth.LEVELS["background"], dtype=np.float32)


@pytest.fixture(scope="module")
def hard(rig):
    # frames around mid-stroke: fastest motion, leading edge turning edge-on
    return synth.render_flapping(rig, n_frames=8, preset="hard", phase_deg=78.0, seed=5)


# -------------------------------------------------------------------------------- rig
def test_thesis_rig_matches_the_thesis_design(rig):
    assert isinstance(rig, StereoRig)
    for cam in (rig.left, rig.right):
        assert cam.image_size == (512, 512)
        assert np.all((cam.fc > 1830) & (cam.fc < 1860))
        assert np.all(np.abs(cam.cc - 255.5) < 10)
        assert np.all(np.abs(cam.kc[:2]) < 0.3) and cam.kc[4] == 0 and cam.alpha_c == 0
    np.testing.assert_allclose(rig.om, [0.026, 0.733, 0.003])
    np.testing.assert_allclose(rig.T, [-272.7, -1.5, 108.7])


def test_thesis_rig_jitter_is_reproducible_per_seed(rig):
    a = synth.thesis_rig(seed=1, jitter=1.0)
    assert a == synth.thesis_rig(seed=1, jitter=1.0)
    assert a != synth.thesis_rig(seed=2, jitter=1.0)
    assert a != rig
    assert synth.thesis_rig(seed=1) == rig  # seed alone does not perturb
    assert np.all(np.abs(a.left.fc - rig.left.fc) < 60)
    with pytest.raises(ValueError, match="needs a seed"):
        synth.thesis_rig(jitter=1.0)
    with pytest.raises(ValueError, match="non-negative"):
        synth.thesis_rig(seed=0, jitter=-1)


def test_scene_frame_is_where_both_cameras_look(rig):
    origin, axes = synth.scene_frame(rig)
    np.testing.assert_allclose(axes.T @ axes, np.eye(3), atol=1e-12)
    assert np.linalg.det(axes) > 0
    xl, xr = rig.project(origin)
    # the axes converge to within ~11 mm (5 mm either side: ~25 px)
    assert np.hypot(*(xl - rig.left.cc)) < 30
    assert np.hypot(*(xr - rig.right.cc)) < 30


def test_rig_dict_round_trip(rig):
    back = synth.rig_from_dict(json.loads(json.dumps(synth.rig_to_dict(rig))))
    assert back == rig


# ------------------------------------------------------------------ checkerboards
def test_calibration_set_structure(calib, rig):
    assert len(calib) == 21 and len(calib.right_images) == 21 and len(calib.poses) == 21
    assert calib.left_images[0].dtype == np.uint8 and calib.left_images[0].shape == (512, 512)
    assert calib.board_points.shape == (54, 3)
    # poses map the board into the left frame; corners are their projections
    for (om, T), cl, cr in zip(calib.poses, calib.corners_left, calib.corners_right):
        X = calib.board_points @ rodrigues(om).T + T
        xl, xr = rig.project(X)
        np.testing.assert_allclose(cl, xl, atol=1e-9)
        np.testing.assert_allclose(cr, xr, atol=1e-9)
        assert np.all(np.isfinite(cl)) and np.all(np.isfinite(cr))  # whole board in view
    assert "21 stereo pairs" in calib.summary()


def test_checkerboard_detected_by_opencv_in_truth_order(calib):
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    worst = 0.0
    for k in range(len(calib)):
        for side in ("left", "right"):
            img = getattr(calib, f"{side}_images")[k]
            truth = getattr(calib, f"corners_{side}")[k]
            found, c = cv2.findChessboardCorners(img, calib.pattern_size)
            assert found, f"pose {k} {side}: board not found"
            c = cv2.cornerSubPix(img, c, (7, 7), (-1, -1), crit).reshape(-1, 2)
            err = np.hypot(*(c - truth).T)
            assert err.max() < 0.15, f"pose {k} {side}: corner error {err.max():.3f} px"
            worst = max(worst, err.max())
    assert worst > 0  # the comparison really happened


def test_checkerboard_render_is_unbiased():
    # noise-free: OpenCV's corners scatter around the truth with a mean below 0.01 px
    cs = synth.render_calibration_set(n_tilts=1, n_pans=3, noise_std=0.0)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-5)
    errs = []
    for img, truth in zip(cs.left_images + cs.right_images, cs.corners_left + cs.corners_right):
        _, c = cv2.findChessboardCorners(img, cs.pattern_size)
        errs.append(cv2.cornerSubPix(img, c, (7, 7), (-1, -1), crit).reshape(-1, 2) - truth)
    e = np.concatenate(errs)
    assert np.all(np.abs(e.mean(axis=0)) < 0.01)
    assert np.abs(e).max() < 0.1


def test_calibration_set_is_deterministic_per_seed():
    a = synth.render_calibration_set(n_tilts=1, n_pans=1, seed=7)
    b = synth.render_calibration_set(n_tilts=1, n_pans=1, seed=7)
    c = synth.render_calibration_set(n_tilts=1, n_pans=1, seed=8)
    assert np.array_equal(a.left_images[0], b.left_images[0])
    assert not np.array_equal(a.left_images[0], c.left_images[0])


def test_pan_tilt_schedule_order():
    angles = synth.pan_tilt_schedule()
    assert angles.shape == (21, 2)
    np.testing.assert_allclose(angles[:7, 0], -20.0)
    np.testing.assert_allclose(angles[:7, 1], np.linspace(-30, 30, 7))
    with pytest.raises(ValueError, match="n_tilts and n_pans"):
        synth.pan_tilt_schedule(0, 7)


# -------------------------------------------------------------------------- flapping
def test_flapping_truth_is_the_projection_of_the_3d_points(clean_noise_free):
    seq = clean_noise_free
    for k in range(len(seq)):
        xl, xr = seq.rig.project(seq.points3d[k])
        np.testing.assert_allclose(seq.points_left[k], xl, atol=1e-9)
        np.testing.assert_allclose(seq.points_right[k], xr, atol=1e-9)


def test_flapping_layout(clean_noise_free):
    seq = clean_noise_free
    assert seq.left.shape == (12, 512, 512) and seq.right.shape == (12, 512, 512)
    assert seq.points3d.shape == (12, 26, 3)
    assert seq.kinds.tolist() == ["wing"] * 18 + ["mount"] * 2 + ["reference"] * 6
    assert seq.fps == 3000.0
    np.testing.assert_allclose(seq.times, np.arange(12) / 3000.0)
    # static points do not move
    np.testing.assert_array_equal(seq.points3d[:, 18:], np.broadcast_to(seq.points3d[0, 18:], (12, 8, 3)))
    # markers 6-11 px across
    px_per_mm = seq.rig.left.fc.mean() / seq.points3d[0, :, 2]
    size = seq.marker_diameter_mm * px_per_mm
    assert size.min() > 5.5 and size.max() < 12
    # numbering: leading to trailing edge within a station, tip (far from hinge) to root
    hinge = np.asarray(seq.params["hinge_left_mm"])
    r = np.linalg.norm(seq.points3d[0, :18] - hinge, axis=1).reshape(6, 3).mean(axis=1)
    assert np.all(np.diff(r) < 0)
    # the clean preset keeps every marker visible
    assert seq.visible_left.all() and seq.visible_right.all()


def test_rendered_blob_centroid_matches_projected_centre(clean_noise_free):
    seq = clean_noise_free
    errs = []
    for side in ("left", "right"):
        img, pts, vis = seq.frames(side), getattr(seq, f"points_{side}"), getattr(seq, f"visible_{side}")
        for k in range(len(seq)):
            c = blob_centroids(img[k], pts[k], vis[k], background=synth.LEVELS["background"])
            errs.append(np.hypot(*(c - pts[k]).T))
    e = np.concatenate(errs)
    assert np.isfinite(e).sum() == 2 * 12 * 26
    assert np.nanmax(e) < 0.1


def test_markers_foreshorten_with_the_wing(rig):
    # face-on at the top of the stroke vs turned at mid-stroke: the blob's second moments
    seq = synth.render_flapping(rig, n_frames=26, preset="clean", pitch_deg=55.0, noise_std=0.0,
                                membrane_level=synth.LEVELS["background"], dtype=np.float32)
    ratios = []
    for k in (0, 25):
        x, y = np.rint(seq.points_left[k, 7]).astype(int)  # a large mid-chord marker
        win = np.clip(seq.left[k, y - 8 : y + 9, x - 8 : x + 9] - synth.LEVELS["background"], 0, None)
        ys, xs = np.mgrid[-8:9, -8:9]
        m = win.sum()
        cx, cy = (win * xs).sum() / m, (win * ys).sum() / m
        cov = np.cov(np.stack([(xs - cx).ravel(), (ys - cy).ravel()]), aweights=win.ravel())
        ev = np.linalg.eigvalsh(cov)
        ratios.append(np.sqrt(ev[0] / ev[1]))
    assert ratios[0] > 0.85  # nearly round
    assert ratios[1] < 0.75  # clearly elliptical


def test_flapping_is_deterministic_per_seed(rig):
    a = synth.render_flapping(rig, n_frames=2, seed=11)
    b = synth.render_flapping(rig, n_frames=2, seed=11)
    c = synth.render_flapping(rig, n_frames=2, seed=12)
    assert np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right)
    assert not np.array_equal(a.left, c.left)
    np.testing.assert_array_equal(a.points3d, c.points3d)  # the seed only draws noise


def test_hard_preset_visibility(hard):
    seq = hard
    assert seq.params["stroke_amplitude_deg"] == 110.0 and seq.params["motion_blur"]
    for side in ("left", "right"):
        pts, vis = getattr(seq, f"points_{side}"), getattr(seq, f"visible_{side}")
        # static points stay visible; some leading-edge wing markers are not (edge-on)
        assert vis[:, 18:].all()
        assert (~vis[:, 0:18:3]).any()
        assert vis[:, 2:18:3].all()  # the trailing edge row stays in view
        # visible points are inside the image
        assert np.all((pts[vis] > 1) & (pts[vis] < 510))


def test_visibility_rule_edge_on(rig):
    # pitch the wing so that it passes edge-on to the left camera: visibility must
    # switch off exactly when the viewing angle exceeds edge_on_deg
    seq = synth.render_flapping(rig, n_frames=30, pitch_deg=89.0, camber=0.0, bend_mm=0.0,
                                noise_std=0.0, merge_gap_px=-100.0)
    angles = []
    for k in range(len(seq)):
        X = seq.points3d[k, :18]
        # the flat wing's normal from three of its markers
        n = np.cross(X[3] - X[0], X[2] - X[0])
        n /= np.linalg.norm(n)
        view = X / np.linalg.norm(X, axis=1, keepdims=True)
        angles.append(np.degrees(np.arccos(np.abs(view @ n))))
    angles = np.array(angles)
    assert np.all((seq.points_left[:, :18] > 12) & (seq.points_left[:, :18] < 499))  # well inside
    expected = angles <= 72.0
    clear = np.abs(angles - 72.0) > 0.5
    assert (~expected).any() and expected.any()
    np.testing.assert_array_equal(seq.visible_left[:, :18][clear], expected[clear])


def test_static_point_behind_the_wing_is_occluded(rig):
    # visibility rule (iv): a static dot that the membrane covers is not visible, and
    # the membrane (painted over it) hides it in the image
    S, B = synth.scene_frame(rig)
    dot = S + B @ np.array([0.0, 0.0, 15.0])
    tri = S + np.array([[-15.0, -15.0, 0.0], [15.0, -15.0, 0.0], [0.0, 15.0, 0.0]]) @ B.T
    level = 40.0
    scene = synth.wing._Scene(
        points=lambda t: (np.vstack([dot, S + B @ [40.0, 0.0, 15.0]]), np.tile(-B[:, 2], (2, 1))),
        diameters=np.array([2.5, 2.5]), static=np.array([True, True]), paint=200.0, light=-B[:, 2],
        membrane=lambda t: (tri, np.array([[0, 1, 2]]), -B[:, 2]), membrane_level=level,
    )
    imgs, _, pts2d, vis = synth.flapping._render_sequence(
        rig, scene, np.zeros(1), fps=1.0, blur_sigma=0.0, noise_std=0.0, dtype=np.float32,
        rng=np.random.default_rng(0), motion_blur=False, exposure=0.0, supersample=4,
        edge_on_deg=72.0, merge_gap_px=1.5)
    for side in ("left", "right"):
        assert vis[side][0].tolist() == [False, True]
        x, y = np.rint(pts2d[side][0, 0]).astype(int)
        assert imgs[side][0, y, x] < level + 1  # the dot is hidden
        x, y = np.rint(pts2d[side][0, 1]).astype(int)
        assert imgs[side][0, y, x] > 150  # the uncovered dot shows


def test_motion_blur_centroid_is_the_mid_exposure_position(hard, rig):
    seq = synth.render_flapping(rig, n_frames=3, preset="hard", phase_deg=78.0, glare=False, noise_std=0.0,
                                membrane_level=synth.LEVELS["background"], dtype=np.float32)
    errs = []
    for k in range(len(seq)):
        pts = seq.points_left[k]
        ok = isolated(pts, seq.visible_left[k], 30)
        c = blob_centroids(seq.left[k], pts, ok, half=13, background=synth.LEVELS["background"])
        errs.append(np.hypot(*(c - pts).T)[ok])
    e = np.concatenate(errs)
    assert e.size >= 10
    assert e.max() < 0.1
    # and the blur is real: the hard frames move markers > 8 px per frame
    step = np.linalg.norm(np.diff(hard.points_left[:, :18], axis=0), axis=2)
    assert step.max() > 8


def test_glare_brightens_the_wing(rig):
    kw = dict(n_frames=1, phase_deg=70.0, noise_std=0.0, dtype=np.float32)
    plain = synth.render_flapping(rig, **kw)
    shiny = synth.render_flapping(rig, glare=True, **kw)
    diff = shiny.left[0] - plain.left[0]
    assert diff.min() >= 0 and diff.max() > 50


def test_dtypes(rig):
    kw = dict(n_frames=1, seed=4)
    u8 = synth.render_flapping(rig, **kw)
    u16 = synth.render_flapping(rig, dtype=np.uint16, **kw)
    f32 = synth.render_flapping(rig, dtype=np.float32, **kw)
    assert u8.left.dtype == np.uint8 and u16.left.dtype == np.uint16 and f32.left.dtype == np.float32
    assert np.abs(u16.left[0] / 257.0 - f32.left[0]).max() <= 0.5 / 257 + 1e-4
    assert np.abs(u8.left[0].astype(float) - f32.left[0]).max() <= 0.5 + 1e-4
    with pytest.raises(ValueError, match="dtype"):
        synth.render_flapping(rig, n_frames=1, dtype=np.int32)


def test_picks_and_truth_tracks(clean_noise_free):
    seq = clean_noise_free
    picks = seq.picks("right")
    assert picks.shape == (26, 2)
    np.testing.assert_array_equal(picks, np.rint(picks))
    assert np.abs(picks - seq.points_right[0]).max() <= 0.5
    tr = seq.truth_tracks("left")
    assert list(tr.columns) == ["camera", "frame", "point", "x", "y", "score", "status"]
    assert tr.frame.dtype == np.int64 and tr.point.dtype == np.int64
    assert len(tr) == 12 * 26 and set(tr.status) == {"ok"} and (tr.camera == "left").all()
    row = tr[(tr.frame == 3) & (tr.point == 5)].iloc[0]
    np.testing.assert_allclose([row.x, row.y], seq.points_left[3, 5])
    pts = seq.truth_points()
    assert {"frame", "point", "X", "Y", "Z", "reproj_err"} <= set(pts.columns)
    with pytest.raises(ValueError, match="camera must be"):
        seq.picks("middle")


def test_truth_tracks_mark_invisible_points_lost(hard):
    tr = hard.truth_tracks("left")
    lost = tr[tr.status == "lost"]
    assert len(lost) == (~hard.visible_left).sum() > 0
    assert lost[["x", "y"]].isna().all().all()
    assert tr[tr.status == "ok"][["x", "y"]].notna().all().all()
    assert np.isnan(hard.picks("left")).any() == (~hard.visible_left[0]).any()


def test_bad_input(rig):
    with pytest.raises(ValueError, match="rig must be"):
        synth.render_flapping("rig", n_frames=1)
    with pytest.raises(ValueError, match="stroke_amplitude_deg"):
        synth.render_flapping(rig, n_frames=1, stroke_amplitude_deg=200)
    with pytest.raises(ValueError, match="preset must be one of"):
        synth.render_flapping(rig, n_frames=1, preset="medium")
    with pytest.raises(ValueError, match="noise_std"):
        synth.render_calibration_set(rig, noise_std=-1)
    with pytest.raises(ValueError, match="pattern_size"):
        synth.render_calibration_set(rig, pattern_size=(1, 6))
    with pytest.raises(ValueError, match="image_size"):
        cam = rig.left.replace(image_size=None)
        synth.render_rigid_target(StereoRig(cam, rig.right, rig.om, rig.T), n_frames=1)
    with pytest.raises(ValueError, match="overlap"):
        synth.render_rigid_target(rig, n_frames=1, distance_mm=2.0, marker_diameter_mm=2.5)


# ----------------------------------------------------------------------- rigid target
def test_rigid_target_distance_and_centroids(rig):
    seq = synth.render_rigid_target(rig, noise_std=0.0, dtype=np.float32)
    assert len(seq) == 21 and seq.kinds.tolist() == ["target", "target"]
    d = np.linalg.norm(seq.points3d[:, 1] - seq.points3d[:, 0], axis=1)
    np.testing.assert_allclose(d, 53.2, atol=1e-9)
    assert seq.visible_left.all() and seq.visible_right.all()
    for side in ("left", "right"):
        img, pts = seq.frames(side), getattr(seq, f"points_{side}")
        for k in range(len(seq)):
            c = blob_centroids(img[k], pts[k], np.ones(2, bool), background=synth.LEVELS["background"])
            assert np.hypot(*(c - pts[k]).T).max() < 0.1
    # the pan-tilt turns the bar: the markers' direction changes between stops
    u = seq.points3d[:, 1] - seq.points3d[:, 0]
    assert np.degrees(np.arccos(np.clip(u[0] @ u[6] / 53.2**2, -1, 1))) > 50


def test_rigid_target_continuous_sweep(rig):
    seq = synth.render_rigid_target(rig, n_frames=5, distance_mm=40.0)
    assert seq.left.shape == (5, 512, 512)
    np.testing.assert_allclose(np.linalg.norm(seq.points3d[:, 1] - seq.points3d[:, 0], axis=1), 40.0)
    angles = np.asarray(seq.params["angles_deg"])
    np.testing.assert_allclose(angles[0], [-20, -30])
    np.testing.assert_allclose(angles[-1], [20, 30])  # 3 tilt rows: ends at the far corner


# ------------------------------------------------------------------------ data-samples
needs_samples = pytest.mark.skipif(not (SAMPLES / "flapping" / "truth.npz").is_file(),
                                   reason="data-samples not generated")


@needs_samples
def test_data_samples_are_what_synth_renders():
    import tifffile

    left = sorted((SAMPLES / "flapping" / "left").glob("frame_*.tif"))
    right = sorted((SAMPLES / "flapping" / "right").glob("frame_*.tif"))
    assert len(left) == len(right) == 60
    calib = sorted((SAMPLES / "calibration" / "left").glob("calib_*.tif"))
    assert 14 <= len(calib) <= 21 and (SAMPLES / "calibration" / "right" / calib[0].name).is_file()
    truth = np.load(SAMPLES / "flapping" / "truth.npz")
    rig = synth.rig_from_dict(json.loads((SAMPLES / "rig.json").read_text()))
    assert rig == synth.thesis_rig()
    xl, xr = rig.project(truth["points3d"][7])
    np.testing.assert_allclose(truth["points_left"][7], xl, atol=1e-9)
    # frame 0 regenerates (same seed and settings), up to 1 grey level of rounding
    seq = synth.render_flapping(rig, n_frames=1, phase_deg=-36.0, noise_std=0.7, seed=1)
    img = tifffile.imread(left[0])
    assert img.dtype == np.uint8 and img.shape == (512, 512)
    diff = np.abs(img.astype(int) - seq.left[0])
    assert diff.max() <= 1 and diff.mean() < 0.01
    np.testing.assert_allclose(truth["points_left"][0], seq.points_left[0], atol=1e-9)
    tracks = pd.read_csv(SAMPLES / "flapping" / "truth_tracks.csv")
    assert list(tracks.columns) == ["camera", "frame", "point", "x", "y", "score", "status"]
    assert len(tracks) == 2 * 60 * 26
    total = sum(p.stat().st_size for p in SAMPLES.rglob("*") if p.is_file())
    assert total < 15.5e6


@needs_samples
def test_sample_manifest_points_at_existing_files():
    manifest = json.loads((SAMPLES / "manifest.json").read_text())
    paths = []

    def walk(node):
        for key, value in node.items():
            if isinstance(value, dict):
                walk(value)
            elif key.endswith(("_dir", "_file")):
                paths.append(SAMPLES / value)
            elif key.endswith("_glob"):
                assert list(SAMPLES.glob(value)), value

    walk(manifest)
    assert len(paths) > 10 and all(p.exists() for p in paths)
    assert manifest["calibration"]["pattern_size"] == [9, 6]
    assert manifest["flapping"]["reference_points"] == list(range(20, 26))
    assert manifest["flapping"]["leading_edge_points"] == list(range(0, 18, 3))


@needs_samples
def test_sample_picks_load_in_the_picker():
    doc = json.loads((SAMPLES / "flapping" / "picks.json").read_text())
    assert doc["format"] == "wingphoto-picks" and doc["version"] == 1
    truth = np.load(SAMPLES / "flapping" / "truth.npz")
    for side in ("left", "right"):
        xy = np.array([[p["x"], p["y"]] for p in doc["picks"][side]])
        pts = [p["point"] for p in doc["picks"][side]]
        assert np.abs(xy - truth[f"points_{side}"][0, pts]).max() <= 0.5
    state = pytest.importorskip("wingphoto.widgets.state")
    picker = state.PickerState.load(SAMPLES / "flapping" / "picks.json")
    assert picker.to_picks("left").shape == (26, 2)
