"""Stereo calibration: both cameras and their pose (om, T) refined jointly -> StereoCalibration."""
from __future__ import annotations

import dataclasses
import logging
import os
from dataclasses import dataclass, field

import numpy as np

from ..camera import StereoRig, rodrigues
from .checks import _MIN_VIEWS, _NOTE, _PM, _check_pattern_size, _check_square_size
from .model import _Estimate, _camera_from_vector, _covariance, _intrinsics_vector, _project, _rodrigues_batch, _solve, _std, _transform
from .mono import CameraCalibration, _calibrate_from_views, _stack
from .report import _camera_entries, _f, _frozen, _intrinsics_block, _rejected_lines, _select, _truth_table
from .views import _board_list, _gather_views, _image_size_of, _unique_names

logger = logging.getLogger(__name__)


# ============================================================== stereo
#: Names of the rows/columns of :attr:`StereoCalibration.covariance`, in order.
RIG_PARAMETER_NAMES = tuple(
    [f"{k}_{s}" if n == 1 else f"{k}_{s}[{i}]" for s in ("left", "right")
     for k, n in (("fc", 2), ("cc", 2), ("alpha_c", 1), ("kc", 5)) for i in range(n)]
    + [f"om[{i}]" for i in range(3)] + [f"T[{i}]" for i in range(3)]
)


@dataclass(frozen=True)
class StereoCalibration:
    """Joint calibration of a stereo rig (the toolbox's Calib_Results_stereo).

    Attributes
    ----------
    rig : StereoRig
        Both cameras and the right camera's pose ``(om, T)``:
        ``X_right = rodrigues(om) @ X_left + T`` (OpenCV ``stereoCalibrate``'s R, T).
    uncertainty : dict
        Three-sigma uncertainties with keys ``fc_left, cc_left, alpha_c_left, kc_left,
        fc_right, cc_right, alpha_c_right, kc_right, om, T`` (the toolbox's
        ``*_error``), ready for ``wingphoto.io.save_bouguet_stereo(rig, path,
        uncertainty=...)``.
    pixel_error : (2,) ndarray
        Per-axis standard deviation of the residuals of both cameras together, pixels.
    pixel_error_left, pixel_error_right : (2,) ndarray
        The same per camera (the toolbox's ``err_std`` of each camera).
    sigma : float
        Standard deviation of all residual components of both cameras.
    pairs : tuple of str
        One name per input pair ("left01.jpg / right01.jpg" or "pair i").
    used : (P,) ndarray of bool
        Pairs used in the joint refinement.
    rejected : dict
        ``{pair name: reason}`` for every pair left out.
    corners_left, corners_right : tuple of ((N, 2) ndarray or None)
        Corners as used (pixel-locking corrected when detected here).
    board_points : tuple of ((N, 3) ndarray or None)
    residuals_left, residuals_right : tuple of ((N, 2) ndarray or None)
        ``observed - projected`` per corner of each used pair, pixels.
    omc_left, Tc_left : (P, 3) ndarray
        Board pose in the left camera for each pair (NaN when unused), with three-sigma
        ``omc_left_error``, ``Tc_left_error``.
    mono_left, mono_right : CameraCalibration
        The single-camera calibrations used as the starting point.
    covariance : (26, 26) ndarray of float64
        One-sigma covariance ``sigma**2 (J^T J)^-1`` (``sigma`` the residual standard
        deviation, px) of the rig parameters of the joint refinement, in the order of
        :attr:`parameter_names`: ``fc_left[0..1], cc_left[0..1], alpha_c_left,
        kc_left[0..4]``, the same for the right camera, ``om[0..2]`` (rad), ``T[0..2]``
        (mm). The per-pair board poses, also estimated, are marginalised out (the
        sub-block of the full inverse). Parameters held fixed (e.g. ``alpha_c``,
        ``kc[4]`` by default) have zero rows and columns; with a fixed aspect ratio the
        ``fc[1]`` row repeats ``fc[0]``'s. ``3 * sqrt(diag(covariance))`` equals
        :attr:`uncertainty` entry by entry. Use it to propagate the calibration's
        uncertainty to 3D points.
    parameter_names : tuple of str
        The 26 names of the rows of :attr:`covariance` (:data:`RIG_PARAMETER_NAMES`),
        e.g. ``"fc_left[0]"``, ``"alpha_c_right"``, ``"om[2]"``, ``"T[0]"`` (the row
        labels of :meth:`compare`).
    pair_check : wingphoto.calibcheck.PairCheck
        Each pair's own rig pose and its consistency with the others, and the pairing
        offset diagnosis (:func:`wingphoto.calibcheck.check_pairs`).
    """

    rig: StereoRig
    uncertainty: dict
    pixel_error: np.ndarray
    pixel_error_left: np.ndarray
    pixel_error_right: np.ndarray
    sigma: float
    pairs: tuple
    used: np.ndarray
    rejected: dict
    corners_left: tuple
    corners_right: tuple
    board_points: tuple
    residuals_left: tuple
    residuals_right: tuple
    omc_left: np.ndarray
    Tc_left: np.ndarray
    omc_left_error: np.ndarray
    Tc_left_error: np.ndarray
    mono_left: CameraCalibration
    mono_right: CameraCalibration
    pattern_size: tuple
    square_size: tuple
    covariance: np.ndarray | None = field(default=None, repr=False)
    parameter_names: tuple = RIG_PARAMETER_NAMES
    pair_check: object = field(default=None, repr=False)
    _inputs: dict = field(repr=False, default_factory=dict)

    def parameter_sigma(self):
        """Return ``{parameter name: 1-sigma}`` from :attr:`covariance` (one third of ``uncertainty``)."""
        if self.covariance is None:
            raise ValueError("this StereoCalibration has no covariance (it was not made by calibrate_stereo)")
        return dict(zip(self.parameter_names, np.sqrt(np.diag(self.covariance))))

    @property
    def camera_uncertainty(self):
        """``{"left": {fc, cc, alpha_c, kc}, "right": {...}}`` (three sigma)."""
        u = self.uncertainty
        return {
            s: {k: u[f"{k}_{s}"] for k in ("fc", "cc", "alpha_c", "kc")} for s in ("left", "right")
        }

    @property
    def view_errors(self):
        """(P, 2) mean reprojection error (pixels) of each pair in the left and right image."""
        out = np.full((len(self.pairs), 2), np.nan)
        for j, res in enumerate((self.residuals_left, self.residuals_right)):
            for i, r in enumerate(res):
                if r is not None:
                    out[i, j] = float(np.nanmean(np.hypot(r[:, 0], r[:, 1])))
        return out

    def summary(self, *, ascii=False):
        """Return the toolbox's stereo results text ("Stereo calibration parameters ...").

        Parameters
        ----------
        ascii : bool, optional
            Write ``+/-`` instead of ``±``.
        """
        pm = "+/-" if ascii else _PM
        cu = self.camera_uncertainty
        u = self.uncertainty
        lines = ["Stereo calibration parameters after optimization:", "", "",
                 "Intrinsic parameters of left camera:", ""]
        lines += _intrinsics_block(self.rig.left, cu["left"], "_left", pm)
        lines += ["", "", "Intrinsic parameters of right camera:", ""]
        lines += _intrinsics_block(self.rig.right, cu["right"], "_right", pm)
        lines += ["", "", "Extrinsic parameters (position of right camera wrt left camera):", ""]
        om, T = self.rig.om, self.rig.T
        lines.append(
            f"Rotation vector:             om = [ {om[0]:3.5f}   {om[1]:3.5f}  {om[2]:3.5f} ] {pm} "
            f"[ {u['om'][0]:3.5f}   {u['om'][1]:3.5f}  {u['om'][2]:3.5f} ]"
        )
        lines.append(
            f"Translation vector:           T = [ {T[0]:3.5f}   {T[1]:3.5f}  {T[2]:3.5f} ] {pm} "
            f"[ {u['T'][0]:3.5f}   {u['T'][1]:3.5f}  {u['T'][2]:3.5f} ]"
        )
        lines += ["", "", _NOTE, ""]
        lines.append(f"Pixel error:     err_left = [ {_f(self.pixel_error_left)} ]")
        lines.append(f"Pixel error:    err_right = [ {_f(self.pixel_error_right)} ]")
        lines.append(f"Pairs used: {int(self.used.sum())} of {len(self.pairs)}")
        lines += _rejected_lines(self.rejected)
        return "\n".join(lines)

    def __str__(self):
        return self.summary()

    def compare(self, truth):
        """Table of every estimated stereo parameter against a known true rig.

        Parameters
        ----------
        truth : StereoRig
            The true rig (e.g. ``wingphoto.synth.load_rig("data-samples/rig.json")``).

        Returns
        -------
        pandas.DataFrame
            Rows fc_left[0] ... kc_right[4], om[0..2], T[0..2] with estimate, truth, error,
            three_sigma, error_in_sigma and inside_3sigma (see
            :meth:`CameraCalibration.compare`).
        """
        u = self.uncertainty
        entries = _camera_entries(self.rig.left, truth.left, u, "_left")
        entries += _camera_entries(self.rig.right, truth.right, u, "_right")
        entries += [("om", self.rig.om, truth.om, u["om"]), ("T", self.rig.T, truth.T, u["T"])]
        return _truth_table(entries)

    def suppress(self, pairs):
        """Recalibrate without some pairs.

        Parameters
        ----------
        pairs : int, str or sequence of them
            Pair indices (0-based) or names (``self.pairs``).

        Returns
        -------
        StereoCalibration
        """
        drop = _select(pairs, list(self.pairs), "pair") | set(self._inputs.get("suppressed", ()))
        kw = dict(self._inputs)
        kw["suppressed"] = drop
        return _stereo_from_views(**kw)

    def save(self, path, **kwargs):
        """Write the toolbox's ``Calib_Results_stereo.mat`` with the uncertainties.

        Calls ``wingphoto.io.save_bouguet_stereo(self.rig, path, uncertainty=self.uncertainty)``.
        """
        from .. import io

        return io.save_bouguet_stereo(self.rig, path, uncertainty=self.uncertainty, **kwargs)


def _compose_right(R_st, T_st, R_l, T_l):
    """Board pose in the right camera from its pose in the left camera and the rig."""
    return R_st @ R_l, R_st @ T_l + T_st


def _stereo_core(obs_l, obs_r, objs, init_l, init_r, om0, T0, poses0, est_l, est_r):
    P = len(objs)
    xl, Xl, vl, ml = _stack(obs_l, objs)
    xr, Xr, vr, mr = _stack(obs_r, objs)
    nL, nR = len(xl), len(xr)
    # residual order: pair by pair, [left rows of the pair, right rows of the pair]
    cl = np.bincount(vl, minlength=P)
    cr = np.bincount(vr, minlength=P)
    sl = np.concatenate([[0], np.cumsum(cl)])
    sr = np.concatenate([[0], np.cumsum(cr)])
    perm = []
    for p in range(P):
        perm.append(np.arange(2 * sl[p], 2 * sl[p + 1]))
        perm.append(2 * nL + np.arange(2 * sr[p], 2 * sr[p + 1]))
    perm = np.concatenate(perm)
    block = np.concatenate([[0], np.cumsum(2 * (cl + cr))])
    fl, fr = est_l.free, est_r.free
    nl, nr = int(fl.sum()), int(fr.sum())
    g0 = nl + nr  # om, T start
    e0 = g0 + 6  # poses start

    def unpack(p):
        il = est_l.unpack(p[:nl], init_l)
        ir = est_r.unpack(p[nl:g0], init_r)
        return il, ir, p[g0:g0 + 3], p[g0 + 3:e0], p[e0:].reshape(P, 6)

    def both(p):
        il, ir, om, T, E = unpack(p)
        R = _rodrigues_batch(E[:, :3])
        Rs = rodrigues(om)
        el = _project(il, _transform(R, E[:, 3:], vl, Xl)) - xl
        XL = _transform(R, E[:, 3:], vr, Xr)
        er = _project(ir, XL @ Rs.T + T) - xr
        return el, er

    def fun(p):
        el, er = both(p)
        return np.concatenate([el.ravel(), er.ravel()])[perm]

    m = 2 * (nL + nR)
    groups = [[j] for j in range(e0)] + [[e0 + 6 * v + k for v in range(P)] for k in range(6)]
    rows_of = {j: slice(None) for j in range(e0)}
    for v in range(P):
        for k in range(6):
            rows_of[e0 + 6 * v + k] = slice(block[v], block[v + 1])
    p0 = np.concatenate([init_l[fl], init_r[fr], om0, T0, np.asarray(poses0).ravel()])
    p, J = _solve(fun, p0, groups, rows_of, m)
    il, ir, om, T, E = unpack(p)
    el, er = both(p)
    el, er = -el, -er
    allres = np.concatenate([el, er])
    sigma = float(_std(allres.ravel()))
    cov = _covariance(J)
    perr = 3.0 * np.sqrt(np.abs(np.diag(cov))) * sigma
    errl, errr = np.zeros(10), np.zeros(10)
    errl[fl] = perr[:nl]
    errr[fr] = perr[nl:g0]
    if not est_l.aspect_ratio:
        errl[1] = errl[0]
    if not est_r.aspect_ratio:
        errr[1] = errr[0]

    def per_pair(e, masks, starts):
        out = []
        for v in range(P):
            r = np.full((len(masks[v]), 2), np.nan)
            r[masks[v]] = e[starts[v] : starts[v + 1]]
            out.append(r)
        return out

    # 1-sigma covariance of the rig parameters (board poses marginalised out: for a
    # Gaussian that is the sub-block), expanded to all 26 rig parameters, zero for fixed ones
    idx = np.concatenate([np.flatnonzero(fl), 10 + np.flatnonzero(fr), 20 + np.arange(6)])
    rig_cov = np.zeros((26, 26))
    sub = cov[:e0, :e0] * sigma**2
    rig_cov[np.ix_(idx, idx)] = 0.5 * (sub + sub.T)  # exactly symmetric; the diagonal is unchanged
    for off, est in ((0, est_l), (10, est_r)):
        if not est.aspect_ratio:  # fc[1] is fc[0]: fully correlated copy
            rig_cov[off + 1, :] = rig_cov[off, :]
            rig_cov[:, off + 1] = rig_cov[:, off]
    return {
        "il": il, "ir": ir, "om": om, "T": T, "E": E, "errl": errl, "errr": errr, "rig_cov": rig_cov,
        "om_error": perr[g0:g0 + 3], "T_error": perr[g0 + 3:e0], "E_error": perr[e0:].reshape(P, 6),
        "el": el, "er": er, "sigma": sigma, "res_l": per_pair(el, ml, sl), "res_r": per_pair(er, mr, sr),
    }


def _pair_names(views_l, views_r, names=None):
    if names is None:
        names = [f"{a.name} / {b.name}" if a.name != b.name else a.name for a, b in zip(views_l, views_r)]
    return tuple(_unique_names([str(n) for n in names]))


def _refine_rig_pose(om0, T0, mono_l, cam_r, obs_r, objs, used):
    """Fit (om, T) alone to the right images, cameras and left board poses held fixed.

    A cheap 6-parameter start for the joint refinement (fewer of its costly iterations).
    """
    x_obs, X, vid, _ = _stack(obs_r, objs)
    R = _rodrigues_batch(mono_l.omc[used])
    XL = _transform(R, mono_l.Tc[used], vid, X)
    intr = _intrinsics_vector(cam_r)

    def fun(p):
        return (_project(intr, XL @ rodrigues(p[:3]).T + p[3:]) - x_obs).ravel()

    groups = [[j] for j in range(6)]
    rows_of = {j: slice(None) for j in range(6)}
    p, _ = _solve(fun, np.concatenate([om0, T0]), groups, rows_of, 2 * len(x_obs))
    return p[:3], p[3:]


def _stereo_from_views(
    views_l, views_r, boards, size_l, size_r, est_l, est_r, pattern_size, square_size,
    threshold, pair_names, suppressed=(), locking=True, force=False, max_offset=3,
):
    from ..calibcheck import check_pairs, identical_pairs

    P = len(boards)
    views_l = [dataclasses.replace(v) for v in views_l]
    views_r = [dataclasses.replace(v) for v in views_r]
    # the same image given as left and right (e.g. one folder passed twice)
    same = [i for i in identical_pairs([v.corners for v in views_l], [v.corners for v in views_r])
            if i not in suppressed]
    both = [i for i in range(P) if i not in suppressed and views_l[i].corners is not None
            and views_r[i].corners is not None]
    if len(both) < _MIN_VIEWS:  # too few pairs anyway: the counting errors below say why
        same = []
    if same and len(same) == len(both):
        raise ValueError(
            f"the left and right images are identical in all {len(same)} pairs with the board in both "
            "(the same folder or files given for both cameras?); give each camera's own images"
        )
    # single-camera calibrations on every view each camera saw (suppressed and identical pairs excluded)
    mono_l = _calibrate_from_views(
        views_l, boards, size_l, est_l, pattern_size, square_size, set(suppressed) | set(same),
        what="left-camera views", locking=locking,
    )
    mono_r = _calibrate_from_views(
        views_r, boards, size_r, est_r, pattern_size, square_size, set(suppressed) | set(same),
        what="right-camera views", locking=locking,
    )
    # the corners as each camera's calibration used them (pixel-locking corrected)
    obs_l, obs_r = mono_l.corners, mono_r.corners
    reasons = {}
    for i in range(P):
        if i in suppressed:
            reasons[i] = "suppressed by the user"
            continue
        if i in same:
            reasons[i] = "left and right images identical (the same image given for both cameras)"
            continue
        bad = []
        for side, mono in (("left", mono_l), ("right", mono_r)):
            if not mono.used[i]:
                bad.append(f"{side} image {mono.views[i]}: {mono.rejected[mono.views[i]]}")
        if bad:
            reasons[i] = "; ".join(bad)
    cand = [i for i in range(P) if i not in reasons]
    if not cand:
        raise ValueError(
            "no pair has the board in both images. Rejected: "
            + "; ".join(f"{pair_names[i]}: {reasons[i]}" for i in range(P))
        )
    # stereo pose from the median of the per-pair relative poses (the toolbox's init), each
    # pair's consistency with it, and the diagnosis of pairs out of sync (wingphoto.calibcheck)
    check = check_pairs(mono_l, mono_r, boards, obs_r, cand, pair_names, max_offset=max_offset)
    if check.offset != 0:
        if not force:
            raise ValueError(check.message + "; or pass force=True (--force) to calibrate the pairs as given")
        logger.warning("%s (calibrating the pairs as given: force=True)", check.message)
    n_ok = int(check.table["consistent"].sum())
    if check.offset == 0 and n_ok < 0.5 * len(cand):
        msg = (f"only {n_ok} of {len(cand)} pairs agree on the rig pose: the left and right images do not look "
               "like simultaneous pairs (wrong order, different sessions, or a moving board)")
        if not force:
            raise ValueError(msg + "; pass force=True (--force) to calibrate the agreeing pairs anyway")
        logger.warning("%s (force=True)", msg)
    om0, T0 = check.om, check.T
    consistent = dict(zip(check.table["pair"], check.table["consistent"]))
    err_px = dict(zip(check.table["pair"], check.table["error_px"]))
    # inconsistent pairs: the toolbox's threshold on the initial errors, then the consistency check
    Rs = rodrigues(om0)
    cam_r = mono_r.camera
    used = []
    for i in cand:
        R, T = _compose_right(Rs, T0, rodrigues(mono_l.omc[i]), mono_l.Tc[i])
        pred = cam_r.project(boards[i] @ R.T + T)
        err = np.nanmax(np.abs(obs_r[i] - pred))
        if err > threshold:
            reasons[i] = (
                f"left and right views inconsistent (initial error {err:.1f} px > threshold "
                f"{threshold:g} px): the board moved between the exposures or the corners differ"
            )
        elif not consistent[pair_names[i]]:
            reasons[i] = (
                f"left and right views inconsistent with the other pairs (right-image RMS error "
                f"{err_px[pair_names[i]]:.2f} px > {check.tolerance_px:.2f} px from the rig pose of the other "
                "pairs): a wrong image in the pair, or the board moved between the two exposures"
            )
        else:
            used.append(i)
    if len(used) < _MIN_VIEWS:
        raise ValueError(
            f"only {len(used)} usable pairs (at least {_MIN_VIEWS} needed for stereo calibration). Rejected: "
            + "; ".join(f"{pair_names[i]}: {reasons[i]}" for i in sorted(reasons))
        )
    for i in sorted(reasons):
        level = logging.INFO if reasons[i] == "suppressed by the user" else logging.WARNING
        logger.log(level, "pair %s not used: %s", pair_names[i], reasons[i])
    om0, T0 = _refine_rig_pose(om0, T0, mono_l, cam_r, [obs_r[i] for i in used], [boards[i] for i in used], used)
    poses0 = np.column_stack([mono_l.omc[used], mono_l.Tc[used]])
    sol = _stereo_core(
        [obs_l[i] for i in used], [obs_r[i] for i in used], [boards[i] for i in used],
        _intrinsics_vector(mono_l.camera), _intrinsics_vector(mono_r.camera), om0, T0, poses0, est_l, est_r,
    )
    left = _camera_from_vector(sol["il"], size_l)
    right = _camera_from_vector(sol["ir"], size_r)
    rig = StereoRig(left, right, sol["om"], sol["T"])
    unc = {}
    for side, e in (("left", sol["errl"]), ("right", sol["errr"])):
        unc[f"fc_{side}"] = _frozen(e[0:2])
        unc[f"cc_{side}"] = _frozen(e[2:4])
        unc[f"alpha_c_{side}"] = _frozen(e[4:5])
        unc[f"kc_{side}"] = _frozen(e[5:10])
    unc["om"] = _frozen(sol["om_error"])
    unc["T"] = _frozen(sol["T_error"])
    om = np.full((P, 3), np.nan)
    T, ome, Te = om.copy(), om.copy(), om.copy()
    om[used], T[used] = sol["E"][:, :3], sol["E"][:, 3:]
    ome[used], Te[used] = sol["E_error"][:, :3], sol["E_error"][:, 3:]
    rl, rr = [None] * P, [None] * P
    for k, i in enumerate(used):
        rl[i], rr[i] = _frozen(sol["res_l"][k]), _frozen(sol["res_r"][k])
    mask = np.zeros(P, bool)
    mask[used] = True
    mask.setflags(write=False)
    allres = np.concatenate([sol["el"], sol["er"]])
    result = StereoCalibration(
        rig=rig, uncertainty=unc, pixel_error=_frozen(_std(allres, axis=0)),
        pixel_error_left=_frozen(_std(sol["el"], axis=0)), pixel_error_right=_frozen(_std(sol["er"], axis=0)),
        sigma=sol["sigma"], pairs=pair_names, used=mask,
        rejected={pair_names[i]: reasons[i] for i in sorted(reasons)},
        corners_left=tuple(obs_l), corners_right=tuple(obs_r),
        board_points=tuple(_frozen(b) for b in boards), residuals_left=tuple(rl), residuals_right=tuple(rr),
        omc_left=_frozen(om), Tc_left=_frozen(T), omc_left_error=_frozen(ome), Tc_left_error=_frozen(Te),
        mono_left=mono_l, mono_right=mono_r, pattern_size=tuple(pattern_size), square_size=tuple(square_size),
        covariance=_frozen(sol["rig_cov"]), parameter_names=RIG_PARAMETER_NAMES, pair_check=check,
        _inputs={
            "views_l": views_l, "views_r": views_r, "boards": boards, "size_l": size_l, "size_r": size_r,
            "est_l": est_l, "est_r": est_r, "pattern_size": pattern_size, "square_size": square_size,
            "threshold": threshold, "pair_names": pair_names, "suppressed": tuple(suppressed),
            "locking": locking, "force": force, "max_offset": max_offset,
        },
    )
    logger.info("stereo calibration: om=%s T=%s over %d pairs", rig.om, rig.T, len(used))
    return result


def calibrate_stereo(
    left_images, right_images, pattern_size, square_size, *, estimate_skew=False, estimate_k3=False,
    estimate_tangential=True, estimate_principal_point=True, estimate_aspect_ratio=True,
    board_points=None, image_size=None, names=None, regions=None, window=7, method="auto",
    correct_locking=True, threshold=50.0, suppress=(), progress=False, force=False, max_offset=3,
):
    """Calibrate a stereo rig from pairs of checkerboard views (the toolbox's stereo_gui).

    Parameters
    ----------
    left_images, right_images : sequence
        One entry per pair, taken at the same instant: image arrays, file paths,
        :class:`CornerDetection` or (N, 2) corner arrays (NaN rows for missing corners),
        as for :func:`calibrate_camera`. Images are only read.
    pattern_size : (2,) tuple of int
        (inner corners per row, inner corners per column), e.g. (9, 6).
    square_size : float or (2,)
        Side of a square in mm.
    estimate_skew, estimate_k3, estimate_tangential, estimate_principal_point, estimate_aspect_ratio : bool
        Which intrinsics are estimated, for both cameras (see :func:`calibrate_camera`).
    board_points : (N, 3) array_like or list of them, optional
        Board coordinates (mm) matching the corners (default from the pattern).
    image_size : (width, height), optional
        Required when only corners are given (both cameras the same size).
    names : sequence of str, optional
        Pair names (default "left01.jpg / right01.jpg" or "pair i").
    regions : dict, optional
        ``{pair index or name: {"rows": ..., "cols": ...}}``: restrict a pair to a
        sub-rectangle of the board, applied identically to both views.
    window, method :
        Corner detection options (see :func:`find_corners`).
    correct_locking : bool, optional
        Remove the corner detector's pixel-locking bias per camera (default True; see
        :func:`calibrate_camera`).
    threshold : float, optional
        A pair whose largest initial right-image error exceeds this many pixels is
        rejected as inconsistent (the toolbox's 50 px).
    suppress : sequence of int or str, optional
        Pairs to leave out.
    progress : bool, optional
        Show progress bars while detecting corners.
    force : bool, optional
        Calibrate even when the pairs look out of sync (a constant pairing offset, or
        fewer than half the pairs agreeing on the rig pose); default False raises.
        Identical left and right images are refused regardless.
    max_offset : int, optional
        Largest pairing offset (in pairs) tried when diagnosing pairs out of sync
        (default 3).

    Returns
    -------
    StereoCalibration
        ``.rig`` (StereoRig), ``.uncertainty`` (3 sigma for every intrinsic and om, T),
        ``.pixel_error``, per-pair residuals, ``.summary()`` in the toolbox's stereo
        layout, ``.save(path)``.

    Raises
    ------
    ValueError
        Different numbers of left and right views, fewer than 3 usable pairs (naming
        every rejected view and why), images of different sizes within a camera, an
        invalid ``pattern_size``; the same images given for both cameras; pairs out of
        sync (the message gives the offset found and how to re-pair the images) unless
        ``force``.

    Notes
    -----
    Each camera is first calibrated alone (:func:`calibrate_camera`, every view where
    it saw the board); the rig's ``(om, T)`` starts at the median of the per-pair
    relative poses; then both cameras' intrinsics, ``om``, ``T`` and the board pose in
    the left camera for every pair are refined together by
    :func:`scipy.optimize.least_squares` (the toolbox's ``go_calib_stereo``), with the
    toolbox's uncertainties ``3 * sqrt(diag((J^T J)^-1)) * std(residuals)``. Only pairs
    with the board in both images enter the joint refinement.

    Bad pairs are refused (:mod:`wingphoto.calibcheck`): identical left and right
    images; a pair whose own rig pose (from its two board poses) disagrees with the
    others (right-image error above ``max(1 px, 8 x`` the median) is rejected and named
    in ``rejected``; a constant offset between the left and right sequences is found by
    re-pairing left ``i`` with right ``i + k`` (``|k| <= max_offset``) and reported with
    the fix. ``result.pair_check`` keeps the per-pair table;
    :func:`wingphoto.calibcheck.cross_validate` compares two halves of the pairs.
    """
    pattern_size = _check_pattern_size(pattern_size)
    square_size = _check_square_size(square_size)
    for nm, seq in (("left_images", left_images), ("right_images", right_images)):
        if isinstance(seq, (str, os.PathLike)) or not hasattr(seq, "__len__"):
            raise ValueError(f"{nm} must be a sequence of images, paths or corner arrays, one per pair")
    if len(left_images) != len(right_images):
        raise ValueError(
            f"left_images has {len(left_images)} views but right_images has {len(right_images)}; "
            "give one left and one right image per board position, in the same order"
        )
    n = pattern_size[0] * pattern_size[1]
    if board_points is not None and not (isinstance(board_points, np.ndarray) and board_points.ndim == 2):
        first = next((b for b in board_points if b is not None), None)
        if first is not None and np.ndim(first) == 2:
            n = np.shape(first)[0]
    if names is not None:
        names = [str(s) for s in names]
        if len(names) != len(left_images):
            raise ValueError(f"names has {len(names)} entries but there are {len(left_images)} pairs")
        if regions:
            regions = {names.index(k) if isinstance(k, str) and k in names else k: v for k, v in regions.items()}
    kw = dict(regions=regions, window=window, method=method, progress=progress)
    views_l = _gather_views(left_images, pattern_size, n, names=None, what="left_images", **kw)
    views_r = _gather_views(right_images, pattern_size, n, names=None, what="right_images", **kw)
    size_l = _image_size_of(views_l, image_size, "left")
    size_r = _image_size_of(views_r, image_size, "right")
    boards = _board_list(board_points, len(views_l), pattern_size, square_size)
    est = _Estimate(
        skew=bool(estimate_skew), k3=bool(estimate_k3), tangential=bool(estimate_tangential),
        principal_point=bool(estimate_principal_point), aspect_ratio=bool(estimate_aspect_ratio),
    )
    pair_names = _pair_names(views_l, views_r, names)
    if names is not None:
        for v, nm in zip(views_l, pair_names):
            v.name = f"{nm} (left)"
        for v, nm in zip(views_r, pair_names):
            v.name = f"{nm} (right)"
    drop = _select(suppress, list(pair_names), "pair")
    return _stereo_from_views(
        views_l, views_r, boards, size_l, size_r, est, est, pattern_size, square_size,
        float(threshold), pair_names, suppressed=drop, locking=bool(correct_locking), force=bool(force),
        max_offset=int(max_offset),
    )

