"""Run every trial of a manifest, in this process or on a Dask cluster, and tabulate them.

:func:`run_batch` builds one small task graph per trial - calibrate (shared by trials with
the same calibration) -> check sequences -> track left | track right -> triangulate and
analyse - and runs it

* in this process, one stage after the other (``workers=1``), or
* on a ``dask.distributed`` cluster: a ``LocalCluster`` sized to the machine (the default),
  or an existing scheduler (``scheduler="tcp://host:8786"``; start it with dask-jobqueue on
  SLURM/PBS, dask-kubernetes, ``dask scheduler`` + ``dask worker`` ...: ``docs/batch.md``).

The tasks carry paths, never image data: each worker reads the frames it tracks from
storage all workers see. Every stage runs OpenCV single-threaded and writes files whose
bytes do not depend on where or in which order it ran, so the batch tables are identical
whichever engine produced them. The tables are written by the calling process from the
trial folders: ``OUT/summary.csv``, ``OUT/trials.csv``, ``OUT/failures.csv``.
"""
from __future__ import annotations

import json
import logging
import os
import shutil
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .manifest import Manifest, load_manifest
from .steps import TRIAL_FILE, TrialError, calibrate_shared, check_sequences, finish_trial, track_camera

__all__ = ["run_batch", "BatchResult", "summarize_batch", "SUMMARY_COLUMNS", "FAILURE_COLUMNS"]

log = logging.getLogger(__name__)

#: Statistics columns of ``summary.csv`` and ``trials.csv`` (after the label columns).
SUMMARY_COLUMNS = ("i", "j", "n_frames", "mean", "std", "min", "max", "nominal", "bias", "max_error",
                   "frames", "ok_share")
#: Columns of ``failures.csv``.
FAILURE_COLUMNS = ("trial", "stage", "error", "log")


@dataclass(frozen=True)
class BatchResult:
    """What a batch run produced.

    Attributes
    ----------
    out : pathlib.Path
        The output folder.
    summary : pandas.DataFrame
        ``summary.csv``: per condition (the manifest's ``group_by`` labels) and length pair,
        over the finished trials of the condition: n_trials, n_frames (frames with a finite
        length), mean, std (ddof 1), min, max (mm) [nominal, bias, max_error], frames (frames
        analysed) and ok_share (share of the tracked point-frames, both cameras, that are
        ``ok``). The thesis' Table 6 over many trials.
    trials : pandas.DataFrame
        ``trials.csv``: the same statistics per finished trial.
    failures : pandas.DataFrame
        ``failures.csv``: trial, stage, error, log (the trial's log file, relative to ``out``).
    done, skipped : tuple of str
        Trials run now, and trials found finished by an earlier run.
    engine : str
        ``"sequential"``, ``"local cluster (N workers)"`` or ``"scheduler ADDRESS"``.
    dashboard : str or None
        The Dask dashboard address while the batch ran.
    elapsed_s : float
        Wall time of the run.
    """

    out: Path
    summary: pd.DataFrame
    trials: pd.DataFrame
    failures: pd.DataFrame
    done: tuple = ()
    skipped: tuple = ()
    engine: str = "sequential"
    dashboard: str | None = None
    elapsed_s: float = 0.0
    records: dict = field(default_factory=dict, repr=False)

    @property
    def ok(self):
        """True when no trial failed."""
        return self.failures.empty

    def summary_text(self):
        """A few lines for a person: counts, failures, where the tables are."""
        lines = [f"batch in {self.out}: {len(self.done)} trial(s) run, {len(self.skipped)} already finished, "
                 f"{len(self.failures)} failed ({self.engine}, {self.elapsed_s:.1f} s)"]
        for r in self.failures.itertuples():
            lines.append(f"  FAILED {r.trial} at {r.stage}: {r.error} (log: {r.log})")
        lines.append(f"tables: {self.out / 'summary.csv'}, {self.out / 'trials.csv'}, {self.out / 'failures.csv'}")
        return "\n".join(lines)


# ----------------------------------------------------------------------------- tables
def _write_csv(df, path):
    from ..io import atomic_write

    with atomic_write(path, "w", newline="") as f:
        df.to_csv(f, index=False)


def _stats(values, nominal):
    v = values[np.isfinite(values)]
    n = int(v.size)
    row = {"n_frames": n,
           "mean": float(np.mean(v)) if n else np.nan,
           "std": float(np.std(v, ddof=1)) if n > 1 else np.nan,
           "min": float(np.min(v)) if n else np.nan,
           "max": float(np.max(v)) if n else np.nan,
           "nominal": np.nan, "bias": np.nan, "max_error": np.nan}
    if nominal is not None and np.isfinite(nominal):
        row["nominal"] = float(nominal)
        if n:
            row["bias"] = row["mean"] - nominal
            row["max_error"] = float(np.max(np.abs(v - nominal)))
    return row


def _nominal(trial, i, j):
    nominal = trial.settings().nominal_lengths or {}
    return nominal.get((i, j), nominal.get((j, i)))


def summarize_batch(manifest, out):
    """Build ``trials.csv`` and ``summary.csv`` from the finished trial folders.

    Parameters
    ----------
    manifest : Manifest or str or Path
    out : str or Path
        The batch output folder (trial folders in ``OUT/trials/``).

    Returns
    -------
    trials, summary : pandas.DataFrame
        See :class:`BatchResult`. Only trials finished with the manifest's current
        settings count; rows follow the manifest's order. Lengths of a condition are
        pooled over its trials' frames in manifest order.
    """
    m = manifest if isinstance(manifest, Manifest) else load_manifest(manifest)
    out = Path(out)
    label_cols = list(m.group_by)
    all_labels = list(dict.fromkeys(k for t in m.trials for k in t.labels))
    trial_rows, groups = [], {}
    for t in m.trials:
        folder = out / "trials" / t.id
        record = _finished(t, folder)
        if record is None:
            continue
        lengths = pd.read_csv(folder / "lengths.csv")
        labels = {k: t.labels.get(k, "") for k in all_labels}
        gkey = tuple(t.labels.get(k, "") for k in label_cols)
        g = groups.setdefault(gkey, {"trials": 0, "frames": 0, "ok": 0, "obs": 0, "pairs": {}})
        g["trials"] += 1
        g["frames"] += record["n_frames"]
        g["ok"] += record["n_ok"]
        g["obs"] += record["n_observations"]
        share = record["n_ok"] / record["n_observations"] if record["n_observations"] else np.nan
        base = {"trial": t.id, **labels}
        pairs = list(t.settings().length_pairs)
        for i, j in pairs:
            v = lengths.loc[(lengths["i"] == i) & (lengths["j"] == j), "length"].to_numpy(np.float64)
            nominal = _nominal(t, i, j)
            trial_rows.append({**base, "i": i, "j": j, **_stats(v, nominal),
                               "frames": record["n_frames"], "ok_share": share})
            p = g["pairs"].setdefault((i, j), {"values": [], "nominal": set()})
            p["values"].append(v)
            p["nominal"].add(nominal)
        if not pairs:
            trial_rows.append({**base, "i": None, "j": None, **_stats(np.empty(0), None),
                               "frames": record["n_frames"], "ok_share": share})
    summary_rows = []
    for gkey, g in groups.items():
        share = g["ok"] / g["obs"] if g["obs"] else np.nan
        base = dict(zip(label_cols, gkey))
        base["n_trials"] = g["trials"]
        if not g["pairs"]:
            summary_rows.append({**base, "i": None, "j": None, **_stats(np.empty(0), None),
                                 "frames": g["frames"], "ok_share": share})
        for (i, j), p in g["pairs"].items():
            nominal = p["nominal"].pop() if len(p["nominal"]) == 1 else None  # differing nominals: none
            summary_rows.append({**base, "i": i, "j": j, **_stats(np.concatenate(p["values"]), nominal),
                                 "frames": g["frames"], "ok_share": share})
    trial_cols = ["trial"] + all_labels + list(SUMMARY_COLUMNS)
    summary_cols = label_cols + ["n_trials"] + list(SUMMARY_COLUMNS)
    return _frame(trial_rows, trial_cols, ["trial"] + all_labels), _frame(summary_rows, summary_cols, label_cols)


def _frame(rows, cols, text_cols):
    df = pd.DataFrame(rows, columns=cols)
    for c in cols:
        if c in text_cols:
            df[c] = df[c].astype(object)
        elif c in ("i", "j", "n_frames", "frames", "n_trials"):
            df[c] = df[c].astype("Int64")
        else:
            df[c] = df[c].astype(np.float64)
    return df


def _finished(trial, folder):
    """The trial.json of a finished trial folder with the trial's current fingerprint, else None."""
    path = Path(folder) / TRIAL_FILE
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return record if record.get("fingerprint") == trial.fingerprint() else None


# ----------------------------------------------------------------------------- engines
def _sequential(plan, cache_dir, check_dir, bar):
    """Run the plan in this process; returns {trial id: record or TrialError}."""
    calibrations, checks, results = {}, {}, {}
    for t, work, final in plan:
        try:
            key = t.calibration.key()
            if key not in calibrations:
                try:
                    calibrations[key] = calibrate_shared(t.calibration, cache_dir)
                except TrialError as exc:
                    calibrations[key] = exc
            if isinstance(calibrations[key], TrialError):
                raise calibrations[key]
            pair = (t.left, t.right, key)
            if pair not in checks:
                try:
                    checks[pair] = check_sequences(t.left, t.right, check_dir, calibrations[key])
                except TrialError as exc:
                    checks[pair] = exc
            if isinstance(checks[pair], TrialError):
                raise checks[pair]
            check = checks[pair]
            left = track_camera(t, "left", work, check)
            right = track_camera(t, "right", work, check)
            results[t.id] = finish_trial(t, work, final, calibrations[key], left, right, check)
        except TrialError as exc:
            results[t.id] = exc
        bar.update(1)
    return results


def _dashboard(client):
    try:
        import bokeh  # noqa: F401  (the dashboard is only served with bokeh installed)
    except ImportError:
        return None
    try:
        return client.dashboard_link
    except Exception:  # no dashboard (e.g. dashboard_address=None)
        return None


def _distributed(plan, cache_dir, check_dir, bar, client):
    """Submit the plan to a Dask client; returns {trial id: record or TrialError}."""
    from dask.distributed import as_completed

    token = uuid.uuid4().hex[:8]
    calibrations, checks, finals, futures = {}, {}, {}, []
    for t, work, final in plan:
        key = t.calibration.key()
        if key not in calibrations:
            calibrations[key] = client.submit(calibrate_shared, t.calibration, str(cache_dir),
                                              key=f"calibrate-{key}-{token}", pure=False)
        name = f"{t.id}-{token}"
        pair = (t.left, t.right, key)
        if pair not in checks:
            checks[pair] = client.submit(check_sequences, t.left, t.right, str(check_dir), calibrations[key],
                                         key=f"check-{len(checks)}-{token}", pure=False)
        check = checks[pair]
        left = client.submit(track_camera, t, "left", str(work), check, key=f"track-left-{name}", pure=False)
        right = client.submit(track_camera, t, "right", str(work), check, key=f"track-right-{name}", pure=False)
        fut = client.submit(finish_trial, t, str(work), str(final), calibrations[key], left, right, check,
                            key=f"finish-{name}", pure=False)
        finals[fut.key] = t.id
        futures.append(fut)
    results = {}
    try:
        for fut in as_completed(futures):
            tid = finals[fut.key]
            if fut.status == "error":
                exc = fut.exception()
                if not isinstance(exc, TrialError):  # the cluster itself failed (a worker died ...)
                    exc = TrialError("dask", f"{type(exc).__name__}: {exc}")
                results[tid] = exc
            else:
                results[tid] = fut.result()
            bar.update(1)
            fut.release()
    except BaseException:
        client.cancel(futures + list(calibrations.values()) + list(checks.values()))
        raise
    return results


def run_batch(manifest, *, out, scheduler=None, workers=None, progress=True, cache=None, cluster_options=None,
              notify=None):
    """Run every trial of a manifest and write the batch tables.

    Parameters
    ----------
    manifest : str, Path or Manifest
        The TOML manifest (:func:`~wingphoto.batch.manifest.load_manifest`,
        ``docs/batch.md``).
    out : str or Path
        Output folder: ``trials/ID/`` per finished trial (``tracks.csv``, ``points3d.csv``,
        ``lengths.csv``, analysis tables, ``log.txt``, ``trial.json``), ``summary.csv``,
        ``trials.csv``, ``failures.csv``. Work in progress lives in ``.partial/`` and the
        calibration cache in ``.cache/`` until finished.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); its workers must see
        the manifest's paths and ``out`` at the same paths.
    workers : int, optional
        Without ``scheduler``: 1 runs in this process, one stage after another; more
        starts a local Dask cluster of that many single-threaded worker processes; None
        (default) sizes it to the machine (``os.cpu_count()``, at most two per trial).
    progress : bool
        A progress bar across trials (``tqdm.auto``).
    cache : str or Path, optional
        Calibration cache folder (default ``OUT/.cache/calibration``); calibrations are
        keyed by the content of their images, board and options, so a cache may be shared
        between batches.
    cluster_options : dict, optional
        Extra keyword arguments of ``dask.distributed.LocalCluster`` (e.g.
        ``{"processes": False}`` for threads in this process, ``{"dashboard_address":
        None}`` for no dashboard; default one worker process per worker, one thread each,
        dashboard on port 8787 or the next free one).
    notify : callable, optional
        Called with one line of text for a person when the engine starts (the engine, and
        the Dask dashboard address when one runs); default: logged at INFO level.

    Returns
    -------
    BatchResult

    Notes
    -----
    Re-running with the same ``out`` skips trials finished with the same settings (their
    ``trial.json`` fingerprint covers the manifest entry and the picks file) and resumes
    unfinished ones from what their stages left in ``.partial/ID/`` (per-camera tracks,
    tracker checkpoints). A failing trial is reported in ``failures.csv`` (its traceback in
    its ``log.txt``) and does not stop the others. Ctrl-C stops the batch; the next run
    resumes it.
    """
    from tqdm.auto import tqdm

    t0 = time.perf_counter()
    m = manifest if isinstance(manifest, Manifest) else load_manifest(manifest)
    if workers is not None and (isinstance(workers, bool) or int(workers) != workers or workers < 1):
        raise ValueError(f"workers must be a whole number >= 1, got {workers!r}")
    out = Path(out).expanduser().resolve()
    if out.exists() and not out.is_dir():
        raise ValueError(f"out {out} is a file; give a folder for the batch results")
    (out / "trials").mkdir(parents=True, exist_ok=True)
    partial = out / ".partial"
    partial.mkdir(exist_ok=True)
    cache_dir = Path(cache).expanduser().resolve() if cache is not None else out / ".cache" / "calibration"
    cache_dir.mkdir(parents=True, exist_ok=True)
    check_dir = out / ".cache" / "checks"  # logs of the shared sequence checks
    check_dir.mkdir(parents=True, exist_ok=True)

    plan, skipped = [], []
    for t in m.trials:
        final = out / "trials" / t.id
        if _finished(t, final) is not None:
            skipped.append(t.id)
            continue
        work = partial / t.id
        stamp = work / "fingerprint.txt"
        fp = t.fingerprint()
        if work.exists() and (not stamp.is_file() or stamp.read_text().strip() != fp):
            log.info("trial %s: discarding unfinished work of different settings in %s", t.id, work)
            shutil.rmtree(work)
        work.mkdir(exist_ok=True)
        if not stamp.is_file():
            stamp.write_text(fp + "\n")
        elif any(work.glob("tracks_*.csv")) or any(work.glob("checkpoint_*")):
            log.info("trial %s: resuming from %s", t.id, work)
        plan.append((t, work, final))
    if skipped:
        log.info("%d trial(s) already finished: %s", len(skipped), ", ".join(skipped))

    engine, dashboard, results = "sequential", None, {}

    def say(engine, dashboard, dask=True):
        line = f"{len(plan)} of {len(m.trials)} trial(s) to run ({engine})"
        if dashboard:
            line += f"; Dask dashboard: {dashboard}"
        elif dask:
            line += "; no Dask dashboard (it needs bokeh: pip install bokeh)"
        (notify or log.info)(line)

    bar = tqdm(total=len(m.trials), initial=len(skipped), desc="trials", unit="trial", disable=not progress)
    try:
        if not plan:
            pass
        elif scheduler is None and (workers == 1 or (workers is None and (os.cpu_count() or 1) == 1)):
            say(engine, None, dask=False)
            results = _sequential(plan, cache_dir, check_dir, bar)
        else:
            from dask.distributed import Client, LocalCluster

            if scheduler is not None:
                with Client(scheduler) as client:
                    engine = f"scheduler {scheduler}"
                    dashboard = _dashboard(client)
                    say(engine, dashboard)
                    results = _distributed(plan, cache_dir, check_dir, bar, client)
            else:
                n = int(workers) if workers is not None else max(1, min(os.cpu_count() or 1, 2 * len(plan)))
                options = {"n_workers": n, "threads_per_worker": 1, "processes": True,
                           "dashboard_address": ":8787"}  # Dask moves it to a free port when taken
                options.update(cluster_options or {})
                import dask

                # Dask sets MALLOC_TRIM_THRESHOLD_=65536 in its worker processes, which makes
                # glibc map and unmap every frame-sized array: the sequence check then costs
                # 3x the CPU (measured). Unset it for the workers started here.
                trim = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
                with dask.config.set(trim), LocalCluster(**options) as cluster, Client(cluster) as client:
                    engine = f"local cluster ({n} workers)"
                    dashboard = _dashboard(client)
                    say(engine, dashboard)
                    results = _distributed(plan, cache_dir, check_dir, bar, client)
    finally:
        bar.close()

    failures = []
    for t, work, final in plan:
        r = results.get(t.id)
        if isinstance(r, TrialError):
            logfile = Path(r.log) if r.log else work / "log.txt"
            if logfile.is_relative_to(out):
                logfile = logfile.relative_to(out).as_posix()
            failures.append({"trial": t.id, "stage": r.stage, "error": r.message, "log": str(logfile)})
    failures = pd.DataFrame(failures, columns=list(FAILURE_COLUMNS))
    trials, summary = summarize_batch(m, out)
    _write_csv(summary, out / "summary.csv")
    _write_csv(trials, out / "trials.csv")
    _write_csv(failures, out / "failures.csv")
    done = tuple(t.id for t, _, _ in plan if isinstance(results.get(t.id), dict))
    result = BatchResult(out=out, summary=summary, trials=trials, failures=failures, done=done,
                         skipped=tuple(skipped), engine=engine, dashboard=dashboard,
                         elapsed_s=round(time.perf_counter() - t0, 3),
                         records={k: v for k, v in results.items() if isinstance(v, dict)})
    log.info(result.summary_text())
    return result
