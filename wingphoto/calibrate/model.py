"""The projection model and the least-squares machinery (Jacobian, solve, covariance) of the calibrations."""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..camera import Camera

logger = logging.getLogger(__name__)


# ============================================================== projection model
def _rodrigues_batch(om):
    """(V, 3) rotation vectors -> (V, 3, 3) matrices (same formula as ``rodrigues``)."""
    om = np.asarray(om, dtype=np.float64).reshape(-1, 3)
    theta = np.linalg.norm(om, axis=1)
    small = theta < np.finfo(float).eps
    t = np.where(small, 1.0, theta)
    w = om / t[:, None]
    z = np.zeros_like(theta)
    wx = np.stack(
        [
            np.stack([z, -w[:, 2], w[:, 1]], axis=1),
            np.stack([w[:, 2], z, -w[:, 0]], axis=1),
            np.stack([-w[:, 1], w[:, 0], z], axis=1),
        ],
        axis=1,
    )
    c, s = np.cos(theta)[:, None, None], np.sin(theta)[:, None, None]
    R = c * np.eye(3) + s * wx + (1.0 - c) * w[:, :, None] * w[:, None, :]
    R[small] = np.eye(3)
    return R


def _project(intr, Xc):
    """Project camera-frame points with the 10 toolbox intrinsics (as ``Camera.project``)."""
    fc1, fc2, cc1, cc2, alpha, k1, k2, p1, p2, k3 = intr
    x = Xc[:, 0] / Xc[:, 2]
    y = Xc[:, 1] / Xc[:, 2]
    r2 = x * x + y * y
    radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    xd = radial * x + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = radial * y + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.column_stack([fc1 * (xd + alpha * yd) + cc1, fc2 * yd + cc2])


def _transform(R, T, vid, obj):
    """Board points of views ``vid`` into the camera frame: R[v] X + T[v]."""
    return np.einsum("mij,mj->mi", R[vid], obj) + T[vid]


def _intrinsics_vector(cam):
    return np.concatenate([cam.fc, cam.cc, [cam.alpha_c], cam.kc])


def _camera_from_vector(v, image_size):
    return Camera(fc=v[0:2], cc=v[2:4], alpha_c=v[4], kc=v[5:10], image_size=image_size)


@dataclass(frozen=True)
class _Estimate:
    """Which intrinsics are estimated (the toolbox's est_* switches)."""

    skew: bool = False
    k3: bool = False
    tangential: bool = True
    principal_point: bool = True
    aspect_ratio: bool = True

    @property
    def free(self):
        t, c = self.tangential, self.principal_point
        return np.array([True, self.aspect_ratio, c, c, self.skew, True, True, t, t, self.k3])

    def unpack(self, p, base):
        out = base.copy()
        out[self.free] = p
        if not self.aspect_ratio:
            out[1] = out[0]
        return out

    def as_dict(self):
        """The toolbox's switches: est_fc, est_aspect_ratio, center_optim, est_alpha, est_dist."""
        return {
            "est_fc": np.array([1, 1]),
            "est_aspect_ratio": int(self.aspect_ratio),
            "center_optim": int(self.principal_point),
            "est_alpha": int(self.skew),
            "est_dist": np.array([1, 1, int(self.tangential), int(self.tangential), int(self.k3)]),
        }


def _fd_jacobian(fun, x, groups, rows_of, f0_size):
    """Central-difference Jacobian using the block structure of the problem.

    ``groups`` are lists of columns that never affect the same residual (one board pose
    parameter of every view), so each group costs two evaluations of ``fun``;
    ``rows_of[j]`` is the slice of residuals column ``j`` affects.
    """
    J = np.zeros((f0_size, x.size))
    step = np.cbrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x))
    for cols in groups:
        xp = x.copy()
        xm = x.copy()
        xp[cols] += step[cols]
        xm[cols] -= step[cols]
        df = fun(xp) - fun(xm)
        for j in cols:
            r = rows_of[j]
            J[r, j] = df[r] / (xp[j] - xm[j])
    return J


def _solve(fun, x0, groups, rows_of, m):
    def jac(x):
        return _fd_jacobian(fun, x, groups, rows_of, m)

    sol = least_squares(
        fun, x0, jac=jac, method="lm", x_scale="jac", ftol=1e-12, xtol=1e-12, gtol=1e-12,
        max_nfev=200,
    )
    if not sol.success:  # pragma: no cover - ill-posed input
        logger.warning("least-squares refinement stopped: %s", sol.message)
    logger.debug("least_squares: %d parameters, %d evaluations, %d Jacobians, cost %.6g -> %.6g",
                 x0.size, sol.nfev, sol.njev, 0.5 * np.sum(fun(x0) ** 2), sol.cost)
    return sol.x, jac(sol.x)


def _covariance(J):
    """(J^T J)^-1, with column scaling for conditioning."""
    d = np.linalg.norm(J, axis=0)
    d[d == 0] = 1.0
    Js = J / d
    try:
        inv = np.linalg.inv(Js.T @ Js)
    except np.linalg.LinAlgError:
        inv = np.linalg.pinv(Js.T @ Js)
    return inv / np.outer(d, d)


def _std(a, axis=None):
    a = np.asarray(a, dtype=np.float64)
    n = a.size if axis is None else a.shape[axis]
    if n < 2:
        return np.full(() if axis is None else a.shape[1 - axis], np.nan)
    return np.std(a, axis=axis, ddof=1)  # MATLAB's std normalises by n - 1

