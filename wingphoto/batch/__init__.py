"""Batch processing: many trials from one TOML manifest, in this process or on a Dask cluster.

* :func:`load_manifest` reads and checks the manifest (``docs/batch.md``);
* :func:`run_batch` runs every trial - calibrate (cached by content) -> check sequences
  -> track both views (checkpointed, one task per camera) -> triangulate -> analyse - and
  writes ``summary.csv`` (the thesis' Table 6 per condition over many trials),
  ``trials.csv`` and ``failures.csv``; a re-run skips finished trials and resumes
  unfinished ones;
* :func:`summarize_batch` rebuilds the tables from the trial folders.

The command line is ``wingphoto batch MANIFEST --out DIR [--scheduler ADDRESS] [--workers N]``.
"""
from .manifest import CalibrationSpec, Manifest, TrialSpec, load_manifest
from .run import FAILURE_COLUMNS, SUMMARY_COLUMNS, BatchResult, run_batch, summarize_batch
from .steps import TrialError

__all__ = [
    "load_manifest",
    "Manifest",
    "TrialSpec",
    "CalibrationSpec",
    "run_batch",
    "BatchResult",
    "summarize_batch",
    "TrialError",
    "SUMMARY_COLUMNS",
    "FAILURE_COLUMNS",
]
