"""The thesis' marker tracking (``NCC.m`` then ``trackcl.m``), non-interactive: the baseline.

:func:`track_thesis` reproduces what the thesis did, so that results and speed of
:func:`wingphoto.track.track_markers` can be compared with it on the same frames. It is
slow by design: every marker is searched over the whole frame in every frame.

``NCC.m``
    The user crops a subimage (template) around each marker in the first frame. Every
    frame is then searched with ``normxcorr2(template, frame)`` over the **whole image**
    with that **fixed** template; the marker's pixel-level position is the correlation
    peak minus the template size plus half the crop rectangle. When a point moves more
    than a few pixels between frames (``maxtravel``; 8-9 px in the thesis) the script
    stopped and asked the user to crop that marker again.
``trackcl.m``
    Each frame is filtered with ``bpass(I, 1, 10, 20)`` and the sub-pixel centre is
    ``cntrd(filtered, ceil(ncc_point), 9)``.

Here the re-crop prompt becomes a recorded event: the point is stopped (status ``'lost'``
from that frame on) unless a correction for it is supplied, in which case the template
is re-cropped there, as the user would have done.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from .centroid import _cntrd, bpass, matlab_round
from .ncc import FrameCorrelator

__all__ = ["track_thesis", "ThesisResult"]

logger = logging.getLogger(__name__)

TRACK_COLUMNS = ["camera", "frame", "point", "x", "y", "score", "status", "x_ncc", "y_ncc"]
EVENT_COLUMNS = ["frame", "point", "kind", "action", "x_prev", "y_prev", "x_ncc", "y_ncc",
                 "distance"]


@dataclass(frozen=True)
class ThesisResult:
    """What :func:`track_thesis` returns.

    Attributes
    ----------
    tracks : pandas.DataFrame
        One row per (frame, point): camera (str), frame, point (int64), x, y (float64,
        px: the ``cntrd`` sub-pixel centre, NaN when lost), score (the ``normxcorr2``
        peak value, NaN when lost or corrected), status (``'ok'``, ``'manual'`` at a
        correction, ``'lost'``), x_ncc, y_ncc (float64, px: the pixel-level
        ``normxcorr2`` match, the thesis' red "+"; NaN once a point is stopped).
    events : pandas.DataFrame
        One row per event, columns frame, point, kind, action, x_prev, y_prev, x_ncc,
        y_ncc, distance. ``kind``: ``'maxtravel'`` (the match moved more than
        ``maxtravel`` px: where ``NCC.m`` prompted for a re-crop; x_ncc, y_ncc is the
        rejected match; ``action`` ``'stopped'``, or ``'corrected'`` when a callable
        ``corrections`` answered), ``'recrop'`` (a supplied correction was used,
        ``action`` ``'corrected'``; x_ncc, y_ncc is the new crop centre), ``'cntrd_edge'`` (``cntrd`` silently drops
        guesses within ``1.5 * cntrd_size`` of the border) and ``'cntrd_empty'`` (the
        filtered window was all zero), both with ``action`` ``'lost_frame'``: that frame
        is lost, tracking goes on.
    n_frames, n_points : int
    camera : str
    """

    tracks: pd.DataFrame
    events: pd.DataFrame
    n_frames: int
    n_points: int
    camera: str

    def summary(self):
        """Counts of statuses and events, one line each."""
        n = max(self.n_frames * self.n_points, 1)
        st = self.tracks["status"].value_counts()
        ev = self.events["kind"].value_counts()
        lines = [
            f"track_thesis ({self.camera}): {self.n_frames} frames x {self.n_points} points",
            "status: " + ", ".join(f"{k} {v} ({100 * v / n:.1f}%)" for k, v in st.items()),
            "events: " + (", ".join(f"{k} {v}" for k, v in ev.items()) or "none"),
        ]
        return "\n".join(lines)


# --------------------------------------------------------------------------- input checks
def _frame_source(frames):
    """Return (get(i) -> 2-D array, n) without stacking the frames."""
    if isinstance(frames, np.ndarray):
        if frames.ndim != 3:
            raise ValueError(
                f"frames must be a (T, H, W) array or an image sequence, got an array of "
                f"shape {frames.shape}; convert colour frames to grey first"
            )
    elif not (hasattr(frames, "__len__") and hasattr(frames, "__getitem__")):
        raise ValueError(
            "frames must be a (T, H, W) array or a sequence from wingphoto.io.read_sequence "
            f"(indexable, with len), got {type(frames).__name__}"
        )
    n = len(frames)
    if n == 0:
        raise ValueError("frames is empty: nothing to track")
    return (lambda i: np.asarray(frames[i])), n


def _check_frame(img, i, shape):
    if img.ndim != 2:
        raise ValueError(
            f"frame {i} has shape {img.shape}; frames must be 2-D grey images (H, W)")
    if not (np.issubdtype(img.dtype, np.integer) or np.issubdtype(img.dtype, np.floating)):
        raise ValueError(f"frame {i} has dtype {img.dtype}; expected integer or float pixels")
    if shape is not None and img.shape != shape:
        raise ValueError(
            f"frame {i} has shape {img.shape} but frame 0 has {shape}; all frames of a "
            "sequence must have the same size")


def _parse_picks(picks, half_size):
    """(N, 4) float array x, y, half_w, half_h from clicks, an (N, 4) array or a picks table."""
    if isinstance(picks, pd.DataFrame):
        missing = [c for c in ("x", "y") if c not in picks.columns]
        if missing:
            raise ValueError(f"picks table lacks columns {missing}; expected point, x, y, "
                             "half_w, half_h (PickerState.to_frame)")
        df = picks.sort_values("point") if "point" in picks.columns else picks
        if "point" in df.columns and not np.array_equal(df["point"].to_numpy(),
                                                        np.arange(len(df))):
            raise ValueError("picks table points must be numbered 0 .. N-1 (one row each)")
        arr = np.column_stack([
            df["x"].to_numpy(np.float64), df["y"].to_numpy(np.float64),
            df["half_w"].to_numpy(np.float64) if "half_w" in df else np.full(len(df), np.nan),
            df["half_h"].to_numpy(np.float64) if "half_h" in df else np.full(len(df), np.nan),
        ])
    else:
        a = np.asarray(picks, dtype=np.float64)
        if a.ndim == 1 and a.shape[0] in (2, 4):
            a = a[None, :]
        if a.ndim != 2 or a.shape[1] not in (2, 4):
            raise ValueError(
                "picks must be an (N, 2) array of (x, y) clicks, an (N, 4) array of "
                "(x, y, half_w, half_h), or a picks table; got shape "
                f"{np.shape(picks)}")
        arr = np.full((a.shape[0], 4), np.nan)
        arr[:, : a.shape[1]] = a
    if len(arr) == 0:
        raise ValueError("picks is empty: give at least one marker position")
    bad = np.flatnonzero(~np.isfinite(arr[:, :2]).all(axis=1))
    if bad.size:
        raise ValueError(f"picks of points {bad.tolist()} are NaN/Inf; every marker needs a "
                         "frame-0 position (drop or place those points)")
    hw, hh = (half_size, half_size) if np.ndim(half_size) == 0 else half_size
    arr[np.isnan(arr[:, 2]), 2] = hw
    arr[np.isnan(arr[:, 3]), 3] = hh
    if np.any(arr[:, 2:] < 1) or not np.isfinite(arr[:, 2:]).all():
        raise ValueError("template half sizes (half_w, half_h) must be >= 1 px")
    return arr


def _crop(img, cx, cy, hw, hh, what):
    """Template rows cy-hh .. cy+hh, cols cx-hw .. cx+hw (MATLAB imcrop of [cx-hw cy-hh 2hw 2hh])."""
    H, W = img.shape
    if cx - hw < 0 or cy - hh < 0 or cx + hw > W - 1 or cy + hh > H - 1:
        inside = 0 <= cx <= W - 1 and 0 <= cy <= H - 1
        raise ValueError(
            f"{what} at (x={cx}, y={cy}) is "
            + ("too close to the image border" if inside else "outside the image")
            + f" ({W}x{H}) for its {2 * hw + 1}x{2 * hh + 1} px template; move it inside "
            "or give a smaller half size")
    return img[cy - hh: cy + hh + 1, cx - hw: cx + hw + 1]


def _parse_corrections(corrections, camera, n_points):
    """{frame: {point: (x, y)}} from Correction tuples / (point, frame, x, y) / a table."""
    out = {}
    if corrections is None:
        return out
    if isinstance(corrections, pd.DataFrame):
        missing = [c for c in ("point", "frame", "x", "y") if c not in corrections.columns]
        if missing:
            raise ValueError(f"corrections table lacks columns {missing}")
        rows = corrections.to_dict("records")
    else:
        rows = []
        for c in corrections:
            if hasattr(c, "_asdict"):
                rows.append(c._asdict())
            elif isinstance(c, dict):
                rows.append(c)
            elif len(c) == 5:
                rows.append(dict(zip(("camera", "point", "frame", "x", "y"), c)))
            elif len(c) == 4:
                rows.append(dict(zip(("point", "frame", "x", "y"), c)))
            else:
                raise ValueError(
                    f"correction {c!r} must be (camera, point, frame, x, y) or "
                    "(point, frame, x, y)")
    for r in rows:
        if "camera" in r and r["camera"] is not None and r["camera"] != camera:
            continue
        p, f = int(r["point"]), int(r["frame"])
        x, y = float(r["x"]), float(r["y"])
        if not (0 <= p < n_points):
            raise ValueError(f"correction for point {p}: there are only {n_points} points")
        if not (math.isfinite(x) and math.isfinite(y)) or f < 0:
            raise ValueError(f"correction (point {p}, frame {f}) needs finite x, y and frame >= 0")
        out.setdefault(f, {})[p] = (x, y)  # a later entry for the same key wins
    return out


def _peak(C):
    """MATLAB ``find(C == max(C(:)))``, first hit in column-major order, and the max."""
    k = int(np.argmax(C))  # first in row-major order
    mx = C.flat[k]
    if np.count_nonzero(C == mx) == 1:
        return k // C.shape[1], k % C.shape[1], float(mx)
    rows, cols = np.nonzero(C == mx)
    k = np.lexsort((rows, cols))[0]
    return int(rows[k]), int(cols[k]), float(mx)


# --------------------------------------------------------------------------- the tracker
def track_thesis(frames, picks, *, maxtravel=8, bpass_args=(1, 10, 20), cntrd_size=9,
                 corrections=None, half_size=10, camera="left", progress=True):
    """Track markers as the thesis did: ``NCC.m`` then ``trackcl.m``, without prompts.

    Parameters
    ----------
    frames : (T, H, W) ndarray or image sequence
        Grey frames (uint8, uint16 or float), e.g. ``wingphoto.io.read_sequence(...)``;
        read one at a time, never stacked.
    picks : (N, 2) array_like, (N, 4) array_like or pandas.DataFrame
        Frame-0 marker positions (x, y) in px (0-based, ``docs/conventions.md``), rounded
        to the pixel as a person clicks (MATLAB rounding, :func:`~wingphoto.centroid.matlab_round`).
        Each click becomes a crop rectangle of ``half_size`` around it, as the subimage
        the user cropped in ``NCC.m``. An (N, 4) array adds per-point ``half_w, half_h``;
        a table needs columns x, y and optionally point (0 .. N-1), half_w, half_h (the
        picker's :meth:`PickerState.to_frame <wingphoto.widgets.state.PickerState.to_frame>`).
    maxtravel : float, optional
        Largest move of the pixel-level match between consecutive frames, px (default 8).
        A larger move is where ``NCC.m`` asked for a re-crop: it is recorded as an event
        and the point is stopped, unless ``corrections`` re-crops it at that frame.
    bpass_args : (lnoise, lobject, threshold), optional
        :func:`~wingphoto.centroid.bpass` parameters (thesis: 1, 10, 20).
    cntrd_size : int, optional
        :func:`~wingphoto.centroid.cntrd` window diameter, odd (thesis: 9).
    corrections : iterable, pandas.DataFrame or callable, optional
        Re-crops, as the user would have made them at the prompts:
        :class:`~wingphoto.widgets.state.Correction` ``(camera, point, frame, x, y)``
        entries (other cameras' entries are ignored), ``(point, frame, x, y)`` tuples, or a
        table with those columns. At each, the template of ``point`` is cropped anew from
        that frame around the rounded (x, y), and a stopped point resumes.
        A callable ``corrections(frame, point) -> (x, y) or None`` plays the user at
        ``NCC.m``'s prompts instead: it is asked at every ``'maxtravel'`` event and its
        answer re-crops the point there (``None`` stops the point). With the ground
        truth as the answer this counts the prompts the thesis' user had to answer.
    half_size : int or (int, int), optional
        Template half width and height for picks without their own, px (default 10:
        21 x 21 templates). Non-integers are rounded (MATLAB rounding).
    camera : str, optional
        Camera name written to the tracks (default ``'left'``).
    progress : bool, optional
        Show a ``tqdm`` progress bar (default True).

    Returns
    -------
    ThesisResult
        ``.tracks`` (the tracks DataFrame, plus x_ncc, y_ncc), ``.events`` (the prompts
        NCC.m would have raised, the re-crops and the frames ``cntrd`` could not refine),
        ``.summary()``.

    Raises
    ------
    ValueError
        Empty ``frames`` or ``picks``; frames not 2-D or of differing size; a pick NaN,
        outside the image or too close to its border for its template; a constant
        template; a template larger than the image; bad ``corrections``; even
        ``cntrd_size``.

    Notes
    -----
    Per frame ``t`` and active point ``p`` (the thesis' two scripts merged into one pass
    over the frames; each frame is read once):

    1. ``C = normxcorr2(template_p, frame_t)`` over the whole frame (one FFT of the frame
       shared by all templates, :class:`~wingphoto.ncc.FrameCorrelator`); the peak is
       MATLAB's ``find(C == max(C(:)))``, first in column-major order.
    2. ``NCC.m``'s position: ``xoffSet = xpeak - size(template, 2)`` is the 0-based column
       of the matched template's top-left pixel (MATLAB's documented ``normxcorr2``
       example), and adding half the crop rectangle (``rect(3) / 2 = half_w``; an
       ``imcrop`` rectangle of width ``2 half_w`` spans ``2 half_w + 1`` pixels) gives
       the template centre: ``x_ncc = j - (n - 1) / 2``, ``y_ncc = i - (m - 1) / 2`` in
       0-based pixels, which is where the marker was clicked in frame 0. (Read literally
       as a 1-based MATLAB coordinate the same expression would sit one pixel up-left of
       the centre; we take the geometric reading, which the thesis' plots of ``+`` on the
       markers support.) Frame 0 is matched too (score 1 at the crop).
    3. If ``|(x_ncc, y_ncc) - previous| > maxtravel`` (previous = the last frame's match
       or the re-crop), ``NCC.m`` would have prompted: event ``'maxtravel'``; the point
       is stopped (``'lost'``, NaN) until a correction re-crops it.
    4. ``trackcl.m``: ``F = bpass(frame_t, *bpass_args)`` once per frame and
       ``cntrd(F, ceil((x_ncc, y_ncc)), cntrd_size)``. ``ceil`` of a 0-based coordinate
       equals MATLAB's ``ceil`` of the 1-based one minus 1, so windows are the
       original's. A guess ``cntrd`` drops (within ``1.5 * cntrd_size`` px of the border)
       or a window that filters to all zeros loses that frame only (events
       ``'cntrd_edge'``, ``'cntrd_empty'``).

    What is *not* reproduced: the interactive prompts themselves, and any clipping
    ``imcrop`` does of a rectangle that overhangs the border (such picks raise instead).

    Cost: one forward FFT plus, per marker, one inverse FFT of the padded frame size
    (e.g. 540 x 540 for 512 x 512 frames and 21 x 21 templates) per frame.

    Examples
    --------
    >>> yy, xx = np.mgrid[:64, :80]
    >>> frames = np.stack([200 * np.exp(-((xx - 30 - 1.5 * t) ** 2 + (yy - 32) ** 2) / 6)
    ...                    for t in range(4)]).astype(np.uint8)
    >>> res = track_thesis(frames, [[30, 32]], half_size=8, progress=False)
    >>> res.tracks[["frame", "x_ncc", "status"]].values.tolist()
    [[0, 30.0, 'ok'], [1, 31.0, 'ok'], [2, 33.0, 'ok'], [3, 34.0, 'ok']]
    >>> np.round(res.tracks["x"].to_numpy() - (30 + 1.5 * np.arange(4)), 2).tolist()
    [0.0, 0.0, 0.0, 0.0]
    """
    get, n_frames = _frame_source(frames)
    pk = _parse_picks(picks, half_size)
    n_points = len(pk)
    if maxtravel is None or not (maxtravel > 0):
        raise ValueError(f"maxtravel must be a positive number of px, got {maxtravel}")
    lnoise, lobject, threshold = bpass_args
    if int(cntrd_size) != cntrd_size or cntrd_size < 1 or cntrd_size % 2 == 0:
        raise ValueError(f"cntrd_size must be a positive odd integer, got {cntrd_size}")
    if callable(corrections):
        ask, fixes = corrections, {}
    else:
        ask, fixes = None, _parse_corrections(corrections, camera, n_points)

    first = get(0)
    _check_frame(first, 0, None)
    shape = first.shape
    cx = matlab_round(pk[:, 0]).astype(int)
    cy = matlab_round(pk[:, 1]).astype(int)
    hw = matlab_round(pk[:, 2]).astype(int)
    hh = matlab_round(pk[:, 3]).astype(int)
    templates = []
    for p in range(n_points):
        tmpl = _crop(first, cx[p], cy[p], hw[p], hh[p], f"pick of point {p}")
        if np.all(tmpl == tmpl.flat[0]):
            raise ValueError(
                f"the template of point {p} at (x={cx[p]}, y={cy[p]}) is constant; "
                "is the marker there in frame 0?")
        templates.append(tmpl)
    corr = FrameCorrelator(templates, shape)

    active = np.ones(n_points, dtype=bool)
    prev = np.column_stack([cx, cy]).astype(np.float64)
    # output columns, filled frame by frame
    n_rows = n_frames * n_points
    xs = np.full(n_rows, np.nan)
    ys = np.full(n_rows, np.nan)
    xn = np.full(n_rows, np.nan)
    yn = np.full(n_rows, np.nan)
    score = np.full(n_rows, np.nan)
    status = np.full(n_rows, "lost", dtype=object)
    events = []

    def event(t, p, kind, action, xp, yp, x, y):
        d = float(np.hypot(x - xp, y - yp)) if np.isfinite(xp) else np.nan
        events.append((t, p, kind, action, xp, yp, x, y, d))

    bar = tqdm(range(n_frames), desc="track_thesis", unit="frame", disable=not progress)
    for t in bar:
        img = first if t == 0 else get(t)
        _check_frame(img, t, shape)
        base = t * n_points
        recropped = set()

        def recrop(p, x, y, kind, what):
            px, py = int(matlab_round(x)), int(matlab_round(y))
            tmpl = _crop(img, px, py, hw[p], hh[p], f"{what} of point {p} at frame {t}")
            if np.all(tmpl == tmpl.flat[0]):
                raise ValueError(f"the re-cropped template of point {p} at frame {t} "
                                 f"(x={px}, y={py}) is constant")
            corr.replace(p, tmpl)
            event(t, p, kind, "corrected", prev[p, 0], prev[p, 1], float(px), float(py))
            active[p] = True
            recropped.add(p)
            prev[p] = (px, py)
            xn[base + p], yn[base + p] = px, py
            status[base + p] = "manual"

        # --- re-crops supplied for this frame (the user's answer to NCC.m's prompt)
        for p, (x, y) in sorted(fixes.get(t, {}).items()):
            recrop(p, x, y, "recrop", "correction")
        # --- NCC.m: whole-image normxcorr2 with the fixed template
        todo = [p for p in np.flatnonzero(active) if p not in recropped]
        for p, C in corr.correlate(img, which=todo):
            m, n = corr.template_shape(p)
            i, j, s = _peak(C)
            x, y = j - (n - 1) / 2.0, i - (m - 1) / 2.0
            if t > 0 and np.hypot(x - prev[p, 0], y - prev[p, 1]) > maxtravel:
                # NCC.m prompts for a re-crop here
                answer = ask(t, int(p)) if ask is not None else None
                if answer is not None:
                    prev_xy = prev[p].copy()
                    recrop(p, answer[0], answer[1], "maxtravel", "answer to the prompt")
                    # keep the rejected match in the event, as for a stopped point
                    events[-1] = (t, p, "maxtravel", "corrected", prev_xy[0], prev_xy[1],
                                  x, y, float(np.hypot(x - prev_xy[0], y - prev_xy[1])))
                    continue
                event(t, p, "maxtravel", "stopped", prev[p, 0], prev[p, 1], x, y)
                logger.info("track_thesis: point %d moved %.1f px > maxtravel at frame %d; "
                            "NCC.m would prompt for a re-crop: point stopped", p,
                            np.hypot(x - prev[p, 0], y - prev[p, 1]), t)
                active[p] = False
                continue
            prev[p] = (x, y)
            xn[base + p], yn[base + p], score[base + p] = x, y, s
            status[base + p] = "ok"
        # --- trackcl.m: bpass + cntrd around ceil(ncc point)
        live = np.flatnonzero(active)
        if live.size:
            filt = bpass(img, lnoise, lobject, threshold)
            guess = np.ceil(np.column_stack([xn[base + live], yn[base + live]]))
            # the border drop is reported as an event below rather than logged per frame
            res = _cntrd(filt, guess, cntrd_size, log=False)
            full = res.full()
            for k, p in enumerate(live):
                r = base + p
                if not res.kept[k]:
                    event(t, p, "cntrd_edge", "lost_frame", np.nan, np.nan, xn[r], yn[r])
                    status[r] = "lost"
                elif not np.isfinite(full[k, :2]).all():
                    event(t, p, "cntrd_empty", "lost_frame", np.nan, np.nan, xn[r], yn[r])
                    status[r] = "lost"
                else:
                    xs[r], ys[r] = full[k, 0], full[k, 1]
    bar.close()

    tracks = pd.DataFrame({
        "camera": pd.Series([camera] * n_rows, dtype=object),
        "frame": np.repeat(np.arange(n_frames, dtype=np.int64), n_points),
        "point": np.tile(np.arange(n_points, dtype=np.int64), n_frames),
        "x": xs, "y": ys, "score": score,
        "status": pd.Series(status, dtype=object),
        "x_ncc": xn, "y_ncc": yn,
    })[TRACK_COLUMNS]
    ev = pd.DataFrame(events, columns=EVENT_COLUMNS).astype(
        {"frame": np.int64, "point": np.int64, "kind": object, "action": object,
         "x_prev": np.float64, "y_prev": np.float64, "x_ncc": np.float64,
         "y_ncc": np.float64, "distance": np.float64})
    result = ThesisResult(tracks, ev, n_frames, n_points, camera)
    n_lost = int((tracks["status"] == "lost").sum())
    if n_lost:
        logger.warning("track_thesis: %d of %d point-frames lost (%d re-crop prompts, "
                       "%d cntrd border drops)", n_lost, n_rows,
                       int((ev["kind"] == "maxtravel").sum()),
                       int((ev["kind"] == "cntrd_edge").sum()))
    return result
