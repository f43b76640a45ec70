"""Stereo triangulation as in Bouguet's toolbox, and reprojection errors.

See ``docs/conventions.md`` for frames and units.
"""
from __future__ import annotations

import logging

import numpy as np

from .camera import StereoRig, as_points

log = logging.getLogger(__name__)

__all__ = ["stereo_triangulation", "reprojection_error", "triangulate_tracks"]


def stereo_triangulation(xL, xR, rig):
    """Triangulate left/right pixel pairs to 3D (the toolbox's ``stereo_triangulation``).

    Parameters
    ----------
    xL, xR : (N, 2) or (2,) array_like
        Corresponding pixels in the left and right images, origin at the centre of the
        top-left pixel. NaN rows give NaN rows.
    rig : StereoRig
        Calibrated stereo rig.

    Returns
    -------
    XL : (N, 3) or (3,) ndarray
        Points in mm in the left camera frame.
    XR : (N, 3) or (3,) ndarray
        The same points in the right camera frame, ``R @ XL + T``.

    Notes
    -----
    Each pixel is undistorted to a ray (``normalize_pixel``, 20 fixed-point
    iterations). With ``xt``, ``xtt`` the homogeneous normalised rays of the left and
    right camera and ``u = R xt``, the depths ``Zt``, ``Ztt`` minimise the distance
    between the two rays (the common perpendicular)::

        D   = |xt|^2 |xtt|^2 - (u.xtt)^2
        Zt  = ((u.xtt)(xtt.T) - |xtt|^2 (u.T)) / D
        Ztt = (|xt|^2 (xtt.T) - (u.T)(u.xtt)) / D

    and the point is the midpoint ``XL = (Zt xt + R^T (Ztt xtt - T)) / 2``.
    The arithmetic follows the toolbox line by line so that results agree to ~1e-12.

    Examples
    --------
    >>> from wingphoto.camera import Camera, StereoRig
    >>> cam = Camera(fc=[1000, 1000], cc=[255.5, 255.5])
    >>> rig = StereoRig(cam, cam, om=[0, 0, 0], T=[-100, 0, 0])
    >>> xL, xR = rig.project([[10.0, 5.0, 800.0]])
    >>> XL, XR = stereo_triangulation(xL, xR, rig)
    >>> np.round(XL, 6).tolist()
    [[10.0, 5.0, 800.0]]
    """
    if not isinstance(rig, StereoRig):
        raise ValueError(f"rig must be a wingphoto.StereoRig, got {type(rig).__name__}")
    pL, single = as_points(xL, 2, "xL")
    pR, single_r = as_points(xR, 2, "xR")
    if pL.shape != pR.shape:
        raise ValueError(f"xL and xR must have the same number of rows, got {pL.shape} and {pR.shape}")
    n = len(pL)
    xt = np.column_stack([rig.left.normalize(pL), np.ones(n)]).T  # (3, N) as the toolbox
    xtt = np.column_stack([rig.right.normalize(pR), np.ones(n)]).T
    R = rig.R
    T = rig.T.reshape(3, 1)
    u = R @ xt
    n_xt2 = np.sum(xt * xt, axis=0)
    n_xtt2 = np.sum(xtt * xtt, axis=0)
    dot_uxtt = np.sum(u * xtt, axis=0)
    DD = n_xt2 * n_xtt2 - dot_uxtt**2
    dot_uT = np.sum(u * T, axis=0)
    dot_xttT = np.sum(xtt * T, axis=0)
    NN1 = dot_uxtt * dot_xttT - n_xtt2 * dot_uT
    NN2 = n_xt2 * dot_xttT - dot_uT * dot_uxtt
    with np.errstate(invalid="ignore", divide="ignore"):
        Zt = NN1 / DD
        Ztt = NN2 / DD
    X1 = xt * Zt
    X2 = R.T @ (xtt * Ztt - T)
    XL = 0.5 * (X1 + X2)
    XR = R @ XL + T
    XL, XR = XL.T, XR.T
    if single and single_r:
        return XL[0], XR[0]
    return XL, XR


def reprojection_error(XL, xL, xR, rig):
    """Distance between observed pixels and the reprojection of triangulated points.

    Parameters
    ----------
    XL : (N, 3) array_like
        Points in mm in the left camera frame.
    xL, xR : (N, 2) array_like
        Observed pixels in the left and right images.
    rig : StereoRig

    Returns
    -------
    err : (N, 2) ndarray
        Pixels; column 0 the left camera, column 1 the right camera. NaN where the
        point or the observation is missing.
    """
    X, _ = as_points(XL, 3, "XL")
    pL, _ = as_points(xL, 2, "xL")
    pR, _ = as_points(xR, 2, "xR")
    if not (len(X) == len(pL) == len(pR)):
        raise ValueError(f"XL, xL, xR must have the same number of rows, got {len(X)}, {len(pL)}, {len(pR)}")
    qL, qR = rig.project(X)
    return np.column_stack([np.linalg.norm(qL - pL, axis=1), np.linalg.norm(qR - pR, axis=1)])


def triangulate_tracks(tracks_left, tracks_right, rig, *, ok_status=("ok", "manual", "interpolated"), force=False,
                       calibration=None, point_sigma_px=None, full_covariance=False):
    """Triangulate two tracks DataFrames into the 3D points DataFrame.

    Parameters
    ----------
    tracks_left, tracks_right : pandas.DataFrame
        Tracks with columns frame, point, x, y and optionally status, camera and sigma
        (``docs/conventions.md``). With a ``camera`` column each table must hold its own
        camera (``left`` / ``right``); a table holding both cameras (the demo's
        ``tracks.csv``) is split, so the same combined table may be given as both.
    rig : StereoRig
    ok_status : tuple of str
        Statuses whose positions are trusted; any other status in either view gives NaN.
    force : bool
        Triangulate even when the result fails the reprojection check (see Raises);
        the failure is then logged as a warning.
    calibration : StereoCalibration or (rig, uncertainty) or dict, optional
        With it, each point gets ``sigma_X, sigma_Y, sigma_Z`` (1-sigma, mm) and their
        tracking-only (``_track``) and calibration-only (``_calib``) parts, propagated to
        first order from the calibration's covariance and each 2D point's ``sigma``
        (:func:`wingphoto.uncertainty.add_point_uncertainty`; a toolbox .mat's 3-sigma
        errors give a diagonal covariance, with a warning).
    point_sigma_px : float, optional
        2D sigma (px) assumed where the tracks carry none (default 0.1 px).
    full_covariance : bool
        With ``calibration``, also add the 3D covariances ``cov_XX`` ... (total and
        ``_track``), which derived lengths and angles need (the axes are correlated).

    Returns
    -------
    points : pandas.DataFrame
        Columns frame, point, X, Y, Z (mm, left camera frame), reproj_err (px, the
        larger of the two views). One row per (frame, point) present in both tables.
        Two empty tables give an empty result with these columns.

    Raises
    ------
    ValueError
        A table is not a tracks DataFrame (an array, a missing column, non-integer
        frame or point numbers, a status outside ok / flagged / lost / manual /
        interpolated); the tables are the same camera, swapped, or identical; they
        share no point number or no frame; no (frame, point) is trusted in both views;
        positions lie outside the image by more than its size; or (unless ``force``)
        the median reprojection error exceeds 10 times the tracks' median ``sigma``
        (at least 0.5 px), or 2 px when the tracks carry no ``sigma``: the message names
        the likely cause (swapped cameras, a frame offset, a wrong calibration).
    """
    import pandas as pd

    if not isinstance(rig, StereoRig):
        raise ValueError(f"rig must be a wingphoto.StereoRig, got {type(rig).__name__}")
    tl = _check_tracks_table(tracks_left, "tracks_left")
    tr = _check_tracks_table(tracks_right, "tracks_right")
    tl, tr = _select_cameras(tl, tr)
    _check_unique(tl, "tracks_left")
    _check_unique(tr, "tracks_right")
    if len(tl) or len(tr):
        _check_overlap(tl, tr)
    _check_in_image(tl, rig.left, "tracks_left")
    _check_in_image(tr, rig.right, "tracks_right")
    m = _merge_trusted(tl, tr, ok_status)
    xL = m[["x_l", "y_l"]].to_numpy(float).reshape(-1, 2)
    xR = m[["x_r", "y_r"]].to_numpy(float).reshape(-1, 2)
    if len(m):
        _check_trusted_pairs(m, tl, tr, ok_status, force)
    XL, _ = stereo_triangulation(xL, xR, rig)
    XL = np.asarray(XL).reshape(-1, 3)
    err = reprojection_error(XL, xL, xR, rig).max(axis=1) if len(m) else np.zeros(0)
    if len(m):
        _check_reprojection(err, m, tl, tr, rig, ok_status, force)
    points = pd.DataFrame(
        {
            "frame": m["frame"].to_numpy(np.int64),
            "point": m["point"].to_numpy(np.int64),
            "X": XL[:, 0],
            "Y": XL[:, 1],
            "Z": XL[:, 2],
            "reproj_err": err,
        }
    )
    if calibration is not None:
        from .uncertainty import add_point_uncertainty

        points = add_point_uncertainty(points, tl, tr, rig, calibration=calibration, point_sigma_px=point_sigma_px,
                                       full=full_covariance)
    return points


# ----------------------------------------------------------------- consistency checks
#: Statuses a tracks table may carry (docs/conventions.md).
TRACK_STATUSES = ("ok", "flagged", "lost", "manual", "interpolated")
_TRACK_HELP = "a tracks DataFrame with columns frame, point, x, y, status (docs/conventions.md)"


def _check_tracks_table(t, name):
    """``t`` as a tracks DataFrame with int64 frame/point and float x/y, or a ValueError."""
    import pandas as pd

    if not isinstance(t, pd.DataFrame):
        hint = " (for pixel arrays use stereo_triangulation(xL, xR, rig))" if isinstance(t, np.ndarray) else ""
        raise ValueError(f"{name} must be {_TRACK_HELP}, got {type(t).__name__}{hint}")
    missing = [c for c in ("frame", "point", "x", "y") if c not in t.columns]
    if missing:
        raise ValueError(f"{name} lacks columns {missing}; expected {_TRACK_HELP}")
    t = t.copy()
    for col, what in (("frame", "frame numbers"), ("point", "marker numbers")):
        s = t[col]
        if not (pd.api.types.is_integer_dtype(s) or pd.api.types.is_float_dtype(s) or pd.api.types.is_bool_dtype(s)):
            example = s.iloc[0] if len(s) else None
            raise ValueError(
                f"{name}: column {col!r} must hold integer {what}, got {s.dtype} values (e.g. {example!r}); "
                f"convert it with .astype(int), or read the file with wingphoto.read_tracks_csv"
            )
        v = s.to_numpy(np.float64)
        if not np.all(np.isfinite(v)) or np.any(v != np.round(v)):
            bad = s[~(np.isfinite(v) & (v == np.round(v)))].iloc[0]
            raise ValueError(f"{name}: column {col!r} must hold whole {what} (no NaN), got {bad!r}")
        t[col] = v.astype(np.int64)
    for col in ("x", "y"):
        try:
            v = pd.to_numeric(t[col], errors="raise").to_numpy(np.float64)
        except (ValueError, TypeError) as exc:
            raise ValueError(
                f"{name}: column {col!r} must hold pixel coordinates (numbers, NaN when missing): {exc}"
            ) from None
        if np.any(np.isinf(v)):
            raise ValueError(f"{name}: column {col!r} holds infinite values; a missing position is NaN")
        t[col] = v
    if "status" in t.columns:
        status = t["status"]
        unknown = sorted({str(v) for v in status.dropna().unique()} - set(TRACK_STATUSES))
        if status.isna().any():
            unknown = ["<empty>"] + unknown
        if unknown:
            hint = ""
            if any(str(u).strip().lower() in TRACK_STATUSES for u in unknown):
                hint = " (statuses are lower case)"
            raise ValueError(
                f"{name}: unknown status value(s) {unknown[:5]}{hint}; a status is one of {', '.join(TRACK_STATUSES)}"
            )
    return t


def _select_cameras(tl, tr):
    """Keep each table's own camera rows; refuse swapped or duplicated views."""
    def cameras(t):
        if "camera" not in t.columns:
            return None
        return sorted({str(v) for v in t["camera"].dropna().unique()})

    def pick(t, want, name):
        cams = cameras(t)
        if not cams or cams == [want]:
            return t
        if want in cams:
            log.info("%s holds cameras %s: using its %r rows", name, cams, want)
            return t[t["camera"].astype(str) == want]
        if set(cams) <= {"left", "right"}:
            raise ValueError(
                f"{name} holds the tracks of camera {cams[0]!r}, not {want!r}: the left and right tracks are "
                f"swapped, the same file was given twice, or the {want} sequence was tracked with --camera "
                f"{cams[0]}; pass the {want} camera's tracks as {name}"
            )
        if len(cams) > 1:
            raise ValueError(
                f"{name} holds several cameras {cams} and none is named {want!r}; give one camera per table"
            )
        return t

    cl, cr = cameras(tl), cameras(tr)
    tl, tr = pick(tl, "left", "tracks_left"), pick(tr, "right", "tracks_right")
    if cl and cr and cl == cr and len(cl) == 1:
        raise ValueError(
            f"tracks_left and tracks_right are both camera {cl[0]!r}: the same file was given twice; "
            "pass each camera's own tracks"
        )
    return tl, tr


def _check_unique(t, name):
    """Refuse repeated (frame, point) rows: they would pair every copy with every other."""
    dup = t.duplicated(["frame", "point"], keep=False).to_numpy()
    if dup.any():
        row = t[dup].iloc[0]
        raise ValueError(
            f"{name} has {int(dup.sum())} rows repeating a (frame, point) (e.g. frame {row['frame']}, point "
            f"{row['point']}): a tracks table has one row per camera, frame and point; were two files concatenated?"
        )


def _span(values):
    values = np.unique(values)
    if len(values) == 0:
        return "none"
    return f"{values[0]}..{values[-1]} ({len(values)})"


def _check_overlap(tl, tr):
    """Refuse tables that share no point number or no frame."""
    for name, t in (("tracks_left", tl), ("tracks_right", tr)):
        if len(t) == 0:
            raise ValueError(f"{name} has no rows (for its camera); nothing can be triangulated")
    if not np.intersect1d(tl["point"], tr["point"]).size:
        raise ValueError(
            f"the left and right tracks share no point number (left points {_span(tl['point'])}, right points "
            f"{_span(tr['point'])}): marker k must carry the same number in both views (docs/conventions.md)"
        )
    if not np.intersect1d(tl["frame"], tr["frame"]).size:
        raise ValueError(
            f"the left and right tracks share no frame (left frames {_span(tl['frame'])}, right frames "
            f"{_span(tr['frame'])}): they must come from the same synchronized recording"
        )


def _check_in_image(t, camera, name):
    """Refuse positions outside the image by more than its size (another camera's, or not pixels)."""
    if camera.image_size is None or len(t) == 0:
        return
    w, h = camera.image_size
    x, y = t["x"].to_numpy(float), t["y"].to_numpy(float)
    with np.errstate(invalid="ignore"):
        out = (x < -w) | (x > 2 * w) | (y < -h) | (y > 2 * h)
    if out.any():
        k = int(np.flatnonzero(out)[0])
        row = t.iloc[k]
        raise ValueError(
            f"{name}: {int(out.sum())} position(s) lie outside the {w}x{h} image by more than its size (e.g. "
            f"frame {row['frame']}, point {row['point']} at ({x[k]:.1f}, {y[k]:.1f}) px): the tracks are not "
            "pixels of this calibration's camera"
        )


def _merge_trusted(tl, tr, ok_status):
    cols = ["frame", "point", "x", "y"]

    def trusted(t):
        t = t.copy()
        if "status" in t.columns:
            t.loc[~t["status"].isin(ok_status), ["x", "y"]] = np.nan
        return t[cols]

    m = trusted(tl).merge(trusted(tr), on=["frame", "point"], suffixes=("_l", "_r"))
    return m.sort_values(["frame", "point"], kind="stable").reset_index(drop=True)


def _check_trusted_pairs(m, tl, tr, ok_status, force):
    """Refuse a result that would be all NaN, or tables that are the same positions twice."""
    both = m[["x_l", "y_l", "x_r", "y_r"]].notna().all(axis=1).to_numpy()
    if not both.any():
        def statuses(t):
            return dict(t["status"].value_counts()) if "status" in t.columns else "no status column"

        msg = (
            f"no (frame, point) has a trusted position (status {' / '.join(ok_status)}) in both views; "
            f"left statuses {statuses(tl)}, right statuses {statuses(tr)}: review the tracks first"
        )
        if not force:
            raise ValueError(msg)
        log.warning(msg)
        return
    same = (m.loc[both, "x_l"].to_numpy() == m.loc[both, "x_r"].to_numpy()) & (
        m.loc[both, "y_l"].to_numpy() == m.loc[both, "y_r"].to_numpy()
    )
    if same.all():
        raise ValueError(
            "the left and right tracks hold identical positions: the same file was given as both views; "
            "pass each camera's own tracks"
        )


def _median_sigma(tl, tr):
    values = [t["sigma"].to_numpy(float) for t in (tl, tr) if "sigma" in t.columns]
    v = np.concatenate(values) if values else np.zeros(0)
    v = v[np.isfinite(v) & (v > 0)]
    return float(np.median(v)) if v.size else None


def _check_reprojection(err, m, tl, tr, rig, ok_status, force):
    """Stop when the median reprojection error says the tracks do not fit the calibration."""
    finite = err[np.isfinite(err)]
    if finite.size == 0:
        if m[["x_l", "y_l", "x_r", "y_r"]].notna().all(axis=1).any():
            msg = (f"no trusted pair could be triangulated (the rays are parallel or the calibration is degenerate: "
                   f"baseline {rig.baseline:.3g} mm); check the calibration file")
            if not force:
                raise ValueError(msg)
            log.warning(msg)
        return
    median = float(np.median(finite))
    sigma = _median_sigma(tl, tr)
    if sigma is None:
        limit, why = 2.0, "2 px (the tracks carry no sigma)"
    else:
        limit = max(10.0 * sigma, 0.5)
        why = f"{limit:.2f} px (10x the tracks' median sigma {sigma:.3f} px, at least 0.5 px)"
    if median <= limit:
        return
    msg = (f"median reprojection error {median:.2f} px exceeds {why}: the left and right tracks do not fit "
           f"this calibration. {_diagnose(tl, tr, rig, ok_status, median)} "
           "Pass force=True (wingphoto triangulate --force) to triangulate anyway.")
    if not force:
        raise ValueError(msg)
    log.warning(msg)


def _median_error(tl, tr, rig, ok_status, max_rows=2000):
    m = _merge_trusted(tl, tr, ok_status).dropna()
    if len(m) == 0:
        return np.inf
    if len(m) > max_rows:
        m = m.iloc[np.linspace(0, len(m) - 1, max_rows).astype(int)]
    xL, xR = m[["x_l", "y_l"]].to_numpy(float), m[["x_r", "y_r"]].to_numpy(float)
    XL, _ = stereo_triangulation(xL, xR, rig)
    err = reprojection_error(np.asarray(XL).reshape(-1, 3), xL, xR, rig).max(axis=1)
    err = err[np.isfinite(err)]
    return float(np.median(err)) if err.size else np.inf


def _diagnose(tl, tr, rig, ok_status, median, max_offset=5):
    """Name the likely cause: try the cameras swapped and small frame offsets."""
    causes = []
    swapped = _median_error(tr, tl, rig, ok_status)
    if swapped < median / 3:
        causes.append(f"with the left and right tracks swapped the median would be {swapped:.2f} px: the cameras "
                      "are swapped (exchange --left and --right)")
    best = None
    for off in range(-max_offset, max_offset + 1):
        if off == 0:
            continue
        shifted = tr.assign(frame=tr["frame"] + off)
        e = _median_error(tl, shifted, rig, ok_status)
        if best is None or e < best[1]:
            best = (off, e)
    if best is not None and best[1] < median / 3:
        causes.append(f"with the right frames shifted by {best[0]:+d} the median would be {best[1]:.2f} px: the "
                      f"two sequences are offset by {abs(best[0])} frame(s) (trim one of them)")
    if causes:
        return "Likely cause: " + "; ".join(causes) + "."
    return ("Likely causes: swapped cameras (--left/--right), a frame offset between the two sequences, or a "
            "calibration of another setup (wrong .mat file, or the cameras moved after calibrating).")
