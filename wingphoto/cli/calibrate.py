"""``wingphoto calibrate``: stereo calibration from checkerboard image pairs -> toolbox .mat + error analysis."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from ._args import pattern_size

_EPILOG = """\
board:
  Give the board with --pattern (inner corners per row x per column, e.g. 9x6) and --square
  (mm), or with --board board.json:
      {"pattern_size": [9, 6], "square_size": 30.0, "rows": [0, 3], "cols": [2, 8]}
  ("rows"/"cols" optional). --rows/--cols restrict every view to a block of the board
  (0-based inner-corner rows/columns, inclusive, e.g. --rows 0-3) for a board partly hidden
  or out of focus in every view.

output (next to --out unless --report is given):
  Calib_Results_stereo.mat   the toolbox's variables, with 3-sigma errors
  view_errors.csv            per pair: number, name, used, reason, mean error left/right (px)
  residuals_left.png, residuals_right.png, view_errors.png, coverage_left.png, coverage_right.png
                             the toolbox's "Analyse error" figures
  The worst views are named on the terminal; rerun with --suppress to leave them out.

checks:
  The same images for both cameras are refused. Each pair's own rig pose (from its two board
  poses) is compared with the others: a pair that disagrees is rejected and named; pairs out
  of sync (right image i+k named i) stop the run with the offset and the fix (--force goes on).
  --cross-validate calibrates two halves of the pairs and compares them with their
  uncertainty (mrcal's check).

examples:
  wingphoto calibrate --left calib/left --right calib/right --pattern 9x6 --square 30
  wingphoto calibrate --left L --right R --board board.json --suppress 3,left07.jpg --estimate-k3
"""


def _block(text):
    """Parse ``--rows 0-3`` (inclusive) into ``range(0, 4)``."""
    try:
        parts = [int(v) for v in str(text).replace(":", "-").split("-")]
        first, last = (parts[0], parts[0]) if len(parts) == 1 else parts
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected first-last board indices, e.g. 0-3; got {text!r}") from None
    if first < 0 or last < first:
        raise argparse.ArgumentTypeError(f"expected 0 <= first <= last, e.g. 0-3; got {text!r}")
    return range(first, last + 1)


def add_parser(sub):
    c = sub.add_parser(
        "calibrate",
        help="stereo calibration from checkerboard image pairs -> toolbox .mat and error analysis",
        description="Detect checkerboard corners in synchronized left/right image pairs, calibrate "
        "both cameras and their relative pose (om, T), print the toolbox-style summary with 3-sigma "
        "uncertainties, write Calib_Results_stereo.mat with the toolbox's variable names, the per-view "
        "errors and the toolbox's Analyse-error figures, and name the worst views.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    c.add_argument("--left", required=True, help="folder or glob of left calibration images")
    c.add_argument("--right", required=True, help="folder or glob of right calibration images (same count, same order)")
    c.add_argument("--pattern", type=pattern_size, help="inner corners per row x per column, e.g. 9x6")
    c.add_argument("--square", type=float, help="square size in mm, e.g. 30")
    c.add_argument("--board", help="board.json with pattern_size, square_size and optional rows/cols (instead of "
                   "--pattern/--square)")
    c.add_argument("--rows", type=_block, help="use only these inner-corner rows of every view, first-last, e.g. 0-3")
    c.add_argument("--cols", type=_block, help="use only these inner-corner columns of every view, e.g. 2-8")
    c.add_argument("--suppress", default="", help="pairs to leave out: comma-separated left file names or numbers "
                   "(1-based, as the toolbox numbers its images), e.g. 3,left07.jpg")
    c.add_argument("--estimate-k3", action="store_true", help="estimate the 6th-order radial distortion kc(5) "
                   "(the toolbox's est_dist(5); default off)")
    c.add_argument("--estimate-skew", action="store_true", help="estimate the skew alpha_c (default off)")
    c.add_argument("--force", action="store_true", help="go on when the pairs look out of sync (the rig found is "
                   "then probably wrong: prefer re-pairing the images)")
    c.add_argument("--cross-validate", action="store_true", help="also calibrate two halves of the pairs and "
                   "compare their projections with the uncertainty (about twice the time)")
    c.add_argument("--out", default="Calib_Results_stereo.mat", help="output .mat file (default: %(default)s)")
    c.add_argument("--report", default=None, help="folder for view_errors.csv and the figures (default: the "
                   "folder of --out)")
    return c


def _read_board(path):
    p = Path(path)
    try:
        board = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"--board {path}: no such file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"--board {path} is not valid JSON ({exc}); expected e.g. "
                         '{"pattern_size": [9, 6], "square_size": 30.0}') from None
    if not isinstance(board, dict) or "pattern_size" not in board or "square_size" not in board:
        raise ValueError(f"--board {path} must hold pattern_size [inner corners per row, per column] and "
                         "square_size (mm), e.g. {\"pattern_size\": [9, 6], \"square_size\": 30.0}")
    unknown = set(board) - {"pattern_size", "square_size", "rows", "cols"}
    if unknown:
        raise ValueError(f"--board {path}: unknown keys {sorted(unknown)} (allowed: pattern_size, square_size, "
                         "rows, cols)")
    out = {"pattern": tuple(board["pattern_size"]), "square": board["square_size"]}
    for key in ("rows", "cols"):
        v = board.get(key)
        if v is None:
            continue
        if isinstance(v, str):
            v = _block(v)
        elif isinstance(v, (list, tuple)) and len(v) == 2:
            v = range(int(v[0]), int(v[1]) + 1)
        else:
            raise ValueError(f"--board {path}: {key} must be [first, last] (inclusive board indices) or "
                             f"'first-last', got {v!r}")
        out[key] = v
    return out


def _suppress_list(text):
    out = []
    for tok in (t.strip() for t in str(text).split(",")):
        if not tok:
            continue
        if tok.isdigit():
            k = int(tok)
            if k < 1:
                raise ValueError(f"--suppress numbers start at 1 (the toolbox's image numbers), got {tok}")
            out.append(k - 1)
        else:
            out.append(tok)
    return out


def _save_figure(fig, path):
    from ..io import atomic_write

    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110, bbox_inches="tight")


def run(args):
    import numpy as np
    import pandas as pd

    from matplotlib.figure import Figure

    from .. import pipeline, plots
    from ..calibrate import suggest_suppress
    from ..io import atomic_write

    board = _read_board(args.board) if args.board else {}
    pattern = args.pattern or board.get("pattern")
    square = args.square if args.square is not None else board.get("square")
    if pattern is None or square is None:
        raise ValueError("give the board: --pattern 9x6 --square 30, or --board board.json")
    rows = args.rows if args.rows is not None else board.get("rows")
    cols = args.cols if args.cols is not None else board.get("cols")
    options = dict(estimate_k3=args.estimate_k3, estimate_skew=args.estimate_skew, force=args.force,
                   suppress=_suppress_list(args.suppress))
    if rows is not None or cols is not None:
        from ..io import read_sequence

        n = len(read_sequence(args.left))
        options["regions"] = {i: {"rows": rows, "cols": cols} for i in range(n)}
    result = pipeline.calibrate_folders(args.left, args.right, pattern, square, out=args.out, **options)
    print(result.summary())
    if result.pair_check is not None:
        print()
        print(result.pair_check.summary())
    print(f"\nwrote {args.out}")
    report = Path(args.report) if args.report else Path(args.out).resolve().parent
    report.mkdir(parents=True, exist_ok=True)
    err = result.view_errors
    table = pd.DataFrame({
        "number": np.arange(1, len(result.pairs) + 1), "pair": list(result.pairs), "used": result.used,
        "reason": [result.rejected.get(p, "") for p in result.pairs],
        "error_left_px": err[:, 0], "error_right_px": err[:, 1],
    })
    with atomic_write(report / "view_errors.csv", "w", encoding="utf-8", newline="") as f:
        table.to_csv(f, index=False, float_format="%.5f")
    figures = []
    for name, draw in (
        ("residuals_left.png", lambda ax: plots.plot_residuals(result, camera="left", ax=ax)),
        ("residuals_right.png", lambda ax: plots.plot_residuals(result, camera="right", ax=ax)),
        ("view_errors.png", lambda ax: plots.plot_view_errors(result, ax=ax)),
        ("coverage_left.png", lambda ax: plots.plot_coverage(result, camera="left", ax=ax)),
        ("coverage_right.png", lambda ax: plots.plot_coverage(result, camera="right", ax=ax)),
    ):
        fig = Figure(figsize=(6, 4.5))  # no pyplot: nothing is shown, no backend is switched
        draw(fig.subplots())
        _save_figure(fig, report / name)
        figures.append(name)
    print(f"wrote {report / 'view_errors.csv'} and {', '.join(figures)} in {report}")
    used = table[table["used"]].assign(worst=lambda t: t[["error_left_px", "error_right_px"]].max(axis=1))
    worst = used.sort_values("worst", ascending=False).head(3)
    print("worst views: " + ", ".join(f"{r.number} {r.pair} ({r.worst:.3f} px)" for r in worst.itertuples()))
    suggested = suggest_suppress(result)
    if suggested:
        nums = [str(result.pairs.index(s) + 1) for s in suggested]
        print(f"these views stand out (mean error > 2 x the median): {', '.join(suggested)}; "
              f"rerun with --suppress {','.join(nums)} to leave them out")
    if args.cross_validate:
        from ..calibcheck import cross_validate

        print()
        print(cross_validate(result).summary())
    return 0
