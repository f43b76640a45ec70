"""Command line: ``wingphoto COMMAND`` (also ``python -m wingphoto``).

One module per subcommand in this package; each defines ``add_parser(subparsers)`` (its
options and help) and ``run(args) -> int`` (the exit code), and wraps one stage of the
library for work outside the notebooks. :func:`main` turns every expected failure
(``ValueError``, ``FileNotFoundError``, ``OSError``, Ctrl-C) into a one-line message on
stderr and a non-zero exit code: no traceback reaches a user.
Run ``wingphoto COMMAND --help`` for the options.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys

__all__ = ["main", "build_parser", "COMMANDS"]

#: Subcommands in the order ``wingphoto --help`` lists them; each is a module of this package.
COMMANDS = (
    "pantilt",
    "calibrate",
    "pick",
    "check",
    "track",
    "triangulate",
    "analyse",
    "export",
    "batch",
    "demo",
)

_EPILOG = """\
A typical session (folders of TIFF frames, a 9x6 inner-corner board of 30 mm squares):

  wingphoto calibrate --left calib/left --right calib/right --pattern 9x6 --square 30 \\
      --out results/Calib_Results_stereo.mat
  wingphoto pick flap/left flap/right --out picks.json    # click the markers (docs/picks.md)
  wingphoto track --frames flap/left --picks picks.json --camera left --out results/tracks_left.csv
  wingphoto track --frames flap/right --picks picks.json --camera right --out results/tracks_right.csv
  wingphoto triangulate --calib results/Calib_Results_stereo.mat \\
      --left results/tracks_left.csv --right results/tracks_right.csv --out results/points3d.csv

  wingphoto demo data-samples --out results      # the whole pipeline on the bundled sample

Conventions (pixel origin at the centre of the top-left pixel, mm, the toolbox's names):
docs/conventions.md.
"""


def _command_module(name):
    return importlib.import_module(f"{__name__}.{name.replace('-', '_')}")


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
    for name in COMMANDS:
        _command_module(name).add_parser(sub)
    return p


def main(argv=None):
    """Entry point of the ``wingphoto`` command; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(_command_module(args.command).run(args) or 0)
    except KeyboardInterrupt:
        print(f"wingphoto {args.command}: interrupted", file=sys.stderr)
        return 130
    except (ValueError, FileNotFoundError, OSError) as exc:
        print(f"wingphoto {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
