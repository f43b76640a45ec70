"""Tests of wingphoto.track: accuracy against ground truth, flags, resume, corrections, bad input.

Ground truth comes from a small anti-aliased disc renderer defined here (exact disc area
coverage by supersampling) and, for the wing sequences, from ``wingphoto.synth``.
"""
import json

import numpy as np
import pandas as pd
import pytest

from wingphoto.camera import Camera, StereoRig
from wingphoto.track import (
    apply_corrections,
    check_stereo,
    load_corrections,
    match_windows,
    refine_centroids,
    retrack_from,
    save_corrections,
    track_markers,
)
from wingphoto.synth import render_discs


# --------------------------------------------------------------------------- helpers
def moving_discs(seed=0, *, T=60, N=8, shape=(150, 190), noise_std=2.0, speed=8.0, dtype=np.uint8):
    """Discs on a grid moving along a sinusoid (peak speed ``speed`` px/frame)."""
    rng = np.random.default_rng(seed)
    gx, gy = np.meshgrid(np.linspace(55, shape[1] - 55, 4), np.linspace(45, shape[0] - 45, 2))
    base = np.column_stack([gx.ravel(), gy.ravel()])[:N] + rng.uniform(-2, 2, (N, 2))
    d = rng.uniform(6, 10, N)
    t = np.arange(T)
    amp = speed / (2 * np.pi / 50)
    truth = np.empty((T, N, 2))
    truth[..., 0] = base[:, 0] + 0.25 * amp * np.sin(2 * np.pi * t / 50)[:, None]
    truth[..., 1] = base[:, 1] + 4 * np.cos(2 * np.pi * t / 40)[:, None]
    frames = np.stack([render_discs(truth[k], d, shape, noise_std=noise_std, rng=rng, dtype=dtype) for k in range(T)])
    return frames, truth, d


def errors(tracks, truth):
    T, N = truth.shape[:2]
    x = tracks["x"].to_numpy().reshape(T, N)
    y = tracks["y"].to_numpy().reshape(T, N)
    status = tracks["status"].to_numpy().reshape(T, N)
    return np.hypot(x - truth[..., 0], y - truth[..., 1]), status


class FailingFrames:
    """A lazy frame sequence that raises on frame ``k`` (a crash in the middle of a run)."""

    def __init__(self, frames, k):
        self.frames, self.k = frames, k

    def __len__(self):
        return len(self.frames)

    def __getitem__(self, i):
        if i == self.k:
            raise RuntimeError("simulated crash")
        return self.frames[i]


# --------------------------------------------------------------------------- refiner / matcher
@pytest.mark.parametrize("threshold, worst", [(0.0, 0.02), (0.2, 0.035)])
def test_refine_centroids_is_unbiased_on_antialiased_discs(threshold, worst):
    """Unblurred discs, the worst case for pixel locking: none with the plain centroid,
    a little with the thresholded default (the price of ignoring what surrounds a blob)."""
    rng = np.random.default_rng(1)
    true = np.column_stack([rng.uniform(20, 40, 40), rng.uniform(20, 30, 40)])
    err = []
    for c in true:
        img = render_discs([c], [8.0], (50, 61), dtype=np.float32)
        xy, mass = refine_centroids(img, np.rint(c)[None, :], 4.0 + 1.5, threshold=threshold)
        err.append(xy[0] - c)
        assert mass[0] > 0
    err = np.array(err)
    assert np.abs(err.mean(0)).max() < 0.005  # no bias (pixel locking would show here)
    assert np.abs(err).max() < worst


def test_refine_centroids_ignores_a_close_neighbour_with_voronoi_split():
    a, b = np.array([30.3, 25.6]), np.array([40.1, 25.2])  # 9.8 px apart, 8 px discs
    img = render_discs([a, b], [8.0, 8.0], (50, 70), dtype=np.float32)
    xy, _ = refine_centroids(img, np.rint([a, b]), 5.5, neighbours=[b, a])
    assert np.abs(xy - [a, b]).max() < 0.05


def test_match_windows_finds_the_template_offset():
    img = render_discs([(40.0, 30.0)], [8.0], (60, 81))
    tpl = img[30 - 6: 30 + 7, 40 - 6: 40 + 7].copy()
    maps, origin, shape = match_windows(img, [tpl], [[38, 33]], [4])
    v, u = np.unravel_index(np.argmax(maps[0]), maps[0].shape)
    assert (origin[0, 0] + u, origin[0, 1] + v) == (40, 30)
    assert tuple(shape[0]) == (9, 9)


# --------------------------------------------------------------------------- accuracy
def test_clean_discs_subpixel_accuracy():
    frames, truth, _ = moving_discs(0)
    tracks = track_markers(frames, np.rint(truth[0]), progress=False)
    assert list(tracks.columns) == ["camera", "frame", "point", "x", "y", "score", "status", "x_pix",
                                    "y_pix", "reason", "sigma"]
    err, status = errors(tracks, truth)
    ok = status == "ok"
    assert ok.mean() == 1.0
    assert np.sqrt(np.mean(err[ok] ** 2)) <= 0.05
    assert err[ok].max() <= 0.2
    # the pixel-level match is the nearest pixel (or one off) of the refined centre
    d = np.hypot(tracks.x - tracks.x_pix, tracks.y - tracks.y_pix)
    assert d.max() < 1.5


@pytest.mark.parametrize("dtype", [np.uint16, np.float32])
def test_other_dtypes_track_like_uint8(dtype):
    frames, truth, _ = moving_discs(3, T=30)
    ref = track_markers(frames, np.rint(truth[0]), progress=False)
    scale = 257 if dtype == np.uint16 else 1.0 / 255
    other = (frames.astype(np.float64) * scale).astype(dtype)
    tr = track_markers(other, np.rint(truth[0]), progress=False)
    assert (tr.status == "ok").all()
    err, _ = errors(tr, truth)
    assert np.sqrt(np.mean(err**2)) <= 0.05
    assert np.abs(tr.x - ref.x).max() < 0.02


def test_non_square_image_keeps_x_and_y_apart():
    T = 12
    truth = np.zeros((T, 1, 2))
    truth[:, 0, 0] = 15.0 + 1.3 * np.arange(T)  # moves along x only
    truth[:, 0, 1] = 11.2
    frames = np.stack([render_discs(truth[k], [6.0], (23, 41)) for k in range(T)])
    tr = track_markers(frames, np.rint(truth[0]), progress=False)
    err, status = errors(tr, truth)
    assert (status == "ok").all() and err.max() < 0.05


def _synth():
    synth = pytest.importorskip("wingphoto.synth")
    if not hasattr(synth, "render_flapping"):
        pytest.skip("wingphoto.synth.render_flapping not available")
    return synth


def test_synth_clean_wing_accuracy():
    synth = _synth()
    seq = synth.render_flapping(n_frames=60, preset="clean", seed=3)
    tr = track_markers(seq.left, seq.picks("left"), progress=False)
    err, status = errors(tr, seq.points_left)
    ok = status == "ok"
    vis = seq.visible_left
    assert np.sqrt(np.mean(err[ok] ** 2)) <= 0.05
    assert err[ok].max() <= 1.0
    assert (ok & vis).sum() >= 0.99 * vis.sum()


@pytest.fixture(scope="module")
def hard_wing():
    """One beat of the hard preset (110 deg stroke, glare, motion blur, edge-on), rendered once."""
    synth = _synth()
    assert synth.flapping_preset("hard")["stroke_amplitude_deg"] >= 110
    return synth.render_flapping(n_frames=100, preset="hard", seed=1)


def test_synth_hard_wing_flags_instead_of_guessing(hard_wing):
    """110 deg stroke, glare, motion blur, edge-on merging: no confident error > 1 px."""
    seq = hard_wing
    tr = track_markers(seq.left, seq.picks("left"), progress=False)
    err, status = errors(tr, seq.points_left)
    ok = status == "ok"
    vis = seq.visible_left
    assert err[ok].max() <= 1.0
    assert (ok & vis).sum() >= 0.95 * vis.sum()
    assert tr.loc[tr.status == "lost", ["x", "y"]].isna().all().all()
    assert set(tr.loc[tr.status != "ok", "reason"]) - {""} and (tr.loc[tr.status == "ok", "reason"] == "").all()


def test_synth_hard_wing_bidirectional(hard_wing):
    """The backward pass may only add ok points it can anchor, and flags disagreement."""
    seq = hard_wing
    tr = track_markers(seq.right, seq.picks("right"), bidirectional=True, progress=False)
    err, status = errors(tr, seq.points_right)
    ok = status == "ok"
    assert err[ok].max() <= 1.0
    assert (ok & seq.visible_right).sum() >= 0.93 * seq.visible_right.sum()


@pytest.mark.parametrize("phase, seed, n_frames, camera", [(37, 1, 30, "right"), (176, 14, 40, "left")])
def test_synth_hard_wing_other_phases_no_confident_error(phase, seed, n_frames, camera):
    """Stroke phases where a marker the tracker does not know (lost, or never picked) sat
    next to an ok one and pulled it 2 px (phase 37), and where a marker re-acquired on its
    neighbour's blob was reported 14 px off (phase 176): flagged now, never ok."""
    synth = _synth()
    seq = synth.render_flapping(n_frames=n_frames, preset="hard", phase_deg=phase, seed=seed)
    truth, vis = getattr(seq, f"points_{camera}"), getattr(seq, f"visible_{camera}")
    tr = track_markers(seq.frames(camera), seq.picks(camera), camera=camera, progress=False)
    err, status = errors(tr, truth)
    ok = status == "ok"
    assert err[ok].max() <= 1.0
    assert (ok & vis).sum() >= 0.9 * vis.sum()


def test_synth_rigid_target_stills_track_to_the_end():
    """The pan-tilt rigid target (two markers, stills at fps=1, the pan reversing): both
    markers ok on every frame of both views, as precise as on a clean wing (a too-small
    disk gave 0.84 px; the stop at the pan's reversal lost marker 0 for good)."""
    synth = _synth()
    seq = synth.render_rigid_target(n_frames=105, seed=1)
    for camera in ("left", "right"):
        truth = getattr(seq, f"points_{camera}")
        tr = track_markers(seq.frames(camera), seq.picks(camera), camera=camera, progress=False)
        err, status = errors(tr, truth)
        assert (status == "ok").all()
        assert err.max() < 0.1


def _stop_and_go(T=40, seed=4):
    """Two markers 120 px apart moving 4 px/frame, stopping dead at frame 20 (stills)."""
    t = np.arange(T)
    xs = np.where(t < 20, 4.0 * t, 80.0)
    truth = np.zeros((T, 2, 2))
    truth[:, 0] = np.column_stack([30.3 + xs, 40.6 + 0.5 * xs])
    truth[:, 1] = np.column_stack([150.7 + xs, 45.2 + 0.5 * xs])
    rng = np.random.default_rng(seed)
    frames = np.stack([render_discs(truth[k], [9.0, 9.0], (110, 290), noise_std=1.0, rng=rng) for k in range(T)])
    return frames, truth, rng


def test_whole_target_stopping_dead_is_not_a_jump():
    """Both markers leave their (constant-acceleration) prediction by 4 px at once: the
    neighbours vouch for each other, so neither is flagged 'jump' and lost."""
    frames, truth, _ = _stop_and_go()
    tr = track_markers(frames, np.rint(truth[0]), progress=False)
    err, status = errors(tr, truth)
    assert (status == "ok").all() and err.max() < 0.1


def test_isolated_marker_is_reacquired_without_neighbours():
    """A marker with one far neighbour vanishes for 12 frames (and the target stops
    meanwhile): the wide fallback search finds it on the first frame it is back."""
    frames, truth, rng = _stop_and_go()
    frames = frames.copy()
    for k in range(10, 22):
        frames[k] = render_discs([truth[k, 1]], [9.0], frames.shape[1:], noise_std=1.0, rng=rng)
    tr = track_markers(frames, np.rint(truth[0]), progress=False)
    err, status = errors(tr, truth)
    assert not (status[10:22, 0] == "ok").any()
    assert tr[(tr.frame == 22) & (tr.point == 0)].reason.item() == "reacquired"
    assert (status[23:, 0] == "ok").all() and (status[:, 1] == "ok").all()
    assert err[status == "ok"].max() < 0.1


def test_unpicked_marker_appearing_next_to_a_tracked_one():
    """A marker without a pick appears 8-12 px from a tracked one and moves with it: the
    tracked one is split from it (ok, precise) when a dark gap separates them, flagged
    'foreign' when they nearly touch - never reported ok off its centre."""
    T = 30
    for sep, share in ((8.0, 0.2), (10.0, 1.0), (12.0, 1.0)):
        rng = np.random.default_rng(3)
        base = np.array([[40.3, 40.6], [40.3 + sep, 42.1], [90.2, 35.4], [70.7, 70.3], [30.4, 75.8]])
        truth = np.stack([base + [1.5 * k + 3 * np.sin(k / 5), 0.8 * k] for k in range(T)])
        frames = []
        for k in range(T):
            c = truth[k].copy()
            if k < 8:
                c[1] = np.nan  # not visible yet: no pick
            frames.append(render_discs(c, [8.0, 8.0, 7.0, 7.0, 7.0], (110, 170), noise_std=2.0, rng=rng))
        picks = np.rint(truth[0])
        picks[1] = np.nan
        tr = track_markers(np.stack(frames), picks, progress=False)
        err, status = errors(tr, truth)
        ok = status == "ok"
        assert err[ok].max() < 0.2
        assert ok[:, 0].mean() >= share
        assert (ok[:8, 0]).all()
        if share < 1:
            assert "foreign" in set(tr.reason[tr.point == 0])


# --------------------------------------------------------------------------- flags
def test_converging_markers_are_never_both_ok_on_one_blob():
    T = 40
    t = np.arange(T)
    gap = 14 - 11 * np.sin(np.pi * t / (T - 1))  # 14 px -> 3 px (merged) -> 14 px
    truth = np.zeros((T, 4, 2))
    truth[:, 0] = np.column_stack([50 - gap / 2, np.full(T, 40.3)])
    truth[:, 1] = np.column_stack([50 + gap / 2, np.full(T, 40.7)])
    truth[:, 2] = [20.4, 20.2]
    truth[:, 3] = [80.6, 62.1]
    rng = np.random.default_rng(5)
    frames = np.stack([render_discs(truth[k], [7.0] * 4, (80, 100), noise_std=1.5, rng=rng) for k in range(T)])
    tr = track_markers(frames, np.rint(truth[0]), progress=False)
    err, status = errors(tr, truth)
    ok = status == "ok"
    assert err[ok].max() <= 1.0
    x = tr.x.to_numpy().reshape(T, 4)
    both = ok[:, 0] & ok[:, 1]
    assert np.all(np.abs(x[both, 0] - x[both, 1]) > 5)
    merged = gap < 7  # the 7 px discs overlap
    assert not ok[merged, :2].any()  # overlapping blobs are flagged, not reported
    assert (tr.reason == "merged").any()
    # blobs predicted to touch but separated by a visible gap are split and reported
    apart = (gap >= 7) & (gap < 8)
    assert apart.any() and ok[apart, :2].all() and err[apart, :2].max() < 0.1


def test_decoy_next_to_a_marker_is_not_reported_as_the_marker():
    """An untracked look-alike merging with a marker: with max_score_drop the sudden fall
    of the correlation flags it (by default a merge with an *untracked* blob can pass)."""
    T = 30
    truth = np.zeros((T, 3, 2))
    truth[:, 0] = np.column_stack([30 + 0.7 * np.arange(T), np.full(T, 30.4)])
    truth[:, 1] = [70.3, 25.5]
    truth[:, 2] = [60.2, 60.6]
    decoy = np.column_stack([truth[:, 0, 0] + 3.0, truth[:, 0, 1] + 2.5])  # overlapping look-alike
    rng = np.random.default_rng(2)
    frames = []
    for k in range(T):
        c = list(truth[k]) + ([decoy[k]] if 12 <= k < 20 else [])
        frames.append(render_discs(c, [8.0] * len(c), (90, 110), noise_std=1.0, rng=rng))
    tr = track_markers(np.stack(frames), np.rint(truth[0]), max_score_drop=0.1, progress=False)
    err, status = errors(tr, truth)
    ok = status == "ok"
    assert err[ok].max() <= 1.0
    assert not ok[12:20, 0].any()
    assert "appearance" in set(tr.reason[tr.point == 0])


def test_marker_leaving_the_frame_is_lost_then_reacquired():
    T = 60
    t = np.arange(T)
    truth = np.zeros((T, 5, 2))
    x0 = 65 + 30 * np.sin(2 * np.pi * t / 60)
    for i, (dx, dy) in enumerate([(40, 0), (10, 12), (-10, -8), (-25, 18), (0, 28)]):
        truth[:, i, 0] = x0 + dx * (1 + 0.05 * np.sin(2 * np.pi * t / 60))  # marker 0 reaches x = 137
        truth[:, i, 1] = 30 + dy + 0.3 * i
    rng = np.random.default_rng(7)
    frames = np.stack([render_discs(truth[k], [7.0] * 5, (70, 130), noise_std=1.0, rng=rng) for k in range(T)])
    tr = track_markers(frames, np.rint(truth[0]), progress=False)
    err, status = errors(tr, truth)
    ok = status == "ok"
    assert err[ok].max() <= 1.0
    outside = truth[:, 0, 0] > 129.5
    assert outside.any() and not ok[outside, 0].any()
    assert tr[(tr.point == 0) & (tr.status == "lost")][["x", "y"]].isna().all().all()
    assert ok[:, 1:].all()
    assert ok[-20:, 0].all()  # found again once back in view
    assert (tr.reason == "reacquired").any() or ok[outside.nonzero()[0][-1] + 1:, 0].all()


def test_vanishing_marker_is_not_ok():
    frames, truth, d = moving_discs(4, T=40)
    frames = frames.copy()
    rng = np.random.default_rng(0)
    vanish = range(15, 25)
    for k in vanish:  # marker 2 disappears (painted over / full glare)
        keep = [c if i != 2 else (np.nan, np.nan) for i, c in enumerate(truth[k])]
        frames[k] = render_discs(keep, d, frames.shape[1:], noise_std=2.0, rng=rng)
    tr = track_markers(frames, np.rint(truth[0]), progress=False)
    err, status = errors(tr, truth)
    assert not (status[list(vanish), 2] == "ok").any()
    ok = status == "ok"
    assert err[ok].max() <= 1.0
    assert ok[-5:, 2].all()


def test_bidirectional_agrees_on_clean_data():
    frames, truth, _ = moving_discs(6, T=30)
    tr = track_markers(frames, np.rint(truth[0]), bidirectional=True, progress=False)
    err, status = errors(tr, truth)
    assert (status == "ok").mean() == 1.0 and err.max() < 0.2


def test_full_search_every_frame_gives_the_same_answer():
    frames, truth, _ = moving_discs(8, T=30)
    a = track_markers(frames, np.rint(truth[0]), progress=False)
    b = track_markers(frames, np.rint(truth[0]), search_every=1, progress=False)
    assert (a.status == b.status).all()
    # the fast path centres its first centroid disk on the prediction, not on the NCC peak
    assert np.abs(a.x - b.x).max() < 0.03 and np.abs(a.y - b.y).max() < 0.03


def test_compiled_and_numpy_paths_agree(monkeypatch):
    """With numba the tracker runs compiled kernels; without it (or WINGPHOTO_NO_NUMBA=1)
    the numpy/OpenCV code: same statuses, same positions (OpenCV correlates the template
    rounded to uint8, hence scores within 0.01)."""
    from wingphoto.track import engine

    if not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed: only the numpy path runs")
    frames, truth, _ = moving_discs(17, T=30)
    frames[12:16, 98:110, 104:110] = 150  # a bright patch next to marker 5: flags
    fast = track_markers(frames, np.rint(truth[0]), progress=False)
    try:
        engine.try_numba(False)
        slow = track_markers(frames, np.rint(truth[0]), progress=False)
    finally:
        engine.try_numba(True)
    assert (fast.status == slow.status).all() and (fast.reason == slow.reason).all()
    assert (fast.status != "ok").any()
    assert np.allclose(fast.x, slow.x, atol=1e-6, equal_nan=True)
    assert np.allclose(fast.score, slow.score, atol=0.01, equal_nan=True)


# --------------------------------------------------------------------------- picks
def test_picker_dataframe_with_ids_and_half_size():
    frames, truth, _ = moving_discs(1, T=15, N=3)
    picks = pd.DataFrame({"point": [7, 3, 11], "x": truth[0, :, 0].round(), "y": truth[0, :, 1].round(),
                          "half_size": [7, 7, 8]})
    tr = track_markers(frames, picks, camera="right", progress=False)
    assert tr.point.unique().tolist() == [7, 3, 11]
    assert (tr.camera == "right").all()
    err, status = errors(tr, truth)
    assert (status == "ok").all() and err.max() < 0.2


def test_picks_as_dicts_with_rect():
    frames, truth, _ = moving_discs(1, T=10, N=2)
    picks = [{"point": i, "x": float(round(x)), "y": float(round(y)), "rect": (round(x) - 6, round(y) - 6, 13, 13)}
             for i, (x, y) in enumerate(truth[0])]
    tr = track_markers(frames, picks, progress=False)
    assert (tr.status == "ok").all()


# --------------------------------------------------------------------------- checkpoint / resume
def test_checkpoint_resume_after_crash_gives_identical_results(tmp_path):
    frames, truth, _ = moving_discs(9, T=45)
    picks = np.rint(truth[0])
    ref = track_markers(frames, picks, progress=False)
    ck = tmp_path / "track.npz"
    with pytest.raises(RuntimeError, match="simulated crash"):
        track_markers(FailingFrames(frames, 31), picks, checkpoint=ck, checkpoint_every=7, progress=False)
    assert ck.is_file()
    resumed = track_markers(frames, picks, checkpoint=ck, checkpoint_every=7, progress=False)
    pd.testing.assert_frame_equal(resumed, ref)
    # another crash point, lost state restored from the periodic checkpoint only
    ck2 = tmp_path / "track2.npz"
    with pytest.raises(RuntimeError):
        track_markers(FailingFrames(frames, 20), picks, checkpoint=ck2, checkpoint_every=1000, progress=False)
    pd.testing.assert_frame_equal(track_markers(frames, picks, checkpoint=ck2, progress=False), ref)


def test_checkpoint_resume_bidirectional(tmp_path):
    frames, truth, _ = moving_discs(10, T=30)
    picks = np.rint(truth[0])
    ref = track_markers(frames, picks, bidirectional=True, progress=False)
    ck = tmp_path / "bi.npz"
    # the backward pass reads frame 12 again after the forward pass has passed it
    with pytest.raises(RuntimeError):
        track_markers(FailingFrames(frames, 12), picks, bidirectional=True, checkpoint=ck, checkpoint_every=5,
                      progress=False)
    pd.testing.assert_frame_equal(
        track_markers(frames, picks, bidirectional=True, checkpoint=ck, checkpoint_every=5, progress=False), ref)


def test_checkpoint_of_other_inputs_is_refused(tmp_path):
    frames, truth, _ = moving_discs(11, T=10)
    ck = tmp_path / "a.npz"
    track_markers(frames, np.rint(truth[0]), checkpoint=ck, progress=False)
    with pytest.raises(ValueError, match="was written for other frames, picks or options"):
        track_markers(frames, np.rint(truth[0]), checkpoint=ck, min_score=0.5, progress=False)


# --------------------------------------------------------------------------- stereo
def _rig():
    cam = Camera(fc=[1850.0, 1845.0], cc=[255.5, 250.5], kc=[-0.1, 0.1, 0.001, -0.001, 0.0], image_size=(512, 512))
    return StereoRig(cam, cam.replace(cc=[260.0, 255.0]), om=[0.026, 0.733, 0.003], T=[-272.7, -1.5, 108.7])


def _stereo_tracks(rig, T=6, N=5, seed=0):
    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.uniform(-20, 20, T * N), rng.uniform(-20, 20, T * N), rng.uniform(380, 420, T * N)])
    xL, xR = rig.project(X + [140.0, 0.0, 0.0])
    frame = np.repeat(np.arange(T), N)
    point = np.tile(np.arange(N), T)

    def df(x, cam):
        return pd.DataFrame({"camera": cam, "frame": frame, "point": point, "x": x[:, 0], "y": x[:, 1],
                             "score": 0.99, "status": "ok", "reason": ""})

    return df(xL, "left"), df(xR, "right")


def test_check_stereo_catches_a_swap_in_one_view():
    rig = _rig()
    tl, tr = _stereo_tracks(rig)
    assert (np.abs(rig.epipolar_distance(tl[["x", "y"]].to_numpy(), tr[["x", "y"]].to_numpy())) < 1e-6).all()
    swap = tr.frame.isin([2, 3]) & tr.point.isin([1, 4])
    a = tr.index[swap & (tr.point == 1)]
    b = tr.index[swap & (tr.point == 4)]
    tr.loc[a, ["x", "y"]], tr.loc[b, ["x", "y"]] = tr.loc[b, ["x", "y"]].to_numpy(), tr.loc[a, ["x", "y"]].to_numpy()
    tr.loc[tr.frame == 5, "status"] = "manual"
    tr.loc[(tr.frame == 5) & (tr.point == 0), ["x", "y"]] += 10.0  # a wrong manual click stays manual
    L, R = check_stereo(tl, tr, rig)
    expect = (tl.frame.isin([2, 3]) & tl.point.isin([1, 4])).to_numpy()
    # the wrong manual click on the right makes its (ok) left partner flagged
    bad_click = ((tl.frame == 5) & (tl.point == 0)).to_numpy()
    for out, want in ((L, expect | bad_click), (R, expect)):
        flagged = (out.status == "flagged").to_numpy()
        assert (flagged == want).all()  # the swapped pairs, in both views, and nothing else
        assert (out.loc[flagged, "reason"] == "stereo").all()
        assert out.epipolar_px.notna().all()
    assert (R.loc[R.frame == 5, "status"] == "manual").all()
    assert (L.loc[expect, "epipolar_px"] > 2).all() and (L.loc[~expect & (L.frame != 5), "epipolar_px"] < 1e-6).all()


def test_check_stereo_bad_input():
    rig = _rig()
    tl, tr = _stereo_tracks(rig)
    with pytest.raises(ValueError, match="rig must be a wingphoto.StereoRig"):
        check_stereo(tl, tr, "rig")
    with pytest.raises(ValueError, match=r"tracks_right lacks columns \['status'\]"):
        check_stereo(tl, tr.drop(columns="status"), rig)


# --------------------------------------------------------------------------- corrections
@pytest.mark.parametrize("suffix", [".csv", ".json"])
def test_corrections_round_trip_and_replay(tmp_path, suffix):
    log = pd.DataFrame({"point": [1, 0, 1], "frame": [3, 5, 3], "x": [10.25, np.nan, 11.125],
                        "y": [20.5, np.nan, 21.0625]})
    path = save_corrections(log, tmp_path / f"corr{suffix}")
    back = load_corrections(path)
    pd.testing.assert_frame_equal(back, log)
    tracks = pd.DataFrame({"camera": "left", "frame": np.repeat(np.arange(6), 2), "point": np.tile([0, 1], 6),
                           "x": 1.0, "y": 2.0, "score": 0.9, "status": "ok", "x_pix": 1.0, "y_pix": 2.0,
                           "reason": ""})
    out = apply_corrections(tracks, back)
    row = out[(out.frame == 3) & (out.point == 1)].iloc[0]
    assert (row.x, row.y, row.status, row.x_pix) == (11.125, 21.0625, "manual", 11.0)  # the later one wins
    lost = out[(out.frame == 5) & (out.point == 0)].iloc[0]
    assert lost.status == "lost" and np.isnan(lost.x) and lost.reason == "manual"
    assert (out.drop(index=[7, 10]) == tracks.drop(index=[7, 10])).all().all()
    assert tracks.status.eq("ok").all()  # input untouched


def test_corrections_bad_input_keeps_the_previous_file(tmp_path):
    path = tmp_path / "c.json"
    save_corrections([(0, 1, 2.0, 3.0)], path)
    before = path.read_text()
    with pytest.raises(ValueError, match=r"corrections lack columns \['x', 'y'\]"):
        save_corrections(pd.DataFrame({"point": [0], "frame": [1]}), path)
    assert path.read_text() == before and json.loads(before)["corrections"][0]["x"] == 2.0
    with pytest.raises(ValueError, match="must end in .csv or .json"):
        save_corrections([(0, 1, 2.0, 3.0)], tmp_path / "c.txt")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_corrections(tmp_path / "missing.csv")
    # a correction without a row adds it (one implementation with the review widget) ...
    tracks = pd.DataFrame({"frame": [0], "point": [0], "x": [1.0], "y": [1.0], "status": ["ok"]})
    added = apply_corrections(tracks, [(0, 9, 2.0, 3.0)])
    assert added.values.tolist() == [[0, 0, 1.0, 1.0, "ok"], [9, 0, 2.0, 3.0, "manual"]]
    assert added.dtypes.to_dict() == tracks.dtypes.to_dict()
    # ... but cannot guess the camera among several
    two = pd.concat([tracks.assign(camera="left"), tracks.assign(camera="right")], ignore_index=True)
    with pytest.raises(ValueError, match="correction of point 0 on frame 9 has no row in tracks of cameras"):
        apply_corrections(two, [(0, 9, 1.0, 1.0)])
    with pytest.raises(ValueError, match=r"tracks lacks columns \['status'\]"):
        apply_corrections(tracks.drop(columns="status"), [(0, 0, 1.0, 1.0)])


def test_corrections_interoperate_with_the_review_widget_log(tmp_path):
    state = pytest.importorskip("wingphoto.widgets.state")
    log = [state.Correction("left", 1, 2, 5.5, 6.25), state.Correction("right", 1, 2, 7.0, 8.0)]
    tracks = pd.DataFrame({"camera": np.repeat(["left", "right"], 6), "frame": np.tile(np.repeat(np.arange(3), 2), 2),
                           "point": np.tile([0, 1], 6), "x": 1.0, "y": 2.0, "status": "ok"})
    out = apply_corrections(tracks, log)
    fixed = out[out.status == "manual"].sort_values("camera")
    assert fixed[["camera", "x", "y"]].values.tolist() == [["left", 5.5, 6.25], ["right", 7.0, 8.0]]
    path = save_corrections(log, tmp_path / "log.json")
    assert state.read_corrections(path) == tuple(log)
    pd.testing.assert_frame_equal(apply_corrections(tracks, load_corrections(path)), out)


def test_retrack_from_a_corrected_frame():
    frames, truth, _ = moving_discs(12, T=40)
    tracks = track_markers(frames, np.rint(truth[0]), progress=False)
    broken = tracks.copy()
    bad = (broken.point == 2) & (broken.frame >= 20)
    broken.loc[bad, ["x", "y"]] = np.nan
    broken.loc[bad, "status"] = "lost"
    fixed = apply_corrections(broken, [(2, 20, float(truth[20, 2, 0]), float(truth[20, 2, 1]))])
    out = retrack_from(frames, fixed, 2, 20, progress=False)
    err, status = errors(out, truth)
    assert status[20, 2] == "manual"
    assert (status[21:, 2] == "ok").all() and err[21:, 2].max() < 0.2
    pd.testing.assert_frame_equal(out[out.point != 2], tracks[tracks.point != 2])
    with pytest.raises(ValueError, match="have no position on frame 25"):
        retrack_from(frames, broken, [2], 25, progress=False)


# --------------------------------------------------------------------------- bad input
def test_bad_input_messages():
    frames, truth, _ = moving_discs(13, T=5, N=2)
    picks = np.rint(truth[0])
    H, W = frames.shape[1:]
    with pytest.raises(ValueError, match=r"pick of point 1 at \(500, 20\) is outside the 190x150 image"):
        track_markers(frames, [picks[0], [500, 20]], progress=False)
    edge = render_discs([(3.2, 40.0)], [6.0], (H, W))
    with pytest.raises(ValueError, match="pick of point 0 at .* is too close to the image edge"):
        track_markers(np.stack([edge, edge]), [[3, 40]], progress=False)
    with pytest.raises(ValueError, match=r"template of point 0 \(201 px, half_size 100\) is larger than the 190x150"):
        track_markers(frames, pd.DataFrame({"x": [picks[0, 0]], "y": [picks[0, 1]], "half_size": [100]}),
                      progress=False)
    with pytest.raises(ValueError, match="picks are all NaN"):
        track_markers(frames, [[np.nan, 3.0]], progress=False)
    with pytest.raises(ValueError, match="frames is empty"):
        track_markers(frames[:0], picks, progress=False)
    with pytest.raises(ValueError, match="got one 2D image"):
        track_markers(frames[0], picks, progress=False)
    mixed = [frames[0], frames[1], frames[2][:, :-3]]
    with pytest.raises(ValueError, match=r"frame 2 has shape \(150, 187\) but frame 0 has \(150, 190\)"):
        track_markers(mixed, picks, progress=False)
    with pytest.raises(ValueError, match="is not on a marker"):
        track_markers(frames, [[20, 140]], progress=False)
    with pytest.raises(ValueError, match=r"picks must be an \(N, 2\) array"):
        track_markers(frames, np.zeros((2, 3)), progress=False)
    with pytest.raises(ValueError, match="picks is empty"):
        track_markers(frames, np.zeros((0, 2)), progress=False)
    with pytest.raises(ValueError, match="got a path"):
        track_markers("frames/", picks, progress=False)
    with pytest.raises(ValueError, match=r"threshold must be in \[0, 1\)"):
        refine_centroids(frames[0], picks, 5.0, threshold=1.5)


def test_nan_pick_gives_a_lost_point(caplog):
    """A marker not visible in frame 0 has no click: its rows are lost, the others tracked."""
    frames, truth, _ = moving_discs(15, T=8, N=3)
    picks = np.rint(truth[0])
    picks[1] = np.nan
    with caplog.at_level("WARNING", logger="wingphoto.track"):
        tr = track_markers(frames, picks, progress=False)
    assert "picks of points [1] are NaN" in caplog.text
    assert tr.point.unique().tolist() == [0, 1, 2] and len(tr) == 8 * 3
    p1 = tr[tr.point == 1]
    assert (p1.status == "lost").all() and (p1.reason == "no_pick").all() and p1.x.isna().all()
    err, status = errors(tr, truth)
    assert (status[:, [0, 2]] == "ok").all() and err[:, [0, 2]].max() < 0.2


def test_sixteen_bit_frames_use_the_full_range():
    frames, truth, _ = moving_discs(14, T=10, N=2)
    deep = frames.astype(np.uint16) * 257 + 3  # 16-bit, values above 255
    tr = track_markers(deep, np.rint(truth[0]), progress=False)
    err, status = errors(tr, truth)
    assert (status == "ok").all() and err.max() < 0.1


def test_lazy_sequence_from_read_sequence_gives_the_array_result(tmp_path):
    import cv2

    from wingphoto.io import read_sequence

    frames, truth, _ = moving_discs(16, T=12, N=3)
    for k, f in enumerate(frames):
        cv2.imwrite(str(tmp_path / f"frame{k}.png"), f)
    seq = read_sequence(tmp_path)
    assert len(seq) == 12
    a = track_markers(seq, np.rint(truth[0]), progress=False)
    b = track_markers(frames, np.rint(truth[0]), progress=False)
    pd.testing.assert_frame_equal(a, b)
