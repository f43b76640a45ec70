"""Tracking review: step through frames with the tracks overlaid, fix flagged and lost points.

All logic lives in :class:`wingphoto.widgets.state.ReviewState`; this view shows a frame
with every point coloured by status, lists the flagged/lost items, turns a click into a
correction (status ``'manual'``) and, when a re-tracking function is available, re-tracks
the corrected point forward from that frame. Corrections go to a replayable log
(:func:`wingphoto.widgets.state.write_corrections`).
"""
from __future__ import annotations

import html
import logging
from pathlib import Path

import ipywidgets as W
import numpy as np
import pandas as pd

from .picker import ImageView, _number_label, frame_image, n_frames_of
from .state import ReviewState, _merge_camera_tracks, read_corrections, replay_corrections

__all__ = ["TrackReview", "default_retrack"]

logger = logging.getLogger(__name__)

STATUS_COLOURS = {
    "ok": "lime",
    "interpolated": "deepskyblue",
    "manual": "magenta",
    "flagged": "orange",
    "lost": "red",
}
MAX_LISTED = 500


def default_retrack():
    """``wingphoto.track.retrack_from`` when the tracking module provides it, else None.

    Imported lazily so the review works (without re-tracking) before tracking is installed.
    """
    try:
        from ..track import retrack_from
    except ImportError:
        return None
    import functools

    # no progress bar: a re-tracking takes ~1 s, and a bar left in a notebook's output stays at 0 %
    return functools.partial(retrack_from, progress=False)


class TrackReview(ImageView):
    """Review tracks frame by frame, correct flagged and lost points, re-track forward.

    Parameters
    ----------
    frames : sequence of images, or dict
        ``{camera: sequence}`` for every camera in ``tracks``, or one sequence used for
        all of them (single-camera tracks). Sequences are (T, H, W) arrays, lists or lazy
        ``wingphoto.io.read_sequence`` objects.
    tracks : pandas.DataFrame
        Tracks (camera, frame, point, x, y, score, status), e.g. ``track_markers`` output.
    corrections_path : str or Path, optional
        Log file (``.csv`` or ``.json``) that Save and Load use.
    retrack : callable, False or None
        ``retrack(frames[camera], camera_tracks, [point], frame) -> camera_tracks``, called
        after each correction to re-track that point forward from the corrected frame. None
        uses ``wingphoto.track.retrack_from`` when it exists; False never re-tracks.
    trail : int
        Frames of the selected point's path drawn before and after the current frame.
    figsize : (w, h)
        Figure size in inches.

    Attributes
    ----------
    state : ReviewState
        Corrected tracks in ``state.tracks``, the log in ``state.corrections``.
    widget : ipywidgets.VBox
        Controls and figure; display it in the notebook.
    retrack : callable or None
        The re-tracking function in use.
    message : str
        The last error or information shown in the status line.

    Notes
    -----
    Mouse: a click moves the selected point to the click in the current frame and camera
    (a correction); dragging a drawn point corrects that point; dragging elsewhere pans
    when zoomed. The problem list and Prev/Next problem step through the flagged and lost
    (frame, point) items. Colours: ok lime, interpolated blue, manual magenta, flagged
    orange, lost red (at its last known position, hollow).

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> frames = np.zeros((3, 30, 40), np.uint8)
    >>> t = pd.DataFrame({"camera": "left", "frame": [0, 1, 2], "point": 0, "x": [5.0, 6.0, np.nan],
    ...                   "y": 5.0, "score": [0.9, 0.9, 0.0], "status": ["ok", "ok", "lost"]})
    >>> r = TrackReview(frames, t, retrack=False)
    >>> r.next_problem(); r.state.frame
    2
    >>> r.on_click(7.0, 5.0)
    >>> r.state.tracks["status"].tolist()
    ['ok', 'ok', 'manual']
    """

    def __init__(self, frames, tracks, *, corrections_path=None, retrack=None, trail=10, figsize=(6.0, 6.0)):
        state = ReviewState(tracks)
        cameras = state.cameras
        if not cameras:
            raise ValueError("tracks is empty: nothing to review")
        if isinstance(frames, dict):
            missing = [c for c in cameras if c not in frames]
            if missing:
                raise ValueError(f"frames lacks cameras {missing} present in tracks; pass {{camera: sequence}}")
            self.frames = {c: frames[c] for c in cameras}
        else:
            self.frames = {c: frames for c in cameras}
        n_frames = min(n_frames_of(f) for f in self.frames.values())
        first = {c: frame_image(f, 0) for c, f in self.frames.items()}
        sizes = {c: (img.shape[1], img.shape[0]) for c, img in first.items()}
        same = len(set(sizes.values())) == 1
        self.state = ReviewState(tracks, n_frames=n_frames, image_size=sizes[cameras[0]] if same else None)
        self.corrections_path = None if corrections_path is None else Path(corrections_path)
        if retrack is False:
            self.retrack = None
        elif retrack is None:
            self.retrack = default_retrack()
        elif callable(retrack):
            self.retrack = retrack
        else:
            raise ValueError(f"retrack must be a callable, None or False, got {retrack!r}")
        self.trail = int(trail)
        self._camera = self.state.camera
        self._cache = {}
        self._init_view(sizes, figsize)
        self._build_controls()
        self._after_change()

    # ---------------------------------------------------------------- controls
    def _build_controls(self):
        s = self.state
        self.camera_toggle = W.ToggleButtons(options=list(s.cameras), value=s.camera, description="View")
        self.frame_slider = W.IntSlider(value=s.frame, min=0, max=max(s.n_frames - 1, 0), description="Frame",
                                        continuous_update=False, layout=W.Layout(width="420px"))
        self.point_box = W.BoundedIntText(value=s.point or 0, min=0, max=10**6, description="Point",
                                          layout=W.Layout(width="150px"))
        self.zoom_slider = W.FloatSlider(value=1.0, min=1.0, max=8.0, step=0.5, description="Zoom",
                                         continuous_update=False)
        self.problem_list = W.Select(options=[], rows=8, description="Problems", layout=W.Layout(width="320px"))
        self.prev_problem_button = W.Button(description="◀ Prev problem")
        self.next_problem_button = W.Button(description="Next problem ▶")
        self.undo_button = W.Button(description="Undo")
        self.save_button = W.Button(description="Save", button_style="success")
        self.load_button = W.Button(description="Load")
        self.retrack_check = W.Checkbox(value=self.retrack is not None, disabled=self.retrack is None,
                                        description="re-track forward", indent=False)
        self.path_text = W.Text(value="" if self.corrections_path is None else str(self.corrections_path),
                                description="Log", placeholder="corrections.csv")
        self.status = W.HTML()

        self.camera_toggle.observe(lambda ch: self._from_control(self.set_camera, ch["new"]), "value")
        self.frame_slider.observe(lambda ch: self._from_control(self.goto, ch["new"]), "value")
        self.point_box.observe(lambda ch: self._from_control(self.select_point, ch["new"]), "value")
        self.zoom_slider.observe(lambda ch: self._from_control(self.set_zoom, ch["new"]), "value")
        self.problem_list.observe(lambda ch: self._from_control(self.goto_problem, ch["new"]), "value")
        self.prev_problem_button.on_click(lambda _: self.next_problem(-1))
        self.next_problem_button.on_click(lambda _: self.next_problem(1))
        self.undo_button.on_click(lambda _: self.undo())
        self.save_button.on_click(lambda _: self.save())
        self.load_button.on_click(lambda _: self.load())
        # Undo/Save and the status line sit above the figure, in sight of the controls
        self.widget = W.VBox([
            W.HBox([self.camera_toggle, self.point_box, self.zoom_slider]),
            self.frame_slider,
            W.HBox([self.undo_button, self.save_button, self.load_button, self.path_text, self.retrack_check]),
            self.status,
            W.HBox([self._canvas_widget,
                    W.VBox([self.problem_list, W.HBox([self.prev_problem_button, self.next_problem_button])])]),
        ])

    # ---------------------------------------------------------------- state changes
    _file_attr = "corrections_path"
    _file_hint = "no corrections file: type a path in Log (e.g. corrections.csv) or pass corrections_path"
    _centre_by_default = True

    def _centre_target(self, state):
        return self._known_position(state)

    def _known_position(self, state=None, camera=None):
        """(x, y) of the selected point in the shown frame, or where it was last seen.

        A lost point has no position; its last finite position before the frame (else the
        first after it) is used to centre the zoom and to highlight it.
        """
        state = self.state if state is None else state
        camera = self._camera if camera is None else camera
        x, y = state.position(camera=camera)
        if np.isfinite(x) and np.isfinite(y):
            return x, y
        t = state.tracks
        t = t[(t["camera"] == camera) & (t["point"] == state.point)]
        t = t[np.isfinite(t["x"].to_numpy(float)) & np.isfinite(t["y"].to_numpy(float))]
        if t.empty:
            return (np.nan, np.nan)
        before = t[t["frame"] < state.frame]
        row = before.loc[before["frame"].idxmax()] if len(before) else t.loc[t["frame"].idxmin()]
        return float(row["x"]), float(row["y"])

    def _problem_options(self):
        """One entry per flagged/lost (frame, point, camera), labelled with its camera and reason."""
        table = self.state.problem_table
        reasons = table["reason"] if "reason" in table.columns else pd.Series("", index=table.index)
        options = []
        for r, why in zip(table.itertuples(index=False), reasons):
            why = "" if not isinstance(why, str) or not why else f" ({why})"
            options.append((f"frame {int(r.frame)}, point {int(r.point)}, {r.camera}: {r.status}{why}",
                            (int(r.frame), int(r.point), str(r.camera))))
        return options[:MAX_LISTED]

    def _after_change(self):
        s = self.state
        self._syncing = True
        try:
            self.camera_toggle.value = s.camera
            self.frame_slider.value = s.frame
            self.point_box.value = s.point or 0
            self.zoom_slider.value = self.zoom
            options = self._problem_options()
            if options != list(self.problem_list.options):
                self.problem_list.options = options
            # highlight only the problem of the camera shown
            current = (s.frame, s.point, s.camera)
            self.problem_list.value = current if any(v == current for _, v in options) else None
            self.undo_button.disabled = not s.can_undo
        finally:
            self._syncing = False
        self.render()

    # ---------------------------------------------------------------- handlers
    def on_click(self, u, v):
        """Click at display (u, v): correct the selected point there in this frame and camera."""
        x, y = self.to_image(u, v)
        self.correct(self.state.point, x, y)

    def _press_target(self, x, y):
        rows = self.state.at()
        rows = rows[np.isfinite(rows["x"].to_numpy(float))]
        if len(rows):
            d = np.hypot(rows["x"].to_numpy(float) - x, rows["y"].to_numpy(float) - y)
            k = int(np.argmin(d))
            if d[k] * self.zoom <= 8.0:
                return ("move", int(rows["point"].iloc[k]))
        return ("pan", None)

    def _drag_to(self, press, x, y):
        s = self.state
        return s.correct(s.camera, press["target"][1], s.frame, x, y)

    def _commit_drag(self, preview):
        c = preview.corrections[-1]
        self.correct(c.point, c.x, c.y)

    def on_release(self, u, v):
        """Mouse button up at display (u, v): a dragged point is corrected, a click corrects."""
        p = self._press
        if p is not None and p["dragging"] and p["target"][0] == "move":
            self.on_motion(u, v)
            self._press = None
            if p["preview"] is not None:
                self._commit_drag(p["preview"])
            else:
                self.render()
            return
        super().on_release(u, v)

    def correct(self, point, x, y, *, frame=None, camera=None):
        """Correct ``point`` to image pixel (x, y) at ``frame`` in ``camera`` (default current).

        Appends to the log (status 'manual'), then re-tracks the point forward from that
        frame when re-tracking is on. One :meth:`undo` reverts both.
        """
        s = self.state
        frame = s.frame if frame is None else frame
        camera = s.camera if camera is None else camera
        if point is None:
            self._report(ValueError("no point selected: choose a point number first"))
            self.render()
            return
        try:
            size = self._sizes[camera] if camera in self._sizes else None
            if size is not None and not (-0.5 <= x <= size[0] - 0.5 and -0.5 <= y <= size[1] - 0.5):
                raise ValueError(f"point (x={x:.2f}, y={y:.2f}) is outside the {camera} image of size {size}")
            new = s.correct(camera, point, frame, x, y)
        except ValueError as exc:
            self._report(exc)
            self.render()
            return
        self.message = f"point {point} corrected at frame {frame} ({camera})"
        if self.retrack is not None and self.retrack_check.value:
            try:
                new = self._retrack(new, camera, point, frame)
                self.message += ", re-tracked forward"
            except Exception as exc:  # a failing tracker must not lose the correction
                logger.exception("re-tracking failed")
                self.message += f"; re-tracking failed: {exc}"
        self._commit(new, centre=False)

    def _retrack(self, state, camera, point, frame):
        tracks = state.tracks
        cam_tracks = tracks[tracks["camera"] == camera].reset_index(drop=True)
        result = self.retrack(self.frames[camera], cam_tracks, [point], frame)
        if not isinstance(result, pd.DataFrame):
            raise ValueError(f"retrack returned {type(result).__name__}, expected a tracks DataFrame")
        return state.with_tracks(_merge_camera_tracks(tracks, camera, result), record=False)

    # ---------------------------------------------------------------- controls as methods
    def goto(self, frame):
        """Show ``frame``."""
        self._apply(self.state.goto, frame)

    def set_camera(self, camera):
        """Show ``camera``."""
        self._apply(self.state.select, camera=camera)

    def select_point(self, point):
        """Select the point that a click corrects."""
        self._apply(self.state.select, point)

    def next_problem(self, step=1):
        """Go to the next (``step=-1``: previous) flagged or lost item."""
        if not self.state.problems:
            self.message = "no flagged or lost points left"
            self.render()
            return
        self._apply(self.state.next_problem, step)

    def goto_problem(self, item):
        """Go to a (frame, point) item of the problem list."""
        if item is None:
            return
        if len(item) == 3:
            frame, point, camera = item
        else:
            frame, point = item
            table = self.state.problem_table
            cams = table[(table["frame"] == frame) & (table["point"] == point)]["camera"].tolist()
            camera = self.state.camera if (not cams or self.state.camera in cams) else cams[0]
        self._apply(lambda: self.state.goto(frame).select(point, camera=camera), centre=True)

    def set_zoom(self, zoom):
        """Magnify the view, centred on the selected point when it has a position."""
        try:
            x, y = self._known_position()
            self._set_viewports(float(zoom), (x, y) if np.isfinite(x) and np.isfinite(y) else None)
        except ValueError as exc:
            self._report(exc)
        self._after_change()

    def undo(self):
        """Undo the last correction (with its re-tracking) or load."""
        self._apply(self.state.undo)

    def _write(self, path):
        """Save the corrections log, CSV or JSON by suffix (see :meth:`ImageView.save`)."""
        self.state.save_corrections(path)
        return f"saved {len(self.state.corrections)} corrections to {path}"

    def load(self, path=None, *, replay=False):
        """Load a corrections log (replacing the current one) and apply it (undoable).

        Parameters
        ----------
        path : str or Path, optional
            Default the Log box or ``corrections_path``.
        replay : bool
            Replay the log on the tracker's tracks with re-tracking after each correction
            (:func:`~wingphoto.widgets.state.replay_corrections`), reproducing the reviewed
            tracks; False only applies the corrected positions.
        """
        try:
            path = self._path(path)
            log = read_corrections(path)
            tracks = None
            if replay and self.retrack is not None:
                tracks = replay_corrections(self.state.source, log, retrack=self.retrack, frames=self.frames)
        except (ValueError, FileNotFoundError) as exc:
            self._report(exc)
            self.render()
            return
        self.corrections_path = path
        self._commit(self.state.with_corrections(log, tracks=tracks))
        self.message = f"loaded {len(log)} corrections from {path}" + (", replayed" if tracks is not None else "")
        self.render()

    @classmethod
    def load_or_review(cls, frames, tracks, *, corrections_path, replay=True, **kwargs):
        """Open a review with the saved corrections applied when ``corrections_path`` exists.

        The notebooks' headless path: with a saved log the reviewed tracks are reproduced
        (replayed with re-tracking when available) without any click; without one the
        tracks are shown as tracked.

        Parameters
        ----------
        frames, tracks, **kwargs
            As for :class:`TrackReview`.
        corrections_path : str or Path
            The corrections log (.csv or .json); Save and Load use it too.
        replay : bool
            Re-track after each loaded correction (see :meth:`load`).

        Returns
        -------
        TrackReview
        """
        review = cls(frames, tracks, corrections_path=corrections_path, **kwargs)
        if Path(corrections_path).is_file():
            review.load(corrections_path, replay=replay)
            if review.message and not review.message.startswith("loaded"):
                raise ValueError(review.message)
        return review

    # ---------------------------------------------------------------- rendering
    def _image(self, camera, frame):
        key = (camera, frame)
        if key not in self._cache:
            if len(self._cache) > 8:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = frame_image(self.frames[camera], frame)
        return self._cache[key]

    def render(self):
        """Redraw the frame with the points coloured by status, the selected point's path and the status."""
        preview = self._press.get("preview") if self._press is not None else None
        s = preview if preview is not None else self.state
        cam, frame = self._camera, s.frame
        self._draw_image(self._image(cam, frame))
        vp = self.viewport
        t = s.tracks
        t = t[t["camera"] == cam]
        if s.point is not None and self.trail > 0:
            path = t[(t["point"] == s.point) & (t["frame"] - frame).abs().le(self.trail)].sort_values("frame")
            u, v = vp.to_display(path["x"].to_numpy(float), path["y"].to_numpy(float))
            self.ax.plot(u, v, "-", color="white", alpha=0.6, linewidth=1)
        now = t[t["frame"] == frame]
        for status, colour in STATUS_COLOURS.items():
            rows = now[now["status"] == status]
            if status == "lost":
                rows = self._last_known(t, rows, frame)
            if rows.empty:
                continue
            u, v = vp.to_display(rows["x"].to_numpy(float), rows["y"].to_numpy(float))
            face = "none" if status == "lost" else colour
            self.ax.scatter(u, v, s=30, facecolors=face, edgecolors=colour, linewidths=1.2)
            for uu, vv, p in zip(u, v, rows["point"].to_numpy(int)):
                if np.isfinite(uu) and np.isfinite(vv):
                    _number_label(self.ax, uu, vv, p, colour)
        x, y = s.position(frame=frame, camera=cam)
        if np.isfinite(x) and np.isfinite(y):
            u, v = vp.to_display(x, y)
            self.ax.scatter([u], [v], s=200, facecolors="none", edgecolors="yellow", linewidths=1.5)
        elif s.point is not None:  # lost here: ring its last known position, dashed
            x, y = self._known_position(s, cam)
            if np.isfinite(x) and np.isfinite(y):
                u, v = vp.to_display(x, y)
                self.ax.scatter([u], [v], s=260, facecolors="none", edgecolors="yellow", linewidths=1.5,
                                linestyles="--")
                self.ax.annotate(f"{s.point} lost: last seen here", (u, v), xytext=(10, 10),
                                 textcoords="offset points", color="yellow", fontsize=8)
        row = now[now["point"] == s.point]
        status = row["status"].iloc[0] if len(row) else "absent"
        parts = [f"<b>{cam}</b> frame <b>{frame}</b>/{s.n_frames - 1}, point <b>{s.point}</b> ({status})",
                 f"{len(s.problems)} flagged/lost items, {len(s.corrections)} corrections"
                 + ("" if self.retrack is not None else ", re-tracking unavailable")]
        if self.message:
            parts.append(f"<i>{html.escape(self.message)}</i>")
        hint = self._static_hint()
        if hint:
            parts.append(hint)
        self.status.value = "<br>".join(parts)
        self._show()

    @staticmethod
    def _last_known(t, lost, frame):
        """Lost rows placed at their point's last finite position before ``frame``."""
        if lost.empty:
            return lost
        out = lost.copy()
        before = t[(t["frame"] < frame) & t["point"].isin(lost["point"]) & np.isfinite(t["x"].to_numpy(float))]
        last = before.sort_values("frame").groupby("point")[["x", "y"]].last()
        fill = out["point"].map(last["x"]), out["point"].map(last["y"])
        out["x"] = out["x"].where(np.isfinite(out["x"].to_numpy(float)), fill[0])
        out["y"] = out["y"].where(np.isfinite(out["y"].to_numpy(float)), fill[1])
        return out
