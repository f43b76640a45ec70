"""Marker picker: click the markers of the first frame in both views, in numbering order.

The view is a matplotlib figure (an interactive ipympl canvas under ``%matplotlib widget``,
a static image otherwise) plus ipywidgets controls. All logic lives in
:class:`wingphoto.widgets.state.PickerState`; the view converts display coordinates (the
axes' data coordinates, see :class:`~wingphoto.widgets.state.Viewport`) to image pixels,
calls a transition and re-renders. The handlers :meth:`Picker.on_click`,
:meth:`Picker.on_press`, :meth:`Picker.on_motion`, :meth:`Picker.on_release` and
:meth:`Picker.on_drag` take display coordinates, so they can be driven without a browser.
"""
from __future__ import annotations

import dataclasses
import html
import io
import logging
import os
from pathlib import Path

import ipywidgets as W
import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from .state import PickerState, Viewport

__all__ = ["Picker", "headless"]

logger = logging.getLogger(__name__)

DRAG_THRESHOLD = 3.0  # display px a press must travel to become a drag
GRAB_TOLERANCE = 5.0  # display px around a rectangle edge that grabs it for resizing


def headless():
    """True when ``WINGPHOTO_HEADLESS`` is set to anything but ``""``/``"0"`` (nbmake, CI)."""
    return os.environ.get("WINGPHOTO_HEADLESS", "").strip() not in ("", "0")


def _in_kernel():
    try:
        from IPython import get_ipython
    except ImportError:  # pragma: no cover - IPython comes with ipywidgets
        return False
    shell = get_ipython()
    return shell is not None and hasattr(shell, "kernel")


def _is_ipympl():
    backend = matplotlib.get_backend().lower()
    return "ipympl" in backend or backend == "widget"


def n_frames_of(frames):
    """Number of frames of a sequence; a single 2D image counts as one."""
    if isinstance(frames, np.ndarray) and frames.ndim == 2:
        return 1
    return len(frames)


def frame_image(frames, index):
    """Image ``index`` of a sequence ((T, H, W) array, list, lazy Sequence) or a 2D image."""
    if isinstance(frames, np.ndarray) and frames.ndim == 2:
        if index != 0:
            raise ValueError(f"frame {index} requested but a single image was given")
        return frames
    n = n_frames_of(frames)
    if not 0 <= index < n:
        raise ValueError(f"frame must be in 0..{n - 1}, got {index}")
    img = np.asarray(frames[index])
    if img.ndim not in (2, 3):
        raise ValueError(f"frames must hold 2D (H, W) or colour (H, W, 3) images, got shape {img.shape}")
    return img


def _display_range(img):
    finite = img[np.isfinite(img)] if img.dtype.kind == "f" else img
    if finite.size == 0:
        return 0.0, 1.0
    lo, hi = np.percentile(finite, [0.5, 99.8])
    return float(lo), float(hi if hi > lo else lo + 1)


def _png(fig, dpi=80):
    """The figure as an IPython PNG image (shown whatever the matplotlib backend, e.g. Agg)."""
    from IPython.display import Image

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return Image(data=buf.getvalue(), format="png")


def _number_label(ax, u, v, number, colour):
    """Write ``number`` just beside its own centre (u, v), on a dark patch, so it is unambiguous."""
    ax.annotate(str(number), (u, v), xytext=(4, -4), textcoords="offset points", ha="left", va="bottom",
                color=colour, fontsize=9, clip_on=True, annotation_clip=True,
                bbox=dict(boxstyle="round,pad=0.1", facecolor="black", alpha=0.55, linewidth=0))


class ImageView:
    """Shared view machinery: figure, zoom/pan viewport per camera, mouse routing, status.

    Subclasses implement ``render`` and the ``on_click``/``_press_target``/``_drag_to``
    hooks. Not public API.
    """

    def _init_view(self, sizes, figsize):
        self._sizes = dict(sizes)  # camera -> (width, height)
        self._viewports = {cam: Viewport(*size) for cam, size in self._sizes.items()}
        self._press = None
        self.message = ""
        self._syncing = False
        if _is_ipympl():
            import matplotlib.pyplot as plt

            with plt.ioff():
                self.fig = plt.figure(figsize=figsize)
            self.fig.canvas.header_visible = False
            self.fig.canvas.toolbar_visible = False
            self._canvas_widget = self.fig.canvas
            self._png = None
        else:  # static fallback: a PNG refreshed after each render
            self.fig = Figure(figsize=figsize)
            from matplotlib.backends.backend_agg import FigureCanvasAgg

            FigureCanvasAgg(self.fig)
            self._png = W.Image(format="png", layout=W.Layout(width=f"{figsize[0] * 80:.0f}px"))
            self._canvas_widget = self._png
        self.ax = self.fig.add_axes((0.0, 0.0, 1.0, 1.0))
        self.ax.format_coord = self.format_coord
        self.fig.canvas.mpl_connect("button_press_event", self._mpl_press)
        self.fig.canvas.mpl_connect("motion_notify_event", self._mpl_motion)
        self.fig.canvas.mpl_connect("button_release_event", self._mpl_release)

    # ---------------------------------------------------------------- coordinates
    @property
    def viewport(self):
        """The :class:`Viewport` of the camera shown."""
        return self._viewports[self._camera]

    def to_image(self, u, v):
        """Display coordinates (axes data) -> image pixels (x, y) of the camera shown."""
        return self.viewport.to_image(u, v)

    def to_display(self, x, y):
        """Image pixels (x, y) of the camera shown -> display coordinates."""
        return self.viewport.to_display(x, y)

    def format_coord(self, u, v):
        """Coordinate readout under the figure: image pixels (not display coordinates)."""
        x, y = self.to_image(u, v)
        return f"{self._camera} x={x:.2f} y={y:.2f} px (zoom {self.zoom:g})"

    @property
    def zoom(self):
        """Current magnification (shared by the cameras)."""
        return self.viewport.zoom

    def _set_viewports(self, zoom, centre=None):
        for cam, vp in self._viewports.items():
            if centre is not None and cam == self._camera:
                self._viewports[cam] = vp.zoomed(zoom, cx=centre[0], cy=centre[1])
            else:
                self._viewports[cam] = vp.zoomed(zoom)

    def centre_on(self, x, y):
        """Centre the camera shown on image pixel (x, y) (clamped to the image)."""
        if np.isfinite(x) and np.isfinite(y):
            self._viewports[self._camera] = self.viewport.centred(x, y)

    # ---------------------------------------------------------------- mouse routing
    def _mpl_press(self, event):
        if event.inaxes is self.ax and event.button == 1 and event.xdata is not None:
            self.on_press(event.xdata, event.ydata)

    def _mpl_motion(self, event):
        if self._press is not None and event.inaxes is self.ax and event.xdata is not None:
            self.on_motion(event.xdata, event.ydata)

    def _mpl_release(self, event):
        if self._press is None:
            return
        if event.inaxes is self.ax and event.xdata is not None:
            self.on_release(event.xdata, event.ydata)
        else:
            self.on_release(*self._press["last"])

    def on_press(self, u, v):
        """Mouse button down at display (u, v): remember what is under it (drag target)."""
        x, y = self.to_image(u, v)
        self._press = {
            "start": (u, v),
            "last": (u, v),
            "image": (x, y),
            "viewport": self.viewport,
            "target": self._press_target(x, y),
            "dragging": False,
            "preview": None,
        }

    def on_motion(self, u, v):
        """Mouse moved to display (u, v) with the button down: preview the drag."""
        p = self._press
        if p is None:
            return
        p["last"] = (u, v)
        if not p["dragging"] and np.hypot(u - p["start"][0], v - p["start"][1]) < DRAG_THRESHOLD:
            return
        p["dragging"] = True
        if p["target"][0] == "pan":
            vp = p["viewport"]
            du, dv = u - p["start"][0], v - p["start"][1]
            self._viewports[self._camera] = vp.centred(vp.cx - du / vp.zoom, vp.cy - dv / vp.zoom)
            self.render()
            return
        x, y = p["viewport"].to_image(u, v)
        try:
            p["preview"] = self._drag_to(p, x, y)
        except ValueError:
            return  # e.g. dragged outside the image: keep the last valid preview
        self.render()

    def on_release(self, u, v):
        """Mouse button up at display (u, v): commit the drag, or treat it as a click."""
        p = self._press
        if p is None:
            return
        self.on_motion(u, v)
        self._press = None
        if not p["dragging"]:
            self.on_click(u, v)
        elif p["preview"] is not None:
            self.message = self._drag_message(p)
            self._commit(p["preview"])
        else:
            self.render()

    def _drag_message(self, press):
        """Status after a committed drag (subclasses say what changed)."""
        return ""

    def on_drag(self, u0, v0, u1, v1):
        """Press at display (u0, v0), drag to (u1, v1) and release (a whole drag at once)."""
        self.on_press(u0, v0)
        self.on_motion((u0 + u1) / 2, (v0 + v1) / 2)
        self.on_release(u1, v1)

    # ---------------------------------------------------------------- state plumbing
    #: attribute holding the default file, and the hint when none is given (subclasses)
    _file_attr = "path"
    _file_hint = "no file: type a path or pass one"
    _centre_by_default = False

    def _from_control(self, method, value):
        if not self._syncing:
            method(value)

    def _centre_target(self, state):
        """(x, y) to centre the zoomed view on after a change, or None (subclasses)."""
        return None

    def _commit(self, new_state, *, centre=None):
        self.state = new_state
        self._camera = new_state.camera
        centre = self._centre_by_default if centre is None else centre
        target = self._centre_target(new_state) if centre and self.zoom > 1 else None
        if target is not None:
            self.centre_on(*target)
        self._after_change()

    def _apply(self, fn, *args, centre=None, **kwargs):
        try:
            new = fn(*args, **kwargs)
        except (ValueError, FileNotFoundError) as exc:
            self._report(exc)
            self.render()
            return False
        self.message = ""
        self._commit(new, centre=centre)
        return True

    def undo(self):
        """Undo the last change."""
        self._apply(self.state.undo)

    def _path(self, path):
        path = path if path is not None else (self.path_text.value.strip() or getattr(self, self._file_attr))
        if not path:
            raise ValueError(self._file_hint)
        return Path(path)

    def _write(self, path):
        """Write the state's file to ``path``; return the status message (subclasses)."""
        raise NotImplementedError

    def save(self, path=None):
        """Save to ``path`` or the path box (atomic); returns the path, or None on error."""
        try:
            path = self._path(path)
            message = self._write(path)
        except (ValueError, OSError) as exc:
            self._report(exc)
            self.render()
            return None
        setattr(self, self._file_attr, path)
        self.message = message
        self.render()
        return path

    def _report(self, exc):
        self.message = str(exc)
        logger.info("%s", exc)

    def _static_hint(self):
        """Status text that says how to get a clickable figure, when the figure is static."""
        if self._png is None:
            return ""
        return ("static image: clicks are not received. Run <code>%matplotlib widget</code> in a cell "
                "before creating the widget (needs ipympl), or pick with <code>wingphoto pick</code>")

    # ---------------------------------------------------------------- drawing
    def _draw_image(self, img):
        ax = self.ax
        ax.clear()
        ax.set_axis_off()
        lo, hi = _display_range(img)
        ax.imshow(img, cmap="gray", vmin=lo, vmax=hi, extent=self.viewport.extent, interpolation="nearest")
        (x0, x1), (y0, y1) = self.viewport.limits
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)

    def _show(self):
        if self._png is None:
            self.fig.canvas.draw_idle()
        elif _in_kernel():  # outside Jupyter (scripts, tests) nobody sees the PNG
            buf = io.BytesIO()
            self.fig.savefig(buf, format="png", dpi=80)
            self._png.value = buf.getvalue()

    def close(self):
        """Close the figure (frees it in pyplot under ipympl)."""
        if self._png is None:
            import matplotlib.pyplot as plt

            plt.close(self.fig)

    def _ipython_display_(self):
        """display(view) shows the widget; headless (nbmake, CI) the figure and status as they are."""
        from IPython.display import HTML, display

        if headless():
            self.render()
            display(HTML(self.status.value))
            display(_png(self.fig))
            return
        display(self.widget)


class Picker(ImageView):
    """Pick the markers of one frame in the left (and right) view.

    Parameters
    ----------
    frames_left : (T, H, W) array, sequence of images, or (H, W) image
        Left view (anything indexable with ``len``, e.g. ``wingphoto.io.read_sequence``).
    frames_right : same, optional
        Right view; None picks the left view only.
    n_points : int, optional
        Number of markers expected (numbers 0 .. n_points - 1).
    picks_path : str or Path, optional
        File that Save and Load use (JSON, :meth:`PickerState.save`).
    frame : int
        Frame to pick in (default the first, where tracking starts).
    half_size : (half_w, half_h)
        Initial subimage rectangle half size in px for new markers.
    state : PickerState, optional
        Start from this state (e.g. loaded picks) instead of an empty one.
    figsize : (w, h)
        Figure size in inches.

    Attributes
    ----------
    state : PickerState
        The picks; read ``state.to_frame("left")`` for the tracker.
    widget : ipywidgets.VBox
        Controls and figure; display it in the notebook.
    fig, ax : matplotlib Figure and Axes
    message : str
        The last error or information shown in the status line.

    Notes
    -----
    Mouse: a click places the active marker (then the next number is active); drag a
    marker's rectangle inside to move it, its edge to resize it; drag elsewhere to pan when
    zoomed. Buttons: Move (the next click moves the active marker), Delete, Undo, Save,
    Load. Markers are numbered from 0, leading edge to trailing edge and tip to root, with
    the same number in both views (``docs/conventions.md``).

    Examples
    --------
    >>> import numpy as np
    >>> frames = np.zeros((2, 40, 60), np.uint8)
    >>> p = Picker(frames, frames, n_points=2)
    >>> p.on_click(10.0, 12.0); p.on_click(30.0, 20.0)
    >>> p.set_camera("right"); p.on_click(11.0, 12.0); p.on_click(31.0, 20.0)
    >>> p.state.is_complete, p.state.to_picks("right").tolist()
    (True, [[11.0, 12.0], [31.0, 20.0]])
    """

    def __init__(self, frames_left, frames_right=None, *, n_points=None, picks_path=None, frame=0,
                 half_size=(10.0, 10.0), state=None, figsize=(6.0, 6.0)):
        self.frames = {"left": frames_left}
        if frames_right is not None:
            self.frames["right"] = frames_right
        self.images = {cam: frame_image(f, frame) for cam, f in self.frames.items()}
        sizes = {cam: (img.shape[1], img.shape[0]) for cam, img in self.images.items()}
        self.frame = int(frame)
        self.picks_path = None if picks_path is None else Path(picks_path)
        cameras = tuple(self.frames)
        size_right = sizes.get("right") if sizes.get("right") != sizes["left"] else None
        if state is None:
            state = PickerState(image_size=sizes["left"], image_size_right=size_right, cameras=cameras,
                                n_points=n_points, half_size=half_size, frame=self.frame)
        self._check_compatible(state)
        self.state = dataclasses.replace(self._fill_sizes(state), frame=self.frame)
        self._camera = self.state.camera
        self._move_armed = False
        self._init_view(sizes, figsize)
        self._build_controls()
        self._after_change()

    # ---------------------------------------------------------------- construction
    @classmethod
    def load_or_pick(cls, frames_left, frames_right=None, *, picks_path, **kwargs):
        """Open a picker on saved picks when ``picks_path`` exists, otherwise an empty one.

        This is the notebooks' headless path: under ``WINGPHOTO_HEADLESS=1`` (nbmake, CI)
        the saved picks are required, so nothing waits for clicks.

        Parameters
        ----------
        frames_left, frames_right, **kwargs
            As for :class:`Picker`.
        picks_path : str or Path
            Saved picks (JSON). Save and Load use it too.

        Returns
        -------
        Picker

        Raises
        ------
        FileNotFoundError
            When ``picks_path`` does not exist and nobody can click: in headless mode
            (``WINGPHOTO_HEADLESS=1``) or outside a Jupyter kernel (a script); the message
            says how to make the file (``wingphoto pick``).
        """
        path = Path(picks_path)
        if path.is_file():
            state = PickerState.load(path)
            return cls(frames_left, frames_right, picks_path=path, state=state, **kwargs)
        if headless():
            raise FileNotFoundError(
                f"WINGPHOTO_HEADLESS is set but the picks file {path} does not exist; run the picker "
                "interactively once and press Save, or unset WINGPHOTO_HEADLESS"
            )
        if not _in_kernel():
            raise FileNotFoundError(
                f"picks file {path} does not exist and there is no notebook to click in; make it with "
                f"`wingphoto pick FRAMES_LEFT FRAMES_RIGHT --out {path}` (a window to click in), in a "
                "notebook with this picker, or write the CSV of docs/picks.md by hand"
            )
        return cls(frames_left, frames_right, picks_path=path, **kwargs)

    def _check_compatible(self, state):
        if tuple(state.cameras) != tuple(self.frames):
            raise ValueError(
                f"the picks are for cameras {state.cameras} but frames were given for {tuple(self.frames)}; "
                "pass frames_right exactly when the picks have a right view"
            )
        for cam, img in self.images.items():
            size = state.size_of(cam)
            if size is not None and size != (img.shape[1], img.shape[0]):
                raise ValueError(
                    f"the picks were made on {cam} images of size {size} (width, height) but the {cam} "
                    f"frames are {img.shape[1]}x{img.shape[0]}; load the picks made for these images"
                )

    def _fill_sizes(self, state):
        if state.image_size is None:
            right = self.images.get("right")
            size_right = None if right is None else (right.shape[1], right.shape[0])
            left = (self.images["left"].shape[1], self.images["left"].shape[0])
            state = dataclasses.replace(state, image_size=left,
                                        image_size_right=size_right if size_right != left else None)
        return state

    def _build_controls(self):
        s = self.state
        self.camera_toggle = W.ToggleButtons(options=list(s.cameras), value=s.camera, description="View")
        upper = s.n_points - 1 if s.n_points is not None else 9999
        self.point_box = W.BoundedIntText(value=s.current, min=0, max=upper, description="Point",
                                          layout=W.Layout(width="150px"))
        self.prev_button = W.Button(description="◀ Prev", layout=W.Layout(width="80px"))
        self.next_button = W.Button(description="Next ▶", layout=W.Layout(width="80px"))
        self.zoom_slider = W.FloatSlider(value=1.0, min=1.0, max=8.0, step=0.5, description="Zoom",
                                         continuous_update=False)
        # one event per drag of the slider, so one drag is one undo step
        self.box_slider = W.IntSlider(value=int(round(s.half_size[0])), min=1, max=100, description="Box ±px",
                                      continuous_update=False)
        self.move_button = W.Button(description="Move", tooltip="the next click moves the active marker")
        self.delete_button = W.Button(description="Delete", tooltip="delete the active marker in this view")
        self.undo_button = W.Button(description="Undo")
        self.save_button = W.Button(description="Save", button_style="success")
        self.load_button = W.Button(description="Load")
        self.path_text = W.Text(value="" if self.picks_path is None else str(self.picks_path),
                                description="File", placeholder="picks.json")
        self.status = W.HTML()

        self.camera_toggle.observe(lambda ch: self._from_control(self.set_camera, ch["new"]), "value")
        self.point_box.observe(lambda ch: self._from_control(self.select_point, ch["new"]), "value")
        self.zoom_slider.observe(lambda ch: self._from_control(self.set_zoom, ch["new"]), "value")
        self.box_slider.observe(lambda ch: self._from_control(self.set_box, ch["new"]), "value")
        self.prev_button.on_click(lambda _: self.next_point(-1))
        self.next_button.on_click(lambda _: self.next_point(1))
        self.move_button.on_click(lambda _: self.arm_move())
        self.delete_button.on_click(lambda _: self.delete())
        self.undo_button.on_click(lambda _: self.undo())
        self.save_button.on_click(lambda _: self.save())
        self.load_button.on_click(lambda _: self.load())
        # the status line (instructions, save confirmations, errors) sits with the controls,
        # above the figure, so it is in sight of the buttons in a normal window
        self.widget = W.VBox([
            W.HBox([self.camera_toggle, self.point_box, self.prev_button, self.next_button]),
            W.HBox([self.zoom_slider, self.box_slider]),
            W.HBox([self.move_button, self.delete_button, self.undo_button, self.save_button,
                    self.load_button, self.path_text]),
            self.status,
            self._canvas_widget,
        ])

    # ---------------------------------------------------------------- state changes
    _file_attr = "picks_path"
    _file_hint = "no picks file: type a path in File (e.g. picks.json) or pass picks_path"

    def _centre_target(self, state):
        pick = state.get(self._camera, state.current)
        return None if pick is None else (pick.x, pick.y)

    def _after_change(self):
        self._camera = self.state.camera
        self._syncing = True
        try:
            self.camera_toggle.value = self.state.camera
            self.point_box.value = self.state.current
            self.zoom_slider.value = self.zoom
            self.box_slider.value = int(round(self.state.half_size[0]))
            self.undo_button.disabled = not self.state.can_undo
            self.move_button.description = "Move: click!" if self._move_armed else "Move"
        finally:
            self._syncing = False
        self.render()

    # ---------------------------------------------------------------- handlers
    def on_click(self, u, v):
        """Click at display (u, v): place the active marker there (or move it, after Move)."""
        x, y = self.to_image(u, v)
        if self._move_armed:
            self._move_armed = False
            self._apply(self.state.move, self._camera, self.state.current, x, y)
            return
        placed = self.state.get(self._camera, self.state.current)
        if placed is not None:  # never move a placed marker by a stray click
            if self.state.missing()[self._camera] == [] and self.state.n_points is not None:
                what = f"all {self.state.n_points} markers are placed in the {self._camera} view"
            else:
                what = f"point {placed.point} is already placed in the {self._camera} view"
            self._report(ValueError(
                f"{what}; this click was ignored. Drag a marker's box to move it, press Move to re-place "
                f"point {placed.point}, choose another number, or switch view"))
            self.render()
            return
        self._apply(self.state.place, self._camera, x, y)

    def _press_target(self, x, y):
        picks = sorted(self.state.picks_of(self._camera), key=lambda p: p.point != self.state.current)
        for p in picks:  # the active marker first
            # the edge band is at most a quarter of the box, so the inside stays grabbable
            tx = min(GRAB_TOLERANCE / self.zoom, 0.25 * p.half_w)
            ty = min(GRAB_TOLERANCE / self.zoom, 0.25 * p.half_h)
            dx, dy = abs(x - p.x), abs(y - p.y)
            on_x_edge = abs(dx - p.half_w) <= tx and dy <= p.half_h + ty
            on_y_edge = abs(dy - p.half_h) <= ty and dx <= p.half_w + tx
            if on_x_edge or on_y_edge:
                return ("resize", p, (on_x_edge, on_y_edge))
        for p in picks:
            if abs(x - p.x) <= p.half_w and abs(y - p.y) <= p.half_h:
                return ("move", p)
        return ("pan", None)

    def _drag_to(self, press, x, y):
        kind, pick = press["target"][:2]
        edges = None if kind == "move" else press["target"][2]
        return self.state.drag(self._camera, pick.point, press["image"], (x, y), edges=edges).select(pick.point)

    def _drag_message(self, press):
        kind, pick = press["target"][:2]
        new = press["preview"].get(self._camera, pick.point)
        if kind == "move":
            return f"point {pick.point} moved to ({new.x:.1f}, {new.y:.1f})"
        return f"point {pick.point} box resized to ±{new.half_w:.1f} x ±{new.half_h:.1f} px"

    # ---------------------------------------------------------------- controls as methods
    def set_camera(self, camera):
        """Show and pick in ``camera`` ('left' or 'right')."""
        self._apply(self.state.select, camera=camera, centre=True)

    def select_point(self, point):
        """Make ``point`` the active marker number."""
        self._apply(self.state.select, point, centre=True)

    def next_point(self, step=1):
        """Select the next (``step=-1``: previous) marker number."""
        self._apply(self.state.next_point, step, centre=True)

    def set_zoom(self, zoom):
        """Magnify the view (1 shows the whole image), centred on the active marker if placed."""
        try:
            pick = self.state.get(self._camera, self.state.current)
            self._set_viewports(float(zoom), None if pick is None else (pick.x, pick.y))
        except ValueError as exc:
            self._report(exc)
        self._after_change()

    def set_box(self, half):
        """Set the rectangle half size (px) for new markers and resize the active one."""
        half = float(half)
        new = self.state.set_half_size(half, half) if half > 0 else self.state
        if half > 0 and new.get(self._camera, new.current) is not None:
            new = new.resize(self._camera, new.current, half, half)
        if half <= 0:
            self._report(ValueError(f"box half size must be positive, got {half}"))
        self._commit(new)

    def arm_move(self):
        """Make the next click move the active marker instead of placing the next one."""
        if self.state.get(self._camera, self.state.current) is None:
            self._report(ValueError(f"point {self.state.current} is not placed in the {self._camera} view yet"))
            self.render()
            return
        self._move_armed = True
        self.message = f"click the new position of point {self.state.current}"
        self._after_change()

    def delete(self, point=None):
        """Delete the active marker (or ``point``) from the view shown."""
        self._apply(self.state.delete, self._camera, self.state.current if point is None else point)

    def undo(self):
        """Undo the last edit."""
        self._move_armed = False
        self._apply(self.state.undo)

    def _write(self, path):
        """Save the picks as JSON (see :meth:`ImageView.save`); the folder is made if needed."""
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        self.state.save(path)
        message = f"saved {self.state.n_rows} markers to {path}"
        if not self.state.is_complete:
            message += " (incomplete: " + html.escape(str(self.state.missing())) + ")"
        return message

    def load(self, path=None):
        """Load picks from ``path`` or the File box (undoable)."""
        try:
            path = self._path(path)
            loaded = dataclasses.replace(self._fill_sizes(PickerState.load(path)), frame=self.frame)
            self._check_compatible(loaded)
        except (ValueError, FileNotFoundError) as exc:
            self._report(exc)
            self.render()
            return
        snapshot = dataclasses.replace(self.state, history=())
        self.picks_path = path
        self._commit(dataclasses.replace(loaded, history=(snapshot,) + self.state.history))
        self.message = f"loaded {path}"
        self.render()

    # ---------------------------------------------------------------- rendering
    def render(self):
        """Redraw the image, the rectangles and numbers of the view shown, and the status."""
        state = self.state
        if self._press is not None and self._press.get("preview") is not None:
            state = self._press["preview"]
        cam = self._camera
        self._draw_image(self.images[cam])
        vp = self.viewport
        for p in state.picks_of(cam):
            active = p.point == state.current
            colour = "yellow" if active else "cyan"
            u0, v0 = vp.to_display(p.x - p.half_w, p.y - p.half_h)
            self.ax.add_patch(Rectangle((u0, v0), 2 * p.half_w * vp.zoom, 2 * p.half_h * vp.zoom,
                                        fill=False, edgecolor=colour, linewidth=1.5 if active else 1.0))
            u, v = vp.to_display(p.x, p.y)
            self.ax.plot([u], [v], "+", color=colour, markersize=8)
            _number_label(self.ax, u, v, p.point, colour)
        missing = state.missing()
        parts = [f"<b>{cam}</b> view, frame {self.frame}, active point <b>{state.current}</b>"]
        counts = [f"{c}: {len(state.numbers(c))} placed" + (f", missing {missing[c]}" if missing[c] else "")
                  for c in state.cameras]
        parts.append(" | ".join(counts))
        if state.is_complete:
            parts.append("complete")
        if self.message:
            parts.append(f"<i>{html.escape(self.message)}</i>")
        hint = self._static_hint()
        if hint:
            parts.append(hint)
        self.status.value = "<br>".join(parts)
        self._show()

    # ---------------------------------------------------------------- static figure
    def static_figure(self, *, figsize=None):
        """A figure of the numbered picks on every view (what a reader sees headless).

        Returns
        -------
        matplotlib.figure.Figure
            One panel per camera: the picked frame, each marker's box, centre and number.
        """
        from ..plots import plot_picks

        return plot_picks(self.images, self.state, frame=self.frame, figsize=figsize)

    def _ipython_display_(self):
        """Show the widget; headless (or with no figure to click), the static figure of the picks."""
        from IPython.display import display

        if headless():
            fig = self.static_figure()
            display(_png(fig))
            import matplotlib.pyplot as plt

            plt.close(fig)
            return
        display(self.widget)
