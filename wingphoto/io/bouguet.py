"""Bouguet toolbox .mat files (Calib_Results.mat, Calib_Results_stereo.mat) with the toolbox's names."""
from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..camera import Camera, StereoRig, rodrigues, rodrigues_inverse
from .atomic import atomic_write



_MATLAB_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,62}$")
#: Uncertainty keys of one camera and their shapes (the toolbox's ``*_error`` variables).
_CAMERA_ERROR_SHAPES = {"fc": (2,), "cc": (2,), "alpha_c": (), "kc": (5,)}
_STEREO_ERROR_SHAPES = {
    **{f"{k}_{side}": s for side in ("left", "right") for k, s in _CAMERA_ERROR_SHAPES.items()},
    "om": (3,),
    "T": (3,),
}


def _readonly(arr):
    arr = np.array(arr, dtype=np.float64)
    arr.setflags(write=False)
    return arr


def _loadmat(path):
    import scipy.io

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"MATLAB file {path} not found; check the path")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy warns about odd headers of old files
            return scipy.io.loadmat(path, mat_dtype=True, squeeze_me=False)
    except NotImplementedError as exc:  # v7.3 (HDF5) files
        raise ValueError(
            f"{path} is a MATLAB v7.3 (HDF5) file, which scipy cannot read; in MATLAB "
            f"re-save it with save('{path.name}', '-v7')"
        ) from exc
    except Exception as exc:
        raise ValueError(f"cannot read {path} as a MATLAB .mat file ({exc}); check the file") from exc


def _mat_vector(m, name, size, path):
    """A MATLAB variable as a flat float64 vector of ``size`` elements (None when absent)."""
    if name not in m:
        return None
    v = np.asarray(m[name], dtype=np.float64).reshape(-1)
    sizes = (size,) if np.isscalar(size) else tuple(size)
    if v.size not in sizes:
        raise ValueError(f"{path}: variable {name} has {v.size} elements, expected {' or '.join(map(str, sizes))}")
    return v


def _mat_kc(m, name, path):
    """kc (or kc_error) padded to 5 coefficients: the toolbox also writes 4 (k3 = 0)."""
    kc = _mat_vector(m, name, (4, 5), path)
    if kc is not None and kc.size == 4:
        kc = np.append(kc, 0.0)
    return kc


def _mat_camera(m, suffix, path):
    """Camera and its uncertainty dict from fc{suffix}, cc{suffix}, ... variables."""
    missing = [n + suffix for n in ("fc", "cc") if n + suffix not in m]
    if missing:
        raise ValueError(
            f"{path} lacks the variable(s) {', '.join(missing)}; expected a Bouguet toolbox "
            f"calibration result (Calib_Results{'_stereo' if suffix else ''}.mat)"
        )
    fc = _mat_vector(m, "fc" + suffix, 2, path)
    cc = _mat_vector(m, "cc" + suffix, 2, path)
    kc = _mat_kc(m, "kc" + suffix, path)
    alpha = _mat_vector(m, "alpha_c" + suffix, 1, path)
    image_size = None
    if "nx" in m and "ny" in m:
        nxy = [np.asarray(m[k], dtype=np.float64).reshape(-1)[:1] for k in ("nx", "ny")]
        if any(v.size != 1 or not np.isfinite(v[0]) for v in nxy):
            raise ValueError(f"{path}: variables nx, ny must be the image width and height in pixels")
        image_size = (int(nxy[0][0]), int(nxy[1][0]))
    try:
        cam = Camera(
            fc=fc,
            cc=cc,
            kc=np.zeros(5) if kc is None else kc,
            alpha_c=0.0 if alpha is None else float(alpha[0]),
            image_size=image_size,
        )
    except ValueError as exc:
        raise ValueError(f"{path}: {exc} (camera{suffix or ''}); the file does not hold a valid calibration") from None
    if image_size is not None and min(image_size) < 1:
        raise ValueError(f"{path}: image size nx, ny = {image_size} is not positive; the file is corrupt")
    unc = {}
    for key, shape in _CAMERA_ERROR_SHAPES.items():
        name = f"{key}{suffix}_error"
        if key == "kc":
            v = _mat_kc(m, name, path)
        else:
            v = _mat_vector(m, name, max(1, int(np.prod(shape))), path)
        if v is not None:
            unc[key] = float(v[0]) if shape == () else _readonly(v)
    return cam, unc


def _mat_rotation(m, path, tol=1e-6):
    """The stereo rotation R, checked to be a rotation (orthonormal, determinant +1)."""
    R = np.asarray(m["R"], dtype=np.float64)
    if R.shape != (3, 3):
        raise ValueError(f"{path}: variable R has shape {R.shape}, expected (3, 3)")
    if not np.all(np.isfinite(R)):
        raise ValueError(f"{path}: variable R is not finite; the file does not hold a valid calibration")
    ortho = float(np.max(np.abs(R.T @ R - np.eye(3))))
    det = float(np.linalg.det(R))
    if ortho > tol or abs(det - 1.0) > tol:
        raise ValueError(
            f"{path}: variable R is not a rotation matrix (|R'R - I| = {ortho:.2g}, det(R) = {det:.3g}); "
            "the file is corrupt or was edited: recalibrate or restore the toolbox's file"
        )
    return R


def _column(v):
    """MATLAB column vector (n, 1) float64."""
    return np.asarray(v, dtype=np.float64).reshape(-1, 1)


def _scalar(v):
    return np.asarray(v, dtype=np.float64).reshape(1, 1)


def _camera_variables(cam, suffix):
    return {
        f"fc{suffix}": _column(cam.fc),
        f"cc{suffix}": _column(cam.cc),
        f"kc{suffix}": _column(cam.kc),
        f"alpha_c{suffix}": _scalar(cam.alpha_c),
        f"KK{suffix}": np.asarray(cam.K, dtype=np.float64),
    }


def _error_variables(uncertainty, shapes, name_of, what):
    if uncertainty is None:
        return {}
    if not hasattr(uncertainty, "items"):
        raise ValueError(f"uncertainty must be a dict of 3-sigma arrays, got {type(uncertainty).__name__}")
    unknown = sorted(set(uncertainty) - set(shapes))
    if unknown:
        raise ValueError(f"uncertainty has unknown key(s) {unknown}; {what} keys are {sorted(shapes)}")
    out = {}
    for key, value in uncertainty.items():
        v = np.asarray(value, dtype=np.float64).reshape(-1)
        size = max(1, int(np.prod(shapes[key])))
        if key.startswith("kc") and v.size == 4:
            v = np.append(v, 0.0)
        if v.size != size:
            raise ValueError(f"uncertainty[{key!r}] must have {size} element(s), got shape {np.shape(value)}")
        out[name_of(key)] = _scalar(v[0]) if shapes[key] == () else _column(v)
    return out


def _add_extra(data, extra):
    if extra is None:
        return data
    if not hasattr(extra, "items"):
        raise ValueError(f"extra must be a dict of MATLAB variable names to values, got {type(extra).__name__}")
    for name, value in extra.items():
        if not isinstance(name, str) or not _MATLAB_NAME.match(name):
            raise ValueError(
                f"extra variable name {name!r} is not a valid MATLAB name (a letter, then up to "
                f"62 letters, digits or underscores)"
            )
        if name in data:
            raise ValueError(f"extra variable {name!r} would overwrite a calibration variable; rename it")
        data[name] = value
    return data


def _savemat(path, data):
    import scipy.io

    with atomic_write(path, "wb") as f:
        scipy.io.savemat(f, data, format="5", oned_as="column")


def _image_size_variables(size):
    if size is None:
        return {}
    return {"nx": _scalar(size[0]), "ny": _scalar(size[1])}


@dataclass(frozen=True, eq=False)
class BouguetCalib:
    """A single-camera calibration read from the toolbox's ``Calib_Results.mat``.

    Per-view entries (``corners``, ``grid``, ``omc``, ``Tc``, ``n_sq_x``, ``n_sq_y``)
    are tuples with one item per calibration image, ``None`` where the view is inactive
    or its data are missing.

    Attributes
    ----------
    camera : Camera
        fc, cc, kc, alpha_c and image_size (from nx, ny).
    uncertainty : dict
        3-sigma uncertainties as the toolbox stores them in ``fc_error``, ``cc_error``,
        ``alpha_c_error`` (float), ``kc_error``; keys ``fc``, ``cc``, ``alpha_c``,
        ``kc``, each absent when the file lacks it.
    err_std : (2,) ndarray
        Standard deviation of the reprojection error in x and y, px (NaN if absent).
    corners : tuple of (N, 2) ndarray or None
        Extracted corners ``x_k`` as rows, px, origin at the centre of the top-left
        pixel (the toolbox's and wingphoto's convention: no shift applied).
    grid : tuple of (N, 3) ndarray or None
        Corresponding grid points ``X_k`` as rows, mm, in the board frame.
    omc, Tc : tuple of (3,) ndarray or None
        Board pose per view: ``X_camera = R(omc) X_grid + Tc`` (mm).
    active : (n_views,) ndarray of bool
        The toolbox's ``active_images``.
    image_size : (int, int) or None
        ``(nx, ny)``, width and height in px.
    dX, dY : float
        Square size of the board in mm (NaN if absent).
    n_sq_x, n_sq_y : tuple of int or None
        Number of squares along the board's x and y axes, per view.
    """

    camera: Camera
    uncertainty: dict
    err_std: np.ndarray
    corners: tuple
    grid: tuple
    omc: tuple
    Tc: tuple
    active: np.ndarray
    image_size: tuple | None = None
    dX: float = float("nan")
    dY: float = float("nan")
    n_sq_x: tuple = field(default=())
    n_sq_y: tuple = field(default=())

    def __post_init__(self):
        def views(items, cols=None):
            out = []
            for v in items:
                if v is None:
                    out.append(None)
                    continue
                a = _readonly(v)
                if cols is not None and (a.ndim != 2 or a.shape[1] != cols):
                    raise ValueError(f"per-view points must be (N, {cols}) rows, got shape {a.shape}")
                out.append(a)
            return tuple(out)

        object.__setattr__(self, "err_std", _readonly(np.asarray(self.err_std, dtype=float).reshape(2)))
        object.__setattr__(self, "corners", views(self.corners, 2))
        object.__setattr__(self, "grid", views(self.grid, 3))
        object.__setattr__(self, "omc", views(self.omc))
        object.__setattr__(self, "Tc", views(self.Tc))
        active = np.array(self.active, dtype=bool).reshape(-1)
        active.setflags(write=False)
        object.__setattr__(self, "active", active)
        object.__setattr__(self, "n_sq_x", tuple(self.n_sq_x))
        object.__setattr__(self, "n_sq_y", tuple(self.n_sq_y))
        object.__setattr__(self, "dX", float(self.dX))
        object.__setattr__(self, "dY", float(self.dY))
        n = len(self.active)
        for name in ("corners", "grid", "omc", "Tc"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} has {len(getattr(self, name))} views but active has {n}")

    @property
    def n_views(self):
        """Number of calibration images (active or not)."""
        return len(self.active)

    def summary(self):
        """Return a short text report: parameters with their 3-sigma uncertainties.

        Returns
        -------
        str
        """
        u = self.uncertainty
        cam = self.camera

        def pm(name, values):
            vals = np.atleast_1d(values)
            err = u.get(name)
            text = "[" + ", ".join(f"{v:.5g}" for v in vals) + "]"
            if err is not None:
                text += " +/- [" + ", ".join(f"{e:.3g}" for e in np.atleast_1d(err)) + "]"
            return f"  {name:<8}{text}"

        lines = [
            f"Bouguet calibration: {int(self.active.sum())} active of {self.n_views} views, "
            f"image size {self.image_size}",
            pm("fc", cam.fc),
            pm("cc", cam.cc),
            pm("alpha_c", cam.alpha_c),
            pm("kc", cam.kc),
            f"  err_std [{self.err_std[0]:.5g}, {self.err_std[1]:.5g}] px",
            "  (uncertainties are 3-sigma, as the toolbox reports them)",
        ]
        return "\n".join(lines)

    def __repr__(self):
        return (
            f"BouguetCalib({self.camera!r}, n_views={self.n_views}, active={int(self.active.sum())}, "
            f"err_std={np.array2string(self.err_std, precision=4)})"
        )


def load_bouguet_calib(path):
    """Read a single-camera calibration (``Calib_Results.mat``) of Bouguet's toolbox.

    Parameters
    ----------
    path : str or Path
        The toolbox's ``Calib_Results.mat`` (MATLAB v5/v7 format), or a file written by
        :func:`save_bouguet_calib`.

    Returns
    -------
    calib : BouguetCalib
        Camera, 3-sigma uncertainties, and the per-view corners, grid points and poses.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        The file is not a readable .mat file or lacks ``fc``/``cc``.

    Notes
    -----
    The toolbox stores points as columns (``x_k`` is (2, N), ``X_k`` is (3, N)); they
    are returned as rows. Its pixel coordinates have (0, 0) at the centre of the
    top-left pixel, the same as wingphoto's, so no shift is applied. The ``*_error``
    values are three times the standard deviations (``go_calib_optim``).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from wingphoto.camera import Camera
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "Calib_Results.mat"
    >>> save_bouguet_calib(Camera(fc=[1000, 1001], cc=[255.5, 255.5], image_size=(512, 512)), p)
    >>> calib = load_bouguet_calib(p)
    >>> calib.camera.fc.tolist(), calib.image_size, calib.n_views
    ([1000.0, 1001.0], (512, 512), 0)
    """
    path = Path(path)
    m = _loadmat(path)
    camera, uncertainty = _mat_camera(m, "", path)
    err_std = _mat_vector(m, "err_std", 2, path)
    view_numbers = [int(mt.group(1)) for name in m if (mt := re.fullmatch(r"x_(\d+)", name))]
    if "n_ima" in m:
        n = int(np.asarray(m["n_ima"]).reshape(-1)[0])
    else:
        n = max(view_numbers, default=0)
    if "active_images" in m:
        active = np.asarray(m["active_images"]).reshape(-1).astype(bool)
        if active.size != n:
            raise ValueError(f"{path}: active_images has {active.size} entries but n_ima is {n}")
    else:
        active = np.array([f"x_{k}" in m for k in range(1, n + 1)], dtype=bool)

    def view(name, rows, k):
        if not active[k - 1] or name not in m:
            return None
        a = np.asarray(m[name], dtype=np.float64)
        if a.size == 0 or np.all(np.isnan(a)):
            return None
        if a.ndim != 2 or a.shape[0] != rows:
            raise ValueError(f"{path}: variable {name} has shape {a.shape}, expected ({rows}, N)")
        return a.T

    def integer(name):
        return int(np.asarray(m[name]).reshape(-1)[0]) if name in m else None

    def scalar(*names):
        for name in names:
            if name in m and np.size(m[name]):
                return float(np.asarray(m[name], dtype=np.float64).reshape(-1)[0])
        return float("nan")

    ks = range(1, n + 1)
    return BouguetCalib(
        camera=camera,
        uncertainty=uncertainty,
        err_std=np.full(2, np.nan) if err_std is None else err_std,
        corners=[view(f"x_{k}", 2, k) for k in ks],
        grid=[view(f"X_{k}", 3, k) for k in ks],
        omc=[None if (v := view(f"omc_{k}", 3, k)) is None else v.reshape(3) for k in ks],
        Tc=[None if (v := view(f"Tc_{k}", 3, k)) is None else v.reshape(3) for k in ks],
        active=active,
        image_size=camera.image_size,
        dX=scalar("dX", "dX_1"),
        dY=scalar("dY", "dY_1"),
        n_sq_x=[integer(f"n_sq_x_{k}") for k in ks],
        n_sq_y=[integer(f"n_sq_y_{k}") for k in ks],
    )


def save_bouguet_calib(camera, path, *, uncertainty=None, err_std=None, extra=None):
    """Write a camera as the toolbox's single-camera ``Calib_Results.mat``.

    Parameters
    ----------
    camera : Camera
        Intrinsics to write; ``image_size`` gives ``nx, ny`` when known.
    path : str or Path
        Destination; written atomically (the old file survives a failure).
    uncertainty : dict, optional
        3-sigma uncertainties with keys among ``fc`` (2,), ``cc`` (2,), ``alpha_c``
        (scalar), ``kc`` (5,), written as ``fc_error``, ``cc_error``, ``alpha_c_error``,
        ``kc_error``.
    err_std : (2,) array_like, optional
        Reprojection error standard deviation in x and y, px.
    extra : dict, optional
        More variables to store (valid MATLAB names that do not clash with the above).

    Raises
    ------
    ValueError
        ``camera`` is not a Camera, or ``uncertainty``/``err_std``/``extra`` are malformed.

    Notes
    -----
    Variables written: ``fc, cc, kc, alpha_c, KK`` (+ ``nx, ny``, ``err_std``,
    ``*_error`` when known), as MATLAB column vectors (``fc`` is (2, 1), ``kc`` (5, 1)).
    The toolbox's ``KK`` is ``[fc1, alpha_c*fc1, cc1; 0, fc2, cc2; 0, 0, 1]``.
    """
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a wingphoto.Camera, got {type(camera).__name__}")
    data = _camera_variables(camera, "")
    data.update(_image_size_variables(camera.image_size))
    if err_std is not None:
        e = np.asarray(err_std, dtype=np.float64).reshape(-1)
        if e.size != 2:
            raise ValueError(f"err_std must have 2 elements (x, y), got shape {np.shape(err_std)}")
        data["err_std"] = _column(e)
    data.update(_error_variables(uncertainty, _CAMERA_ERROR_SHAPES, lambda k: f"{k}_error", "camera"))
    _savemat(path, _add_extra(data, extra))


def load_bouguet_stereo(path):
    """Read a stereo calibration (``Calib_Results_stereo.mat``) of Bouguet's toolbox.

    Parameters
    ----------
    path : str or Path
        File saved by the toolbox's ``stereo_gui`` (or by :func:`save_bouguet_stereo`).

    Returns
    -------
    rig : StereoRig
        Both cameras (image_size from ``nx, ny`` when present) and ``om, T`` with
        ``X_right = R(om) X_left + T`` (mm). ``om`` is derived from ``R`` when only
        ``R`` is stored.
    uncertainty : dict
        3-sigma uncertainties from the ``*_error`` variables, keys ``fc_left``,
        ``cc_left``, ``alpha_c_left`` (float), ``kc_left``, the same ``_right``, ``om``
        and ``T``; a key is absent when the file lacks it.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        The file is not a readable .mat file or lacks a required variable.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from wingphoto.camera import Camera, StereoRig
    >>> cam = Camera(fc=[1840, 1845], cc=[255.5, 255.5], image_size=(512, 512))
    >>> rig = StereoRig(cam, cam, om=[0.026, 0.733, 0.003], T=[-272.7, -1.5, 108.7])
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "Calib_Results_stereo.mat"
    >>> save_bouguet_stereo(rig, p, uncertainty={"T": [0.5, 0.1, 0.9]})
    >>> rig2, unc = load_bouguet_stereo(p)
    >>> rig2 == rig, unc["T"].tolist()
    (True, [0.5, 0.1, 0.9])
    """
    path = Path(path)
    m = _loadmat(path)
    left, unc_left = _mat_camera(m, "_left", path)
    right, unc_right = _mat_camera(m, "_right", path)
    if "T" not in m or ("om" not in m and "R" not in m):
        raise ValueError(
            f"{path} lacks the stereo pose (om or R, and T); expected the toolbox's "
            f"Calib_Results_stereo.mat"
        )
    T = _mat_vector(m, "T", 3, path)
    om = _mat_vector(m, "om", 3, path) if "om" in m else None
    R = _mat_rotation(m, path) if "R" in m else None
    if om is not None and not np.all(np.isfinite(om)):
        raise ValueError(f"{path}: variable om is not finite ({om}); the file does not hold a valid calibration")
    if om is None:
        om = rodrigues_inverse(R)
    elif R is not None and np.max(np.abs(rodrigues(om) - R)) > 1e-6:
        raise ValueError(
            f"{path}: variables om and R disagree (R(om) differs from R by up to "
            f"{np.max(np.abs(rodrigues(om) - R)):.2g}); the file was edited or mixes two calibrations"
        )
    if not np.all(np.isfinite(T)):
        raise ValueError(f"{path}: variable T is not finite ({T}); the file does not hold a valid calibration")
    if not np.linalg.norm(T) > 0:
        raise ValueError(f"{path}: variable T is zero: the two cameras would share one centre (no baseline), so "
                         "nothing can be triangulated; the file does not hold a stereo calibration")
    rig = StereoRig(left, right, om=om, T=T)
    uncertainty = {f"{k}_left": v for k, v in unc_left.items()}
    uncertainty.update({f"{k}_right": v for k, v in unc_right.items()})
    for key in ("om", "T"):
        v = _mat_vector(m, f"{key}_error", 3, path)
        if v is not None:
            uncertainty[key] = _readonly(v)
    return rig, uncertainty


def save_bouguet_stereo(rig, path, *, uncertainty=None, extra=None):
    """Write a stereo rig with the variable names of the toolbox's ``Calib_Results_stereo.mat``.

    Parameters
    ----------
    rig : StereoRig
        The rig; both cameras must share one image size (the toolbox stores one
        ``nx, ny``) or leave it unknown.
    path : str or Path
        Destination; written atomically (the old file survives a failure).
    uncertainty : dict, optional
        3-sigma uncertainties with keys among ``fc_left``, ``cc_left``,
        ``alpha_c_left``, ``kc_left``, the same ``_right``, ``om`` and ``T``; written
        as ``fc_left_error``, ..., ``om_error``, ``T_error``.
    extra : dict, optional
        More variables to store (valid MATLAB names that do not clash with the above).

    Raises
    ------
    ValueError
        ``rig`` is not a StereoRig, the cameras' image sizes differ, or ``uncertainty``
        / ``extra`` are malformed.

    Notes
    -----
    Variables written: ``om, R, T, fc_left, cc_left, kc_left, alpha_c_left, KK_left``,
    the same ``_right``, and ``nx, ny`` when the image size is known; vectors as
    MATLAB columns (``om``, ``T``: (3, 1); ``fc``, ``cc``: (2, 1); ``kc``: (5, 1)),
    scalars as (1, 1), all double. OpenCV's ``stereoCalibrate`` R, T have the same
    meaning as the toolbox's R, T.
    """
    if not isinstance(rig, StereoRig):
        raise ValueError(f"rig must be a wingphoto.StereoRig, got {type(rig).__name__}")
    sizes = {s for s in (rig.left.image_size, rig.right.image_size) if s is not None}
    if len(sizes) > 1:
        raise ValueError(
            f"the left and right image sizes differ ({rig.left.image_size} vs "
            f"{rig.right.image_size}) but the toolbox stores a single nx, ny; set both "
            f"cameras' image_size to the same value (Camera.replace(image_size=...))"
        )
    data = {"om": _column(rig.om), "R": rodrigues(rig.om), "T": _column(rig.T)}
    data.update(_camera_variables(rig.left, "_left"))
    data.update(_camera_variables(rig.right, "_right"))
    data.update(_image_size_variables(next(iter(sizes)) if sizes else None))
    data.update(_error_variables(uncertainty, _STEREO_ERROR_SHAPES, lambda k: f"{k}_error", "stereo"))
    _savemat(path, _add_extra(data, extra))



# =====================================================================================
# Tracks and 3D points tables
# =====================================================================================

#: Columns of a tracks DataFrame, in order (extra columns may follow).