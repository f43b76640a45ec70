"""Measure the tracker on sequences of the independent renderer (:mod:`wingphoto.synth.independent`).

``python benchmarks/track_independent.py [--set dev|test] [--kinds KIND ...] [--seeds N] [--frames N]
[--cameras left right] [--save DIR]``

For every kind (clean, hard, dropped, repeated, black, bumped, clean16), seed of the set and
camera, renders the sequence, tracks it with ``wingphoto.track_markers`` (default options,
frames in memory) from frame-0 picks of the visible points (the truth rounded to the
pixel) and scores it against the truth with :mod:`wingphoto.validation`. Prints one row
per kind and camera (pooled over seeds): share of visible point-frames ok, RMS / p95 /
worst error of ok points (px), confident errors (ok > 1 px), share of ok points within 3
sigma, median error / sigma, frames/s of tracking (wall clock; rendering not timed), and
the reasons of the visible non-ok point-frames. Then every confident error (sequence,
frame, point, error, reason of the frames around it). With ``--save DIR`` each
sequence's tracks and truth go to ``DIR/<kind>_<seed>_<camera>.csv.gz`` / ``.npz`` for
diagnosis. Exits 1 on any confident error or crash. Tune on ``--set dev``; report ``--set test``.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from collections import Counter

import numpy as np
import pandas as pd

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from track_sweep import versions  # noqa: E402  (one place for the versions line)


def track_one(seq):
    """Track one rendered sequence from its frame-0 picks; return tracks, frames/s and a crash message."""
    from wingphoto import track_markers

    t0 = time.perf_counter()
    try:
        tr = track_markers(seq.frames(), seq.picks(), camera=seq.camera, progress=False)
    except Exception as exc:  # a crash is a result
        empty = pd.DataFrame({"camera": [], "frame": [], "point": [], "x": [], "y": [], "status": []})
        return empty, np.nan, f"{type(exc).__name__}: {exc}"
    return tr, len(seq.images) / (time.perf_counter() - t0), None


def reasons_of_loss(tr, seq):
    """Counter of the ``status:reason`` of visible point-frames that are not ok."""
    if not len(tr):
        return Counter()
    t = tr.set_index(["frame", "point"])
    fr, pt = np.nonzero(seq.visible)
    sub = t.reindex(pd.MultiIndex.from_arrays([fr, pt]))
    bad = sub[sub["status"] != "ok"]
    reason = bad["reason"].fillna("") if "reason" in bad else pd.Series("", index=bad.index)
    return Counter((bad["status"].fillna("missing") + ":" + reason.astype(str)).tolist())


def sequence_notes(tr, seq, ok):
    """One line on a sequence's wing markers: ok share, lost while face-on, frames with none ok."""
    wing = seq.point_kind == "wing"
    vis = seq.visible & wing
    lost = np.zeros_like(vis)
    if len(tr):
        t = tr[tr["status"] == "lost"]
        lost[t["frame"].to_numpy(int), t["point"].to_numpy(int)] = True
    face_lost = int((lost & vis & (seq.view_angle < 45)).sum())
    none_ok = np.flatnonzero(vis.any(1) & ~(ok & vis).any(1))
    span = f"{none_ok.min()}-{none_ok.max()} ({none_ok.size} frames)" if none_ok.size else "none"
    return (f"wing ok {(ok & vis).sum() / max(vis.sum(), 1):.3f}, lost while face-on (< 45 deg) {face_lost}, "
            f"frames with no ok wing marker: {span}")


def confident_rows(tr, seq, err, ok, label):
    """One line per confident error: frame, point, its kind, error, the tracked and true positions."""
    out = []
    t = tr.set_index(["frame", "point"])
    for f, p in zip(*np.nonzero(ok & (err > 1.0))):
        r = t.loc[(f, p)]
        out.append(f"  {label} frame {f} point {p} ({seq.point_kind[p]}): {err[f, p]:.2f} px, "
                   f"at ({r['x']:.1f}, {r['y']:.1f}) truth ({seq.points[f, p, 0]:.1f}, {seq.points[f, p, 1]:.1f}), "
                   f"sigma {r.get('sigma', np.nan):.3f}, score {r.get('score', np.nan):.3f}")
    return out


_ANGLE_BINS = {"<45deg": (0, 45), "45-60": (45, 60), "60-70": (60, 70), "70-80": (70, 80), ">80": (80, 90)}


def ok_by_view_angle(cat):
    """Share of visible wing point-frames ok per bin of the angle between disk normal and view ray."""
    out = {}
    vis = cat["visible"].astype(bool) & np.isfinite(cat["angle"])
    for b, (lo, hi) in _ANGLE_BINS.items():
        sel = vis & (cat["angle"] >= lo) & (cat["angle"] < hi)
        out["n_" + b] = int(sel.sum())
        out["ok_" + b] = float(cat["ok"][sel].mean()) if sel.any() else np.nan
    return out


def main(argv=None):
    from wingphoto.synth import independent
    from wingphoto.validation import point_errors, summarize_errors

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", choices=("dev", "test"), default="dev")
    ap.add_argument("--kinds", nargs="*", default=list(independent.KINDS))
    ap.add_argument("--seeds", type=int, default=None, help="only the first N seeds of the set")
    ap.add_argument("--seed-list", type=int, nargs="*", default=None,
                    help="other DEV seeds instead of the set's (e.g. the extra DEV seeds 3-12; never TEST seeds)")
    ap.add_argument("--frames", type=int, default=100, help="frames per sequence (default 100, one wing beat)")
    ap.add_argument("--cameras", nargs="*", default=list(independent.CAMERAS))
    ap.add_argument("--save", default=None, help="directory for each sequence's tracks and truth")
    ap.add_argument("--csv", default=None, help="table (default benchmarks/track_independent_<set>.csv)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    bad = [k for k in args.kinds if k not in independent.KINDS]
    if bad:
        ap.error(f"unknown kinds {bad}; choose from {list(independent.KINDS)}")
    seeds = independent.DEV_SEEDS if args.set == "dev" else independent.TEST_SEEDS
    seeds = seeds[: args.seeds] if args.seeds else seeds
    if args.seed_list:
        if args.set != "dev" or set(args.seed_list) & set(independent.TEST_SEEDS):
            ap.error("--seed-list is for DEV seeds only (TEST seeds are only reported, with --set test)")
        seeds = tuple(args.seed_list)
    if args.save:
        os.makedirs(args.save, exist_ok=True)

    print(versions())
    print(f"independent renderer, seed set {args.set}: {list(seeds)}, {args.frames} frames, cameras {args.cameras}")
    print(f"{'kind':9s} {'cam':5s} {'seqs':>4s} {'ok':>6s} {'RMS':>6s} {'p95':>6s} {'worst':>6s} {'conf':>5s} "
          f"{'<=3sig':>6s} {'med e/s':>7s} {'fps':>6s}  non-ok visible point-frames by status:reason")
    rows, confident, crashes, notes = [], [], [], []
    warm = independent.render_independent(args.kinds[0], seed=seeds[0], camera=args.cameras[0], n_frames=4)
    track_one(warm)  # compile the kernels outside the timed runs
    for kind in args.kinds:
        for cam in args.cameras:
            pooled = {k: [] for k in ("error", "ok", "visible", "sigma", "angle")}
            rates, reasons = [], Counter()
            for seed in seeds:
                seq = independent.render_independent(kind, seed=seed, camera=cam, n_frames=args.frames)
                tr, fps, crash = track_one(seq)
                label = f"{kind} seed {seed} {cam}"
                if crash:
                    crashes.append(f"{label}: {crash}")
                    print(f"    CRASH {crashes[-1]}", flush=True)
                rates.append(fps)
                a = point_errors(tr, seq, cam)
                a["angle"] = np.where(seq.point_kind == "wing", seq.view_angle, np.nan)
                for k in pooled:
                    pooled[k].append(a[k].ravel())
                reasons += reasons_of_loss(tr, seq)
                notes.append(f"  {label}: {sequence_notes(tr, seq, a['ok'])}; glitch {seq.glitch}")
                confident += confident_rows(tr, seq, a["error"], a["ok"], label)
                if args.save:
                    base = os.path.join(args.save, f"{kind}_{seed}_{cam}")
                    tr.to_csv(base + ".csv.gz", index=False)
                    np.savez_compressed(base + ".npz", points=seq.points, visible=seq.visible,
                                        time_index=seq.time_index, point_kind=seq.point_kind,
                                        view_angle=seq.view_angle,
                                        glitch=repr(seq.glitch))
            cat = {k: np.concatenate(v) for k, v in pooled.items()}
            s = summarize_errors(cat["error"], cat["ok"], cat["visible"], cat["sigma"])
            s.update(kind=kind, camera=cam, n_sequences=len(seeds), set=args.set,
                     fps=float(np.nanmedian(rates)) if np.isfinite(rates).any() else np.nan,
                     crashes=int(np.isnan(rates).sum()),
                     non_ok=";".join(f"{k}={v}" for k, v in reasons.most_common()))
            rows.append(s)
            s.update(ok_by_view_angle(cat))
            top = ", ".join(f"{k} {v}" for k, v in reasons.most_common(4))
            print(f"{kind:9s} {cam:5s} {len(seeds):4d} {s['ok_share']:6.3f} {s['rms_px']:6.3f} {s['p95_px']:6.3f} "
                  f"{s['worst_px']:6.2f} {s['confident_errors']:5d} {s['within_3_sigma']:6.3f} "
                  f"{s['median_error_over_sigma']:7.2f} {s['fps']:6.0f}  {top}", flush=True)
            print("          wing ok share by view angle: " + ", ".join(
                f"{b} {s['ok_' + b]:.3f} (n={s['n_' + b]})" for b in _ANGLE_BINS), flush=True)

    out = args.csv or os.path.join(os.path.dirname(os.path.abspath(__file__)), f"track_independent_{args.set}.csv")
    pd.DataFrame(rows).to_csv(out, index=False)
    print(f"table written to {out}")
    n_conf = sum(r["confident_errors"] for r in rows)
    print(f"confident errors (ok > 1 px): {n_conf}; crashed runs: {len(crashes)}")
    print("per sequence:")
    for line in notes:
        print(line)
    for line in confident[:200]:
        print(line)
    if len(confident) > 200:
        print(f"  ... {len(confident) - 200} more")
    for c in crashes:
        print(f"  crash: {c}")
    return 1 if n_conf or crashes else 0


if __name__ == "__main__":
    sys.exit(main())
