"""The whole job, stage by stage, on folders of files: what ``make demo`` and the CLI run.

Each function reads the user's files, calls one library stage and writes its result
atomically, so a batch can be re-run or resumed stage by stage:

* :func:`calibrate_folders` - checkerboard pairs -> ``Calib_Results_stereo.mat``;
* :func:`track_folder` - an image sequence and saved picks -> tracks CSV;
* :func:`triangulate_files` - a stereo .mat and two tracks CSV -> 3D points CSV;
* :func:`run_demo` - all of it on a sample folder laid out like ``data-samples/``.

Nothing here modifies the input images.
"""
from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from .io import (
    atomic_write,
    load_bouguet_stereo,
    read_sequence,
    read_tracks_csv,
    save_bouguet_stereo,
    write_points_csv,
    write_tracks_csv,
)
from .io.atomic import check_output_path, ensure_output_folder
from .triangulate import triangulate_tracks

log = logging.getLogger(__name__)

__all__ = [
    "calibrate_folders",
    "track_folder",
    "triangulate_files",
    "load_picks",
    "load_sample",
    "track_stereo",
    "run_demo",
    "analyse_points",
]


def calibrate_folders(left, right, pattern_size, square_size, *, out=None, progress=True, **options):
    """Stereo-calibrate from two folders (or globs) of checkerboard images.

    Parameters
    ----------
    left, right : str or Path
        Folders or glob patterns of the left and right calibration images; they are
        paired in natural-sort order and must be equally many.
    pattern_size : (int, int)
        Inner corners per row and per column, e.g. (9, 6).
    square_size : float
        Square side in mm.
    out : str or Path, optional
        Where to write the toolbox's ``Calib_Results_stereo.mat`` (with 3-sigma errors).
    **options
        Passed to :func:`wingphoto.calibrate.calibrate_stereo`.

    Returns
    -------
    StereoCalibration
    """
    from .calibrate import calibrate_stereo

    if out is not None:
        check_output_path(out)  # refuse a folder or FIFO before minutes of work, not after
    seq_l, seq_r = read_sequence(left), read_sequence(right)
    if len(seq_l) != len(seq_r):
        raise ValueError(
            f"{left} has {len(seq_l)} images but {right} has {len(seq_r)}: calibration images must come in "
            "synchronized left/right pairs; remove the unmatched files"
        )
    names = [Path(p).name for p in seq_l.paths] if len(seq_l.paths) == len(seq_l) else None
    result = calibrate_stereo(list(seq_l), list(seq_r), pattern_size, square_size, names=names,
                              progress=progress, **options)
    if out is not None:
        save_bouguet_stereo(result.rig, out, uncertainty=result.uncertainty)
    return result


def load_picks(path, camera):
    """Read one camera's picks from a picks file (JSON or CSV) as the tracker's table.

    Delegates to :func:`wingphoto.picks.load_picks` (formats: ``docs/picks.md``).

    Parameters
    ----------
    path : str or Path
        Picks JSON written by the picker (``wingphoto pick``, the widget) or a CSV with
        columns ``camera,point,frame,x,y[,half_w,half_h]``.
    camera : {"left", "right"}

    Returns
    -------
    pandas.DataFrame
        Columns point, frame, x, y, half_w, half_h, half_size; one row per picked marker.
    """
    from .picks import load_picks as _load_picks

    return _load_picks(path, camera)


def _stop_message(name, source, stop):
    return (f"{name} ({source or 'frames'}) has {'; '.join(stop)}: tracking them would give wrong "
            f"positions at the wrong times. Fix the sequence (see `wingphoto check`), or pass force=True "
            f"(--force) to track it anyway")


def _watched(frames, name, *, force):
    """Open ``frames`` for tracking, checked by :func:`wingphoto.check_sequence` on the same reads.

    Stray files stop the run here; the frames are checked as the tracker reads them (a
    :class:`~wingphoto.integrity.SequenceScan`), and a duplicated frame stops it when it
    is read - unless ``force``. Returns (the frames to track, the scan); after tracking,
    :func:`_finish_check` completes the scan.
    """
    from .integrity import SequenceScan

    seq = read_sequence(frames) if isinstance(frames, (str, Path)) else frames
    scan = SequenceScan(seq)
    strays = list(getattr(seq, "strays", []))
    if strays and not force:
        raise ValueError(_stop_message(name, scan.source,
                                       [f"stray file(s) {', '.join(Path(p).name for p in strays[:3])}"]))

    def on_duplicate(t):
        if not force:
            raise ValueError(_stop_message(name, scan.source, [f"duplicated frame(s) at index {t}"]))

    return scan.watch(seq, on_duplicate=on_duplicate), scan


def _finish_check(scan, name, *, force):
    """The scan's report (reading the frames the tracker did not read in order, if any):
    blank frames, jumps and gaps are logged; duplicates found only now stop unless forced."""
    report = scan.report()
    for line in report.problems():
        if not any(line.startswith(k) for k in ("stray", "duplic")) and "identical" not in line:
            log.warning("%s: %s", name, line)
    if len(report.duplicates) and not force:
        raise ValueError(_stop_message(name, report.source, [
            f"duplicated frame(s) at index {', '.join(str(int(i)) for i in report.duplicates[:8])}"]))
    return report


def _check_pick_frames(table, n_frames, source, camera):
    """Refuse picks made in a frame the sequence does not have (they would be applied elsewhere)."""
    if not isinstance(table, pd.DataFrame) or "frame" not in table.columns or not len(table):
        return
    f = pd.to_numeric(table["frame"], errors="coerce").to_numpy(float)
    bad = ~((f >= 0) & (f < n_frames))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        point, frame = table["point"].to_numpy()[k], table["frame"].to_numpy()[k]
        raise ValueError(
            f"{source}: {camera} point {point} was picked in frame {frame}, but the sequence has "
            f"frames 0..{n_frames - 1}; pick it in this sequence (or fix its frame number)"
        )


def track_folder(frames, picks, *, camera="left", out=None, checkpoint=None, progress=True, check=True,
                 force=False, **options):
    """Track the picked markers through one camera's sequence.

    Parameters
    ----------
    frames : str or Path or sequence
        Folder, glob or multi-page TIFF (read lazily), or frames already opened.
    picks : str or Path or DataFrame
        Saved picks file (:func:`load_picks`) or a picks table.
    camera : {"left", "right"}
    out : str or Path, optional
        Tracks CSV to write.
    checkpoint : str or Path, optional
        Checkpoint file; a rerun resumes from it with identical results.
    check : bool
        Run :func:`wingphoto.check_sequence` (default True) on the frames as the tracker
        reads them (each frame is read once; frames the tracker did not read in order -
        after a resume, or before a pick made in a later frame - are read for the check
        after tracking): stray files stop the run before tracking and a duplicated frame
        when it is read, unless ``force``; blank frames, jumps and gaps are logged.
    force : bool
        Track despite a failed check.

    Returns
    -------
    pandas.DataFrame
        The tracks table (``docs/conventions.md``).
    """
    from .track import track_markers

    for path in (out, checkpoint):
        if path is not None:
            check_output_path(path)  # refuse a folder or FIFO before tracking, not after
    name = f"{camera} sequence"
    if check:
        seq, scan = _watched(frames, name, force=force)
    else:
        seq = read_sequence(frames) if isinstance(frames, (str, Path)) else frames
    table = load_picks(picks, camera) if isinstance(picks, (str, Path)) else picks
    _check_pick_frames(table, len(seq), picks if isinstance(picks, (str, Path)) else "the picks table", camera)
    tracks = track_markers(seq, table, camera=camera, checkpoint=checkpoint, progress=progress, **options)
    if check:
        _finish_check(scan, name, force=force)
    if out is not None:
        write_tracks_csv(tracks, out)
    return tracks


def _stereo_stop(problems):
    return ("left and right sequences do not match: " + "; ".join(problems)
            + ". Fix the sequences (`wingphoto check LEFT --right RIGHT` shows the full report), "
            "or pass force=True (--force) to track them anyway")


def track_stereo(frames_left, frames_right, picks, rig, *, checkpoint_dir=None, progress=True, check=True,
                 force=False, **options):
    """Track both views, check them against each other, and triangulate.

    Parameters
    ----------
    frames_left, frames_right : str, Path or sequence
        The two synchronized sequences (folders, globs, multi-page TIFFs, or frames).
    picks : str, Path, PickerState or dict
        A saved picks file, a :class:`~wingphoto.widgets.state.PickerState`, or
        ``{"left": table, "right": table}`` of picks.
    rig : StereoRig
        The calibrated rig.
    checkpoint_dir : str or Path, optional
        Folder for per-camera checkpoints (``checkpoint_left.npz`` ...), so an interrupted
        run resumes.
    check : bool
        Run :func:`wingphoto.check_stereo_sequences` (default True): a left/right mismatch
        (frame counts, rates, time stamps, a frame offset, duplicated frames, gaps or stray
        files) stops with a message naming it, unless ``force``. Each view is checked on
        the frames as the tracker reads them (one read per frame): different frame counts
        and stray files stop the run before tracking, a duplicated frame when it is read,
        and the rest (a frame offset, rates, time stamps, gaps) once both views are tracked
        (with ``checkpoint_dir``, a rerun with ``force=True`` then resumes at once).
    force : bool
        Go on despite a failed check (the findings are logged).
    **options
        Passed to :func:`wingphoto.track.track_markers`.

    Returns
    -------
    tracks : pandas.DataFrame
        Both cameras, after :func:`wingphoto.track.check_stereo` (inconsistent pairs
        flagged with reason ``stereo``).
    points : pandas.DataFrame
        frame, point, X, Y, Z (mm, left camera frame), reproj_err (px), from the trusted
        observations.
    """
    from .track import check_stereo

    if isinstance(picks, (str, Path)):
        tables = {cam: load_picks(picks, cam) for cam in ("left", "right")}
    elif isinstance(picks, dict):
        tables = picks
    else:  # a PickerState
        tables = {cam: picks.to_frame(cam) for cam in ("left", "right")}
    views = {"left": frames_left, "right": frames_right}
    scans = {}
    if check:
        from .integrity import SequenceScan, check_stereo_sequences

        views = {cam: read_sequence(f) if isinstance(f, (str, Path)) else f for cam, f in views.items()}
        # what needs no frame read stops the run before tracking; the rest is checked on
        # the tracker's reads and judged once both views are tracked
        early = [] if len(views["left"]) == len(views["right"]) else [
            f"frame counts differ: left {len(views['left'])}, right {len(views['right'])}"]
        for cam, seq in views.items():
            strays = list(getattr(seq, "strays", []))
            if strays:
                early.append(f"{cam}: {len(strays)} stray file(s): {', '.join(Path(p).name for p in strays[:3])}")
        if early and not force:
            raise ValueError(_stereo_stop(early))
        for cam in views:
            scans[cam] = SequenceScan(views[cam])

            def on_duplicate(t, cam=cam):
                if not force:
                    raise ValueError(_stereo_stop([f"{cam}: duplicated frame(s) at index {t}"]))

            views[cam] = scans[cam].watch(views[cam], on_duplicate=on_duplicate)
    tracks = {}
    for cam, frames in views.items():
        ckpt = None if checkpoint_dir is None else Path(checkpoint_dir) / f"checkpoint_{cam}.npz"
        tracks[cam] = track_folder(frames, tables[cam], camera=cam, checkpoint=ckpt, progress=progress,
                                   check=False, **options)
    if check:
        report = check_stereo_sequences(scans["left"].seq, scans["right"].seq, rig=rig,
                                        reports=(scans["left"].report(), scans["right"].report()))
        for note in report.notes:
            log.warning("%s", note)
        if not report.ok:
            if not force:
                raise ValueError(_stereo_stop(report.problems))
            for problem in report.problems:
                log.warning("forced past a failed sequence check: %s", problem)
    tl, tr = check_stereo(tracks["left"], tracks["right"], rig)
    points = triangulate_tracks(tl, tr, rig)
    return pd.concat([tl, tr], ignore_index=True), points


def triangulate_files(calib, left, right, *, out=None, force=False, uncertainty=False):
    """Triangulate two tracks CSV files with a stereo calibration .mat.

    Parameters
    ----------
    calib : str or Path
        ``Calib_Results_stereo.mat``.
    left, right : str or Path
        Tracks CSV of each camera (the same combined two-camera file may be given as both).
    out : str or Path, optional
        3D points CSV to write.
    force : bool
        Go on despite a failed reprojection check (see
        :func:`wingphoto.triangulate.triangulate_tracks`).
    uncertainty : bool
        Add each point's 1-sigma and 3D covariance (``sigma_X`` ..., ``cov_XX`` ...,
        tracking and calibration parts) from the tracks' ``sigma`` and the file's
        3-sigma errors; a toolbox .mat has no parameter correlations, so a diagonal
        covariance is used (and a warning logged).

    Returns
    -------
    pandas.DataFrame
        frame, point, X, Y, Z (mm, left camera frame), reproj_err (px).

    Raises
    ------
    ValueError
        The files do not belong together (see :func:`~wingphoto.triangulate.triangulate_tracks`);
        the message names the files.
    """
    if out is not None:
        check_output_path(out)
    rig, errors = load_bouguet_stereo(calib)
    tracks_left, tracks_right = read_tracks_csv(left), read_tracks_csv(right)
    try:
        points = triangulate_tracks(tracks_left, tracks_right, rig, force=force,
                                    calibration=(rig, errors) if uncertainty else None, full_covariance=uncertainty)
    except ValueError as exc:
        raise ValueError(f"{exc} [left {left}, right {right}, calibration {calib}]") from None
    if out is not None:
        write_points_csv(points, out)
    return points


def load_sample(data):
    """Check and describe a sample folder laid out like ``data-samples/``.

    Parameters
    ----------
    data : str or Path
        Folder with ``calibration/left``, ``calibration/right`` (checkerboard pairs),
        ``calibration/truth.npz`` (or ``board.json``) giving ``pattern_size`` and
        ``square_size``, and ``flapping/left``, ``flapping/right`` (frames) with
        ``flapping/picks.json``. ``rig.json`` and ``flapping/truth.npz`` (ground truth,
        optional) let the demo report its errors.

    Returns
    -------
    dict
        Paths (``calib_left``, ``calib_right``, ``seq_left``, ``seq_right``, ``picks``),
        ``pattern_size``, ``square_size`` and the optional truth (``rig``, ``truth``).
    """
    data = Path(data)
    need = {
        "calib_left": data / "calibration" / "left",
        "calib_right": data / "calibration" / "right",
        "seq_left": data / "flapping" / "left",
        "seq_right": data / "flapping" / "right",
        "picks": data / "flapping" / "picks.json",
    }
    missing = [str(p) for p in need.values() if not p.exists()]
    if missing:
        raise FileNotFoundError(
            f"{data} is not laid out like data-samples/: missing {', '.join(missing)} "
            "(regenerate the sample with `python data-samples/make_samples.py`)"
        )
    sample = dict(need)
    board_json = data / "calibration" / "board.json"
    truth_npz = data / "calibration" / "truth.npz"
    if board_json.is_file():
        board = json.loads(board_json.read_text())
    elif truth_npz.is_file():
        with np.load(truth_npz) as t:
            board = {"pattern_size": t["pattern_size"].tolist(), "square_size": float(t["square_size"])}
    else:
        raise FileNotFoundError(f"{board_json} not found: it must give pattern_size and square_size of the board")
    sample["pattern_size"] = tuple(int(v) for v in board["pattern_size"])
    sample["square_size"] = float(board["square_size"])
    sample["rig"] = None
    sample["truth"] = None
    if (data / "rig.json").is_file():
        from .synth import rig_from_dict

        sample["rig"] = rig_from_dict(json.loads((data / "rig.json").read_text()))
    if (data / "flapping" / "truth.npz").is_file():
        with np.load(data / "flapping" / "truth.npz") as t:
            sample["truth"] = {k: t[k] for k in t.files}
    return sample


def _save_figure(fig, path):
    import matplotlib.pyplot as plt

    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)


def run_demo(data="data-samples", *, out="results", video=True, progress=True):
    """Run the whole pipeline on a sample folder and write ``out/``.

    Stereo calibration -> tracking (both views, saved picks) -> stereo consistency check
    -> triangulation -> analysis (reference stillness, mount-marker length statistics,
    stroke angle and reversals) -> figures and a verification video. When the sample
    carries ground truth (``data-samples`` does) the errors against it are reported.

    Parameters
    ----------
    data : str or Path
        Sample folder (see :func:`load_sample`).
    out : str or Path
        Output folder, created if needed; files in it are replaced atomically.
    video : bool
        Write ``tracking_left.mp4`` (or ``.avi``).

    Returns
    -------
    str
        A short human-readable summary (also written to ``out/summary.txt``).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from . import plots, plots3d
    from .analysis import align_rigid, find_reversals, length_statistics, reference_stillness, stroke_angle
    sample = load_sample(data)
    out = ensure_output_folder(out)
    lines = []

    # 1. stereo calibration
    calib = calibrate_folders(sample["calib_left"], sample["calib_right"], sample["pattern_size"],
                              sample["square_size"], out=out / "Calib_Results_stereo.mat", progress=progress)
    with atomic_write(out / "calibration_summary.txt", "w") as f:
        f.write(calib.summary() + "\n")
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    plots.plot_residuals(calib, camera="left", ax=axes[0])
    plots.plot_residuals(calib, camera="right", ax=axes[1])
    _save_figure(fig, out / "calibration_residuals.png")
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    plots.plot_view_errors(calib, camera="left", ax=axes[0])
    plots.plot_view_errors(calib, camera="right", ax=axes[1])
    _save_figure(fig, out / "calibration_view_errors.png")
    px = np.ravel(calib.pixel_error)
    lines.append(f"calibration: {int(np.sum(calib.used))} of {len(calib.used)} pairs used, "
                 f"pixel error {np.array2string(px, precision=4)} px, baseline {calib.rig.baseline:.2f} mm")
    if sample["rig"] is not None:
        cmp_ = calib.compare(sample["rig"])
        with atomic_write(out / "calibration_vs_truth.csv", "w", newline="") as f:
            cmp_.to_csv(f, index=False)
        lines.append(f"  vs truth: {int(cmp_['inside_3sigma'].sum())}/{len(cmp_)} parameters inside their 3-sigma; "
                     f"|T error| = {np.linalg.norm(calib.rig.T - sample['rig'].T):.3f} mm")

    # 2. tracking, both views, from the saved picks; 3. triangulation
    all_tracks, points = track_stereo(sample["seq_left"], sample["seq_right"], sample["picks"], calib.rig,
                                      checkpoint_dir=out / ".checkpoints", progress=progress)
    tl = all_tracks[all_tracks["camera"] == "left"]
    write_tracks_csv(all_tracks, out / "tracks.csv")
    counts = all_tracks["status"].value_counts()
    lines.append("tracking: " + ", ".join(f"{k} {v}" for k, v in counts.items())
                 + f" of {len(all_tracks)} point-frames")
    truth = sample["truth"]
    if truth is not None:
        for cam, t in all_tracks.groupby("camera"):
            true_xy = truth[f"points_{cam}"][t["frame"].to_numpy(), t["point"].to_numpy()]
            err = np.hypot(t["x"].to_numpy() - true_xy[:, 0], t["y"].to_numpy() - true_xy[:, 1])
            ok = (t["status"] == "ok").to_numpy()
            lines.append(f"  {cam} vs truth: RMS {np.sqrt(np.nanmean(err[ok] ** 2)):.3f} px over ok points, "
                         f"max {np.nanmax(err[ok]):.3f} px, ok points > 1 px from truth: {int(np.sum(err[ok] > 1))}")

    write_points_csv(points, out / "points3d.csv")
    lines.append(f"triangulation: {int(points['X'].notna().sum())} of {len(points)} point-frames, "
                 f"median reprojection error {points['reproj_err'].median():.3f} px")
    if truth is not None:
        true3 = truth["points3d"][points["frame"].to_numpy(), points["point"].to_numpy()]
        d = np.linalg.norm(points[["X", "Y", "Z"]].to_numpy() - true3, axis=1)
        _, _, rms_shape = align_rigid(points[["X", "Y", "Z"]].to_numpy(), true3)
        lines.append(f"  vs truth: RMS 3D error {np.sqrt(np.nanmean(d ** 2)):.3f} mm (max {np.nanmax(d):.3f} mm); "
                     f"after removing the best rigid offset of the whole scene {rms_shape:.3f} mm")

    # 4. analysis: marker roles from the sample's truth kinds when present, else the
    # data-samples numbering (18 wing, 2 mount, 6 reference)
    if truth is not None and "kinds" in truth:
        kinds = np.asarray(truth["kinds"]).astype(str)
    else:
        kinds = np.array(["wing"] * 18 + ["mount"] * 2 + ["reference"] * 6)
    wing = np.flatnonzero(kinds == "wing")
    mount = np.flatnonzero(kinds == "mount")
    refs = np.flatnonzero(kinds == "reference")
    still = reference_stillness(points, refs.tolist())
    with atomic_write(out / "reference_stillness.csv", "w", newline="") as f:
        still.table.to_csv(f, index=False)
    lines.append(f"reference stillness: max displacement {float(np.nanmax(still.table['max_displacement'])):.3f} mm "
                 f"-> test {'valid' if still.valid else 'INVALID (references moved)'}")
    pairs = [(int(mount[0]), int(mount[1]))] + [(int(refs[k]), int(refs[k + 1])) for k in range(len(refs) - 1)]
    nominal = None
    if truth is not None:
        P = truth["points3d"][0]
        nominal = {p: float(np.linalg.norm(P[p[0]] - P[p[1]])) for p in pairs}
    stats = length_statistics(points, pairs)
    if nominal is not None:
        stats["nominal"] = [nominal[(int(i), int(j))] for i, j in zip(stats["i"], stats["j"])]
        stats["max_error"] = np.maximum(np.abs(stats["max"] - stats["nominal"]), np.abs(stats["min"] - stats["nominal"]))
    with atomic_write(out / "length_statistics.csv", "w", newline="") as f:
        stats.to_csv(f, index=False)
    lines.append("rigid lengths (mm): " + "; ".join(
        f"{int(r.i)}-{int(r.j)} mean {r.mean:.3f} std {r.std:.3f}" for r in stats.itertuples()))
    le = wing[::3]  # leading-edge markers, tip to root (3 per spanwise station)
    angle = stroke_angle(points, le.tolist())
    rev = find_reversals(angle.angle_deg)
    lines.append(f"stroke angle: {np.nanmin(angle.angle_deg):.1f} to {np.nanmax(angle.angle_deg):.1f} deg; "
                 f"reversals at frames {', '.join(f'{f:.2f}' for f in rev['frame'])}")
    with atomic_write(out / "stroke_angle.csv", "w", newline="") as f:
        pd.DataFrame({"frame": np.arange(len(angle.angle_deg)), "stroke_angle_deg": angle.angle_deg}).to_csv(f, index=False)

    # 5. figures
    frames_3d = [0, len(angle.angle_deg) // 2, len(angle.angle_deg) - 1]
    fig = plt.figure(figsize=(6, 5))
    ax = fig.add_subplot(projection="3d")
    plots3d.plot_points_3d(points, frames=frames_3d, ax=ax, point_ids=wing.tolist())
    _save_figure(fig, out / "points3d.png")
    fig, ax = plt.subplots(figsize=(6, 4))
    plots3d.plot_length_statistics(stats, ax=ax)
    _save_figure(fig, out / "length_statistics.png")
    fig, ax = plt.subplots(figsize=(7, 4))
    plots3d.plot_stroke_angle(angle, rev, ax=ax)
    _save_figure(fig, out / "stroke_angle.png")
    fig, ax = plt.subplots(figsize=(6, 4))
    plots3d.plot_reference_stillness(still, ax=ax)
    _save_figure(fig, out / "reference_stillness.png")

    # 6. verification video
    if video:
        from .video import write_tracking_video

        path = write_tracking_video(read_sequence(sample["seq_left"]), tl, out / "tracking_left.mp4", progress=progress)
        lines.append(f"video: {path}")
    shutil.rmtree(out / ".checkpoints", ignore_errors=True)  # the run finished: nothing to resume
    summary = "wingphoto demo on " + str(data) + "\n" + "\n".join(lines) + f"\nresults in {out}/"
    with atomic_write(out / "summary.txt", "w") as f:
        f.write(summary + "\n")
    return summary


def _write_table(df, path):
    with atomic_write(path, "w", newline="") as f:
        df.to_csv(f, index=False)


def analyse_points(points, settings, *, out=None, tracks=None):
    """Analyse a 3D points table with the user's marker roles: every table and figure.

    Parameters
    ----------
    points : pandas.DataFrame or str or Path
        3D points (frame, point, X, Y, Z mm[, sigma/covariance columns]) or their CSV.
    settings : AnalysisSettings, mapping, or str / Path
        Marker roles and options (:class:`wingphoto.config.AnalysisSettings`; a mapping
        is its ``[analysis]`` table; a path a TOML file with that table).
    out : str or Path, optional
        Folder for ``<table>.csv``, figures (``.png``), the wing-surface meshes
        (``surface/wing.vtu.series``) and the settings used (``analysis.toml``).
    tracks : pandas.DataFrame, optional
        The tracks the points came from: adds a ``tracking`` table (point-frames per
        camera and status).

    Returns
    -------
    dict of str -> pandas.DataFrame
        Only what the settings allow: ``reference_stillness`` (reference_ids),
        ``length_statistics`` (length_pairs; nominal columns where known; expected_std
        with point uncertainties), ``kinematics`` and ``reversals`` (leading_edge;
        with ``fps`` also ``time_s``),
        ``phase_average`` (when the stroke shows two reversals), ``surface_residuals``
        (trailing_edge at >= 2 stations), ``tracking`` (tracks).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from . import plots3d
    from .analysis import length_statistics, reference_stillness
    from .config import AnalysisSettings, load_analysis_settings
    from .io import read_points_csv
    from .kinematics import (
        fit_wing_surface,
        kinematic_reversals,
        phase_average,
        plot_kinematics,
        resample_phase,
        stroke_phase,
        wing_kinematics,
    )

    if isinstance(settings, (str, Path)):
        settings = load_analysis_settings(settings)
    elif not isinstance(settings, AnalysisSettings):
        settings = AnalysisSettings.from_dict(settings)
    if isinstance(points, (str, Path)):
        points = read_points_csv(points)
    out = None if out is None else Path(out)
    if out is not None:
        ensure_output_folder(out)
        with atomic_write(out / "analysis.toml", "w") as f:
            f.write(settings.to_toml())
    s = settings
    tables = {}
    figures = []
    if s.reference_ids:
        still = reference_stillness(points, list(s.reference_ids), tol_mm=s.reference_tol_mm)
        tables["reference_stillness"] = still.table
        fig, ax = plt.subplots(figsize=(6, 4))
        plots3d.plot_reference_stillness(still, ax=ax)
        figures.append((fig, "reference_stillness.png"))
    if s.length_pairs:
        stats = length_statistics(points, list(s.length_pairs))
        if s.nominal_lengths:
            nom = [s.nominal_lengths.get((int(i), int(j)), np.nan) for i, j in zip(stats["i"], stats["j"])]
            stats["nominal"] = nom
            stats["bias"] = stats["mean"] - stats["nominal"]
            stats["max_error"] = np.maximum(np.abs(stats["max"] - stats["nominal"]),
                                            np.abs(stats["min"] - stats["nominal"]))
        tables["length_statistics"] = stats
        fig, ax = plt.subplots(figsize=(6, 4))
        plots3d.plot_length_statistics(stats, ax=ax)
        figures.append((fig, "length_statistics.png"))
    if s.leading_edge:
        kin = wing_kinematics(points, leading_edge=s.leading_edge, trailing_edge=s.trailing_edge or None,
                              chord_rows=s.chord_rows, root=s.root, hinge=s.hinge, stroke_plane=s.stroke_plane)
        tables["reversals"] = kinematic_reversals(kin)
        if s.fps is not None:  # times in seconds beside the frame numbers
            kin = kin.assign(time_s=kin["frame"] / s.fps)
            tables["reversals"]["time_s"] = tables["reversals"]["frame"] / s.fps
        tables["kinematics"] = kin
        stroke = kin[kin["quantity"] == "stroke"]
        try:
            phase = stroke_phase(stroke["value"].to_numpy(), stroke["frame"].to_numpy())
        except ValueError as exc:
            log.info("no phase average: %s", exc)
            phase = None
        if phase is not None:
            parts = []
            for (q, st), g in kin.groupby(["quantity", kin["station"].fillna(-1.0)], sort=False):
                r = resample_phase(g["value"].to_numpy(), phase, bins=s.phase_bins, method=s.interpolation,
                                   tension=s.cardinal_tension, frames=g["frame"].to_numpy())
                parts.append(r.assign(quantity=q, station=np.nan if st == -1.0 else st))
            tables["phase_average"] = phase_average(pd.concat(parts, ignore_index=True), by=["quantity", "station"])
        axes = plot_kinematics(kin)
        figures.append((axes[0].figure, "kinematics.png"))
        if len(s.trailing_edge) >= 2:
            surf = fit_wing_surface(points, leading_edge=s.leading_edge, trailing_edge=s.trailing_edge,
                                    chord_rows=s.chord_rows, root=s.root, hinge=s.hinge, model=s.surface_model,
                                    mesh_shape=s.mesh_shape)
            tables["surface_residuals"] = surf.residuals
            if out is not None and np.isfinite(surf.vertices).all(axis=(1, 2)).any():
                surf.write(out / "surface", fmt="vtu", name="wing")
    if tracks is not None:
        key = ["camera", "status"] if "camera" in tracks.columns else ["status"]
        tables["tracking"] = tracks.groupby(key).size().rename("point_frames").reset_index()
    if out is not None:
        for name, df in tables.items():
            _write_table(df, out / f"{name}.csv")
        for fig, name in figures:
            _save_figure(fig, out / name)
    else:
        for fig, _ in figures:
            plt.close(fig)
    return tables
