"""Result arrays of a pass and the tidy tracks table."""
from __future__ import annotations

import numpy as np

from .status import _R, FLAGGED, LOST, OK, REASONS, STATUS

#: Columns of :func:`~wingphoto.track.track_markers`' result: :data:`wingphoto.io.TRACK_COLUMNS` plus
#: the pixel-level match, the reason of a flag and ``sigma``, the 1-sigma per-axis
#: uncertainty of the position (px).
TRACKER_COLUMNS = ["camera", "frame", "point", "x", "y", "score", "status", "x_pix", "y_pix", "reason", "sigma"]


class _Results:
    """Preallocated (T, N) result arrays of one pass."""

    names = ("x", "y", "score", "xpix", "ypix", "sigma")

    def __init__(self, T, N):
        for k in self.names:
            setattr(self, k, np.full((T, N), np.nan))
        self.status = np.full((T, N), LOST, np.int8)
        self.reason = np.zeros((T, N), np.int8)

    def arrays(self, prefix):
        out = {prefix + k: getattr(self, k) for k in self.names}
        out[prefix + "status"] = self.status
        out[prefix + "reason"] = self.reason
        return out

    def load(self, d, prefix):
        for k in self.names + ("status", "reason"):
            getattr(self, k)[...] = d[prefix + k]

    def rows(self, sl):
        """A view of the rows ``sl`` (a slice, possibly reversed): writing to it writes here."""
        view = object.__new__(_Results)
        for k in self.names + ("status", "reason"):
            setattr(view, k, getattr(self, k)[sl])
        return view


def _labels(names, codes):
    """String column ``names[codes]``, built from the few names and taken per row (5x
    faster than converting an object column of 26,000 strings per 1000 frames)."""
    import pandas as pd

    # (astype(str) on the names: the string dtype of the installed pandas, as before)
    return pd.Series(list(names), dtype=object).astype(str).array.take(np.asarray(codes, np.intp))


def _tracks_frame(res, ids, camera, frames_idx=None):
    import pandas as pd

    T, N = res.x.shape
    fidx = np.arange(T) if frames_idx is None else np.asarray(frames_idx)
    return pd.DataFrame(
        {
            "camera": _labels([str(camera)], np.zeros(T * N, np.intp)),
            "frame": np.repeat(fidx.astype(np.int64), N),
            "point": np.tile(np.asarray(ids, np.int64), T),
            "x": res.x.ravel(),
            "y": res.y.ravel(),
            "score": res.score.ravel(),
            "status": _labels(STATUS, res.status.ravel()),
            "x_pix": res.xpix.ravel(),
            "y_pix": res.ypix.ravel(),
            "reason": _labels(REASONS, res.reason.ravel()),
            "sigma": res.sigma.ravel(),
        }
    )


def _merge_backward(fw, bw, tol):
    """Flag forward/backward disagreement; fill forward losses from anchored backward runs.

    A backward position replaces a forward loss only inside a run of consecutive
    backward-ok frames that, later in the sequence, agreed with an ok forward position
    (the run is anchored to a point both passes saw at the same place); an unanchored
    backward run may have started on the wrong blob.
    """
    both = (fw.status == OK) & (bw.status == OK)
    d = np.hypot(fw.x - bw.x, fw.y - bw.y)
    agree = both & (d <= tol)
    dis = both & (d > tol)
    soft = (_R["lost_track"], _R["out_of_frame"], _R["low_score"], _R["no_signal"], _R["edge"], _R["jump"])
    fillable = (fw.status != OK) & (bw.status == OK) & np.isin(fw.reason, soft)
    T, N = fw.x.shape
    fill = np.zeros_like(fillable)
    bok = bw.status == OK
    for i in range(N):
        anchored = False
        for t in range(T - 1, -1, -1):  # the backward pass ran from the end
            if not bok[t, i]:
                anchored = False
                continue
            if agree[t, i]:
                anchored = True
            elif fillable[t, i] and anchored:
                fill[t, i] = True
    fw.status[dis] = FLAGGED
    fw.reason[dis] = _R["fb_disagree"]
    for k in _Results.names:
        getattr(fw, k)[fill] = getattr(bw, k)[fill]
    fw.status[fill] = OK
    fw.reason[fill] = 0

