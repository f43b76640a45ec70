"""Stereo triangulation as in Bouguet's toolbox, and reprojection errors.

See ``docs/conventions.md`` for frames and units.
"""
from __future__ import annotations

import numpy as np

from .camera import StereoRig, as_points

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


def triangulate_tracks(tracks_left, tracks_right, rig, *, ok_status=("ok", "manual", "interpolated")):
    """Triangulate two tracks DataFrames into the 3D points DataFrame.

    Parameters
    ----------
    tracks_left, tracks_right : pandas.DataFrame
        Tracks with columns frame, point, x, y, status (one camera each, or with a
        ``camera`` column which is ignored).
    rig : StereoRig
    ok_status : tuple of str
        Statuses whose positions are trusted; any other status in either view gives NaN.

    Returns
    -------
    points : pandas.DataFrame
        Columns frame, point, X, Y, Z (mm, left camera frame), reproj_err (px, the
        larger of the two views). One row per (frame, point) present in both tables.
    """
    import pandas as pd

    cols = ["frame", "point", "x", "y"]
    for name, t in (("tracks_left", tracks_left), ("tracks_right", tracks_right)):
        missing = [c for c in cols if c not in t.columns]
        if missing:
            raise ValueError(f"{name} lacks columns {missing}; expected a tracks DataFrame")

    def _trusted(t):
        t = t.copy()
        if "status" in t.columns:
            bad = ~t["status"].isin(ok_status)
            t.loc[bad, ["x", "y"]] = np.nan
        return t[cols]

    m = _trusted(tracks_left).merge(_trusted(tracks_right), on=["frame", "point"], suffixes=("_l", "_r"))
    m = m.sort_values(["frame", "point"], kind="stable").reset_index(drop=True)
    xL = m[["x_l", "y_l"]].to_numpy(float).reshape(-1, 2)
    xR = m[["x_r", "y_r"]].to_numpy(float).reshape(-1, 2)
    XL, _ = stereo_triangulation(xL, xR, rig)
    XL = np.asarray(XL).reshape(-1, 3)
    err = reprojection_error(XL, xL, xR, rig).max(axis=1) if len(m) else np.zeros(0)
    return pd.DataFrame(
        {
            "frame": m["frame"].to_numpy(np.int64),
            "point": m["point"].to_numpy(np.int64),
            "X": XL[:, 0],
            "Y": XL[:, 1],
            "Z": XL[:, 2],
            "reproj_err": err,
        }
    )
