"""Diagnostic figures. Every function takes ``ax=None`` (a new figure) and returns the axes.

Pixel axes follow ``docs/conventions.md``: (x, y) with (0, 0) at the centre of the
top-left pixel, y drawn downwards.
"""
from __future__ import annotations

import numpy as np

__all__ = ["plot_corners", "plot_residuals", "plot_view_errors", "plot_coverage", "plot_contact_sheet", "plot_picks"]


def _axes(ax):
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots()
    return ax


def _colours(n):
    import matplotlib

    cmap = matplotlib.colormaps["turbo"]
    return [cmap(v) for v in np.linspace(0.05, 0.95, max(n, 1))]


# --- calibration diagnostics ---
def _calibration_views(result, camera):
    """(names, used, residuals, corners, image_size) of one camera of a calibration."""
    from .calibrate import CameraCalibration, StereoCalibration

    if isinstance(result, CameraCalibration):
        if camera not in (None, "left", "right"):
            raise ValueError(f"camera must be None for a single-camera calibration, got {camera!r}")
        return list(result.views), np.asarray(result.used), result.residuals, result.corners, result.image_size
    if isinstance(result, StereoCalibration):
        side = camera or "left"
        if side not in ("left", "right"):
            raise ValueError(f"camera must be 'left' or 'right', got {camera!r}")
        res = result.residuals_left if side == "left" else result.residuals_right
        cor = result.corners_left if side == "left" else result.corners_right
        size = (result.rig.left if side == "left" else result.rig.right).image_size
        return list(result.pairs), np.asarray(result.used), res, cor, size
    raise ValueError(
        f"result must be a CameraCalibration or StereoCalibration, got {type(result).__name__}"
    )


def plot_corners(image, detection, *, ax=None, cmap="gray"):
    """Show an image with its detected corners, the first corner and the row order.

    Parameters
    ----------
    image : (H, W) array_like or str or Path
        The image the corners were found in.
    detection : CornerDetection or (N, 2) array_like
        Result of :func:`wingphoto.calibrate.find_corners` (or corner pixels).
    ax : matplotlib Axes, optional
    cmap : str, optional

    Returns
    -------
    ax : matplotlib Axes
        The corners joined in their order (a line along each row), corner 0 circled.
    """
    from .calibrate.corners import CornerDetection, _read_gray

    ax = _axes(ax)
    img, _ = _read_gray(image, "image")
    ax.imshow(img, cmap=cmap, interpolation="nearest")
    if isinstance(detection, CornerDetection):
        pts = detection.corners
        title = detection.message
    else:
        pts = None if detection is None else np.asarray(detection, dtype=np.float64)
        title = ""
    if pts is not None:
        ax.plot(pts[:, 0], pts[:, 1], "-", color="tab:orange", lw=0.8)
        ax.plot(pts[:, 0], pts[:, 1], "+", color="tab:red", ms=6)
        first = pts[np.flatnonzero(np.isfinite(pts[:, 0]))[:1]]
        if len(first):
            ax.plot(first[:, 0], first[:, 1], "o", mfc="none", mec="yellow", ms=12, mew=2)
            ax.annotate("0", first[0], color="yellow", xytext=(6, -6), textcoords="offset points")
    ax.set_title(title, fontsize=8)
    return ax


def _view_colour_scale(ax, names, idx, cmap="turbo"):
    """Colours of the used views and a compact colour bar naming them (instead of a legend).

    Returns the list of colours, one per entry of ``idx``; adds a colour bar to ``ax``'s
    figure with at most ~8 labelled ticks (view names).
    """
    import matplotlib
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import BoundaryNorm, ListedColormap

    n = max(len(idx), 1)
    base = matplotlib.colormaps[cmap]
    colours = [base(v) for v in np.linspace(0.05, 0.95, n)]
    norm = BoundaryNorm(np.arange(n + 1) - 0.5, n)
    mappable = ScalarMappable(norm=norm, cmap=ListedColormap(colours))
    # a thin horizontal bar under the axes: it never runs into a neighbouring panel
    cax = ax.inset_axes((0.0, -0.26, 1.0, 0.035))
    bar = ax.figure.colorbar(mappable, cax=cax, orientation="horizontal")
    used = [str(names[i]) for i in idx]
    short, prefix, suffix = _short_names(used)
    step = max(1, int(np.ceil(n / 12)))
    ticks = list(range(0, len(used), step))
    bar.set_ticks(ticks)
    bar.set_ticklabels([short[t] for t in ticks])
    bar.ax.tick_params(labelsize=7)
    what = f"{prefix}…{suffix}" if (prefix or suffix) else "view"
    bar.set_label(f"view ({what}, {len(idx)} used)", fontsize=8)
    return colours, bar


def _short_names(names):
    """Names without their common prefix and suffix (``calib_07.tif`` -> ``07``)."""
    import os

    if len(names) < 2:
        return list(names), "", ""
    prefix = os.path.commonprefix(names)
    suffix = os.path.commonprefix([n[::-1] for n in names])[::-1]
    if any(len(n) <= len(prefix) + len(suffix) for n in names):
        return list(names), "", ""
    return [n[len(prefix):len(n) - len(suffix)] for n in names], prefix, suffix


def plot_residuals(result, *, camera=None, ax=None, marker="+"):
    """Scatter the reprojection residuals, one colour per view (the toolbox's "Analyse error").

    Parameters
    ----------
    result : CameraCalibration or StereoCalibration
    camera : {"left", "right"}, optional
        Which camera of a stereo calibration (default left); None for one camera.
    ax : matplotlib Axes, optional
    marker : str, optional

    Returns
    -------
    ax : matplotlib Axes
        One scatter collection per used view (its ``label`` the view name), x and y
        residuals ``observed - projected`` in pixels, equal axis scales. The views are
        told apart by a compact colour bar (not a legend covering the data); the title
        gives the RMS error.
    """
    names, used, residuals, _, _ = _calibration_views(result, camera)
    ax = _axes(ax)
    idx = np.flatnonzero(used)
    colours, _ = _view_colour_scale(ax, names, idx)
    for c, i in zip(colours, idx):
        r = residuals[i]
        ax.scatter(r[:, 0], r[:, 1], s=14, marker=marker, color=c, label=names[i], linewidths=0.8)
    ax.set_xlabel("x residual (px)")
    ax.set_ylabel("y residual (px)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.axhline(0, color="0.7", lw=0.5)
    ax.axvline(0, color="0.7", lw=0.5)
    side = f" ({camera or 'left'} camera)" if len(names) and hasattr(result, "rig") else ""
    allr = np.concatenate([residuals[i] for i in idx]) if len(idx) else np.zeros((0, 2))
    allr = allr[np.all(np.isfinite(allr), axis=1)]
    rms = float(np.sqrt(np.mean(np.sum(allr ** 2, axis=1)))) if len(allr) else float("nan")
    ax.set_title(f"Reprojection error{side}: RMS {rms:.3f} px, {len(allr)} corners", fontsize=10)
    return ax


def plot_view_errors(result, *, camera=None, ax=None, worst=3, factor=2.0):
    """Bar chart of each view's mean reprojection error; views suggested for suppression in red.

    Parameters
    ----------
    result : CameraCalibration or StereoCalibration
    camera : {"left", "right"}, optional
        For a stereo calibration, show one camera only (default: both, side by side).
    ax : matplotlib Axes, optional
    worst : int, optional
        Name at most this many of the views suggested for suppression above their bars
        (default 3). Views that are not suggested are never named in red.
    factor : float, optional
        Views that :func:`wingphoto.calibrate.suggest_suppress` (with this factor)
        proposes to suppress are drawn in red.

    Returns
    -------
    ax : matplotlib Axes
        Mean pixel distance between observed and projected corners per view, with the
        standard deviation over its corners as error bars; unused views are left empty.
        The title names the camera and how many views are suggested for suppression.
    """
    from .calibrate import StereoCalibration, suggest_suppress

    ax = _axes(ax)
    stereo = isinstance(result, StereoCalibration)
    sides = [camera] if camera is not None or not stereo else ["left", "right"]
    suggested = set(suggest_suppress(result, factor=factor))
    width = 0.8 / len(sides)
    means_all = None
    highest = 0.0
    names = []
    for k, side in enumerate(sides):
        names, used, residuals, _, _ = _calibration_views(result, side)
        n = len(names)
        means, stds = np.full(n, np.nan), np.full(n, np.nan)
        for i in np.flatnonzero(used):
            d = np.hypot(residuals[i][:, 0], residuals[i][:, 1])
            means[i], stds[i] = np.nanmean(d), np.nanstd(d)
        x = np.arange(n) + (k - (len(sides) - 1) / 2) * width
        base = "tab:blue" if k == 0 else "tab:cyan"
        colours = ["tab:red" if names[i] in suggested else base for i in range(n)]
        label = f"{side} camera" if stereo else None
        ax.bar(x, np.nan_to_num(means), width=width, yerr=np.nan_to_num(stds), color=colours,
               capsize=2, label=label, error_kw={"lw": 0.8})
        means_all = means if means_all is None else np.fmax(means_all, means)
        highest = max(highest, float(np.nanmax(means + stds)) if np.any(np.isfinite(means)) else 0.0)
    flagged = [i for i in np.argsort(-np.nan_to_num(means_all, nan=-1.0))
               if names[i] in suggested and np.isfinite(means_all[i])]
    top = np.nanmax(means_all) if np.any(np.isfinite(means_all)) else 1.0
    for i in flagged[: max(0, int(worst))]:
        ax.annotate(names[i], (i, means_all[i]), xytext=(0, 6), textcoords="offset points",
                    ha="center", va="bottom", fontsize=7, color="tab:red")
    ax.set_xticks(np.arange(len(names)))
    ax.set_xticklabels(names, rotation=90, fontsize=6)
    ax.set_ylabel("mean reprojection error (px)")
    who = f"{camera} camera" if camera is not None and stereo else ("both cameras" if stereo else "")
    verdict = (f"{len(suggested)} suggested for suppression (red)" if suggested
               else "none suggested for suppression")
    ax.set_title(f"Reprojection error per view{', ' + who if who else ''}\n{verdict}", fontsize=9)
    if len(sides) > 1:
        ax.legend(fontsize=7)
    ax.set_ylim(0, max(top * 1.3, highest * 1.05))
    return ax


def plot_coverage(result, *, camera=None, ax=None, show_unused=True):
    """Show where the corners fell in the image, one colour per view.

    Parameters
    ----------
    result : CameraCalibration or StereoCalibration
    camera : {"left", "right"}, optional
        Which camera of a stereo calibration (default left).
    ax : matplotlib Axes, optional
    show_unused : bool, optional
        Also draw the corners of views that were detected but not used (grey x).

    Returns
    -------
    ax : matplotlib Axes
        The image frame, each used view's corners and the outline of its board; areas
        without corners (often the image corners) constrain the distortion poorly.
    """
    names, used, _, corners, size = _calibration_views(result, camera)
    ax = _axes(ax)
    idx = np.flatnonzero(used)
    colours = _colours(len(idx))
    pattern = getattr(result, "pattern_size", None)
    for c, i in zip(colours, idx):
        pts = corners[i]
        ax.plot(pts[:, 0], pts[:, 1], ".", color=c, ms=3, label=names[i])
        if pattern is not None and pts.shape[0] == pattern[0] * pattern[1]:
            g = pts.reshape(pattern[1], pattern[0], 2)
            ring = np.concatenate([g[0, :], g[:, -1], g[-1, ::-1], g[::-1, 0]])
            ax.plot(ring[:, 0], ring[:, 1], "-", color=c, lw=0.6)
    if show_unused:
        for i in np.flatnonzero(~used):
            if corners[i] is not None:
                ax.plot(corners[i][:, 0], corners[i][:, 1], "x", color="0.6", ms=3)
    if size is not None:
        w, h = size
        ax.plot([-0.5, w - 0.5, w - 0.5, -0.5, -0.5], [-0.5, -0.5, h - 0.5, h - 0.5, -0.5], "k-", lw=1)
        ax.set_xlim(-0.5 - 0.02 * w, w - 0.5 + 0.02 * w)
        ax.set_ylim(h - 0.5 + 0.02 * h, -0.5 - 0.02 * h)
    else:
        ax.invert_yaxis()
    ax.set_aspect("equal")
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    n = sum(int(np.isfinite(corners[i][:, 0]).sum()) for i in idx)
    side = f" ({camera or 'left'} camera)" if hasattr(result, "rig") else ""
    ax.set_title(f"Corner coverage{side}: {n} corners in {len(idx)} views")
    return ax


# --- image overviews ---
def plot_contact_sheet(images, *, titles=None, ncols=7, axes=None, cmap="gray", size=1.8):
    """Show many images as a grid (e.g. the 21 calibration views of a pan-tilt schedule).

    Parameters
    ----------
    images : sequence of (H, W) arrays or a read_sequence
        The images, shown in order, row by row; each is scaled to its own min-max.
    titles : sequence of str, optional
        One short title per image.
    ncols : int
        Images per row (7 = one pan sweep of the thesis' schedule).
    axes : array of Axes, optional
        At least ``len(images)`` axes to draw into; a new figure otherwise.
    size : float
        Inches per image for a new figure.

    Returns
    -------
    axes : (rows, ncols) ndarray of Axes
    """
    import matplotlib.pyplot as plt

    n = len(images)
    if n == 0:
        raise ValueError("images is empty: nothing to show")
    if titles is not None and len(titles) != n:
        raise ValueError(f"titles must have one entry per image ({n}), got {len(titles)}")
    ncols = max(1, min(int(ncols), n))
    nrows = -(-n // ncols)
    if axes is None:
        _, axes = plt.subplots(nrows, ncols, figsize=(size * ncols, size * nrows), squeeze=False)
    axes = np.asarray(axes, dtype=object).reshape(-1)
    if axes.size < n:
        raise ValueError(f"axes has {axes.size} axes for {n} images")
    for k, ax in enumerate(axes):
        ax.set_axis_off()
        if k < n:
            ax.imshow(np.asarray(images[k]), cmap=cmap)
            if titles is not None:
                ax.set_title(str(titles[k]), fontsize=8)
    return axes.reshape(nrows, -1) if axes.size == nrows * ncols else axes


# --- picks ---
def plot_picks(images, picks, *, frame=0, axes=None, figsize=None):
    """Show the picked markers, numbered, on every view (the picker's headless figure).

    Parameters
    ----------
    images : dict
        ``{camera: (H, W) image}`` (the frame the markers were picked in).
    picks : PickerState or pandas.DataFrame
        The picks: a :class:`~wingphoto.widgets.state.PickerState` or a table with
        columns camera, point, x, y[, half_w, half_h] (:func:`wingphoto.picks.read_picks`).
    frame : int
        Frame number, for the titles.
    axes : sequence of Axes, optional
        One per camera; a new figure otherwise.
    figsize : (w, h), optional

    Returns
    -------
    matplotlib.figure.Figure
        One panel per camera: image, each marker's subimage box, its centre and its number
        written beside the centre.
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    if hasattr(picks, "to_table"):
        picks = picks.to_table()
    cameras = [c for c in ("left", "right") if c in images]
    if not cameras:
        raise ValueError(f"images must be a dict with 'left' and/or 'right', got keys {list(images)}")
    if axes is None:
        fig, axes = plt.subplots(1, len(cameras), figsize=figsize or (5.0 * len(cameras), 5.0), squeeze=False)
        axes = axes[0]
    else:
        axes = list(np.atleast_1d(axes))
        fig = axes[0].figure
    for ax, cam in zip(axes, cameras):
        img = np.asarray(images[cam])
        lo, hi = np.nanpercentile(img, [0.5, 99.8]) if img.size else (0, 1)
        ax.imshow(img, cmap="gray", vmin=lo, vmax=hi if hi > lo else lo + 1, interpolation="nearest")
        rows = picks[picks["camera"] == cam] if "camera" in picks.columns else picks
        for r in rows.itertuples(index=False):
            hw = getattr(r, "half_w", np.nan)
            hh = getattr(r, "half_h", np.nan)
            if np.isfinite(hw) and np.isfinite(hh):
                ax.add_patch(Rectangle((r.x - hw, r.y - hh), 2 * hw, 2 * hh, fill=False, edgecolor="cyan", lw=0.7))
            ax.plot([r.x], [r.y], "+", color="yellow", ms=6, mew=1)
            ax.annotate(str(int(r.point)), (r.x, r.y), xytext=(3, -3), textcoords="offset points", fontsize=7,
                        color="yellow", ha="left", va="bottom",
                        bbox=dict(boxstyle="round,pad=0.1", facecolor="black", alpha=0.55, linewidth=0))
        ax.set_title(f"{cam} view, frame {frame}: {len(rows)} markers picked", fontsize=9)
        ax.set_xlabel("x (px)")
        ax.set_ylabel("y (px)")
        if len(rows):  # zoom on the picked area with a margin, so the numbers are readable
            pad = 30.0
            x0, x1 = rows["x"].min() - pad, rows["x"].max() + pad
            y0, y1 = rows["y"].min() - pad, rows["y"].max() + pad
            ax.set_xlim(max(x0, -0.5), min(x1, img.shape[1] - 0.5))
            ax.set_ylim(min(y1, img.shape[0] - 0.5), max(y0, -0.5))
    fig.tight_layout()
    return fig
