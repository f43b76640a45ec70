"""Regenerate this folder from wingphoto.synth (deterministic: the same files every time).

Run from the repository root:

    .venv/bin/python data-samples/make_samples.py

(equivalently ``python -m wingphoto.synth data-samples``). Takes about 10 s.
"""
import logging
import sys
from pathlib import Path

from wingphoto.synth import write_samples

if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent
    files = write_samples(out, progress=True)
    total = sum(f.stat().st_size for f in files) / 1e6
    logging.getLogger("make_samples").info("%d files, %.1f MB in %s", len(files), total, out)
