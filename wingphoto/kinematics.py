"""Wing kinematics and deformation per frame, the wing surface, and time on a stroke-phase grid.

* :func:`wing_kinematics` - stroke, deviation, geometric pitch along the span, twist,
  camber and spanwise bending per frame, as a tidy table with a 1-sigma per value;
  :func:`kinematic_reversals` - the sub-frame extrema (reversals) of each quantity.
* :func:`fit_wing_surface` - a smooth surface through the markers in the wing's own
  span/chord coordinates, sampled on a regular mesh per frame, with its fit residual
  (:class:`WingSurface`; :meth:`WingSurface.write` exports PLY/VTK meshes and a ParaView
  time series).
* :func:`stroke_phase`, :func:`interpolate`, :func:`resample_phase`,
  :func:`phase_average`, :func:`compare_interpolation` - the stroke phase from the
  reversals, resampling onto a phase grid (linear, cubic spline or cardinal spline, the
  DeLeon method), averaging over strokes with the spread, and the linear-vs-spline
  comparison at 12-24 and 100 frames per stroke.

Points are the points DataFrame (``frame, point, X, Y, Z`` mm, left camera frame) or a
``(T, N, 3)`` array; optional ``sigma_X, sigma_Y, sigma_Z`` columns (mm, from
:func:`wingphoto.triangulate.triangulate_tracks` with a calibration) give the kinematic
sigmas. Definitions, frames and sign conventions: ``docs/kinematics.md``.
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .analysis import _as_array, _column, _unit, find_reversals
from .uncertainty import covariance_array

__all__ = [
    "wing_kinematics",
    "kinematic_reversals",
    "kinematics_wide",
    "plot_kinematics",
    "fit_wing_surface",
    "WingSurface",
    "stroke_phase",
    "interpolate",
    "resample_phase",
    "phase_average",
    "compare_interpolation",
    "KINEMATIC_UNITS",
]

log = logging.getLogger(__name__)

#: Unit of each quantity of :func:`wing_kinematics` (``chord``: a fraction of the chord).
KINEMATIC_UNITS = {
    "stroke": "deg",
    "deviation": "deg",
    "pitch": "deg",
    "twist": "deg",
    "camber": "chord",
    "bending": "mm",
}
KIN_COLUMNS = ("frame", "quantity", "station", "value", "unit", "sigma")


# =========================================================================== geometry
def _span_directions(P, cols, root):
    """Unit root-to-tip direction (T, 3): principal axis of the leading-edge markers (+ root).

    The same definition as the original ``stroke_angle`` (tip first; oriented from the
    root, or the last leading-edge marker, towards the tip), vectorised over frames.
    """
    pts = P[:, cols]
    if root is not None:
        pts = np.concatenate([pts, root[:, None, :]], axis=1)
    ok = np.all(np.isfinite(pts), axis=2)
    n = ok.sum(axis=1)
    w = ok[..., None]
    z = np.where(w, pts, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = z.sum(axis=1) / n[:, None]
    c = np.where(w, pts - centre[:, None, :], 0.0)
    S = np.einsum("tki,tkj->tij", c, c)
    S = np.where(np.isfinite(S), S, 0.0)
    vals, vecs = np.linalg.eigh(S)
    d = vecs[:, :, -1]
    good = (n >= 2) & (np.sqrt(np.maximum(vals[:, -1], 0.0)) >= 1e-9)
    tip = P[:, cols[0]]
    r = root if root is not None else P[:, cols[-1]]
    tip_ok = np.all(np.isfinite(tip), axis=1)[:, None]
    r_ok = np.all(np.isfinite(r), axis=1)[:, None]
    ref = np.where(tip_ok, tip, centre) - np.where(r_ok, r, centre)
    bad_ref = ~np.all(np.isfinite(ref), axis=1) | (np.linalg.norm(np.nan_to_num(ref), axis=1) < 1e-12)
    if bad_ref.any():
        # ordered tip first: first seen minus last seen
        for t in np.flatnonzero(bad_ref & good):
            seen = pts[t][ok[t]]
            ref[t] = seen[0] - seen[-1]
    sign = np.where(np.sum(d * ref, axis=1) >= 0, 1.0, -1.0)
    D = d * sign[:, None]
    D[~good] = np.nan
    return D


def _stroke_frame(D, stroke_plane):
    """(normal, axis) of the stroke plane: given, or fitted to the span directions."""
    good = np.all(np.isfinite(D), axis=1)
    axis = None
    if stroke_plane is None:
        if good.sum() < 2:
            raise ValueError("fewer than two frames have a leading-edge direction: cannot fit the stroke plane")
        _, _, vt = np.linalg.svd(D[good], full_matrices=False)
        normal = vt[-1]
        normal = normal if normal[np.argmax(np.abs(normal))] > 0 else -normal
    else:
        sp = stroke_plane
        if isinstance(sp, (tuple, list)) and len(sp) == 2 and np.ndim(sp[0]) == 1:
            sp, axis = sp
        normal = np.asarray(sp, dtype=np.float64).reshape(-1)
        if normal.shape != (3,):
            raise ValueError(f"stroke_plane must be a (3,) normal or (normal, axis), got {stroke_plane!r}")
        normal = _unit(normal)
    if axis is None:
        if not good.any():
            raise ValueError("no frame has a leading-edge direction: cannot choose the zero-angle axis")
        axis = D[good].mean(axis=0)
    axis = np.asarray(axis, dtype=np.float64).reshape(3)
    axis = _unit(axis - (axis @ normal) * normal)
    return normal, axis


def _nunit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 1e-12, v / n, np.nan)


@dataclass
class _Layout:
    """Column indices of the marker roles and the constants fixed by the unperturbed data."""

    le: list
    te: list
    rows: list
    root_col: int | None
    hinge: np.ndarray | None
    normal: np.ndarray = None
    axis: np.ndarray = None
    chord_sign: float = 1.0
    radius: float = np.nan
    station: np.ndarray = None

    def root(self, P):
        if self.root_col is not None:
            return P[:, self.root_col]
        if self.hinge is not None:
            return np.broadcast_to(self.hinge, (P.shape[0], 3))
        return None


def _compute(P, lay, *, fix=False):
    """Every kinematic array of frames ``P`` (T, N, 3); ``fix`` sets the layout's constants."""
    root = lay.root(P)
    D = _span_directions(P, lay.le, root)
    if fix:
        lay.normal, lay.axis = _stroke_frame(D, lay._plane)
    n, e1 = lay.normal, lay.axis
    e2 = np.cross(n, e1)
    out = {
        "direction": D,
        "stroke": np.degrees(np.arctan2(D @ e2, D @ e1)),
        "deviation": np.degrees(np.arcsin(np.clip(D @ n, -1.0, 1.0))),
    }
    base = root if root is not None else P[:, lay.le[-1]]
    T = P.shape[0]
    # wing cross-section frame: h = stroke-plane normal made perpendicular to the span, t = h x d
    h = _nunit(n[None, :] - (D @ n)[:, None] * D)
    tdir = np.cross(h, D)
    nst = len(lay.te)
    chord = None
    if nst:
        c = P[:, lay.te] - P[:, lay.le]  # (T, S, 3) LE -> TE
        cp = c - np.sum(c * D[:, None, :], axis=2, keepdims=True) * D[:, None, :]
        ch_ = np.sum(cp * h[:, None, :], axis=2)
        ct_ = np.sum(cp * tdir[:, None, :], axis=2)
        if fix:
            med = np.nanmedian(ct_) if np.isfinite(ct_).any() else 1.0
            lay.chord_sign = 1.0 if med >= 0 else -1.0
        s = lay.chord_sign
        out["pitch"] = np.degrees(np.arctan2(s * ch_, s * ct_))
        chord = cp
    # spanwise station of each leading-edge marker (fraction of the outermost station's radius)
    r = np.sum((P[:, lay.le] - base[:, None, :]) * D[:, None, :], axis=2)  # (T, L)
    if fix:
        med_r = np.array([np.nanmedian(r[:, k]) if np.isfinite(r[:, k]).any() else np.nan for k in range(r.shape[1])])
        if lay.radius is None or not np.isfinite(lay.radius):
            lay.radius = float(np.nanmax(med_r)) if np.isfinite(med_r).any() else np.nan
        lay.station = med_r / lay.radius
    if nst >= 2:
        st = lay.station[:nst]
        if np.isfinite(st).sum() >= 2:
            k_out, k_in = int(np.nanargmax(st)), int(np.nanargmin(st))
            out["twist"] = out["pitch"][:, k_out] - out["pitch"][:, k_in]
    # camber per chord row (>= 3 markers): sagitta of the least-squares parabola / chord
    if lay.rows and any(len(rw) >= 3 for rw in lay.rows):
        cam = np.full((T, len(lay.rows)), np.nan)
        for k, rw in enumerate(lay.rows):
            if len(rw) < 3:
                continue
            Q = P[:, rw]  # (T, m, 3)
            cvec = Q[:, -1] - Q[:, 0]
            L = np.linalg.norm(cvec, axis=1)
            chat = _nunit(cvec)
            nw = _nunit(np.cross(D, chat))
            rel = Q - Q[:, :1]
            x = np.sum(rel * chat[:, None, :], axis=2)
            z = np.sum(rel * nw[:, None, :], axis=2)
            a = _quad_coef(x, z)
            a[~(np.isfinite(x[:, 0]) & np.isfinite(x[:, -1]))] = np.nan
            cam[:, k] = -a * L / 4.0
        out["camber"] = cam
    # spanwise bending: quadratic term of the leading edge's deflection along the wing normal,
    # as the deflection of the outermost marker from the tangent at the innermost one
    if chord is not None and len(lay.le) >= 3:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # frames without any chord: NaN
            mean_c = np.nanmean(chord, axis=1)
        nw = _nunit(np.cross(D, mean_c * lay.chord_sign))
        q = P[:, lay.le] - base[:, None, :]
        x = np.sum(q * D[:, None, :], axis=2)
        y = np.sum(q * nw[:, None, :], axis=2)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # frames without the edge: NaN
            fin = np.isfinite(y)
            span = np.nanmax(np.where(fin, x, np.nan), axis=1) - np.nanmin(np.where(fin, x, np.nan), axis=1)
        out["bending"] = _quad_coef(x, y) * span**2
    return out


def _quad_coef(x, y):
    """Leading coefficient of the least-squares parabola through each row's finite (x, y); (T,).

    NaN for rows with fewer than 3 finite points.
    """
    ok = np.isfinite(x) & np.isfinite(y)
    xs = np.where(ok, x, 0.0)
    ys = np.where(ok, y, 0.0)
    # centre and scale x per row for conditioning
    n = ok.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx = xs.sum(axis=1) / n
        sx = np.sqrt(np.where(ok, (xs - mx[:, None]) ** 2, 0.0).sum(axis=1) / n)
        u = np.where(ok, (xs - mx[:, None]) / sx[:, None], 0.0)
    w = ok.astype(float)
    A = np.stack([u**2 * w, u * w, w], axis=2)  # (T, m, 3)
    M = np.einsum("tmi,tmj->tij", A, A)
    b = np.einsum("tmi,tm->ti", A, ys)
    out = np.full(x.shape[0], np.nan)
    good = (n >= 3) & np.isfinite(sx) & (sx > 1e-12)
    if good.any():
        M_g = M[good]
        det = np.linalg.det(M_g)
        g2 = np.abs(det) > 1e-12
        idx = np.flatnonzero(good)[g2]
        if idx.size:
            sol = np.linalg.solve(M[idx], b[idx][..., None])[..., 0]
            out[idx] = sol[:, 0] / sx[idx] ** 2
    return out


def _quantities(out):
    """(name, (T, S) array or (T,) array) for the tidy table, in table order."""
    for name in ("stroke", "deviation", "pitch", "twist", "camber", "bending"):
        if name in out:
            yield name, out[name]


def _propagate(P, C, lay, base, step=1e-3):
    """First-order sigma of every quantity from the per-point 3D covariances ``C`` (T, N, 3, 3).

    Points are independent of each other; a point's three axes may be correlated.
    """
    cols = sorted(set(lay.le) | set(lay.te) | {c for rw in lay.rows for c in rw}
                  | ({lay.root_col} if lay.root_col is not None else set()))
    var = {k: np.zeros_like(np.asarray(v, dtype=float)) for k, v in _quantities(base)}
    unknown = {k: np.zeros(np.shape(v), bool) for k, v in var.items()}
    for j in cols:
        grads = []
        for a in range(3):
            Pp, Pm = P.copy(), P.copy()
            Pp[:, j, a] += step
            Pm[:, j, a] -= step
            hi, lo = _compute(Pp, lay), _compute(Pm, lay)
            g = {}
            for k in var:
                d = np.asarray(hi[k]) - np.asarray(lo[k])
                if k in ("stroke", "deviation", "pitch", "twist"):  # wrap-safe angle differences
                    d = (d + 180.0) % 360.0 - 180.0
                g[k] = np.where(np.isfinite(d), d / (2 * step), 0.0)
            grads.append(g)
        Cj = C[:, j]  # (T, 3, 3)
        cfin = np.all(np.isfinite(Cj), axis=(1, 2))
        Cz = np.where(cfin[:, None, None], Cj, 0.0)
        for k in var:
            G = np.stack([grads[a][k] for a in range(3)], axis=-1)  # (T[, S], 3)
            if G.ndim == 2:
                contrib = np.einsum("ta,tab,tb->t", G, Cz, G)
                used = np.any(G != 0, axis=-1)
                unknown[k] |= used & ~cfin
            else:
                contrib = np.einsum("tsa,tab,tsb->ts", G, Cz, G)
                used = np.any(G != 0, axis=-1)
                unknown[k] |= used & ~cfin[:, None]
            var[k] += contrib
    return {k: np.where(unknown[k] | ~np.isfinite(np.asarray(base[k], float)), np.nan, np.sqrt(np.maximum(v, 0.0)))
            for k, v in var.items()}


def _layout(ids, leading_edge, trailing_edge, chord_rows, root, hinge, span_mm, stroke_plane, P):
    le = np.asarray(leading_edge, dtype=np.int64).reshape(-1)
    if root is None and hinge is None and le.size < 2:
        raise ValueError("give at least two leading_edge markers, or a root marker or hinge with one")
    if root is not None and hinge is not None:
        raise ValueError("give either root (a marker) or hinge (a fixed point), not both")
    te = [] if trailing_edge is None else list(np.asarray(trailing_edge, dtype=np.int64).reshape(-1))
    if te and len(te) != len(le):
        raise ValueError(
            f"trailing_edge has {len(te)} markers but leading_edge has {len(le)}: give one trailing-edge marker "
            "per leading-edge station, tip first"
        )
    lay = _Layout(
        le=[_column(ids, int(p), "leading-edge point") for p in le],
        te=[_column(ids, int(p), "trailing-edge point") for p in te],
        rows=[[_column(ids, int(p), "chord_rows point") for p in rw] for rw in (chord_rows or ())],
        root_col=None if root is None else _column(ids, int(root), "root"),
        hinge=None,
    )
    if hinge is not None:
        hv = np.asarray(hinge, dtype=np.float64).reshape(-1)
        if hv.shape != (3,) or not np.all(np.isfinite(hv)):
            raise ValueError(f"hinge must be a finite (3,) point in mm, got {hinge!r}")
        lay.hinge = hv
    if span_mm is not None:
        if not float(span_mm) > 0:
            raise ValueError(f"span_mm must be a positive length in mm, got {span_mm!r}")
        lay.radius = float(span_mm)
    lay._plane = stroke_plane
    return lay


def wing_kinematics(points, *, leading_edge, trailing_edge=None, root=None, hinge=None, stroke_plane=None,
                    chord_rows=None, span_mm=None, sigma=None):
    """Stroke, deviation, pitch along the span, twist, camber and bending per frame.

    Parameters
    ----------
    points : pandas.DataFrame or (T, N, 3) array_like
        3D points in mm, left camera frame. A DataFrame with the 3D covariance columns
        (``triangulate_tracks(..., full_covariance=True)``: the tracking term
        ``cov_XX_track`` ... is used when present, else the total ``cov_XX`` ...) or
        the per-axis ``sigma_X, sigma_Y, sigma_Z`` (``_track`` preferred; 1-sigma, mm;
        correlations then ignored) gives every value its sigma.
    leading_edge : sequence of int
        Leading-edge markers, tip first (at least two, or one with ``root``/``hinge``).
    trailing_edge : sequence of int, optional
        Trailing-edge markers of the same spanwise stations, tip first: pitch per
        station, twist and bending.
    root : int, optional
        A marker at the wing root; joins the leading edge for the span axis.
    hinge : (3,) array_like, optional
        Fixed root (hinge) position, mm, when no root marker exists.
    stroke_plane : None, (3,) normal, or (normal, axis)
        The stroke plane; None fits it (see ``docs/kinematics.md``).
    chord_rows : sequence of sequence of int, optional
        Markers of each station from leading to trailing edge; rows of >= 3 markers give
        the camber.
    span_mm : float, optional
        Wing length; station = radius / span_mm. Default: the station's radius over the
        outermost station's (the outermost is 1).
    sigma : (T, N, 3) array_like or False, optional
        Per-axis 1-sigma of the points (mm), instead of the DataFrame's columns; False
        skips the propagation (the sigma column is NaN).

    Returns
    -------
    kinematics : pandas.DataFrame
        Tidy: frame, quantity (stroke, deviation, pitch, twist, camber, bending),
        station (span fraction for per-station quantities, NaN for whole-wing ones),
        value, unit (``deg``, ``chord``, ``mm``), sigma (1-sigma, same unit; NaN without
        point sigmas). ``attrs`` holds ``stroke_plane_normal`` and ``stroke_plane_axis``
        (lists).

    Raises
    ------
    ValueError
        Unknown marker numbers, mismatched edges, root and hinge both given, or too few
        frames to fit the stroke plane.

    Notes
    -----
    Definitions (``docs/kinematics.md``): the span axis ``d`` is the principal axis of
    the leading-edge markers plus the root, root to tip. Stroke ``phi = atan2(d.e2,
    d.e1)``, deviation ``theta = asin(d.n)`` with the stroke plane ``(n, e1, e2 = n x
    e1)``. Pitch at a station is the right-handed rotation about ``d`` of the chord
    (leading to trailing edge, made perpendicular to ``d``) from the stroke plane. Twist
    is the outermost station's pitch minus the innermost's. Camber is the sagitta of the
    least-squares parabola through a chord row over its chord length, positive towards
    ``d x chord``. Bending is the quadratic term of the leading edge's deflection along
    that normal, as a deflection at the outermost marker (mm). The sigma is the
    first-order propagation of the points' covariances, with the stroke plane held
    fixed and points independent of each other. That is right for the tracking term
    (independent per point, frame to frame); the calibration's error is common to all
    points and largely cancels in angles between nearby markers, so it is left out when
    the points carry the tracking term separately (it would be overstated if treated
    as independent per point).

    Examples
    --------
    >>> phi = np.radians([-30.0, 0.0, 30.0])
    >>> tip = np.stack([100 * np.sin(phi), np.zeros(3), 100 * np.cos(phi)], axis=1)
    >>> P = np.stack([tip, np.zeros((3, 3))], axis=1)
    >>> k = wing_kinematics(P, leading_edge=[0, 1], stroke_plane=[0.0, 1.0, 0.0])
    >>> k[k.quantity == "stroke"]["value"].round(6).tolist()
    [-30.0, 0.0, 30.0]
    """
    P, frames, ids, _ = _as_array(points)
    lay = _layout(ids, leading_edge, trailing_edge, chord_rows, root, hinge, span_mm, stroke_plane, P)
    base = _compute(P, lay, fix=True)
    C = None
    if sigma is False:
        C = None
    elif sigma is not None:
        S = np.asarray(sigma, dtype=np.float64)
        if S.shape != P.shape:
            raise ValueError(f"sigma must have the points' shape {P.shape}, got {S.shape}")
        C = np.zeros(P.shape + (3,))
        C[..., [0, 1, 2], [0, 1, 2]] = S**2
    elif isinstance(points, pd.DataFrame):
        C = covariance_array(points, frames, ids)
    sig = _propagate(P, C, lay, base) if C is not None else {}
    parts = []
    T = len(frames)
    st_le = lay.station
    for name, v in _quantities(base):
        v = np.asarray(v, dtype=np.float64)
        s = sig.get(name, np.full(v.shape, np.nan))
        if v.ndim == 1:
            parts.append(pd.DataFrame({"frame": frames, "quantity": name, "station": np.nan, "value": v,
                                       "unit": KINEMATIC_UNITS[name], "sigma": s}))
        else:
            if name == "camber":
                stn = np.array([np.nan if len(rw) == 0 else _row_station(rw, lay) for rw in lay.rows])
            else:
                stn = st_le[: v.shape[1]]
            for k in range(v.shape[1]):
                parts.append(pd.DataFrame({"frame": frames, "quantity": name, "station": np.full(T, stn[k]),
                                           "value": v[:, k], "unit": KINEMATIC_UNITS[name], "sigma": s[:, k]}))
    out = pd.concat(parts, ignore_index=True)
    out = out.astype({"frame": np.int64, "station": np.float64, "value": np.float64, "sigma": np.float64})
    out.attrs["stroke_plane_normal"] = lay.normal.tolist()
    out.attrs["stroke_plane_axis"] = lay.axis.tolist()
    return out


def _row_station(row_cols, lay):
    """Station of a chord row: that of its leading-edge marker when it is one, else NaN."""
    if row_cols[0] in lay.le:
        return float(lay.station[lay.le.index(row_cols[0])])
    return np.nan


def kinematics_wide(kin):
    """One column per quantity (and station), one row per frame: ``pitch@0.86`` etc.

    Parameters
    ----------
    kin : pandas.DataFrame
        The tidy table of :func:`wing_kinematics`.

    Returns
    -------
    pandas.DataFrame
        Indexed by frame.
    """
    label = kin["quantity"].where(kin["station"].isna(), kin["quantity"] + "@" + kin["station"].round(3).astype(str))
    return kin.assign(label=label).pivot_table(index="frame", columns="label", values="value", dropna=False,
                                               sort=False)


def plot_kinematics(kin, *, quantities=("stroke", "deviation", "pitch", "camber"), truth=None, axes=None):
    """Plot kinematic quantities against the frame, one panel each, stations as lines.

    Parameters
    ----------
    kin : pandas.DataFrame
        The tidy table of :func:`wing_kinematics`.
    quantities : sequence of str
    truth : dict of str -> (T,) array_like, optional
        True values per quantity (e.g. ``{"stroke": motion.kinematics["stroke_deg"]}``),
        drawn dashed.
    axes : sequence of matplotlib Axes, optional
        One per quantity; default a new figure with a 2-column grid.

    Returns
    -------
    ndarray of matplotlib Axes
    """
    import matplotlib.pyplot as plt

    quantities = list(quantities)
    if axes is None:
        rows = (len(quantities) + 1) // 2
        _, axes = plt.subplots(rows, 2, figsize=(11, 3.3 * rows), sharex=True, squeeze=False)
    axes = np.ravel(axes)
    for ax, q in zip(axes, quantities):
        sub = kin[kin["quantity"] == q]
        for st, g in sub.groupby(sub["station"].fillna(-1.0), sort=False):
            line, = ax.plot(g["frame"], g["value"], lw=1.2, label=None if st == -1.0 else f"station {st:.2f}")
            if g["sigma"].notna().any():
                ax.fill_between(g["frame"], g["value"] - 3 * g["sigma"], g["value"] + 3 * g["sigma"],
                                color=line.get_color(), alpha=0.2, lw=0)
        if truth is not None and q in truth:
            frames = np.sort(sub["frame"].unique())
            ax.plot(frames, np.asarray(truth[q])[: len(frames)], "k--", lw=0.8, label="truth")
        ax.set_title(q)
        ax.set_ylabel(sub["unit"].iloc[0] if len(sub) else "")
        if ax.get_legend_handles_labels()[1]:
            ax.legend(fontsize=7)
    for ax in axes[-2:]:
        ax.set_xlabel("frame")
    for ax in axes[len(quantities):]:
        ax.set_visible(False)
    return axes


def kinematic_reversals(kin, *, window=5, prominence=None):
    """Sub-frame extrema (reversals) of every quantity of a kinematics table.

    Parameters
    ----------
    kin : pandas.DataFrame
        The tidy table of :func:`wing_kinematics`.
    window, prominence
        As in :func:`wingphoto.analysis.find_reversals` (parabola over ``window``
        samples around each extremum).

    Returns
    -------
    pandas.DataFrame
        Columns quantity, station, frame (float, sub-frame), value, kind (max/min). A
        quantity whose range is within 3 times its median sigma (or rounding) is left
        out: it does not reverse.
    """
    rows = []
    for (q, st), g in kin.groupby(["quantity", kin["station"].fillna(-1.0)], sort=False):
        g = g.sort_values("frame")
        v = g["value"].to_numpy(float)
        if np.isfinite(v).sum() < 3:
            continue
        rng = float(np.nanmax(v) - np.nanmin(v))
        noise = float(np.nanmedian(g["sigma"])) if g["sigma"].notna().any() else 0.0
        if rng <= max(3.0 * noise, 1e-9 * (1.0 + float(np.nanmax(np.abs(v))))):
            continue  # a constant quantity (e.g. no twist) has no reversals, only rounding noise
        rev = find_reversals(g["value"].to_numpy(float), frames=g["frame"].to_numpy(float), window=window,
                             prominence=prominence)
        for r in rev.itertuples(index=False):
            rows.append((q, np.nan if st == -1.0 else st, r.frame, r.angle_deg, r.kind))
    return pd.DataFrame(rows, columns=["quantity", "station", "frame", "value", "kind"]).astype(
        {"station": np.float64, "frame": np.float64, "value": np.float64})


# ============================================================================ surface
@dataclass(frozen=True)
class WingSurface:
    """A smooth wing surface per frame, sampled on a regular span x chord mesh.

    Attributes
    ----------
    frames : (T,) ndarray of int64
    vertices : (T, V, 3) ndarray
        Mesh vertices in mm, left camera frame; NaN for frames without a fit.
    faces : (F, 3) ndarray of int64
        Triangles (vertex indices), the same for every frame.
    mesh_shape : (int, int)
        Samples along the span and along the chord (``V = span * chord``).
    residuals : pandas.DataFrame
        Per frame: frame, n (markers), rms, max (mm, marker distance to the surface
        along the wing normal), loo_rms (mm, leave-one-out: each marker predicted by the
        surface fitted without it).
    model : str
    """

    frames: np.ndarray
    vertices: np.ndarray = field(repr=False)
    faces: np.ndarray = field(repr=False)
    mesh_shape: tuple
    residuals: pd.DataFrame = field(repr=False)
    model: str

    def summary(self):
        """Fit residuals over all frames, as text."""
        r = self.residuals
        ok = r["n"] > 0
        return (f"wing surface ({self.model}, mesh {self.mesh_shape[0]}x{self.mesh_shape[1]}) on {int(ok.sum())} of "
                f"{len(r)} frames: median rms {r['rms'][ok].median():.3f} mm, worst max {r['max'][ok].max():.3f} mm, "
                f"median leave-one-out rms {r['loo_rms'][ok].median():.3f} mm")

    def write(self, folder, *, fmt="vtu", name="wing"):
        """Write one mesh per frame and a ParaView index (``.vtu.series`` / ``.pvd``).

        Parameters
        ----------
        folder : str or Path
        fmt : {"vtu", "vtp", "vtk", "ply"}
        name : str
            File stem: ``wing_000012.vtu`` ...

        Returns
        -------
        Path
            The ParaView index ``<name>.<fmt>.series`` (:func:`wingphoto.io.mesh.write_series`).
        """
        from .io.mesh import write_series

        items = []
        for t, f in enumerate(self.frames):
            v = self.vertices[t]
            if not np.all(np.isfinite(v)):
                continue
            items.append({"time": float(f), "vertices": v, "faces": self.faces, "name": f"{name}_{int(f):06d}.{fmt}"})
        return write_series(folder, items, name=name)


def _design(x, y, model):
    if model == "poly2":
        return np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])
    return np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y, x**3, x * x * y, x * y * y, y**3])


def _fit_eval(model, x, y, z, xq, yq, smoothing):
    """Fit z(x, y) and evaluate at (xq, yq); also return residuals and leave-one-out residuals."""
    if model == "tps":
        from scipy.interpolate import RBFInterpolator

        xy = np.column_stack([x, y])
        f = RBFInterpolator(xy, z, kernel="thin_plate_spline", smoothing=smoothing)
        res = z - f(xy)
        loo = np.empty_like(z)
        for i in range(len(z)):
            keep = np.arange(len(z)) != i
            fi = RBFInterpolator(xy[keep], z[keep], kernel="thin_plate_spline", smoothing=smoothing)
            loo[i] = z[i] - fi(xy[i : i + 1])[0]
        return f(np.column_stack([xq, yq])), res, loo
    A = _design(x, y, model)
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    res = z - A @ coef
    Hd = np.einsum("ij,ji->i", A, np.linalg.pinv(A))
    with np.errstate(divide="ignore", invalid="ignore"):
        loo = np.where(Hd < 1 - 1e-9, res / (1 - Hd), np.nan)
    return _design(xq, yq, model) @ coef, res, loo


def _mesh_faces(ns, nc):
    idx = np.arange(ns * nc).reshape(ns, nc)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)


def fit_wing_surface(points, *, leading_edge, trailing_edge, chord_rows=None, root=None, hinge=None,
                     wing_ids=None, model="poly2", mesh_shape=(21, 11), smoothing=0.0):
    """Fit a smooth surface through the wing markers in every frame and mesh it.

    Parameters
    ----------
    points : pandas.DataFrame or (T, N, 3) array_like
        3D points in mm, left camera frame.
    leading_edge, trailing_edge : sequence of int
        Markers of each spanwise station (tip first); they fix the wing frame and the
        meshed region.
    chord_rows : sequence of sequence of int, optional
        Further markers per station (all markers of the rows are fitted).
    root, hinge : optional
        As in :func:`wing_kinematics` (the span axis).
    wing_ids : sequence of int, optional
        Markers to fit; default every marker named above.
    model : {"poly2", "poly3", "tps"}
        Quadratic or cubic polynomial ``w(x, y)``, or a thin-plate spline (with
        ``smoothing``), in the wing frame.
    mesh_shape : (int, int)
        Samples along the span and along the chord.
    smoothing : float
        Smoothing of the thin-plate spline (0 interpolates the markers).

    Returns
    -------
    WingSurface

    Notes
    -----
    Wing frame per frame: origin at the root (or the innermost leading-edge marker),
    ``x`` the span axis ``d`` of :func:`wing_kinematics`, ``y`` the mean chord
    direction (leading to trailing edge) made perpendicular to ``x``, ``z = x x y``. The
    surface is ``z = w(x, y)`` fitted by least squares to the markers' wing-frame
    coordinates. The mesh spans the marked region: from the innermost to the outermost
    station along ``x`` and, at each ``x``, from the leading to the trailing edge
    (linearly interpolated between stations) along ``y``.
    """
    from .config import SURFACE_MODELS

    if model not in SURFACE_MODELS:
        raise ValueError(f"model must be one of {list(SURFACE_MODELS)}, got {model!r}")
    ns, nc = (int(v) for v in mesh_shape)
    if ns < 2 or nc < 2:
        raise ValueError(f"mesh_shape must be two sample counts >= 2, got {mesh_shape!r}")
    P, frames, ids, _ = _as_array(points)
    if trailing_edge is None or len(trailing_edge) < 2:
        raise ValueError("fit_wing_surface needs trailing_edge markers at >= 2 stations (same stations as leading_edge)")
    lay = _layout(ids, leading_edge, trailing_edge, chord_rows, root, hinge, None, None, P)
    base = _compute(P, lay, fix=True)
    D = base["direction"]
    named = set(lay.le) | set(lay.te) | {c for rw in lay.rows for c in rw}
    cols = sorted(named) if wing_ids is None else [_column(ids, p, "wing_ids point") for p in wing_ids]
    nmin = 6 if model in ("poly2", "tps") else 10
    T = len(frames)
    V = np.full((T, ns * nc, 3), np.nan)
    res_rows = []
    rootp = lay.root(P)
    for t in range(T):
        d = D[t]
        c = P[t, lay.te] - P[t, lay.le]
        c = c[np.all(np.isfinite(c), axis=1)]
        Q = P[t, cols]
        okq = np.all(np.isfinite(Q), axis=1)
        if not np.all(np.isfinite(d)) or len(c) == 0 or okq.sum() < nmin:
            res_rows.append((frames[t], int(okq.sum()), np.nan, np.nan, np.nan))
            continue
        y_ax = c.mean(axis=0)
        y_ax = _unit(y_ax - (y_ax @ d) * d)
        z_ax = np.cross(d, y_ax)
        o = rootp[t] if rootp is not None else P[t, lay.le[-1]]
        if not np.all(np.isfinite(o)):
            o = np.nanmean(Q[okq], axis=0)
        loc = (Q[okq] - o) @ np.column_stack([d, y_ax, z_ax])
        le_l = (P[t, lay.le] - o) @ np.column_stack([d, y_ax])
        te_l = (P[t, lay.te] - o) @ np.column_stack([d, y_ax])
        okst = np.all(np.isfinite(le_l), axis=1) & np.all(np.isfinite(te_l), axis=1)
        if okst.sum() < 2:
            res_rows.append((frames[t], int(okq.sum()), np.nan, np.nan, np.nan))
            continue
        xs = 0.5 * (le_l[okst, 0] + te_l[okst, 0])
        order = np.argsort(xs)
        xs = xs[order]
        xg = np.linspace(xs[0], xs[-1], ns)
        y0 = np.interp(xg, xs, le_l[okst, 1][order])
        y1 = np.interp(xg, xs, te_l[okst, 1][order])
        frac = np.linspace(0.0, 1.0, nc)
        X = np.repeat(xg, nc)
        Y = (y0[:, None] + (y1 - y0)[:, None] * frac[None, :]).ravel()
        Z, res, loo = _fit_eval(model, loc[:, 0], loc[:, 1], loc[:, 2], X, Y, smoothing)
        V[t] = o + np.column_stack([X, Y, Z]) @ np.vstack([d, y_ax, z_ax])
        res_rows.append((frames[t], int(okq.sum()), float(np.sqrt(np.mean(res**2))), float(np.max(np.abs(res))),
                         float(np.sqrt(np.nanmean(loo**2))) if np.isfinite(loo).any() else np.nan))
    resid = pd.DataFrame(res_rows, columns=["frame", "n", "rms", "max", "loo_rms"]).astype(
        {"frame": np.int64, "n": np.int64})
    V.setflags(write=False)
    return WingSurface(frames=frames, vertices=V, faces=_mesh_faces(ns, nc), mesh_shape=(ns, nc),
                       residuals=resid, model=model)


# =============================================================================== time
def stroke_phase(angle, frames=None, *, window=5, prominence=None):
    """Stroke phase (in cycles) of every frame from the reversals of the stroke angle.

    Parameters
    ----------
    angle : (T,) array_like or pandas.Series
        Stroke angle (deg); NaN where the wing was not seen (a partial view is fine).
    frames : (T,) array_like, optional
        Frame numbers (default the Series' index, or 0..T-1).
    window, prominence
        As in :func:`wingphoto.analysis.find_reversals`; an extremum whose ``window``
        samples are not all finite (the edge of an unseen stretch) is not a reversal.

    Returns
    -------
    phase : (T,) ndarray
        Cycles, increasing with time: an integer at every maximum of the stroke angle,
        integer + 0.5 at every minimum, linear in time between reversals and
        extrapolated with the nearest half-stroke's rate. ``phase % 1`` is the stroke
        phase in [0, 1).

    Raises
    ------
    ValueError
        Fewer than two reversals are seen: the phase cannot be measured (give it).

    Examples
    --------
    >>> t = np.arange(300)
    >>> ph = stroke_phase(60 * np.cos(2 * np.pi * (t - 10) / 100))
    >>> np.round(ph[[60, 110, 135]], 3).tolist()
    [0.5, 1.0, 1.25]
    """
    if isinstance(angle, pd.Series):
        frames = angle.index.to_numpy(float) if frames is None else frames
        y = angle.to_numpy(float)
    else:
        y = np.asarray(angle, dtype=np.float64).reshape(-1)
    frames = np.arange(len(y), dtype=np.float64) if frames is None else np.asarray(frames, dtype=np.float64)
    rev = find_reversals(y, frames=frames, window=window, prominence=prominence)
    half = int(window) // 2
    ok = np.isfinite(y)
    keep = [all(ok[max(k - half, 0) : k + half + 1]) and half <= k < len(y) - half for k in rev["sample"]]
    rev = rev[np.asarray(keep, bool)] if len(rev) else rev
    if len(rev) < 2:
        raise ValueError(
            f"only {len(rev)} stroke reversal(s) seen: the stroke phase cannot be measured from this stroke angle; "
            "give the phase (e.g. from the flapper's trigger) instead"
        )
    t_rev = rev["frame"].to_numpy(float)
    kinds = rev["kind"].to_numpy()
    ph = np.zeros(len(rev))
    ph[0] = 0.0 if kinds[0] == "max" else 0.5
    for k in range(1, len(rev)):
        step = 1.0 if kinds[k] == kinds[k - 1] else 0.5
        ph[k] = ph[k - 1] + step
    phase = np.interp(frames, t_rev, ph)
    lo, hi = frames < t_rev[0], frames > t_rev[-1]
    r0 = (ph[1] - ph[0]) / (t_rev[1] - t_rev[0])
    r1 = (ph[-1] - ph[-2]) / (t_rev[-1] - t_rev[-2])
    phase[lo] = ph[0] + (frames[lo] - t_rev[0]) * r0
    phase[hi] = ph[-1] + (frames[hi] - t_rev[-1]) * r1
    return phase


def _cardinal(t, y, tq, tension):
    n = len(t)
    m = np.empty(n)
    m[1:-1] = (1.0 - tension) * (y[2:] - y[:-2]) / (t[2:] - t[:-2])
    m[0] = (1.0 - tension) * (y[1] - y[0]) / (t[1] - t[0])
    m[-1] = (1.0 - tension) * (y[-1] - y[-2]) / (t[-1] - t[-2])
    k = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, n - 2)
    h = t[k + 1] - t[k]
    s = (tq - t[k]) / h
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * y[k] + h10 * h * m[k] + h01 * y[k + 1] + h11 * h * m[k + 1]


def interpolate(t, y, t_new, *, method="linear", tension=0.0):
    """Interpolate samples ``y(t)`` at ``t_new`` (NaN samples are skipped).

    Parameters
    ----------
    t, y : (K,) array_like
        Sample times (increasing) and values.
    t_new : array_like
        Query times; outside ``[t[0], t[-1]]`` the result is NaN.
    method : {"linear", "cubic", "cardinal"}
        Straight lines; a not-a-knot cubic spline (:class:`scipy.interpolate.CubicSpline`);
        or a cardinal spline (cubic Hermite with tangents ``(1 - tension) (y[k+1] -
        y[k-1]) / (t[k+1] - t[k-1])``; tension 0 is the Catmull-Rom spline), DeLeon's
        method.
    tension : float
        Cardinal-spline tension in (-1, 1).

    Returns
    -------
    ndarray
        The shape of ``t_new``.

    Examples
    --------
    >>> interpolate([0, 1, 2, 3], [0, 1, 4, 9], [1.5], method="cardinal").round(3).tolist()
    [2.25]
    """
    from .config import INTERPOLATIONS

    if method not in INTERPOLATIONS:
        raise ValueError(f"method must be one of {list(INTERPOLATIONS)}, got {method!r}")
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    if t.shape != y.shape:
        raise ValueError(f"t and y must have the same length, got {t.shape} and {y.shape}")
    tq = np.asarray(t_new, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(y)
    t, y = t[ok], y[ok]
    out = np.full(tq.shape, np.nan)
    if len(t) < 2:
        return out
    if np.any(np.diff(t) <= 0):
        raise ValueError("t must increase strictly (sort the samples, drop duplicates)")
    inside = (tq >= t[0]) & (tq <= t[-1])
    q = tq[inside]
    if method == "linear" or len(t) < 3:
        out[inside] = np.interp(q, t, y)
    elif method == "cubic":
        from scipy.interpolate import CubicSpline

        out[inside] = CubicSpline(t, y)(q)
    else:
        out[inside] = _cardinal(t, y, q, float(tension))
    return out


def resample_phase(values, phase, *, bins=100, method="linear", tension=0.0, frames=None):
    """Resample a time series onto a regular stroke-phase grid, stroke by stroke.

    Parameters
    ----------
    values : (T,) array_like or pandas.Series
        One value per frame (NaN where missing).
    phase : (T,) array_like
        Phase in cycles per frame (:func:`stroke_phase`), increasing.
    bins : int
        Grid samples per stroke: phases ``k / bins``.
    method, tension
        Time interpolation (:func:`interpolate`).
    frames : (T,) array_like, optional
        Frame numbers (the interpolation's time axis); default 0..T-1.

    Returns
    -------
    pandas.DataFrame
        Columns cycle (int), phase (in [0, 1)), frame (float, the time of that phase),
        value. Only grid points inside the observed frames; NaN where the data around
        the grid point are missing (a gap is not bridged by more than one frame).
    """
    y = np.asarray(values, dtype=np.float64).reshape(-1)
    ph = np.asarray(phase, dtype=np.float64).reshape(-1)
    if ph.shape != y.shape:
        raise ValueError(f"phase must have one value per frame ({len(y)}), got {ph.shape}")
    fr = np.arange(len(y), dtype=np.float64) if frames is None else np.asarray(frames, dtype=np.float64)
    if np.any(np.diff(ph) <= 0):
        raise ValueError("phase must increase with time (use stroke_phase)")
    bins = int(bins)
    if bins < 2:
        raise ValueError(f"bins must be >= 2, got {bins}")
    k0, k1 = int(np.ceil(ph[0] * bins)), int(np.floor(ph[-1] * bins))
    grid = np.arange(k0, k1 + 1) / bins
    tq = np.interp(grid, ph, fr)
    v = interpolate(fr, y, tq, method=method, tension=tension)
    # do not bridge gaps: the two frames around each grid point must be present
    fin = np.isfinite(y)
    j = np.clip(np.searchsorted(fr, tq, side="right") - 1, 0, len(fr) - 1)
    j1 = np.clip(j + 1, 0, len(fr) - 1)
    exact = np.isclose(fr[j], tq)
    v = np.where((fin[j] & (fin[j1] | exact)), v, np.nan)
    cyc = np.floor(grid + 1e-12).astype(np.int64)
    return pd.DataFrame({"cycle": cyc, "phase": np.round(grid - cyc, 12), "frame": tq, "value": v})


def phase_average(resampled, *, by=None):
    """Mean and spread over strokes at every phase of a resampled series.

    Parameters
    ----------
    resampled : pandas.DataFrame
        :func:`resample_phase` output (cycle, phase, value) and optionally grouping
        columns (e.g. quantity, station).
    by : list of str, optional
        Extra grouping columns.

    Returns
    -------
    pandas.DataFrame
        Columns [by...,] phase, mean, std (sample std over strokes), n (strokes).
    """
    keys = list(by or []) + ["phase"]
    g = resampled.groupby(keys, sort=True)["value"]
    out = pd.DataFrame({"mean": g.mean(), "std": g.std(ddof=1), "n": g.count()}).reset_index()
    return out.astype({"n": np.int64})


def compare_interpolation(truth, *, samples_per_stroke=(12, 24, 100), methods=("linear", "cubic", "cardinal"),
                          strokes=3, offset=0.137, dense=2000, tension=0.0):
    """Error of each time interpolation against a known signal, at several frame rates.

    The thesis argued that at ~100 frames per stroke linear interpolation between
    frames is adequate, where DeLeon's strobe method (12-24 images per stroke) needed
    cardinal splines. This samples ``truth`` at ``samples_per_stroke``, interpolates
    back onto a dense grid with each method and compares.

    Parameters
    ----------
    truth : callable
        ``truth(phase_in_cycles) -> values`` (e.g. the stroke angle of a synth wing:
        ``lambda c: wing.kinematics(c / wing.flap_hz)["stroke_deg"]``).
    samples_per_stroke : sequence of int
    methods : sequence of str
    strokes : int
        Strokes compared (the first and last half stroke are left out: no end effects).
    offset : float
        Phase of the first sample (cycles), so samples do not sit on the extrema.
    dense : int
        Comparison points per stroke.
    tension : float
        Cardinal-spline tension.

    Returns
    -------
    pandas.DataFrame
        Columns samples_per_stroke, method, rms_error, max_error (units of ``truth``).
    """
    rows = []
    q = np.linspace(0.5, strokes + 0.5, int(dense * strokes) + 1)
    yq = np.asarray(truth(q), dtype=np.float64)
    for n in samples_per_stroke:
        n = int(n)
        if n < 3:
            raise ValueError(f"samples_per_stroke must be >= 3, got {n}")
        ts = offset + np.arange(-2, int((strokes + 1) * n) + 3) / n
        ys = np.asarray(truth(ts), dtype=np.float64)
        for m in methods:
            e = interpolate(ts, ys, q, method=m, tension=tension) - yq
            rows.append((n, m, float(np.sqrt(np.mean(e**2))), float(np.max(np.abs(e)))))
    return pd.DataFrame(rows, columns=["samples_per_stroke", "method", "rms_error", "max_error"])
