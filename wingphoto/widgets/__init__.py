"""Interactive marker picker and tracking review for Jupyter (ipywidgets + ipympl).

The pure state (:mod:`wingphoto.widgets.state`) imports no widget library and is what the
tests exercise; the views (:class:`Picker`, :class:`TrackReview`) are imported lazily so
that ``import wingphoto.widgets.state`` never pulls in ipywidgets or matplotlib.

Use ``%matplotlib widget`` (ipympl) in the notebook to click in the figure; with another
backend the figure is shown as a static image and the buttons still work.
"""
from .state import (
    Correction,
    Pick,
    PickerState,
    ReviewState,
    Viewport,
    apply_corrections,
    read_corrections,
    replay_corrections,
    write_corrections,
)

__all__ = [
    "Picker",
    "TrackReview",
    "WindowPicker",
    "headless",
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


def __getattr__(name):
    if name == "Picker":
        from .picker import Picker

        return Picker
    if name == "headless":
        from .picker import headless

        return headless
    if name == "WindowPicker":
        from .window import WindowPicker

        return WindowPicker
    if name == "TrackReview":
        from .review import TrackReview

        return TrackReview
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
