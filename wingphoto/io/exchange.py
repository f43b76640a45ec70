"""Data exchange: DLTdv8/Argus files, 11-parameter DLT coefficients, the thesis' MATLAB files, Parquet.

Every writer goes through :func:`wingphoto.io.atomic_write` (a temporary file renamed over
the target: normal permissions, an interrupted write leaves the old file, non-regular
targets refused). Every reader gives back wingphoto's own tables (``docs/conventions.md``).

Coordinate conventions (also in ``docs/formats.md``)
----------------------------------------------------
wingphoto pixels: ``(x, y)``, x right, y down, ``(0, 0)`` the centre of the top-left pixel.

- **DLTdv8** (``xypts.csv``, ``_dltCoefs.csv``): MATLAB pixels, 1-based, y down, origin at
  the top-left (``y_axis="down"``, the default): ``x_dlt = x + 1``, ``y_dlt = y + 1``.
  **Argus and DLTdv 1-7** put the origin at the bottom-left, y up (``y_axis="up"``):
  ``x_dlt = x + 1``, ``y_dlt = H - y`` for an image ``H`` pixels high. Points are numbered
  from 1 (``pt1`` is wingphoto point 0), cameras from 1 (``cam1`` left, ``cam2`` right),
  rows are frames 0, 1, 2, ... (DLTdv's frame 1 is row 1). Missing values are NaN.
- **The thesis' MATLAB files**: MATLAB pixels, 1-based and y down: ``x_mat = x + 1``,
  ``y_mat = y + 1``; frames and points are the 1-based struct indices (``Pointl(p)`` is
  wingphoto point ``p - 1``, ``Img(i)`` frame ``i - 1``). 3D points are 3xT columns in mm,
  ``XL`` in the left camera frame, ``XR`` in the right (``XR = R XL + T``).
"""
from __future__ import annotations

import dataclasses
import io as _stdio
import re
from pathlib import Path

import numpy as np
import pandas as pd

from .atomic import atomic_write

__all__ = [
    "DLTFit",
    "fit_dlt",
    "write_dlt_coefficients",
    "read_dlt_coefficients",
    "dlt_project",
    "write_dltdv",
    "read_dltdv",
    "write_thesis_mat",
    "read_thesis_mat",
    "write_parquet",
    "read_parquet",
]

CAMERAS = ("left", "right")


def _image_height(height, camera, y_axis="up"):
    if y_axis == "down":
        return None
    if y_axis != "up":
        raise ValueError(f"y_axis must be 'down' (DLTdv8) or 'up' (Argus, DLTdv 1-7), got {y_axis!r}")
    if height is None:
        raise ValueError(
            f"image_heights must give the {camera} image's height in pixels: with y_axis='up' (Argus, "
            f"DLTdv 1-7) y_dlt = H - y, so pixel rows cannot be converted without it"
        )
    h = float(height)
    if not h > 0:
        raise ValueError(f"image height of the {camera} camera must be > 0 px, got {height}")
    return h


def _heights(image_heights):
    if isinstance(image_heights, dict):
        return [image_heights.get(c) for c in CAMERAS]
    if image_heights is None:
        return [None, None]
    arr = list(np.atleast_1d(image_heights))
    return arr * 2 if len(arr) == 1 else arr[:2]


# ====================================================================================
# DLT coefficients
# ====================================================================================
@dataclasses.dataclass(frozen=True)
class DLTFit:
    """11-parameter DLT coefficients of both cameras, fitted from a :class:`~wingphoto.StereoRig`.

    Attributes
    ----------
    coefficients : (11, 2) ndarray
        Column c is camera c+1's ``L1..L11``, in the pixel convention of ``y_axis`` (see
        the module docstring). World frame: the left camera frame shifted by
        ``origin`` (``X_world = X_left - origin``, mm).
    origin : (3,) ndarray
        Where the DLT world origin lies in the left camera frame, mm. The DLT cannot put
        its origin at a camera centre (``L12 = 1`` normalisation), so it is placed in
        the measurement volume.
    rms_px, max_px : (2,) ndarray
        Per camera, RMS and largest difference between the DLT projection and the full
        calibrated model (with lens distortion) over the fitted volume: what leaving out
        the distortion costs a DLTdv/Argus user.
    n_points : int
        3D points the fit used.
    """

    coefficients: np.ndarray
    origin: np.ndarray
    rms_px: np.ndarray
    max_px: np.ndarray
    n_points: int
    y_axis: str = "down"

    def summary(self):
        """One line per camera with the distortion residual."""
        return "\n".join(
            f"{cam}: DLT vs full model {self.rms_px[i]:.3f} px RMS, {self.max_px[i]:.3f} px max "
            f"over {self.n_points} points" for i, cam in enumerate(CAMERAS)
        )


def _to_dlt_pixels(x, height):
    """wingphoto pixels -> DLT pixels: y down (height None) or y up (H - y); 1-based."""
    y = x[:, 1] + 1.0 if height is None else height - x[:, 1]
    return np.column_stack([x[:, 0] + 1.0, y])


def _from_dlt_pixels(u, height):
    y = u[:, 1] - 1.0 if height is None else height - u[:, 1]
    return np.column_stack([u[:, 0] - 1.0, y])


def _solve_dlt(X, u):
    """Linear least-squares 11-parameter DLT from (N, 3) world points and (N, 2) pixels."""
    n = len(X)
    A = np.zeros((2 * n, 11))
    b = np.zeros(2 * n)
    A[0::2, 0:3] = X
    A[0::2, 3] = 1
    A[0::2, 8:11] = -u[:, :1] * X
    A[1::2, 4:7] = X
    A[1::2, 7] = 1
    A[1::2, 8:11] = -u[:, 1:2] * X
    b[0::2] = u[:, 0]
    b[1::2] = u[:, 1]
    # scale columns for conditioning
    scale = np.maximum(np.abs(A).max(axis=0), 1e-12)
    L, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
    return L / scale


def dlt_project(coefficients, X):
    """Project (N, 3) world points with 11 DLT coefficients -> (N, 2) DLT pixels (1-based, y up)."""
    L = np.asarray(coefficients, dtype=float).reshape(11)
    X = np.atleast_2d(np.asarray(X, dtype=float))
    den = X @ L[8:11] + 1.0
    return np.column_stack([(X @ L[0:3] + L[3]) / den, (X @ L[4:7] + L[7]) / den])


def fit_dlt(rig, *, points=None, origin=None, depth_range=0.2, n_grid=21, y_axis="down"):
    """Fit DLTdv/Argus 11-parameter DLT coefficients to a calibrated rig.

    Parameters
    ----------
    rig : StereoRig
        With ``image_size`` set on both cameras (needed for DLTdv's y-up pixels).
    points : (N, 3) array_like, optional
        3D points (mm, left camera frame) spanning the measurement volume, e.g. the
        triangulated markers; the DLT is fitted where they are. Without them, a grid of
        rays through the left image (``n_grid`` x ``n_grid``) at depths ``(1 +- depth_range)``
        times the distance where the optical axes pass closest is used.
    origin : (3,) array_like, optional
        DLT world origin in the left camera frame, mm (default: the centre of the volume,
        rounded to 1 mm).
    depth_range : float
        Relative depth span of the default volume (default 0.2).
    n_grid : int
        Rays per image side of the default volume (default 21).
    y_axis : {"down", "up"}
        "down" (default): DLTdv8's MATLAB pixels; "up": Argus / DLTdv 1-7 (origin at the
        bottom-left).

    Returns
    -------
    DLTFit
    """
    _image_height(1, "left", y_axis)  # validates y_axis
    sizes = [rig.left.image_size, rig.right.image_size]
    if any(s is None for s in sizes):
        raise ValueError(
            "both cameras need image_size (width, height) to write DLT coefficients; load the "
            "calibration from a Calib_Results_stereo.mat (it stores nx, ny) or set Camera.image_size"
        )
    if points is None:
        w, h = sizes[0]
        # depth: where the two optical axes pass closest (left axis z, right axis R^T z)
        d_right = rig.R.T @ np.array([0.0, 0.0, 1.0])
        c_right = -rig.R.T @ rig.T
        a = np.array([[1.0, -d_right[2]], [d_right[2], -1.0]])
        rhs = np.array([c_right[2], c_right @ d_right])
        try:
            s, _ = np.linalg.solve(a, rhs)
        except np.linalg.LinAlgError:
            s = np.nan
        depth = s if np.isfinite(s) and s > 0 else 10 * rig.baseline
        gx, gy = np.meshgrid(np.linspace(0, w - 1, n_grid), np.linspace(0, h - 1, n_grid))
        xn = rig.left.normalize(np.column_stack([gx.ravel(), gy.ravel()]))
        rays = np.column_stack([xn, np.ones(len(xn))])
        pts = np.concatenate([rays * z for z in depth * np.linspace(1 - depth_range, 1 + depth_range, 5)])
    else:
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if len(pts) < 6:
            raise ValueError(f"points must hold at least 6 finite 3D points to fit a DLT, got {len(pts)}")
    origin = np.round(np.median(pts, axis=0)) if origin is None else np.asarray(origin, float).reshape(3)
    coefs, rms, mx = np.zeros((11, 2)), np.zeros(2), np.zeros(2)
    xl, xr = rig.project(pts)
    n_used = len(pts)
    for i, (x, (w, h)) in enumerate(zip((xl, xr), sizes)):
        inside = np.all(np.isfinite(x), axis=1) & (x[:, 0] > -0.5) & (x[:, 0] < w - 0.5) & (x[:, 1] > -0.5) & (x[:, 1] < h - 0.5)
        if inside.sum() < 6:
            raise ValueError(f"fewer than 6 of the fitting points fall inside the {CAMERAS[i]} image; pass points=")
        u = _to_dlt_pixels(x[inside], h if y_axis == "up" else None)
        Xw = pts[inside] - origin
        coefs[:, i] = _solve_dlt(Xw, u)
        err = np.linalg.norm(dlt_project(coefs[:, i], Xw) - u, axis=1)
        rms[i] = float(np.sqrt(np.mean(err**2)))
        mx[i] = float(err.max())
        n_used = min(n_used, int(inside.sum()))
    return DLTFit(coefs, origin, rms, mx, n_used, y_axis)


def write_dlt_coefficients(fit, path):
    """Write ``_dltCoefs.csv``: 11 rows, one column per camera, no header (DLTdv8, Argus)."""
    coefs = fit.coefficients if isinstance(fit, DLTFit) else np.asarray(fit, float)
    if coefs.shape[0] != 11:
        raise ValueError(f"DLT coefficients must be (11, n_cameras), got shape {coefs.shape}")
    with atomic_write(path, "w", newline="") as f:
        np.savetxt(f, coefs, delimiter=",", fmt="%.17g")
    return Path(path)


def read_dlt_coefficients(path):
    """Read a ``_dltCoefs.csv`` -> (11, n_cameras) ndarray."""
    try:
        coefs = np.loadtxt(path, delimiter=",", ndmin=2)
    except ValueError as exc:
        raise ValueError(f"{path} is not a DLT coefficients file (11 rows of numbers): {exc}") from None
    if coefs.shape[0] != 11:
        raise ValueError(f"{path} has {coefs.shape[0]} rows; a DLT coefficients file has 11 (one column per camera)")
    return coefs


# ====================================================================================
# DLTdv8 xypts / xyzpts / xyzres / offsets
# ====================================================================================
def _frames_points(tracks, points3d):
    frames, pts = [], []
    for t in (tracks, points3d):
        if t is not None and len(t):
            frames.append(np.asarray(t["frame"], np.int64))
            pts.append(np.asarray(t["point"], np.int64))
    if not frames:
        raise ValueError("nothing to export: give tracks and/or 3D points with at least one row")
    f = np.concatenate(frames)
    p = np.concatenate(pts)
    if f.min() < 0 or p.min() < 0:
        raise ValueError("frames and points must be >= 0 to be written as DLTdv rows and pt columns")
    return int(f.max()) + 1, int(p.max()) + 1


def write_dltdv(out, *, tracks=None, points3d=None, image_heights=None, prefix="", origin=None,
                statuses=("ok", "manual", "interpolated"), y_axis="down"):
    """Write DLTdv8 files: ``{prefix}xypts.csv``, ``xyzpts.csv``, ``xyzres.csv``, ``offsets.csv``.

    Parameters
    ----------
    out : str or Path
        Folder to write into (created if missing).
    tracks : DataFrame, optional
        Tracks of both cameras (``camera`` left/right, frame, point, x, y, status);
        observations whose status is not in ``statuses`` are written as NaN.
    points3d : DataFrame, optional
        frame, point, X, Y, Z (mm, left camera frame), reproj_err (px) -> xyzpts/xyzres.
    image_heights : dict or (2,) sequence, optional
        Image height of each camera in px; needed with ``y_axis="up"`` only.
    prefix : str
        File name prefix, e.g. ``"trial01-"`` (DLTdv8 writes ``trial01-xypts.csv``).
    origin : (3,) array_like, optional
        Subtracted from the 3D points so that they are in the DLT world frame of a
        :class:`DLTFit` (pass ``fit.origin``); default: the left camera frame.
    statuses : tuple of str
        Track statuses exported as positions.
    y_axis : {"down", "up"}
        "down" (default): DLTdv8 (MATLAB pixels, origin top-left); "up": Argus and
        DLTdv 1-7 (origin bottom-left, ``y_dlt = H - y``).

    Returns
    -------
    dict
        Written paths by kind (``xypts``, ``xyzpts``, ``xyzres``, ``offsets``).
    """
    out = Path(out)
    n_frames, n_points = _frames_points(tracks, points3d)
    written = {}
    if tracks is not None:
        heights = _heights(image_heights)
        xy = np.full((n_frames, n_points * 4), np.nan)
        cams = tracks["camera"].astype(str).str.lower()
        unknown = sorted(set(cams) - set(CAMERAS))
        if unknown:
            raise ValueError(f"tracks has camera(s) {unknown}; DLTdv export takes 'left' (cam1) and 'right' (cam2)")
        use = tracks["status"].astype(str).isin(statuses).to_numpy()
        for c, cam in enumerate(CAMERAS):
            sel = (cams == cam).to_numpy() & use
            if not sel.any():
                continue
            h = _image_height(heights[c], cam, y_axis)
            f = tracks["frame"].to_numpy(np.int64)[sel]
            p = tracks["point"].to_numpy(np.int64)[sel]
            u = _to_dlt_pixels(tracks[["x", "y"]].to_numpy(float)[sel], h)
            xy[f, p * 4 + 2 * c] = u[:, 0]
            xy[f, p * 4 + 2 * c + 1] = u[:, 1]
        cols = [f"pt{p + 1}_cam{c + 1}_{a}" for p in range(n_points) for c in range(2) for a in "XY"]
        written["xypts"] = _write_csv(pd.DataFrame(xy, columns=cols), out / f"{prefix}xypts.csv")
        offsets = pd.DataFrame(np.zeros((n_frames, 2)), columns=["cam1_offset", "cam2_offset"])
        written["offsets"] = _write_csv(offsets, out / f"{prefix}offsets.csv")
    if points3d is not None:
        xyz = np.full((n_frames, n_points * 3), np.nan)
        res = np.full((n_frames, n_points), np.nan)
        f = points3d["frame"].to_numpy(np.int64)
        p = points3d["point"].to_numpy(np.int64)
        X = points3d[["X", "Y", "Z"]].to_numpy(float)
        if origin is not None:
            X = X - np.asarray(origin, float).reshape(3)
        for a in range(3):
            xyz[f, p * 3 + a] = X[:, a]
        if "reproj_err" in points3d:
            res[f, p] = points3d["reproj_err"].to_numpy(float)
        cols = [f"pt{q + 1}_{a}" for q in range(n_points) for a in "XYZ"]
        written["xyzpts"] = _write_csv(pd.DataFrame(xyz, columns=cols), out / f"{prefix}xyzpts.csv")
        written["xyzres"] = _write_csv(
            pd.DataFrame(res, columns=[f"pt{q + 1}_dltres" for q in range(n_points)]), out / f"{prefix}xyzres.csv")
    return written


def _write_csv(df, path):
    with atomic_write(path, "w", newline="") as f:
        df.to_csv(f, index=False, na_rep="NaN", float_format="%.17g")
    return Path(path)


_XY_COL = re.compile(r"^pt(\d+)_cam(\d+)_([XY])$")
_XYZ_COL = re.compile(r"^pt(\d+)_([XYZ])$")


def read_dltdv(xypts=None, *, xyzpts=None, xyzres=None, image_heights=None, origin=None, y_axis="down"):
    """Read DLTdv8 files back into wingphoto tables.

    Parameters
    ----------
    xypts : str or Path, optional
        ``xypts.csv``; cam1 becomes ``left``, cam2 ``right`` (more cameras: ``cam3``...).
    xyzpts, xyzres : str or Path, optional
    image_heights : dict or (2,) sequence, optional
        Needed with ``y_axis="up"`` (y_dlt = H - y).
    origin : (3,) array_like, optional
        Added back to the 3D points (see :func:`write_dltdv`).
    y_axis : {"down", "up"}
        As in :func:`write_dltdv`.

    Returns
    -------
    tracks : DataFrame or None
        camera, frame, point, x, y (wingphoto px), status ``"manual"`` where digitized
        (DLTdv points are user clicks or its own tracking), ``"lost"`` where NaN.
    points3d : DataFrame or None
        frame, point, X, Y, Z, reproj_err (NaN when no xyzres).
    """
    tracks = points = None
    if xypts is not None:
        df = pd.read_csv(xypts)
        heights = _heights(image_heights)
        rows = []
        for col in df.columns:
            m = _XY_COL.match(col.strip())
            if not m:
                raise ValueError(f"{xypts}: column {col!r} is not a DLTdv xypts column (pt<N>_cam<C>_X/Y)")
        n = len(df)
        points_ids = sorted({int(_XY_COL.match(c.strip()).group(1)) for c in df.columns})
        cams = sorted({int(_XY_COL.match(c.strip()).group(2)) for c in df.columns})
        for c in cams:
            name = CAMERAS[c - 1] if c <= 2 else f"cam{c}"
            h = _image_height(heights[c - 1] if c <= 2 else None, name, y_axis)
            for p in points_ids:
                u = df[[f"pt{p}_cam{c}_X", f"pt{p}_cam{c}_Y"]].to_numpy(float)
                x = _from_dlt_pixels(u, h)
                ok = np.all(np.isfinite(x), axis=1)
                rows.append(pd.DataFrame({
                    "camera": name, "frame": np.arange(n, dtype=np.int64), "point": np.int64(p - 1),
                    "x": x[:, 0], "y": x[:, 1], "score": np.nan,
                    "status": np.where(ok, "manual", "lost"),
                }))
        tracks = pd.concat(rows, ignore_index=True).sort_values(["camera", "frame", "point"], kind="stable")
        tracks = tracks.reset_index(drop=True)
    if xyzpts is not None:
        df = pd.read_csv(xyzpts)
        ids = sorted({int(m.group(1)) for m in (_XYZ_COL.match(c.strip()) for c in df.columns) if m})
        if not ids:
            raise ValueError(f"{xyzpts} has no pt<N>_X/Y/Z columns; is it a DLTdv xyzpts file?")
        res = pd.read_csv(xyzres) if xyzres is not None else None
        rows = []
        n = len(df)
        for p in ids:
            X = df[[f"pt{p}_X", f"pt{p}_Y", f"pt{p}_Z"]].to_numpy(float)
            if origin is not None:
                X = X + np.asarray(origin, float).reshape(3)
            r = res[f"pt{p}_dltres"].to_numpy(float) if res is not None and f"pt{p}_dltres" in res else np.full(n, np.nan)
            rows.append(pd.DataFrame({"frame": np.arange(n, dtype=np.int64), "point": np.int64(p - 1),
                                      "X": X[:, 0], "Y": X[:, 1], "Z": X[:, 2], "reproj_err": r}))
        points = pd.concat(rows, ignore_index=True)
        points = points[np.isfinite(points[["X", "Y", "Z"]].to_numpy()).all(axis=1)]
        points = points.sort_values(["frame", "point"], kind="stable").reset_index(drop=True)
    return tracks, points


# ====================================================================================
# The thesis' MATLAB files
# ====================================================================================
def _struct_array(n, fields):
    return np.zeros((1, n), dtype=[(f, object) for f in fields])


def write_thesis_mat(out, *, tracks=None, points3d=None, rig=None):
    """Write the thesis' MATLAB files: ``xl.mat``/``xr.mat``, ``cntrdl.mat``/``cntrdr.mat``, ``3dall.mat``.

    Parameters
    ----------
    out : str or Path
        Folder to write into.
    tracks : DataFrame, optional
        Both cameras' tracks. Writes ``xl.mat`` (``Pointl(p).x``: T x 2, MATLAB pixels
        [x y], NaN where missing), ``xr.mat`` (``Pointr(p).x``), ``cntrdl.mat``
        (``Img(i).cnt(p).xl``: 1 x 2 [x y]) and ``cntrdr.mat`` (``Img(i).cnt(p).xr``).
    points3d : DataFrame, optional
        frame, point, X, Y, Z (mm, left camera frame). Writes ``3dall.mat``: ``PT(p).XL``
        (3 x T, left camera frame, NaN columns where missing) and, with ``rig``,
        ``PT(p).XR`` (3 x T, right camera frame).
    rig : StereoRig, optional

    Returns
    -------
    dict
        Written paths by file name.

    Notes
    -----
    1-based throughout: ``Pointl(p)`` is wingphoto point ``p - 1``, row/``Img(i)`` frame
    ``i - 1``, pixel ``[x y]`` = wingphoto ``(x + 1, y + 1)`` (MATLAB's pixel (1, 1) is the
    centre of the top-left pixel). Only ok / manual / interpolated positions are written.
    """
    from scipy.io import savemat

    out = Path(out)
    n_frames, n_points = _frames_points(tracks, points3d)
    written = {}
    if tracks is not None:
        good = tracks["status"].astype(str).isin(("ok", "manual", "interpolated")).to_numpy()
        cams = tracks["camera"].astype(str).str.lower().to_numpy()
        for cam, s in (("left", "l"), ("right", "r")):
            sel = (cams == cam) & good
            xy = np.full((n_frames, n_points, 2), np.nan)
            f = tracks["frame"].to_numpy(np.int64)[sel]
            p = tracks["point"].to_numpy(np.int64)[sel]
            xy[f, p] = tracks[["x", "y"]].to_numpy(float)[sel] + 1.0
            point = _struct_array(n_points, ["x"])
            for q in range(n_points):
                point[0, q]["x"] = xy[:, q, :]
            img = _struct_array(n_frames, ["cnt"])
            for i in range(n_frames):
                cnt = _struct_array(n_points, [f"x{s}"])
                for q in range(n_points):
                    cnt[0, q][f"x{s}"] = xy[i, q, :].reshape(1, 2)
                img[0, i]["cnt"] = cnt
            written[f"x{s}.mat"] = _savemat(out / f"x{s}.mat", {f"Point{s}": point}, savemat)
            written[f"cntrd{s}.mat"] = _savemat(out / f"cntrd{s}.mat", {"Img": img}, savemat)
    if points3d is not None:
        XL = np.full((n_points, 3, n_frames), np.nan)
        f = points3d["frame"].to_numpy(np.int64)
        p = points3d["point"].to_numpy(np.int64)
        XL[p, :, f] = points3d[["X", "Y", "Z"]].to_numpy(float)
        fields = ["XL", "XR"] if rig is not None else ["XL"]
        pt = _struct_array(n_points, fields)
        for q in range(n_points):
            pt[0, q]["XL"] = XL[q]
            if rig is not None:
                pt[0, q]["XR"] = rig.R @ XL[q] + rig.T.reshape(3, 1)
        written["3dall.mat"] = _savemat(out / "3dall.mat", {"PT": pt}, savemat)
    return written


def _savemat(path, variables, savemat):
    buf = _stdio.BytesIO()
    savemat(buf, variables, do_compression=True, oned_as="row")
    with atomic_write(path, "wb") as f:
        f.write(buf.getvalue())
    return Path(path)


def read_thesis_mat(path):
    """Read one of the thesis' MATLAB files back into a wingphoto table.

    ``xl.mat``/``xr.mat``/``cntrdl.mat``/``cntrdr.mat`` -> tracks (camera, frame, point,
    x, y, status ``ok``/``lost``); ``3dall.mat`` -> 3D points (frame, point, X, Y, Z in the
    left camera frame, reproj_err NaN). Conventions: :func:`write_thesis_mat`.
    """
    from scipy.io import loadmat

    path = Path(path)
    try:
        data = loadmat(path, squeeze_me=False, struct_as_record=True)
    except Exception as exc:
        raise ValueError(f"cannot read {path} as a MATLAB file ({exc})") from None
    rows = []
    for var, cam in (("Pointl", "left"), ("Pointr", "right")):
        if var in data:
            s = data[var].reshape(-1)
            for q, rec in enumerate(s):
                xy = np.asarray(rec["x"], float).reshape(-1, 2) - 1.0
                rows.append(_track_rows(cam, q, xy))
            return _tracks(rows)
    if "Img" in data:
        imgs = data["Img"].reshape(-1)
        cnt0 = imgs[0]["cnt"].reshape(-1)
        field = [n for n in cnt0.dtype.names if n in ("xl", "xr")]
        if not field:
            raise ValueError(f"{path}: Img(i).cnt has no xl or xr field")
        cam = "left" if field[0] == "xl" else "right"
        n_points = cnt0.size
        xy = np.full((len(imgs), n_points, 2), np.nan)
        for i, img in enumerate(imgs):
            for q, rec in enumerate(img["cnt"].reshape(-1)):
                xy[i, q] = np.asarray(rec[field[0]], float).reshape(2) - 1.0
        return _tracks([_track_rows(cam, q, xy[:, q]) for q in range(n_points)])
    if "PT" in data:
        out = []
        for q, rec in enumerate(data["PT"].reshape(-1)):
            XL = np.asarray(rec["XL"], float).reshape(3, -1)
            n = XL.shape[1]
            out.append(pd.DataFrame({"frame": np.arange(n, dtype=np.int64), "point": np.int64(q),
                                     "X": XL[0], "Y": XL[1], "Z": XL[2], "reproj_err": np.nan}))
        pts = pd.concat(out, ignore_index=True)
        pts = pts[np.isfinite(pts[["X", "Y", "Z"]].to_numpy()).all(axis=1)]
        return pts.sort_values(["frame", "point"], kind="stable").reset_index(drop=True)
    raise ValueError(f"{path} holds none of the thesis' variables (Pointl, Pointr, Img, PT)")


def _track_rows(cam, q, xy):
    ok = np.all(np.isfinite(xy), axis=1)
    return pd.DataFrame({"camera": cam, "frame": np.arange(len(xy), dtype=np.int64), "point": np.int64(q),
                         "x": xy[:, 0], "y": xy[:, 1], "score": np.nan, "status": np.where(ok, "ok", "lost")})


def _tracks(rows):
    return pd.concat(rows, ignore_index=True).sort_values(["camera", "frame", "point"], kind="stable").reset_index(drop=True)


# ====================================================================================
# Parquet
# ====================================================================================
def write_parquet(table, path):
    """Write a tidy table (tracks, points, analysis) to Parquet, atomically (needs pyarrow)."""
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        raise ImportError("Parquet needs pyarrow: pip install 'wingphoto[exchange]' (or pip install pyarrow)") from None
    buf = _stdio.BytesIO()
    table.to_parquet(buf, index=False, engine="pyarrow")
    with atomic_write(path, "wb") as f:
        f.write(buf.getvalue())
    return Path(path)


def read_parquet(path):
    """Read a Parquet table written by :func:`write_parquet`."""
    return pd.read_parquet(path, engine="pyarrow")
