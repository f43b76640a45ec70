"""Checks that tell a user whether a stereo calibration can be trusted.

:func:`wingphoto.calibrate.calibrate_stereo` calls :func:`check_pairs` before its
joint refinement, and refuses input that the toolbox would have calibrated silently:

* **identical views**: the same image (or the same corners) given as left and right, e.g.
  one folder passed twice. Every pair identical is an error; single identical pairs are
  rejected by name.
* **pairs out of sync**: each pair gives its own estimate of the rig pose ``(om, T)`` from
  its two board poses (one per camera, from each camera's own calibration). A pair
  whose right image is not the one taken with its left image disagrees with the rest:
  it is rejected and named. A constant offset (right image ``i + k`` named ``i``) is
  diagnosed by pairing left ``i`` with right ``i - k`` for small ``k``: the offset that
  makes the most pairs consistent wins, and the message says how to fix the pairing.

  A pan-tilt schedule makes this subtle: consecutive poses differ by the same pan
  step, so with an offset most pairs agree on a *wrong* rig (on the thesis rig, T off
  by 70 mm with a 0.014 px pixel error); only the pairs at the turns of the schedule
  disagree. Counting the consistent pairs at each offset still finds the right pairing.

:func:`cross_validate` is the mrcal-style check of the result: calibrate on two halves of
the pairs and compare the two calibrations' projections with the difference their own
uncertainties predict.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .camera import rodrigues, rodrigues_inverse

__all__ = ["PairCheck", "check_pairs", "identical_pairs", "CrossValidation", "cross_validate"]

logger = logging.getLogger(__name__)

#: A pair is inconsistent when its right-image RMS error (predicted from its left board
#: pose and the median rig) exceeds this factor times the median over the pairs ...
CONSISTENCY_FACTOR = 8.0
#: ... and this floor (px).
CONSISTENCY_FLOOR_PX = 1.0


def identical_pairs(corners_left, corners_right, *, atol=1e-6):
    """Indices of pairs whose left and right corners are the same (the same image twice).

    Parameters
    ----------
    corners_left, corners_right : sequence of ((N, 2) ndarray or None)

    Returns
    -------
    list of int
    """
    out = []
    for i, (a, b) in enumerate(zip(corners_left, corners_right)):
        if a is None or b is None:
            continue
        a, b = np.asarray(a, float), np.asarray(b, float)
        if a.shape == b.shape and np.any(np.isfinite(a)) and np.allclose(a, b, atol=atol, equal_nan=True):
            out.append(i)
    return out


def _pair_poses(mono_l, mono_r, pairs):
    """Rig pose (om, T) implied by each (left view i, right view j) in ``pairs``."""
    oms, Ts = [], []
    for i, j in pairs:
        Rl, Rr = rodrigues(mono_l.omc[i]), rodrigues(mono_r.omc[j])
        R = Rr @ Rl.T
        oms.append(rodrigues_inverse(R))
        Ts.append(mono_r.Tc[j] - R @ mono_l.Tc[i])
    return np.array(oms).reshape(-1, 3), np.array(Ts).reshape(-1, 3)


def _pair_errors(mono_l, mono_r, boards, obs_r, pairs, om, T):
    """RMS right-image error of each pair, its right corners predicted from its left pose and (om, T)."""
    Rs = rodrigues(om)
    out = np.full(len(pairs), np.inf)
    for k, (i, j) in enumerate(pairs):
        Rl = rodrigues(mono_l.omc[i])
        X = boards[i] @ (Rs @ Rl).T + (Rs @ mono_l.Tc[i] + T)
        if np.any(X[:, 2] <= 0):
            continue
        d = obs_r[j] - mono_r.camera.project(X)
        ok = np.all(np.isfinite(d), axis=1)
        if ok.any():
            out[k] = float(np.sqrt(np.mean(np.sum(d[ok] ** 2, axis=1))))
    return out


def _consistency(mono_l, mono_r, boards, obs_r, pairs):
    """Median rig of ``pairs``, each pair's rig pose and its right-image error under the median rig."""
    om, T = _pair_poses(mono_l, mono_r, pairs)
    om0, T0 = np.median(om, axis=0), np.median(T, axis=0)
    err = _pair_errors(mono_l, mono_r, boards, obs_r, pairs, om0, T0)
    return om0, T0, om, T, err


def _median(err):
    e = err[np.isfinite(err)]
    return float(np.median(e)) if e.size else np.inf


@dataclass(frozen=True)
class PairCheck:
    """Result of :func:`check_pairs`.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per candidate pair: ``pair`` (name), ``om0..om2``, ``T0..T2`` (the rig
        pose that pair alone implies; rad, mm), ``error_px`` (RMS right-image error
        predicted from the pair's left board pose and the median rig), ``consistent``,
        ``identical``.
    om, T : (3,) ndarray
        The median rig pose of the candidate pairs (the start of the joint refinement).
    tolerance_px : float
        The consistency tolerance used: ``max(1 px, 8 x`` the median error of the
        best-agreeing pairing).
    offset : int
        The pairing offset that makes the most pairs consistent: 0 when the pairs are
        in sync; ``k`` when left image ``i`` matches right image ``i + k``.
    offsets : pandas.DataFrame
        ``offset, n_pairs, n_consistent, share`` for every offset tried.
    message : str
        The diagnosis in words ('' when nothing is wrong).
    """

    table: pd.DataFrame
    om: np.ndarray
    T: np.ndarray
    tolerance_px: float
    offset: int
    offsets: pd.DataFrame
    message: str

    @property
    def inconsistent(self):
        """Names of the pairs inconsistent with the rest."""
        t = self.table
        return t.loc[~t["consistent"] & ~t["identical"], "pair"].tolist()

    def summary(self):
        """A few lines: consistent pairs, the worst ones, the offset diagnosis."""
        t = self.table
        lines = [f"pair consistency: {int(t['consistent'].sum())} of {len(t)} pairs agree on the rig pose "
                 f"(right-image error <= {self.tolerance_px:.2f} px)"]
        for _, r in t[~t["consistent"]].sort_values("error_px", ascending=False).iterrows():
            why = "identical left and right" if r["identical"] else f"{r['error_px']:.1f} px"
            lines.append(f"  {r['pair']}: {why}")
        if self.message:
            lines.append(self.message)
        return "\n".join(lines)


def check_pairs(mono_left, mono_right, boards, corners_right, candidates, pair_names, *, max_offset=3,
                identical=()):
    """Per-pair rig poses, inconsistent pairs, and the diagnosis of a constant offset.

    Parameters
    ----------
    mono_left, mono_right : CameraCalibration
        Each camera's own calibration over every view it saw (board poses ``omc``, ``Tc``).
    boards : list of (N, 3) ndarray
        Board points of each pair (mm).
    corners_right : sequence of ((N, 2) ndarray or None)
        The right corners as the right calibration used them.
    candidates : sequence of int
        Pairs with the board in both views (and not suppressed).
    pair_names : sequence of str
    max_offset : int, optional
        Largest pairing offset tried (default 3).
    identical : sequence of int, optional
        Pairs known to be identical views (excluded, marked).

    Returns
    -------
    PairCheck
    """
    identical = set(identical)
    cand = [i for i in candidates if i not in identical]
    if not cand:
        raise ValueError("no pair left to check")
    om0, T0, om, T, err = _consistency(mono_left, mono_right, boards, corners_right, [(i, i) for i in cand])
    # other pairings: left view i with right view i + k (nearest offsets first)
    used_l = set(np.flatnonzero(mono_left.used)) - identical
    used_r = set(np.flatnonzero(mono_right.used)) - identical
    P = len(pair_names)
    trials = {}
    for k in sorted(range(-int(max_offset), int(max_offset) + 1), key=lambda k: (abs(k), k)):
        if k == 0:
            continue
        pairs = [(i, i + k) for i in range(P) if 0 <= i + k < P and i in used_l and (i + k) in used_r]
        if len(pairs) >= 3:
            trials[k] = _consistency(mono_left, mono_right, boards, corners_right, pairs)[-1]
    # one tolerance for every pairing, from the best-agreeing one (the noise of a good pair)
    best_median = min([_median(err)] + [_median(e) for e in trials.values()])
    tol = max(CONSISTENCY_FLOOR_PX, CONSISTENCY_FACTOR * best_median) if np.isfinite(best_median) else np.inf
    ok = err <= tol
    rows = []
    for k, i in enumerate(cand):
        rows.append((pair_names[i], *om[k], *T[k], err[k], bool(ok[k]), False))
    for i in sorted(identical):
        rows.append((pair_names[i], *[np.nan] * 6, np.nan, False, True))
    table = pd.DataFrame(rows, columns=["pair", "om0", "om1", "om2", "T0", "T1", "T2", "error_px", "consistent",
                                        "identical"])
    order = {n: k for k, n in enumerate(pair_names)}
    table = table.sort_values("pair", key=lambda s: s.map(order)).reset_index(drop=True)
    share0 = float(np.mean(ok))
    offs = [(0, len(cand), int(ok.sum()), share0)]
    best, best_share = 0, share0
    for k, e in trials.items():
        okk = e <= tol
        share = float(np.mean(okk))
        offs.append((k, len(e), int(okk.sum()), share))
        # a different pairing must explain clearly more pairs (not one lucky pair)
        if share > best_share + 0.5 / len(cand) and okk.sum() >= ok.sum() and share > 0.75:
            best, best_share = k, share
    offsets = pd.DataFrame(offs, columns=["offset", "n_pairs", "n_consistent", "share"]).sort_values("offset")
    offsets = offsets.reset_index(drop=True)
    message = ""
    if best != 0:
        n0 = int(ok.sum())
        row = offsets.set_index("offset").loc[best]
        k = abs(best)
        if best > 0:  # right image i + k was taken with left image i
            fix = (f"pair left image i with right image i+{k}: drop the first {k} right image(s) and the last "
                   f"{k} left image(s)")
        else:  # right image i - k was taken with left image i (right i named for frame i + k)
            fix = (f"pair left image i with right image i-{k}: drop the first {k} left image(s) and the last "
                   f"{k} right image(s)")
        message = (
            f"the pairs look out of sync by {best:+d}: left image i matches right image i{best:+d} "
            f"({int(row.n_consistent)} of {int(row.n_pairs)} pairs consistent), against {n0} of {len(cand)} "
            f"as given. Fix: {fix} (with frame selection, pass the offset found from the board motion)"
        )
    elif not ok.all():
        bad = [pair_names[i] for k, i in enumerate(cand) if not ok[k]]
        message = (f"{len(bad)} pair(s) disagree with the others on the rig pose (a wrong image in the pair, or "
                   f"the board moved between the two exposures): {', '.join(bad)}")
    return PairCheck(table=table, om=om0, T=T0, tolerance_px=float(tol), offset=int(best), offsets=offsets,
                     message=message)


# ============================================================== cross-validation
def _rig_vector(rig):
    cams = []
    for cam in (rig.left, rig.right):
        cams.append(np.concatenate([cam.fc, cam.cc, [cam.alpha_c], cam.kc]))
    return np.concatenate([*cams, rig.om, rig.T])


def _project_vector(p, XL):
    from .calibrate.model import _project

    xl = _project(p[0:10], XL)
    XR = XL @ rodrigues(p[20:23]).T + p[23:26]
    return xl, _project(p[10:20], XR)


def _projection_covariance(p, C, XL):
    """(M, 2, 2) covariances of the left and right projections of XL under parameter covariance C."""
    free = np.flatnonzero(np.diag(C) > 0)
    M = len(XL)
    Jl = np.zeros((M, 2, len(free)))
    Jr = np.zeros((M, 2, len(free)))
    for c, j in enumerate(free):
        h = 1e-6 * max(1.0, abs(p[j]))
        pp, pm = p.copy(), p.copy()
        pp[j] += h
        pm[j] -= h
        lp, rp = _project_vector(pp, XL)
        lm, rm = _project_vector(pm, XL)
        Jl[:, :, c] = (lp - lm) / (2 * h)
        Jr[:, :, c] = (rp - rm) / (2 * h)
    Cf = C[np.ix_(free, free)]
    return (np.einsum("mai,ij,mbj->mab", Jl, Cf, Jl), np.einsum("mai,ij,mbj->mab", Jr, Cf, Jr))


@dataclass(frozen=True)
class CrossValidation:
    """Result of :func:`cross_validate`.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per test point and camera: ``camera``, ``x``, ``y`` (where the full
        calibration projects it, px), ``difference_px`` (distance between the two
        halves' projections), ``expected_px`` (RMS of that distance predicted by the
        halves' covariances, ``sqrt(trace(C_a + C_b))``), ``chi2`` (the difference's
        Mahalanobis square under ``C_a + C_b``; 2 on average when the uncertainty is
        honest).
    halves : tuple of (tuple of str, tuple of str)
        The pairs of each half.
    depth_mm : float
        Distance of the test points from the left camera (the boards' median distance).
    """

    table: pd.DataFrame
    halves: tuple
    depth_mm: float

    def ratio(self, camera=None):
        """RMS of the differences over their predicted RMS (about 1 when the uncertainty is honest)."""
        t = self.table if camera is None else self.table[self.table["camera"] == camera]
        return float(np.sqrt(np.mean(t["chi2"]) / 2.0))

    @property
    def ok(self):
        """True when the halves agree within twice their predicted difference, in both cameras."""
        return all(self.ratio(c) <= 2.0 for c in ("left", "right"))

    def summary(self):
        lines = [f"cross-validation (mrcal-style): two halves of {len(self.halves[0])} and "
                 f"{len(self.halves[1])} pairs, test points at {self.depth_mm:.0f} mm"]
        for cam in ("left", "right"):
            t = self.table[self.table["camera"] == cam]
            lines.append(
                f"  {cam}: projections differ by {t['difference_px'].median():.3f} px (median; max "
                f"{t['difference_px'].max():.3f}), their uncertainty predicts {t['expected_px'].median():.3f} px; "
                f"ratio {self.ratio(cam):.2f}"
            )
        lines.append(
            "  the halves agree within their uncertainty: the reported uncertainty can be trusted" if self.ok else
            "  the halves disagree by more than their uncertainty allows: the model (e.g. distortion terms) or "
            "the corners are worse than the pixel error says; add views covering the image, try --estimate-k3, "
            "look at the worst views"
        )
        return "\n".join(lines)


def cross_validate(result, *, split="alternate", grid=(8, 6), depth=None):
    """Calibrate on two halves of the pairs and compare the projections (mrcal's check).

    Parameters
    ----------
    result : StereoCalibration
        A result of :func:`wingphoto.calibrate.calibrate_stereo` with at least 6 used pairs.
    split : {"alternate", "halves"}, optional
        ``"alternate"`` (default): pairs 0, 2, 4, ... against 1, 3, 5, ... (both halves
        cover the schedule: tests the model and the noise); ``"halves"``: the first half
        of the capture against the second (also catches a change during the session: a
        bumped camera, a turned focus ring).
    grid : (int, int), optional
        Test points: a grid of this many columns x rows over the left image, back-projected
        to ``depth`` (default 8 x 6).
    depth : float, optional
        Distance of the test points (mm, left camera z); default the median distance of
        the boards.

    Returns
    -------
    CrossValidation
        ``.table``, ``.ratio(camera)``, ``.ok``, ``.summary()``.

    Notes
    -----
    Each half is calibrated as the full set was (same
    estimated parameters, the corners as used). Both halves project the same 3D points
    (fixed in the left camera's frame, so no frame alignment is needed); their
    difference is compared with ``C_a + C_b``, the sum of the two projections'
    covariances propagated from :attr:`StereoCalibration.covariance`. A ratio near 1
    means the uncertainty is honest; well above 2 means the errors are not the
    independent corner noise the formula assumes (a too simple distortion model,
    biased corners, a moving board). As in mrcal, this is a necessary check, not a
    sufficient one: errors common to both halves (a wrong square size) pass it.
    """
    from .calibrate import StereoCalibration, calibrate_stereo

    if not isinstance(result, StereoCalibration):
        raise ValueError(f"result must be a StereoCalibration, got {type(result).__name__}")
    used = np.flatnonzero(result.used)
    if len(used) < 6:
        raise ValueError(f"cross-validation needs at least 6 used pairs (3 per half), this calibration has {len(used)}")
    inp = result._inputs
    est = inp.get("est_l")
    kw = {}
    if est is not None:
        kw = dict(estimate_skew=est.skew, estimate_k3=est.k3, estimate_tangential=est.tangential,
                  estimate_principal_point=est.principal_point, estimate_aspect_ratio=est.aspect_ratio)
    if split == "alternate":
        parts = (used[0::2], used[1::2])
    elif split == "halves":
        parts = (used[: (len(used) + 1) // 2], used[(len(used) + 1) // 2:])
    else:
        raise ValueError(f"split must be 'alternate' or 'halves', got {split!r}")
    halves, sols = [], []
    for part in parts:
        names = [result.pairs[i] for i in part]
        sol = calibrate_stereo(
            [result.corners_left[i] for i in part], [result.corners_right[i] for i in part], result.pattern_size,
            result.square_size, board_points=[result.board_points[i] for i in part],
            image_size=result.rig.left.image_size, names=names, force=True, **kw,
        )
        if sol.covariance is None:  # pragma: no cover - calibrate_stereo always sets it
            raise ValueError("cross-validation needs the halves' covariances")
        halves.append(tuple(names))
        sols.append(sol)
    if depth is None:
        depth = float(np.nanmedian(np.linalg.norm(result.Tc_left[used], axis=1)))
    w, h = result.rig.left.image_size
    gx, gy = np.meshgrid(np.linspace(0.05, 0.95, grid[0]) * (w - 1), np.linspace(0.05, 0.95, grid[1]) * (h - 1))
    px = np.column_stack([gx.ravel(), gy.ravel()])
    xn = result.rig.left.normalize(px)
    XL = np.column_stack([xn, np.ones(len(xn))]) * depth
    xl_full, xr_full = result.rig.project(XL)
    proj, covs = [], []
    for sol in sols:
        p = _rig_vector(sol.rig)
        proj.append(_project_vector(p, XL))
        covs.append(_projection_covariance(p, np.asarray(sol.covariance), XL))
    rows = []
    for c, cam in enumerate(("left", "right")):
        d = proj[0][c] - proj[1][c]
        S = covs[0][c] + covs[1][c]
        full = xl_full if c == 0 else xr_full
        for m in range(len(XL)):
            try:
                chi2 = float(d[m] @ np.linalg.solve(S[m], d[m]))
            except np.linalg.LinAlgError:  # pragma: no cover
                chi2 = np.nan
            rows.append((cam, full[m, 0], full[m, 1], float(np.hypot(*d[m])), float(np.sqrt(np.trace(S[m]))), chi2))
    table = pd.DataFrame(rows, columns=["camera", "x", "y", "difference_px", "expected_px", "chi2"])
    cv = CrossValidation(table=table, halves=tuple(halves), depth_mm=depth)
    logger.info("%s", cv.summary())
    return cv
