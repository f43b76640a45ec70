"""Tracking options: the single place for defaults and validation."""
from __future__ import annotations

import numpy as np

#: Disk radius of the centroid (px): at least _RD_MIN, at most _RD_MAX, and
#: _RD_MARGIN beyond the blob's measured support (blur tails).
_RD_MIN, _RD_MAX, _RD_MARGIN = 2.5, 14.0, 3.0
#: Flag 'background' when the RMS departure of the ring from a plane exceeds this
#: fraction of the marker's contrast.
_BG_RESIDUAL, _BG_RESIDUAL_FADED, _FADED, _WEAK = 0.1, 0.04, 0.6, 0.75
#: Two markers predicted to touch are not 'merged' when the image between them falls below
#: this fraction of the marker's peak (a visible gap: the pixel split separates them).
_MERGE_VALLEY, _BRIDGE = 0.5, 0.8


_PARAM_DEFAULTS = dict(
    search_radius=20,
    min_score=0.6,
    lost_score=0.3,
    ambiguity_margin=0.1,
    update_score=0.88,
    refresh_below=0.93,
    update_rate=0.5,
    original_weight=0.3,
    max_coast=6,
    reacquire_radius=6,
    reacquire_score=0.8,
    min_mass_ratio=0.25,
    max_mass_ratio=np.inf,
    jump_px=3.0,
    max_score_drop=np.inf,
    polarity="auto",
    fb_tolerance=0.5,
    search_every=4,
    update_every=4,
)



class _Params:
    """Validated tracking options (a plain record; see :func:`track_markers`)."""

    def __init__(self, **kw):
        for k, v in _PARAM_DEFAULTS.items():
            setattr(self, k, kw.pop(k, v))
        if kw:
            raise TypeError(f"unknown option(s) {sorted(kw)}")
        if self.search_radius is None:
            self.search_radius = _PARAM_DEFAULTS["search_radius"]
        self.search_radius = int(self.search_radius)
        if self.search_radius < 2:
            raise ValueError(f"search_radius must be >= 2 px, got {self.search_radius}")
        for k in ("min_score", "lost_score", "update_score", "refresh_below", "reacquire_score"):
            v = float(getattr(self, k))
            if not -1.0 <= v <= 1.0:
                raise ValueError(f"{k} must be a correlation score in [-1, 1], got {v}")
            setattr(self, k, v)
        if self.lost_score > self.min_score:
            raise ValueError(f"lost_score ({self.lost_score}) must not exceed min_score ({self.min_score})")
        for k in ("update_rate", "original_weight"):
            v = float(getattr(self, k))
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{k} must be in [0, 1], got {v}")
            setattr(self, k, v)
        if self.polarity not in ("auto", 1, -1):
            raise ValueError(f"polarity must be 'auto', 1 (bright markers) or -1 (dark), got {self.polarity!r}")
        for k in ("max_mass_ratio", "max_score_drop"):
            v = getattr(self, k)
            setattr(self, k, np.inf if v is None else float(v))
        self.jump_px = float(self.jump_px)
        self.max_coast = int(self.max_coast)
        self.search_every = int(self.search_every)
        self.update_every = max(int(self.update_every), 1)
        if self.search_every < 1:
            raise ValueError(f"search_every must be >= 1 frame, got {self.search_every}")
        self.reacquire_radius = int(self.reacquire_radius)

    def as_dict(self):
        return {k: getattr(self, k) for k in _PARAM_DEFAULTS}

