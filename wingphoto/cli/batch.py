"""``wingphoto batch``: run every trial of a manifest (here or on a Dask cluster) -> summary tables."""
from __future__ import annotations

import sys


def _workers(text):
    import argparse

    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"--workers must be a whole number >= 1, got {text!r}")
    return n


def add_parser(sub):
    b = sub.add_parser(
        "batch",
        help="run many trials from a TOML manifest -> per-trial folders and summary tables",
        description="Run every trial of a TOML manifest (docs/batch.md): calibrate (cached), check the "
        "sequences, track both views, triangulate and analyse, each trial into OUT/trials/ID/, then "
        "OUT/summary.csv (length statistics per condition over the trials), OUT/trials.csv and "
        "OUT/failures.csv. A failing trial does not stop the others. Re-running the same command "
        "skips finished trials and resumes interrupted ones.",
    )
    b.add_argument("manifest", help="the batch manifest (TOML), e.g. data-samples/batch.toml")
    b.add_argument("--out", required=True, help="output folder of the batch")
    b.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of a running Dask scheduler (tcp://host:8786); its workers must see the "
                   "data and --out at the same paths. Default: a local cluster")
    b.add_argument("--workers", type=_workers, default=None, metavar="N",
                   help="local workers: 1 runs the trials one after another in this process; default "
                   "one per CPU core")
    b.add_argument("--cache", default=None, help="calibration cache folder (default OUT/.cache/calibration)")
    b.add_argument("--no-progress", action="store_true", help="no progress bar")
    return b


def run(args):
    import logging

    from ..batch import run_batch

    if not getattr(args, "verbose", False) and not (args.workers == 1 and args.scheduler is None):
        # Dask logs every worker start and stop at INFO level (its import sets that level,
        # so quiet it after importing); -v shows them
        import distributed  # noqa: F401

        logging.getLogger("distributed").setLevel(logging.ERROR)
    if args.scheduler is not None and args.workers is not None:
        raise ValueError("give either --scheduler (an existing cluster) or --workers (a local one), not both")
    result = run_batch(args.manifest, out=args.out, scheduler=args.scheduler, workers=args.workers,
                       progress=not args.no_progress, cache=args.cache,
                       notify=lambda line: print(line, file=sys.stderr, flush=True))
    print(result.summary_text())
    return 0 if result.ok else 1
