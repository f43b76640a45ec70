"""3D point clouds and analysis plots. Every function takes ``ax=None`` and returns the axes.

3D views show the left camera frame with the depth Z as the horizontal second axis and
Y (down in the camera) pointing down, so the picture looks like the camera's view from
above-behind: plot x = X, plot y = Z, plot z = Y with the vertical axis inverted.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from .analysis import ReferenceStillness, StrokeAngle, _as_array

__all__ = ["plot_points_3d", "plot_length_statistics", "plot_stroke_angle", "plot_reference_stillness"]


def _new_axes(projection=None):
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(6, 5) if projection else (6, 4))
    return fig.add_subplot(projection=projection)


def _polylines(ids, connect):
    """Lists of point numbers to join with lines."""
    ids = [int(i) for i in ids]
    if connect is None or connect is False:
        return []
    if isinstance(connect, str):
        if connect != "sequence":
            raise ValueError(f"connect must be None, 'sequence', an int (markers per chord) or lists, got {connect!r}")
        return [ids]
    if isinstance(connect, (int, np.integer)):
        n = int(connect)
        if n < 1:
            raise ValueError(f"connect as markers per chord must be >= 1, got {n}")
        chords = [ids[k:k + n] for k in range(0, len(ids), n)]
        spans = [[c[m] for c in chords if m < len(c)] for m in range(n)]
        return chords + spans
    return [[int(i) for i in line] for line in connect]


def plot_points_3d(points, frames=None, ax=None, *, point_ids=None, connect="sequence", cmap="viridis",
                   labels=False, marker_size=12.0):
    """Plot 3D marker points of one or several frames, joined in wing numbering.

    Parameters
    ----------
    points : pandas.DataFrame or (T, N, 3) array_like
        3D points in mm, left camera frame (``frame, point, X, Y, Z``).
    frames : int or sequence of int, optional
        Frames to draw (frame numbers for a DataFrame, indices for an array); default
        all. Several frames are coloured along ``cmap`` (e.g. an upstroke).
    ax : mpl_toolkits.mplot3d.Axes3D, optional
        Axes to draw on; default a new figure.
    point_ids : sequence of int, optional
        Points to draw; default all.
    connect : None, "sequence", int, or list of lists
        Lines between markers: "sequence" joins consecutive numbers (leading edge to
        trailing edge, tip to root); an int ``n`` is the number of markers per chord and
        draws the chords and the spanwise lines of the marker grid; lists are explicit
        polylines of point numbers.
    cmap : str
        Colour map over the frames.
    labels : bool
        Write the point numbers next to the markers.
    marker_size : float

    Returns
    -------
    ax : Axes3D
    """
    P, all_frames, ids, _ = _as_array(points)
    if ax is None:
        ax = _new_axes("3d")
    elif getattr(ax, "name", "") != "3d":
        raise ValueError("ax must be a 3D axes: fig.add_subplot(projection='3d')")
    if frames is None:
        rows = np.arange(len(all_frames))
    else:
        wanted = np.atleast_1d(np.asarray(frames, dtype=np.int64))
        rows = pd.Index(all_frames).get_indexer(wanted)
        if (rows < 0).any():
            raise ValueError(f"frames {wanted[rows < 0].tolist()} are not in the points")
    if point_ids is None:
        cols = np.arange(len(ids))
    else:
        cols = pd.Index(ids).get_indexer(np.asarray(point_ids, dtype=np.int64))
        if (cols < 0).any():
            raise ValueError(f"point_ids {np.asarray(point_ids)[cols < 0].tolist()} are not in the points")
    shown = ids[cols]
    lines = _polylines(shown, connect)
    index = {int(p): k for k, p in enumerate(ids)}
    import matplotlib
    from matplotlib.colors import Normalize

    single = len(rows) == 1
    colours = _colours(cmap, len(rows)) if not single else ["0.45"]
    if single:  # one frame: the markers are coloured by depth, the colour bar says how deep
        Zs = P[rows[0], cols][:, 2]
        finite = Zs[np.isfinite(Zs)]
        norm = Normalize(*(finite.min(), finite.max() + 1e-9) if len(finite) else (0.0, 1.0))
        bar_label = "depth Z (mm)"
    else:
        norm = Normalize(float(all_frames[rows[0]]), float(all_frames[rows[-1]]) + 1e-9)
        bar_label = "frame"
    for c, r in zip(colours, rows):
        X = P[r, cols]
        colour = matplotlib.colormaps[cmap](norm(X[:, 2])) if single else c
        ax.scatter(X[:, 0], X[:, 2], X[:, 1], color=colour, s=marker_size, depthshade=False)
        for line in lines:
            L = P[r, [index[p] for p in line if p in index]]
            ax.plot(L[:, 0], L[:, 2], L[:, 1], color=c, linewidth=0.8)
        if labels:
            for p, x in zip(shown, X):
                if np.all(np.isfinite(x)):
                    ax.text(x[0], x[2], x[1], str(int(p)), fontsize=7)
    from matplotlib.cm import ScalarMappable
    from matplotlib.ticker import MaxNLocator

    if len(rows):
        bar = ax.figure.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.6, pad=0.12)
        bar.set_label(bar_label, fontsize=8)
        bar.ax.tick_params(labelsize=7)
    ax.set_xlabel("X (mm)", fontsize=8, labelpad=6)
    ax.set_ylabel("Z (mm, depth)", fontsize=8, labelpad=6)
    ax.set_zlabel("Y (mm, down)", fontsize=8, labelpad=6)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):  # few, short tick labels: readable, not overlapping
        axis.set_major_locator(MaxNLocator(4))
    ax.tick_params(labelsize=7, pad=1)
    sel = P[np.ix_(rows, cols)].reshape(-1, 3)
    sel = sel[np.all(np.isfinite(sel), axis=1)]
    if len(sel):
        lo, hi = sel.min(axis=0), sel.max(axis=0)
        span = np.maximum(hi - lo, 1e-3)
        ax.set_xlim(lo[0], hi[0] + (span[0] <= 1e-3))
        ax.set_ylim(lo[2], hi[2] + (span[2] <= 1e-3))
        ax.set_zlim(hi[1] + (span[1] <= 1e-3), lo[1])  # Y down
        ax.set_box_aspect((span[0], span[2], span[1]))
    if len(rows) == 1:
        ax.set_title(f"frame {all_frames[rows[0]]}")
    elif len(rows):
        ax.set_title(f"frames {all_frames[rows[0]]}-{all_frames[rows[-1]]}")
    return ax


def _colours(cmap, n):
    import matplotlib

    if n <= 1:
        return ["C0"] * n
    return [matplotlib.colormaps[cmap](v) for v in np.linspace(0.0, 1.0, n)]


def plot_length_statistics(stats, ax=None, *, nominal=None):
    """Length per condition as the deviation from each pair's mean: mean +/- std, min and max.

    Lengths of different pairs (10 to 100 mm) on one axis hide their sub-micrometre
    spread; so each pair is drawn relative to its own mean over all conditions, in um
    when the deviations are below 0.1 mm (else mm), and its legend entry gives the
    mean length, the pooled frame-to-frame std and, when known, the bias against the
    nominal length.

    Parameters
    ----------
    stats : pandas.DataFrame
        :func:`wingphoto.analysis.length_statistics` output.
    ax : matplotlib Axes, optional
    nominal : float, optional
        Known length in mm of every pair; default the ``nominal`` column when present.

    Returns
    -------
    ax : matplotlib Axes
        One entry per pair in the legend (plus one explaining the min-max bars).
    """
    need = ["condition", "i", "j", "mean", "std", "min", "max"]
    missing = [c for c in need if c not in stats.columns]
    if missing:
        raise ValueError(f"stats lacks columns {missing}; pass length_statistics(...) output")
    if ax is None:
        ax = _new_axes()
    conditions = list(pd.unique(stats["condition"]))
    pairs = list(dict.fromkeys(zip(stats["i"], stats["j"])))
    width = 0.6 / max(len(pairs), 1)
    centres = {}
    for i, j in pairs:
        s = stats[(stats["i"] == i) & (stats["j"] == j)]
        weights = s["n"].to_numpy(float) if "n" in s.columns else np.ones(len(s))
        ok = np.isfinite(s["mean"].to_numpy(float)) & (weights > 0)
        centres[(i, j)] = (float(np.average(s["mean"].to_numpy(float)[ok], weights=weights[ok]))
                           if ok.any() else float("nan"))
    dev = np.concatenate([np.abs(stats[c].to_numpy(float) - stats.apply(lambda r: centres[(r["i"], r["j"])], axis=1)
                                 .to_numpy(float)) for c in ("min", "max")]) if len(stats) else np.zeros(1)
    dev = dev[np.isfinite(dev)]
    micro = not len(dev) or dev.max() < 0.1
    scale, unit = (1000.0, "µm") if micro else (1.0, "mm")
    for k, (i, j) in enumerate(pairs):
        s = stats[(stats["i"] == i) & (stats["j"] == j)].set_index("condition").reindex(conditions)
        x = np.arange(len(conditions)) + (k - (len(pairs) - 1) / 2) * width
        colour = f"C{k % 10}"
        c = centres[(i, j)]
        pooled = float(np.sqrt(np.nanmean(s["std"].to_numpy(float) ** 2)))
        label = f"points {i}-{j}: {c:.3f} mm, std {pooled * scale:.3g} {unit}"
        ref = nominal
        if ref is None and "nominal" in s.columns and s["nominal"].notna().any():
            ref = float(s["nominal"].dropna().iloc[0])
        if ref is not None:
            label += f", bias {(c - ref) * scale:+.3g} {unit}"
        ax.errorbar(x, (s["mean"] - c) * scale, yerr=s["std"] * scale, fmt="o", color=colour, capsize=4,
                    label=label, markersize=4)
        ax.vlines(x, (s["min"] - c) * scale, (s["max"] - c) * scale, color=colour, linewidth=0.8, alpha=0.6)
        ax.plot(x, (s["min"] - c) * scale, "_", color=colour, markersize=10)
        ax.plot(x, (s["max"] - c) * scale, "_", color=colour, markersize=10)
        if ref is not None and len(pairs) == 1:  # one pair: the nominal length as a line too
            ax.axhline((ref - c) * scale, color="k", linestyle="--", linewidth=1, label=f"nominal {ref:g} mm")
    ax.plot([], [], "_", color="0.4", markersize=10, label="thin bar: min to max; dot ± std")
    ax.axhline(0.0, color="0.6", linewidth=0.6)
    ax.set_xticks(np.arange(len(conditions)), [str(c) for c in conditions])
    ax.set_xlabel("test condition")
    ax.set_ylabel(f"length − pair mean ({unit})")
    ax.set_title("Length per condition, as deviation from each pair's mean", fontsize=10)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    return ax


def plot_stroke_angle(angle, reversals=None, ax=None, *, fps=None):
    """Stroke angle against frame (or time) with the stroke reversals marked.

    Parameters
    ----------
    angle : StrokeAngle, pandas.Series or (T,) array_like
        Stroke angle in degrees (:func:`wingphoto.analysis.stroke_angle`).
    reversals : pandas.DataFrame, optional
        :func:`wingphoto.analysis.find_reversals` output.
    ax : matplotlib Axes, optional
    fps : float, optional
        Frame rate; the x axis is then time in ms.

    Returns
    -------
    ax : matplotlib Axes
    """
    if isinstance(angle, StrokeAngle):
        frames, y = angle.frames.astype(float), angle.angle_deg
    elif isinstance(angle, pd.Series):
        frames, y = angle.index.to_numpy(float), angle.to_numpy(float)
    else:
        y = np.asarray(angle, dtype=float)
        frames = np.arange(len(y), dtype=float)
    scale = 1000.0 / fps if fps else 1.0
    if ax is None:
        ax = _new_axes()
    ax.plot(frames * scale, y, "-", color="C0", linewidth=1.2, label="stroke angle")
    if reversals is not None and len(reversals):
        for kind, marker, colour in (("max", "v", "C3"), ("min", "^", "C2")):
            r = reversals[reversals["kind"] == kind]
            if len(r):
                ax.plot(r["frame"] * scale, r["angle_deg"], marker, color=colour, label=f"reversal ({kind})")
                for f in r["frame"]:
                    ax.axvline(f * scale, color=colour, linestyle=":", linewidth=0.8)
    ax.axhline(0.0, color="0.6", linewidth=0.6)
    ax.set_xlabel("time (ms)" if fps else "frame")
    ax.set_ylabel("stroke angle (deg)")
    ax.legend(fontsize=8)
    return ax


def plot_reference_stillness(stillness, ax=None):
    """Displacement of each static reference point per frame, against the tolerance.

    Parameters
    ----------
    stillness : ReferenceStillness
        :func:`wingphoto.analysis.reference_stillness` output.
    ax : matplotlib Axes, optional

    Returns
    -------
    ax : matplotlib Axes
    """
    if not isinstance(stillness, ReferenceStillness):
        raise ValueError("stillness must be the result of wingphoto.analysis.reference_stillness")
    if ax is None:
        ax = _new_axes()
    for k, p in enumerate(stillness.point_ids):
        ax.plot(stillness.frames, stillness.displacement[:, k], linewidth=1, label=f"point {p}")
    ax.axhline(stillness.tol_mm, color="C3", linestyle="--", linewidth=1, label=f"tolerance {stillness.tol_mm:g} mm")
    ax.set_xlabel("frame")
    ax.set_ylabel(f"displacement from {stillness.relative_to} position (mm)")
    ax.set_title("references still: test valid" if stillness.valid else "a reference moved: test INVALID")
    ax.legend(fontsize=8)
    return ax
