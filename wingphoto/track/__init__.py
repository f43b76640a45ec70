"""Automatic marker tracking that flags instead of guessing.

:func:`track_markers` follows painted wing markers through a high-speed sequence and
returns the tidy tracks DataFrame of ``docs/conventions.md``; every point-frame is ``ok``,
``flagged`` (a best guess, with a ``reason``) or ``lost``. The design - each choice and
the failure it prevents - is described in ``docs/tracker.md``.

One stage per module (``docs/tracker.md``, *Code map*, says more of each; 25 modules):

========================  ==============================================================
``options``               :class:`TrackOptions`: the user's options, their defaults and validation
``inputs``                validated frames and picks
``predict``               motion model: prediction, search plan, update
``match``                 windowed NCC (:func:`match_windows`), peak analysis
``refine``                sub-pixel centring (:func:`refine_centroids`), per-point diagnostics
``background``            the background under a marker: plane, curvature, edge rule
``sigma``                 the one sigma formula (compiled and numpy twins)
``templates``             templates cut at the refined centre, blended, matched
``identity``              search, conflicts, neighbour consensus, vouching
``geometry``              nearest neighbours, affine maps, neighbour predictions
``hop``                   whether a marker's path changed blob while not ok
``status``                statuses, reasons and the ordered status rules
``glitch``                blank, repeated and dropped frames, camera bumps
``reacquire``             re-acquisition of lost markers from their neighbours
``relocate``              re-acquisition of a group lost at once, by its constellation
``audit``                 the check after tracking: ok points against their neighbours' map
``tracker``               :class:`~wingphoto.track.tracker.Tracker`: ``step`` calls the stages
``fastpath``              a steady frame's whole ``step`` in one compiled call
``checkpoint``            save/resume a run
``results``               the per-pass result arrays and the tracks table
``driver``                :func:`track_markers`: the passes over a sequence
``retrack``               :func:`retrack_from`: re-tracking from a corrected frame
``stereo``                :func:`check_stereo`
``engine``                the numba/numpy switch (:func:`try_numba`)
========================  ==============================================================

Each stage keeps its own constants beside the code that reads them; the user's options
and their defaults are in one place, :class:`TrackOptions`.
"""
from __future__ import annotations

from ..corrections import apply_corrections, load_corrections, save_corrections
from ..video import write_tracking_video
from .driver import track_markers
from .retrack import retrack_from
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
