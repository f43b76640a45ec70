"""``wingphoto demo``: the whole pipeline on a sample folder laid out like data-samples/."""
from __future__ import annotations


def add_parser(sub):
    d = sub.add_parser(
        "demo",
        help="run the whole pipeline on a sample folder (default data-samples/)",
        description="Stereo calibration -> tracking -> triangulation -> analysis on a sample folder laid "
        "out like data-samples/, without interaction (saved picks). Writes results/ and prints a summary.",
    )
    d.add_argument("data", nargs="?", default="data-samples", help="sample folder (default: %(default)s)")
    d.add_argument("--out", default="results", help="output folder (default: %(default)s)")
    d.add_argument("--no-video", action="store_true", help="skip the verification video")
    return d


def run(args):
    from .. import pipeline

    print(pipeline.run_demo(args.data, out=args.out, video=not args.no_video))
    return 0
