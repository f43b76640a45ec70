"""``wingphoto triangulate``: left/right tracks + a stereo calibration -> 3D points CSV."""
from __future__ import annotations


def add_parser(sub):
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
    g.add_argument("--force", action="store_true",
                   help="triangulate even when the median reprojection error says the tracks do not fit the "
                   "calibration (swapped cameras, a frame offset, another setup's calibration)")
    g.add_argument("--uncertainty", action="store_true",
                   help="add each point's 1-sigma and covariance (tracking and calibration parts) from the tracks' "
                   "sigma and the .mat's 3-sigma errors (diagonal: the .mat has no correlations)")
    return g


def run(args):
    from .. import pipeline

    points = pipeline.triangulate_files(args.calib, args.left, args.right, out=args.out, force=args.force,
                                        uncertainty=getattr(args, "uncertainty", False))
    print(f"triangulated {points[['X']].notna().sum().iloc[0]} of {len(points)} point-frames; "
          f"median reprojection error {points['reproj_err'].median():.3f} px")
    if "sigma_X" in points.columns:
        med = points[["sigma_X", "sigma_Y", "sigma_Z"]].median()
        print(f"median 1-sigma {med['sigma_X']:.3f}, {med['sigma_Y']:.3f}, {med['sigma_Z']:.3f} mm (X, Y, Z)")
    print(f"wrote {args.out}")
    return 0
