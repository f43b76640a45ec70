"""Marker picker in a plain matplotlib window (no Jupyter): ``wingphoto pick``.

The same rules as the notebook picker, because the same :class:`PickerState` does the
work: markers are numbered from 0 (leading edge to trailing edge, tip to root, the same
number in both views); a click places the active number and the next missing number
becomes active; a click never moves a placed marker (drag its box, or press ``m`` first);
dragging inside a box moves the marker, dragging its edge resizes that side.

Both views are shown side by side in image pixels, so the axes' data coordinates *are*
image pixels and the window's coordinate readout shows them. Zoom with the scroll wheel
(centred on the mouse) or the toolbar's zoom/pan tools (clicks are not picks while a tool
is active). Keys: ``n``/``p`` next/previous number, ``m`` move the active marker with the
next click, ``d`` delete the active marker, ``u`` (or ctrl+z) undo, ``+``/``-`` grow/shrink
the active box, ``s`` save, ``q`` save and close.

The handlers (:meth:`WindowPicker.on_press`, :meth:`~WindowPicker.on_motion`,
:meth:`~WindowPicker.on_release`, :meth:`~WindowPicker.on_key`) take a camera and image
pixels, so tests drive them without a display.
"""
from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import numpy as np

from .state import PickerState

__all__ = ["WindowPicker", "KEYS"]

logger = logging.getLogger(__name__)

#: key -> what it does (shown in the window's help line and ``wingphoto pick --help``)
KEYS = {
    "n / p": "next / previous marker number",
    "m": "the next click moves the active marker",
    "d": "delete the active marker in the view under the mouse (or the last view clicked)",
    "u, ctrl+z": "undo",
    "+ / -": "grow / shrink the active marker's box by 1 px",
    "s": "save",
    "q": "save and close",
    "scroll": "zoom in / out around the mouse",
}
DRAG_THRESHOLD_PX = 3.0  # screen px a press must travel to become a drag
GRAB_PX = 5.0  # screen px around a box edge that grabs it


def _display_range(img):
    finite = img[np.isfinite(img)] if img.dtype.kind == "f" else img
    if finite.size == 0:
        return 0.0, 1.0
    lo, hi = np.percentile(finite, [0.5, 99.8])
    return float(lo), float(hi if hi > lo else lo + 1)


class WindowPicker:
    """Pick markers in a matplotlib figure, one panel per view.

    Parameters
    ----------
    images : dict
        ``{"left": (H, W) image, "right": (H, W) image}`` (or left only): the frame to pick in.
    out : str or Path
        Picks file to save (``.json`` or ``.csv``, ``docs/picks.md``).
    frame : int
        Frame number the images are (saved with each pick).
    n_points : int, optional
        Number of markers expected.
    half_size : float
        Default subimage half size (px) of a new marker.
    state : PickerState, optional
        Start from these picks (e.g. to continue a saved file).
    figure : matplotlib Figure, optional
        Figure to draw in (default a new pyplot figure).

    Attributes
    ----------
    state : PickerState
    message : str
        Last information or error (also in the figure's title line).
    """

    def __init__(self, images, out, *, frame=0, n_points=None, half_size=10.0, state=None, figure=None):
        self.images = {c: np.asarray(images[c]) for c in ("left", "right") if c in images}
        if "left" not in self.images:
            raise ValueError("images must hold at least the left view")
        for cam, img in self.images.items():
            if img.ndim != 2:
                raise ValueError(f"the {cam} image must be 2D (H, W) grey levels, got shape {img.shape}")
        self.out = Path(out)
        sizes = {c: (img.shape[1], img.shape[0]) for c, img in self.images.items()}
        right = sizes.get("right")
        if state is None:
            state = PickerState(image_size=sizes["left"], image_size_right=right if right != sizes["left"] else None,
                                cameras=tuple(self.images), n_points=n_points,
                                half_size=(float(half_size), float(half_size)), frame=frame)
        else:
            if tuple(state.cameras) != tuple(self.images):
                raise ValueError(f"the picks are for cameras {state.cameras} but images of {tuple(self.images)} "
                                 "were given")
            state = dataclasses.replace(state, image_size=sizes["left"],
                                        image_size_right=right if right != sizes["left"] else None, frame=frame)
        self.state = state
        self.frame = int(frame)
        self.message = "click the markers in numbering order (0 = leading edge at the tip); h: keys in the terminal"
        self.saved = None
        self._press = None
        self._move_armed = False
        if figure is None:
            import matplotlib.pyplot as plt

            figure = plt.figure(figsize=(6.0 * len(self.images), 6.5))
        self.fig = figure
        n = len(self.images)
        self.axes = {}
        for k, cam in enumerate(self.images):
            ax = self.fig.add_subplot(1, n, k + 1)
            img = self.images[cam]
            lo, hi = _display_range(img)
            ax.imshow(img, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
            ax.set_xlabel("x (px)")
            ax.set_ylabel("y (px)")
            self.axes[cam] = ax
        self._artists = []
        self.fig.subplots_adjust(left=0.06, right=0.98, bottom=0.07, top=0.86, wspace=0.2)
        c = self.fig.canvas
        c.mpl_connect("button_press_event", self._mpl_press)
        c.mpl_connect("motion_notify_event", self._mpl_motion)
        c.mpl_connect("button_release_event", self._mpl_release)
        c.mpl_connect("key_press_event", self._mpl_key)
        c.mpl_connect("scroll_event", self._mpl_scroll)
        self.render()

    # ---------------------------------------------------------------- matplotlib events
    def _camera_of(self, event):
        for cam, ax in self.axes.items():
            if event.inaxes is ax:
                return cam
        return None

    def _tool_active(self):
        toolbar = getattr(self.fig.canvas, "toolbar", None)
        return bool(getattr(toolbar, "mode", ""))

    def _mpl_press(self, event):
        cam = self._camera_of(event)
        if cam is None or event.button != 1 or event.xdata is None or self._tool_active():
            return
        self.on_press(cam, event.xdata, event.ydata)

    def _mpl_motion(self, event):
        if self._press is None or self._camera_of(event) != self._press["camera"] or event.xdata is None:
            return
        self.on_motion(event.xdata, event.ydata)

    def _mpl_release(self, event):
        if self._press is None:
            return
        if self._camera_of(event) == self._press["camera"] and event.xdata is not None:
            self.on_release(event.xdata, event.ydata)
        else:
            self.on_release(*self._press["last"])

    def _mpl_key(self, event):
        if event.key is not None:
            cam = self._camera_of(event)
            self.on_key(event.key, camera=cam)

    def _mpl_scroll(self, event):
        cam = self._camera_of(event)
        if cam is None or event.xdata is None:
            return
        self.zoom(cam, 1.5 if event.button == "up" else 1 / 1.5, event.xdata, event.ydata)

    # ---------------------------------------------------------------- handlers (image px)
    def _screen_per_px(self, camera):
        """Screen pixels per image pixel in the panel of ``camera`` (its current zoom)."""
        ax = self.axes[camera]
        (x0, y0), (x1, _) = ax.transData.transform([(0.0, 0.0), (1.0, 0.0)])
        return max(abs(x1 - x0), 1e-9)

    def _target(self, camera, x, y):
        scale = self._screen_per_px(camera)
        picks = sorted(self.state.picks_of(camera), key=lambda p: p.point != self.state.current)
        for p in picks:
            tx = min(GRAB_PX / scale, 0.25 * p.half_w)
            ty = min(GRAB_PX / scale, 0.25 * p.half_h)
            dx, dy = abs(x - p.x), abs(y - p.y)
            x_edge = abs(dx - p.half_w) <= tx and dy <= p.half_h + ty
            y_edge = abs(dy - p.half_h) <= ty and dx <= p.half_w + tx
            if x_edge or y_edge:
                return ("resize", p, (x_edge, y_edge))
        for p in picks:
            if abs(x - p.x) <= p.half_w and abs(y - p.y) <= p.half_h:
                return ("move", p, None)
        return ("click", None, None)

    def on_press(self, camera, x, y):
        """Button down at image pixel (x, y) of ``camera``."""
        self._press = {"camera": camera, "start": (x, y), "last": (x, y), "target": self._target(camera, x, y),
                       "dragging": False, "preview": None}

    def on_motion(self, x, y):
        """Mouse moved to (x, y) with the button down: preview the drag of a box."""
        p = self._press
        if p is None:
            return
        p["last"] = (x, y)
        moved = np.hypot(x - p["start"][0], y - p["start"][1]) * self._screen_per_px(p["camera"])
        if not p["dragging"] and moved < DRAG_THRESHOLD_PX:
            return
        p["dragging"] = True
        kind, pick, edges = p["target"]
        if kind == "click":
            return
        x0, y0 = p["start"]
        try:
            p["preview"] = self.state.drag(p["camera"], pick.point, (x0, y0), (x, y),
                                           edges=None if kind == "move" else edges)
            p["preview"] = p["preview"].select(pick.point, camera=p["camera"])
        except ValueError as exc:
            self.message = str(exc)
        self.render()

    def on_release(self, x, y):
        """Button up at (x, y): commit a drag, or treat it as a click."""
        p = self._press
        if p is None:
            return
        self.on_motion(x, y)
        self._press = None
        if not p["dragging"]:
            self.click(p["camera"], *p["start"])
        elif p["preview"] is not None:
            self.state = p["preview"]
            self.message = f"point {self.state.current} adjusted in the {p['camera']} view"
            self.render()
        else:
            self.render()

    def click(self, camera, x, y):
        """A click at image pixel (x, y) of ``camera``: place the active marker (or move it after ``m``)."""
        s = self.state
        try:
            if camera != s.camera:
                s = s.select(camera=camera)
            if self._move_armed:
                self._move_armed = False
                s = s.move(camera, s.current, x, y)
                self.message = f"moved point {s.current}"
            elif s.get(camera, s.current) is not None:
                if not s.missing()[camera] and s.n_points is not None:
                    what = f"all {s.n_points} markers are placed in the {camera} view"
                else:
                    what = f"point {s.current} is already placed in the {camera} view"
                raise ValueError(f"{what}; click ignored (drag a box to move it, m then click to re-place "
                                 f"point {s.current}, n/p to choose another number)")
            else:
                placed = s.current
                s = s.place(camera, x, y)
                self.message = f"placed point {placed} in the {camera} view at ({x:.1f}, {y:.1f})"
        except ValueError as exc:
            self.message = str(exc)
            self.render()
            return
        self.state = s
        self.render()

    def on_key(self, key, camera=None):
        """A key press (see :data:`KEYS`); ``camera`` is the view under the mouse, if any."""
        s = self.state
        cam = camera or s.camera
        try:
            if key == "n":
                self.state = s.next_point(1)
            elif key == "p":
                self.state = s.next_point(-1)
            elif key == "m":
                if s.get(cam, s.current) is None:
                    raise ValueError(f"point {s.current} is not placed in the {cam} view yet")
                self.state = s.select(camera=cam) if cam != s.camera else s
                self.state = self.state.select(s.current)
                self._move_armed = True
                self.message = f"click the new position of point {s.current} in the {cam} view"
            elif key == "d":
                self.state = s.delete(cam, s.current)
                self.message = f"deleted point {s.current} in the {cam} view"
            elif key in ("u", "ctrl+z"):
                self.state = s.undo()
                self.message = "undone" if s.can_undo else "nothing to undo"
            elif key in ("+", "=", "-"):
                pick = s.get(cam, s.current)
                if pick is None:
                    raise ValueError(f"point {s.current} is not placed in the {cam} view")
                step = -1.0 if key == "-" else 1.0
                self.state = s.resize(cam, s.current, max(pick.half_w + step, 1.0), max(pick.half_h + step, 1.0))
            elif key == "s":
                self.save()
            elif key == "q":
                if self.save() is not None:
                    import matplotlib.pyplot as plt

                    plt.close(self.fig)
                    return
            elif key == "h":
                print("\n".join(f"  {k:10s} {v}" for k, v in KEYS.items()))
            else:
                return
        except ValueError as exc:
            self.message = str(exc)
        self.render()

    def zoom(self, camera, factor, x, y):
        """Magnify the panel of ``camera`` by ``factor`` around image pixel (x, y)."""
        ax = self.axes[camera]
        h, w = self.images[camera].shape
        (x0, x1), (y1, y0) = ax.get_xlim(), ax.get_ylim()  # y axis points down
        nx = np.clip((x1 - x0) / factor, 8.0, w)
        ny = np.clip((y1 - y0) / factor, 8.0, h)
        fx = (x - x0) / (x1 - x0) if x1 > x0 else 0.5
        fy = (y - y0) / (y1 - y0) if y1 > y0 else 0.5
        left = np.clip(x - fx * nx, -0.5, w - 0.5 - nx)
        top = np.clip(y - fy * ny, -0.5, h - 0.5 - ny)
        ax.set_xlim(left, left + nx)
        ax.set_ylim(top + ny, top)
        self.render()

    def save(self):
        """Write the picks to :attr:`out` (atomic); returns the path, or None when refused."""
        try:
            self.state.save(self.out)
        except (ValueError, OSError) as exc:
            self.message = f"not saved: {exc}"
            self.render()
            return None
        self.saved = self.out
        missing = {c: m for c, m in self.state.missing().items() if m}
        self.message = f"saved {sum(len(self.state.numbers(c)) for c in self.state.cameras)} picks to {self.out}"
        if missing:
            self.message += f" (incomplete: {missing})"
        logger.info("%s", self.message)
        self.render()
        return self.out

    # ---------------------------------------------------------------- drawing
    def render(self):
        """Draw every box, centre and number, and the status in the figure's title."""
        from matplotlib.patches import Rectangle

        for a in self._artists:
            a.remove()
        self._artists = []
        state = self._press["preview"] if self._press and self._press.get("preview") is not None else self.state
        for cam, ax in self.axes.items():
            for p in state.picks_of(cam):
                active = p.point == state.current
                colour = "yellow" if active else "cyan"
                self._artists.append(ax.add_patch(Rectangle((p.x - p.half_w, p.y - p.half_h), 2 * p.half_w,
                                                            2 * p.half_h, fill=False, edgecolor=colour,
                                                            lw=1.5 if active else 0.8)))
                self._artists += ax.plot([p.x], [p.y], "+", color=colour, ms=8)
                self._artists.append(ax.annotate(
                    str(p.point), (p.x, p.y), xytext=(4, -4), textcoords="offset points", color=colour,
                    fontsize=9, ha="left", va="bottom", annotation_clip=True,
                    bbox=dict(boxstyle="round,pad=0.1", facecolor="black", alpha=0.55, linewidth=0)))
            missing = state.missing()[cam]
            mark = " <- active" if cam == state.camera else ""
            ax.set_title(f"{cam} view, frame {self.frame}: {len(state.numbers(cam))} placed"
                         + (f", missing {missing[:8]}{'...' if len(missing) > 8 else ''}" if missing else "") + mark,
                         fontsize=9)
        head = (f"active point {state.current}" + (" (move: click its new position)" if self._move_armed else "")
                + (" | complete" if state.is_complete else "")
                + "\nkeys: n/p number, m move, d delete, u undo, +/- box, s save, q save+quit, scroll zoom")
        self._title = self.fig.suptitle(head + "\n" + self.message, fontsize=9)
        self.fig.canvas.draw_idle()
