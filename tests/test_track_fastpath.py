"""The compiled fast frame (wingphoto.track.fastpath) changes the speed, never the tracks.

Each sequence is tracked twice with the compiled engine, the fast frame on and off
(``engine.try_fast_frames``), and the two tables must be identical: statuses and reasons
equal, floats equal to 1e-9. Each test also asserts that the fast frame did handle frames
(and, on clean sequences, most of them), so that the comparison is not vacuous; the
glitched sequences check that the frames it must not handle (blank, repeated) go back to
the Python step.
"""
import numpy as np
import pytest

from wingphoto import synth
from wingphoto.synth import realdots, scenarios
from wingphoto.track import engine, fastpath, track_markers

pytestmark = pytest.mark.skipif(not engine.NUMBA_AVAILABLE, reason="the fast frame needs numba")

FLOATS = ["x", "y", "score", "sigma", "x_pix", "y_pix"]


def _track_both(frames, picks, **kw):
    """Tracks with the fast frame off and on, and the fast frame's counts of the second run."""
    try:
        engine.try_fast_frames(False)
        fastpath.reset_stats()
        slow = track_markers(frames, picks, progress=False, **kw)
        assert fastpath.stats.sum() == 0, "the switch did not turn the fast frame off"
        engine.try_fast_frames(True)
        fast = track_markers(frames, picks, progress=False, **kw)
    finally:
        engine.try_fast_frames(True)
    return slow, fast, fastpath.summary()


def _assert_identical(slow, fast):
    assert list(slow.columns) == list(fast.columns)
    assert (slow.dtypes == fast.dtypes).all()
    for c in ("camera", "frame", "point", "status", "reason"):
        bad = (slow[c].to_numpy() != fast[c].to_numpy()).nonzero()[0]
        assert bad.size == 0, f"{c} differs on {bad.size} rows, first {fast.iloc[bad[0]][['frame', 'point']].tolist()}"
    for c in FLOATS:
        a, b = slow[c].to_numpy(), fast[c].to_numpy()
        same = np.isclose(a, b, rtol=0.0, atol=1e-9, equal_nan=True)
        assert same.all(), f"{c} differs on {(~same).sum()} rows (worst {np.nanmax(np.abs(a - b)):.3g})"


@pytest.fixture(scope="module")
def clean():
    return synth.render_flapping(n_frames=30, preset="clean", seed=0)


@pytest.fixture(scope="module")
def hard():
    return synth.render_flapping(n_frames=24, preset="hard", seed=2)  # (right: 11 flagged points)


@pytest.mark.parametrize("camera", ["left", "right"])
def test_clean_wing_identical_and_mostly_fast(clean, camera):
    slow, fast, counts = _track_both(clean.frames(camera), clean.picks(camera), camera=camera)
    _assert_identical(slow, fast)
    T = len(clean.frames(camera))
    assert counts.get("handled", 0) >= 0.8 * (T - 1), counts


@pytest.mark.parametrize("camera", ["left", "right"])
def test_hard_wing_identical(hard, camera):
    slow, fast, counts = _track_both(hard.frames(camera), hard.picks(camera), camera=camera)
    _assert_identical(slow, fast)
    assert counts.get("handled", 0) > 0, counts
    # a sequence with flags, and events (besides frame 1's wide search) the Python step handled
    assert (fast.status == "flagged").any()
    assert sum(v for k, v in counts.items() if k != "handled") >= 2, counts


def test_backward_pass_identical(clean):
    frames = clean.frames("left")[:20]
    slow, fast, counts = _track_both(frames, clean.picks("left"), bidirectional=True)
    _assert_identical(slow, fast)
    assert counts.get("handled", 0) >= 24, counts  # both passes


@pytest.mark.parametrize("name", ["dropped_frames", "repeated_frames", "bumped_camera", "black_frame", "enter_leave"])
def test_glitched_scenarios_identical(name):
    seq = scenarios.render_scenario(name, seed=scenarios.DEV_SEEDS[0], n_frames=20)
    slow, fast, counts = _track_both(seq.frames("left"), seq.picks("left"))
    _assert_identical(slow, fast)
    assert counts.get("handled", 0) > 0, counts
    if name in ("repeated_frames", "black_frame"):
        # a repeated or blank frame is the Python step's: the frame check sent it back
        assert counts.get("frame_check", 0) >= 2, counts


def test_real_dots_identical():
    folder = realdots.default_folder()
    if not (folder / "cal1.tif").is_file():
        pytest.skip(f"real-dot photographs not found at {folder}")
    seq = realdots.render_realdots("cam1", seed=realdots.DEV_SEEDS[2], n_frames=30, folder=folder)
    slow, fast, counts = _track_both(seq.frames(), seq.picks())
    _assert_identical(slow, fast)
    # (dots leave this view all the time: a lost or edge marker sends the frame to Python)
    assert sum(counts.values()) == len(seq) - 1, counts


def test_numpy_engine_never_runs_the_fast_frame(clean):
    fastpath.reset_stats()
    try:
        engine.try_numba(False)
        assert not engine.use_fast_frames()
        track_markers(clean.frames("left")[:5], clean.picks("left"), progress=False)
    finally:
        engine.try_numba(True)
    assert fastpath.stats.sum() == 0
    assert engine.use_fast_frames()


def test_fast_frame_is_compiled_for_the_stage_kernels_it_calls():
    # numba's cache key includes the closure's cell contents: the hash of the stage
    # modules' sources, so an edit of a stage kernel recompiles the fast frame
    cells = dict(zip(fastpath._fast_frame.py_func.__code__.co_freevars,
                     (c.cell_contents for c in fastpath._fast_frame.py_func.__closure__)))
    assert cells["key"] == fastpath._dependency_key() > 0


def test_kernel_caches_are_cleared_when_a_kernel_module_changes(tmp_path):
    """numba keys a kernel's cache by its own file: an edit of another kernel module (a
    callee, a constant) must clear the package's caches, and an unchanged source not."""
    from wingphoto.track.engine import clear_stale_caches

    (tmp_path / "a.py").write_text("X = 1\n")
    (tmp_path / "b.py").write_text("Y = 2\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    assert clear_stale_caches(tmp_path, ("a", "b"))  # no stamp yet
    kernel = cache / "b.kernel-1.py311.1.nbc"
    kernel.write_bytes(b"compiled")
    (cache / "b.kernel-1.py311.nbi").write_bytes(b"index")
    assert not clear_stale_caches(tmp_path, ("a", "b"))
    assert kernel.exists()
    (tmp_path / "a.py").write_text("X = 3\n")  # the callee's module changed
    assert clear_stale_caches(tmp_path, ("a", "b"))
    assert not kernel.exists() and not list(cache.glob("*.nbi"))
    assert not clear_stale_caches(tmp_path, ("a", "b"))
