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
from .triangulate import triangulate_tracks

log = logging.getLogger(__name__)

__all__ = [
    "calibrate_folders",
    "track_folder",
    "triangulate_files",
    "load_picks",
    "load_sample",
    "run_demo",
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
    """Read a saved picks file (the picker's JSON) as the table the trackers take.

    Parameters
    ----------
    path : str or Path
        Picks JSON written by :class:`wingphoto.widgets.state.PickerState` (``save``).
    camera : {"left", "right"}

    Returns
    -------
    pandas.DataFrame
        Columns point, x, y, half_w, half_h, half_size; one row per marker number.
    """
    from .widgets.state import PickerState

    state = PickerState.load(path)
    if camera not in state.cameras:
        raise ValueError(f"{path} has no picks for camera {camera!r} (it has {list(state.cameras)})")
    return state.to_frame(camera)


def track_folder(frames, picks, *, camera="left", out=None, checkpoint=None, progress=True, **options):
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

    Returns
    -------
    pandas.DataFrame
        The tracks table (``docs/conventions.md``).
    """
    from .track import track_markers

    seq = read_sequence(frames) if isinstance(frames, (str, Path)) else frames
    table = load_picks(picks, camera) if isinstance(picks, (str, Path)) else picks
    tracks = track_markers(seq, table, camera=camera, checkpoint=checkpoint, progress=progress, **options)
    if out is not None:
        write_tracks_csv(tracks, out)
    return tracks


def triangulate_files(calib, left, right, *, out=None):
    """Triangulate two tracks CSV files with a stereo calibration .mat.

    Returns
    -------
    pandas.DataFrame
        frame, point, X, Y, Z (mm, left camera frame), reproj_err (px).
    """
    rig, _ = load_bouguet_stereo(calib)
    points = triangulate_tracks(read_tracks_csv(left), read_tracks_csv(right), rig)
    if out is not None:
        write_points_csv(points, out)
    return points


def load_sample(data):
    """Read the manifest of a sample folder laid out like ``data-samples/``.

    Parameters
    ----------
    data : str or Path
        The sample folder; it must contain ``manifest.json``.

    Returns
    -------
    dict
        The manifest with every relative path resolved against ``data``.
    """
    data = Path(data)
    manifest = data / "manifest.json"
    if not manifest.is_file():
        raise FileNotFoundError(
            f"{manifest} not found: a sample folder needs a manifest.json like data-samples/ "
            "(regenerate data-samples with `python data-samples/make_samples.py`)"
        )
    m = json.loads(manifest.read_text())

    def resolve(node):
        if isinstance(node, dict):
            return {k: (str(data / v) if k.endswith(("_dir", "_file", "_glob")) and isinstance(v, str) else resolve(v))
                    for k, v in node.items()}
        return node

    return resolve(m)
