"""Experiment planner: where a camera placement loses the wing, and how well it measures it.

:func:`plan_views` takes a stereo rig and a wing motion (the synthetic wing's, or a
measured one) and reports, per frame and marker, whether both cameras see the marker,
how edge-on each sees it (foreshortening) and the 3D uncertainty expected from a given
2D tracking sigma (and optionally a calibration's covariance). :func:`plot_view_plan`
shows over the stroke where a placement loses the wing - the thesis' Figure 33 problem,
where the wing left the view near the ends of the 110 deg stroke - and
:func:`compare_placements` tabulates two or more placements side by side.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .camera import StereoRig

__all__ = ["plan_views", "ViewPlan", "compare_placements", "plot_view_plan", "plot_placements"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ViewPlan:
    """Visibility, foreshortening and expected 3D uncertainty of every marker and frame.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per (frame, point): frame, point, kind, in_left, in_right (projected
        inside the image by ``margin_px``, in front of the camera), cos_left, cos_right
        (|cos| of the angle between the marker's normal and the viewing ray: 1 face-on,
        0 edge-on; NaN without normals), visible (in both views and seen less obliquely
        than ``edge_on_deg`` in both), sigma_X, sigma_Y, sigma_Z (expected 1-sigma, mm)
        and sigma_max.
    frames : pandas.DataFrame
        One row per frame: frame, stroke_deg (true stroke angle when the motion has
        one, else NaN), visible_share (share of the wing markers visible), min_cos
        (most edge-on visible wing marker), sigma_median (median sigma_max over the
        visible wing markers, mm).
    edge_on_deg, margin_px, sigma_px : float
    label : str
    """

    table: pd.DataFrame = field(repr=False)
    frames: pd.DataFrame = field(repr=False)
    edge_on_deg: float
    margin_px: float
    sigma_px: float
    label: str = ""

    def summary(self):
        """Share of visible wing point-frames, frames losing markers, expected sigma, as text."""
        w = self.table[self.table["kind"] == "wing"]
        f = self.frames
        lost = f[f["visible_share"] < 1.0]
        vis = w[w["visible"]]
        text = (f"{self.label or 'placement'}: {100 * w['visible'].mean():.1f} % of wing point-frames visible in both "
                f"views; {len(lost)} of {len(f)} frames lose at least one wing marker")
        if f["stroke_deg"].notna().any() and len(lost):
            text += f" (stroke angles {lost['stroke_deg'].min():.0f} to {lost['stroke_deg'].max():.0f} deg)"
        if len(vis):
            text += (f"; expected 3D sigma (largest axis) median {vis['sigma_max'].median():.3f} mm, "
                     f"95th percentile {vis['sigma_max'].quantile(0.95):.3f} mm")
        return text


def _motion_arrays(motion):
    """(X (T, N, 3), normals or None, kinds (N,), stroke (T,) or None, frames (T,))."""
    from .analysis import points_to_array

    if hasattr(motion, "points3d") and hasattr(motion, "kinds"):
        X = np.asarray(motion.points3d, dtype=np.float64)
        Nrm = getattr(motion, "normals", None)
        kin = getattr(motion, "kinematics", None)
        stroke = None
        if isinstance(kin, dict) and "stroke_deg" in kin:
            stroke = np.asarray(kin["stroke_deg"], dtype=np.float64)
        elif getattr(motion, "stroke_angle_deg", None) is not None:
            stroke = np.asarray(motion.stroke_angle_deg, dtype=np.float64)
        return X, (None if Nrm is None else np.asarray(Nrm, float)), np.asarray(motion.kinds).astype(str), stroke, \
            np.arange(X.shape[0], dtype=np.int64)
    if isinstance(motion, pd.DataFrame):
        X, frames, ids = points_to_array(motion)
        Nrm = None
        if {"nX", "nY", "nZ"} <= set(motion.columns):
            nt = motion[["frame", "point", "nX", "nY", "nZ"]].rename(columns={"nX": "X", "nY": "Y", "nZ": "Z"})
            Nrm, _, _ = points_to_array(nt, frames=frames, point_ids=ids)
        kinds = np.full(len(ids), "wing")
        if "kind" in motion.columns:
            k = motion.drop_duplicates("point").set_index("point")["kind"]
            kinds = k.reindex(ids).fillna("wing").astype(str).to_numpy()
        return X, Nrm, kinds, None, frames
    raise ValueError(
        "motion must be a wingphoto.synth.wing_motion(...) / render_flapping(...) result or a points DataFrame "
        f"(frame, point, X, Y, Z[, nX, nY, nZ, kind]) in the rig's left camera frame; got {type(motion).__name__}"
    )


def plan_views(rig, motion, *, edge_on_deg=72.0, margin_px=3.0, sigma_px=0.1, calibration=None, label=""):
    """Predict, per frame and marker, what a camera placement sees and how precisely.

    Parameters
    ----------
    rig : StereoRig
        The placement (calibrated or planned), with ``image_size`` set.
    motion : WingMotion, StereoSequence or pandas.DataFrame
        The wing's motion in the rig's left camera frame:
        :func:`wingphoto.synth.wing_motion` (positions, normals and true kinematics),
        a rendered sequence, or a measured points table (normals as ``nX, nY, nZ``
        columns, optional ``kind`` column; without normals no foreshortening).
    edge_on_deg : float
        A marker seen more obliquely than this (angle between its normal and the
        viewing ray) is not measurable (default 72 deg, as in ``synth``).
    margin_px : float
        A marker's centre must project this far inside the image.
    sigma_px : float
        2D tracking sigma (px, per axis) for the expected 3D uncertainty.
    calibration : optional
        Anything :func:`wingphoto.uncertainty.calibration_covariance` takes, to include
        the calibration's uncertainty.
    label : str
        Name of the placement in summaries and plots.

    Returns
    -------
    ViewPlan
    """
    from .uncertainty import propagate_point_covariance

    if not isinstance(rig, StereoRig):
        raise ValueError(f"rig must be a wingphoto.StereoRig, got {type(rig).__name__}")
    for side in ("left", "right"):
        if getattr(rig, side).image_size is None:
            raise ValueError(f"rig.{side} has no image_size: set it (Camera(..., image_size=(w, h))) to plan views")
    X, Nrm, kinds, stroke, frames = _motion_arrays(motion)
    T, N = X.shape[:2]
    flat = X.reshape(-1, 3)
    xl, xr = rig.project(flat)
    Xr = flat @ rig.R.T + rig.T
    c_right = -rig.R.T @ rig.T

    def inside(p, cam, Z):
        w, h = cam.image_size
        with np.errstate(invalid="ignore"):
            return ((p[:, 0] >= margin_px - 0.5) & (p[:, 0] <= w - 0.5 - margin_px) & (p[:, 1] >= margin_px - 0.5)
                    & (p[:, 1] <= h - 0.5 - margin_px) & (Z > 0))

    in_l = inside(xl, rig.left, flat[:, 2])
    in_r = inside(xr, rig.right, Xr[:, 2])
    if Nrm is not None:
        nf = Nrm.reshape(-1, 3)
        with np.errstate(invalid="ignore", divide="ignore"):
            vl = flat / np.linalg.norm(flat, axis=1, keepdims=True)
            vr = (flat - c_right) / np.linalg.norm(flat - c_right, axis=1, keepdims=True)
        cos_l, cos_r = np.abs(np.sum(vl * nf, axis=1)), np.abs(np.sum(vr * nf, axis=1))
        lim = np.cos(np.radians(edge_on_deg))
        with np.errstate(invalid="ignore"):
            facing = (cos_l >= lim) & (cos_r >= lim)
    else:
        cos_l = cos_r = np.full(len(flat), np.nan)
        facing = np.ones(len(flat), bool)
    visible = in_l & in_r & facing & np.all(np.isfinite(flat), axis=1)
    res = propagate_point_covariance(xl, xr, rig, sigma_left=sigma_px, sigma_right=sigma_px, calibration=calibration)
    s = np.sqrt(np.clip(np.diagonal(res["cov"], axis1=1, axis2=2), 0.0, None))
    table = pd.DataFrame({
        "frame": np.repeat(frames, N), "point": np.tile(np.arange(N, dtype=np.int64), T),
        "kind": np.tile(kinds, T), "in_left": in_l, "in_right": in_r, "cos_left": cos_l, "cos_right": cos_r,
        "visible": visible, "sigma_X": s[:, 0], "sigma_Y": s[:, 1], "sigma_Z": s[:, 2], "sigma_max": s.max(axis=1),
    })
    wing = table[table["kind"] == "wing"]
    if len(wing) == 0:
        wing = table
    g = wing.groupby("frame")
    mc = wing.assign(c=np.fmin(wing["cos_left"], wing["cos_right"]).where(wing["visible"]))
    per = pd.DataFrame({
        "frame": frames,
        "stroke_deg": stroke if stroke is not None else np.full(T, np.nan),
        "visible_share": g["visible"].mean().reindex(frames).to_numpy(),
        "min_cos": mc.groupby("frame")["c"].min().reindex(frames).to_numpy(),
        "sigma_median": wing[wing["visible"]].groupby("frame")["sigma_max"].median().reindex(frames).to_numpy(),
    })
    return ViewPlan(table=table, frames=per, edge_on_deg=float(edge_on_deg), margin_px=float(margin_px),
                    sigma_px=float(sigma_px), label=str(label))


def compare_placements(*plans):
    """One row per placement: what it sees of the wing and how precisely.

    Parameters
    ----------
    *plans : ViewPlan

    Returns
    -------
    pandas.DataFrame
        label, visible_share (wing point-frames seen by both cameras), frames_complete
        (share of frames with every wing marker visible), stroke_seen_deg (range of the
        stroke angle over complete frames, when known), min_cos (most edge-on visible
        marker), sigma_median and sigma_p95 (mm, largest-axis sigma of visible wing
        markers).
    """
    rows = []
    for k, p in enumerate(plans):
        if not isinstance(p, ViewPlan):
            raise ValueError(f"compare_placements takes ViewPlan objects (plan_views), got {type(p).__name__}")
        w = p.table[p.table["kind"] == "wing"]
        vis = w[w["visible"]]
        f = p.frames
        comp = f[f["visible_share"] >= 1.0]
        seen = np.ptp(comp["stroke_deg"]) if comp["stroke_deg"].notna().any() else np.nan
        rows.append({
            "label": p.label or f"placement {k}",
            "visible_share": float(w["visible"].mean()),
            "frames_complete": float((f["visible_share"] >= 1.0).mean()),
            "stroke_seen_deg": float(seen),
            "min_cos": float(f["min_cos"].min()),
            "sigma_median": float(vis["sigma_max"].median()) if len(vis) else np.nan,
            "sigma_p95": float(vis["sigma_max"].quantile(0.95)) if len(vis) else np.nan,
        })
    return pd.DataFrame(rows)


def plot_view_plan(plan, *, ax=None):
    """Share of wing markers visible and expected sigma over the stroke for one placement.

    Parameters
    ----------
    plan : ViewPlan
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib Axes
        Visible share (left axis) and median expected sigma (right axis, mm) against the
        stroke angle (or the frame when the motion has none); frames that lose markers
        are shaded.
    """
    return plot_placements([plan], ax=ax)


def plot_placements(plans, *, ax=None):
    """Compare placements over the stroke: visible share and expected sigma (see :func:`plot_view_plan`)."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(7, 4))
    ax2 = ax.twinx()
    for k, p in enumerate(plans):
        f = p.frames
        use_stroke = f["stroke_deg"].notna().all()
        x = f["stroke_deg"] if use_stroke else f["frame"]
        color = f"C{k}"
        label = p.label or f"placement {k}"
        ax.plot(x, 100 * f["visible_share"], ".", color=color, label=f"{label}: visible %", ms=4)
        ax2.plot(x, f["sigma_median"], "x", color=color, ms=3, alpha=0.6, label=f"{label}: sigma")
        lost = f["visible_share"] < 1.0
        if lost.any():
            ax.plot(x[lost], np.full(int(lost.sum()), -5.0), "|", color=color, ms=8)
    ax.set_xlabel("stroke angle (deg)" if all(p.frames["stroke_deg"].notna().all() for p in plans) else "frame")
    ax.set_ylabel("wing markers visible in both views (%)")
    ax2.set_ylabel("expected 3D sigma, median (mm)")
    ax.set_ylim(-10, 105)
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title("where the placement loses the wing (ticks at -5 %: frames losing markers)")
    return ax
