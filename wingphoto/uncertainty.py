"""Uncertainty of every triangulated 3D point: calibration and tracking, propagated to first order.

A triangulated point ``X = f(xL, xR; theta)`` depends on the two pixel positions and on
the 26 rig parameters ``theta`` (``fc, cc, alpha_c, kc`` of both cameras, ``om``, ``T``;
the order of :data:`wingphoto.calibrate.RIG_PARAMETER_NAMES`). To first order::

    Cov(X) = Jx diag(sL^2, sL^2, sR^2, sR^2) Jx^T   (tracking: each 2D point's sigma)
           + Jt Cov(theta) Jt^T                     (calibration: its full covariance)

with ``Jx = dX/d(xL, xR)`` and ``Jt = dX/dtheta`` by central finite differences of
:func:`wingphoto.triangulate.stereo_triangulation` (steps of 1e-3 px, and 1 % of each
parameter's own sigma). The two terms are reported separately so a user sees which
dominates. ``sigma_X, sigma_Y, sigma_Z`` are the square roots of the diagonal (1-sigma,
mm, left camera frame).

The calibration term is the same for all frames of a point that does not move: it is a
bias of the whole reconstruction rather than frame-to-frame scatter. Frame-to-frame
scatter (e.g. the spread of a rigid length) is predicted by the tracking term alone.

A calibration from :func:`wingphoto.calibrate.calibrate_stereo` carries its full
covariance (``.covariance``, ``.parameter_names``). A calibration read from a toolbox
``Calib_Results_stereo.mat`` has only the 3-sigma errors: a diagonal covariance is then
used (parameter correlations ignored), a warning is logged and the result says so.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .camera import Camera, StereoRig
from .triangulate import stereo_triangulation

__all__ = [
    "CalibrationCovariance",
    "calibration_covariance",
    "rig_parameters",
    "rig_from_parameters",
    "triangulation_jacobians",
    "propagate_point_covariance",
    "add_point_uncertainty",
    "monte_carlo_errors",
    "coverage",
    "DEFAULT_POINT_SIGMA_PX",
    "COV_NAMES",
    "point_covariances",
]

log = logging.getLogger(__name__)

#: 2D positional uncertainty (1-sigma, px, per axis) assumed where tracks carry no sigma.
DEFAULT_POINT_SIGMA_PX = 0.1
#: Names of the six independent entries of a 3D covariance (columns ``cov_XX`` ...).
COV_NAMES = ("XX", "XY", "XZ", "YY", "YZ", "ZZ")
_COV_INDEX = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def covariance_array(points, frames, ids):
    """(T, N, 3, 3) per-point covariances of a points table laid out on its frame x point grid.

    Uses the tracking term (``*_track`` columns) when the table has it, else the total;
    NaN where a (frame, point) has no row. Returns None when the table carries no
    uncertainty columns (or is not a DataFrame). Used by the derived quantities (length
    statistics, kinematic angles), whose calibration term largely cancels between
    neighbouring markers.
    """
    if not isinstance(points, pd.DataFrame):
        return None
    C, _ = point_covariances(points, part="_track")
    if C is None:
        C, _ = point_covariances(points)
    if C is None:
        return None
    out = np.full((len(frames), len(ids), 3, 3), np.nan)
    fi = pd.Index(frames).get_indexer(points["frame"].to_numpy())
    pi = pd.Index(ids).get_indexer(points["point"].to_numpy())
    keep = (fi >= 0) & (pi >= 0)
    out[fi[keep], pi[keep]] = C[keep]
    return out


def point_covariances(points, *, part=""):
    """(N, 3, 3) covariance of each row of a points table, from its ``cov_*`` or ``sigma_*`` columns.

    Parameters
    ----------
    points : pandas.DataFrame
    part : {"", "_track", "_calib"}
        Which term: total, tracking only, calibration only.

    Returns
    -------
    cov : (N, 3, 3) ndarray or None
        The full covariance when the six ``cov_XX{part}`` ... columns exist, else the
        diagonal from ``sigma_X{part}`` ... (correlations unknown), else None.
    full : bool
        Whether the correlations are included.
    """
    cols = [f"cov_{n}{part}" for n in COV_NAMES]
    if set(cols) <= set(points.columns):
        C = np.zeros((len(points), 3, 3))
        for (i, j), c in zip(_COV_INDEX, cols):
            C[:, i, j] = C[:, j, i] = points[c].to_numpy(np.float64)
        return C, True
    cols = [f"sigma_{a}{part}" for a in "XYZ"]
    if set(cols) <= set(points.columns):
        s = points[cols].to_numpy(np.float64)
        C = np.zeros((len(points), 3, 3))
        C[:, [0, 1, 2], [0, 1, 2]] = s**2
        return C, False
    return None, False


def _names():
    from .calibrate import RIG_PARAMETER_NAMES

    return tuple(RIG_PARAMETER_NAMES)


def rig_parameters(rig):
    """The rig's 26 parameters in the order of ``RIG_PARAMETER_NAMES`` (a (26,) array).

    Examples
    --------
    >>> from wingphoto.synth import thesis_rig
    >>> rig_parameters(thesis_rig()).shape
    (26,)
    """
    out = []
    for cam in (rig.left, rig.right):
        out += [*cam.fc, *cam.cc, cam.alpha_c, *cam.kc]
    out += [*rig.om, *rig.T]
    return np.asarray(out, dtype=np.float64)


def rig_from_parameters(rig, theta):
    """A copy of ``rig`` with its 26 parameters replaced by ``theta`` (image sizes kept)."""
    th = np.asarray(theta, dtype=np.float64).reshape(-1)
    if th.shape != (26,):
        raise ValueError(f"theta must hold the 26 rig parameters, got shape {th.shape}")

    def cam(c, o):
        return Camera(fc=th[o : o + 2], cc=th[o + 2 : o + 4], alpha_c=th[o + 4], kc=th[o + 5 : o + 10],
                      image_size=c.image_size)

    return StereoRig(cam(rig.left, 0), cam(rig.right, 10), om=th[20:23], T=th[23:26])


@dataclass(frozen=True)
class CalibrationCovariance:
    """The covariance of the 26 rig parameters used for propagation.

    Attributes
    ----------
    covariance : (26, 26) ndarray
        1-sigma covariance, order of ``parameter_names``.
    parameter_names : tuple of str
    diagonal : bool
        True when only per-parameter errors were available (a toolbox ``.mat``): the
        correlations are then ignored.
    source : str
        Where it came from (for reports).
    """

    covariance: np.ndarray = field(repr=False)
    parameter_names: tuple = field(repr=False)
    diagonal: bool
    source: str

    @property
    def sigma(self):
        """1-sigma of each parameter, (26,)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))


def _diag_from_uncertainty(unc, source):
    names = _names()
    var = np.zeros(len(names))
    found = False
    for i, name in enumerate(names):
        base, _, idx = name.partition("[")
        if base not in unc:
            continue
        v = np.atleast_1d(np.asarray(unc[base], dtype=np.float64)).reshape(-1)
        k = int(idx.rstrip("]")) if idx else 0
        if k < v.size and np.isfinite(v[k]):
            var[i] = (v[k] / 3.0) ** 2  # the toolbox stores 3-sigma errors
            found = True
    if not found:
        raise ValueError(
            f"{source} holds no parameter errors (fc_left, ..., om, T): cannot propagate the calibration's uncertainty"
        )
    log.warning("%s carries only the toolbox's 3-sigma errors: using a diagonal covariance of the rig parameters "
                "(their correlations are ignored, which usually overstates the 3D uncertainty)", source)
    return CalibrationCovariance(covariance=np.diag(var), parameter_names=names, diagonal=True, source=source)


def calibration_covariance(calibration):
    """The rig parameters' covariance from a calibration result, a toolbox file's errors, or a matrix.

    Parameters
    ----------
    calibration : StereoCalibration, dict, (rig, dict) tuple, (26, 26) array or CalibrationCovariance
        A :class:`~wingphoto.calibrate.StereoCalibration` (its full ``.covariance``); the
        3-sigma ``uncertainty`` dict of :func:`wingphoto.io.load_bouguet_stereo` (alone
        or with its rig), giving a diagonal covariance; or a covariance matrix in the
        order of ``RIG_PARAMETER_NAMES``.

    Returns
    -------
    CalibrationCovariance

    Raises
    ------
    ValueError
        Anything else, or a matrix of the wrong shape or with other parameter names.
    """
    names = _names()
    if isinstance(calibration, CalibrationCovariance):
        return calibration
    cov = getattr(calibration, "covariance", None)
    if cov is not None:
        pn = tuple(getattr(calibration, "parameter_names", names))
        if pn != names:
            raise ValueError(f"the calibration's parameter_names {pn[:3]}... differ from {names[:3]}...; cannot map them")
        return CalibrationCovariance(covariance=np.asarray(cov, dtype=np.float64), parameter_names=names,
                                     diagonal=False, source="calibrate_stereo covariance")
    if hasattr(calibration, "uncertainty") and isinstance(calibration.uncertainty, dict):
        return _diag_from_uncertainty(calibration.uncertainty, f"{type(calibration).__name__} (no covariance)")
    if isinstance(calibration, tuple) and len(calibration) == 2 and isinstance(calibration[1], dict):
        return _diag_from_uncertainty(calibration[1], "the toolbox .mat calibration")
    if isinstance(calibration, dict):
        return _diag_from_uncertainty(calibration, "the toolbox .mat calibration")
    arr = np.asarray(calibration, dtype=np.float64) if isinstance(calibration, (np.ndarray, list)) else None
    if arr is not None and arr.shape == (len(names), len(names)):
        return CalibrationCovariance(covariance=arr, parameter_names=names, diagonal=False, source="given matrix")
    raise ValueError(
        "calibration must be a StereoCalibration (calibrate_stereo), the uncertainty dict (or (rig, uncertainty)) of "
        f"load_bouguet_stereo, or a ({len(names)}, {len(names)}) covariance matrix; got {type(calibration).__name__}"
    )


def _tri(xL, xR, rig):
    X, _ = stereo_triangulation(xL, xR, rig)
    return np.asarray(X).reshape(-1, 3)


def triangulation_jacobians(xL, xR, rig, *, parameters=None, step_px=1e-3):
    """Derivatives of the triangulated points with respect to the pixels and the rig parameters.

    Parameters
    ----------
    xL, xR : (N, 2) array_like
        Pixels in the left and right image.
    rig : StereoRig
    parameters : (26,) array_like of float, optional
        Finite-difference step of each rig parameter (0 skips it); default no parameter
        derivatives.
    step_px : float
        Pixel step.

    Returns
    -------
    J_px : (N, 3, 4) ndarray
        ``dX / d(xL, yL, xR, yR)`` (mm / px).
    J_theta : (N, 3, 26) ndarray or None
        ``dX / dtheta`` (zero for skipped parameters).
    """
    xL = np.asarray(xL, dtype=np.float64).reshape(-1, 2)
    xR = np.asarray(xR, dtype=np.float64).reshape(-1, 2)
    n = len(xL)
    Jx = np.zeros((n, 3, 4))
    for k in range(4):
        dL, dR = np.zeros((n, 2)), np.zeros((n, 2))
        (dL if k < 2 else dR)[:, k % 2] = step_px
        Jx[:, :, k] = (_tri(xL + dL, xR + dR, rig) - _tri(xL - dL, xR - dR, rig)) / (2 * step_px)
    Jt = None
    if parameters is not None:
        steps = np.asarray(parameters, dtype=np.float64).reshape(-1)
        theta = rig_parameters(rig)
        Jt = np.zeros((n, 3, len(theta)))
        for i, h in enumerate(steps):
            if not h > 0:
                continue
            tp, tm = theta.copy(), theta.copy()
            tp[i] += h
            tm[i] -= h
            Jt[:, :, i] = (_tri(xL, xR, rig_from_parameters(rig, tp)) - _tri(xL, xR, rig_from_parameters(rig, tm))) / (2 * h)
    return Jx, Jt


def propagate_point_covariance(xL, xR, rig, *, sigma_left, sigma_right, calibration=None):
    """First-order 3D covariance of triangulated points, tracking and calibration terms apart.

    Parameters
    ----------
    xL, xR : (N, 2) array_like
        Pixels (NaN rows give NaN).
    rig : StereoRig
        The calibrated rig the points are triangulated with.
    sigma_left, sigma_right : float or (N,) array_like
        1-sigma per-axis pixel uncertainty of each observation, px.
    calibration : optional
        Anything :func:`calibration_covariance` takes; None leaves out the calibration
        term (then ``cov_calib`` is NaN).

    Returns
    -------
    dict
        ``cov_track``, ``cov_calib``, ``cov`` : (N, 3, 3) ndarrays (mm^2), and
        ``calibration`` (the :class:`CalibrationCovariance` or None).
    """
    xL = np.asarray(xL, dtype=np.float64).reshape(-1, 2)
    xR = np.asarray(xR, dtype=np.float64).reshape(-1, 2)
    n = len(xL)
    sl = np.broadcast_to(np.asarray(sigma_left, dtype=np.float64), (n,))
    sr = np.broadcast_to(np.asarray(sigma_right, dtype=np.float64), (n,))
    cc = None if calibration is None else calibration_covariance(calibration)
    steps = None if cc is None else 1e-2 * cc.sigma
    Jx, Jt = triangulation_jacobians(xL, xR, rig, parameters=steps)
    W = np.stack([sl**2, sl**2, sr**2, sr**2], axis=1)  # (N, 4)
    cov_track = np.einsum("nik,nk,njk->nij", Jx, W, Jx)
    if cc is not None:
        C = cc.covariance
        cov_calib = np.einsum("nik,kl,njl->nij", Jt, C, Jt)
        cov = cov_track + cov_calib
    else:
        cov_calib = np.full_like(cov_track, np.nan)
        cov = cov_track
    return {"cov_track": cov_track, "cov_calib": cov_calib, "cov": cov, "calibration": cc}


def _pixel_table(t, name):
    cols = ["frame", "point", "x", "y"] + (["sigma"] if "sigma" in t.columns else [])
    out = t[cols].copy()
    if "sigma" not in out.columns:
        out["sigma"] = np.nan
    return out.rename(columns={"x": f"x_{name}", "y": f"y_{name}", "sigma": f"sigma_{name}"})


def add_point_uncertainty(points, tracks_left, tracks_right, rig, *, calibration=None, point_sigma_px=None,
                          full=False):
    """Add per-point 1-sigma columns (tracking, calibration, total) to a 3D points table.

    Parameters
    ----------
    points : pandas.DataFrame
        3D points (frame, point, X, Y, Z, ...), triangulated from the two tracks tables.
    tracks_left, tracks_right : pandas.DataFrame
        The tracks the points came from (frame, point, x, y, optional ``sigma`` px); one
        camera each.
    rig : StereoRig
    calibration : optional
        Anything :func:`calibration_covariance` takes; None: tracking term only.
    point_sigma_px : float, optional
        2D sigma (px) used where the tracks carry none (default
        :data:`DEFAULT_POINT_SIGMA_PX`, 0.1 px; the number used is logged).
    full : bool
        Also add the six covariance entries ``cov_XX, cov_XY, cov_XZ, cov_YY, cov_YZ,
        cov_ZZ`` (mm^2, total) and the same of the tracking term (``cov_XX_track`` ...).
        A stereo point's error lies mostly along the viewing rays, so its axes are
        strongly correlated: derived quantities (lengths, angles) are propagated
        correctly only with these; with the per-axis sigmas alone the correlations are
        ignored.

    Returns
    -------
    pandas.DataFrame
        ``points`` with ``sigma_X, sigma_Y, sigma_Z`` (total), ``sigma_X_track`` ...
        (tracking only) and ``sigma_X_calib`` ... (calibration only; NaN without a
        calibration), mm. ``attrs["uncertainty"]`` records the calibration source,
        whether its covariance was diagonal, and the assumed 2D sigma.
    """
    default = DEFAULT_POINT_SIGMA_PX if point_sigma_px is None else float(point_sigma_px)
    if not default > 0:
        raise ValueError(f"point_sigma_px must be a positive 2D sigma in px, got {point_sigma_px!r}")
    key = ["frame", "point"]
    m = points[key].merge(_pixel_table(tracks_left, "l"), on=key, how="left").merge(
        _pixel_table(tracks_right, "r"), on=key, how="left")
    sl, sr = m["sigma_l"].to_numpy(float), m["sigma_r"].to_numpy(float)
    n_assumed = int(np.sum(~(np.isfinite(sl) & (sl > 0))) + np.sum(~(np.isfinite(sr) & (sr > 0))))
    if n_assumed:
        log.info("%d of %d 2D observations carry no sigma: assuming %.3g px", n_assumed, 2 * len(m), default)
    sl = np.where(np.isfinite(sl) & (sl > 0), sl, default)
    sr = np.where(np.isfinite(sr) & (sr > 0), sr, default)
    res = propagate_point_covariance(m[["x_l", "y_l"]].to_numpy(float), m[["x_r", "y_r"]].to_numpy(float), rig,
                                     sigma_left=sl, sigma_right=sr, calibration=calibration)
    out = points.copy()
    finite = np.isfinite(points[["X", "Y", "Z"]].to_numpy(float)).all(axis=1)
    for tag, cov in (("", res["cov"]), ("_track", res["cov_track"]), ("_calib", res["cov_calib"])):
        s = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0.0, None))
        s[~finite] = np.nan
        for i, ax in enumerate("XYZ"):
            out[f"sigma_{ax}{tag}"] = s[:, i]
    if full:
        for tag, cov in (("", res["cov"]), ("_track", res["cov_track"])):
            for (i, j), name in zip(_COV_INDEX, COV_NAMES):
                v = cov[:, i, j].copy()
                v[~finite] = np.nan
                out[f"cov_{name}{tag}"] = v
    cc = res["calibration"]
    out.attrs["uncertainty"] = {
        "calibration": "none" if cc is None else cc.source,
        "diagonal_calibration_covariance": bool(cc is not None and cc.diagonal),
        "assumed_point_sigma_px": default,
        "observations_with_assumed_sigma": n_assumed,
    }
    return out


def monte_carlo_errors(X, rig, *, sigma_px=0.0, calibration=None, n_draws=200, seed=0):
    """3D errors of triangulation under simulated pixel noise and calibration error.

    For validation: the true points ``X`` are projected with the true ``rig``; each draw
    adds Gaussian pixel noise (``sigma_px`` per axis) to both views and triangulates
    with a rig whose parameters are drawn from ``N(theta_true, Cov(theta))``.

    Parameters
    ----------
    X : (N, 3) array_like
        True points, mm, left camera frame.
    rig : StereoRig
        The true rig.
    sigma_px : float or (N,) array_like
    calibration : optional
        Anything :func:`calibration_covariance` takes; None: no calibration error.
    n_draws : int
    seed : int

    Returns
    -------
    errors : (n_draws, N, 3) ndarray
        Triangulated minus true, mm.
    """
    rng = np.random.default_rng(seed)
    X = np.asarray(X, dtype=np.float64).reshape(-1, 3)
    xL, xR = rig.project(X)
    n = len(X)
    s = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64), (n,))[:, None]
    theta = rig_parameters(rig)
    cc = None if calibration is None else calibration_covariance(calibration)
    if cc is not None:
        w, V = np.linalg.eigh(cc.covariance)
        A = V * np.sqrt(np.clip(w, 0.0, None))
    out = np.empty((int(n_draws), n, 3))
    for k in range(int(n_draws)):
        r = rig if cc is None else rig_from_parameters(rig, theta + A @ rng.standard_normal(len(theta)))
        nl = rng.standard_normal((n, 2)) * s
        nr = rng.standard_normal((n, 2)) * s
        out[k] = _tri(xL + nl, xR + nr, r) - X
    return out


def coverage(errors, sigma):
    """Share of errors within 1, 2 and 3 sigma per axis, and the ratio of scatter to sigma.

    Parameters
    ----------
    errors : (D, N, 3) or (N, 3) array_like
        Errors (estimate minus truth), mm: Monte Carlo draws of N points, or one
        realisation.
    sigma : (N, 3) array_like
        Reported 1-sigma per point and axis, mm.

    Returns
    -------
    pandas.DataFrame
        One row per axis (X, Y, Z): within_1sigma, within_2sigma, within_3sigma (shares;
        a Gaussian gives 0.683, 0.954, 0.997) and scatter_over_sigma (median over
        points of the RMS error / sigma; 1 when the sigma is right).
    """
    E = np.asarray(errors, dtype=np.float64)
    if E.ndim == 2:
        E = E[None]
    S = np.asarray(sigma, dtype=np.float64).reshape(E.shape[1:])
    z = np.abs(E) / S
    rows = []
    for i, ax in enumerate("XYZ"):
        zi = z[..., i]
        zi = zi[np.isfinite(zi)]
        rms = np.sqrt(np.nanmean(E[..., i] ** 2, axis=0)) / S[:, i]
        rows.append({"axis": ax, "within_1sigma": float(np.mean(zi <= 1)), "within_2sigma": float(np.mean(zi <= 2)),
                     "within_3sigma": float(np.mean(zi <= 3)), "scatter_over_sigma": float(np.nanmedian(rms))})
    return pd.DataFrame(rows)
