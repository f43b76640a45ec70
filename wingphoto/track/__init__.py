"""Automatic marker tracking that flags instead of guessing.

:func:`track_markers` follows painted wing markers through a high-speed sequence and
returns the tidy tracks DataFrame of ``docs/conventions.md``; every point-frame is ``ok``,
``flagged`` (a best guess, with a ``reason``) or ``lost``. The design - each choice and
the failure it prevents - is described in ``docs/tracker.md``.

One stage per module:

========================  ==============================================================
``options``               :class:`TrackOptions`: every default and its validation
``inputs``                validated frames and picks
``predict``               motion model: prediction and its update
``match``                 windowed NCC (:func:`match_windows`), peak analysis
``refine``                sub-pixel centring (:func:`refine_centroids`)
``templates``             templates cut at the refined centre, blended, matched
``identity``              conflicts, neighbour consensus, vouching
``status``                statuses, reasons and the status rules
``reacquire``             re-acquisition of lost markers from their neighbours
``checkpoint``            save/resume a run
``tracker``               :class:`~wingphoto.track.tracker.Tracker`: ``step`` calls the stages
``driver``                :func:`track_markers`, :func:`retrack_from`
``stereo``                :func:`check_stereo`
``engine``                the numba/numpy switch (:func:`try_numba`)
========================  ==============================================================
"""
from __future__ import annotations

from ..corrections import apply_corrections, load_corrections, save_corrections
from ..video import write_tracking_video
from .driver import retrack_from, track_markers
from .engine import try_numba
from .match import match_windows
from .options import TrackOptions
from .refine import refine_centroids
from .results import TRACKER_COLUMNS
from .status import REASONS, STATUS
from .stereo import check_stereo

__all__ = [
    "track_markers",
    "match_windows",
    "refine_centroids",
    "check_stereo",
    "apply_corrections",
    "save_corrections",
    "load_corrections",
    "retrack_from",
    "write_tracking_video",
    "try_numba",
    "TrackOptions",
    "TRACKER_COLUMNS",
    "REASONS",
    "STATUS",
]
