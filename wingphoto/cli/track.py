"""``wingphoto track``: track the picked markers through one camera's sequence -> tracks CSV."""
from __future__ import annotations


def add_parser(sub):
    t = sub.add_parser(
        "track",
        help="track markers through one camera's sequence -> tracks CSV",
        description="Track the picked markers through an image sequence (folder, glob or multi-page "
        "TIFF). Points the tracker is unsure of are flagged or lost, never guessed; review them in the "
        "tracking notebook.",
    )
    t.add_argument("--frames", required=True,
                   help="folder, glob pattern, multi-page TIFF, Phantom .cine, Photron .mraw/.cih(x) or video file")
    t.add_argument("--picks", required=True,
                   help="picks file: the JSON that `wingphoto pick` or the picker widget saves, or a CSV with "
                   "columns camera,point,frame,x,y[,half_w,half_h] (px; docs/picks.md, `wingphoto pick --help`)")
    t.add_argument("--camera", default="left", choices=["left", "right"], help="which view's picks to use")
    t.add_argument("--out", required=True, help="output tracks CSV")
    t.add_argument("--checkpoint", default=None,
                   help="checkpoint file (.npz): saved while tracking and on Ctrl-C; a rerun resumes from it")
    t.add_argument("--checkpoint-every", type=_positive_int, default=500, metavar="N",
                   help="frames between two checkpoint saves (default 500)")
    t.add_argument("--max-sigma", type=float, default=None, metavar="PX",
                   help="largest positional uncertainty (px) of an ok point (default 0.25)")
    t.add_argument("--bidirectional", action="store_true",
                   help="also track backwards and flag points where the two passes disagree (fb_disagree); "
                        "about twice the time")
    t.add_argument("--force", action="store_true",
                   help="track despite a failed sequence check (duplicated frames, stray files; `wingphoto check`)")
    return t


def _positive_int(text):
    import argparse

    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of frames, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1 frame, got {v}")
    return v


def run(args):
    import sys

    from .. import pipeline

    try:
        tracks = pipeline.track_folder(args.frames, args.picks, camera=args.camera, out=args.out,
                                       checkpoint=args.checkpoint, force=getattr(args, "force", False),
                                       checkpoint_every=args.checkpoint_every, max_sigma=args.max_sigma,
                                       bidirectional=getattr(args, "bidirectional", False))
    except KeyboardInterrupt:
        if args.checkpoint:
            print(f"wingphoto track: interrupted; progress saved in {args.checkpoint}: run the same command "
                  "again to resume", file=sys.stderr)
        else:
            print("wingphoto track: interrupted; nothing saved (give --checkpoint FILE to be able to resume)",
                  file=sys.stderr)
        return 130
    counts = tracks["status"].value_counts().to_dict()
    print(f"tracked {tracks['point'].nunique()} points over {tracks['frame'].nunique()} frames: {counts}")
    print(f"wrote {args.out}")
    return 0
