"""Command line: ``wingphoto calibrate | track | triangulate | demo`` (also ``python -m wingphoto``).

Each subcommand wraps one stage of :mod:`wingphoto.pipeline` for batch work outside the
notebooks. Run ``wingphoto SUBCOMMAND --help`` for the options.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

__all__ = ["main", "build_parser"]

_EPILOG = """\
A typical session (folders of TIFF frames, a 9x6 inner-corner board of 30 mm squares):

  wingphoto calibrate --left calib/left --right calib/right --pattern 9x6 --square 30 \\
      --out results/Calib_Results_stereo.mat
  wingphoto track --frames flap/left --picks picks.json --camera left --out results/tracks_left.csv
  wingphoto track --frames flap/right --picks picks.json --camera right --out results/tracks_right.csv
  wingphoto triangulate --calib results/Calib_Results_stereo.mat \\
      --left results/tracks_left.csv --right results/tracks_right.csv --out results/points3d.csv

  wingphoto demo data-samples --out results      # the whole pipeline on the bundled sample

Conventions (pixel origin at the centre of the top-left pixel, mm, the toolbox's names):
docs/conventions.md.
"""


def _pattern(text):
    try:
        cols, rows = (int(v) for v in text.lower().replace(",", "x").split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--pattern must be inner corners per row x per column, e.g. 9x6; got {text!r}"
        ) from None
    if cols < 2 or rows < 2:
        raise argparse.ArgumentTypeError(f"--pattern needs at least 2x2 inner corners, got {text!r}")
    return cols, rows


def build_parser():
    """Return the argparse parser of the ``wingphoto`` command."""
    p = argparse.ArgumentParser(
        prog="wingphoto",
        description="High-speed stereo photogrammetry of flapping wings: calibrate two cameras, "
        "track painted markers, triangulate them to 3D and analyse them.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    c = sub.add_parser(
        "calibrate",
        help="stereo calibration from checkerboard image pairs -> toolbox .mat",
        description="Detect checkerboard corners in synchronized left/right image pairs, calibrate "
        "both cameras and their relative pose (om, T), print the toolbox-style summary with 3-sigma "
        "uncertainties, and write Calib_Results_stereo.mat with the toolbox's variable names.",
    )
    c.add_argument("--left", required=True, help="folder or glob of left calibration images")
    c.add_argument("--right", required=True, help="folder or glob of right calibration images (same count, same order)")
    c.add_argument("--pattern", required=True, type=_pattern, help="inner corners per row x per column, e.g. 9x6")
    c.add_argument("--square", required=True, type=float, help="square size in mm, e.g. 30")
    c.add_argument("--out", default="Calib_Results_stereo.mat", help="output .mat file (default: %(default)s)")

    t = sub.add_parser(
        "track",
        help="track markers through one camera's sequence -> tracks CSV",
        description="Track the picked markers through an image sequence (folder, glob or multi-page "
        "TIFF). Points the tracker is unsure of are flagged or lost, never guessed; review them in the "
        "tracking notebook.",
    )
    t.add_argument("--frames", required=True, help="folder, glob pattern or multi-page TIFF of the sequence")
    t.add_argument("--picks", required=True, help="picks JSON saved by the picker widget (or data-samples' picks.json)")
    t.add_argument("--camera", default="left", choices=["left", "right"], help="which view's picks to use")
    t.add_argument("--out", required=True, help="output tracks CSV")
    t.add_argument("--checkpoint", default=None, help="checkpoint file: a rerun resumes from it")

    g = sub.add_parser(
        "triangulate",
        help="triangulate left/right tracks with a stereo calibration -> 3D points CSV",
        description="Triangulate the trusted (ok/manual/interpolated) left/right observations with the "
        "toolbox's stereo_triangulation; writes frame, point, X, Y, Z (mm, left camera frame), reproj_err (px).",
    )
    g.add_argument("--calib", required=True, help="Calib_Results_stereo.mat (ours or the toolbox's)")
    g.add_argument("--left", required=True, help="left tracks CSV")
    g.add_argument("--right", required=True, help="right tracks CSV")
    g.add_argument("--out", required=True, help="output 3D points CSV")

    d = sub.add_parser(
        "demo",
        help="run the whole pipeline on a sample folder (default data-samples/)",
        description="Stereo calibration -> tracking -> triangulation -> analysis on a sample folder laid "
        "out like data-samples/, without interaction (saved picks). Writes results/ and prints a summary.",
    )
    d.add_argument("data", nargs="?", default="data-samples", help="sample folder (default: %(default)s)")
    d.add_argument("--out", default="results", help="output folder (default: %(default)s)")
    d.add_argument("--no-video", action="store_true", help="skip the verification video")
    return p


def main(argv=None):
    """Entry point of the ``wingphoto`` command; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    if args.command is None:
        parser.print_help()
        return 2
    from . import pipeline

    try:
        if args.command == "calibrate":
            result = pipeline.calibrate_folders(args.left, args.right, args.pattern, args.square, out=args.out)
            print(result.summary())
            print(f"\nwrote {args.out}")
        elif args.command == "track":
            tracks = pipeline.track_folder(args.frames, args.picks, camera=args.camera, out=args.out, checkpoint=args.checkpoint)
            counts = tracks["status"].value_counts().to_dict()
            print(f"tracked {tracks['point'].nunique()} points over {tracks['frame'].nunique()} frames: {counts}")
            print(f"wrote {args.out}")
        elif args.command == "triangulate":
            points = pipeline.triangulate_files(args.calib, args.left, args.right, out=args.out)
            print(f"triangulated {points[['X']].notna().sum().iloc[0]} of {len(points)} point-frames; "
                  f"median reprojection error {points['reproj_err'].median():.3f} px")
            print(f"wrote {args.out}")
        elif args.command == "demo":
            summary = pipeline.run_demo(args.data, out=args.out, video=not args.no_video)
            print(summary)
    except (ValueError, FileNotFoundError) as exc:
        print(f"wingphoto {args.command}: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
