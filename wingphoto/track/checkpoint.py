"""Checkpoints: save and resume a tracking run.

A checkpoint (``.npz``, written atomically) holds the result arrays, the tracker's state,
where the run stands (its pass and next frame) and a fingerprint of what the run was
given: the picks (with the frames they were made in), the options, the sequence's
length, size and type, and the *content* of up to :data:`FINGERPRINT_FRAMES` frames
sampled from frame 0 to the highest frame read so far (evenly spaced: the saved state
depends on those frames only). A checkpoint written
for other frames, picks or options is refused with a message; so is a file that is not a
wingphoto checkpoint (empty, truncated, foreign).
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import signal
import threading
import zipfile
from pathlib import Path

import numpy as np

_CHECKPOINT_VERSION = 5  # 4: passes of picks in several frames; 5: the tracker state holds `restarted`
#: Frames whose content the fingerprint hashes (spread over the sequence).
FINGERPRINT_FRAMES = 8
_WAY_OUT = "delete it or pass another checkpoint path"


def _fingerprint(fr, xy, ids, half, params, camera, bidirectional, pick_frames=None):
    """Hash of a run's inputs: picks (NaN ones too), pick frames, options, the frames' layout."""
    hsh = hashlib.sha1()
    hsh.update(np.nan_to_num(np.ascontiguousarray(xy), nan=-1e300).tobytes())
    hsh.update(np.ascontiguousarray(ids).tobytes())
    hsh.update(np.ascontiguousarray(half).tobytes())
    if pick_frames is not None:
        hsh.update(np.ascontiguousarray(pick_frames, np.int64).tobytes())
    hsh.update(json.dumps([params.as_dict(), camera, bool(bidirectional), fr.n, list(fr.shape), str(fr.dtype)],
                          sort_keys=True, default=str).encode())
    return hsh.hexdigest()


def _sampled_frames(last):
    """Frames whose content a checkpoint saved after frame ``last`` hashes: 0, ``last``
    and evenly spaced ones between (the state depends on those frames only)."""
    return np.unique(np.linspace(0, max(last, 0), min(FINGERPRINT_FRAMES, last + 1)).round().astype(int)).tolist()


def _content(fr, frames):
    hsh = hashlib.sha1()
    for t in frames:
        hsh.update(np.ascontiguousarray(fr[t]).tobytes())
    return hsh.hexdigest()


def _save_checkpoint(path, meta, arrays):
    from ..io import atomic_write

    payload = dict(arrays)
    payload["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    with atomic_write(path, "wb") as f:
        np.savez(f, **payload)


def _load_checkpoint(path, fingerprint, fr, required=()):
    """Read a checkpoint written for the same inputs (``fingerprint``).

    Raises
    ------
    ValueError
        The file is not a readable wingphoto checkpoint (empty, truncated, random bytes,
        another program's .npz, an older version), lacks one of the ``required`` arrays,
        or was written for other frames, picks or options - naming the file and the way
        out.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"checkpoint {path} is not a regular file; {_WAY_OUT}")
    if path.stat().st_size == 0:
        raise ValueError(f"checkpoint {path} is empty (0 bytes: a run killed while creating it?); {_WAY_OUT}")
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            if not hasattr(z, "files") or "meta" not in z.files:
                raise KeyError("meta")
            meta = json.loads(bytes(z["meta"]).decode())
            if not isinstance(meta, dict):
                raise ValueError("meta is not a record")
            if meta.get("version") == _CHECKPOINT_VERSION and meta.get("fingerprint") == fingerprint:
                arrays = {k: z[k] for k in z.files if k != "meta"}
    except (OSError, EOFError, ValueError, KeyError, TypeError, AttributeError, zipfile.BadZipFile,
            UnicodeDecodeError) as exc:
        raise ValueError(f"checkpoint {path} is not a readable wingphoto checkpoint (truncated, corrupt or "
                         f"another program's file: {type(exc).__name__}: {exc}); {_WAY_OUT}") from None
    if meta.get("version") != _CHECKPOINT_VERSION:
        raise ValueError(f"checkpoint {path} was written by another version of wingphoto (format "
                         f"{meta.get('version')!r}, this one reads {_CHECKPOINT_VERSION}); {_WAY_OUT}")
    if meta.get("fingerprint") != fingerprint:
        raise ValueError(f"checkpoint {path} was written for other frames, picks or options; {_WAY_OUT}")
    sampled = meta.get("sampled")
    if not (isinstance(sampled, list) and all(isinstance(t, int) and 0 <= t < len(fr) for t in sampled)):
        raise ValueError(f"checkpoint {path} is incomplete (no record of the frames it was written for); {_WAY_OUT}")
    if meta.get("content") != _content(fr, sampled):
        raise ValueError(f"checkpoint {path} was written for other frames, picks or options (the content of "
                         f"frames {sampled} differs); {_WAY_OUT}")
    missing = [k for k in required if k not in arrays]
    if missing or "pass" not in meta or "next" not in meta:
        raise ValueError(f"checkpoint {path} is incomplete (lacks {missing or ['pass/next']}); {_WAY_OUT}")
    return meta, arrays


def _run_pass(fr, tracker, res, frames_order, direction, ckpt, progress, desc):
    """Run ``tracker`` over ``frames_order`` (a range of frame indices) into ``res``.

    ``ckpt`` (or None) is told of each tracked frame (``ckpt.completed(t)``) and asked to
    save (``ckpt.save()``) when the pass stops on an exception (Ctrl-C, a read error).
    With ``ckpt``, a Ctrl-C that arrives while a frame is being tracked takes effect when
    that frame is done (a second Ctrl-C at once): a checkpoint never holds half a frame.
    """
    from tqdm.auto import tqdm

    bar = tqdm(total=len(frames_order), disable=not progress, desc=desc, leave=False)
    done = 0
    first = frames_order[0] - direction if len(frames_order) else -1
    # the frame before the first one: a repeated frame is recognised on resume too
    tracker._prev = fr[first] if 0 <= first < len(fr) else None
    tracker._prev2 = fr[first - direction] if 0 <= first - direction < len(fr) else None
    try:
        with _whole_frames(ckpt is not None) as interrupted:
            for t in frames_order:
                tracker.step(fr[t], t, res, direction)
                done += 1
                if ckpt is not None:
                    ckpt.completed(t)
                if interrupted:
                    raise KeyboardInterrupt
                if done & 255 == 0:
                    bar.update(256)
    except BaseException:
        if ckpt is not None:
            ckpt.save()
        raise
    finally:
        bar.update(done & 255)
        bar.close()


@contextlib.contextmanager
def _whole_frames(enabled):
    """Defer a Ctrl-C (SIGINT) to the end of the frame under way; yields the list a deferred
    one is noted in. Only where Python's own handler is installed, in the main thread (not
    under a handler of the caller's); a second Ctrl-C raises at once."""
    pending = []
    if not (enabled and threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
        yield pending
        return

    def note(signum, frame):
        if pending:
            raise KeyboardInterrupt
        pending.append(signum)

    signal.signal(signal.SIGINT, note)
    try:
        yield pending
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


class _Checkpointer:
    """Saves ``state_fn()`` (meta with ``read``, the highest frame read, and arrays) to
    ``path`` every ``every`` completed frames and when asked (:meth:`save`)."""

    def __init__(self, path, fingerprint, every, state_fn, fr):
        self.fr = fr
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
        meta["sampled"] = _sampled_frames(min(int(meta["read"]), len(self.fr) - 1))
        meta["content"] = _content(self.fr, meta["sampled"])
        _save_checkpoint(self.path, meta, arrays)
        self.since = 0

