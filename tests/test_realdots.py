"""synth.realdots: real dot photographs moved by known warps (skipped without ../shared)."""
import numpy as np
import pytest

from wingphoto.synth import realdots
from wingphoto.synth.realdots import _warp_point
from wingphoto.validation import score_tracks


@pytest.fixture(scope="module")
def folder():
    f = realdots.default_folder()
    if not (f / "cal1.tif").is_file():
        pytest.skip(f"real-dot photographs not found at {f}")
    return f


@pytest.fixture(scope="module")
def seq(folder):
    return realdots.render_realdots("cam2", seed=3, n_frames=12, size=160, folder=folder)


def test_missing_folder_and_bad_arguments(tmp_path):
    with pytest.raises(FileNotFoundError, match="real-dot photographs not found"):
        realdots.render_realdots("cam1", seed=0, folder=tmp_path)
    with pytest.raises(ValueError, match="camera must be one of"):
        realdots.render_realdots("cam3", seed=0, folder=tmp_path)
    with pytest.raises(ValueError, match="n_frames must be >= 2"):
        realdots.render_realdots("cam1", seed=0, n_frames=1, folder=tmp_path)
    with pytest.raises(ValueError, match="peak_speed must be"):
        realdots.render_realdots("cam1", seed=0, peak_speed=(5, 3), folder=tmp_path)
    with pytest.raises(ValueError, match="exposure must be"):
        realdots.render_realdots("cam1", seed=0, exposure=1.5, folder=tmp_path)


def test_a_milder_warp(folder):
    """peak_speed and exposure choose a steadier sequence: slower, and sharp without blur."""
    slow = realdots.render_realdots("cam2", seed=3, n_frames=12, size=160, folder=folder, peak_speed=(3, 5),
                                    exposure=0.0)
    speed = np.linalg.norm(np.diff(slow.points, axis=0), axis=2)
    assert 1 < np.median(speed) < 8
    assert slow.params["exposure"] == 0.0


def test_truth_is_the_reference_through_the_warp(seq, folder):
    ref = np.loadtxt(folder / "cam2_cal_points", ndmin=2)[:, :2][seq.params["reference_rows"]]
    for k in (0, 5, 11):
        np.testing.assert_allclose(seq.points[k], _warp_point(seq.homographies[k], ref), atol=1e-9)
    assert seq.images.shape == (12, 160, 160) and seq.images.dtype == np.uint8
    # it moves: 10-15 px/frame at the view's centre, more or less elsewhere
    speed = np.linalg.norm(np.diff(seq.points, axis=0), axis=2)
    assert 5 < np.median(speed) < 25
    picks = seq.picks("cam2")
    assert np.array_equal(np.isfinite(picks[:, 0]), seq.visible[0])
    with pytest.raises(ValueError, match="camera must be 'cam2'"):
        seq.picks("cam1")


def test_dots_sit_at_their_truth(seq):
    """A local shape centroid of each visible dot agrees with its truth to ~the reference's
    accuracy (the photograph's dots are ~5 px across and faint)."""
    errs = []
    for k in (0, 6):
        img = seq.images[k].astype(float)
        for p in seq.points[k][seq.visible[k]]:
            x0, y0 = int(round(p[0])), int(round(p[1]))
            win = img[y0 - 5 : y0 + 6, x0 - 5 : x0 + 6]
            ys, xs = np.mgrid[-5:6, -5:6]
            bg = np.median(win[np.hypot(xs, ys) > 4])
            w = np.clip(win - bg, 0, None) * (np.hypot(xs + x0 - p[0], ys + y0 - p[1]) < 3.5)
            c = np.array([(w * (xs + x0)).sum(), (w * (ys + y0)).sum()]) / w.sum()
            errs.append(np.hypot(*(c - p)))
    errs = np.array(errs)
    assert len(errs) > 10
    assert np.median(errs) < 0.35 and np.percentile(errs, 90) < 0.8


def test_scoring_a_one_camera_sequence(seq):
    import pandas as pd

    T, N = seq.visible.shape
    tr = pd.DataFrame({"camera": "cam2", "frame": np.repeat(np.arange(T), N), "point": np.tile(np.arange(N), T),
                       "x": seq.points[..., 0].ravel() + 0.1, "y": seq.points[..., 1].ravel(), "status": "ok"})
    s = score_tracks(tr, seq, "cam2")
    assert s["ok_share"] == 1.0 and s["rms_px"] == pytest.approx(0.1) and s["confident_errors"] == 0


@pytest.fixture(scope="module")
def long_seq(folder):
    return realdots.render_realdots("cam1", seed=4, n_frames=25 + realdots.GLITCH_SPARE, size=128, folder=folder)


def test_glitches_carry_the_truth_with_them(long_seq):
    """Each glitch changes the frames and moves the truth with them: dropped frames skip
    source frames (images and truth alike), repeats deliver a frame twice (the first
    byte-identical, the others re-noised), black frames are zero and not visible, a bump
    shifts image and truth together."""
    src = long_seq
    d = realdots.with_glitch(src, "dropped", seed=1)
    gone = d.params["glitch"]["dropped_source_frames"]
    kept = np.setdiff1d(np.arange(len(src)), gone)[: len(d)]
    assert len(d) == 25 and len(gone) == 5
    assert np.array_equal(d.images, src.images[kept]) and np.allclose(d.points, src.points[kept])

    r = realdots.with_glitch(src, "repeated", seed=1)
    twice = np.flatnonzero([np.allclose(r.points[i], r.points[i - 1]) for i in range(1, len(r))]) + 1
    assert len(twice) == 3
    identical = [np.array_equal(r.images[i], r.images[i - 1]) for i in twice]
    assert sum(identical) == 1  # one byte-identical repeat, two re-noised
    for i in twice:
        diff = np.abs(r.images[i].astype(int) - r.images[i - 1].astype(int))
        assert diff.mean() < 3  # re-noised, not another frame

    b = realdots.with_glitch(src, "black", seed=1)
    black = b.params["glitch"]["black_frames"]
    assert b.images[black].max() == 0 and not b.visible[black].any()
    assert np.array_equal(np.delete(b.images, black, 0), np.delete(src.images[:25], black, 0))

    m = realdots.with_glitch(src, "bumped", seed=1)
    k, (dx, dy) = m.params["glitch"]["bumped_from"], m.params["glitch"]["shift"]
    assert np.allclose(m.points[k:], src.points[k:25] + (dx, dy)) and np.allclose(m.points[:k], src.points[:k])
    assert np.array_equal(m.images[k, 20:100, 20:100], src.images[k, 20 - dy:100 - dy, 20 - dx:100 - dx])

    with pytest.raises(ValueError, match="kind must be one of"):
        realdots.with_glitch(src, "shaken", seed=1)
    with pytest.raises(ValueError, match="render more frames"):
        realdots.with_glitch(src, "dropped", seed=1, n_frames=len(src))


def test_head_keeps_the_first_frames_and_their_truth(long_seq):
    h = long_seq.head(4)
    assert len(h) == 4 and h.camera == long_seq.camera
    assert np.array_equal(h.images, long_seq.images[:4]) and np.array_equal(h.points, long_seq.points[:4])
    assert np.array_equal(h.visible, long_seq.visible[:4]) and np.array_equal(h.homographies, long_seq.homographies[:4])
    with pytest.raises(ValueError, match="n_frames must be between 1 and"):
        long_seq.head(len(long_seq) + 1)


def test_glitch_benchmark_writes_one_row_per_sequence(folder, tmp_path):
    """``benchmarks/track_realdots_glitches.py`` tracks, scores and tables each sequence,
    and its exit code says whether any ok point was more than 1 px off."""
    import importlib.util
    import sys
    from pathlib import Path

    import pandas as pd

    bench = Path(__file__).resolve().parents[1] / "benchmarks"
    sys.path.insert(0, str(bench))
    try:
        spec = importlib.util.spec_from_file_location("track_realdots_glitches", bench / "track_realdots_glitches.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        out = tmp_path / "t.csv"
        rc = mod.main(["--seed-list", "1", "--kinds", "none", "bumped", "--frames", "20", "--csv", str(out)])
    finally:
        sys.path.remove(str(bench))
    df = pd.read_csv(out)
    assert sorted(zip(df.kind, df.camera)) == sorted((k, c) for k in ("none", "bumped") for c in realdots.CAMERAS)
    assert (df.n_visible > 0).all() and df.ok_share.between(0, 1).all()
    assert rc == int(df.confident_errors.sum() > 0)
