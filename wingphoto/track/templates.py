"""Templates: cut at the refined centre, updated without drift, matched."""
from __future__ import annotations

import cv2
import numpy as np

from . import engine
from .match import _ncc_kernel, _score_kernel, match_windows
from .refine import _gather


class TemplateStage:
    """Template cutting, blending and matching of :class:`~wingphoto.track.tracker.Tracker`.

    The templates are tracker state (they persist from frame to frame); this mixin owns
    them. Per marker ``i`` (N markers):

    * ``tpl0[i]``, ``tplr[i]`` : (2 h[i] + 1, 2 h[i] + 1) float32 - the template cut on
      the picks' frame and the running one (blended with each update,
      :meth:`~wingphoto.track.tracker.Tracker._refresh_templates`); a checkpoint saves
      both. The template matched is ``original_weight * tpl0 + (1 - original_weight) *
      tplr``, which keeps the running template from drifting off the marker.
    * ``tplu[i]`` : that template as OpenCV matches it (uint8 for 8-bit frames), made when
      needed (:meth:`_tplu`), None when stale.
    * ``tz`` (N, s, s) float32, ``tzf`` (N, s * s) its flat view, ``tmask`` (N, s * s),
      ``tcount`` (N,), ``to`` (s,): the zero-mean, unit-norm templates padded to the
      largest size ``s`` for the compiled kernels and :meth:`_score_at`, their masks,
      pixel counts and offsets (:meth:`_init_stack`).

    Reads the tracker's ``h`` (template half sizes), ``p.original_weight`` and ``is_u8``.
    """

    def _fit_margin(self, idx, at):
        """How far (px) each point ``at`` ((m, 2), x y) lies inside the region where the
        template of marker ``idx[k]`` can be centred whole (``h`` px from every image
        edge); negative where it does not fit. (m,) array."""
        at = np.asarray(at, np.float64)
        h = np.asarray(self.h, np.float64)[idx]
        return np.minimum.reduce([at[:, 0] - h, self.W - 1 - h - at[:, 0], at[:, 1] - h, self.H - 1 - h - at[:, 1]])

    def _cut(self, frame, x, y, h):
        """Template of size 2h+1 centred on sub-pixel (x, y), float32."""
        s = 2 * int(h) + 1
        ix, iy = int(round(x)), int(round(y))
        g = int(h) + 2
        y0, x0 = max(iy - g, 0), max(ix - g, 0)
        crop = np.ascontiguousarray(frame[y0: iy + g + 1, x0: ix + g + 1], dtype=np.float32)
        return cv2.getRectSubPix(crop, (s, s), (float(x - x0), float(y - y0)))

    def _as_match(self, t):
        """Template ``t`` as OpenCV matches it: rounded to uint8 for 8-bit frames, else float32."""
        if self.is_u8:
            return np.clip(np.rint(t), 0, 255).astype(np.uint8)
        return np.ascontiguousarray(t, dtype=np.float32)


    def _set_template(self, i):
        """Marker ``i``'s templates changed: restack the matched template, drop ``tplu[i]``."""
        w = self.p.original_weight
        t = w * self.tpl0[i] + (1.0 - w) * self.tplr[i]
        self.tplu[i] = None  # made when needed (:meth:`_tplu`)
        self._stack_template(i, t)

    def _tplu(self, i):
        """Template of marker ``i`` as matched by OpenCV (uint8 for uint8 frames)."""
        if self.tplu[i] is None:
            w = self.p.original_weight
            self.tplu[i] = self._as_match(w * self.tpl0[i] + (1.0 - w) * self.tplr[i])
        return self.tplu[i]

    def _stack_template(self, i, t):
        """Write template ``t`` of marker ``i``, zero-mean and unit-norm, centred in ``tz[i]``."""
        s = self.tz.shape[1]
        hi = int(self.h[i])
        a = (s // 2) - hi
        tt = np.asarray(t, np.float64)
        tz = tt - tt.mean()
        nrm = np.sqrt((tz * tz).sum())
        self.tz[i] = 0.0
        self.tz[i, a: a + 2 * hi + 1, a: a + 2 * hi + 1] = tz / max(nrm, 1e-12)

    def _init_stack(self):
        """Build ``tz``, ``tzf``, ``tmask``, ``to`` and ``tcount`` from ``tpl0`` and ``tplr``
        (set-up and resume)."""
        s = 2 * int(self.h.max()) + 1
        n = len(self.h)
        self.tz = np.zeros((n, s, s), np.float32)
        self.tmask = np.zeros((n, s * s), np.float32)
        o = np.arange(s) - s // 2
        for i in range(n):
            hi = int(self.h[i])
            m = (np.abs(o)[:, None] <= hi) & (np.abs(o)[None, :] <= hi)
            self.tmask[i] = m.ravel()
            w = self.p.original_weight
            t = w * self.tpl0[i] + (1.0 - w) * self.tplr[i]
            self.tplu[i] = None
            self._stack_template(i, t)
        self.tzf = self.tz.reshape(n, -1)
        self.to = o
        self.tcount = self.tmask.sum(1)

    def _match(self, frame, idx, centres, radii):
        """Windowed correlation of markers ``idx`` (:func:`match_windows`; compiled when
        numba is available, with the unrounded templates, for windows of radius <= 6 px:
        OpenCV's SIMD code is faster on wider ones)."""
        if not engine.use_numba() or np.max(radii) > 6:
            return match_windows(frame, [self._tplu(i) for i in idx], centres, radii)
        centres = np.asarray(centres, np.int64).reshape(-1, 2)
        radii = np.asarray(radii, np.int64).reshape(-1)
        n = len(centres)
        m = 2 * int(radii.max()) + 1 if n else 1
        maps = np.full((n, m, m), -2.0, np.float32)
        origin = np.zeros((n, 2), np.int64)
        shape = np.zeros((n, 2), np.int64)
        if n:
            idx = np.asarray(idx, np.int64)
            _ncc_kernel(frame, self.tz, idx, self.h[idx], np.ascontiguousarray(centres[:, 0]),
                        np.ascontiguousarray(centres[:, 1]), radii, maps, origin, shape)
        return maps, origin, shape

    def _score_at(self, frame, idx, cx, cy):
        """TM_CCOEFF_NORMED of each template centred at integer pixels (cx, cy)."""
        if engine.use_numba():
            out = np.empty(len(idx))
            _score_kernel(frame, self.tz, idx, self.h[idx], cx.astype(np.int64), cy.astype(np.int64), out)
            return out
        I = _gather(frame, cx.astype(np.int64), cy.astype(np.int64), self.to)
        m = self.tmask[idx]
        s1 = np.einsum("ij,ij->i", I, m)
        s2 = np.einsum("ij,ij->i", I * I, m)
        num = np.einsum("ij,ij->i", I, self.tzf[idx])
        var = s2 - s1 * s1 / self.tcount[idx]
        with np.errstate(invalid="ignore", divide="ignore"):
            sc = num / np.sqrt(np.maximum(var, 0.0))
        return np.where(var > 1e-6 * (s2 + 1.0), sc, 0.0)

