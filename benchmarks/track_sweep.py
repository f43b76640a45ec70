"""Validation sweep of the tracker over the synthetic scenarios and real dot texture.

``python benchmarks/track_sweep.py [--set dev|test] [--scenarios NAME ...] [--seeds N]
[--real-speed LOW HIGH] [--real-exposure E]``

(``--real-speed 3 5 --real-exposure 0``: the real dots on a milder warp, slower and
without motion blur.)

For every scenario of :mod:`wingphoto.synth.scenarios` (and the real-dot sequences of
:mod:`wingphoto.synth.realdots` when ``../shared/data/real-dots`` is there), every seed of
the chosen set and both cameras, renders the sequence, tracks it from its frame-0 picks
with ``wingphoto.track_markers`` (default options; frames in memory) and scores the
tracks against the exact truth with :func:`wingphoto.validation.score_tracks`. Prints,
per scenario (pooled over seeds and cameras):

* ``ok``: share of visible point-frames reported ok (visible: as the sequence says:
  the marker's centre inside the image and its face towards the camera); ``ok(pk)`` the
  same over the points that had a frame-0 pick;
* ``RMS``, ``p95``, ``worst``: radial error of the ok points, px;
* ``conf``: confident errors, ok points more than 1 px from the truth;
* ``<=3sig``, ``med e/s``: sigma honesty over ok points (share within 3 sigma, median of
  error / sigma; ``nan`` when the tracks carry no ``sigma``);
* ``fps``, ``(CPU)``: frames per second of ``track_markers`` per camera, median over the
  sequences, of wall-clock and of process CPU time (rendering not timed; short
  sequences, so the start of tracking weighs in: ``benchmarks/track_bench.py`` measures
  speed properly).

Then the thesis baseline (``wingphoto.track_thesis``) on the first seed of
``clean_glare`` (``--thesis-frames`` frames) for comparison. Writes the table to
``--csv`` (default ``benchmarks/track_sweep_<set>.csv``). Exits 1 if any ok point is
more than 1 px from the truth or if tracking crashed on any sequence (a crash is
reported and scored as nothing ok). Tune on ``--set dev``; report ``--set test``.
"""
from __future__ import annotations

import argparse
import logging
import os
import platform
import sys
import time

import numpy as np
import pandas as pd


def versions():
    """One line with the library versions the figures depend on."""
    import cv2

    parts = [f"Python {platform.python_version()}", f"numpy {np.__version__}", f"OpenCV {cv2.__version__}"]
    try:
        import numba

        parts.append(f"numba {numba.__version__}")
    except ImportError:
        parts.append("no numba")
    load = os.getloadavg() if hasattr(os, "getloadavg") else (np.nan,) * 3
    parts.append(f"{os.cpu_count()} CPUs, load {load[0]:.2f}")
    return "; ".join(parts)


def _track(frames, picks, camera):
    """Track; return the tracks, frames/s of wall-clock time and of process CPU time."""
    from wingphoto import track_markers

    c0, t0 = time.process_time(), time.perf_counter()
    tr = track_markers(frames, picks, camera=camera, progress=False)
    return tr, len(frames) / (time.perf_counter() - t0), len(frames) / max(time.process_time() - c0, 1e-9)


def _sequences(names, seeds, n_frames, real):
    """Yield (scenario, seed, sequence, cameras)."""
    from wingphoto.synth import scenarios

    for name in names:
        for seed in seeds:
            if name.startswith("realdots"):
                seq = real(name, seed, n_frames)
                if seq is None:
                    break
                yield name, seed, seq, (seq.camera,)
            else:
                yield name, seed, scenarios.render_scenario(name, seed=seed, n_frames=n_frames), ("left", "right")


def main(argv=None):
    from wingphoto.synth import realdots, scenarios
    from wingphoto.validation import point_errors, summarize_errors

    real_names = tuple(f"realdots_{c}" for c in realdots.CAMERAS)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", choices=("dev", "test"), default="dev", help="seed set (default dev)")
    ap.add_argument("--scenarios", nargs="*", default=list(scenarios.SCENARIOS) + list(real_names),
                    help="scenario names (default all, real dots included)")
    ap.add_argument("--seeds", type=int, default=None, help="use only the first N seeds of the set")
    ap.add_argument("--frames", type=int, default=None, help="frames per sequence (default: each scenario's)")
    ap.add_argument("--thesis-frames", type=int, default=30, help="frames for the thesis baseline (0: skip)")
    ap.add_argument("--csv", default=None, help="output CSV (default benchmarks/track_sweep_<set>.csv)")
    ap.add_argument("--real-speed", type=float, nargs=2, default=(10.0, 15.0), metavar=("LOW", "HIGH"),
                    help="real dots: range of the peak speed, px/frame (default 10 15; 3 5: a milder warp)")
    ap.add_argument("--real-exposure", type=float, default=0.4,
                    help="real dots: exposure, share of the frame interval (default 0.4; 0: no motion blur)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)  # the tracker's per-sequence warnings (NaN picks) are expected
    unknown = [n for n in args.scenarios if n not in scenarios.SCENARIOS and n not in real_names]
    if unknown:
        ap.error(f"unknown scenarios {unknown}; choose from {list(scenarios.SCENARIOS) + list(real_names)}")
    seeds = scenarios.DEV_SEEDS if args.set == "dev" else scenarios.TEST_SEEDS
    rseeds = realdots.DEV_SEEDS if args.set == "dev" else realdots.TEST_SEEDS
    if args.seeds is not None:
        seeds, rseeds = seeds[: args.seeds], rseeds[: args.seeds]

    def real(name, seed, n_frames):
        try:
            return realdots.render_realdots(name.split("_", 1)[1], seed=seed, n_frames=n_frames,
                                            peak_speed=tuple(args.real_speed), exposure=args.real_exposure)
        except FileNotFoundError as exc:
            print(f"{name}: skipped ({exc})")
            return None

    print(versions())
    print(f"seed set {args.set}: scenarios {list(seeds)}, real dots {list(rseeds)} (peak speed "
          f"{args.real_speed[0]:g}-{args.real_speed[1]:g} px/frame, exposure {args.real_exposure:g})")
    hdr = (f"{'scenario':18s} {'seqs':>4s} {'ok':>6s} {'ok(pk)':>6s} {'RMS':>6s} {'p95':>6s} {'worst':>6s} "
           f"{'conf':>5s} {'<=3sig':>6s} {'med e/s':>7s} {'fps':>6s} {'(CPU)':>6s}")
    print(hdr)
    rows = []
    crashes = []
    for name in args.scenarios:
        pooled = {k: [] for k in ("error", "ok", "visible", "sigma", "ok_pk", "vis_pk")}
        rates, crates, n_seq, worst_seq = [], [], 0, ""
        for _, seed, seq, cams in _sequences([name], rseeds if name in real_names else seeds, args.frames, real):
            for cam in cams:
                picks = seq.picks(cam)
                try:
                    tr, fps, cfps = _track(seq.frames(cam), picks, cam)
                except Exception as exc:  # a crash is a result: counted, reported, exit status 1
                    crashes.append(f"{name} seed {seed} {cam}: {type(exc).__name__}: {exc}")
                    print(f"    CRASH {crashes[-1]}", flush=True)
                    tr = pd.DataFrame({"camera": [], "frame": [], "point": [], "x": [], "y": [], "status": []})
                    fps = cfps = np.nan
                rates.append(fps)
                crates.append(cfps)
                a = point_errors(tr, seq, cam)
                picked = np.flatnonzero(np.all(np.isfinite(picks), axis=1))
                b = point_errors(tr, seq, cam, points=picked)
                for k in ("error", "ok", "visible", "sigma"):
                    pooled[k].append(a[k].ravel())
                pooled["ok_pk"].append(b["ok"].ravel())
                pooled["vis_pk"].append(b["visible"].ravel())
                s = summarize_errors(a["error"], a["ok"], a["visible"], a["sigma"])
                if s["confident_errors"]:
                    worst_seq += f" seed {seed} {cam}: {s['confident_errors']} (worst {s['worst_px']:.1f} px);"
                n_seq += 1
        if not n_seq:
            continue
        cat = {k: np.concatenate(v) for k, v in pooled.items()}
        s = summarize_errors(cat["error"], cat["ok"], cat["visible"], cat["sigma"])
        vis_pk = cat["vis_pk"].sum()
        s["ok_share_picked"] = (cat["ok_pk"] & cat["vis_pk"]).sum() / vis_pk if vis_pk else np.nan
        s["fps"] = float(np.nanmedian(rates)) if np.isfinite(rates).any() else np.nan
        s["fps_cpu"] = float(np.nanmedian(crates)) if np.isfinite(crates).any() else np.nan
        s["crashes"] = int(np.isnan(rates).sum())
        s.update(scenario=name, n_sequences=n_seq, set=args.set)
        rows.append(s)
        print(f"{name:18s} {n_seq:4d} {s['ok_share']:6.3f} {s['ok_share_picked']:6.3f} {s['rms_px']:6.3f} "
              f"{s['p95_px']:6.3f} {s['worst_px']:6.2f} {s['confident_errors']:5d} {s['within_3_sigma']:6.3f} "
              f"{s['median_error_over_sigma']:7.2f} {s['fps']:6.0f} {s['fps_cpu']:6.0f}", flush=True)
        if worst_seq:
            print(f"    confident errors:{worst_seq}")

    if args.thesis_frames > 0 and "clean_glare" in args.scenarios:
        from wingphoto import track_thesis

        n = args.thesis_frames
        seq = scenarios.render_scenario("clean_glare", seed=seeds[0], n_frames=n)
        picks = seq.picks("left")
        keep = np.all(np.isfinite(picks), axis=1)
        t0 = time.perf_counter()
        res = track_thesis(seq.frames("left"), picks[keep], camera="left", progress=False)
        fps = n / (time.perf_counter() - t0)
        tr = res.tracks.copy()
        tr["point"] = np.flatnonzero(keep)[tr["point"].to_numpy()]
        s = summarize_errors(**{k: v for k, v in point_errors(tr, seq, "left").items()})
        tr2, fps2, _ = _track(seq.frames("left"), picks, "left")
        s2 = summarize_errors(**point_errors(tr2, seq, "left"))
        print(f"\nthesis baseline, clean_glare seed {seeds[0]}, left camera, {n} frames:")
        for label, r, f in (("track_thesis", s, fps), ("track_markers", s2, fps2)):
            print(f"  {label:14s} ok {r['ok_share']:.3f}  RMS {r['rms_px']:.3f} px  worst {r['worst_px']:.2f} px  "
                  f"conf {r['confident_errors']}  {f:.0f} frames/s")
        rows.append(dict(s, scenario="thesis_baseline(clean_glare)", n_sequences=1, set=args.set, fps=fps,
                         ok_share_picked=np.nan))

    if rows:
        out = args.csv or os.path.join(os.path.dirname(os.path.abspath(__file__)), f"track_sweep_{args.set}.csv")
        from wingphoto.io import atomic_write

        with atomic_write(out, "w") as fh:
            pd.DataFrame(rows).to_csv(fh, index=False)
        print(f"table written to {out}")
    bad = sum(r["confident_errors"] for r in rows if not r["scenario"].startswith("thesis"))
    print(f"confident errors (ok > 1 px) over all scenarios: {bad}; crashed runs: {len(crashes)}")
    for c in crashes:
        print(f"  crash: {c}")
    return 1 if bad or crashes else 0


if __name__ == "__main__":
    sys.exit(main())
