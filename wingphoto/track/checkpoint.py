"""Checkpoints: save and resume a tracking run."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

_CHECKPOINT_VERSION = 2


def _fingerprint(fr, xy, ids, half, params, camera, bidirectional):
    hsh = hashlib.sha1()
    hsh.update(np.nan_to_num(np.ascontiguousarray(xy), nan=-1e300).tobytes())
    hsh.update(np.ascontiguousarray(ids).tobytes())
    hsh.update(np.ascontiguousarray(half).tobytes())
    hsh.update(json.dumps([params.as_dict(), camera, bool(bidirectional), fr.n, list(fr.shape), str(fr.dtype)],
                          sort_keys=True, default=str).encode())
    hsh.update(np.ascontiguousarray(fr[0]).tobytes())
    return hsh.hexdigest()


def _save_checkpoint(path, meta, arrays):
    from ..io import atomic_write

    payload = dict(arrays)
    payload["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    with atomic_write(path, "wb") as f:
        np.savez(f, **payload)


def _load_checkpoint(path, fingerprint):
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(bytes(z["meta"]).decode())
        if meta.get("version") != _CHECKPOINT_VERSION or meta.get("fingerprint") != fingerprint:
            raise ValueError(
                f"checkpoint {path} was written for other frames, picks or options; delete it or "
                "pass another checkpoint path"
            )
        arrays = {k: z[k] for k in z.files if k != "meta"}
    return meta, arrays


def _run_pass(fr, tracker, res, frames_order, direction, ckpt, progress, desc):
    """Run ``tracker`` over ``frames_order`` (iterable of frame indices), checkpointing."""
    from tqdm.auto import tqdm

    bar = tqdm(total=len(frames_order), disable=not progress, desc=desc, leave=False)
    done = 0
    try:
        for t in frames_order:
            tracker.step(fr[t], t, res, direction)
            done += 1
            if ckpt is not None:
                ckpt.completed(t)
            if done & 255 == 0:
                bar.update(256)
    except BaseException:
        if ckpt is not None:
            ckpt.save()
        raise
    finally:
        bar.update(done & 255)
        bar.close()


class _Checkpointer:
    def __init__(self, path, fingerprint, every, state_fn):
        self.path = Path(path)
        self.fingerprint = fingerprint
        self.every = int(every)
        if self.every < 1:
            raise ValueError(f"checkpoint_every must be >= 1 frame, got {every}")
        self.state_fn = state_fn
        self.since = 0
        self.last = None

    def completed(self, t):
        self.last = t
        self.since += 1
        if self.since >= self.every:
            self.save()

    def save(self):
        meta, arrays = self.state_fn()
        meta["version"] = _CHECKPOINT_VERSION
        meta["fingerprint"] = self.fingerprint
        _save_checkpoint(self.path, meta, arrays)
        self.since = 0

