"""Argument types shared by several subcommands."""
from __future__ import annotations

import argparse


def pattern_size(text):
    """Parse ``--pattern 9x6`` (inner corners per row x per column) into ``(9, 6)``."""
    try:
        cols, rows = (int(v) for v in text.lower().replace(",", "x").split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--pattern must be inner corners per row x per column, e.g. 9x6; got {text!r}"
        ) from None
    if cols < 2 or rows < 2:
        raise argparse.ArgumentTypeError(f"--pattern needs at least 2x2 inner corners, got {text!r}")
    return cols, rows
