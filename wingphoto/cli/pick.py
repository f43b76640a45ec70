"""``wingphoto pick``: click the markers of the first frame in a window -> picks file."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

_FORMATS = """\
Picks files (docs/picks.md). `wingphoto track --picks` reads either:

  JSON (what this command and the notebook picker save):
    {"format": "wingphoto-picks", "version": 2, "cameras": ["left", "right"],
     "picks": {"left":  [{"point": 0, "frame": 0, "x": 302.0, "y": 168.0, "half_w": 8, "half_h": 8}, ...],
               "right": [...]}}

  CSV (easy to write by hand or from another tool), header required:
    camera,point,frame,x,y,half_w,half_h
    left,0,0,302.0,168.0,8,8
    right,0,0,288.5,170.25,8,8
  frame (default 0) and half_w,half_h (the tracker's subimage half-sizes in px, default 10)
  may be left out.

Pixels: x right, y down, (0, 0) the centre of the top-left pixel. Markers are numbered from
0, leading edge to trailing edge and tip to root, the same number in both views; each
marker once per view, never two on one spot.
"""

_NO_DISPLAY = """\
wingphoto pick: no display to open a window on (DISPLAY/WAYLAND_DISPLAY unset, or no GUI
backend for matplotlib). To make {out}:
  1. on a machine with a screen: wingphoto pick {left} {right} --out {out}
     (over ssh: ssh -X, or install python3-tk / PyQt for a matplotlib window);
  2. in JupyterLab: notebooks/04_picking_markers.ipynb (`make lab`), press Save;
  3. by hand: open frame {frame} of each view in any image viewer that shows pixel
     coordinates, and write a CSV:
       camera,point,frame,x,y,half_w,half_h
       left,0,{frame},302.0,168.0,8,8
       ...
     ({frame_note})
Then: wingphoto track --frames {left} --picks {out} --camera left --out tracks_left.csv
"""


def add_parser(sub):
    from ..widgets.window import KEYS

    keys = "\n".join(f"  {k:10s} {v}" for k, v in KEYS.items())
    p = sub.add_parser(
        "pick",
        help="click the markers in a window -> picks file (JSON or CSV) for `track --picks`",
        description="Open a window with frame FRAME of both views and click the markers in numbering "
        "order (0 = the leading edge at the tip; the same number in both views). A click places the "
        "active number; drag inside a box to move its marker, drag an edge to resize that side of the "
        "subimage; the toolbar and the scroll wheel zoom. Without a display, prints how to make the "
        "picks file otherwise.",
        epilog="Mouse: click = place the active marker (a click never moves a placed one); drag a box = "
        "move; drag a box edge = resize.\nKeys:\n" + keys + "\n\n" + _FORMATS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("frames_left", metavar="FRAMES_LEFT", help="left sequence: folder, glob, multi-page TIFF or recording")
    p.add_argument("frames_right", metavar="FRAMES_RIGHT", nargs="?", default=None,
                   help="right sequence (omit for one camera)")
    p.add_argument("--out", required=True, help="picks file to write: .json (default format) or .csv")
    p.add_argument("--frame", type=int, default=0, help="frame to pick in (default 0, where tracking starts)")
    p.add_argument("--n-points", type=int, default=None, help="number of markers (numbers 0..N-1); optional")
    p.add_argument("--half-size", type=float, default=10.0,
                   help="default subimage half-size in px of a new marker (default 10; shrunk near neighbours)")
    p.add_argument("--continue", dest="resume", action="store_true",
                   help="start from the picks already in --out (add or fix markers)")
    return p


def has_display():
    """True when a matplotlib window can be opened (a GUI backend and, on Linux, a display)."""
    import matplotlib

    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return False
    backend = matplotlib.get_backend().lower()
    return backend not in ("agg", "pdf", "ps", "svg", "cairo", "template") and "inline" not in backend


def _frame(seq, index, name):
    import numpy as np

    n = len(seq)
    if not 0 <= index < n:
        raise ValueError(f"--frame {index} is outside {name}, which has {n} frames (0..{n - 1})")
    img = np.asarray(seq[index])
    if img.ndim != 2:
        raise ValueError(f"frame {index} of {name} has shape {img.shape}; wingphoto pick needs grey-level frames")
    return img


def run(args):
    from ..io import read_sequence

    out = Path(args.out)
    if out.suffix.lower() not in (".json", ".csv"):
        raise ValueError(f"--out {out} must end in .json or .csv (the two picks formats, docs/picks.md)")
    if args.frame < 0:
        raise ValueError(f"--frame must be >= 0, got {args.frame}")
    if args.half_size <= 0:
        raise ValueError(f"--half-size must be positive pixels, got {args.half_size}")
    if args.n_points is not None and args.n_points < 1:
        raise ValueError(f"--n-points must be >= 1, got {args.n_points}")
    images = {"left": _frame(read_sequence(args.frames_left), args.frame, args.frames_left)}
    if args.frames_right is not None:
        images["right"] = _frame(read_sequence(args.frames_right), args.frame, args.frames_right)
    if not has_display():
        note = "frame is the frame you picked in; half_w,half_h may be left out"
        print(_NO_DISPLAY.format(out=out, left=args.frames_left, right=args.frames_right or "", frame=args.frame,
                                 frame_note=note), file=sys.stderr)
        return 1
    from ..widgets.state import PickerState
    from ..widgets.window import WindowPicker
    import matplotlib.pyplot as plt

    state = None
    if args.resume and out.is_file():
        state = PickerState.load(out)
    picker = WindowPicker(images, out, frame=args.frame, n_points=args.n_points, half_size=args.half_size,
                          state=state)
    print("click the markers in numbering order; q saves and closes (keys: wingphoto pick --help)")
    plt.show()
    if picker.saved is None:
        print(f"window closed without saving: {out} not written (press s or q to save)", file=sys.stderr)
        return 1
    n = {c: len(picker.state.numbers(c)) for c in picker.state.cameras}
    print(f"wrote {out}: " + ", ".join(f"{k} markers {c}" for c, k in n.items()))
    return 0
