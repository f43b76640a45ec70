"""Pinhole camera with Bouguet/Zhang lens distortion, and a calibrated stereo rig.

Conventions (see ``docs/conventions.md``): pixel (x, y) with (0, 0) at the centre of
the top-left pixel, x right and y down; camera frame x right, y down, z forward, in mm;
parameters keep the Bouguet toolbox names ``fc, cc, alpha_c, kc = [k1 k2 p1 p2 k3]``;
a stereo rig maps left-camera points to the right camera as ``X_right = R(om) X_left + T``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Camera", "StereoRig", "rodrigues", "as_points"]


def _frozen_array(value, shape, name):
    arr = np.array(value, dtype=np.float64).reshape(-1) if np.ndim(value) else np.array(value, dtype=np.float64)
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr}")
    arr.setflags(write=False)
    return arr


def as_points(points, dim, name="points"):
    """Return ``points`` as a float64 (N, dim) array and whether a single point was given.

    Parameters
    ----------
    points : array_like, (N, dim) or (dim,)
        Rows of coordinates.
    dim : int
        2 for pixels, 3 for points in mm.
    name : str
        Argument name used in error messages.

    Returns
    -------
    pts : (N, dim) ndarray of float64
    single : bool
        True when a single (dim,) point was given (callers then return a single row).
    """
    arr = np.asarray(points, dtype=np.float64)
    single = arr.ndim == 1
    if single:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(
            f"{name} must be an (N, {dim}) array of rows (or a single ({dim},) point), "
            f"got shape {np.shape(points)}; transpose MATLAB-style ({dim}, N) arrays first"
        )
    return arr, single


def rodrigues(om):
    """Rotation matrix of a rotation vector, as the toolbox's ``rodrigues.m``.

    Parameters
    ----------
    om : (3,) array_like
        Rotation vector (axis times angle in radians).

    Returns
    -------
    R : (3, 3) ndarray
        ``R = cos(t) I + sin(t) [w]x + (1 - cos(t)) w w^T`` with ``t = |om|``, ``w = om / t``.

    Examples
    --------
    >>> import numpy as np
    >>> np.allclose(rodrigues([0, 0, np.pi / 2]) @ [1, 0, 0], [0, 1, 0])
    True
    """
    om = np.asarray(om, dtype=np.float64).reshape(3)
    theta = np.linalg.norm(om)
    if theta < np.finfo(float).eps:
        return np.eye(3)
    w = om / theta
    wx = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return np.cos(theta) * np.eye(3) + np.sin(theta) * wx + (1.0 - np.cos(theta)) * np.outer(w, w)


def rodrigues_inverse(R):
    """Rotation vector of a rotation matrix (inverse of :func:`rodrigues`)."""
    import cv2  # OpenCV's Rodrigues handles the angle-near-pi branch robustly

    om, _ = cv2.Rodrigues(np.asarray(R, dtype=np.float64))
    return om.reshape(3)


@dataclass(frozen=True)
class Camera:
    """A calibrated camera: pinhole, skew and Bouguet/Zhang distortion.

    Parameters
    ----------
    fc : (2,) array_like
        Focal lengths in pixels (OpenCV ``K[0, 0], K[1, 1]``).
    cc : (2,) array_like
        Principal point in pixels, origin at the centre of the top-left pixel
        (OpenCV ``K[0, 2], K[1, 2]``).
    kc : (5,) array_like, optional
        Distortion ``[k1, k2, p1, p2, k3]`` (OpenCV ``dist`` in the same order).
    alpha_c : float, optional
        Skew coefficient; the angle between the pixel axes is ``acos(alpha_c)``
        (OpenCV ``K[0, 1] = alpha_c * fc[0]``).
    image_size : (2,) tuple of int or None, optional
        (width, height) in pixels.

    Notes
    -----
    Projection of a point X = (X, Y, Z) in this camera's frame (Bouguet, Zhang):
    ``xn = (X/Z, Y/Z)``, ``r2 = |xn|^2``,
    ``xd = (1 + k1 r2 + k2 r2^2 + k3 r2^3) xn + dx`` with tangential term
    ``dx = (2 p1 x y + p2 (r2 + 2 x^2), p1 (r2 + 2 y^2) + 2 p2 x y)``, then
    ``u = fc1 (xd1 + alpha_c xd2) + cc1``, ``v = fc2 xd2 + cc2``.

    Examples
    --------
    >>> cam = Camera(fc=[1000, 1000], cc=[255.5, 255.5])
    >>> cam.project([[0.0, 0.0, 500.0]]).tolist()
    [[255.5, 255.5]]
    """

    fc: np.ndarray
    cc: np.ndarray
    kc: np.ndarray = field(default=(0.0, 0.0, 0.0, 0.0, 0.0))
    alpha_c: float = 0.0
    image_size: tuple | None = None

    def __post_init__(self):
        object.__setattr__(self, "fc", _frozen_array(self.fc, (2,), "fc"))
        object.__setattr__(self, "cc", _frozen_array(self.cc, (2,), "cc"))
        kc = np.asarray(self.kc, dtype=np.float64).reshape(-1)
        if kc.size == 4:  # the toolbox also accepts 4 coefficients (k3 = 0)
            kc = np.append(kc, 0.0)
        object.__setattr__(self, "kc", _frozen_array(kc, (5,), "kc"))
        alpha = float(np.asarray(self.alpha_c, dtype=np.float64).reshape(-1)[0])
        if not np.isfinite(alpha):
            raise ValueError(f"alpha_c must be a finite skew coefficient (usually 0), got {alpha}")
        object.__setattr__(self, "alpha_c", alpha)
        if np.any(self.fc <= 0):
            raise ValueError(f"fc must be positive focal lengths in pixels, got {self.fc}")
        if self.image_size is not None:
            size = np.asarray(self.image_size, dtype=np.float64).reshape(-1)
            if size.size != 2 or not np.all(np.isfinite(size)) or np.any(size < 1) or np.any(size != np.round(size)):
                raise ValueError(f"image_size must be (width, height) in whole pixels >= 1, got {self.image_size!r}")
            w, h = (int(v) for v in size)
            object.__setattr__(self, "image_size", (w, h))

    # ------------------------------------------------------------------ model
    @property
    def K(self):
        """(3, 3) intrinsic matrix (OpenCV's camera matrix)."""
        return np.array(
            [
                [self.fc[0], self.alpha_c * self.fc[0], self.cc[0]],
                [0.0, self.fc[1], self.cc[1]],
                [0.0, 0.0, 1.0],
            ]
        )

    def distort(self, xn):
        """Apply the lens distortion to normalised coordinates.

        Parameters
        ----------
        xn : (N, 2) array_like
            Undistorted normalised coordinates (X/Z, Y/Z).

        Returns
        -------
        xd : (N, 2) ndarray
            Distorted normalised coordinates.
        """
        xn, single = as_points(xn, 2, "xn")
        k1, k2, p1, p2, k3 = self.kc
        x, y = xn[:, 0], xn[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
        dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        xd = np.column_stack([radial * x + dx, radial * y + dy])
        return xd[0] if single else xd

    def project(self, X):
        """Project 3D points in this camera's frame to pixels.

        Parameters
        ----------
        X : (N, 3) or (3,) array_like
            Points in mm in this camera's frame. NaN rows give NaN rows.

        Returns
        -------
        x : (N, 2) or (2,) ndarray
            Pixel coordinates, origin at the centre of the top-left pixel.
        """
        X, single = as_points(X, 3, "X")
        with np.errstate(invalid="ignore", divide="ignore"):
            xn = X[:, :2] / X[:, 2:3]
        xd = self.distort(xn)
        u = self.fc[0] * (xd[:, 0] + self.alpha_c * xd[:, 1]) + self.cc[0]
        v = self.fc[1] * xd[:, 1] + self.cc[1]
        x = np.column_stack([u, v])
        return x[0] if single else x

    def normalize(self, x, *, iterations=20):
        """Undistorted normalised coordinates of pixels (the toolbox's ``normalize_pixel``).

        Parameters
        ----------
        x : (N, 2) or (2,) array_like
            Pixel coordinates. NaN rows give NaN rows.
        iterations : int, optional
            Fixed-point iterations of ``comp_distortion_oulu`` (default 20, as the
            toolbox). OpenCV's ``undistortPoints`` uses 5 by default and differs by up
            to ~0.09 px at the corners of a strongly distorted image.

        Returns
        -------
        xn : (N, 2) or (2,) ndarray
            Normalised coordinates (X/Z, Y/Z) of the viewing rays.
        """
        x, single = as_points(x, 2, "x")
        xd = np.column_stack(
            [(x[:, 0] - self.cc[0]) / self.fc[0], (x[:, 1] - self.cc[1]) / self.fc[1]]
        )
        xd[:, 0] -= self.alpha_c * xd[:, 1]
        if np.linalg.norm(self.kc) != 0:
            # Written by hand because it must match the toolbox's comp_distortion_oulu
            # to 1e-9 (fixed iteration count and order); cv2.undistortPoints differs.
            k1, k2, p1, p2, k3 = self.kc
            xn = xd.copy()
            for _ in range(int(iterations)):
                px, py = xn[:, 0], xn[:, 1]
                r2 = px * px + py * py
                radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
                dx = 2.0 * p1 * px * py + p2 * (r2 + 2.0 * px * px)
                dy = p1 * (r2 + 2.0 * py * py) + 2.0 * p2 * px * py
                xn = np.column_stack([(xd[:, 0] - dx) / radial, (xd[:, 1] - dy) / radial])
        else:
            xn = xd
        return xn[0] if single else xn

    def undistort_points(self, x, *, iterations=20):
        """Pixels with the lens distortion removed (same K, ideal pinhole)."""
        xn, single = as_points(self.normalize(x, iterations=iterations), 2, "x")
        u = self.fc[0] * (xn[:, 0] + self.alpha_c * xn[:, 1]) + self.cc[0]
        v = self.fc[1] * xn[:, 1] + self.cc[1]
        out = np.column_stack([u, v])
        return out[0] if single else out

    # -------------------------------------------------------------- interop
    def to_opencv(self):
        """Return ``(K, dist, image_size)`` for OpenCV (dist = [k1, k2, p1, p2, k3])."""
        return self.K, self.kc.copy(), self.image_size

    @classmethod
    def from_opencv(cls, K, dist, image_size=None):
        """Build a Camera from OpenCV's camera matrix and distortion vector.

        Parameters
        ----------
        K : (3, 3) array_like
            Camera matrix.
        dist : array_like
            Distortion coefficients; the first five are used as [k1, k2, p1, p2, k3]
            (rational or thin-prism terms beyond them are not part of the Bouguet model
            and must be zero).
        image_size : (width, height), optional
        """
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (3, 3):
            raise ValueError(f"K must be a 3x3 camera matrix, got shape {K.shape}")
        d = np.asarray(dist, dtype=np.float64).reshape(-1)
        if d.size < 4:
            raise ValueError(f"dist must have at least 4 coefficients, got {d.size}")
        if d.size > 5 and np.any(d[5:] != 0):
            raise ValueError("dist has non-zero terms beyond k3, which the Bouguet model lacks")
        kc = np.zeros(5)
        kc[: min(5, d.size)] = d[:5]
        fc = np.array([K[0, 0], K[1, 1]])
        return cls(fc=fc, cc=K[:2, 2], kc=kc, alpha_c=K[0, 1] / K[0, 0], image_size=image_size)

    def replace(self, **changes):
        """Return a copy with some parameters changed (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)

    def __eq__(self, other):
        if not isinstance(other, Camera):
            return NotImplemented
        return (
            np.array_equal(self.fc, other.fc)
            and np.array_equal(self.cc, other.cc)
            and np.array_equal(self.kc, other.kc)
            and self.alpha_c == other.alpha_c
            and self.image_size == other.image_size
        )

    __hash__ = None

    def __repr__(self):
        f = np.array2string
        return (
            f"Camera(fc={f(self.fc, precision=5)}, cc={f(self.cc, precision=5)}, "
            f"kc={f(self.kc, precision=5)}, alpha_c={self.alpha_c:.5g}, image_size={self.image_size})"
        )


@dataclass(frozen=True)
class StereoRig:
    """Two calibrated cameras and the pose of the right camera relative to the left.

    Parameters
    ----------
    left, right : Camera
    om : (3,) array_like
        Rotation vector of the right camera relative to the left (Bouguet ``om``).
    T : (3,) array_like
        Translation in mm (Bouguet ``T``): ``X_right = R(om) @ X_left + T``
        (OpenCV ``stereoCalibrate``'s R, T have the same meaning).
    """

    left: Camera
    right: Camera
    om: np.ndarray
    T: np.ndarray

    def __post_init__(self):
        for name in ("left", "right"):
            if not isinstance(getattr(self, name), Camera):
                raise ValueError(f"{name} must be a wingphoto.Camera, got {type(getattr(self, name)).__name__}")
        object.__setattr__(self, "om", _frozen_array(self.om, (3,), "om"))
        object.__setattr__(self, "T", _frozen_array(self.T, (3,), "T"))

    @property
    def R(self):
        """(3, 3) rotation matrix ``R(om)``."""
        return rodrigues(self.om)

    @property
    def baseline(self):
        """Distance between the optical centres, mm."""
        return float(np.linalg.norm(self.T))

    def to_right(self, X_left):
        """Transform (N, 3) points from the left camera frame to the right camera frame."""
        X, single = as_points(X_left, 3, "X_left")
        Xr = X @ self.R.T + self.T
        return Xr[0] if single else Xr

    def project(self, X_left):
        """Project points given in the left camera frame into both images.

        Returns
        -------
        xL, xR : (N, 2) ndarray
            Pixels in the left and right images.
        """
        return self.left.project(X_left), self.right.project(self.to_right(X_left))

    @property
    def essential_matrix(self):
        """E = [T]x R, with ``xnR^T E xnL = 0`` for normalised homogeneous coordinates."""
        t = self.T
        tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
        return tx @ self.R

    @property
    def fundamental_matrix(self):
        """F = K_R^-T E K_L^-1 for *undistorted* pixels (``xR^T F xL = 0``)."""
        return np.linalg.inv(self.right.K).T @ self.essential_matrix @ np.linalg.inv(self.left.K)

    def epipolar_distance(self, xL, xR):
        """Symmetric epipolar distance of left/right pixel pairs, in pixels.

        Lens distortion is removed first (the toolbox's undistortion), then the distance
        of each point from the other's epipolar line is measured in the undistorted
        image and the two are averaged.

        Parameters
        ----------
        xL, xR : (N, 2) array_like
            Corresponding pixels in the left and right images.

        Returns
        -------
        d : (N,) ndarray
            Pixels; NaN where either observation is NaN.
        """
        uL, single = as_points(self.left.undistort_points(xL), 2, "xL")
        uR, _ = as_points(self.right.undistort_points(xR), 2, "xR")
        if uL.shape != uR.shape:
            raise ValueError(f"xL and xR must have the same shape, got {uL.shape} and {uR.shape}")
        F = self.fundamental_matrix
        hL = np.column_stack([uL, np.ones(len(uL))])
        hR = np.column_stack([uR, np.ones(len(uR))])
        lR = hL @ F.T  # lines in the right image
        lL = hR @ F  # lines in the left image
        num = np.abs(np.sum(hR * lR, axis=1))
        dR = num / np.hypot(lR[:, 0], lR[:, 1])
        dL = num / np.hypot(lL[:, 0], lL[:, 1])
        d = 0.5 * (dR + dL)
        return d[0] if single else d

    def replace(self, **changes):
        """Return a copy with some fields changed (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)

    def __eq__(self, other):
        if not isinstance(other, StereoRig):
            return NotImplemented
        return (
            self.left == other.left
            and self.right == other.right
            and np.array_equal(self.om, other.om)
            and np.array_equal(self.T, other.T)
        )

    __hash__ = None
