"""Files in and out: image sequences, Bouguet toolbox .mat files, tracks and points tables.

Three groups of functions, one per kind of file, one module each (``sequence``,
``bouguet``, ``tables``; ``atomic`` holds the one atomic writer every output goes through):

- **Image sequences** - :func:`read_sequence` opens a folder, a glob pattern, a
  multi-page TIFF or a list of files as a lazy :class:`Sequence` of grayscale frames
  (read on access, memory-mapped where the TIFF allows it, 8/16-bit kept as stored).
- **Bouguet toolbox** - :func:`load_bouguet_calib` / :func:`save_bouguet_calib` for a
  single camera's ``Calib_Results.mat``, :func:`load_bouguet_stereo` /
  :func:`save_bouguet_stereo` for ``Calib_Results_stereo.mat``, with the toolbox's own
  variable names so MATLAB users can move results back and forth.
- **Camera files** - ``.cine``, ``.mraw`` and video files open through the same
  :func:`read_sequence` (one module per format in :mod:`wingphoto.io.formats`).
- **Exchange** - :mod:`wingphoto.io.exchange`: DLTdv8 files, DLT coefficients, the
  thesis' MATLAB files and Parquet (``docs/formats.md``).
- **Tables** - :func:`write_tracks_csv` / :func:`read_tracks_csv` and
  :func:`write_points_csv` / :func:`read_points_csv` round-trip the tracks and 3D points
  DataFrames exactly (dtypes, NaN, empty tables); :func:`empty_tracks` and
  :func:`empty_points` give the empty tables with the right dtypes.

Outputs are written atomically (a temporary file in the same folder, then an atomic
rename), so an interrupted run never leaves a half-written result behind. Source images
are only ever opened read-only.

Conventions (pixel origin, frames, units, names): ``docs/conventions.md``.
"""
from .atomic import atomic_write, check_output_path, ensure_output_folder
from .bouguet import BouguetCalib, load_bouguet_calib, load_bouguet_stereo, save_bouguet_calib, save_bouguet_stereo
from .sequence import IMAGE_EXTENSIONS, Sequence, SequenceWarning, parse_numbering, read_sequence
from .exchange import (
    DLTFit,
    fit_dlt,
    read_dlt_coefficients,
    read_dltdv,
    read_parquet,
    read_thesis_mat,
    write_dlt_coefficients,
    write_dltdv,
    write_parquet,
    write_thesis_mat,
)
from .tables import (
    POINT_COLUMNS,
    TRACK_COLUMNS,
    empty_points,
    empty_tracks,
    find_samples,
    read_points_csv,
    read_tracks_csv,
    write_points_csv,
    write_tracks_csv,
)

__all__ = [
    "atomic_write",
    "check_output_path",
    "ensure_output_folder",
    "find_samples",
    # image sequences
    "IMAGE_EXTENSIONS",
    "Sequence",
    "read_sequence",
    "SequenceWarning",
    "parse_numbering",
    # exchange (DLTdv8, DLT coefficients, the thesis' .mat files, Parquet)
    "DLTFit",
    "fit_dlt",
    "write_dlt_coefficients",
    "read_dlt_coefficients",
    "write_dltdv",
    "read_dltdv",
    "write_thesis_mat",
    "read_thesis_mat",
    "write_parquet",
    "read_parquet",
    # Bouguet toolbox
    "BouguetCalib",
    "load_bouguet_calib",
    "save_bouguet_calib",
    "load_bouguet_stereo",
    "save_bouguet_stereo",
    # tables
    "TRACK_COLUMNS",
    "POINT_COLUMNS",
    "empty_tracks",
    "empty_points",
    "write_tracks_csv",
    "read_tracks_csv",
    "write_points_csv",
    "read_points_csv",
]
