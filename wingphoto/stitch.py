"""Stitch several tests, each seeing part of the stroke, into one full stroke.

The thesis could not see the whole 110 deg stroke from one camera placement and
recommended several tests (cameras or flapper moved between them) tied together by
reference points built into the flapper. :func:`stitch_tests` does that:

1. in each test the static references must have stayed still
   (:func:`wingphoto.analysis.reference_stillness`), else the test is refused;
2. each test's reference rest positions are fitted to the first test's by the
   least-squares rigid motion (Kabsch / Umeyama, :func:`wingphoto.analysis.align_rigid`),
   which needs at least 3 shared references and is refused when a reference's residual
   exceeds the tolerance (the references moved relative to each other between tests);
3. every point of every test is moved into the first test's frame, and each frame gets
   its stroke phase (from the stroke angle's reversals, or given), so the tests merge
   over phase into one stroke (:meth:`Stitched.phase_mean`).

3D points in mm; the result is in the first test's left camera frame.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .analysis import _as_array, align_rigid, reference_stillness

__all__ = ["stitch_tests", "Stitched"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Stitched:
    """Several tests in one frame, with their stroke phase.

    Attributes
    ----------
    points : pandas.DataFrame
        test (int, 0 = the first), frame, point, X, Y, Z (mm, the first test's frame),
        phase (cycles, see :func:`wingphoto.kinematics.stroke_phase`; NaN when unknown),
        stroke_phase (``phase % 1``), and any other columns of the inputs.
    rotations : (K, 3, 3) ndarray
    translations : (K, 3) ndarray
        Test ``k``'s points are ``X_first = R_k X_k + t_k``.
    residuals : pandas.DataFrame
        test, point (reference), residual (mm, distance after the rigid fit), n (frames
        the reference was seen in).
    rms : (K,) ndarray
        RMS reference residual per test, mm.
    reference_ids : tuple of int
    stroke : pandas.DataFrame or None
        test, frame, stroke_deg (in the common stroke plane), phase, stroke_phase; when
        the phase came from the stroke angle.
    """

    points: pd.DataFrame = field(repr=False)
    rotations: np.ndarray = field(repr=False)
    translations: np.ndarray = field(repr=False)
    residuals: pd.DataFrame = field(repr=False)
    rms: np.ndarray
    reference_ids: tuple
    stroke: pd.DataFrame = field(default=None, repr=False)

    def plot(self, *, ax=None):
        """Stroke angle against stroke phase, one colour per test: the assembled stroke.

        Returns
        -------
        matplotlib Axes
        """
        import matplotlib.pyplot as plt

        if self.stroke is None:
            raise ValueError("no stroke angle: stitch with leading_edge=... to plot the assembled stroke")
        if ax is None:
            _, ax = plt.subplots(figsize=(7, 4))
        for k, g in self.stroke.groupby("test"):
            ax.plot(g["stroke_phase"], g["stroke_deg"], ".", ms=3, label=f"test {k}")
        seen = self.stroke["stroke_deg"]
        ax.set_title(f"assembled stroke: {np.nanmin(seen):.0f} to {np.nanmax(seen):.0f} deg "
                     f"({np.nanmax(seen) - np.nanmin(seen):.0f} deg)")
        ax.set_xlabel("stroke phase (0 = the stroke angle's maximum)")
        ax.set_ylabel("stroke angle (deg)")
        ax.legend(fontsize=8)
        return ax

    def summary(self):
        """Per test: the rigid motion's size and the reference residuals, as text."""
        lines = [f"stitched {len(self.rms)} tests on references {list(self.reference_ids)}"]
        for k, (R, t) in enumerate(zip(self.rotations, self.translations)):
            ang = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
            r = self.residuals[self.residuals["test"] == k]
            ph = self.points.loc[self.points["test"] == k, "phase"]
            span = f"phase {np.nanmin(ph):.2f}..{np.nanmax(ph):.2f}" if ph.notna().any() else "phase unknown"
            lines.append(f"  test {k}: rotation {ang:.2f} deg, translation {np.linalg.norm(t):.2f} mm, reference "
                         f"residual rms {self.rms[k]:.3f} mm (max {r['residual'].max():.3f} mm), {span}")
        return "\n".join(lines)

    def phase_mean(self, *, bins=100, point_ids=None):
        """Mean position of each point per stroke-phase bin over all tests and strokes.

        Parameters
        ----------
        bins : int
            Bins per stroke; bin ``k`` covers phases ``[k, k + 1) / bins``.
        point_ids : sequence of int, optional
            Points to include (default all).

        Returns
        -------
        pandas.DataFrame
            phase (bin centre), point, X, Y, Z (mean, mm), std (RMS distance from the
            mean, mm), n (samples), tests (how many tests contributed).
        """
        p = self.points[self.points["stroke_phase"].notna()]
        if point_ids is not None:
            p = p[p["point"].isin(list(point_ids))]
        p = p.dropna(subset=["X", "Y", "Z"])
        b = np.minimum((p["stroke_phase"].to_numpy() * bins).astype(np.int64), bins - 1)
        p = p.assign(bin=b)
        g = p.groupby(["bin", "point"])
        mean = g[["X", "Y", "Z"]].mean()
        dev = p.merge(mean.add_suffix("_m").reset_index(), on=["bin", "point"], how="left")
        d2 = ((dev["X"] - dev["X_m"]) ** 2 + (dev["Y"] - dev["Y_m"]) ** 2 + (dev["Z"] - dev["Z_m"]) ** 2)
        std = np.sqrt(d2.groupby([dev["bin"], dev["point"]]).mean())
        out = mean.assign(std=std, n=g.size(), tests=g["test"].nunique()).reset_index()
        out.insert(0, "phase", (out.pop("bin") + 0.5) / bins)
        return out.astype({"point": np.int64, "n": np.int64, "tests": np.int64})


def _rest_positions(P, ids, refs):
    rest = np.full((len(refs), 3), np.nan)
    n = np.zeros(len(refs), np.int64)
    for k, r in enumerate(refs):
        hit = np.flatnonzero(ids == r)
        if hit.size == 0:
            continue
        X = P[:, hit[0]]
        ok = np.all(np.isfinite(X), axis=1)
        n[k] = ok.sum()
        if n[k]:
            rest[k] = X[ok].mean(axis=0)
    return rest, n


def _phase_from_others(phases, angles, frames, errors, n_bins=200):
    """Phase tests that saw no reversal (a mid-stroke view) against the others' stroke-angle curve.

    The flapping period comes from the phased tests; the unknown phase offset is the one
    that best matches the test's stroke angles to the phased tests' stroke angle as a
    function of phase (least squares over the overlapping angles, a grid search).
    """
    known = [k for k, p in enumerate(phases) if p is not None]
    if not known:
        k = min(errors)
        raise ValueError(f"test {k}: {errors[k]}") from None
    rates = [np.median(np.diff(phases[k]) / np.diff(frames[k])) for k in known]
    period = 1.0 / float(np.median(rates))
    ph = np.concatenate([np.mod(phases[k], 1.0) for k in known])
    an = np.concatenate([angles[k] for k in known])
    ok = np.isfinite(an)
    b = np.minimum((ph[ok] * n_bins).astype(int), n_bins - 1)
    ref = np.full(n_bins, np.nan)
    for i in range(n_bins):
        v = an[ok][b == i]
        if v.size:
            ref[i] = v.mean()
    for k in errors:
        a, f = angles[k], np.asarray(frames[k], float)
        seen = np.isfinite(a)
        if seen.sum() < 3:
            raise ValueError(f"test {k}: {errors[k]}") from None
        best = None
        for off in np.linspace(0.0, 1.0, 4 * n_bins, endpoint=False):
            pk = np.mod(f[seen] / period + off, 1.0)
            r = ref[np.minimum((pk * n_bins).astype(int), n_bins - 1)]
            m = np.isfinite(r)
            if m.sum() < max(3, 0.3 * seen.sum()):
                continue
            cost = float(np.mean((a[seen][m] - r[m]) ** 2))
            if best is None or cost < best[0]:
                best = (cost, off)
        if best is None:
            raise ValueError(
                f"test {k}: {errors[k]} (and its stroke angles do not overlap the other tests' to phase it)"
            ) from None
        log.info("test %d saw no stroke reversal: phased against the other tests (rms %.2f deg)", k, np.sqrt(best[0]))
        phases[k] = f / period + best[1]


def stitch_tests(tests, reference_ids, *, phase=None, leading_edge=None, root=None, hinge=None, stroke_plane=None,
                 tol_mm=0.5, stillness_tol_mm=None):
    """Bring several tests into the first test's frame by their static references.

    Parameters
    ----------
    tests : sequence of pandas.DataFrame
        Points tables (frame, point, X, Y, Z mm), one per test, each in its own
        capture's left camera frame; point numbers shared between tests.
    reference_ids : sequence of int
        The static reference points (at least 3 seen in both the first test and each
        other test).
    phase : sequence of (T_k,) array_like, optional
        Stroke phase (cycles) of every frame of each test (in the order of its sorted
        frames), e.g. from the flapper's trigger. Default: from the stroke angle's
        reversals (needs ``leading_edge``); a test that sees no reversal (a mid-stroke
        view) is phased by matching its stroke angles to the other tests' stroke angle
        over phase, with their flapping period.
    leading_edge : sequence of int, optional
        Leading-edge markers (tip first) for the stroke angle.
    root, hinge, stroke_plane : optional
        As in :func:`wingphoto.kinematics.wing_kinematics` (``hinge`` in the first
        test's frame). The stroke plane is fitted to all tests together unless given.
    tol_mm : float
        Largest residual of a reference after the rigid fit, mm (default 0.5).
    stillness_tol_mm : float, optional
        Tolerance of the within-test stillness check (default ``tol_mm``).

    Returns
    -------
    Stitched

    Raises
    ------
    ValueError
        No tests; a test whose references moved during it; fewer than 3 references
        shared with the first test; a reference residual above ``tol_mm`` after the
        fit (the message names the test and the reference); no phase can be measured.

    Notes
    -----
    The rigid motion minimises the squared distances between the references' rest
    positions (their mean over the test's frames) in the two tests (Kabsch 1976,
    Umeyama 1991, without scale).
    """
    from .kinematics import _span_directions, _stroke_frame, stroke_phase

    tests = list(tests)
    if not tests:
        raise ValueError("tests is empty: give a list of points DataFrames, one per test")
    refs = np.asarray(reference_ids, dtype=np.int64).reshape(-1)
    if refs.size < 3:
        raise ValueError(f"give at least 3 reference_ids (static references) to stitch tests, got {refs.tolist()}")
    still_tol = float(tol_mm if stillness_tol_mm is None else stillness_tol_mm)
    arrays, rests, counts = [], [], []
    for k, t in enumerate(tests):
        if not isinstance(t, pd.DataFrame):
            raise ValueError(f"tests[{k}] must be a points DataFrame (frame, point, X, Y, Z), got {type(t).__name__}")
        P, frames, ids, _ = _as_array(t)
        present = [int(r) for r in refs if r in ids]
        if present:
            still = reference_stillness(t, present, tol_mm=still_tol, min_frames=1)
            moved = still.table[~still.table["valid"]]
            if len(moved):
                r = moved.iloc[0]
                raise ValueError(
                    f"test {k}: reference {int(r['point'])} moved by up to {r['max_displacement']:.3f} mm during the test "
                    f"(tolerance {still_tol:g} mm): the test cannot be stitched; check the mount or leave the test out"
                )
        rest, n = _rest_positions(P, ids, refs)
        arrays.append((P, frames, ids))
        rests.append(rest)
        counts.append(n)
    K = len(tests)
    Rs, ts, res_rows, rms = np.zeros((K, 3, 3)), np.zeros((K, 3)), [], np.zeros(K)
    for k in range(K):
        shared = np.all(np.isfinite(rests[0]), axis=1) & np.all(np.isfinite(rests[k]), axis=1)
        if shared.sum() < 3:
            raise ValueError(
                f"test {k} shares {int(shared.sum())} reference(s) with test 0 ({refs[shared].tolist()}); at least 3 "
                "are needed for a rigid fit: keep three or more references in view in every test"
            )
        R, t, r = align_rigid(rests[k][shared], rests[0][shared])
        resid = np.linalg.norm(rests[k][shared] @ R.T + t - rests[0][shared], axis=1)
        worst = int(np.argmax(resid))
        if resid[worst] > tol_mm:
            raise ValueError(
                f"test {k}: reference {int(refs[shared][worst])} is {resid[worst]:.3f} mm off after the rigid fit to test 0 "
                f"(tolerance {tol_mm:g} mm): the references moved relative to each other between the tests; "
                "leave that reference out of reference_ids or the test out"
            )
        Rs[k], ts[k], rms[k] = R, t, r
        for rid, e, n in zip(refs[shared], resid, counts[k][shared]):
            res_rows.append((k, int(rid), float(e), int(n)))
    parts = []
    for k, t in enumerate(tests):
        X = t[["X", "Y", "Z"]].to_numpy(np.float64) @ Rs[k].T + ts[k]
        part = t.copy()
        part[["X", "Y", "Z"]] = X
        part.insert(0, "test", k)
        parts.append(part)
    # stroke phase per test
    phases = []
    if phase is not None:
        phase = list(phase)
        if len(phase) != K:
            raise ValueError(f"phase must hold one array per test ({K}), got {len(phase)}")
        for k, (ph, (P, frames, _)) in enumerate(zip(phase, arrays)):
            ph = np.asarray(ph, dtype=np.float64).reshape(-1)
            if ph.shape != frames.shape:
                raise ValueError(f"phase[{k}] must have one value per frame of test {k} ({len(frames)}), got {ph.shape}")
            phases.append(ph)
    elif leading_edge is not None:
        le = [int(v) for v in np.asarray(leading_edge).reshape(-1)]
        dirs, per = [], []
        for k, (P, frames, ids) in enumerate(arrays):
            Pa = P @ Rs[k].T + ts[k]
            cols = [int(np.flatnonzero(ids == p)[0]) for p in le if p in ids]
            if len(cols) < (1 if (root is not None or hinge is not None) else 2):
                raise ValueError(f"test {k} lacks the leading-edge markers {le}: cannot measure its stroke angle")
            rt = None
            if root is not None:
                rt = Pa[:, int(np.flatnonzero(ids == root)[0])]
            elif hinge is not None:
                rt = np.broadcast_to(np.asarray(hinge, dtype=np.float64), (len(frames), 3))
            D = _span_directions(Pa, cols, rt)
            dirs.append(D)
            per.append(D)
        normal, axis = _stroke_frame(np.concatenate(dirs), stroke_plane)
        e2 = np.cross(normal, axis)
        angles, errors = [], {}
        for k, D in enumerate(per):
            angle = np.degrees(np.arctan2(D @ e2, D @ axis))
            angles.append(angle)
            try:
                phases.append(stroke_phase(angle, arrays[k][1]))
            except ValueError as exc:
                phases.append(None)
                errors[k] = exc
        if errors:
            _phase_from_others(phases, angles, [a[1] for a in arrays], errors)
        stroke_rows = [pd.DataFrame({"test": k, "frame": arrays[k][1], "stroke_deg": angles[k], "phase": phases[k],
                                     "stroke_phase": np.mod(phases[k], 1.0)}) for k in range(K)]
    for k, part in enumerate(parts):
        if phases:
            lut = pd.Series(phases[k], index=arrays[k][1])
            ph = lut.reindex(part["frame"].to_numpy()).to_numpy()
        else:
            ph = np.full(len(part), np.nan)
        part["phase"] = ph
        part["stroke_phase"] = np.mod(ph, 1.0)
    points = pd.concat(parts, ignore_index=True)
    residuals = pd.DataFrame(res_rows, columns=["test", "point", "residual", "n"])
    stroke = None
    if phase is None and leading_edge is not None:
        stroke = pd.concat(stroke_rows, ignore_index=True)
    if not phases:
        log.info("no phase given and no leading_edge: the stitched points carry no stroke phase")
    return Stitched(points=points, rotations=Rs, translations=ts, residuals=residuals, rms=rms,
                    reference_ids=tuple(int(r) for r in refs), stroke=stroke)
