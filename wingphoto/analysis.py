"""Analysis of 3D marker points: distances, rigid-body length statistics, reference
stillness, stroke angle and stroke reversals.

Every function takes the 3D points either as the points DataFrame (``frame, point, X, Y,
Z`` in mm, left camera frame; ``docs/conventions.md``) or as a ``(T, N, 3)`` array (frame,
point, xyz); DataFrame inputs identify points by their ``point`` number, arrays by their
column index. Missing points are NaN and are skipped by the statistics (``n`` counts the
finite values).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

__all__ = [
    "points_to_array",
    "pairwise_distance",
    "length_statistics",
    "reference_stillness",
    "ReferenceStillness",
    "stroke_angle",
    "StrokeAngle",
    "find_reversals",
    "align_rigid",
    "tracking_error",
]

logger = logging.getLogger(__name__)

POINT_COLUMNS = ("frame", "point", "X", "Y", "Z")


# --------------------------------------------------------------------------- arrays
def points_to_array(points, *, frames=None, point_ids=None):
    """Pivot the points DataFrame into a ``(T, N, 3)`` array.

    Parameters
    ----------
    points : pandas.DataFrame
        Columns frame, point, X, Y, Z (mm); one row per (frame, point).
    frames : array_like of int, optional
        Frames to include, in this order; default all frames, sorted.
    point_ids : array_like of int, optional
        Points to include, in this order; default all points, sorted.

    Returns
    -------
    P : (T, N, 3) ndarray of float64
        ``P[t, k]`` is point ``point_ids[k]`` at frame ``frames[t]``; NaN when absent.
    frames : (T,) ndarray of int64
    point_ids : (N,) ndarray of int64

    Examples
    --------
    >>> df = pd.DataFrame({"frame": [0, 0, 1], "point": [0, 1, 1],
    ...                    "X": [0.0, 3.0, 3.0], "Y": 0.0, "Z": [0.0, 4.0, 4.0]})
    >>> P, frames, ids = points_to_array(df)
    >>> P.shape, P[1, 0].tolist()
    ((2, 2, 3), [nan, nan, nan])
    """
    if not isinstance(points, pd.DataFrame):
        raise ValueError(f"points must be the points DataFrame, got {type(points).__name__}")
    missing = [c for c in POINT_COLUMNS if c not in points.columns]
    if missing:
        raise ValueError(f"points lacks columns {missing}; expected frame, point, X, Y, Z (mm)")
    f = points["frame"].to_numpy(np.int64)
    p = points["point"].to_numpy(np.int64)
    frames = np.unique(f) if frames is None else np.asarray(frames, dtype=np.int64).reshape(-1)
    point_ids = np.unique(p) if point_ids is None else np.asarray(point_ids, dtype=np.int64).reshape(-1)
    key = pd.MultiIndex.from_arrays([f, p])
    if key.has_duplicates:
        dup = key[key.duplicated()][0]
        raise ValueError(
            f"points has several rows for frame {dup[0]}, point {dup[1]}; split the tests first "
            "(e.g. by a condition column)"
        )
    ti = pd.Index(frames).get_indexer(f)
    pi = pd.Index(point_ids).get_indexer(p)
    keep = (ti >= 0) & (pi >= 0)
    P = np.full((len(frames), len(point_ids), 3), np.nan)
    P[ti[keep], pi[keep]] = points.loc[keep, ["X", "Y", "Z"]].to_numpy(np.float64)
    return P, frames, point_ids


def _as_array(points, name="points"):
    """Return (P (T, N, 3), frames, point_ids, is_frame) from a DataFrame or an array."""
    if isinstance(points, pd.DataFrame):
        P, frames, ids = points_to_array(points)
        return P, frames, ids, True
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3:
        raise ValueError(
            f"{name} must be the points DataFrame or a (T, N, 3) array (frame, point, xyz), got shape {P.shape}"
        )
    return P, np.arange(P.shape[0], dtype=np.int64), np.arange(P.shape[1], dtype=np.int64), False


def _column(ids, point, name="point"):
    hit = np.flatnonzero(ids == point)
    if hit.size == 0:
        raise ValueError(f"{name} {point!r} is not in the points (points present: {ids.tolist()})")
    return int(hit[0])


# --------------------------------------------------------------------------- distances
def pairwise_distance(points, i, j):
    """Distance between points ``i`` and ``j`` in every frame.

    Parameters
    ----------
    points : pandas.DataFrame or (T, N, 3) array_like
        3D points in mm (see the module docstring).
    i, j : int
        Point numbers (DataFrame) or column indices (array).

    Returns
    -------
    distance : pandas.Series or (T,) ndarray
        mm; a Series indexed by frame for a DataFrame input. NaN where either point is
        missing.

    Examples
    --------
    >>> P = np.zeros((2, 2, 3)); P[:, 1] = [3.0, 4.0, 0.0]; P[1, 0] = np.nan
    >>> pairwise_distance(P, 0, 1).tolist()
    [5.0, nan]
    """
    P, frames, ids, is_frame = _as_array(points)
    a, b = _column(ids, i, "i"), _column(ids, j, "j")
    d = np.linalg.norm(P[:, a] - P[:, b], axis=1)
    if is_frame:
        return pd.Series(d, index=pd.Index(frames, name="frame"), name=f"distance_{i}_{j}")
    return d


def _pairs(pairs):
    arr = np.asarray(pairs)
    if arr.ndim == 1 and arr.size == 2:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
        raise ValueError(f"pairs must be a pair (i, j) or a list of pairs, got {pairs!r}")
    return [(int(a), int(b)) for a, b in arr]


def _split_conditions(points, condition):
    """Yield (condition, points) groups."""
    if isinstance(points, dict):
        if condition is not None:
            raise ValueError("give the conditions either as a dict of points or as condition=, not both")
        yield from points.items()
        return
    if condition is None:
        yield "all", points
        return
    if isinstance(condition, str):
        if not isinstance(points, pd.DataFrame) or condition not in points.columns:
            raise ValueError(f"condition={condition!r} must name a column of the points DataFrame")
        for value in pd.unique(points[condition]):
            yield value, points[points[condition] == value]
        return
    labels = np.asarray(condition)
    P, frames, ids, is_frame = _as_array(points)
    if labels.shape != (len(frames),):
        raise ValueError(
            f"condition must be None, a column name, or one label per frame ({len(frames)}), got shape {labels.shape}"
        )
    for value in pd.unique(labels):
        sel = labels == value
        if is_frame:
            yield value, points[points["frame"].isin(frames[sel])]
        else:
            yield value, P[sel]


def length_statistics(points, pairs, *, condition=None, nominal=None, ddof=1):
    """Statistics of point-to-point lengths per test condition (the thesis' Table 6).

    For a rigid body every frame should give the same length; the spread of the
    measured length is the 3D measurement error along that direction.

    Parameters
    ----------
    points : pandas.DataFrame, (T, N, 3) array_like, or dict
        3D points in mm; a dict ``{condition: points}`` gives one test per condition.
    pairs : (i, j) or sequence of (i, j)
        Point pairs whose distance is measured.
    condition : None, str or (T,) array_like
        None: a single condition ``"all"``; a column name of the DataFrame holding the
        test condition of each row (tests may reuse frame numbers); or one label per frame.
    nominal : float, optional
        Known length in mm (e.g. 53.2); adds ``nominal``, ``bias`` = mean - nominal and
        ``max_error`` = max |length - nominal|.
    ddof : int
        Delta degrees of freedom of ``std`` (1: sample standard deviation).

    Returns
    -------
    stats : pandas.DataFrame
        One row per (condition, pair): condition, i, j, n (finite frames), mean, std,
        min, max, range (mm) [, nominal, bias, max_error] [, expected_std].
        ``expected_std`` (mm) appears when the points carry per-point uncertainties
        (from ``triangulate_tracks(..., calibration=..., full_covariance=True)``): the
        frame-to-frame spread of the length the 2D tracking uncertainty predicts,
        ``sqrt(mean over frames of u^T (C_i + C_j) u)`` with ``u`` the unit direction
        i -> j and ``C`` the tracking-only 3D covariance (``cov_*_track``; else the
        total ``cov_*``; else the per-axis ``sigma_*`` whose ignored correlations make
        it approximate), to set beside the measured ``std``. The calibration's part is
        left out when separable: it biases a length the same way in every frame rather
        than spreading it.

    Examples
    --------
    >>> P = np.zeros((3, 2, 3)); P[:, 1, 0] = [53.0, 53.2, 53.4]
    >>> s = length_statistics(P, (0, 1), nominal=53.2)
    >>> s[["n", "mean", "min", "max", "range"]].round(3).values.tolist()
    [[3.0, 53.2, 53.0, 53.4, 0.4]]
    """
    if isinstance(ddof, bool) or not isinstance(ddof, (int, np.integer)) or ddof < 0:
        raise ValueError(f"ddof must be a whole number >= 0 (1: the sample standard deviation), got {ddof!r}")
    pairs = _pairs(pairs)
    rows = []
    for cond, pts in _split_conditions(points, condition):
        for i, j in pairs:
            d = np.asarray(pairwise_distance(pts, i, j), dtype=np.float64)
            d = d[np.isfinite(d)]
            n = d.size
            row = {
                "condition": cond,
                "i": i,
                "j": j,
                "n": n,
                "mean": d.mean() if n else np.nan,
                "std": d.std(ddof=ddof) if n > ddof else np.nan,
                "min": d.min() if n else np.nan,
                "max": d.max() if n else np.nan,
            }
            row["range"] = row["max"] - row["min"]
            expected = _expected_length_std(pts, i, j)
            if expected is not None:
                row["expected_std"] = expected
            if nominal is not None:
                row["nominal"] = float(nominal)
                row["bias"] = row["mean"] - float(nominal)
                row["max_error"] = np.abs(d - float(nominal)).max() if n else np.nan
            rows.append(row)
    columns = ["condition", "i", "j", "n", "mean", "std", "min", "max", "range"]
    if nominal is not None:
        columns += ["nominal", "bias", "max_error"]
    if any("expected_std" in r for r in rows):
        columns += ["expected_std"]
    out = pd.DataFrame(rows, columns=columns)
    return out.astype({"i": np.int64, "j": np.int64, "n": np.int64})


def _expected_length_std(points, i, j):
    """RMS over frames of the length sigma predicted by per-point covariances, or None without them."""
    from .uncertainty import covariance_array

    if not isinstance(points, pd.DataFrame):
        return None
    P, frames, ids = points_to_array(points)
    Cs = covariance_array(points, frames, ids)
    if Cs is None:
        return None
    a, b = _column(ids, i, "i"), _column(ids, j, "j")
    d = P[:, a] - P[:, b]
    with np.errstate(invalid="ignore", divide="ignore"):
        u = d / np.linalg.norm(d, axis=1, keepdims=True)
    var = np.einsum("ti,tij,tj->t", u, Cs[:, a] + Cs[:, b], u)
    var = var[np.isfinite(var)]
    return float(np.sqrt(var.mean())) if var.size else np.nan


# --------------------------------------------------------------------------- references
@dataclass(frozen=True)
class ReferenceStillness:
    """How far the static reference points moved during a test.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per reference: point, n (finite frames), max_displacement,
        rms_displacement (mm), valid (max_displacement <= tol_mm).
    displacement : (T, R) ndarray
        Distance of each reference from its rest position in every frame (mm).
    frames : (T,) ndarray of int64
    point_ids : (R,) ndarray of int64
    rest : (R, 3) ndarray
        Rest positions (mm, left camera frame).
    tol_mm : float
        The tolerance used (given, or derived from ``scatter_mm``).
    relative_to : str
    valid : bool
        True when every reference stayed within ``tol_mm``; a reference never seen
        cannot be checked and makes the test invalid.
    scatter_mm : float
        The references' own noise: the median distance a reference moves between
        consecutive frames in which it was seen (mm; NaN when no reference was seen in
        two consecutive frames).
    tol_derived : bool
        True when ``tol_mm`` was derived from ``scatter_mm`` (the default).
    """

    table: pd.DataFrame
    displacement: np.ndarray = field(repr=False)
    frames: np.ndarray = field(repr=False)
    point_ids: np.ndarray
    rest: np.ndarray = field(repr=False)
    tol_mm: float
    relative_to: str
    valid: bool
    scatter_mm: float = float("nan")
    tol_derived: bool = False

    def summary(self):
        """One line per reference and the verdict, as text."""
        how = (f" = {STILLNESS_NOISE_FACTOR:g} x the references' frame-to-frame scatter {self.scatter_mm:.2g} mm"
               if self.tol_derived else "")
        lines = [f"reference stillness (tolerance {self.tol_mm:.3g} mm{how}, from the {self.relative_to} position)"]
        for r in self.table.itertuples(index=False):
            lines.append(
                f"  point {r.point}: max {r.max_displacement:.3f} mm, rms {r.rms_displacement:.3f} mm "
                f"over {r.n} frames{'' if r.valid else '  <- moved'}"
            )
        lines.append("  test VALID" if self.valid else "  test INVALID: a reference moved (or was never seen)")
        return "\n".join(lines)


#: Default stillness tolerance, in units of the references' median frame-to-frame step.
STILLNESS_NOISE_FACTOR = 10.0
#: Smallest derived tolerance (mm): noiseless (synthetic) references still pass round-off.
_MIN_DERIVED_TOL_MM = 1e-6


def _frame_to_frame_scatter(R, seen):
    """Median distance (mm) a reference moves between consecutive frames where it was seen."""
    both = seen[1:] & seen[:-1]
    steps = np.linalg.norm(np.diff(R, axis=0), axis=2)[both]
    return float(np.median(steps)) if steps.size else float("nan")


def reference_stillness(points, reference_ids, *, tol_mm=None, relative_to="mean", min_frames=None):
    """Check that the static reference points did not move during a test.

    Parameters
    ----------
    points : pandas.DataFrame or (T, N, 3) array_like
        3D points in mm.
    reference_ids : sequence of int
        The static reference points (mount dots that must stay still).
    tol_mm : float, optional
        Largest displacement allowed; larger means the camera or the mount moved and the
        test is invalid. It must exceed the triangulation noise (a still point's maximum
        distance from its mean over T frames is ~3-4 times its 3D noise sigma). Default:
        derived from the references' own noise, :data:`STILLNESS_NOISE_FACTOR` (10) times
        their median frame-to-frame step (see Notes).
    relative_to : {"mean", "first"}
        Rest position: the NaN-aware mean position, or the first frame where the point
        was seen.
    min_frames : int, optional
        Frames a reference must be seen in for its stillness to count (default: 10, or
        all frames when fewer than 10 were recorded). A reference the tracker lost for
        most of the test proves nothing, so it makes the test invalid rather than
        passing it on one frame.

    Returns
    -------
    ReferenceStillness

    Notes
    -----
    The default tolerance comes from the data, so that it scales with the rig's real
    triangulation noise: a bump or a slow drift of a camera or the mount changes the
    references' positions over many frames but hardly their median frame-to-frame step,
    while noise sets both. With per-axis noise sigma, the median step is ~1-2.2 sigma
    (noise mostly in depth .. isotropic) and a still reference's largest excursion over
    thousands of frames ~4-5 sigma, so 10 median steps (~10-20 sigma) does not fail a still
    recording, and anything moving the references by more than that fails it. A fixed
    0.5 mm let a camera bumped by one pixel (0.19 mm on the sample rig) pass.

    Examples
    --------
    >>> P = np.zeros((4, 1, 3)); P[:, 0, 2] = [600.0, 600.1, 599.9, 600.0]
    >>> reference_stillness(P, [0], tol_mm=0.2).valid
    True
    >>> rng = np.random.default_rng(0)
    >>> P = 600 + rng.normal(0, 0.01, (60, 2, 3))     # two still references, 0.01 mm noise
    >>> still = reference_stillness(P, [0, 1])
    >>> still.valid, round(still.tol_mm, 2)
    (True, 0.22)
    >>> P[30:, :, 2] += 0.5                            # the camera is bumped at frame 30
    >>> reference_stillness(P, [0, 1]).valid
    False
    """
    if relative_to not in ("mean", "first"):
        raise ValueError(f"relative_to must be 'mean' or 'first', got {relative_to!r}")
    if tol_mm is not None:
        tol_mm = float(tol_mm)
        if not tol_mm > 0:
            raise ValueError(f"tol_mm must be a positive length in mm, got {tol_mm}")
    P, frames, ids, _ = _as_array(points)
    ref = np.asarray(reference_ids, dtype=np.int64).reshape(-1)
    if ref.size == 0:
        raise ValueError("reference_ids is empty: give the numbers of the static reference points")
    R = P[:, [_column(ids, r, "reference point") for r in ref]]  # (T, R, 3)
    seen = np.all(np.isfinite(R), axis=2)
    n = seen.sum(axis=0)
    scatter = _frame_to_frame_scatter(R, seen)
    derived = tol_mm is None
    if derived:
        tol_mm = max(STILLNESS_NOISE_FACTOR * scatter, _MIN_DERIVED_TOL_MM) if np.isfinite(scatter) else float("nan")
        if not np.isfinite(tol_mm):
            logger.warning("no reference was seen in two consecutive frames: their noise, and so the "
                           "tolerance, is unknown; the test cannot be validated (or give tol_mm)")
    rest = np.full((len(ref), 3), np.nan)
    for k in range(len(ref)):
        if n[k]:
            rest[k] = R[seen[:, k], k].mean(axis=0) if relative_to == "mean" else R[np.argmax(seen[:, k]), k]
    disp = np.linalg.norm(R - rest[None], axis=2)
    with np.errstate(invalid="ignore"):
        finite = np.where(seen, disp, np.nan)
        max_d = np.array([np.nanmax(finite[:, k]) if n[k] else np.nan for k in range(len(ref))])
        rms = np.array([np.sqrt(np.nanmean(finite[:, k] ** 2)) if n[k] else np.nan for k in range(len(ref))])
    if min_frames is None:
        min_frames = min(10, len(P))
    if not (np.isfinite(min_frames) and int(min_frames) >= 1):
        raise ValueError(f"min_frames must be a number of frames >= 1, got {min_frames}")
    valid = (n >= int(min_frames)) & (max_d <= tol_mm)
    for r, k in zip(ref, n):
        if 0 < k < int(min_frames):
            logger.warning("reference point %d seen in only %d frames (< min_frames=%d): test not validated",
                           r, k, int(min_frames))
    table = pd.DataFrame(
        {"point": ref, "n": n.astype(np.int64), "max_displacement": max_d, "rms_displacement": rms, "valid": valid}
    )
    for r in ref[n == 0]:
        logger.warning("reference point %d was never seen: the test cannot be validated", r)
    return ReferenceStillness(
        table=table,
        displacement=disp,
        frames=frames,
        point_ids=ref,
        rest=rest,
        tol_mm=tol_mm,
        relative_to=relative_to,
        valid=bool(valid.all()),
        scatter_mm=scatter,
        tol_derived=derived,
    )


# --------------------------------------------------------------------------- stroke angle
@dataclass(frozen=True)
class StrokeAngle:
    """Stroke angle of a flapping wing per frame.

    Attributes
    ----------
    frames : (T,) ndarray of int64
    angle_deg : (T,) ndarray
        Stroke angle in degrees: the leading-edge direction's angle in the stroke plane,
        measured from ``axis`` towards ``cross(normal, axis)``. NaN where too few markers
        were seen.
    elevation_deg : (T,) ndarray
        Deviation of the leading edge from the stroke plane, towards ``normal``.
    direction : (T, 3) ndarray
        Unit leading-edge direction (root to tip), left camera frame.
    normal : (3,) ndarray
        Unit normal of the stroke plane.
    axis : (3,) ndarray
        Unit in-plane direction of zero stroke angle (mid-stroke by default).
    """

    frames: np.ndarray
    angle_deg: np.ndarray
    elevation_deg: np.ndarray
    direction: np.ndarray = field(repr=False)
    normal: np.ndarray
    axis: np.ndarray

    def to_frame(self):
        """DataFrame with columns frame, angle_deg, elevation_deg."""
        return pd.DataFrame({"frame": self.frames, "angle_deg": self.angle_deg, "elevation_deg": self.elevation_deg})

    def summary(self):
        """Amplitude, range and stroke plane as text."""
        a = self.angle_deg[np.isfinite(self.angle_deg)]
        if a.size == 0:
            return "stroke angle: no frame with enough leading-edge markers"
        return (
            f"stroke angle over {a.size} frames: min {a.min():.2f} deg, max {a.max():.2f} deg, "
            f"peak-to-peak {np.ptp(a):.2f} deg; stroke plane normal {np.round(self.normal, 4).tolist()}, "
            f"max out-of-plane {np.nanmax(np.abs(self.elevation_deg)):.2f} deg"
        )


def _unit(v):
    n = np.linalg.norm(v)
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"cannot normalise the vector {v}: zero or not finite")
    return v / n


def stroke_angle(points, leading_edge_ids, *, root_id=None, hinge=None, stroke_plane=None):
    """Stroke angle per frame from the direction of the wing's leading edge.

    Parameters
    ----------
    points : pandas.DataFrame or (T, N, 3) array_like
        3D points in mm, left camera frame.
    leading_edge_ids : sequence of int
        Leading-edge markers, tip first (the wing numbering runs tip to root).
    root_id : int, optional
        A marker at the wing root (e.g. on the mount at the hinge); its position in each
        frame joins the leading-edge markers.
    hinge : (3,) array_like, optional
        Fixed hinge position in mm, used like ``root_id`` when no root marker exists.
    stroke_plane : None, (3,) normal, or (normal, axis)
        The stroke plane through the origin of directions, by its normal (and optionally
        the in-plane zero-angle axis). None fits it.

    Returns
    -------
    StrokeAngle

    Notes
    -----
    Definition. In each frame the leading-edge direction ``d`` is the principal axis (the
    least-squares line) of the leading-edge markers plus the root marker or hinge, oriented
    from the root towards the tip; with two points it is the unit vector root -> tip.

    The stroke plane is the plane swept by ``d``. Unless given, its normal ``n`` is the
    right singular vector with the smallest singular value of the (T, 3) matrix of
    directions (the plane through the origin closest to all of them, a PCA without
    centring), with its sign chosen so that its largest component is positive. The zero
    angle axis ``e1`` is the mean direction projected on the plane (mid-stroke), and
    ``e2 = n x e1``. Then::

        stroke angle  phi   = atan2(d . e2, d . e1)      (deg)
        elevation     theta = asin(d . n)                (deg, out of the stroke plane)

    The sign of a fitted plane is a convention; pass ``stroke_plane`` to fix it.
    This is the stroke and deviation of :func:`wingphoto.kinematics.wing_kinematics`
    (which also gives pitch, twist, camber, bending and sigmas; ``docs/kinematics.md``).

    Examples
    --------
    >>> phi = np.radians([-30.0, 0.0, 30.0])
    >>> tip = np.stack([100 * np.sin(phi), np.zeros(3), 100 * np.cos(phi)], axis=1)
    >>> P = np.stack([tip, np.zeros((3, 3))], axis=1)        # tip, root at the origin
    >>> s = stroke_angle(P, [0, 1], stroke_plane=[0.0, 1.0, 0.0])
    >>> np.round(s.angle_deg, 6).tolist()
    [-30.0, 0.0, 30.0]
    """
    from .kinematics import wing_kinematics

    le = np.asarray(leading_edge_ids, dtype=np.int64).reshape(-1)
    if root_id is None and hinge is None and le.size < 2:
        raise ValueError("give at least two leading_edge_ids, or a root_id or hinge with one leading-edge marker")
    if root_id is not None and hinge is not None:
        raise ValueError("give either root_id (a marker) or hinge (a fixed point), not both")
    frames = _as_array(points)[1]
    kin = wing_kinematics(points, leading_edge=le, root=root_id, hinge=hinge, stroke_plane=stroke_plane, sigma=False)
    angle = kin.loc[kin["quantity"] == "stroke", "value"].to_numpy(np.float64, copy=True)
    elevation = kin.loc[kin["quantity"] == "deviation", "value"].to_numpy(np.float64, copy=True)
    normal = np.asarray(kin.attrs["stroke_plane_normal"])
    axis = np.asarray(kin.attrs["stroke_plane_axis"])
    phi, theta = np.radians(angle), np.radians(elevation)
    D = (np.cos(theta) * np.cos(phi))[:, None] * axis + (np.cos(theta) * np.sin(phi))[:, None] * np.cross(normal, axis) \
        + np.sin(theta)[:, None] * normal
    return StrokeAngle(frames=frames, angle_deg=angle, elevation_deg=elevation, direction=D, normal=normal, axis=axis)


# --------------------------------------------------------------------------- reversals
def _parabola_vertex(y, k, half):
    """Sub-sample vertex of a least-squares parabola through y[k-half : k+half+1]."""
    lo, hi = max(k - half, 0), min(k + half + 1, len(y))
    s = np.arange(lo, hi) - k
    v = y[lo:hi]
    ok = np.isfinite(v)
    if ok.sum() < 3 or not (ok[s < 0].any() and ok[s > 0].any()):
        return 0.0, y[k]
    a, b, c = np.polyfit(s[ok], v[ok], 2)
    if a == 0:
        return 0.0, y[k]
    delta = -b / (2 * a)
    if abs(delta) > 1.0:  # the extremum is not at this sample: keep the sample
        return 0.0, y[k]
    return delta, c - b * b / (4 * a)


def find_reversals(angle, *, frames=None, window=5, prominence=None, min_separation=None):
    """Frames of stroke reversal: the extrema of the stroke angle, to a fraction of a frame.

    Parameters
    ----------
    angle : (T,) array_like, pandas.Series or StrokeAngle
        Stroke angle in degrees (a Series' index, or a StrokeAngle's frames, give the
        frame numbers).
    frames : (T,) array_like, optional
        Frame numbers of the samples; default ``0 .. T - 1`` (or as above).
    window : int
        Odd number of samples (>= 3) of the least-squares parabola fitted around each
        extremum; 3 is the classic three-point interpolation, more averages noise.
    prominence : float, optional
        Minimum prominence (deg) of an extremum; default 5 % of the angle's range, so
        noise wiggles are not reversals while a reversal near the start or end of a
        short recording (whose prominence is cut by the recording's end) still counts.
    min_separation : int, optional
        Minimum number of samples between two extrema of the same kind.

    Returns
    -------
    reversals : pandas.DataFrame
        Columns frame (float, sub-frame), angle_deg (interpolated extreme value), kind
        (``"max"`` or ``"min"``), sample (int, index of the extreme sample); sorted by
        frame. Extrema at the ends of the record are not reported.

    Notes
    -----
    Extrema are found with :func:`scipy.signal.find_peaks` on the angle (NaN gaps filled
    linearly for the search only). Around each, ``y(s) = a s^2 + b s + c`` is fitted to
    the ``window`` samples (``s`` = sample offset) and the vertex ``s* = -b / (2a)``,
    ``y* = c - b^2 / (4a)`` gives the sub-frame reversal time and angle.

    Examples
    --------
    >>> t = np.arange(200)
    >>> phi = 60 * np.sin(2 * np.pi * (t - 0.3) / 100)
    >>> find_reversals(phi)["frame"].round(2).tolist()
    [25.3, 75.3, 125.3, 175.3]
    """
    from scipy.signal import find_peaks

    if isinstance(angle, StrokeAngle):
        frames = angle.frames if frames is None else frames
        y = np.asarray(angle.angle_deg, dtype=np.float64)
    elif isinstance(angle, pd.Series):
        frames = angle.index.to_numpy() if frames is None else frames
        y = angle.to_numpy(np.float64)
    else:
        y = np.asarray(angle, dtype=np.float64)
    if y.ndim != 1:
        raise ValueError(f"angle must be one value per frame (T,), got shape {y.shape}")
    frames = np.arange(len(y), dtype=np.float64) if frames is None else np.asarray(frames, dtype=np.float64)
    if frames.shape != y.shape:
        raise ValueError(f"frames must have the angle's length {len(y)}, got {frames.shape}")
    window = int(window)
    if window < 3 or window % 2 == 0:
        raise ValueError(f"window must be an odd number of samples >= 3, got {window}")
    columns = ["frame", "angle_deg", "kind", "sample"]
    empty = pd.DataFrame({"frame": pd.Series(dtype=np.float64), "angle_deg": pd.Series(dtype=np.float64),
                          "kind": pd.Series(dtype=object), "sample": pd.Series(dtype=np.int64)})
    ok = np.isfinite(y)
    if ok.sum() < 3:
        return empty
    filled = np.interp(np.arange(len(y)), np.flatnonzero(ok), y[ok])
    if prominence is None:
        prominence = 0.05 * float(np.ptp(filled))
    if prominence <= 0:
        return empty
    kw = {"prominence": prominence}
    if min_separation is not None:
        kw["distance"] = int(min_separation)
    rows = []
    for kind, sign in (("max", 1.0), ("min", -1.0)):
        peaks, _ = find_peaks(sign * filled, **kw)
        for k in peaks:
            if not ok[k]:
                continue
            delta, value = _parabola_vertex(y, int(k), window // 2)
            frame = float(np.interp(k + delta, np.arange(len(y)), frames))
            rows.append((frame, float(value), kind, int(k)))
    if not rows:
        return empty
    out = pd.DataFrame(rows, columns=columns).sort_values("frame", kind="stable").reset_index(drop=True)
    return out.astype({"sample": np.int64})


def align_rigid(source, target):
    """Best rigid motion taking ``source`` points onto ``target`` (Kabsch / Umeyama).

    Used to separate the *shape* error of a reconstruction from a rigid offset of the
    whole scene: a stereo calibration error in the left camera's principal point moves
    every triangulated point together, which leaves lengths and angles intact.

    Parameters
    ----------
    source, target : (N, 3) array_like
        Corresponding points in mm; rows with NaN in either are ignored.

    Returns
    -------
    R : (3, 3) ndarray
    t : (3,) ndarray
        ``target ~ source @ R.T + t``.
    rms : float
        RMS distance (mm) after alignment over the finite rows.

    Examples
    --------
    >>> import numpy as np
    >>> P = np.random.default_rng(0).normal(size=(10, 3))
    >>> R, t, rms = align_rigid(P, P + [1.0, 2.0, 3.0])
    >>> np.round(t, 9).tolist(), rms < 1e-9
    ([1.0, 2.0, 3.0], True)
    """
    A = np.asarray(source, dtype=np.float64).reshape(-1, 3)
    B = np.asarray(target, dtype=np.float64).reshape(-1, 3)
    if A.shape != B.shape:
        raise ValueError(f"source and target must have the same shape, got {A.shape} and {B.shape}")
    ok = np.isfinite(A).all(axis=1) & np.isfinite(B).all(axis=1)
    if ok.sum() < 3:
        raise ValueError(f"align_rigid needs at least 3 finite point pairs, got {int(ok.sum())}")
    A, B = A[ok], B[ok]
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    t = cb - R @ ca
    rms = float(np.sqrt(np.mean(np.sum((A @ R.T + t - B) ** 2, axis=1))))
    return R, t, rms


def tracking_error(tracks, truth):
    """Attach the true position and the error to every tracked point.

    Parameters
    ----------
    tracks : pandas.DataFrame
        Tracks (camera, frame, point, x, y, status, ...), one or both cameras.
    truth : pandas.DataFrame
        True tracks in the same layout (``StereoSequence.truth_tracks``,
        ``data-samples/flapping/truth_tracks.csv``); NaN where the marker is not visible.

    Returns
    -------
    pandas.DataFrame
        ``tracks`` with ``x_true``, ``y_true`` and ``error_px`` (Euclidean, px; NaN where
        either position is missing) appended.
    """
    key = ["camera", "frame", "point"] if "camera" in tracks.columns and "camera" in truth.columns else ["frame", "point"]
    missing = [c for c in key + ["x", "y"] if c not in truth.columns]
    if missing:
        raise ValueError(f"truth lacks columns {missing}; expected a tracks-layout table")
    true = truth[key + ["x", "y"]].rename(columns={"x": "x_true", "y": "y_true"})
    out = tracks.merge(true, on=key, how="left")
    out["error_px"] = np.hypot(out["x"] - out["x_true"], out["y"] - out["y_true"])
    return out
