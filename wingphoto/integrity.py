"""Sequence checks: frames that are silently wrong, found before tracking.

The field's most reported failure is a frame that is not what it claims to be: a frame
duplicated or dropped by time-based seeking, a stray ``frame_0030 copy.tif`` sorted in
among the frames, a black frame, a bumped camera, a left view one frame behind the right.
Each of these triangulates without complaint (a duplicated frame gives a 0.008 px median
reprojection error and 10 mm 3D errors), so they are looked for here, from the frames and
their file names, before any tracking:

- :func:`check_sequence` - one camera: duplicates, blank frames, global image jumps (a
  camera bump, from :mod:`wingphoto.motion`), numbering gaps and stray files;
- :func:`check_stereo_sequences` - two cameras: the above for each, plus frame counts,
  sizes, frame rates, time stamps and an estimate of a constant frame offset between them.

Both return frozen reports with a ``summary()``; :class:`StereoSequenceReport` has
``.ok`` and ``.problems`` (what should stop a stereo run unless forced).
"""
from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from .io.sequence import SequenceWarning, read_sequence
from .motion import _prepared, frame_content, static_background

__all__ = [
    "SequenceReport",
    "SequenceScan",
    "SequenceWarning",
    "StereoSequenceReport",
    "check_sequence",
    "check_stereo_sequences",
]

logger = logging.getLogger(__name__)

_JUMP_COLUMNS = ("frame", "dx", "dy", "response")


def _open(frames, name):
    """A read_sequence for paths (its warnings are reported, not raised), else as given."""
    if isinstance(frames, (str, os.PathLike)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SequenceWarning)
            return read_sequence(frames, strays="keep")
    if isinstance(frames, (list, tuple)) and frames and isinstance(frames[0], (str, os.PathLike)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SequenceWarning)
            return read_sequence(list(frames), strays="keep")
    if not hasattr(frames, "__len__") or not hasattr(frames, "__getitem__"):
        raise ValueError(
            f"{name} must be a folder/file/pattern, a read_sequence result or a (T, H, W) array, "
            f"got {type(frames).__name__}"
        )
    arr = frames if hasattr(frames, "shape") and not isinstance(frames, np.ndarray) else np.asarray(frames)
    if len(arr) == 0:
        raise ValueError(f"{name} holds no frames")
    if np.ndim(arr[0]) != 2:
        raise ValueError(f"{name} must hold 2-D grey frames, got frames of shape {np.shape(arr[0])}")
    return arr


@dataclasses.dataclass(frozen=True)
class SequenceReport:
    """Findings of :func:`check_sequence` for one camera's frames.

    Attributes
    ----------
    n_frames : int
    shape : (int, int)
        (H, W) of the frames.
    dtype : str
    fps : float or None
        From the file header, when it has one.
    frame_numbers : (T,) ndarray of int64
        The camera's own image numbers (see :attr:`wingphoto.io.Sequence.frame_numbers`).
    timestamps : (T,) ndarray of float or None
    duplicates : (K,) ndarray of int64
        Indices (0-based positions in the sequence) of frames identical to the previous
        frame (mean absolute difference <= ``duplicate_tolerance`` grey levels).
    blank : (K,) ndarray of int64
        Indices of frames without content (grey-level std below ``blank_fraction`` of the
        sequence's median, or zero).
    jumps : DataFrame
        ``frame, dx, dy, response``: frames where the whole image (its static content)
        moved by more than ``jump_threshold`` px against the previous frame; dx, dy in px.
    gaps : list of int
        Numbers missing from a regular numbering (file names, image numbers) or, with
        time stamps, frames missing from a regular time base.
    strays : list of Path
        Files whose names do not fit the sequence's numbering.
    motion_measurable : bool
        False when the frames share no static content (median phase-correlation response
        against the static background below 0.3): jumps are then not reported.
    camera_offset : (T, 2) ndarray of float
        Each frame's static content against the sequence's static background, px (the
        series whose steps are the jumps).
    motion_energy : (T,) ndarray of float
        Mean absolute grey-level change from the previous frame (0 for frame 0), on
        downsampled frames: the signal :func:`check_stereo_sequences` aligns.
    content : (T,) ndarray of float
        Grey-level standard deviation of each frame.
    """

    n_frames: int
    shape: tuple
    dtype: str
    fps: float | None
    frame_numbers: np.ndarray
    timestamps: np.ndarray | None
    duplicates: np.ndarray
    blank: np.ndarray
    jumps: pd.DataFrame
    gaps: list
    strays: list
    camera_offset: np.ndarray
    motion_energy: np.ndarray
    content: np.ndarray
    source: str = ""
    variable_frame_rate: bool = False
    camera_numbers: bool = False
    motion_measurable: bool = True

    @property
    def ok(self):
        """True when nothing was found."""
        return not (len(self.duplicates) or len(self.blank) or len(self.jumps) or self.gaps or self.strays
                    or self.variable_frame_rate)

    def problems(self):
        """One line per finding (empty when :attr:`ok`)."""
        out = []
        if self.strays:
            names = ", ".join(Path(p).name for p in self.strays[:5])
            out.append(f"{len(self.strays)} stray file(s) not fitting the numbering: {names}")
        if self.gaps:
            out.append(f"{len(self.gaps)} missing number(s) (dropped frames?): {_short(self.gaps)}")
        if len(self.duplicates):
            out.append(f"{len(self.duplicates)} frame(s) identical to the previous one at index {_short(self.duplicates)}")
        if len(self.blank):
            out.append(f"{len(self.blank)} blank frame(s) at index {_short(self.blank)}")
        if len(self.jumps):
            steps = ", ".join(f"{int(r.frame)} ({r.dx:+.1f}, {r.dy:+.1f}) px" for r in self.jumps.head(5).itertuples())
            out.append(f"{len(self.jumps)} whole-image jump(s) (camera bump?) at index {steps}")
        if self.variable_frame_rate:
            out.append("variable frame rate: use the time stamps, not a constant frame interval")
        return out

    def summary(self):
        """Return a short multi-line text report."""
        h, w = self.shape
        fps = f", {self.fps:g} frames/s" if self.fps else ""
        first = f", image numbers {self.frame_numbers[0]}..{self.frame_numbers[-1]}" if self.n_frames else ""
        lines = [f"{self.source or 'sequence'}: {self.n_frames} frames of {w}x{h} px ({self.dtype}){fps}{first}"]
        problems = self.problems()
        lines += [f"  - {p}" for p in problems] or ["  no duplicates, blank frames, jumps, gaps or stray files found"]
        if not self.motion_measurable:
            lines.append("  (no static content to measure camera motion against: jumps were not looked for)")
        return "\n".join(lines)


def _short(values, n=8):
    values = [int(v) for v in values]
    return ", ".join(str(v) for v in values[:n]) + (" ..." if len(values) > n else "")


def _time_gaps(timestamps, fps):
    """Frame positions missing from a regular time base (a dropped frame doubles an interval)."""
    if timestamps is None or len(timestamps) < 3:
        return []
    dt = np.diff(np.asarray(timestamps, dtype=np.float64))
    step = 1.0 / fps if fps else float(np.median(dt))
    if not step > 0:
        return []
    missing = np.rint(dt / step).astype(np.int64) - 1
    out = []
    for k in np.flatnonzero(missing > 0):
        out += [int(k) + 1 + m for m in range(int(missing[k]))]
    return out


def check_sequence(frames, *, duplicate_tolerance=0.0, blank_fraction=0.1, jump_threshold=2.0,
                   max_size=256, progress=False):
    """Check one camera's frames for duplicates, blank frames, jumps, gaps and strays.

    Parameters
    ----------
    frames : str, Path, list of paths, Sequence or (T, H, W) array
        A folder, glob pattern or camera file (opened with :func:`wingphoto.read_sequence`,
        whose stray/gap warnings become findings here), or frames already opened.
    duplicate_tolerance : float, optional
        A frame is a duplicate when its mean absolute difference from the previous frame
        is at most this many grey levels. Default 0: bit-identical frames (real sensors
        never give two identical frames; a re-encoded video may need ~0.5).
    blank_fraction : float, optional
        A frame is blank when its grey-level standard deviation is below this fraction of
        the sequence's median (default 0.1), or exactly 0.
    jump_threshold : float, optional
        Smallest whole-image shift between consecutive frames reported as a jump, px
        (default 2.0; on the flapping-wing samples the wing's own motion moves the measure
        by up to 0.5 px over 60 frames and 1.05 px over 30, a 5 px bump by 5.4 px).
    max_size : int, optional
        Frames are downsampled to this longer side for the motion measures (default 256).
    progress : bool, optional
        Show a ``tqdm`` progress bar.

    Returns
    -------
    SequenceReport

    Notes
    -----
    Every frame is read once (plus up to 31 spread frames for the static background, see
    :func:`wingphoto.motion.static_background`). Gaps come from the file names' numbering
    (:func:`wingphoto.io.parse_numbering`), the camera's image numbers, or time stamps.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> frames = rng.integers(0, 255, (6, 32, 40), dtype=np.uint8)
    >>> frames[3] = frames[2]
    >>> frames[5] = 0
    >>> report = check_sequence(frames)
    >>> report.duplicates.tolist(), report.blank.tolist()
    ([3], [5])
    """
    from tqdm.auto import tqdm

    scan = SequenceScan(frames, duplicate_tolerance=duplicate_tolerance, blank_fraction=blank_fraction,
                        jump_threshold=jump_threshold, max_size=max_size)
    for t in tqdm(range(scan.n_frames), disable=not progress, desc="checking frames"):
        scan.add(t, scan.seq[t])
    return scan.report()


class SequenceScan:
    """The checks of :func:`check_sequence`, fed one frame at a time, in order.

    What lets a caller that reads every frame anyway (the tracker, through
    :func:`wingphoto.pipeline.track_folder`) check the sequence on the same reads:
    :meth:`add` each frame as it streams by (:meth:`watch` wraps a sequence so that its
    reads do it), then :meth:`report` (which reads the frames not added, if any).
    Opening the scan reads up to 31 spread frames for the static background
    (:func:`wingphoto.motion.static_background`).

    Parameters
    ----------
    frames : str, Path, list of paths, Sequence or (T, H, W) array
        As for :func:`check_sequence`.
    duplicate_tolerance, blank_fraction, jump_threshold, max_size
        As for :func:`check_sequence`.

    Attributes
    ----------
    seq : sequence
        The opened frames.
    n_frames : int
    next : int
        The frame :meth:`add` expects next.
    duplicates : list of int
        The duplicated frames found so far (a caller may stop at the first).
    """

    def __init__(self, frames, *, duplicate_tolerance=0.0, blank_fraction=0.1, jump_threshold=2.0, max_size=256):
        self.seq = seq = _open(frames, "frames")
        self.n_frames = n = len(seq)
        if n == 0:
            raise ValueError("frames holds no frames")
        first = np.asarray(seq[0])
        self.shape = tuple(int(s) for s in first.shape)
        self.dtype = str(first.dtype)
        self.duplicate_tolerance, self.blank_fraction = duplicate_tolerance, blank_fraction
        self.jump_threshold = jump_threshold
        self.bg = static_background(seq, max_size=max_size)
        self.content, self.energy, self.responses = np.zeros(n), np.zeros(n), np.zeros(n)
        self.offsets = np.full((n, 2), np.nan)
        self.duplicates = []
        self.next = 0
        self.source = getattr(getattr(seq, "_store", None), "description", "") or ""
        self._digest = self._small = self._frame = None

    def add(self, t, frame):
        """Check frame ``t`` (the next one: :attr:`next`) against the one before it."""
        if t != self.next:
            raise ValueError(f"SequenceScan.add: frame {t} given, frame {self.next} expected (frames go in order)")
        frame = np.asarray(frame)
        if frame.shape != self.shape:
            raise ValueError(f"frame {t} has shape {frame.shape} but frame 0 has {self.shape}; "
                             "all frames must have one size")
        digest = hashlib.blake2b(np.ascontiguousarray(frame).tobytes(), digest_size=16).digest()
        if t:
            if digest == self._digest:
                self.duplicates.append(t)
            elif self.duplicate_tolerance > 0:
                mad = float(np.mean(np.abs(frame.astype(np.float64) - self._frame)))
                if mad <= self.duplicate_tolerance:
                    self.duplicates.append(t)
        self._digest = digest
        self.content[t] = frame_content(frame)
        small = _prepared(frame, self.bg.scale)
        if self._small is not None:
            self.energy[t] = float(np.mean(np.abs(small - self._small)))
        self._small = small
        if self.duplicate_tolerance > 0:
            self._frame = frame.astype(np.float64)
        shift = self.bg.offset(frame)
        self.offsets[t] = (shift.dx, shift.dy)
        self.responses[t] = shift.response
        self.next = t + 1

    def watch(self, frames=None, *, on_duplicate=None):
        """``frames`` (default: :attr:`seq`) as a sequence whose in-order reads are :meth:`add`-ed.

        ``on_duplicate(t)``, if given, is called when frame ``t`` is found to duplicate the
        one before it (it may raise to stop the reader)."""
        return _Watched(self.seq if frames is None else frames, self, on_duplicate)

    def report(self):
        """The :class:`SequenceReport`, once the frames not added yet are read and added."""
        seq, n = self.seq, self.n_frames
        for t in range(self.next, n):
            self.add(t, seq[t])
        content, offsets, responses = self.content, self.offsets, self.responses
        median_content = float(np.median(content))
        blank = np.flatnonzero((content == 0) | (content < self.blank_fraction * median_content))
        # a step of the static content between consecutive frames; blank frames carry no offset
        valid = np.ones(n, bool)
        valid[blank] = False
        # the static background must explain the frames for its offsets to mean anything: real
        # scenes give phase-correlation responses of 0.6-0.75 (flapping samples and scenarios),
        # frames of unrelated noise 0.15 (median)
        typical = float(np.median(responses[valid])) if valid.any() else 0.0
        measurable = typical >= 0.3
        valid &= measurable & (responses >= 0.5 * typical)
        rows = []
        last = None
        for t in range(n):
            if not valid[t] or not np.all(np.isfinite(offsets[t])):
                continue
            if last is not None:
                d = offsets[t] - offsets[last]
                if np.hypot(*d) > self.jump_threshold:
                    rows.append((t, float(d[0]), float(d[1]), float(responses[t])))
            last = t
        jumps = pd.DataFrame(rows, columns=list(_JUMP_COLUMNS)).astype(
            {"frame": "int64", "dx": "float64", "dy": "float64", "response": "float64"})
        numbers = getattr(seq, "frame_numbers", None)
        numbers = np.arange(n, dtype=np.int64) if numbers is None else np.asarray(numbers, dtype=np.int64)
        strays = list(getattr(seq, "strays", []))
        gaps = list(getattr(seq, "gaps", []))
        timestamps = getattr(seq, "timestamps", None)
        fps = getattr(seq, "fps", None)
        if not gaps and numbers.size > 2 and getattr(seq, "paths", None) is not None and len(seq.paths) == 1:
            d = np.diff(numbers)
            if np.all(d >= 1) and np.any(d > 1):  # image numbers of one recording are consecutive
                gaps = [int(v) for v in np.setdiff1d(np.arange(numbers[0], numbers[-1] + 1), numbers)]
        if not gaps and not getattr(seq, "variable_frame_rate", False):
            gaps = _time_gaps(timestamps, fps)
        source = self.source
        return SequenceReport(
            n_frames=n, shape=self.shape, dtype=self.dtype, fps=fps, frame_numbers=numbers,
            timestamps=None if timestamps is None else np.asarray(timestamps, float),
            duplicates=np.asarray(self.duplicates, dtype=np.int64), blank=blank.astype(np.int64), jumps=jumps,
            gaps=gaps, strays=strays, camera_offset=offsets, motion_energy=self.energy, content=content,
            source=source, variable_frame_rate=bool(getattr(seq, "variable_frame_rate", False)),
            camera_numbers=getattr(seq, "info", {}).get("format") in ("cine", "mraw"),
            motion_measurable=measurable,
        )


class _Watched:
    """A sequence whose reads of frame :attr:`SequenceScan.next` feed the scan (any other
    read - a frame again, out of order - passes through)."""

    def __init__(self, frames, scan, on_duplicate=None):
        self.frames, self.scan, self.on_duplicate = frames, scan, on_duplicate

    def __len__(self):
        return len(self.frames)

    def __getattr__(self, name):  # paths, strays, fps ... of the sequence
        return getattr(self.frames, name)

    def __getitem__(self, i):
        frame = self.frames[i]
        if isinstance(i, (int, np.integer)) and 0 <= i == self.scan.next:
            self.scan.add(int(i), frame)
            if self.on_duplicate is not None and self.scan.duplicates[-1:] == [int(i)]:
                self.on_duplicate(int(i))
        return frame


@dataclasses.dataclass(frozen=True)
class StereoSequenceReport:
    """Findings of :func:`check_stereo_sequences` for a left/right pair.

    Attributes
    ----------
    left, right : SequenceReport
    offset : int or None
        Estimated constant frame offset: right frame ``t`` shows the instant of left frame
        ``t + offset``. 0 when in step. From epipolar geometry when a rig is given, from
        the trigger-relative image numbers of two .cine/.mraw files, else None (the images'
        motion alone gives only a hint, reported in ``notes``).
    offset_score : float
        With a rig: the share of blobs on their epipolar lines at ``offset``; without:
        the correlation of the two cameras' motion-energy signals at ``offset``.
    problems : tuple of str
        Findings that make the pair unfit for triangulation (count, rate or time-stamp
        mismatch, a frame offset, duplicates, gaps or strays in either view).
    notes : tuple of str
        Findings worth knowing that do not stop a run (different frame sizes, blank
        frames, camera bumps).
    """

    left: SequenceReport
    right: SequenceReport
    offset: int | None
    offset_score: float
    problems: tuple
    notes: tuple

    @property
    def ok(self):
        """True when nothing stops a stereo run (see :attr:`problems`)."""
        return not self.problems

    def summary(self):
        """Return a short multi-line text report of both views and their agreement."""
        lines = ["left  " + self.left.summary().replace("\n", "\n      "),
                 "right " + self.right.summary().replace("\n", "\n      ")]
        off = "unknown" if self.offset is None else f"{self.offset:+d} frame(s)"
        lines.append(f"left/right offset: {off} (score {self.offset_score:.3f})")
        lines += [f"PROBLEM: {p}" for p in self.problems]
        lines += [f"note: {p}" for p in self.notes]
        lines.append("left/right consistent" if self.ok else "left/right NOT consistent")
        return "\n".join(lines)


def _estimate_offset(a, b, max_lag):
    """Lag maximising the correlation of b[t] with a[t + lag]; (lag, score, second best)."""
    a = np.asarray(a, float)[1:]
    b = np.asarray(b, float)[1:]
    scores = {}
    for lag in range(-max_lag, max_lag + 1):
        x = a[lag:] if lag >= 0 else a
        y = b if lag >= 0 else b[-lag:]
        m = min(len(x), len(y))
        if m < 8:
            continue
        x, y = x[:m], y[:m]
        if x.std() == 0 or y.std() == 0:
            continue
        scores[lag] = float(np.mean((x - x.mean()) * (y - y.mean())) / (x.std() * y.std()))
    if not scores:
        return None, float("nan"), float("nan")
    best = max(scores, key=scores.get)
    others = [v for k, v in scores.items() if k != best]
    return best, scores[best], (max(others) if others else float("nan"))


def _blobs(frame):
    """Centroids (N, 2) of small bright (or, on a bright wing, dark) blobs: marker candidates."""
    import cv2

    a = np.asarray(frame, dtype=np.float32)
    hp = a - cv2.GaussianBlur(a, (0, 0), 4)
    sample = hp[::3, ::3].ravel()  # statistics on a ninth of the pixels: 10x faster, same thresholds
    lo, hi = np.percentile(sample, [0.1, 99.9])
    if -lo > hi:  # dark markers on a bright wing
        hp, sample = -hp, -sample
    mad = 1.4826 * float(np.median(np.abs(sample - np.median(sample))))
    thr = max(6 * mad, 0.25 * float(hp.max()), 1e-6)
    n, _, stats, centroids = cv2.connectedComponentsWithStats((hp > thr).astype(np.uint8))
    keep = (stats[1:, cv2.CC_STAT_AREA] >= 3) & (stats[1:, cv2.CC_STAT_AREA] <= 0.01 * a.size)
    return centroids[1:][keep]


def _epipolar_offset(left, right, rig, max_lag, n_frames=20):
    """Frame offset from epipolar geometry: blobs of left frame t against right frame t + lag.

    Returns (offset, matched share at the offset, best share at any other lag); right
    frame t shows left frame t + offset.
    """
    n = min(len(left), len(right))
    if n < 3:
        return None, float("nan"), float("nan")
    idx = np.unique(np.linspace(0, n - 1, min(n, n_frames)).round().astype(int))
    F = rig.fundamental_matrix
    ul = {}
    for t in idx:
        b = _blobs(left[int(t)])
        ul[int(t)] = rig.left.undistort_points(b) if len(b) else b
    ur_cache = {}

    def right_blobs(s):
        if s not in ur_cache:
            b = _blobs(right[s])
            ur_cache[s] = rig.right.undistort_points(b) if len(b) else b
        return ur_cache[s]

    share = {}
    for lag in range(-max_lag, max_lag + 1):
        hits = total = 0
        for t in idx:
            s = int(t) + lag
            if s < 0 or s >= len(right) or len(ul[int(t)]) == 0:
                continue
            ur = right_blobs(s)
            if len(ur) == 0:
                continue
            lines = np.column_stack([ul[int(t)], np.ones(len(ul[int(t)]))]) @ F.T
            d = np.abs(lines @ np.column_stack([ur, np.ones(len(ur))]).T) / np.hypot(lines[:, 0], lines[:, 1])[:, None]
            hits += int(np.sum(d.min(axis=1) < 1.0))
            total += len(d)
        if total:
            share[lag] = hits / total
    if not share:
        return None, float("nan"), float("nan")
    lag = max(share, key=share.get)
    others = [v for k, v in share.items() if k != lag]
    return -lag, share[lag], (max(others) if others else float("nan"))


def check_stereo_sequences(left, right, *, rig=None, max_offset=5, min_offset_score=0.2, reports=None, **options):
    """Check a left/right pair of sequences for everything that breaks stereo.

    Parameters
    ----------
    left, right : str, Path, Sequence or (T, H, W) array
        The two views (anything :func:`check_sequence` takes).
    rig : StereoRig, optional
        The calibrated rig. With it the frame offset comes from epipolar geometry (see
        Notes), which is exact where the motion-energy estimate is not.
    max_offset : int, optional
        Largest frame offset looked for (default 5).
    min_offset_score : float, optional
        Smallest correlation of the motion signals for the offset estimate to count
        (default 0.2); below it ``offset`` is None.
    reports : (SequenceReport, SequenceReport), optional
        The views' reports, already made from these frames (e.g. by a
        :class:`SequenceScan` fed while tracking): they are not checked again, and only
        the frames of the epipolar check (with ``rig``) are read.
    **options
        Passed to :func:`check_sequence` for both views.

    Returns
    -------
    StereoSequenceReport

    Notes
    -----
    With ``rig``, the offset is the lag at which the most marker-like blobs of a left
    frame lie within 1 px of the epipolar line of a blob in the right frame (20 frames
    spread over the sequence, lags ``-max_offset..max_offset``). On the flapping sample
    the true lag matches 100 % of the blobs (median epipolar distance 0.07 px) and the
    best wrong lag 45-64 %, with 60, 40, 20 or 10 frames. ``offset_score`` is then the
    matched share.

    Without a rig, two .cine/.mraw files give the offset from their trigger-relative image
    numbers. Otherwise the images' motion energies (mean absolute change between
    consecutive frames) are cross-correlated over lags ``-max_offset..max_offset``, but
    only as a hint in ``notes``: the peak is flat and view-dependent (on the flapping
    sample: correlation 0.991 at the true lag, 0.984 next to it on 60 frames, and the
    wrong lag on 91 % of 20-40-frame windows), so ``offset`` stays None.
    With the cameras' image numbers or time stamps (.cine, .mraw), those are compared too.
    """
    if rig is not None and (isinstance(left, SequenceReport) or isinstance(right, SequenceReport)):
        raise ValueError("with rig=, pass the frames (not SequenceReports): the epipolar check reads them")
    if not isinstance(left, SequenceReport):
        left = _open(left, "left")
    if not isinstance(right, SequenceReport):
        right = _open(right, "right")
    if reports is not None:
        lrep, rrep = reports
    else:
        lrep = left if isinstance(left, SequenceReport) else check_sequence(left, **options)
        rrep = right if isinstance(right, SequenceReport) else check_sequence(right, **options)
    problems, notes = [], []
    if lrep.n_frames != rrep.n_frames:
        problems.append(f"frame counts differ: left {lrep.n_frames}, right {rrep.n_frames}")
    if lrep.shape != rrep.shape:
        notes.append(f"frame sizes differ: left {lrep.shape[1]}x{lrep.shape[0]}, right {rrep.shape[1]}x{rrep.shape[0]} px")
    if lrep.fps and rrep.fps and abs(lrep.fps - rrep.fps) > 1e-6 * max(lrep.fps, rrep.fps):
        problems.append(f"frame rates differ: left {lrep.fps:g}, right {rrep.fps:g} frames/s")
    if rig is not None:
        offset, score, second = _epipolar_offset(left, right, rig, int(max_offset))
        if offset is not None and not (score >= 0.5 and score - second >= 0.15):
            notes.append(f"the epipolar frame-offset check is inconclusive (best lag matches {score:.0%} of the "
                         f"blobs, the next {second:.0%})")
            offset = None
        n = min(len(left), len(right))
        if n >= 12:  # the same check on the first and last quarter: a frame lost in one view midway
            q = max(6, n // 4)
            start = _epipolar_offset(left[:q], right[:q], rig, int(max_offset), n_frames=10)
            end = _epipolar_offset(left[len(left) - q:], right[len(right) - q:], rig, int(max_offset), n_frames=10)
            end_offset = None if end[0] is None else end[0] + (len(left) - len(right))
            good = [r[0] is not None and r[1] >= 0.5 and r[1] - r[2] >= 0.15 for r in (start, end)]
            if all(good) and start[0] != end_offset:
                problems.append(
                    f"the frame offset changes from {start[0]:+d} over the first {q} frames to {end_offset:+d} "
                    f"over the last {q} (right frame t shows left frame t + offset): a frame was dropped or "
                    f"repeated in one view in between; cut both sequences at that point"
                )
                offset = None
    else:
        guess, score, second = _estimate_offset(lrep.motion_energy, rrep.motion_energy, int(max_offset))
        offset = None
        if lrep.camera_numbers and rrep.camera_numbers:
            # trigger-relative image numbers of two synchronized cameras: equal numbers, same instant
            offset = int(rrep.frame_numbers[0] - lrep.frame_numbers[0])
            score = 1.0
        elif guess is not None and score >= min_offset_score and score > second:
            # the motion energy's correlation peak is flat: on the flapping sample it finds a
            # 1-frame offset on 60 frames but calls 40 in-step frames offset by +1, so it is a
            # hint, not a finding
            notes.append(
                f"the images' motion peaks at a {guess:+d} frame offset (correlation {score:.3f}, next "
                f"{second:.3f}); this is unreliable for offsets of a frame or two: check with the "
                f"calibration (rig=, --calib), which finds the offset exactly"
            )
    if lrep.timestamps is not None and rrep.timestamps is not None:
        m = min(lrep.n_frames, rrep.n_frames)
        dt = np.asarray(rrep.timestamps[:m]) - np.asarray(lrep.timestamps[:m])
        step = 1.0 / lrep.fps if lrep.fps else float(np.median(np.diff(lrep.timestamps))) if m > 1 else 0
        if step and np.nanmax(np.abs(dt)) > 0.5 * step:
            problems.append(
                f"time stamps differ by up to {np.nanmax(np.abs(dt)) * 1e3:.3f} ms "
                f"({np.nanmax(np.abs(dt)) / step:.1f} frame intervals) between left and right"
            )
    if offset:
        problems.append(
            f"the right view seems offset by {offset:+d} frame(s) from the left (right frame t "
            f"matches left frame t{offset:+d}); trim one sequence so that both start at the same instant"
        )
    for name, rep in (("left", lrep), ("right", rrep)):
        if rep.strays:
            problems.append(f"{name}: {len(rep.strays)} stray file(s): {', '.join(Path(p).name for p in rep.strays[:3])}")
        if rep.gaps:
            problems.append(f"{name}: missing frame number(s) {_short(rep.gaps)}")
        if len(rep.duplicates):
            problems.append(f"{name}: duplicated frame(s) at index {_short(rep.duplicates)}")
        if len(rep.blank):
            notes.append(f"{name}: blank frame(s) at index {_short(rep.blank)}")
        if len(rep.jumps):
            notes.append(f"{name}: whole-image jump(s) at index {_short(rep.jumps['frame'])} (camera bump? "
                         f"the calibration may no longer hold after it)")
        if rep.variable_frame_rate:
            problems.append(f"{name}: variable frame rate")
    return StereoSequenceReport(lrep, rrep, offset, float(score) if score == score else float("nan"),
                                tuple(problems), tuple(notes))
