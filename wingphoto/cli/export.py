"""``wingphoto export``: hand results to DLTdv/Argus, MATLAB (the thesis' files), ParaView/CFD/FEA or Parquet."""
from __future__ import annotations

from pathlib import Path

#: format -> (inputs it can use, at least one of which is needed, description)
FORMATS = {
    "dltdv": (("tracks", "points"), "DLTdv8 xypts/offsets.csv (from --tracks; --y-up for Argus / DLTdv 1-7, "
              "which then needs --image-height or --calib) and xyzpts/xyzres.csv (from --points)"),
    "dlt-coefs": (("calib",), "_dltCoefs.csv: 11 DLT coefficients per camera fitted to --calib "
                  "(fitted where --points lie, when given); prints the residual lens distortion costs"),
    "thesis-mat": (("tracks", "points"), "xl.mat/xr.mat/cntrdl.mat/cntrdr.mat (from --tracks) and 3dall.mat "
                   "(from --points; XR needs --calib)"),
    "ply": (("points",), "one PLY point cloud per frame + a ParaView .ply.series index (from --points)"),
    "vtk": (("points",), "one VTU point cloud per frame + a ParaView .vtu.series index (from --points)"),
    "parquet": (("tracks", "points"), "tracks.parquet / points3d.parquet (from --tracks / --points)"),
}


def add_parser(sub):
    e = sub.add_parser(
        "export",
        help="export tracks / 3D points / calibration for DLTdv, MATLAB, ParaView or Parquet",
        description="Export results for other tools. Formats and the inputs they use:\n"
        + "\n".join(f"  {k}: {v[1]}" for k, v in FORMATS.items())
        + "\nConventions (1-based, DLTdv's y-up pixels, ...): docs/formats.md.",
    )
    e.add_argument("--format", required=True, choices=sorted(FORMATS), help="what to write")
    e.add_argument("--out", required=True, help="output folder (created)")
    e.add_argument("--points", default=None, help="3D points CSV (wingphoto triangulate)")
    e.add_argument("--tracks", default=None, help="tracks CSV with both cameras (or give --tracks twice: left, right)",
                   action="append")
    e.add_argument("--calib", default=None, help="Calib_Results_stereo.mat")
    e.add_argument("--y-up", action="store_true",
                   help="pixels with the origin at the bottom-left, y up (Argus, DLTdv 1-7); default: DLTdv8's "
                   "MATLAB pixels (origin top-left, 1-based)")
    e.add_argument("--image-height", type=int, default=None,
                   help="image height in px for --y-up (default: from --calib)")
    e.add_argument("--prefix", default="", help="file name prefix for DLTdv files, e.g. trial01-")
    return e


def _tracks(paths):
    import pandas as pd

    from ..io import read_tracks_csv

    if not paths:
        return None
    return pd.concat([read_tracks_csv(p) for p in paths], ignore_index=True)


def run(args):
    from ..io import exchange, load_bouguet_stereo, read_points_csv

    needs, _ = FORMATS[args.format]
    given = {"tracks": bool(args.tracks), "points": args.points is not None, "calib": args.calib is not None}
    if not any(given[n] for n in needs):
        raise ValueError(f"--format {args.format} needs {' and/or '.join('--' + n for n in needs)}: {FORMATS[args.format][1]}")
    out = Path(args.out)
    rig = load_bouguet_stereo(args.calib)[0] if args.calib else None
    points = read_points_csv(args.points) if args.points else None
    tracks = _tracks(args.tracks)
    written = []
    if args.format == "dltdv":
        heights = None
        if args.image_height is not None:
            heights = (args.image_height, args.image_height)
        elif rig is not None and rig.left.image_size and rig.right.image_size:
            heights = (rig.left.image_size[1], rig.right.image_size[1])
        y_axis = "up" if args.y_up else "down"
        if tracks is not None and heights is None and y_axis == "up":
            raise ValueError("--y-up with --tracks needs --image-height (or --calib with the image size)")
        written += exchange.write_dltdv(out, tracks=tracks, points3d=points, image_heights=heights,
                                        prefix=args.prefix, y_axis=y_axis).values()
    elif args.format == "dlt-coefs":
        fit = exchange.fit_dlt(rig, points=None if points is None else points[["X", "Y", "Z"]].to_numpy(),
                               y_axis="up" if args.y_up else "down")
        written.append(exchange.write_dlt_coefficients(fit, out / f"{args.prefix}dltCoefs.csv"))
        print(fit.summary())
        print(f"DLT world origin = left camera frame shifted by {fit.origin.tolist()} mm "
              f"(X_dlt = X_left - origin)")
    elif args.format == "thesis-mat":
        written += exchange.write_thesis_mat(out, tracks=tracks, points3d=points, rig=rig).values()
    elif args.format in ("ply", "vtk"):
        from ..io.mesh import write_series

        ext = "ply" if args.format == "ply" else "vtu"
        items = []
        for frame, g in points.groupby("frame", sort=True):
            items.append({"time": float(frame), "vertices": g[["X", "Y", "Z"]].to_numpy(float), "faces": None,
                          "point_data": {"point": g["point"].to_numpy(), "reproj_err": g["reproj_err"].to_numpy(float)},
                          "name": f"points_{int(frame):06d}.{ext}"})
        if not items:
            raise ValueError(f"{args.points} holds no 3D points to export")
        written.append(write_series(out, items, name="points"))
    elif args.format == "parquet":
        if tracks is not None:
            written.append(exchange.write_parquet(tracks, out / "tracks.parquet"))
        if points is not None:
            written.append(exchange.write_parquet(points, out / "points3d.parquet"))
    for p in written:
        print(f"wrote {p}")
    return 0
