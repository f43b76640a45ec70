"""Tracking speed and memory, and an accuracy sweep, run by hand.

``python benchmarks/track_bench.py``: frames per second per camera for 30 markers on
512 x 512 frames, in one run:

* ``track_markers`` (wingphoto.track: tracking + sub-pixel refinement), default options,
  on ``--frames`` (default 300) and on 1000 frames (its start - picks, the wide search of
  frame 1 - costs ~15 ms once), with the full NCC search on every marker every frame
  (``search_every=1``), and without the optional numba kernels (the numpy/OpenCV code,
  in a subprocess with ``WINGPHOTO_NO_NUMBA=1``);
* ``track_thesis`` (wingphoto.thesis: NCC.m + trackcl.m, the thesis baseline);
* ``trackpy.locate`` (a peer: bandpass + peak finding + centroid refinement per frame,
  no linking), ``diameter`` the odd size just above the marker diameter;
* ``track_markers`` on a realistic wing render (:func:`wingphoto.synth.render_flapping`:
  perspective, shading, 26 markers; one wing beat cycled to 1000 frames) next to the disc
  row, with the ratio of the two (wall clock and CPU time), and the same run with the
  compiled fast frame off (``engine.try_fast_frames(False)``: every frame stage by stage,
  :mod:`wingphoto.track.fastpath`); the notes give the share of frames the fast frame
  handled.

Every run prints the library versions (Python, numpy, numba, OpenCV), the CPU count and
the load average with the figures: on a shared machine compare the CPU-time column.

The sequence is rendered first (anti-aliased discs moving as on a flapping wing, periodic
so that it can be cycled without a jump) and held in memory, so decoding is not timed
there. Decoding is timed on its own, and end to end: the wing render's 1000 frames are
written to a temporary folder as one TIFF per frame (the thesis' exports) and as one
multi-page TIFF, then read back with :func:`wingphoto.read_sequence` (every frame
decoded, nothing tracked) and tracked straight from the files (``track_markers`` on the
lazy sequence: decoding + tracking, as ``wingphoto track`` runs; ``--no-io`` skips it).
Ratios are against ``track_thesis``. Then the peak memory (``tracemalloc``) of
``track_markers`` on lazily produced sequences of growing length shows that frames are
streamed: what grows is only the result table (~0.5 kB per frame for 30 markers).

The target (issues 4 and 8) is >= 3000 frames/s per camera (the cameras' own rate) on
the realistic wing render. Timings
depend on the machine and its load: the script prints the CPU count and load average.

``python benchmarks/track_bench.py --sweep [--sweep-args ...]`` runs the validation sweep
of ``benchmarks/track_sweep.py`` (the synth scenarios); ``--sweep --legacy-sweep``: tracks
hard ``wingphoto.synth`` sequences
(110 deg stroke, glare, motion blur, edge-on markers) started at several stroke phases
and seeds - markers invisible in frame 0 have no pick - and prints, per sequence and
camera, the share of visible point-frames reported ok and the largest error of an ok
point; it exits with status 1 if any ok point is more than 1 px from the truth (the
issue's hard rule). ``--phases`` and ``--seeds`` choose the sequences (paired in order).
"""
from __future__ import annotations

import argparse
import gc
import os
import subprocess
import sys
import time
import tracemalloc

import numpy as np

from wingphoto.synth import render_discs


def wing_sequence(n_frames=100, n_markers=30, *, period=100, seed=0):
    """30 markers on a 5 x 6 grid rotating about a hinge (peak speed ~12 px/frame)."""
    rng = np.random.default_rng(seed)
    span = np.linspace(60, 230, 6)
    chord = np.linspace(-40, 40, 5)
    s, c = np.meshgrid(span, chord)
    local = np.column_stack([s.ravel(), c.ravel()])[:n_markers]
    diam = rng.uniform(6, 11, n_markers)
    hinge = np.array([150.0, 256.0])
    t = np.arange(n_frames)
    ang = np.deg2rad(50) * np.sin(2 * np.pi * t / period)  # +-50 deg: tip ~13 px/frame
    truth = np.empty((n_frames, n_markers, 2))
    for k in range(n_frames):
        ca, sa = np.cos(ang[k]), np.sin(ang[k])
        truth[k, :, 0] = hinge[0] + ca * local[:, 0] - sa * local[:, 1]
        truth[k, :, 1] = hinge[1] + sa * local[:, 0] + ca * local[:, 1]
    frames = np.stack([render_discs(truth[k], diam, (512, 512), bg=20.0, amp=200.0, noise_std=2.0, rng=rng, ss=4) for k in range(n_frames)])
    return frames, truth, diam


class CycledFrames:
    """A lazy sequence of ``n`` frames that cycles a periodic block (constant memory)."""

    def __init__(self, block, n):
        self.block, self.n = block, n

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        if not 0 <= i < self.n:
            raise IndexError(i)
        return self.block[i % len(self.block)]


def timed(fn, repeat):
    """Best wall-clock time of ``repeat`` runs (and the process CPU time of that run)."""
    best = (np.inf, np.inf)
    out = None
    for _ in range(repeat):
        gc.collect()
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        run = (time.perf_counter() - t0, time.process_time() - c0)
        best = min(best, run)
    return best, out


def sweep(phases, seeds, n_frames):
    """Track hard sequences at the given (phase, seed) pairs, print one row per sequence
    and camera; return True when no ok point is more than 1 px from the truth."""
    from wingphoto import synth
    from wingphoto.track import track_markers

    print(f"{'phase':>5s} {'seed':>4s} {'camera':6s} {'no pick':>7s} {'ok share':>8s} {'(picked)':>8s} "
          f"{'max ok err':>10s} {'ok > 1 px':>9s}")
    bad_total = 0
    shares = []
    worst = 0.0
    for phase, seed in zip(phases, seeds):
        seq = synth.render_flapping(n_frames=n_frames, preset="hard", phase_deg=phase, seed=seed)
        for camera in ("left", "right"):
            truth, vis = getattr(seq, f"points_{camera}"), getattr(seq, f"visible_{camera}")
            picks = seq.picks(camera)
            tr = track_markers(seq.frames(camera), picks, camera=camera, progress=False)
            T, N = truth.shape[:2]
            x = tr.x.to_numpy().reshape(T, N)
            y = tr.y.to_numpy().reshape(T, N)
            ok = (tr.status == "ok").to_numpy().reshape(T, N)
            err = np.hypot(x - truth[..., 0], y - truth[..., 1])
            picked = np.isfinite(picks[:, 0])
            share = (ok & vis).sum() / vis.sum()
            share_p = (ok & vis)[:, picked].sum() / vis[:, picked].sum()
            mx = float(err[ok].max()) if ok.any() else float("nan")
            bad = int((ok & (err > 1.0)).sum())
            bad_total += bad
            shares.append(share)
            worst = max(worst, mx)
            print(f"{phase:5.0f} {seed:4d} {camera:6s} {int((~picked).sum()):7d} {share:8.3f} {share_p:8.3f} "
                  f"{mx:10.3f} {bad:9d}")
    print(f"mean ok share {np.mean(shares):.3f}; largest ok error {worst:.3f} px; ok points > 1 px: {bad_total}")
    return bad_total == 0


def _rate_without_numba(frames, repeat):
    """track_markers' frames/s with the numpy/OpenCV code only (a fresh interpreter)."""
    code = (
        "import sys, time, numpy as np; sys.path.insert(0, %r)\n"
        "import track_bench as b\n"
        "from wingphoto.track import track_markers\n"
        "block, truth, _ = b.wing_sequence(100, period=100)\n"
        "p = np.rint(truth[0]); track_markers(b.CycledFrames(block, 5), p, progress=False)\n"
        "best = b.timed(lambda: track_markers(b.CycledFrames(block, %d), p, progress=False), %d)[0][0]\n"
        "print(%d / best)\n" % (os.path.dirname(os.path.abspath(__file__)), frames, repeat, frames)
    )
    env = dict(os.environ, WINGPHOTO_NO_NUMBA="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def _fast_share():
    """Share of the frames since the last reset that the compiled fast frame handled."""
    import wingphoto.track as wt

    if not wt.engine.use_fast_frames():
        return "fast frame not in use"
    s = wt.fastpath.stats.copy()
    wt.fastpath.reset_stats()
    return f"fast frame {s[0] / max(s.sum(), 1):.1%} of frames" if s.sum() else "fast frame not in use"


def decode_and_track(wblock, wpicks, n, repeat):
    """Rows (name, frames/s, CPU frames/s, note) for reading ``n`` frames of the wing render
    from TIFF files, alone and with tracking, in a temporary folder (removed after)."""
    import tempfile

    import tifffile

    from wingphoto import read_sequence
    from wingphoto.track import track_markers

    rows = []
    with tempfile.TemporaryDirectory(prefix="wingphoto-bench-") as tmp:
        folder = os.path.join(tmp, "frames")
        os.mkdir(folder)
        for i in range(n):
            tifffile.imwrite(os.path.join(folder, f"frame_{i:05d}.tif"), wblock[i % len(wblock)])
        stack = os.path.join(tmp, "stack.tif")
        with tifffile.TiffWriter(stack) as tw:
            for i in range(n):
                tw.write(wblock[i % len(wblock)], contiguous=True)
        for label, source in (("one TIFF per frame", folder), ("multi-page TIFF", stack)):
            def decode():
                seq = read_sequence(source)
                for i in range(len(seq)):
                    seq[i]
            (dt, cpu), _ = timed(decode, repeat)
            rows.append((f"read_sequence ({label})", n / dt, n / cpu, f"{n} frames decoded, not tracked"))
            (dt, cpu), _ = timed(lambda: track_markers(read_sequence(source), wpicks, progress=False), repeat)
            rows.append(("  + track_markers (end to end)", n / dt, n / cpu,
                         "wing render read from the files and tracked"))
    return rows


def versions():
    """One line: the libraries and machine every figure depends on."""
    import platform

    import cv2

    import wingphoto.track as wt

    try:
        import numba

        nb = numba.__version__
    except ImportError:
        nb = "not installed"
    load = os.getloadavg() if hasattr(os, "getloadavg") else (np.nan,) * 3
    return (f"Python {platform.python_version()}, numpy {np.__version__}, numba {nb} "
            f"({'used' if wt.engine.use_numba() else 'not used'}), OpenCV {cv2.__version__} "
            f"({cv2.getNumThreads()} threads); {os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} "
            f"{load[2]:.2f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=300, help="frames for track_markers (default 300)")
    ap.add_argument("--thesis-frames", type=int, default=20, help="frames for track_thesis (slow; default 20)")
    ap.add_argument("--trackpy-frames", type=int, default=50, help="frames for trackpy.locate (default 50)")
    ap.add_argument("--repeat", type=int, default=3, help="best of this many runs (default 3)")
    ap.add_argument("--memory", type=int, nargs="*", default=[500, 2000, 8000],
                    help="sequence lengths for the memory test")
    ap.add_argument("--sweep", action="store_true", help="run the accuracy sweep instead of the timings")
    ap.add_argument("--phases", type=float, nargs="*", default=[37.0 * k for k in range(10)],
                    help="stroke phases (deg) of the sweep's sequences")
    ap.add_argument("--seeds", type=int, nargs="*", default=list(range(10)), help="their seeds")
    ap.add_argument("--sweep-frames", type=int, default=100, help="frames per sweep sequence (default 100)")
    ap.add_argument("--legacy-sweep", action="store_true", help="the older phase sweep of this script")
    ap.add_argument("--sweep-args", nargs=argparse.REMAINDER, default=[],
                    help="arguments passed on to benchmarks/track_sweep.py")
    ap.add_argument("--no-io", action="store_true", help="skip the decoding and end-to-end rows (TIFF files)")
    ap.add_argument("--realistic-frames", type=int, default=100,
                    help="frames of the realistic wing render, cycled to 1000 (default 100: one beat)")
    args = ap.parse_args(argv)

    if args.sweep:
        sweep_script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "track_sweep.py")
        if os.path.exists(sweep_script) and not args.legacy_sweep:
            # the validation sweep over the synth scenarios (benchmarks/track_sweep.py)
            return subprocess.call([sys.executable, sweep_script] + list(args.sweep_args))
        if len(args.phases) != len(args.seeds):
            ap.error("--phases and --seeds must have the same length (they are paired)")
        return 0 if sweep(args.phases, args.seeds, args.sweep_frames) else 1

    import wingphoto.track as wt
    from wingphoto.track import track_markers

    print(versions())
    print(f"engine: {'compiled (numba)' if wt.engine.use_numba() else 'numpy/OpenCV'}")
    period = 100
    block, truth, diam = wing_sequence(period, period=period)
    T = args.frames
    frames = CycledFrames(block, T)
    picks = np.rint(truth[0])
    print(f"sequence: {len(picks)} markers ({diam.min():.1f}-{diam.max():.1f} px), 512x512 uint8, "
          f"peak speed {np.abs(np.diff(truth, axis=0)).max():.1f} px/frame")

    rows = []
    track_markers(CycledFrames(block, 5), picks, progress=False)  # warm-up (imports, caches)
    wt.fastpath.reset_stats()
    (dt, cpu), tr = timed(lambda: track_markers(frames, picks, progress=False), args.repeat)
    err = np.hypot(tr.x.to_numpy().reshape(T, -1) - np.tile(truth, (T // period + 1, 1, 1))[:T, :, 0],
                   tr.y.to_numpy().reshape(T, -1) - np.tile(truth, (T // period + 1, 1, 1))[:T, :, 1])
    ok = (tr.status == "ok").to_numpy().reshape(T, -1)
    rows.append((f"track_markers ({T} frames)", T / dt, T / cpu,
                 f"ok {ok.mean():.3f}, RMS {np.sqrt(np.mean(err[ok] ** 2)):.3f} px"))
    (dt, cpu), _ = timed(lambda: track_markers(CycledFrames(block, 1000), picks, progress=False), args.repeat)
    rows.append(("track_markers (1000 frames)", 1000 / dt, 1000 / cpu,
                 f"the start (~15 ms) spread over more frames; {_fast_share()}"))
    disc = rows[-1]
    # a realistic wing: wingphoto.synth.render_flapping (perspective, shading, ~26 markers),
    # one wing beat rendered and cycled to 1000 frames
    from wingphoto import synth

    wing = synth.render_flapping(n_frames=args.realistic_frames, preset="clean", seed=0)
    wblock = wing.frames("left")
    wpicks = wing.picks("left")
    track_markers(CycledFrames(wblock, 5), wpicks, progress=False)
    wt.fastpath.reset_stats()
    (dt, cpu), wtr = timed(lambda: track_markers(CycledFrames(wblock, 1000), wpicks, progress=False), args.repeat)
    nw = int(np.isfinite(wpicks[:, 0]).sum())
    rows.append(("track_markers (wing render, 1000)", 1000 / dt, 1000 / cpu,
                 f"{nw} markers, {wblock.shape[1]}x{wblock.shape[2]}; ok {np.mean(wtr.status == 'ok'):.3f}; "
                 f"wall {1000 / dt / disc[1]:.2f}x, CPU {1000 / cpu / disc[2]:.2f}x the disc row; "
                 f"{_fast_share()}"))
    if wt.engine.use_fast_frames():
        try:
            wt.engine.try_fast_frames(False)
            (dt, cpu), _ = timed(lambda: track_markers(CycledFrames(wblock, 1000), wpicks, progress=False),
                                 args.repeat)
        finally:
            wt.engine.try_fast_frames(True)
        rows.append(("  (wing render, fast frame off)", 1000 / dt, 1000 / cpu,
                     "every frame stage by stage (the tracks are identical)"))
    if not args.no_io:
        rows += decode_and_track(wblock, wpicks, 1000, args.repeat)
    if wt.engine.use_numba():
        rows.append(("track_markers (no numba)", _rate_without_numba(T, args.repeat), np.nan,
                     "numpy/OpenCV code only (WINGPHOTO_NO_NUMBA=1)"))
    (dt, cpu), tr = timed(lambda: track_markers(frames, picks, search_every=1, progress=False), args.repeat)
    rows.append(("track_markers(search_every=1)", T / dt, T / cpu, "full NCC search on every marker, every frame"))

    try:
        from wingphoto.thesis import track_thesis
    except ImportError:
        track_thesis = None
    if track_thesis is not None:
        n = args.thesis_frames
        (dt, cpu), _ = timed(lambda: track_thesis(CycledFrames(block, n), picks, progress=False), 1)
        rows.append(("track_thesis", n / dt, n / cpu, "NCC.m + trackcl.m (whole-frame normxcorr2)"))
    else:
        rows.append(("track_thesis", np.nan, np.nan, "wingphoto.thesis not available"))

    try:
        import trackpy

        trackpy.quiet()
        n = args.trackpy_frames
        d = int(np.ceil(diam.max())) | 1

        def locate():
            for i in range(n):
                # threshold: without it (and without numba) trackpy refines every noise
                # maximum in Python, ~0.4 s per frame
                trackpy.locate(block[i % period], d, minmass=100, threshold=10)

        (dt, cpu), _ = timed(locate, 1)
        rows.append((f"trackpy.locate(diameter={d})", n / dt, n / cpu,
                     "peer: bandpass + detection + refinement per frame, no linking"))
    except ImportError:
        rows.append(("trackpy.locate", np.nan, np.nan, "trackpy not installed (pip install trackpy)"))

    ref = next((r[1] for r in rows if r[0] == "track_thesis"), np.nan)
    print(f"\n{'method':34s} {'frames/s':>9s} {'(CPU)':>7s} {'x thesis':>9s}  notes")
    for name, fps, cfps, note in rows:
        print(f"{name:34s} {fps:9.0f} {cfps:7.0f} {fps / ref:9.1f}  {note}")
    print("frames/s: wall clock, best of runs; (CPU): frames per second of process CPU time")
    print(versions())
    print("target: track_markers >= 3000 frames/s per camera")

    print("\npeak memory of track_markers (tracemalloc), frames produced lazily:")
    print(f"{'frames':>8s} {'peak MB':>9s} {'kB/frame':>9s}")
    for n in args.memory:
        gc.collect()
        tracemalloc.start()
        tr = track_markers(CycledFrames(block, n), picks, progress=False)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        print(f"{n:8d} {peak / 1e6:9.1f} {peak / n / 1e3:9.2f}")
        del tr
    print("a frame is 262 kB: the peak grows by the result table only (frames are not kept)")


if __name__ == "__main__":
    sys.exit(main())
