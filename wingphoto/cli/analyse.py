"""``wingphoto analyse``: a 3D points CSV and the analysis settings -> tables, figures, meshes."""
from __future__ import annotations


def add_parser(sub):
    a = sub.add_parser(
        "analyse",
        help="analyse 3D points with your marker numbering -> tables, figures, wing meshes",
        description="Analyse a 3D points CSV (frame, point, X, Y, Z): reference stillness, rigid lengths, wing "
        "kinematics (stroke, deviation, pitch, twist, camber, bending) with reversals and phase averages, and "
        "the wing surface as a ParaView time series. Which markers are references, edges and length pairs "
        "comes from the [analysis] table of a TOML file (the same schema a batch manifest uses; see "
        "wingphoto.config.AnalysisSettings). Definitions: docs/kinematics.md.",
    )
    a.add_argument("points", help="3D points CSV (from wingphoto triangulate)")
    a.add_argument("--config", required=True, help="TOML file with an [analysis] table")
    a.add_argument("--out", required=True, help="output folder (created)")
    a.add_argument("--tracks", default=None, help="tracks CSV the points came from (adds a tracking table)")
    return a


def run(args):
    from .. import pipeline
    from ..config import load_analysis_settings
    from ..io import read_points_csv, read_tracks_csv

    settings = load_analysis_settings(args.config)
    points = read_points_csv(args.points)
    tracks = read_tracks_csv(args.tracks) if args.tracks else None
    tables = pipeline.analyse_points(points, settings, out=args.out, tracks=tracks)
    if not tables:
        print("nothing to analyse: the [analysis] table names no references, length pairs or leading edge")
        return 1
    for name, df in tables.items():
        print(f"{name}: {len(df)} rows")
    if "length_statistics" in tables:
        for r in tables["length_statistics"].itertuples():
            print(f"  length {r.i}-{r.j}: mean {r.mean:.3f} mm, std {r.std:.3f} mm")
    if "reference_stillness" in tables:
        ok = bool(tables["reference_stillness"]["valid"].all())
        print(f"  references {'still: test valid' if ok else 'MOVED: test invalid'}")
    print(f"wrote {args.out}")
    return 0
