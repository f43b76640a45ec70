"""Stereo consistency check of two views' tracks."""
from __future__ import annotations

import numpy as np


# --------------------------------------------------------------------------- stereo
def check_stereo(tracks_left, tracks_right, rig, *, max_epipolar_px=2.0, max_reproj_px=2.0,
                 trusted=("ok", "manual", "interpolated")):
    """Flag left/right pairs that are not geometrically consistent.

    Parameters
    ----------
    tracks_left, tracks_right : pandas.DataFrame
        Tracks of the two cameras (columns frame, point, x, y, status).
    rig : StereoRig
        The calibrated rig (``docs/conventions.md``).
    max_epipolar_px : float
        Largest symmetric epipolar distance (:meth:`StereoRig.epipolar_distance`, px, lens
        distortion removed) of a consistent pair.
    max_reproj_px : float
        Largest reprojection error (px, the worse of the two views) of the pair's
        triangulated point (:func:`wingphoto.triangulate.stereo_triangulation`).
    trusted : tuple of str
        Statuses whose positions are checked (both views must be trusted).

    Returns
    -------
    tracks_left, tracks_right : pandas.DataFrame
        Copies in which the ``ok`` rows of an inconsistent pair become ``flagged`` with
        reason ``stereo`` (``manual`` and ``interpolated`` rows keep their status: the
        user decided). Two columns are added: ``epipolar_px`` and ``reproj_px`` (NaN where
        the pair was not checked).

    Notes
    -----
    A marker swapped with another in one view (the classic tracking error) leaves the
    pair off the epipolar geometry and is caught, unless the two markers lie on the same
    epipolar line (within the threshold): geometry alone cannot see that swap.

    Examples
    --------
    >>> import pandas as pd
    >>> from wingphoto.camera import Camera, StereoRig
    >>> cam = Camera(fc=[1000, 1000], cc=[255.5, 255.5])
    >>> rig = StereoRig(cam, cam, om=[0, 0, 0], T=[-100, 0, 0])
    >>> xL, xR = rig.project([[10.0, 5.0, 800.0], [-20.0, 30.0, 800.0]])
    >>> tl = pd.DataFrame({"frame": 0, "point": [0, 1], "x": xL[:, 0], "y": xL[:, 1], "status": "ok"})
    >>> tr = pd.DataFrame({"frame": 0, "point": [0, 1], "x": xR[::-1, 0], "y": xR[::-1, 1], "status": "ok"})
    >>> l2, r2 = check_stereo(tl, tr, rig)
    >>> l2.status.tolist(), r2.reason.tolist()
    (['flagged', 'flagged'], ['stereo', 'stereo'])
    """
    from ..camera import StereoRig
    from ..triangulate import reprojection_error, stereo_triangulation

    if not isinstance(rig, StereoRig):
        raise ValueError(f"rig must be a wingphoto.StereoRig, got {type(rig).__name__}")
    for name, t in (("tracks_left", tracks_left), ("tracks_right", tracks_right)):
        missing = [c for c in ("frame", "point", "x", "y", "status") if c not in t.columns]
        if missing:
            raise ValueError(f"{name} lacks columns {missing}; expected a tracks DataFrame")
    L = tracks_left.copy()
    R = tracks_right.copy()
    for t in (L, R):
        if "reason" not in t.columns:
            t["reason"] = ""
        t["reason"] = t["reason"].fillna("").astype(str)
        t["epipolar_px"] = np.nan
        t["reproj_px"] = np.nan
    key = ["frame", "point"]
    li = L.reset_index()[key + ["index", "x", "y", "status"]]
    ri = R.reset_index()[key + ["index", "x", "y", "status"]]
    m = li.merge(ri, on=key, suffixes=("_l", "_r"))
    m = m[m["status_l"].isin(trusted) & m["status_r"].isin(trusted)]
    xl = m[["x_l", "y_l"]].to_numpy(float)
    xr = m[["x_r", "y_r"]].to_numpy(float)
    fin = np.all(np.isfinite(xl), 1) & np.all(np.isfinite(xr), 1)
    m, xl, xr = m[fin], xl[fin], xr[fin]
    if len(m) == 0:
        return L, R
    epi = np.asarray(rig.epipolar_distance(xl, xr), float).reshape(-1)
    XL, _ = stereo_triangulation(xl, xr, rig)
    rep = reprojection_error(np.asarray(XL).reshape(-1, 3), xl, xr, rig).max(axis=1)
    bad = ~((epi <= max_epipolar_px) & (rep <= max_reproj_px))
    for t, col in ((L, "index_l"), (R, "index_r")):
        idx = m[col].to_numpy()
        t.loc[idx, "epipolar_px"] = epi
        t.loc[idx, "reproj_px"] = rep
        flag = idx[bad]
        flag = flag[(t.loc[flag, "status"] == "ok").to_numpy()]
        t.loc[flag, "status"] = "flagged"
        t.loc[flag, "reason"] = "stereo"
    return L, R

