"""``wingphoto check``: look for wrong frames in one sequence, or a left/right pair, before tracking."""
from __future__ import annotations


def add_parser(sub):
    c = sub.add_parser(
        "check",
        help="check a sequence (or a left/right pair) for duplicated, dropped, stray, blank and shifted frames",
        description="Check a sequence for frames that are silently wrong: duplicated frames, numbering gaps "
        "(dropped frames), stray files that do not fit the numbering, blank frames and whole-image jumps "
        "(a bumped camera). With --right, also compare the two views: frame counts, sizes, frame rates, time "
        "stamps and a constant frame offset (exact with --calib). Exit code 0 when nothing was found, 1 "
        "otherwise (the report says what).",
    )
    c.add_argument("frames", help="folder, glob pattern, multi-page TIFF, .cine, .mraw/.cih(x) or video (left view)")
    c.add_argument("--right", default=None, help="the right view, to check the pair against each other")
    c.add_argument("--calib", default=None,
                   help="Calib_Results_stereo.mat: with --right, find a frame offset from epipolar geometry (exact) "
                   "instead of the motion of the images")
    c.add_argument("--jump", type=float, default=2.0, help="smallest whole-image jump reported, px (default 2)")
    c.add_argument("--duplicate-tolerance", type=float, default=0.0,
                   help="mean grey-level difference at or below which a frame is a duplicate (default 0: identical)")
    return c


def run(args):
    from ..integrity import check_sequence, check_stereo_sequences

    if not args.jump > 0:
        raise ValueError(f"--jump must be a positive number of pixels, got {args.jump}")
    if not args.duplicate_tolerance >= 0:
        raise ValueError(f"--duplicate-tolerance must be >= 0, got {args.duplicate_tolerance}")
    options = dict(jump_threshold=args.jump, duplicate_tolerance=args.duplicate_tolerance)
    if args.right is None:
        report = check_sequence(args.frames, **options)
        print(report.summary())
        return 0 if report.ok else 1
    rig = None
    if args.calib is not None:
        from ..io import load_bouguet_stereo

        rig = load_bouguet_stereo(args.calib)[0]
    report = check_stereo_sequences(args.frames, args.right, rig=rig, **options)
    print(report.summary())
    return 0 if report.ok and report.left.ok and report.right.ok else 1
