"""Pure state of the marker picker and the tracking review, in image pixels.

This module imports neither ipywidgets nor matplotlib: every user action is a
*transition* on a frozen dataclass that returns a new state, so the logic is tested on
its own and the views (:mod:`wingphoto.widgets.picker`, :mod:`wingphoto.widgets.review`)
only convert display coordinates, route events and re-render.

Conventions (``docs/conventions.md``): pixel (x, y), x right, y down, (0, 0) the centre of
the top-left pixel, so an image of width W spans x in [-0.5, W - 0.5]. Markers are numbered
from 0, leading edge to trailing edge and tip to root, with the same number in both views;
point number ``k`` is row ``k`` of :meth:`PickerState.to_picks`.
"""
from __future__ import annotations

import dataclasses
import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from ..io import atomic_write
from ..picks import SAME_SPOT_PX, picks_document, read_picks, read_picks_document

__all__ = [
    "Pick",
    "PickerState",
    "Correction",
    "ReviewState",
    "Viewport",
    "apply_corrections",
    "replay_corrections",
    "read_corrections",
    "write_corrections",
]

CAMERAS = ("left", "right")
MAX_UNDO = 200
#: smallest half size (px) a new marker's box is shrunk to so that it does not overlap a neighbour's
MIN_AUTO_HALF = 3.0
CORRECTIONS_FORMAT = "wingphoto-corrections"
PROBLEM_STATUS = ("flagged", "lost")
TRACK_COLUMNS = ("camera", "frame", "point", "x", "y", "score", "status")


# --------------------------------------------------------------------------- helpers
def _finite(value, name):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def _point_number(value, name="point"):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        if isinstance(value, (float, np.floating)) and float(value).is_integer():
            value = int(value)
        else:
            raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
    if value < 0:
        raise ValueError(f"{name} must be a non-negative integer (markers are numbered from 0), got {value}")
    return int(value)


def _image_size(value, name):
    if value is None:
        return None
    try:
        w, h = (int(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be (width, height) in pixels, got {value!r}") from None
    if w <= 0 or h <= 0:
        raise ValueError(f"{name} must be a positive (width, height), got {value!r}")
    return (w, h)


def _check_inside(x, y, size, what):
    """Raise ValueError when (x, y) lies outside an image of ``size`` = (width, height)."""
    x = _finite(x, "x")
    y = _finite(y, "y")
    if size is not None:
        w, h = size
        if not (-0.5 <= x <= w - 0.5 and -0.5 <= y <= h - 0.5):
            raise ValueError(
                f"point (x={x:.2f}, y={y:.2f}) is outside the {what} "
                f"(width {w}, height {h}: x must lie in [-0.5, {w - 0.5}] and y in [-0.5, {h - 0.5}], "
                "origin at the centre of the top-left pixel); click inside the image"
            )
    return x, y


def _check_free(picks, point, x, y, camera):
    """Raise ValueError when another marker of the view lies on (x, y) (the same spot)."""
    for p in picks:
        if p.point != point and math.hypot(p.x - x, p.y - y) < SAME_SPOT_PX:
            raise ValueError(
                f"point {p.point} is already at ({p.x:.1f}, {p.y:.1f}) in the {camera} view, less than "
                f"{SAME_SPOT_PX:g} px from this click; each marker is picked once (drag point {p.point} "
                "to move it, or Delete it)"
            )


def _push(state, **changes):
    """Return ``state`` with ``changes`` and the current state pushed on its undo history."""
    snapshot = dataclasses.replace(state, history=())
    history = (snapshot,) + state.history[: MAX_UNDO - 1]
    return dataclasses.replace(state, history=history, **changes)


# --------------------------------------------------------------------------- viewport
@dataclass(frozen=True)
class Viewport:
    """Zoom and pan between display coordinates and image pixels.

    The display is a canvas of the image's size, spanning ``[-0.5, width - 0.5]`` by
    ``[-0.5, height - 0.5]`` (the axes' data coordinates in the views). At ``zoom = 1``
    display and image coordinates coincide; at ``zoom = z`` the display shows the
    ``width / z`` by ``height / z`` pixels around the centre ``(cx, cy)``::

        x = cx + (u - (width - 1) / 2) / zoom,     y = cy + (v - (height - 1) / 2) / zoom

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    zoom : float
        Magnification, at least 1.
    cx, cy : float, optional
        Image pixel shown at the centre of the display; default the image centre. It is
        clamped so that the display never shows outside the image.

    Examples
    --------
    >>> vp = Viewport(512, 256, zoom=4.0, cx=100.0, cy=50.0)
    >>> vp.to_image(255.5, 127.5)
    (100.0, 50.0)
    >>> vp.to_display(*vp.to_image(10.0, 20.0))
    (10.0, 20.0)
    """

    width: int
    height: int
    zoom: float = 1.0
    cx: float | None = None
    cy: float | None = None

    def __post_init__(self):
        w, h = _image_size((self.width, self.height), "(width, height)")
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "height", h)
        zoom = _finite(self.zoom, "zoom")
        if zoom < 1.0:
            raise ValueError(f"zoom must be at least 1 (1 shows the whole image), got {zoom}")
        object.__setattr__(self, "zoom", zoom)
        cx = (w - 1) / 2 if self.cx is None else _finite(self.cx, "cx")
        cy = (h - 1) / 2 if self.cy is None else _finite(self.cy, "cy")
        hx, hy = w / (2 * zoom), h / (2 * zoom)
        object.__setattr__(self, "cx", float(np.clip(cx, -0.5 + hx, w - 0.5 - hx)))
        object.__setattr__(self, "cy", float(np.clip(cy, -0.5 + hy, h - 0.5 - hy)))

    @property
    def _centre(self):
        return (self.width - 1) / 2, (self.height - 1) / 2

    def to_image(self, u, v):
        """Convert display coordinates (u, v) to image pixels (x, y) (scalars or arrays)."""
        uc, vc = self._centre
        return self.cx + (u - uc) / self.zoom, self.cy + (v - vc) / self.zoom

    def to_display(self, x, y):
        """Convert image pixels (x, y) to display coordinates (u, v) (scalars or arrays)."""
        uc, vc = self._centre
        return uc + (x - self.cx) * self.zoom, vc + (y - self.cy) * self.zoom

    @property
    def extent(self):
        """Display extent of the whole image, ``(left, right, bottom, top)`` for ``imshow``."""
        left, top = self.to_display(-0.5, -0.5)
        right, bottom = self.to_display(self.width - 0.5, self.height - 0.5)
        return (left, right, bottom, top)

    @property
    def limits(self):
        """Display axis limits ``((xmin, xmax), (ymax, ymin))`` (y down)."""
        return (-0.5, self.width - 0.5), (self.height - 0.5, -0.5)

    def zoomed(self, zoom, *, cx=None, cy=None):
        """Return the viewport at another zoom, centred on (cx, cy) or the same centre."""
        return Viewport(self.width, self.height, zoom, self.cx if cx is None else cx, self.cy if cy is None else cy)

    def centred(self, cx, cy):
        """Return the viewport centred on image pixel (cx, cy) (clamped to the image)."""
        return Viewport(self.width, self.height, self.zoom, cx, cy)


# --------------------------------------------------------------------------- picker
class Pick(NamedTuple):
    """One picked marker in one view: centre and half size of its subimage rectangle (px).

    ``frame`` is the frame the marker was picked in (default 0, where tracking starts).
    """

    point: int
    x: float
    y: float
    half_w: float
    half_h: float
    frame: int = 0


def _as_picks(value, camera):
    picks = []
    for p in value:
        p = Pick(*p) if not isinstance(p, Pick) else p
        point = _point_number(p.point, f"{camera} pick point")
        picks.append(
            Pick(point, _finite(p.x, "x"), _finite(p.y, "y"), _finite(p.half_w, "half_w"), _finite(p.half_h, "half_h"),
                 _point_number(p.frame, f"{camera} pick frame"))
        )
    numbers = [p.point for p in picks]
    if len(set(numbers)) != len(numbers):
        raise ValueError(f"{camera} picks repeat a point number: {sorted(numbers)}; each number appears once per view")
    return tuple(sorted(picks, key=lambda p: p.point))


@dataclass(frozen=True)
class PickerState:
    """Markers picked in the first frame of the left and right views.

    Every transition (:meth:`place`, :meth:`move`, :meth:`resize`, :meth:`delete`,
    :meth:`select`, :meth:`next_point`, :meth:`undo`) returns a new state; editing
    transitions keep the previous state in :attr:`history` so :meth:`undo` returns it.

    Parameters
    ----------
    image_size : (width, height) or None
        Size of the left image in pixels; clicks outside it raise ValueError. None skips
        the check.
    image_size_right : (width, height) or None
        Size of the right image when it differs from the left one.
    left, right : tuple of Pick
        Picks per view, sorted by point number. A pick is ``(point, x, y, half_w, half_h)``:
        marker centre in pixels and half width/height of the subimage (template)
        rectangle the tracker searches with.
    cameras : tuple of str
        Views being picked, ``("left", "right")`` or ``("left",)`` for a single camera.
    camera : str
        Active view (where clicks go).
    current : int
        Active marker number: the next click places this marker.
    n_points : int or None
        Number of markers expected (numbers 0 .. n_points - 1); None leaves it open.
    half_size : (half_w, half_h)
        Rectangle half size in pixels given to newly placed markers.
    frame : int
        Frame being picked in (default 0); :meth:`place` records it in each new pick.
    history : tuple of PickerState
        Previous states, newest first (at most 200); not saved to JSON, not compared.

    Notes
    -----
    Numbering (``docs/conventions.md``): markers are numbered from 0 leading edge to
    trailing edge and tip to root, with the same number in both views; the user picks in
    numbering order, so :meth:`place` puts the active number and advances to the next
    number missing in that view.

    Examples
    --------
    >>> s = PickerState(image_size=(64, 48), half_size=(5, 5))
    >>> s = s.place("left", 10, 12).place("left", 30, 20)
    >>> s = s.place("right", 12, 12).place("right", 33, 21)
    >>> s.to_picks("right").tolist()
    [[12.0, 12.0], [33.0, 21.0]]
    >>> s.is_complete
    True
    >>> s.undo().missing()
    {'left': [], 'right': [1]}
    """

    image_size: tuple | None = None
    image_size_right: tuple | None = None
    left: tuple = ()
    right: tuple = ()
    cameras: tuple = CAMERAS
    camera: str = "left"
    current: int = 0
    n_points: int | None = None
    half_size: tuple = (10.0, 10.0)
    frame: int = 0
    history: tuple = field(default=(), repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "image_size", _image_size(self.image_size, "image_size"))
        object.__setattr__(self, "image_size_right", _image_size(self.image_size_right, "image_size_right"))
        cams = tuple(self.cameras)
        if not cams or any(c not in CAMERAS for c in cams) or len(set(cams)) != len(cams):
            raise ValueError(f"cameras must be ('left', 'right') or ('left',), got {self.cameras!r}")
        object.__setattr__(self, "cameras", cams)
        self._check_camera(self.camera)
        if self.n_points is not None:
            n = _point_number(self.n_points, "n_points")
            if n == 0:
                raise ValueError("n_points must be positive (or None for an open number of markers)")
            object.__setattr__(self, "n_points", n)
        object.__setattr__(self, "current", self._check_number(self.current, "current"))
        hw, hh = (_finite(v, "half_size") for v in self.half_size)
        if hw <= 0 or hh <= 0:
            raise ValueError(f"half_size must be positive (half_w, half_h) in pixels, got {self.half_size!r}")
        object.__setattr__(self, "half_size", (hw, hh))
        object.__setattr__(self, "frame", _point_number(self.frame, "frame"))
        for cam in CAMERAS:
            picks = _as_picks(getattr(self, cam), cam)
            if picks and cam not in cams:
                raise ValueError(f"{cam} picks given but cameras is {cams}")
            for p in picks:
                self._check_number(p.point, f"{cam} pick point")
                _check_inside(p.x, p.y, self.size_of(cam), f"{cam} image")
                self._check_half(p.half_w, p.half_h)
                _check_free(picks, p.point, p.x, p.y, cam)
            object.__setattr__(self, cam, picks)
        object.__setattr__(self, "history", tuple(self.history))

    # ---------------------------------------------------------------- checks
    def _check_camera(self, camera):
        if camera not in self.cameras:
            raise ValueError(f"camera must be one of {self.cameras}, got {camera!r}")
        return camera

    def _check_number(self, point, name="point"):
        point = _point_number(point, name)
        if self.n_points is not None and point >= self.n_points:
            raise ValueError(f"{name} must be in 0..{self.n_points - 1} (n_points={self.n_points}), got {point}")
        return point

    @staticmethod
    def _check_half(half_w, half_h):
        half_w, half_h = _finite(half_w, "half_w"), _finite(half_h, "half_h")
        if half_w <= 0 or half_h <= 0:
            raise ValueError(f"half_w and half_h must be positive pixels, got ({half_w}, {half_h})")
        return half_w, half_h

    def size_of(self, camera):
        """Image size (width, height) of a view, or None when unknown."""
        self._check_camera(camera)
        if camera == "right" and self.image_size_right is not None:
            return self.image_size_right
        return self.image_size

    # ---------------------------------------------------------------- queries
    def picks_of(self, camera):
        """Tuple of :class:`Pick` of a view, sorted by point number."""
        return getattr(self, self._check_camera(camera))

    def get(self, camera, point):
        """The :class:`Pick` of ``point`` in ``camera``, or None when not placed."""
        for p in self.picks_of(camera):
            if p.point == point:
                return p
        return None

    def numbers(self, camera):
        """Sorted list of the point numbers placed in ``camera``."""
        return [p.point for p in self.picks_of(camera)]

    @property
    def n_rows(self):
        """Rows of :meth:`to_picks`: ``n_points``, else one more than the largest number."""
        if self.n_points is not None:
            return self.n_points
        numbers = [p.point for cam in self.cameras for p in self.picks_of(cam)]
        return max(numbers) + 1 if numbers else 0

    def missing(self):
        """Numbers missing per view: absent in that view but expected or present in another.

        Returns
        -------
        dict
            ``{camera: sorted list of point numbers}``.
        """
        expected = set(range(self.n_points)) if self.n_points is not None else set()
        for cam in self.cameras:
            expected |= set(self.numbers(cam))
        return {cam: sorted(expected - set(self.numbers(cam))) for cam in self.cameras}

    @property
    def is_complete(self):
        """True when every view holds the same, non-empty set of numbers (all ``n_points``)."""
        return self.n_rows > 0 and not any(self.missing().values())

    def check_complete(self):
        """Raise ValueError listing the missing numbers unless :attr:`is_complete`."""
        if self.n_rows == 0:
            raise ValueError("no markers picked yet; click the markers in numbering order")
        missing = {cam: nums for cam, nums in self.missing().items() if nums}
        if missing:
            text = "; ".join(f"{cam} view lacks {nums}" for cam, nums in missing.items())
            raise ValueError(f"picks are incomplete: {text}. Place the same numbers in both views")
        return self

    def next_missing(self, camera=None, after=None):
        """First number not placed in ``camera`` after ``after`` (wrapping), or None."""
        camera = self._check_camera(self.camera if camera is None else camera)
        placed = set(self.numbers(camera))
        after = self.current if after is None else after
        if self.n_points is not None:
            order = list(range(after + 1, self.n_points)) + list(range(0, after + 1))
            return next((k for k in order if k not in placed), None)
        k = after + 1
        while k in placed:
            k += 1
        return k

    def first_missing(self, camera):
        """Smallest number missing in ``camera`` (see :meth:`missing`), else the next free one."""
        missing = self.missing()[self._check_camera(camera)]
        if missing:
            return missing[0]
        nxt = self.next_missing(camera, after=-1)
        return self.current if nxt is None else nxt

    # ---------------------------------------------------------------- transitions
    def _with_pick(self, view, pick, **changes):
        picks = tuple(sorted([p for p in self.picks_of(view) if p.point != pick.point] + [pick], key=lambda p: p.point))
        return _push(self, **{view: picks}, **changes)

    def _require(self, camera, point):
        self._check_camera(camera)
        point = self._check_number(point)
        pick = self.get(camera, point)
        if pick is None:
            raise ValueError(
                f"point {point} is not placed in the {camera} view (placed: {self.numbers(camera)}); place it first"
            )
        return pick

    def _fit_boxes(self, camera, pick):
        """Picks of ``camera`` with ``pick`` added, default-sized boxes shrunk so none overlap.

        A new marker's box, and the boxes of neighbours that still have the default size
        (:attr:`half_size`), are shrunk to at most half the distance (along x or y, the
        larger) to the nearest other marker, but not below :data:`MIN_AUTO_HALF` px; boxes
        the user resized are kept.
        """
        others = [p for p in self.picks_of(camera) if p.point != pick.point]
        everyone = others + [pick]

        def fitted(p):
            if (p.half_w, p.half_h) != self.half_size and p is not pick:
                return p
            gaps = [max(abs(q.x - p.x), abs(q.y - p.y)) for q in everyone if q.point != p.point]
            if not gaps:
                return p
            limit = max(MIN_AUTO_HALF, math.floor(min(gaps)) / 2.0)
            return p._replace(half_w=min(p.half_w, limit), half_h=min(p.half_h, limit))

        return tuple(sorted((fitted(p) for p in everyone), key=lambda p: p.point))

    def place(self, camera, x, y, *, point=None):
        """Place marker ``point`` (default the active one) at (x, y) in ``camera``.

        Placing in a view other than the active one starts at that view's first missing
        number. A marker already placed there is moved (its rectangle size kept). A new
        marker gets the default :attr:`half_size` box, shrunk (with default-sized neighbours)
        so that boxes do not overlap (:meth:`_fit_boxes`). The active camera becomes
        ``camera`` and the active number advances to the next number missing in that view.

        Raises
        ------
        ValueError
            Unknown camera, bad number, (x, y) outside the image, or (x, y) on another
            marker of that view (less than ``SAME_SPOT_PX`` away).
        """
        self._check_camera(camera)
        if point is None:
            point = self.current if camera == self.camera else self.first_missing(camera)
        point = self._check_number(point)
        x, y = _check_inside(x, y, self.size_of(camera), f"{camera} image")
        _check_free(self.picks_of(camera), point, x, y, camera)
        old = self.get(camera, point)
        if old is not None:
            new = self._with_pick(camera, old._replace(x=x, y=y, frame=self.frame), camera=camera)
        else:
            picks = self._fit_boxes(camera, Pick(point, x, y, *self.half_size, self.frame))
            new = _push(self, **{camera: picks}, camera=camera)
        nxt = new.next_missing(camera, after=point)
        return dataclasses.replace(new, current=point if nxt is None else nxt)

    def move(self, camera, point, x, y):
        """Move placed marker ``point`` of ``camera`` to (x, y); ValueError if not placed."""
        pick = self._require(camera, point)
        x, y = _check_inside(x, y, self.size_of(camera), f"{camera} image")
        _check_free(self.picks_of(camera), point, x, y, camera)
        return self._with_pick(camera, pick._replace(x=x, y=y))

    def resize(self, camera, point, half_w, half_h):
        """Set the half width and height (px) of the rectangle of placed marker ``point``."""
        pick = self._require(camera, point)
        half_w, half_h = self._check_half(half_w, half_h)
        return self._with_pick(camera, pick._replace(half_w=half_w, half_h=half_h))

    def drag(self, camera, point, start, now, *, edges=None):
        """Drag marker ``point`` from image position ``start`` to ``now`` (px).

        ``edges=None`` moves the marker by the drag. ``edges=(x_edge, y_edge)`` drags its
        box's edge (or a corner, both True): each grabbed edge changes only its own
        half-size, by how much farther from the centre the mouse is than where the drag
        started (never below 1 px), so a box never collapses to a line.
        """
        pick = self._require(camera, point)
        (x0, y0), (x, y) = start, now
        if edges is None:
            return self.move(camera, point, pick.x + x - x0, pick.y + y - y0)
        x_edge, y_edge = edges
        half_w = max(pick.half_w + abs(x - pick.x) - abs(x0 - pick.x), 1.0) if x_edge else pick.half_w
        half_h = max(pick.half_h + abs(y - pick.y) - abs(y0 - pick.y), 1.0) if y_edge else pick.half_h
        return self.resize(camera, point, half_w, half_h)

    def delete(self, camera, point):
        """Remove marker ``point`` from ``camera``; it becomes the active number."""
        self._require(camera, point)
        picks = tuple(p for p in self.picks_of(camera) if p.point != point)
        return _push(self, **{camera: picks}, camera=camera, current=point)

    def set_half_size(self, half_w, half_h):
        """Set the rectangle half size given to newly placed markers (not undoable)."""
        return dataclasses.replace(self, half_size=self._check_half(half_w, half_h))

    def select(self, point=None, *, camera=None):
        """Make ``point`` the active number and/or ``camera`` the active view (not undoable).

        Switching view without a ``point`` selects the new view's first missing number.
        """
        changes = {}
        if camera is not None:
            changes["camera"] = self._check_camera(camera)
            if point is None and camera != self.camera:
                changes["current"] = self.first_missing(camera)
        if point is not None:
            changes["current"] = self._check_number(point)
        return dataclasses.replace(self, **changes)

    def next_point(self, step=1):
        """Select the next number (``step=-1``: the previous one), bounded by ``n_points``."""
        k = self.current + int(step)
        upper = self.n_points - 1 if self.n_points is not None else max(k, 0)
        return dataclasses.replace(self, current=int(np.clip(k, 0, upper)))

    @property
    def can_undo(self):
        """True when there is an edit to undo."""
        return bool(self.history)

    def undo(self):
        """Return the state before the last edit (this state when there is none)."""
        if not self.history:
            return self
        return dataclasses.replace(self.history[0], history=self.history[1:])

    # ---------------------------------------------------------------- export
    def to_frame(self, camera, *, dropna=False):
        """Picks of a view as the tracker's picks table.

        Parameters
        ----------
        camera : str
        dropna : bool
            Drop the rows of numbers missing in this view (the tracker needs a click for
            every marker it tracks).

        Returns
        -------
        picks : pandas.DataFrame
            Columns point (int64), frame (int64, the frame each marker was picked in), x,
            y (px), half_w, half_h (px, float64) and half_size (the larger half side, for a
            square template); one row per number ``0 .. n_rows - 1``, NaN (frame 0)
            where the number is missing in this view.
        """
        self._check_camera(camera)
        rows = np.full((self.n_rows, 4), np.nan)
        frames = np.zeros(self.n_rows, np.int64)
        for p in self.picks_of(camera):
            rows[p.point] = (p.x, p.y, p.half_w, p.half_h)
            frames[p.point] = p.frame
        df = pd.DataFrame(rows, columns=["x", "y", "half_w", "half_h"])
        df.insert(0, "frame", frames)
        df.insert(0, "point", np.arange(self.n_rows, dtype=np.int64))
        df["half_size"] = np.fmax(df["half_w"].to_numpy(), df["half_h"].to_numpy())
        if dropna:
            df = df[np.isfinite(df["x"].to_numpy())].reset_index(drop=True)
        return df

    def to_picks(self, camera):
        """(N, 2) array of marker centres (x, y) in px, row k = number k, NaN when missing."""
        return self.to_frame(camera)[["x", "y"]].to_numpy(np.float64)

    def to_table(self):
        """Every pick as one tidy table: camera, point, frame, x, y, half_w, half_h."""
        rows = [(cam, p.point, p.frame, p.x, p.y, p.half_w, p.half_h)
                for cam in self.cameras for p in self.picks_of(cam)]
        table = pd.DataFrame(rows, columns=["camera", "point", "frame", "x", "y", "half_w", "half_h"])
        return table.astype({"point": np.int64, "frame": np.int64, "x": np.float64, "y": np.float64,
                             "half_w": np.float64, "half_h": np.float64})

    def to_dict(self):
        """JSON-ready dict (the saved picks file, :mod:`wingphoto.picks`); no undo history."""
        return picks_document(
            self.to_table(),
            cameras=list(self.cameras),
            image_size=self.image_size,
            image_size_right=self.image_size_right,
            n_points=self.n_points,
            half_size=self.half_size,
            camera=self.camera,
            current=self.current,
        )

    def to_json(self):
        """The saved picks file as a JSON string (see :meth:`from_json`)."""
        return json.dumps(self.to_dict(), indent=1)

    @classmethod
    def from_table(cls, table, **meta):
        """Build a state from a tidy picks table (camera, point, [frame,] x, y, [half_w, half_h])."""
        picks = {cam: [] for cam in CAMERAS}
        for r in table.itertuples(index=False):
            picks[r.camera].append(Pick(int(r.point), float(r.x), float(r.y), float(r.half_w), float(r.half_h),
                                        int(r.frame)))
        cameras = tuple(meta.pop("cameras", None) or [c for c in CAMERAS if picks[c]] or CAMERAS)
        for cam in CAMERAS:
            if picks[cam] and cam not in cameras:
                cameras = cameras + (cam,)
        if meta.get("camera") not in cameras:
            meta["camera"] = cameras[0]
        return cls(cameras=cameras, **meta, left=tuple(picks["left"]), right=tuple(picks["right"]))

    @classmethod
    def from_dict(cls, data, *, source="picks"):
        """Build a state from :meth:`to_dict` output; ValueError naming ``source`` if malformed."""
        table, meta = read_picks_document(data, source=source)
        try:
            return cls.from_table(table, **meta)
        except (KeyError, TypeError) as exc:
            raise ValueError(f"{source} is a malformed picks file: {exc!r}") from None

    @classmethod
    def from_json(cls, text):
        """Parse a saved picks JSON string (the inverse of :meth:`to_json`)."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"picks text is not valid JSON: {exc}") from None
        return cls.from_dict(data)

    def save(self, path):
        """Write the picks to a JSON file atomically (an interrupted save keeps the old file).

        A ``.csv`` path writes the documented CSV instead (picks only, no picker state).
        """
        path = Path(path)
        if path.suffix.lower() == ".csv":
            from ..picks import write_picks

            return write_picks(self.to_table(), path)
        with atomic_write(path, "w", encoding="utf-8") as f:
            f.write(self.to_json())
        return path

    @classmethod
    def load(cls, path):
        """Read picks saved by :meth:`save` (JSON) or a picks CSV (``docs/picks.md``).

        Raises
        ------
        FileNotFoundError
            When ``path`` does not exist.
        ValueError
            When the file is not a wingphoto picks file.
        """
        path = Path(path)
        if path.suffix.lower() == ".csv":
            return cls.from_table(read_picks(path))
        if not path.is_file():
            read_picks(path)  # raises the FileNotFoundError that says how to make one
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise ValueError(f"picks file {path} is not valid JSON: {exc}") from None
        except UnicodeDecodeError:
            raise ValueError(f"picks file {path} is not text (binary content)") from None
        return cls.from_dict(data, source=f"picks file {path}")

    @classmethod
    def from_picks(cls, picks, *, image_size=None, image_size_right=None, half_size=(10.0, 10.0), n_points=None):
        """Build a state from arrays or tables of marker centres per view.

        Parameters
        ----------
        picks : dict
            ``{camera: (N, 2) array of (x, y) px, row k = number k (NaN rows skipped)}``
            or ``{camera: DataFrame with point, x, y[, half_w, half_h]}``, e.g. the
            synthetic ``StereoSequence.picks(camera)``.
        image_size, image_size_right, half_size, n_points
            As in :class:`PickerState`; ``half_size`` fills absent rectangle sizes.

        Returns
        -------
        PickerState
        """
        if not isinstance(picks, dict) or not picks:
            raise ValueError("picks must be a dict {camera: (N, 2) array or DataFrame}")
        hw0, hh0 = half_size
        out = {}
        for cam, value in picks.items():
            if isinstance(value, pd.DataFrame):
                missing = [c for c in ("point", "x", "y") if c not in value.columns]
                if missing:
                    raise ValueError(f"picks[{cam!r}] lacks columns {missing}")
                df = value
            else:
                arr = np.asarray(value, dtype=np.float64)
                if arr.ndim != 2 or arr.shape[1] != 2:
                    raise ValueError(f"picks[{cam!r}] must be an (N, 2) array of (x, y), got shape {arr.shape}")
                df = pd.DataFrame({"point": np.arange(len(arr)), "x": arr[:, 0], "y": arr[:, 1]})
            rows = []
            for r in df.itertuples(index=False):
                x, y = float(r.x), float(r.y)
                if np.isnan(x) or np.isnan(y):
                    continue
                hw = float(getattr(r, "half_w", np.nan))
                hh = float(getattr(r, "half_h", np.nan))
                rows.append(Pick(int(r.point), x, y, hw0 if np.isnan(hw) else hw, hh0 if np.isnan(hh) else hh,
                                 int(getattr(r, "frame", 0))))
            out[cam] = tuple(rows)
        cameras = tuple(c for c in CAMERAS if c in out)
        if set(out) - set(CAMERAS):
            raise ValueError(f"picks keys must be among {CAMERAS}, got {sorted(out)}")
        state = cls(
            image_size=image_size,
            image_size_right=image_size_right,
            cameras=cameras,
            camera=cameras[0],
            n_points=n_points,
            half_size=half_size,
            **out,
        )
        nxt = state.next_missing(cameras[0], after=-1)
        return state.select(nxt if nxt is not None and (n_points is None or nxt < n_points) else 0)


# --------------------------------------------------------------------------- corrections
class Correction(NamedTuple):
    """One manual correction: ``point`` of ``camera`` at ``frame`` is at (x, y) px."""

    camera: str
    point: int
    frame: int
    x: float
    y: float


def _as_correction(c):
    c = Correction(*c)
    if not isinstance(c.camera, str) or not c.camera:
        raise ValueError(f"correction camera must be a camera name, got {c.camera!r}")
    try:
        lost = math.isnan(float(c.x)) and math.isnan(float(c.y))
    except (TypeError, ValueError):
        lost = False
    return Correction(
        c.camera,
        _point_number(c.point, "correction point"),
        _point_number(c.frame, "correction frame"),
        # NaN, NaN declares the point lost (as a log saved by wingphoto.track may hold)
        math.nan if lost else _finite(c.x, "correction x"),
        math.nan if lost else _finite(c.y, "correction y"),
    )


def _check_tracks(tracks, name="tracks"):
    if not isinstance(tracks, pd.DataFrame):
        raise ValueError(f"{name} must be a tracks DataFrame, got {type(tracks).__name__}")
    missing = [c for c in ("camera", "frame", "point", "x", "y", "status") if c not in tracks.columns]
    if missing:
        raise ValueError(f"{name} lacks columns {missing}; expected camera, frame, point, x, y, score, status")
    return tracks


def apply_corrections(tracks, corrections):
    """Return ``tracks`` with each correction's position and status ``'manual'``.

    The one implementation, :func:`wingphoto.track.apply_corrections`, after checking
    that ``tracks`` has a camera column: a later correction of the same (camera, point,
    frame) wins, corrected rows get score NaN (no correlation score for a hand-placed
    position), reason ``""`` and, when present, the tracker's ``x_pix``, ``y_pix`` = the
    rounded position; a correction for a row absent from ``tracks`` adds the row (then
    sorted by camera, frame, point).

    Parameters
    ----------
    tracks : pandas.DataFrame
        Tracks (camera, frame, point, x, y, score, status); not modified.
    corrections : iterable of Correction or (camera, point, frame, x, y)

    Returns
    -------
    tracks : pandas.DataFrame
    """
    _check_tracks(tracks)
    corrections = [_as_correction(c) for c in corrections]
    return _track_corrections().apply_corrections(tracks, corrections)


def _track_corrections():
    from .. import corrections

    return corrections


def _merge_camera_tracks(tracks, camera, new):
    """Replace the rows of ``camera`` in ``tracks`` by ``new`` (one camera's tracks)."""
    new = new.copy()
    if "camera" not in new.columns:
        new.insert(0, "camera", camera)
    new = new[new["camera"] == camera]
    _check_tracks(new, "the re-tracked tracks")
    keep = tracks[tracks["camera"] != camera]
    out = pd.concat([keep, new[[c for c in tracks.columns if c in new.columns]]], ignore_index=True)
    out = out.astype({"frame": np.int64, "point": np.int64})
    return out.sort_values(["camera", "frame", "point"], kind="stable").reset_index(drop=True)


def replay_corrections(tracks, corrections, *, retrack=None, frames=None):
    """Replay a corrections log on tracks, optionally re-tracking after each correction.

    Parameters
    ----------
    tracks : pandas.DataFrame
        The tracker's output the log was recorded on.
    corrections : iterable of Correction
        The log, e.g. from :func:`read_corrections`.
    retrack : callable, optional
        ``retrack(frames[camera], camera_tracks, [point], frame) -> camera_tracks``
        (``wingphoto.track.retrack_from``), called after each correction with that
        camera's corrected tracks; None only applies the positions.
    frames : dict, optional
        ``{camera: image sequence}``, required with ``retrack``.

    Returns
    -------
    tracks : pandas.DataFrame
        Corrected (and re-tracked) tracks; every correction is applied last, so manual
        positions always win over re-tracked ones.
    """
    _check_tracks(tracks)
    corrections = [_as_correction(c) for c in corrections]
    if retrack is not None and frames is None:
        raise ValueError("frames={camera: sequence} is required to replay with retrack")
    out = tracks
    for k, c in enumerate(corrections):
        out = apply_corrections(out, [c])
        if retrack is not None:
            cam = out[out["camera"] == c.camera].reset_index(drop=True)
            out = _merge_camera_tracks(out, c.camera, retrack(frames[c.camera], cam, [c.point], c.frame))
            out = apply_corrections(out, corrections[: k + 1])
    return out


def write_corrections(corrections, path):
    """Save a corrections log atomically as CSV (``.csv``) or JSON (``.json``).

    The format of :func:`wingphoto.track.save_corrections` (which writes it). CSV columns:
    camera, point, frame, x, y. JSON: ``{"format": "wingphoto-corrections", "version": 1,
    "corrections": [{camera, point, frame, x, y}, ...]}``. Order is kept: it is the
    replay order.
    """
    corrections = [_as_correction(c) for c in corrections]
    if not corrections:
        frame = pd.DataFrame({k: pd.Series(dtype=d) for k, d in
                              zip(Correction._fields, (str, np.int64, np.int64, np.float64, np.float64))})
    else:
        frame = pd.DataFrame(corrections, columns=list(Correction._fields))
    return _track_corrections().save_corrections(frame, path)


def read_corrections(path):
    """Read a corrections log written by :func:`write_corrections` (CSV or JSON).

    Read by :func:`wingphoto.track.load_corrections`; the log must name the camera of
    each correction.

    Returns
    -------
    tuple of Correction

    Raises
    ------
    FileNotFoundError
        When ``path`` does not exist.
    ValueError
        When the suffix is not .csv/.json or the content is malformed.
    """
    c = _track_corrections().load_corrections(path)
    if "camera" not in c.columns:
        raise ValueError(f"corrections file {path} lacks columns ['camera']: the review needs each correction's camera")
    rows = c[list(Correction._fields)].itertuples(index=False, name=None)
    return tuple(_as_correction(r) for r in rows)


# --------------------------------------------------------------------------- review
@dataclass(frozen=True, eq=False)
class ReviewState:
    """Review of a tracking result: current frame, problems, corrections log, undo.

    Parameters
    ----------
    source : pandas.DataFrame
        Tracks (camera, frame, point, x, y, score, status) as the tracker (or the last
        re-tracking) produced them; never modified. :attr:`tracks` applies the
        corrections on top of it.
    frame : int
        Current frame.
    camera : str, optional
        Current camera; default the first camera in ``source``.
    point : int, optional
        Selected point (the one a click corrects); default the smallest number.
    corrections : tuple of Correction
        The replayable log, in the order the corrections were made.
    n_frames : int, optional
        Number of frames; default one more than the largest frame in ``source``.
    image_size : (width, height), optional
        Corrections outside the image raise ValueError; None skips the check.
    history : tuple of ReviewState
        Undo history (newest first), filled by :meth:`correct` and :meth:`with_tracks`.

    Examples
    --------
    >>> import pandas as pd
    >>> t = pd.DataFrame({"camera": "left", "frame": [0, 1, 2], "point": 0,
    ...                   "x": [5.0, 6.0, float("nan")], "y": 5.0, "score": [0.9, 0.4, 0.0],
    ...                   "status": ["ok", "flagged", "lost"]})
    >>> s = ReviewState(t)
    >>> s.problems
    ((1, 0), (2, 0))
    >>> s = s.next_problem()
    >>> s.frame
    1
    >>> s = s.correct("left", 0, 1, 6.5, 5.0)
    >>> s.problems
    ((2, 0),)
    >>> s.undo().corrections
    ()
    """

    source: pd.DataFrame
    frame: int = 0
    camera: str | None = None
    point: int | None = None
    corrections: tuple = ()
    n_frames: int | None = None
    image_size: tuple | None = None
    history: tuple = field(default=(), repr=False)

    def __post_init__(self):
        src = _check_tracks(self.source, "source")
        object.__setattr__(self, "image_size", _image_size(self.image_size, "image_size"))
        cameras = tuple(sorted(src["camera"].astype(str).unique()))
        object.__setattr__(self, "corrections", tuple(_as_correction(c) for c in self.corrections))
        if self.n_frames is None:
            n = int(src["frame"].max()) + 1 if len(src) else 0
            n = max([n] + [c.frame + 1 for c in self.corrections])
            object.__setattr__(self, "n_frames", n)
        else:
            object.__setattr__(self, "n_frames", _point_number(self.n_frames, "n_frames"))
        camera = self.camera if self.camera is not None else (cameras[0] if cameras else None)
        if cameras and camera not in cameras:
            raise ValueError(f"camera must be one of {cameras} (the cameras in the tracks), got {camera!r}")
        object.__setattr__(self, "camera", camera)
        object.__setattr__(self, "frame", self._check_frame(self.frame))
        if self.point is None and len(src):
            object.__setattr__(self, "point", int(src["point"].min()))
        elif self.point is not None:
            object.__setattr__(self, "point", _point_number(self.point))
        object.__setattr__(self, "history", tuple(self.history))

    def _check_frame(self, frame):
        frame = _point_number(frame, "frame")
        if self.n_frames and frame >= self.n_frames:
            raise ValueError(f"frame must be in 0..{self.n_frames - 1}, got {frame}")
        return frame

    # ---------------------------------------------------------------- derived (cached)
    @functools.cached_property
    def tracks(self):
        """The corrected tracks: :attr:`source` with :attr:`corrections` applied.

        Computed once per edit and shared by the navigation states: treat it as read-only
        (``.copy()`` it to modify).
        """
        return apply_corrections(self.source, self.corrections)

    @property
    def cameras(self):
        """Sorted camera names in the tracks."""
        return tuple(sorted(self.source["camera"].astype(str).unique()))

    @property
    def points(self):
        """Sorted point numbers in the tracks."""
        return tuple(int(p) for p in np.unique(self.tracks["point"].to_numpy(np.int64)))

    @functools.cached_property
    def problem_table(self):
        """Rows of the corrected tracks whose status is flagged or lost, by frame and point."""
        t = self.tracks
        bad = t[t["status"].isin(PROBLEM_STATUS)]
        cols = [c for c in TRACK_COLUMNS if c in bad.columns]
        return bad[cols].sort_values(["frame", "point", "camera"], kind="stable").reset_index(drop=True)

    @property
    def problems(self):
        """Sorted unique (frame, point) items flagged or lost in any camera."""
        p = self.problem_table
        return tuple(dict.fromkeys(zip(p["frame"].astype(int).tolist(), p["point"].astype(int).tolist())))

    def at(self, frame=None, camera=None):
        """Corrected tracks rows of one camera (default current) at one frame (default current)."""
        frame = self.frame if frame is None else frame
        camera = self.camera if camera is None else camera
        t = self.tracks
        return t[(t["camera"] == camera) & (t["frame"] == frame)]

    def position(self, point=None, frame=None, camera=None):
        """(x, y) of a point (default selected) at a frame in a camera; NaNs when unknown."""
        point = self.point if point is None else point
        rows = self.at(frame, camera)
        rows = rows[rows["point"] == point]
        if rows.empty:
            return (np.nan, np.nan)
        return float(rows["x"].iloc[0]), float(rows["y"].iloc[0])

    # ---------------------------------------------------------------- navigation
    def _navigate(self, **changes):
        """Replace view fields only; the corrected tracks and problems are reused, not recomputed."""
        new = dataclasses.replace(self, **changes)
        for name in ("tracks", "problem_table"):
            if name in self.__dict__:
                new.__dict__[name] = self.__dict__[name]
        return new

    def goto(self, frame):
        """Show ``frame``; ValueError outside 0..n_frames-1."""
        return self._navigate(frame=self._check_frame(frame))

    def select(self, point=None, *, camera=None):
        """Select the point a click corrects and/or the camera shown."""
        changes = {}
        if point is not None:
            changes["point"] = _point_number(point)
        if camera is not None:
            if camera not in self.cameras:
                raise ValueError(f"camera must be one of {self.cameras}, got {camera!r}")
            changes["camera"] = camera
        return self._navigate(**changes)

    def next_problem(self, step=1):
        """Go to the next flagged/lost (frame, point) after the current one (wrapping).

        ``step=-1`` goes to the previous one. The frame, point and camera (the first
        camera where it is a problem) are selected. With no problems, returns self.
        """
        problems = self.problems
        if not problems:
            return self
        here = (self.frame, -1 if self.point is None else self.point)
        if step >= 0:
            later = [p for p in problems if p > here]
            target = later[0] if later else problems[0]
        else:
            earlier = [p for p in problems if p < here]
            target = earlier[-1] if earlier else problems[-1]
        table = self.problem_table
        cams = table[(table["frame"] == target[0]) & (table["point"] == target[1])]["camera"].tolist()
        camera = self.camera if self.camera in cams else cams[0]
        return self._navigate(frame=target[0], point=target[1], camera=camera)

    # ---------------------------------------------------------------- edits
    def correct(self, camera, point, frame, x, y):
        """Record that ``point`` of ``camera`` is at (x, y) px in ``frame`` (status 'manual').

        The correction is appended to the log; frame, point and camera become current.

        Raises
        ------
        ValueError
            Unknown camera, frame out of range, or (x, y) outside the image.
        """
        if camera not in self.cameras:
            raise ValueError(f"camera must be one of {self.cameras}, got {camera!r}")
        frame = self._check_frame(frame)
        point = _point_number(point)
        x, y = _check_inside(x, y, self.image_size, f"{camera} image")
        c = Correction(camera, point, frame, x, y)
        return _push(self, corrections=self.corrections + (c,), frame=frame, point=point, camera=camera)

    def with_tracks(self, tracks, *, record=True):
        """Replace :attr:`source` (e.g. by re-tracked tracks); the log is kept and re-applied.

        With ``record=False`` no undo step is added, so a re-tracking that follows a
        correction is undone together with it.
        """
        _check_tracks(tracks)
        if record:
            return _push(self, source=tracks)
        return dataclasses.replace(self, source=tracks)

    def with_corrections(self, corrections, *, tracks=None):
        """Replace the corrections log (undoable), e.g. by one read from a file.

        ``tracks`` also replaces :attr:`source` in the same undo step (e.g. the result of
        :func:`replay_corrections` with re-tracking).
        """
        changes = {"corrections": tuple(_as_correction(c) for c in corrections)}
        if tracks is not None:
            changes["source"] = _check_tracks(tracks)
        return _push(self, **changes)

    @property
    def can_undo(self):
        """True when there is an edit to undo."""
        return bool(self.history)

    def undo(self):
        """Return the state before the last edit (this state when there is none)."""
        if not self.history:
            return self
        return dataclasses.replace(self.history[0], history=self.history[1:])

    def save_corrections(self, path):
        """Write the corrections log (CSV or JSON by suffix) atomically."""
        return write_corrections(self.corrections, path)

    def load_corrections(self, path):
        """Return the state with the log read from ``path`` (replacing the current log)."""
        return self.with_corrections(read_corrections(path))
