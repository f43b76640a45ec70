"""Tracking options: the single place for defaults and validation.

:class:`TrackOptions` holds every option of :func:`~wingphoto.track.track_markers`. The
first few are the ones a user tunes (``search_radius``, ``max_sigma``, ``polarity``,
``max_coast``, ``fb_tolerance``); the rest are expert thresholds, documented here and
validated here, whose defaults were set on the synthetic validation scenarios. The few
module constants below are those the option handling and several stages share; every
other internal constant (not an option) sits in the stage module that reads it.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

__all__ = ["TrackOptions"]

#: Disk radius of the centroid (px): at most _RD_MAX, and _RD_MARGIN beyond the blob's
#: measured support (blur tails); the inner disk (:func:`~.refine._inner_disk`) is not
#: shrunk below _RD_MIN.
_RD_MIN, _RD_MAX, _RD_MARGIN = 2.5, 14.0, 3.0
#: ... and at least _RD_FACE_MARGIN beyond the radius of its face (the blob above half its
#: face's median brightness, :func:`~.tracker._measure_pick`), where a highlight is brighter
#: than the rest.
_RD_FACE_MARGIN = 1.5
#: A frame-0 pick whose refinement sees a background ring this far from a plane
#: (fraction of the marker's contrast) keeps the click (``pick_moved``).
_BG_RESIDUAL = 0.1
#: Two markers predicted to touch are not 'merged' when the image between them falls below
#: this fraction of the marker's peak (a visible gap: the pixel split separates them).
_MERGE_VALLEY, _BRIDGE = 0.5, 0.8


@dataclass(frozen=True)
class TrackOptions:
    """Options of :func:`~wingphoto.track.track_markers` (frozen; change with
    :func:`dataclasses.replace` or ``TrackOptions(**changes)``).

    User options
    ------------
    search_radius : int
        Largest search radius (px, default 20): used on frame 1, where no velocity is known
        yet, and as the cap of the prediction-driven radius. Must exceed the largest motion
        between frames 0 and 1.
    max_sigma : float
        A point is ``ok`` only if its positional uncertainty ``sigma`` (px, per axis) is at
        most this (default 0.25 px); above it the point is flagged ``imprecise``.
    polarity : {"auto", 1, -1}
        Bright (1) or dark (-1) markers; "auto" decides per marker from frame 0.
    max_coast : int
        Frames a marker may go without a reliable position before it is declared lost
        (``lost_track``) and searched for from its neighbours.
    fb_tolerance : float
        With ``bidirectional=True``: flag ``fb_disagree`` where the passes disagree by more
        than this (px).

    Expert options
    --------------
    min_score, lost_score : float
        Correlation (TM_CCOEFF_NORMED) below ``min_score`` is flagged ``low_score``, below
        ``lost_score`` lost.
    ambiguity_margin : float
        Flag ``ambiguous`` when a second, unexplained correlation peak comes within this
        margin of the best.
    update_score, refresh_below, update_rate, original_weight : float
        Template update: when ``update_score <= score < refresh_below`` the template cut at
        the refined centre is blended into the running template with weight
        ``update_rate``; the matched template is ``original_weight * original +
        (1 - original_weight) * running``.
    update_every : int
        At most one template update per marker every this many frames.
    reacquire_radius, reacquire_score : int, float
        Search radius and minimum score to re-acquire a lost marker.
    min_mass_ratio : float
        Flag ``no_signal`` when the blob's integrated brightness drops below this fraction
        of its frame-0 value.
    max_mass_ratio : float or None
        Flag ``merged`` when the integrated brightness exceeds this multiple of its running
        value. Off (None) by default.
    jump_px : float
        Smallest distance (px) between refined and predicted position flagged ``jump``; the
        limit is ``max(jump_px, 4 rms + 2 (frames coasted))``, rms the marker's running
        prediction residual.
    max_score_drop : float or None
        Flag ``appearance`` when the correlation falls by more than this below its running
        value. Off (None) by default: glare sweeps make it flag good points.
    search_every : int
        A marker on the fast path (moving predictably, alone, matched well on the frame
        before: :func:`~.predict.start_frame`, ``FAST_RMS`` and ``FAST_SCORE``) gets the
        full windowed NCC search only every ``search_every`` frames; in between it is
        refined at its prediction and verified. 1 searches every marker every frame.
    """

    search_radius: int = 20
    max_sigma: float = 0.25
    polarity: object = "auto"
    max_coast: int = 6
    fb_tolerance: float = 0.5
    min_score: float = 0.6
    lost_score: float = 0.3
    ambiguity_margin: float = 0.1
    update_score: float = 0.88
    refresh_below: float = 0.93
    update_rate: float = 0.5
    original_weight: float = 0.3
    update_every: int = 4
    reacquire_radius: int = 6
    reacquire_score: float = 0.8
    min_mass_ratio: float = 0.25
    max_mass_ratio: float = None
    jump_px: float = 3.0
    max_score_drop: float = None
    search_every: int = 4

    def __post_init__(self):
        def put(k, v):
            object.__setattr__(self, k, v)

        if self.search_radius is None:
            put("search_radius", type(self).search_radius)
        for k in ("search_radius", "max_coast", "update_every", "reacquire_radius", "search_every"):
            v = getattr(self, k)
            try:
                iv = int(v)
            except (TypeError, ValueError):
                raise ValueError(f"{k} must be an integer number of px/frames, got {v!r}") from None
            if iv != v:
                raise ValueError(f"{k} must be an integer, got {v!r}")
            put(k, iv)
        if self.search_radius < 2:
            raise ValueError(f"search_radius must be >= 2 px, got {self.search_radius}")
        if self.max_coast < 0:
            raise ValueError(f"max_coast must be >= 0 frames, got {self.max_coast}")
        if self.search_every < 1:
            raise ValueError(f"search_every must be >= 1 frame, got {self.search_every}")
        if self.reacquire_radius < 1:
            raise ValueError(f"reacquire_radius must be >= 1 px, got {self.reacquire_radius}")
        put("update_every", max(self.update_every, 1))
        for k in ("max_sigma", "fb_tolerance", "min_score", "lost_score", "ambiguity_margin", "update_score",
                  "refresh_below", "update_rate", "original_weight", "reacquire_score", "min_mass_ratio", "jump_px"):
            v = getattr(self, k)
            try:
                fv = float(v)
            except (TypeError, ValueError):
                raise ValueError(f"{k} must be a number, got {v!r}") from None
            if not math.isfinite(fv):
                raise ValueError(f"{k} must be finite, got {v!r}")
            put(k, fv)
        if not self.max_sigma > 0:
            raise ValueError(f"max_sigma must be > 0 px, got {self.max_sigma}")
        if not self.fb_tolerance > 0:
            raise ValueError(f"fb_tolerance must be > 0 px, got {self.fb_tolerance}")
        for k in ("min_score", "lost_score", "update_score", "refresh_below", "reacquire_score"):
            v = getattr(self, k)
            if not -1.0 <= v <= 1.0:
                raise ValueError(f"{k} must be a correlation score in [-1, 1], got {v}")
        if self.lost_score > self.min_score:
            raise ValueError(f"lost_score ({self.lost_score}) must not exceed min_score ({self.min_score})")
        for k in ("update_rate", "original_weight"):
            v = getattr(self, k)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{k} must be in [0, 1], got {v}")
        if not 0.0 <= self.ambiguity_margin <= 2.0:
            raise ValueError(f"ambiguity_margin must be in [0, 2], got {self.ambiguity_margin}")
        if self.min_mass_ratio < 0:
            raise ValueError(f"min_mass_ratio must be >= 0, got {self.min_mass_ratio}")
        if self.polarity not in ("auto", 1, -1):
            raise ValueError(f"polarity must be 'auto', 1 (bright markers) or -1 (dark), got {self.polarity!r}")
        for k in ("max_mass_ratio", "max_score_drop"):
            v = getattr(self, k)
            if v is not None:
                fv = float(v)
                if math.isnan(fv) or fv < 0:
                    raise ValueError(f"{k} must be >= 0 or None (off), got {v!r}")
                put(k, None if math.isinf(fv) else fv)

    # the rules compare with these (inf: off)
    @property
    def mass_ratio_cap(self):
        return math.inf if self.max_mass_ratio is None else self.max_mass_ratio

    @property
    def score_drop_cap(self):
        return math.inf if self.max_score_drop is None else self.max_score_drop

    def as_dict(self):
        """The options as a plain dict (for the checkpoint's fingerprint)."""
        return dataclasses.asdict(self)

    @classmethod
    def names(cls):
        """Names of all options."""
        return tuple(f.name for f in dataclasses.fields(cls))
