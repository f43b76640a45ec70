"""The error analysis: which views to suppress (the toolbox's Analyse error, automated)."""
from __future__ import annotations

import numpy as np

from .checks import _MIN_VIEWS
from .mono import CameraCalibration
from .stereo import StereoCalibration

# ============================================================== error analysis
def suggest_suppress(result, *, factor=2.0):
    """Name the views whose reprojection error stands out (candidates to suppress).

    Parameters
    ----------
    result : CameraCalibration or StereoCalibration
    factor : float, optional
        A view is suggested when its mean reprojection error exceeds ``factor`` times
        the median over the used views (for a stereo pair, the worse of its two
        images). Default 2.

    Returns
    -------
    names : list of str
        View (or pair) names, worst first, at most as many as keep 3 views in use; pass
        them to ``result.suppress(names)``. Empty when no view stands out.

    Notes
    -----
    The toolbox leaves this judgement to the user reading the "Analyse error" figure
    (:func:`wingphoto.plots.plot_residuals`, :func:`wingphoto.plots.plot_view_errors`);
    this rule gives the same candidates for a view with a mislocated corner or a
    blurred board.
    """
    if not np.isfinite(factor) or factor <= 0:
        raise ValueError(f"factor must be a positive number, got {factor!r}")
    if isinstance(result, StereoCalibration):
        ve = result.view_errors
        err = np.full(len(ve), np.nan)
        seen = np.isfinite(ve).any(axis=1)
        err[seen] = np.nanmax(ve[seen], axis=1)  # unused pairs stay NaN (no all-NaN warning)
        names = result.pairs
    elif isinstance(result, CameraCalibration):
        err = result.view_errors
        names = result.views
    else:
        raise ValueError(f"result must be a CameraCalibration or StereoCalibration, got {type(result).__name__}")
    used = np.flatnonzero(np.asarray(result.used))
    med = float(np.median(err[used]))
    bad = [i for i in used if err[i] > factor * med]
    bad.sort(key=lambda i: -err[i])
    return [names[i] for i in bad[: max(0, len(used) - _MIN_VIEWS)]]
