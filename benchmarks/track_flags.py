"""Are the tracker's flags earned? Flags and losses by view angle, with the true error.

``python benchmarks/track_flags.py DIR [--good 0.3]``

Reads the sequences that ``benchmarks/track_independent.py --save DIR`` wrote (each
``<kind>_<seed>_<camera>.csv.gz`` with its ``.npz`` truth) and prints, for the visible
wing point-frames binned by the angle between the marker's disk normal and the view ray:
the share ok / flagged / lost, then per (bin, reason) of the flagged points their count,
median true error (px) and the share within ``--good`` px of the truth. A flag on points
that are mostly within ``--good`` px is a false flag (the tracker doubted a right point);
a flag on points a pixel or more off is earned. This is how the ok share of the
independent renderer is read: it falls with the view angle, and the question is whether
the flags there are caution or necessity.
"""
from __future__ import annotations

import argparse
import glob
import os

import numpy as np
import pandas as pd

BINS = [0, 45, 60, 70, 80, 90]


def load(base):
    """Visible wing point-frames of one saved sequence: status, reason, error, angle."""
    tr = pd.read_csv(base + ".csv.gz")
    z = np.load(base + ".npz")
    T, N = z["visible"].shape
    t = tr.set_index(["frame", "point"]).reindex(pd.MultiIndex.from_product([range(T), range(N)]))
    x, y = t["x"].to_numpy().reshape(T, N), t["y"].to_numpy().reshape(T, N)
    err = np.hypot(x - z["points"][..., 0], y - z["points"][..., 1])
    sel = z["visible"] & (z["point_kind"] == "wing")[None, :]
    return pd.DataFrame({
        "sequence": os.path.basename(base),
        "status": t["status"].fillna("missing").to_numpy().reshape(T, N)[sel],
        "reason": t["reason"].fillna("").to_numpy().reshape(T, N)[sel],
        "error": err[sel],
        "angle": z["view_angle"][sel],
    })


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder", help="a --save folder of benchmarks/track_independent.py")
    ap.add_argument("--good", type=float, default=0.3, help="px: a flagged point this close is a false flag")
    args = ap.parse_args(argv)
    bases = sorted(p[: -len(".csv.gz")] for p in glob.glob(os.path.join(args.folder, "*.csv.gz")))
    if not bases:
        ap.error(f"no saved sequences (*.csv.gz) in {args.folder}: run "
                 f"benchmarks/track_independent.py --save {args.folder} first")
    d = pd.concat([load(b) for b in bases], ignore_index=True)
    d["bin"] = pd.cut(d["angle"], BINS)
    print(f"{len(bases)} sequences, {len(d)} visible wing point-frames")
    print(d.groupby("bin", observed=False)["status"].value_counts(normalize=True).unstack().round(3).to_string())
    fl = d[d["status"] == "flagged"]
    g = fl.groupby(["bin", "reason"], observed=True)["error"]
    table = pd.DataFrame({"n": g.size(), "median_error_px": g.median(),
                          f"within_{args.good:g}px": g.apply(lambda e: float((e < args.good).mean()))})
    print(table[table["n"] >= 10].round(3).to_string())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
