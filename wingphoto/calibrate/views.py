"""Gathering the views: corners from images or arrays, regions, names, suppression, screening."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .checks import _MIN_POINTS, _MIN_VIEWS, _index_range, board_points
from .corners import CornerDetection, find_corners



# ============================================================== gathering the views
@dataclass
class _View:
    name: str
    corners: np.ndarray | None  # (N, 2), NaN for missing
    reason: str | None = None
    image_size: tuple | None = None
    detected: bool = False  # corners from find_corners here (eligible for the locking correction)


def _looks_like_corners(item, n):
    if isinstance(item, (str, os.PathLike, CornerDetection)) or item is None:
        return False
    a = np.asarray(item)
    return a.ndim == 2 and a.shape[1] == 2 and a.shape[0] == n and np.issubdtype(a.dtype, np.floating)


def _region_for(regions, i, name):
    if not regions:
        return None, None
    reg = regions.get(i, regions.get(name)) if isinstance(regions, dict) else None
    if reg is None:
        return None, None
    if isinstance(reg, dict):
        unknown = set(reg) - {"rows", "cols"}
        if unknown:
            raise ValueError(f"regions[{i!r}] keys must be 'rows' and/or 'cols', got {sorted(unknown)}")
        return reg.get("rows"), reg.get("cols")
    rows, cols = reg
    return rows, cols


def _mask_region(corners, pattern_size, rows, cols):
    ncols, nrows = pattern_size
    if corners.shape[0] != ncols * nrows:
        raise ValueError(
            "regions can only restrict corners in the canonical board order "
            f"({ncols * nrows} corners of pattern_size {pattern_size}), got {corners.shape[0]}"
        )
    ri, ci = _index_range(rows, nrows, "rows"), _index_range(cols, ncols, "cols")
    keep = np.zeros((nrows, ncols), bool)
    keep[ri.start : ri.stop, ci.start : ci.stop] = True
    out = corners.copy()
    out[~keep.ravel()] = np.nan
    return out


def _unique_names(names):
    seen = {}
    out = []
    for n in names:
        k = seen.get(n, 0)
        seen[n] = k + 1
        out.append(n if k == 0 else f"{n} #{k + 1}")
    return out


def _gather_views(items, pattern_size, n_points, *, regions, names, window, method, what, progress):
    """Detect or accept the corners of every view -> list of _View (never drops a view)."""
    if isinstance(items, (str, os.PathLike)) or (isinstance(items, np.ndarray) and items.ndim == 2):
        raise ValueError(f"{what} must be a sequence of images, paths or corner arrays, one per view")
    items = list(items)
    if names is not None:
        names = [str(n) for n in names]
        if len(names) != len(items):
            raise ValueError(f"names has {len(names)} entries but {what} has {len(items)} views")
    views = []
    try:
        from tqdm.auto import tqdm

        it = tqdm(items, desc=f"corners ({what})", disable=not progress)
    except ImportError:  # pragma: no cover
        it = items
    for i, item in enumerate(it):
        label = names[i] if names is not None else None
        key = label or (Path(item).name if isinstance(item, (str, os.PathLike)) else None)
        rows, cols = _region_for(regions, i, key)
        if item is None:
            views.append(_View(label or f"view {i}", None, "no image given"))
            continue
        if isinstance(item, CornerDetection):
            lab = label or item.name
            if not item.found:
                views.append(_View(lab, None, item.message, item.image_size))
                continue
            c = np.array(item.corners, dtype=np.float64)
            if rows is not None or cols is not None:
                c = _mask_region(c, item.pattern_size, rows, cols)
            views.append(_View(lab, c, None, item.image_size, detected=True))
            continue
        if _looks_like_corners(item, n_points):
            c = np.array(item, dtype=np.float64)
            if rows is not None or cols is not None:
                c = _mask_region(c, pattern_size, rows, cols)
            views.append(_View(label or f"view {i}", c, None, None))
            continue
        arr = None if isinstance(item, (str, os.PathLike)) else np.asarray(item)
        if (
            arr is not None and arr.ndim == 2 and arr.shape[1] == 2 and arr.shape[0] < 64
            and np.issubdtype(arr.dtype, np.floating)
        ):
            raise ValueError(
                f"{what}[{i}] looks like corners of shape {arr.shape}, but the board has {n_points} "
                f"corners (pattern_size {pattern_size}); pass one (x, y) row per corner, NaN for missing"
            )
        if label is None and not isinstance(item, (str, os.PathLike)):
            label = f"view {i}"
        det = find_corners(item, pattern_size, rows=rows, cols=cols, window=window, method=method, name=label)
        if det.found:
            views.append(_View(det.name, np.array(det.corners), None, det.image_size, detected=True))
        else:
            views.append(_View(det.name, None, det.message, det.image_size))
    for v, n in zip(views, _unique_names([v.name for v in views])):
        v.name = n
    return views


def _image_size_of(views, image_size, what):
    sizes = {}
    for v in views:
        if v.image_size is not None:
            sizes.setdefault(tuple(v.image_size), v.name)
    if len(sizes) > 1:
        (s1, n1), (s2, n2) = list(sizes.items())[:2]
        raise ValueError(
            f"{what} images differ in size: {n1} is {s1[0]}x{s1[1]} but {n2} is {s2[0]}x{s2[1]} "
            "(width x height); calibrate images of one camera at one resolution"
        )
    found = next(iter(sizes), None)
    if image_size is not None:
        image_size = tuple(int(v) for v in image_size)
        if len(image_size) != 2 or min(image_size) <= 0:
            raise ValueError(f"image_size must be (width, height) in pixels, got {image_size!r}")
        if found is not None and found != image_size:
            raise ValueError(f"image_size={image_size} but the {what} images are {found[0]}x{found[1]}")
        return image_size
    if found is None:
        raise ValueError(
            f"image_size=(width, height) is required when the {what} views are given as corners "
            "rather than images"
        )
    return found


def _board_list(board, n_views, pattern_size, square_size):
    if board is None:
        b = board_points(pattern_size, square_size)
        return [b] * n_views
    if isinstance(board, np.ndarray) or (
        isinstance(board, (list, tuple)) and len(board) and np.ndim(board[0]) == 1
    ):
        b = np.asarray(board, dtype=np.float64)
        if b.ndim != 2 or b.shape[1] != 3:
            raise ValueError(f"board_points must be (N, 3) mm or a list of them per view, got shape {b.shape}")
        return [b] * n_views
    out = [None if b is None else np.asarray(b, dtype=np.float64) for b in board]
    if len(out) != n_views:
        raise ValueError(f"board_points has {len(out)} entries but there are {n_views} views")
    for i, b in enumerate(out):
        if b is not None and (b.ndim != 2 or b.shape[1] != 3):
            raise ValueError(f"board_points[{i}] must be (N, 3) mm, got shape {b.shape}")
    return out


def _screen_views(views, boards, suppressed=()):
    """Attach reasons for views that cannot be used; returns indices of usable views."""
    used = []
    for i, (v, b) in enumerate(zip(views, boards)):
        if i in suppressed:
            v.reason = "suppressed by the user"
        if v.reason is not None:
            continue
        if b is None:
            v.reason = "no board points given"
            continue
        if v.corners.shape[0] != b.shape[0]:
            raise ValueError(
                f"view {v.name} has {v.corners.shape[0]} corners but its board has {b.shape[0]} "
                "points; corners and board_points must correspond row by row"
            )
        n = int(np.all(np.isfinite(v.corners), axis=1).sum())
        if n < _MIN_POINTS:
            v.reason = f"only {n} corners (at least {_MIN_POINTS} needed)"
            continue
        used.append(i)
    return used


def _too_few(views, used, what, need=_MIN_VIEWS):
    lines = "; ".join(f"{v.name}: {v.reason}" for v in views if v.reason)
    hint = ""
    if all("not found" in (v.reason or "") for v in views if v.reason) and not used:
        hint = " The board was found in no image: check pattern_size (inner corners per row and column)."
    return ValueError(
        f"only {len(used)} usable {what} (at least {need} needed to calibrate). "
        f"Rejected: {lines or 'none'}.{hint}"
    )

