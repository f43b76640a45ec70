"""``wingphoto calibrate``: stereo calibration from checkerboard image pairs -> toolbox .mat."""
from __future__ import annotations

from ._args import pattern_size


def add_parser(sub):
    c = sub.add_parser(
        "calibrate",
        help="stereo calibration from checkerboard image pairs -> toolbox .mat",
        description="Detect checkerboard corners in synchronized left/right image pairs, calibrate "
        "both cameras and their relative pose (om, T), print the toolbox-style summary with 3-sigma "
        "uncertainties, and write Calib_Results_stereo.mat with the toolbox's variable names.",
    )
    c.add_argument("--left", required=True, help="folder or glob of left calibration images")
    c.add_argument("--right", required=True, help="folder or glob of right calibration images (same count, same order)")
    c.add_argument("--pattern", required=True, type=pattern_size, help="inner corners per row x per column, e.g. 9x6")
    c.add_argument("--square", required=True, type=float, help="square size in mm, e.g. 30")
    c.add_argument("--out", default="Calib_Results_stereo.mat", help="output .mat file (default: %(default)s)")
    return c


def run(args):
    from .. import pipeline

    result = pipeline.calibrate_folders(args.left, args.right, args.pattern, args.square, out=args.out)
    print(result.summary())
    print(f"\nwrote {args.out}")
    return 0
