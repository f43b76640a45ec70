"""Measure the tracker on real-dot sequences with recording glitches (:func:`wingphoto.synth.realdots.with_glitch`).

``python benchmarks/track_realdots_glitches.py [--set dev|test] [--seed-list S ...] [--kinds KIND ...]
[--dropped-runs START:LENGTH ...] [--frames N] [--csv FILE]``

For every seed, camera (cam1, cam2) and kind (``none``: the sequence as rendered, and the
glitches ``dropped``, ``repeated``, ``black``, ``bumped``; or, with ``--dropped-runs``,
``dropped`` with exactly those runs of source frames left out) renders a real-dot sequence
(:func:`~wingphoto.synth.realdots.render_realdots`, 256 x 256, the sweep's warp), puts
the glitch in, tracks it with ``wingphoto.track_markers`` (default options) from its
frame-0 picks and scores the picked points against the truth
(:func:`wingphoto.validation.score_tracks`). Prints one line per sequence and a pooled
row per kind and camera: share of visible point-frames ok, RMS / worst error of ok
points, confident errors (ok > 1 px). Writes one row per sequence to ``--csv``. Exits 1 on
any confident error or crash.

The dots of these photographs lie on a regular grid about as far apart as they move in
a frame or two, so a glitch that is not explained leaves several identities that fit
equally well: the hardest case for "flag, never guess". Tune on ``--set dev``
(seeds 0, 1, 2 or any ``--seed-list``); report ``--set test``.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import time

import numpy as np
import pandas as pd

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from track_sweep import versions  # noqa: E402  (one place for the versions line)

KINDS = ("none",) + ("dropped", "repeated", "black", "bumped")


def run_one(base, kind, seed, n_frames, run=None):
    """Glitch, track and score one sequence; returns a dict (one CSV row). ``run``
    (start, length): ``kind`` 'dropped' with exactly that run of source frames left out."""
    from wingphoto import track_markers
    from wingphoto.synth import realdots
    from wingphoto.validation import score_tracks

    if kind == "none":
        seq = base.head(n_frames)
    else:
        seq = realdots.with_glitch(base, kind, seed=seed, n_frames=n_frames, dropped_run=run)
    picks = base.picks()
    picked = np.flatnonzero(np.all(np.isfinite(picks), axis=1))
    label = kind if run is None else f"dropped {run[0]}:{run[1]}"
    row = dict(kind=label, camera=base.camera, seed=seed, glitch=str(seq.params.get("glitch", "")))
    t0 = time.perf_counter()
    try:
        tr = track_markers(seq.frames(), picks, camera=seq.camera, progress=False)
    except Exception as exc:  # a crash is a result
        row.update(crash=f"{type(exc).__name__}: {exc}", confident_errors=0)
        return row
    row["fps"] = len(seq) / (time.perf_counter() - t0)
    s = score_tracks(tr, seq, seq.camera, points=picked)
    row.update({k: s[k] for k in ("n_visible", "n_ok_visible", "ok_share", "rms_px", "worst_px", "confident_errors",
                                  "within_3_sigma", "median_error_over_sigma")})
    row["crash"] = ""
    return row


def main(argv=None):
    from wingphoto.synth import realdots

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", choices=("dev", "test"), default="dev")
    ap.add_argument("--seed-list", type=int, nargs="*", default=None, help="seeds (default: the set's)")
    ap.add_argument("--kinds", nargs="*", default=list(KINDS), choices=KINDS)
    ap.add_argument("--frames", type=int, default=60, help="frames delivered per sequence (default 60)")
    ap.add_argument("--dropped-runs", nargs="*", default=[], metavar="START:LENGTH",
                    help="instead of --kinds, 'dropped' with exactly these runs of source frames left out, "
                         "one sequence per run (e.g. 5:3 10:4: a run before a stroke reversal passes unseen)")
    ap.add_argument("--csv", default=None, help="one row per sequence (default: none written)")
    args = ap.parse_args(argv)
    try:
        runs = [tuple(int(v) for v in r.split(":")) for r in args.dropped_runs]
        if any(len(r) != 2 for r in runs):
            raise ValueError
    except ValueError:
        ap.error(f"--dropped-runs takes START:LENGTH pairs of integers (e.g. 5:3), got {args.dropped_runs}")
    jobs = [("dropped", r) for r in runs] if runs else [(k, None) for k in args.kinds]
    logging.basicConfig(level=logging.ERROR)  # the tracker's per-sequence warnings (NaN picks) are expected
    try:
        realdots.render_realdots("cam1", seed=0, n_frames=2, size=64)
    except FileNotFoundError as exc:
        print(f"skipped: {exc}")
        return 0
    seeds = args.seed_list or (realdots.DEV_SEEDS if args.set == "dev" else realdots.TEST_SEEDS)
    print(versions())
    rows = []
    for seed in seeds:
        for cam in realdots.CAMERAS:
            base = realdots.render_realdots(cam, seed=seed, n_frames=args.frames + realdots.GLITCH_SPARE)
            for kind, run in jobs:
                r = run_one(base, kind, seed, args.frames, run)
                rows.append(r)
                if r["crash"]:
                    print(f"{r['kind']:9s} {cam} seed {seed:4d}: CRASH {r['crash']}", flush=True)
                else:
                    print(f"{r['kind']:9s} {cam} seed {seed:4d}: ok {r['ok_share']:.3f}  RMS {r['rms_px']:.3f}  "
                          f"worst {r['worst_px']:.2f}  confident errors {r['confident_errors']}  {r['glitch']}",
                          flush=True)
    df = pd.DataFrame(rows)
    if args.csv:
        df.to_csv(args.csv, index=False)
        print(f"table written to {args.csv}")
    ok = df[df["crash"] == ""]
    pooled = ok.groupby(["kind", "camera"], sort=False).agg(
        seqs=("seed", "size"), ok_share=("n_ok_visible", "sum"), n_visible=("n_visible", "sum"),
        worst_px=("worst_px", "max"), confident_errors=("confident_errors", "sum"),
        seqs_with_errors=("confident_errors", lambda c: int((c > 0).sum())))
    pooled["ok_share"] = pooled["ok_share"] / pooled["n_visible"]
    print(pooled.drop(columns="n_visible").to_string(float_format=lambda v: f"{v:.3f}"))
    n_conf, n_crash = int(ok["confident_errors"].sum()), int((df["crash"] != "").sum())
    print(f"confident errors (ok > 1 px): {n_conf} in {int((ok['confident_errors'] > 0).sum())} of {len(df)} "
          f"sequences; crashed runs: {n_crash}")
    return 1 if n_conf or n_crash else 0


if __name__ == "__main__":
    sys.exit(main())
