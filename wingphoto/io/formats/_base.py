"""Shared plumbing of the single-file camera formats (.cine, .mraw, video).

A *store* holds where each frame of one recording lives and how to decode it; it is what
:class:`wingphoto.io.Sequence` indexes. Every store exposes ``paths``, ``file_of``,
``page_of``, ``shape`` (H, W), ``dtype``, ``description``, ``read(j)``, ``where(j)``,
``close()`` and the recording's metadata: ``fps`` (float or None), ``frame_numbers``
((T,) int64, the camera's own image numbers), ``timestamps`` ((T,) float64 seconds or
None) and ``info`` (a dict of header values worth showing).
"""
from __future__ import annotations

import os
import threading
import weakref

import numpy as np


def file_signature(path):
    """(size, mtime_ns, inode) of ``path``: changes when the file is rewritten or replaced."""
    st = os.stat(path)
    return (int(st.st_size), int(st.st_mtime_ns), int(st.st_ino))


def changed_error(path, before, after):
    what = []
    if before[0] != after[0]:
        what.append(f"size {before[0]} -> {after[0]} bytes")
    if before[2] != after[2]:
        what.append("replaced by another file")
    elif before[1] != after[1]:
        what.append("modification time changed")
    return ValueError(
        f"{path} changed on disk after the sequence was opened ({', '.join(what)}); its frames "
        f"would be read from a different file than the one checked: open it again with read_sequence"
    )


def _close(state):
    mm = state.get("mm")
    state["mm"] = None
    if mm is not None and hasattr(mm, "_mmap") and mm._mmap is not None:
        try:
            mm._mmap.close()
        except (BufferError, ValueError):  # a frame view is still alive; the GC frees it
            pass


class FileStore:
    """A recording in one file, memory-mapped read-only on first access.

    Subclasses fill ``shape``, ``dtype``, ``fps``, ``frame_numbers``, ``timestamps``,
    ``info`` and implement :meth:`decode` (global frame index -> (H, W) array).
    """

    kind = "file"

    def __init__(self, path, *, memmap=True, data_path=None):
        self.path = os.fspath(path)
        self.data_path = os.fspath(data_path or path)
        self.paths = [type(path)(self.data_path) if not isinstance(path, str) else self.data_path]
        self.memmap = bool(memmap)
        self.signature = file_signature(self.data_path)
        self.description = f"{self.kind} file {self.path}"
        self.fps = None
        self.timestamps = None
        self.info = {}
        self._init_state()

    # -- the Sequence protocol -------------------------------------------------------
    def _finish(self, n_frames):
        self.file_of = np.zeros(n_frames, dtype=np.int64)
        self.page_of = np.arange(n_frames, dtype=np.int64)

    def _init_state(self):
        self._lock = threading.RLock()
        self._state = {"mm": None}
        self._finalizer = weakref.finalize(self, _close, self._state)

    def __getstate__(self):
        state = self.__dict__.copy()
        for key in ("_lock", "_state", "_finalizer"):
            state.pop(key)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._init_state()

    def close(self):
        with self._lock:
            _close(self._state)

    def where(self, j):
        return self.paths[0], int(j)

    def check_unchanged(self):
        now = file_signature(self.data_path)
        if now != self.signature:
            self.close()
            raise changed_error(self.data_path, self.signature, now)

    def bytes_at(self, offset, nbytes):
        """``nbytes`` raw bytes at ``offset`` (a memory-map view, or a plain read)."""
        try:
            self.check_unchanged()
        except FileNotFoundError:
            raise FileNotFoundError(f"{self.data_path} no longer exists; it was moved or deleted after opening") from None
        if self.memmap:
            with self._lock:
                if self._state["mm"] is None:
                    self._state["mm"] = np.memmap(self.data_path, dtype=np.uint8, mode="r")
                raw = self._state["mm"][offset : offset + nbytes]
        else:
            with open(self.data_path, "rb") as fh:
                fh.seek(offset)
                raw = np.frombuffer(fh.read(nbytes), dtype=np.uint8)
        if raw.size < nbytes:
            raise ValueError(
                f"{self.data_path} is truncated: frame data at byte {offset} needs {nbytes} bytes; "
                f"re-copy the file"
            )
        return raw

    def read(self, j):
        return self.decode(int(j))

    def decode(self, j):  # pragma: no cover - abstract
        raise NotImplementedError


def unpack_bits_msb(raw, count, bits):
    """Unpack ``count`` big-endian (MSB-first) ``bits``-bit codes from a byte array.

    Phantom's P10 and Photron's 12-bit packing both store pixels as one continuous
    MSB-first bit stream: 4 pixels in 5 bytes (10 bit), 2 pixels in 3 bytes (12 bit).
    """
    raw = np.asarray(raw, dtype=np.uint8)
    if bits == 12:
        b = raw[: count // 2 * 3].reshape(-1, 3).astype(np.uint16)
        out = np.empty((b.shape[0], 2), dtype=np.uint16)
        out[:, 0] = (b[:, 0] << 4) | (b[:, 1] >> 4)
        out[:, 1] = ((b[:, 1] & 0x0F) << 8) | b[:, 2]
        return out.reshape(-1)[:count]
    if bits == 10:
        b = raw[: count // 4 * 5].reshape(-1, 5).astype(np.uint16)
        out = np.empty((b.shape[0], 4), dtype=np.uint16)
        out[:, 0] = (b[:, 0] << 2) | (b[:, 1] >> 6)
        out[:, 1] = ((b[:, 1] & 0x3F) << 4) | (b[:, 2] >> 4)
        out[:, 2] = ((b[:, 2] & 0x0F) << 6) | (b[:, 3] >> 2)
        out[:, 3] = ((b[:, 3] & 0x03) << 8) | b[:, 4]
        return out.reshape(-1)[:count]
    raise ValueError(f"bits must be 10 or 12, got {bits}")


def unpack_12bit_lsb(raw, count):
    """Unpack Phantom's P12L: 2 pixels in 3 bytes, little-endian nibble order."""
    b = np.asarray(raw, dtype=np.uint8)[: count // 2 * 3].reshape(-1, 3).astype(np.uint16)
    out = np.empty((b.shape[0], 2), dtype=np.uint16)
    out[:, 0] = b[:, 0] | ((b[:, 1] & 0x0F) << 8)
    out[:, 1] = (b[:, 1] >> 4) | (b[:, 2] << 4)
    return out.reshape(-1)[:count]
