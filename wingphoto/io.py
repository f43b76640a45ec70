"""Files in and out: image sequences, Bouguet toolbox .mat files, tracks and points tables.

Three groups of functions, one per kind of file:

- **Image sequences** - :func:`read_sequence` opens a folder, a glob pattern, a
  multi-page TIFF or a list of files as a lazy :class:`Sequence` of grayscale frames
  (read on access, memory-mapped where the TIFF allows it, 8/16-bit kept as stored).
- **Bouguet toolbox** - :func:`load_bouguet_calib` / :func:`save_bouguet_calib` for a
  single camera's ``Calib_Results.mat``, :func:`load_bouguet_stereo` /
  :func:`save_bouguet_stereo` for ``Calib_Results_stereo.mat``, with the toolbox's own
  variable names so MATLAB users can move results back and forth.
- **Tables** - :func:`write_tracks_csv` / :func:`read_tracks_csv` and
  :func:`write_points_csv` / :func:`read_points_csv` round-trip the tracks and 3D points
  DataFrames exactly (dtypes, NaN, empty tables); :func:`empty_tracks` and
  :func:`empty_points` give the empty tables with the right dtypes.

Outputs are written atomically (a temporary file in the same folder, then an atomic
rename), so an interrupted run never leaves a half-written result behind. Source images
are only ever opened read-only.

Conventions (pixel origin, frames, units, names): ``docs/conventions.md``.
"""
from __future__ import annotations

import contextlib
import io as _stdio
import logging
import operator
import os
import re
import tempfile
import threading
import warnings
import weakref
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .camera import Camera, StereoRig, rodrigues, rodrigues_inverse

logger = logging.getLogger(__name__)

__all__ = [
    "atomic_write",
    "find_samples",
    # image sequences
    "IMAGE_EXTENSIONS",
    "Sequence",
    "read_sequence",
    # Bouguet toolbox
    "BouguetCalib",
    "load_bouguet_calib",
    "save_bouguet_calib",
    "load_bouguet_stereo",
    "save_bouguet_stereo",
    # tables
    "TRACK_COLUMNS",
    "POINT_COLUMNS",
    "empty_tracks",
    "empty_points",
    "write_tracks_csv",
    "read_tracks_csv",
    "write_points_csv",
    "read_points_csv",
]


@contextlib.contextmanager
def atomic_write(path, mode="wb", **open_kwargs):
    """Open a temporary file next to ``path`` and rename it over ``path`` on success.

    Parameters
    ----------
    path : str or Path
        Destination file; its folder must exist (it is created if missing).
    mode : str
        ``"wb"`` or ``"w"`` (text); extra keyword arguments go to :func:`open`.

    Yields
    ------
    file object
        Write to it; on an exception the temporary file is removed and ``path`` is
        left as it was.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "out.txt"
    >>> with atomic_write(p, "w") as f:
    ...     _ = f.write("done")
    >>> p.read_text()
    'done'
    """
    path = Path(path)
    if mode not in ("wb", "w"):
        raise ValueError(f"mode must be 'wb' or 'w', got {mode!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode, **open_kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


# =====================================================================================
# Image sequences
# =====================================================================================

#: File extensions :func:`read_sequence` picks up when given a folder.
IMAGE_EXTENSIONS = (".tif", ".tiff", ".png", ".jpg", ".jpeg", ".bmp")
_TIFF_SUFFIXES = {".tif", ".tiff"}
_SUFFIX_KIND = {".tif": "TIFF", ".tiff": "TIFF", ".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".bmp": "BMP"}
_GLOB_CHARS = re.compile(r"[*?\[]")
_MAX_OPEN_FILES = 8  # open TIFF handles / memory maps kept per sequence (least recently used)
_LUMA = (0.299, 0.587, 0.114)  # ITU-R BT.601 weights, as cv2.cvtColor and MATLAB rgb2gray


def _natural_key(path):
    """Sort key that orders digit runs by value: ``frame2`` before ``frame10``."""
    text = str(path)
    parts = re.split(r"(\d+)", text)
    return [int(p) if i % 2 else p.casefold() for i, p in enumerate(parts)], text


def _resolve_source(source):
    """Turn a folder / glob pattern / file / list of files into (paths, description)."""
    if isinstance(source, (str, os.PathLike)):
        text = os.fspath(source)
        path = Path(text).expanduser()
        if path.is_dir():
            files = [
                p for p in path.iterdir()
                if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in IMAGE_EXTENSIONS
            ]
            if not files:
                raise FileNotFoundError(
                    f"no image files ({', '.join(IMAGE_EXTENSIONS)}) in folder {path}; check the "
                    f"folder, or pass a glob pattern such as '{path / 'frame*.tif'}'"
                )
            kinds = sorted({_SUFFIX_KIND[p.suffix.lower()] for p in files})
            if len(kinds) > 1:
                raise ValueError(
                    f"folder {path} mixes image types ({', '.join(kinds)}); pass a glob pattern "
                    f"that selects one of them, such as '{path / '*.tif'}'"
                )
            return sorted(files, key=_natural_key), f"folder {path}"
        if path.is_file():
            return [path], f"file {path}"
        if _GLOB_CHARS.search(text):
            import glob

            matches = [Path(p) for p in glob.glob(os.path.expanduser(text), recursive=True) if os.path.isfile(p)]
            if not matches:
                raise FileNotFoundError(
                    f"no files match the pattern {text!r}; check the folder and the pattern "
                    f"(for example 'frames/frame*.tif')"
                )
            return sorted(matches, key=_natural_key), f"pattern {text!r}"
        raise FileNotFoundError(
            f"{text!r} is not an existing file or folder and contains no glob wildcard; "
            f"check the path (source may be a folder, a glob pattern, a multi-page TIFF or a list of files)"
        )
    if isinstance(source, np.ndarray) or not hasattr(source, "__iter__"):
        raise ValueError(
            f"source must be a folder, a glob pattern, an image file or a list of files, "
            f"got {type(source).__name__}; frames already in memory need no read_sequence"
        )
    paths = []
    for item in source:
        if not isinstance(item, (str, os.PathLike)):
            raise ValueError(f"source list must hold file paths, got an item of type {type(item).__name__}")
        p = Path(item).expanduser()
        if not p.is_file():
            raise FileNotFoundError(f"file {p} in the source list does not exist; check the path")
        paths.append(p)
    if not paths:
        raise ValueError("source is an empty list of files; pass at least one file")
    return paths, f"{len(paths)} listed file(s)"


@contextlib.contextmanager
def _tifffile_errors():
    """Collect the errors tifffile logs (it logs, rather than raises, on truncated IFD chains)."""
    messages = []

    class _Collect(logging.Handler):
        def emit(self, record):
            messages.append(record.getMessage())

    handler = _Collect(level=logging.ERROR)
    tiff_logger = logging.getLogger("tifffile")
    tiff_logger.addHandler(handler)
    try:
        yield messages
    finally:
        tiff_logger.removeHandler(handler)


def _colour_error(path, shape):
    return ValueError(
        f"{path} holds colour frames (shape {tuple(shape)}); wingphoto works on grayscale "
        f"frames: convert the files to grayscale, or pass as_gray=True to read_sequence to "
        f"convert them on reading (ITU-R BT.601 luminance, dtype kept)"
    )


def _to_gray(arr, path, as_gray, channel_order):
    """Check a decoded frame is 2-D grayscale, converting colour when ``as_gray``."""
    if arr.ndim == 2:
        return arr
    if arr.ndim == 3 and arr.shape[2] in (2, 3, 4):
        if not as_gray:
            raise _colour_error(path, arr.shape)
        if arr.shape[2] == 2:  # gray + alpha
            return np.ascontiguousarray(arr[..., 0])
        rgb = arr[..., :3] if channel_order == "rgb" else arr[..., 2::-1]
        gray = rgb.astype(np.float64) @ np.array(_LUMA)
        if np.issubdtype(arr.dtype, np.integer):
            info = np.iinfo(arr.dtype)
            gray = np.clip(np.rint(gray), info.min, info.max)
        return gray.astype(arr.dtype)
    raise ValueError(
        f"{path} holds an image of shape {arr.shape}, not a 2-D grayscale frame; "
        f"export the frames as single-channel 2-D images"
    )


def _pillow_loads(data):
    """True when Pillow decodes ``data`` completely (used to confirm an odd file ending)."""
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - Pillow comes with scikit-image
        return False
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(_stdio.BytesIO(data)) as im:
                im.load()
        return True
    except Exception:
        return False


def _check_complete(path, data):
    """Raise ValueError when a PNG/JPEG/BMP file is visibly truncated.

    OpenCV decodes a truncated JPEG into a partly grey image and only complains on
    stderr, so the file's end marker is checked before decoding.
    """
    kind = _SUFFIX_KIND.get(path.suffix.lower())
    problem = None
    if kind == "PNG" and data[:8] == b"\x89PNG\r\n\x1a\n":
        if data.rfind(b"IEND\xaeB`\x82", max(0, len(data) - 65536)) < 0:
            problem = "its IEND end chunk is missing"
    elif kind == "JPEG" and data[:2] == b"\xff\xd8":
        if data.rstrip(b"\x00")[-2:] != b"\xff\xd9" and not _pillow_loads(data):
            problem = "its end-of-image marker is missing"
    elif kind == "BMP" and data[:2] == b"BM" and len(data) >= 6:
        declared = int.from_bytes(data[2:6], "little")
        if len(data) < declared:
            problem = f"it has {len(data)} bytes but its header declares {declared}"
    if problem:
        raise ValueError(f"image file {path} is truncated ({problem}); re-copy or re-export it")


def _decode_image_file(path, as_gray):
    """Decode one PNG/JPEG/BMP (any OpenCV format) file, unchanged bit depth."""
    import cv2

    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"frame file {path} no longer exists; it was moved or deleted after opening") from None
    except OSError as exc:
        raise ValueError(f"cannot read image file {path} ({exc}); check its permissions") from exc
    _check_complete(path, data)
    arr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if arr is None:
        raise ValueError(
            f"cannot decode image file {path}: it is corrupt or not a supported image "
            f"({', '.join(IMAGE_EXTENSIONS)}); re-export it"
        )
    return _to_gray(arr, path, as_gray, "bgr")


def _scan_tiff(path, as_gray):
    """Read a TIFF file's headers (no pixel data).

    Returns
    -------
    frames : list of (page_index, data_offset)
        ``data_offset`` is the file offset of the page's raw pixels when they are stored
        uncompressed and contiguous (read straight or memory-mapped), else -1 (decoded
        by tifffile on access).
    shape : (H, W)
    dtype : numpy dtype (native byte order)
    byteorder : '<' or '>'
    """
    import tifffile

    size = path.stat().st_size
    pages = []
    try:
        with _tifffile_errors() as errors, tifffile.TiffFile(path) as tif:
            byteorder = tif.byteorder
            tif.pages.cache = False
            for k, page in enumerate(tif.pages):
                end = max((o + c for o, c in zip(page.dataoffsets, page.databytecounts)), default=0)
                pages.append(
                    dict(
                        index=k,
                        hw=(int(page.imagelength), int(page.imagewidth)),
                        depth=int(page.imagedepth),
                        samples=int(page.samplesperpixel),
                        shape=tuple(page.shape),
                        dtype=page.dtype,
                        palette=int(page.photometric) == 3,
                        end=end,
                        offset=int(page.dataoffsets[0]) if page.is_final and page.dataoffsets else -1,
                        nbytes=int(page.nbytes),
                    )
                )
            imagej_images = 0
            if len(pages) == 1 and tif.is_imagej and tif.imagej_metadata:
                imagej_images = int(tif.imagej_metadata.get("images", 1))
    except (FileNotFoundError, PermissionError):
        raise
    except Exception as exc:
        with open(path, "rb") as fh:
            magic = fh.read(4)
        if magic not in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
            raise ValueError(
                f"cannot read TIFF file {path}: it is not a TIFF (it starts with {magic!r}); "
                f"check the file and its extension"
            ) from exc
        raise ValueError(f"TIFF file {path} is truncated or corrupt ({exc}); re-copy or re-export it") from exc
    if errors:
        raise ValueError(f"TIFF file {path} is truncated or corrupt (tifffile: {errors[0]}); re-copy or re-export it")
    if not pages:
        raise ValueError(f"TIFF file {path} contains no images")
    first = pages[0]
    frames = []
    for p in pages:
        where = f"{path}" + (f" (page {p['index']})" if len(pages) > 1 else "")
        if p["end"] > size:
            raise ValueError(
                f"TIFF file {path} is truncated: page {p['index']} needs {p['end']} bytes but the "
                f"file has {size}; re-copy or re-export it"
            )
        if p["dtype"] is None:
            raise ValueError(f"{where} uses a pixel format numpy cannot hold; re-export as 8- or 16-bit grayscale")
        if p["palette"]:
            raise ValueError(f"{where} is a palette (indexed colour) image; convert the files to grayscale")
        if p["depth"] > 1:
            raise ValueError(f"{where} is a volume of depth {p['depth']}, not a 2-D frame; export 2-D frames")
        if p["samples"] > 1 and not as_gray:
            raise _colour_error(where, p["shape"])
        if p["hw"] != first["hw"]:
            raise ValueError(
                f"{where} has frames of shape (H, W) = {p['hw']} but page 0 of the same file has "
                f"{first['hw']}; all frames of a sequence must have the same size: split the file"
            )
        if p["dtype"] != first["dtype"]:
            raise ValueError(
                f"{where} holds {p['dtype']} pixels but page 0 holds {first['dtype']}; "
                f"convert the file to one bit depth"
            )
        frames.append((p["index"], p["offset"] if p["samples"] == 1 else -1))
    if imagej_images > 1 and first["offset"] >= 0 and first["samples"] == 1:
        # ImageJ files over 4 GB store one IFD and the frames back to back after it
        stride = first["nbytes"]
        if first["offset"] + imagej_images * stride <= size:
            frames = [(0, first["offset"] + k * stride) for k in range(imagej_images)]
    return frames, first["hw"], np.dtype(first["dtype"]).newbyteorder("="), byteorder


def _close_handles(handles):
    for h in list(handles.values()):
        with contextlib.suppress(Exception):
            if hasattr(h, "close"):
                h.close()
    handles.clear()


class _FrameStore:
    """The frames of a list of files: where each frame lives, and the open file handles.

    Shared by a :class:`Sequence` and all its slices. Headers are read here; pixels are
    read by :meth:`read`.
    """

    def __init__(self, paths, *, as_gray, memmap, description):
        self.paths = list(paths)
        self.as_gray = bool(as_gray)
        self.memmap = bool(memmap)
        self.description = description
        self.is_tiff = [p.suffix.lower() in _TIFF_SUFFIXES for p in self.paths]
        self.byteorder = ["="] * len(self.paths)
        self.frames_in_file = [1] * len(self.paths)
        file_of, page_of, offset_of = [], [], []
        self.shape = None  # (H, W)
        self.dtype = None
        self.reference = None  # description of the frame that fixed shape and dtype
        for i, path in enumerate(self.paths):
            if self.is_tiff[i]:
                frames, hw, dtype, byteorder = _scan_tiff(path, self.as_gray)
                self.byteorder[i] = byteorder
                self.frames_in_file[i] = len(frames)
                self._check(path, hw, dtype)
                for page, offset in frames:
                    file_of.append(i)
                    page_of.append(page)
                    offset_of.append(offset)
            else:
                if self.shape is None:  # the first frame fixes shape and dtype: decode it
                    arr = _decode_image_file(path, self.as_gray)
                    self._check(path, arr.shape, arr.dtype)
                file_of.append(i)
                page_of.append(0)
                offset_of.append(-1)
        self.file_of = np.asarray(file_of, dtype=np.int64)
        self.page_of = np.asarray(page_of, dtype=np.int64)
        self.offset_of = np.asarray(offset_of, dtype=np.int64)
        self._init_handles()

    # ------------------------------------------------------------ housekeeping
    def _init_handles(self):
        self._lock = threading.RLock()
        self._handles = OrderedDict()
        self._finalizer = weakref.finalize(self, _close_handles, self._handles)

    def __getstate__(self):
        state = self.__dict__.copy()
        for key in ("_lock", "_handles", "_finalizer"):
            state.pop(key)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._init_handles()

    def close(self):
        with self._lock:
            _close_handles(self._handles)

    def _handle(self, i, opener):
        """LRU cache of open TiffFile handles / memory maps, keyed by file index."""
        h = self._handles.get(i)
        if h is None:
            h = opener(self.paths[i])
            self._handles[i] = h
            while len(self._handles) > _MAX_OPEN_FILES:
                _, old = self._handles.popitem(last=False)
                if hasattr(old, "close"):
                    old.close()
        else:
            self._handles.move_to_end(i)
        return h

    def _check(self, where, shape, dtype):
        shape = tuple(int(s) for s in shape)
        if self.shape is None:
            self.shape, self.dtype, self.reference = shape, np.dtype(dtype), str(where)
            return
        if shape != self.shape:
            raise ValueError(
                f"{where} has frames of shape (H, W) = {shape} but {self.reference} has "
                f"{self.shape}; all frames of a sequence must have the same size: remove or "
                f"crop the odd file(s)"
            )
        if np.dtype(dtype) != self.dtype:
            raise ValueError(
                f"{where} holds {np.dtype(dtype)} pixels but {self.reference} holds {self.dtype}; "
                f"all frames must have the same bit depth: convert the odd file(s)"
            )

    # ------------------------------------------------------------------ pixels
    def where(self, j):
        """(path, page) of global frame ``j``."""
        return self.paths[self.file_of[j]], int(self.page_of[j])

    def read(self, j):
        """Read global frame ``j`` as a new, writable (H, W) array."""
        i = int(self.file_of[j])
        path = self.paths[i]
        if not self.is_tiff[i]:
            arr = _decode_image_file(path, self.as_gray)
        elif self.offset_of[j] >= 0:
            arr = self._read_raw(i, int(self.offset_of[j]))
        else:
            arr = self._read_page(i, int(self.page_of[j]))
        where = path if self.frames_in_file[i] == 1 else f"{path} (page {int(self.page_of[j])})"
        self._check(where, arr.shape, arr.dtype)
        return arr

    def _read_raw(self, i, offset):
        path = self.paths[i]
        stored = self.dtype.newbyteorder(self.byteorder[i])
        nbytes = self.shape[0] * self.shape[1] * stored.itemsize
        try:
            if self.memmap and self.frames_in_file[i] > 1:
                with self._lock:
                    mm = self._handle(i, lambda p: np.memmap(p, dtype=np.uint8, mode="r"))
                raw = mm[offset : offset + nbytes]
            else:
                with open(path, "rb") as fh:
                    fh.seek(offset)
                    raw = fh.read(nbytes)
        except FileNotFoundError:
            raise FileNotFoundError(f"frame file {path} no longer exists; it was moved or deleted after opening") from None
        except (OSError, ValueError) as exc:
            raise ValueError(f"cannot read TIFF file {path} ({exc}); re-copy or re-export it") from exc
        if len(raw) < nbytes:
            raise ValueError(f"TIFF file {path} is truncated (frame data at byte {offset} is cut short); re-copy or re-export it")
        frame = np.frombuffer(raw, dtype=stored).reshape(self.shape)
        return frame.astype(self.dtype, copy=True)

    def _read_page(self, i, page):
        import tifffile

        path = self.paths[i]
        try:
            with self._lock, _tifffile_errors() as errors:
                tif = self._handle(i, tifffile.TiffFile)
                tiff_page = tif.pages[page]
                arr = tiff_page.asarray()
                separate = int(tiff_page.planarconfig) == 2 and arr.ndim == 3
        except FileNotFoundError:
            raise FileNotFoundError(f"frame file {path} no longer exists; it was moved or deleted after opening") from None
        except Exception as exc:
            raise ValueError(f"cannot decode page {page} of TIFF file {path} ({exc}); re-copy or re-export it") from exc
        if errors:
            raise ValueError(f"TIFF file {path} is corrupt (tifffile: {errors[0]}); re-copy or re-export it")
        if separate:
            arr = np.moveaxis(arr, 0, -1)  # planar (separate) samples -> channels last
        return _to_gray(np.asarray(arr), path, self.as_gray, "rgb")


class Sequence:
    """A lazy stack of grayscale frames read from files on access.

    Made by :func:`read_sequence`; behaves like a read-only ``(T, H, W)`` array whose
    frames are decoded only when indexed or iterated, so sequences far larger than
    memory can be tracked frame by frame.

    Attributes
    ----------
    shape : tuple of int
        ``(T, H, W)``: frames, rows, columns.
    dtype : numpy.dtype
        Pixel type as stored (``uint8`` and ``uint16`` are not rescaled).
    frame_size : (int, int)
        ``(width, height)`` in pixels, the order of :attr:`wingphoto.Camera.image_size`.
    paths : list of pathlib.Path
        Files holding the frames, in frame order (one entry for a multi-page TIFF).

    Notes
    -----
    - ``seq[i]`` (negative ``i`` allowed) returns a new, writable ``(H, W)`` array;
      the source file is never modified.
    - ``seq[a:b:c]`` and ``seq[[i, j, ...]]`` return a lazy sub-``Sequence``.
    - Iterating streams the frames one at a time; :meth:`to_array` (or
      ``np.asarray(seq)``) stacks them into memory on request.
    - Uncompressed TIFF frames are memory-mapped (multi-page files) or read straight
      from their byte offset; compressed TIFFs are decoded page by page through a
      handle kept open (:meth:`close` releases it; the sequence reopens on demand).
    - Frame sizes and bit depths of TIFF files are checked from their headers when the
      sequence is opened; other formats are checked as each frame is read, or all at
      once by :meth:`validate`.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np, tifffile
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> for t in (1, 2, 10):
    ...     tifffile.imwrite(folder / f"frame{t}.tif", np.full((23, 21), t, np.uint16))
    >>> seq = read_sequence(folder / "frame*.tif")
    >>> seq.shape, seq.dtype, seq.frame_size
    ((3, 23, 21), dtype('uint16'), (21, 23))
    >>> [p.name for p in seq.paths]
    ['frame1.tif', 'frame2.tif', 'frame10.tif']
    >>> int(seq[-1][0, 0]), len(seq[1:])
    (10, 2)
    """

    def __init__(self, store, index):
        self._store = store
        index = np.asarray(index, dtype=np.int64)
        index.setflags(write=False)
        self._index = index

    # ------------------------------------------------------------ array-like
    def __len__(self):
        return len(self._index)

    @property
    def shape(self):
        """``(T, H, W)``."""
        return (len(self._index),) + tuple(self._store.shape)

    @property
    def ndim(self):
        """Always 3, as for a ``(T, H, W)`` array."""
        return 3

    @property
    def dtype(self):
        """Pixel dtype as stored in the files."""
        return self._store.dtype

    @property
    def frame_size(self):
        """``(width, height)`` in pixels."""
        h, w = self._store.shape
        return (w, h)

    @property
    def paths(self):
        """Files holding this sequence's frames, in frame order, each listed once."""
        seen = dict.fromkeys(int(i) for i in self._store.file_of[self._index])
        return [self._store.paths[i] for i in seen]

    def locate(self, i):
        """Return ``(path, page)`` of frame ``i``: the file and its page (0 for one-frame files).

        Parameters
        ----------
        i : int
            Frame index in this sequence (negative counts from the end).
        """
        return self._store.where(self._index[self._frame_index(i)])

    def _frame_index(self, key):
        n = len(self._index)
        i = operator.index(key)
        if not -n <= i < n:
            raise IndexError(f"frame index {key} is out of range for a sequence of {n} frames")
        return i % n

    def __getitem__(self, key):
        if isinstance(key, (int, np.integer)) and not isinstance(key, (bool, np.bool_)):
            return self._store.read(self._index[self._frame_index(key)])
        if isinstance(key, slice):
            return Sequence(self._store, self._index[key])
        if isinstance(key, tuple):
            raise TypeError(
                "a Sequence takes one index (frames); crop after reading, e.g. seq[i][rows, cols]"
            )
        arr = np.asarray(key)
        if arr.dtype == bool and arr.shape == self._index.shape:
            return Sequence(self._store, self._index[arr])
        if arr.ndim == 1 and (arr.size == 0 or np.issubdtype(arr.dtype, np.integer)):
            arr = arr.astype(np.int64)
            n = len(self._index)
            if arr.size and (arr.min() < -n or arr.max() >= n):
                raise IndexError(f"frame indices {arr.min()}..{arr.max()} are out of range for a sequence of {n} frames")
            return Sequence(self._store, self._index[arr])
        raise TypeError(
            f"Sequence indices must be integers, slices, 1-D integer arrays or boolean masks of "
            f"length {len(self)}, got {type(key).__name__}"
        )

    def __iter__(self):
        for j in self._index:
            yield self._store.read(j)

    def to_array(self, *, progress=False):
        """Read every frame into one in-memory ``(T, H, W)`` array.

        Parameters
        ----------
        progress : bool, optional
            Show a ``tqdm`` progress bar (default False).

        Returns
        -------
        frames : (T, H, W) ndarray
            A new array of :attr:`dtype`.
        """
        from tqdm.auto import tqdm

        out = np.empty(self.shape, dtype=self.dtype)
        for t, frame in enumerate(tqdm(self, total=len(self), disable=not progress, desc="reading frames")):
            out[t] = frame
        return out

    def __array__(self, dtype=None, copy=None):
        arr = self.to_array()
        return arr if dtype is None else arr.astype(dtype, copy=False)

    def validate(self, *, progress=False):
        """Decode every frame now, raising on the first unreadable or mismatched one.

        TIFF headers are checked when the sequence is opened; PNG/JPEG/BMP frames are
        only checked as they are read. Call this before a long run to fail early.

        Parameters
        ----------
        progress : bool, optional
            Show a ``tqdm`` progress bar (default False).

        Returns
        -------
        self : Sequence
            For chaining: ``seq = read_sequence(folder).validate()``.

        Raises
        ------
        ValueError
            Naming the first truncated, corrupt, colour or differently sized file.
        """
        from tqdm.auto import tqdm

        for _ in tqdm(self, total=len(self), disable=not progress, desc="validating frames"):
            pass
        return self

    def close(self):
        """Release open file handles and memory maps (they reopen on the next access)."""
        self._store.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        t, h, w = self.shape
        return f"<Sequence of {t} frames, {h}x{w} (H x W) {self.dtype}, from {self._store.description}>"


def read_sequence(source, *, as_gray=False, memmap=True):
    """Open an image sequence lazily: frames are read from disk only when accessed.

    Parameters
    ----------
    source : str, Path or list of str/Path
        One of

        - a folder: its files with an extension in :data:`IMAGE_EXTENSIONS` (hidden
          files skipped; one image type per folder), in natural order;
        - a glob pattern (``"run3/cam_left_*.tif"``, ``**`` allowed), natural order:
          ``frame2`` comes before ``frame10``;
        - a single file: a multi-page TIFF (one frame per page) or one image;
        - a list of files, kept in the order given (multi-page TIFFs contribute all
          their pages).
    as_gray : bool, optional
        Convert colour (RGB/RGBA) frames to grayscale on reading with the ITU-R BT.601
        weights (0.299 R + 0.587 G + 0.114 B, rounded, dtype kept). Default False:
        colour frames raise a ValueError.
    memmap : bool, optional
        Memory-map uncompressed multi-page TIFFs (default True). False reads each
        frame with a plain file read instead.

    Returns
    -------
    seq : Sequence
        Lazy ``(T, H, W)`` stack; see :class:`Sequence`.

    Raises
    ------
    FileNotFoundError
        Nothing matches the pattern, the folder holds no images, or a path does not exist.
    ValueError
        A file is unreadable, truncated or corrupt; a frame's size or bit depth differs
        from the first frame's (the message names the first offending file and both
        shapes); frames are in colour and ``as_gray`` is False.

    Notes
    -----
    Pixel values are never rescaled: 8-bit frames come back as ``uint8`` and 16-bit
    frames (including 10-14-bit camera data stored in 16 bits) as ``uint16``. TIFF
    headers are read at once (cheap: no pixel data) to count frames and check sizes,
    bit depth, colour and truncation; for PNG/JPEG/BMP only the first frame is
    decoded at opening, the rest are checked as they are read (or by
    :meth:`Sequence.validate`). Files are opened read-only and never modified.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np, tifffile
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "stack.tif"
    >>> frames = np.arange(4 * 23 * 21, dtype=np.uint16).reshape(4, 23, 21)
    >>> tifffile.imwrite(path, frames, photometric="minisblack")
    >>> seq = read_sequence(path)
    >>> len(seq), seq.shape, seq.dtype
    (4, (4, 23, 21), dtype('uint16'))
    >>> int(seq[-1][0, 0]), seq[::2].shape
    (1449, (2, 23, 21))
    """
    paths, description = _resolve_source(source)
    store = _FrameStore(paths, as_gray=as_gray, memmap=memmap, description=description)
    logger.debug("opened %d frames of %s %s from %s", len(store.file_of), store.shape, store.dtype, description)
    return Sequence(store, np.arange(len(store.file_of)))


# =====================================================================================
# Bouguet Camera Calibration Toolbox .mat files
# =====================================================================================

_MATLAB_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,62}$")
#: Uncertainty keys of one camera and their shapes (the toolbox's ``*_error`` variables).
_CAMERA_ERROR_SHAPES = {"fc": (2,), "cc": (2,), "alpha_c": (), "kc": (5,)}
_STEREO_ERROR_SHAPES = {
    **{f"{k}_{side}": s for side in ("left", "right") for k, s in _CAMERA_ERROR_SHAPES.items()},
    "om": (3,),
    "T": (3,),
}


def _readonly(arr):
    arr = np.array(arr, dtype=np.float64)
    arr.setflags(write=False)
    return arr


def _loadmat(path):
    import scipy.io

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"MATLAB file {path} not found; check the path")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy warns about odd headers of old files
            return scipy.io.loadmat(path, mat_dtype=True, squeeze_me=False)
    except NotImplementedError as exc:  # v7.3 (HDF5) files
        raise ValueError(
            f"{path} is a MATLAB v7.3 (HDF5) file, which scipy cannot read; in MATLAB "
            f"re-save it with save('{path.name}', '-v7')"
        ) from exc
    except Exception as exc:
        raise ValueError(f"cannot read {path} as a MATLAB .mat file ({exc}); check the file") from exc


def _mat_vector(m, name, size, path):
    """A MATLAB variable as a flat float64 vector of ``size`` elements (None when absent)."""
    if name not in m:
        return None
    v = np.asarray(m[name], dtype=np.float64).reshape(-1)
    sizes = (size,) if np.isscalar(size) else tuple(size)
    if v.size not in sizes:
        raise ValueError(f"{path}: variable {name} has {v.size} elements, expected {' or '.join(map(str, sizes))}")
    return v


def _mat_kc(m, name, path):
    """kc (or kc_error) padded to 5 coefficients: the toolbox also writes 4 (k3 = 0)."""
    kc = _mat_vector(m, name, (4, 5), path)
    if kc is not None and kc.size == 4:
        kc = np.append(kc, 0.0)
    return kc


def _mat_camera(m, suffix, path):
    """Camera and its uncertainty dict from fc{suffix}, cc{suffix}, ... variables."""
    missing = [n + suffix for n in ("fc", "cc") if n + suffix not in m]
    if missing:
        raise ValueError(
            f"{path} lacks the variable(s) {', '.join(missing)}; expected a Bouguet toolbox "
            f"calibration result (Calib_Results{'_stereo' if suffix else ''}.mat)"
        )
    fc = _mat_vector(m, "fc" + suffix, 2, path)
    cc = _mat_vector(m, "cc" + suffix, 2, path)
    kc = _mat_kc(m, "kc" + suffix, path)
    alpha = _mat_vector(m, "alpha_c" + suffix, 1, path)
    image_size = None
    if "nx" in m and "ny" in m:
        image_size = (int(np.asarray(m["nx"]).reshape(-1)[0]), int(np.asarray(m["ny"]).reshape(-1)[0]))
    cam = Camera(
        fc=fc,
        cc=cc,
        kc=np.zeros(5) if kc is None else kc,
        alpha_c=0.0 if alpha is None else float(alpha[0]),
        image_size=image_size,
    )
    unc = {}
    for key, shape in _CAMERA_ERROR_SHAPES.items():
        name = f"{key}{suffix}_error"
        if key == "kc":
            v = _mat_kc(m, name, path)
        else:
            v = _mat_vector(m, name, max(1, int(np.prod(shape))), path)
        if v is not None:
            unc[key] = float(v[0]) if shape == () else _readonly(v)
    return cam, unc


def _column(v):
    """MATLAB column vector (n, 1) float64."""
    return np.asarray(v, dtype=np.float64).reshape(-1, 1)


def _scalar(v):
    return np.asarray(v, dtype=np.float64).reshape(1, 1)


def _camera_variables(cam, suffix):
    return {
        f"fc{suffix}": _column(cam.fc),
        f"cc{suffix}": _column(cam.cc),
        f"kc{suffix}": _column(cam.kc),
        f"alpha_c{suffix}": _scalar(cam.alpha_c),
        f"KK{suffix}": np.asarray(cam.K, dtype=np.float64),
    }


def _error_variables(uncertainty, shapes, name_of, what):
    if uncertainty is None:
        return {}
    if not hasattr(uncertainty, "items"):
        raise ValueError(f"uncertainty must be a dict of 3-sigma arrays, got {type(uncertainty).__name__}")
    unknown = sorted(set(uncertainty) - set(shapes))
    if unknown:
        raise ValueError(f"uncertainty has unknown key(s) {unknown}; {what} keys are {sorted(shapes)}")
    out = {}
    for key, value in uncertainty.items():
        v = np.asarray(value, dtype=np.float64).reshape(-1)
        size = max(1, int(np.prod(shapes[key])))
        if key.startswith("kc") and v.size == 4:
            v = np.append(v, 0.0)
        if v.size != size:
            raise ValueError(f"uncertainty[{key!r}] must have {size} element(s), got shape {np.shape(value)}")
        out[name_of(key)] = _scalar(v[0]) if shapes[key] == () else _column(v)
    return out


def _add_extra(data, extra):
    if extra is None:
        return data
    if not hasattr(extra, "items"):
        raise ValueError(f"extra must be a dict of MATLAB variable names to values, got {type(extra).__name__}")
    for name, value in extra.items():
        if not isinstance(name, str) or not _MATLAB_NAME.match(name):
            raise ValueError(
                f"extra variable name {name!r} is not a valid MATLAB name (a letter, then up to "
                f"62 letters, digits or underscores)"
            )
        if name in data:
            raise ValueError(f"extra variable {name!r} would overwrite a calibration variable; rename it")
        data[name] = value
    return data


def _savemat(path, data):
    import scipy.io

    with atomic_write(path, "wb") as f:
        scipy.io.savemat(f, data, format="5", oned_as="column")


def _image_size_variables(size):
    if size is None:
        return {}
    return {"nx": _scalar(size[0]), "ny": _scalar(size[1])}


@dataclass(frozen=True, eq=False)
class BouguetCalib:
    """A single-camera calibration read from the toolbox's ``Calib_Results.mat``.

    Per-view entries (``corners``, ``grid``, ``omc``, ``Tc``, ``n_sq_x``, ``n_sq_y``)
    are tuples with one item per calibration image, ``None`` where the view is inactive
    or its data are missing.

    Attributes
    ----------
    camera : Camera
        fc, cc, kc, alpha_c and image_size (from nx, ny).
    uncertainty : dict
        3-sigma uncertainties as the toolbox stores them in ``fc_error``, ``cc_error``,
        ``alpha_c_error`` (float), ``kc_error``; keys ``fc``, ``cc``, ``alpha_c``,
        ``kc``, each absent when the file lacks it.
    err_std : (2,) ndarray
        Standard deviation of the reprojection error in x and y, px (NaN if absent).
    corners : tuple of (N, 2) ndarray or None
        Extracted corners ``x_k`` as rows, px, origin at the centre of the top-left
        pixel (the toolbox's and wingphoto's convention: no shift applied).
    grid : tuple of (N, 3) ndarray or None
        Corresponding grid points ``X_k`` as rows, mm, in the board frame.
    omc, Tc : tuple of (3,) ndarray or None
        Board pose per view: ``X_camera = R(omc) X_grid + Tc`` (mm).
    active : (n_views,) ndarray of bool
        The toolbox's ``active_images``.
    image_size : (int, int) or None
        ``(nx, ny)``, width and height in px.
    dX, dY : float
        Square size of the board in mm (NaN if absent).
    n_sq_x, n_sq_y : tuple of int or None
        Number of squares along the board's x and y axes, per view.
    """

    camera: Camera
    uncertainty: dict
    err_std: np.ndarray
    corners: tuple
    grid: tuple
    omc: tuple
    Tc: tuple
    active: np.ndarray
    image_size: tuple | None = None
    dX: float = float("nan")
    dY: float = float("nan")
    n_sq_x: tuple = field(default=())
    n_sq_y: tuple = field(default=())

    def __post_init__(self):
        def views(items, cols=None):
            out = []
            for v in items:
                if v is None:
                    out.append(None)
                    continue
                a = _readonly(v)
                if cols is not None and (a.ndim != 2 or a.shape[1] != cols):
                    raise ValueError(f"per-view points must be (N, {cols}) rows, got shape {a.shape}")
                out.append(a)
            return tuple(out)

        object.__setattr__(self, "err_std", _readonly(np.asarray(self.err_std, dtype=float).reshape(2)))
        object.__setattr__(self, "corners", views(self.corners, 2))
        object.__setattr__(self, "grid", views(self.grid, 3))
        object.__setattr__(self, "omc", views(self.omc))
        object.__setattr__(self, "Tc", views(self.Tc))
        active = np.array(self.active, dtype=bool).reshape(-1)
        active.setflags(write=False)
        object.__setattr__(self, "active", active)
        object.__setattr__(self, "n_sq_x", tuple(self.n_sq_x))
        object.__setattr__(self, "n_sq_y", tuple(self.n_sq_y))
        object.__setattr__(self, "dX", float(self.dX))
        object.__setattr__(self, "dY", float(self.dY))
        n = len(self.active)
        for name in ("corners", "grid", "omc", "Tc"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} has {len(getattr(self, name))} views but active has {n}")

    @property
    def n_views(self):
        """Number of calibration images (active or not)."""
        return len(self.active)

    def summary(self):
        """Return a short text report: parameters with their 3-sigma uncertainties.

        Returns
        -------
        str
        """
        u = self.uncertainty
        cam = self.camera

        def pm(name, values):
            vals = np.atleast_1d(values)
            err = u.get(name)
            text = "[" + ", ".join(f"{v:.5g}" for v in vals) + "]"
            if err is not None:
                text += " +/- [" + ", ".join(f"{e:.3g}" for e in np.atleast_1d(err)) + "]"
            return f"  {name:<8}{text}"

        lines = [
            f"Bouguet calibration: {int(self.active.sum())} active of {self.n_views} views, "
            f"image size {self.image_size}",
            pm("fc", cam.fc),
            pm("cc", cam.cc),
            pm("alpha_c", cam.alpha_c),
            pm("kc", cam.kc),
            f"  err_std [{self.err_std[0]:.5g}, {self.err_std[1]:.5g}] px",
            "  (uncertainties are 3-sigma, as the toolbox reports them)",
        ]
        return "\n".join(lines)

    def __repr__(self):
        return (
            f"BouguetCalib({self.camera!r}, n_views={self.n_views}, active={int(self.active.sum())}, "
            f"err_std={np.array2string(self.err_std, precision=4)})"
        )


def load_bouguet_calib(path):
    """Read a single-camera calibration (``Calib_Results.mat``) of Bouguet's toolbox.

    Parameters
    ----------
    path : str or Path
        The toolbox's ``Calib_Results.mat`` (MATLAB v5/v7 format), or a file written by
        :func:`save_bouguet_calib`.

    Returns
    -------
    calib : BouguetCalib
        Camera, 3-sigma uncertainties, and the per-view corners, grid points and poses.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        The file is not a readable .mat file or lacks ``fc``/``cc``.

    Notes
    -----
    The toolbox stores points as columns (``x_k`` is (2, N), ``X_k`` is (3, N)); they
    are returned as rows. Its pixel coordinates have (0, 0) at the centre of the
    top-left pixel, the same as wingphoto's, so no shift is applied. The ``*_error``
    values are three times the standard deviations (``go_calib_optim``).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from wingphoto.camera import Camera
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "Calib_Results.mat"
    >>> save_bouguet_calib(Camera(fc=[1000, 1001], cc=[255.5, 255.5], image_size=(512, 512)), p)
    >>> calib = load_bouguet_calib(p)
    >>> calib.camera.fc.tolist(), calib.image_size, calib.n_views
    ([1000.0, 1001.0], (512, 512), 0)
    """
    path = Path(path)
    m = _loadmat(path)
    camera, uncertainty = _mat_camera(m, "", path)
    err_std = _mat_vector(m, "err_std", 2, path)
    view_numbers = [int(mt.group(1)) for name in m if (mt := re.fullmatch(r"x_(\d+)", name))]
    if "n_ima" in m:
        n = int(np.asarray(m["n_ima"]).reshape(-1)[0])
    else:
        n = max(view_numbers, default=0)
    if "active_images" in m:
        active = np.asarray(m["active_images"]).reshape(-1).astype(bool)
        if active.size != n:
            raise ValueError(f"{path}: active_images has {active.size} entries but n_ima is {n}")
    else:
        active = np.array([f"x_{k}" in m for k in range(1, n + 1)], dtype=bool)

    def view(name, rows, k):
        if not active[k - 1] or name not in m:
            return None
        a = np.asarray(m[name], dtype=np.float64)
        if a.size == 0 or np.all(np.isnan(a)):
            return None
        if a.ndim != 2 or a.shape[0] != rows:
            raise ValueError(f"{path}: variable {name} has shape {a.shape}, expected ({rows}, N)")
        return a.T

    def integer(name):
        return int(np.asarray(m[name]).reshape(-1)[0]) if name in m else None

    def scalar(*names):
        for name in names:
            if name in m and np.size(m[name]):
                return float(np.asarray(m[name], dtype=np.float64).reshape(-1)[0])
        return float("nan")

    ks = range(1, n + 1)
    return BouguetCalib(
        camera=camera,
        uncertainty=uncertainty,
        err_std=np.full(2, np.nan) if err_std is None else err_std,
        corners=[view(f"x_{k}", 2, k) for k in ks],
        grid=[view(f"X_{k}", 3, k) for k in ks],
        omc=[None if (v := view(f"omc_{k}", 3, k)) is None else v.reshape(3) for k in ks],
        Tc=[None if (v := view(f"Tc_{k}", 3, k)) is None else v.reshape(3) for k in ks],
        active=active,
        image_size=camera.image_size,
        dX=scalar("dX", "dX_1"),
        dY=scalar("dY", "dY_1"),
        n_sq_x=[integer(f"n_sq_x_{k}") for k in ks],
        n_sq_y=[integer(f"n_sq_y_{k}") for k in ks],
    )


def save_bouguet_calib(camera, path, *, uncertainty=None, err_std=None, extra=None):
    """Write a camera as the toolbox's single-camera ``Calib_Results.mat``.

    Parameters
    ----------
    camera : Camera
        Intrinsics to write; ``image_size`` gives ``nx, ny`` when known.
    path : str or Path
        Destination; written atomically (the old file survives a failure).
    uncertainty : dict, optional
        3-sigma uncertainties with keys among ``fc`` (2,), ``cc`` (2,), ``alpha_c``
        (scalar), ``kc`` (5,), written as ``fc_error``, ``cc_error``, ``alpha_c_error``,
        ``kc_error``.
    err_std : (2,) array_like, optional
        Reprojection error standard deviation in x and y, px.
    extra : dict, optional
        More variables to store (valid MATLAB names that do not clash with the above).

    Raises
    ------
    ValueError
        ``camera`` is not a Camera, or ``uncertainty``/``err_std``/``extra`` are malformed.

    Notes
    -----
    Variables written: ``fc, cc, kc, alpha_c, KK`` (+ ``nx, ny``, ``err_std``,
    ``*_error`` when known), as MATLAB column vectors (``fc`` is (2, 1), ``kc`` (5, 1)).
    The toolbox's ``KK`` is ``[fc1, alpha_c*fc1, cc1; 0, fc2, cc2; 0, 0, 1]``.
    """
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a wingphoto.Camera, got {type(camera).__name__}")
    data = _camera_variables(camera, "")
    data.update(_image_size_variables(camera.image_size))
    if err_std is not None:
        e = np.asarray(err_std, dtype=np.float64).reshape(-1)
        if e.size != 2:
            raise ValueError(f"err_std must have 2 elements (x, y), got shape {np.shape(err_std)}")
        data["err_std"] = _column(e)
    data.update(_error_variables(uncertainty, _CAMERA_ERROR_SHAPES, lambda k: f"{k}_error", "camera"))
    _savemat(path, _add_extra(data, extra))


def load_bouguet_stereo(path):
    """Read a stereo calibration (``Calib_Results_stereo.mat``) of Bouguet's toolbox.

    Parameters
    ----------
    path : str or Path
        File saved by the toolbox's ``stereo_gui`` (or by :func:`save_bouguet_stereo`).

    Returns
    -------
    rig : StereoRig
        Both cameras (image_size from ``nx, ny`` when present) and ``om, T`` with
        ``X_right = R(om) X_left + T`` (mm). ``om`` is derived from ``R`` when only
        ``R`` is stored.
    uncertainty : dict
        3-sigma uncertainties from the ``*_error`` variables, keys ``fc_left``,
        ``cc_left``, ``alpha_c_left`` (float), ``kc_left``, the same ``_right``, ``om``
        and ``T``; a key is absent when the file lacks it.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        The file is not a readable .mat file or lacks a required variable.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from wingphoto.camera import Camera, StereoRig
    >>> cam = Camera(fc=[1840, 1845], cc=[255.5, 255.5], image_size=(512, 512))
    >>> rig = StereoRig(cam, cam, om=[0.026, 0.733, 0.003], T=[-272.7, -1.5, 108.7])
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "Calib_Results_stereo.mat"
    >>> save_bouguet_stereo(rig, p, uncertainty={"T": [0.5, 0.1, 0.9]})
    >>> rig2, unc = load_bouguet_stereo(p)
    >>> rig2 == rig, unc["T"].tolist()
    (True, [0.5, 0.1, 0.9])
    """
    path = Path(path)
    m = _loadmat(path)
    left, unc_left = _mat_camera(m, "_left", path)
    right, unc_right = _mat_camera(m, "_right", path)
    if "T" not in m or ("om" not in m and "R" not in m):
        raise ValueError(
            f"{path} lacks the stereo pose (om or R, and T); expected the toolbox's "
            f"Calib_Results_stereo.mat"
        )
    T = _mat_vector(m, "T", 3, path)
    if "om" in m:
        om = _mat_vector(m, "om", 3, path)
    else:
        R = np.asarray(m["R"], dtype=np.float64)
        if R.shape != (3, 3):
            raise ValueError(f"{path}: variable R has shape {R.shape}, expected (3, 3)")
        om = rodrigues_inverse(R)
    rig = StereoRig(left, right, om=om, T=T)
    uncertainty = {f"{k}_left": v for k, v in unc_left.items()}
    uncertainty.update({f"{k}_right": v for k, v in unc_right.items()})
    for key in ("om", "T"):
        v = _mat_vector(m, f"{key}_error", 3, path)
        if v is not None:
            uncertainty[key] = _readonly(v)
    return rig, uncertainty


def save_bouguet_stereo(rig, path, *, uncertainty=None, extra=None):
    """Write a stereo rig with the variable names of the toolbox's ``Calib_Results_stereo.mat``.

    Parameters
    ----------
    rig : StereoRig
        The rig; both cameras must share one image size (the toolbox stores one
        ``nx, ny``) or leave it unknown.
    path : str or Path
        Destination; written atomically (the old file survives a failure).
    uncertainty : dict, optional
        3-sigma uncertainties with keys among ``fc_left``, ``cc_left``,
        ``alpha_c_left``, ``kc_left``, the same ``_right``, ``om`` and ``T``; written
        as ``fc_left_error``, ..., ``om_error``, ``T_error``.
    extra : dict, optional
        More variables to store (valid MATLAB names that do not clash with the above).

    Raises
    ------
    ValueError
        ``rig`` is not a StereoRig, the cameras' image sizes differ, or ``uncertainty``
        / ``extra`` are malformed.

    Notes
    -----
    Variables written: ``om, R, T, fc_left, cc_left, kc_left, alpha_c_left, KK_left``,
    the same ``_right``, and ``nx, ny`` when the image size is known; vectors as
    MATLAB columns (``om``, ``T``: (3, 1); ``fc``, ``cc``: (2, 1); ``kc``: (5, 1)),
    scalars as (1, 1), all double. OpenCV's ``stereoCalibrate`` R, T have the same
    meaning as the toolbox's R, T.
    """
    if not isinstance(rig, StereoRig):
        raise ValueError(f"rig must be a wingphoto.StereoRig, got {type(rig).__name__}")
    sizes = {s for s in (rig.left.image_size, rig.right.image_size) if s is not None}
    if len(sizes) > 1:
        raise ValueError(
            f"the left and right image sizes differ ({rig.left.image_size} vs "
            f"{rig.right.image_size}) but the toolbox stores a single nx, ny; set both "
            f"cameras' image_size to the same value (Camera.replace(image_size=...))"
        )
    data = {"om": _column(rig.om), "R": rodrigues(rig.om), "T": _column(rig.T)}
    data.update(_camera_variables(rig.left, "_left"))
    data.update(_camera_variables(rig.right, "_right"))
    data.update(_image_size_variables(next(iter(sizes)) if sizes else None))
    data.update(_error_variables(uncertainty, _STEREO_ERROR_SHAPES, lambda k: f"{k}_error", "stereo"))
    _savemat(path, _add_extra(data, extra))



# =====================================================================================
# Tracks and 3D points tables
# =====================================================================================

#: Columns of a tracks DataFrame, in order (extra columns may follow).
TRACK_COLUMNS = ["camera", "frame", "point", "x", "y", "score", "status"]
#: Columns of a 3D points DataFrame, in order (extra columns may follow).
POINT_COLUMNS = ["frame", "point", "X", "Y", "Z", "reproj_err"]
_TRACK_KINDS = {"camera": "str", "frame": "int", "point": "int", "x": "float", "y": "float", "score": "float", "status": "str"}
_POINT_KINDS = {"frame": "int", "point": "int", "X": "float", "Y": "float", "Z": "float", "reproj_err": "float"}


def _string_dtype():
    """pandas' default dtype for text: ``str`` (pandas >= 3) or ``object`` (pandas 2)."""
    import pandas as pd

    return pd.Series(["a"]).dtype


def _as_strings(series):
    import pandas as pd

    target = _string_dtype()
    if target != object:
        return series.astype(target)
    values = [v if pd.isna(v) else str(v) for v in series.tolist()]
    return pd.Series(values, index=series.index, dtype=object, name=series.name)


def _empty_table(kinds):
    import pandas as pd

    dtypes = {"str": _string_dtype(), "int": np.int64, "float": np.float64}
    return pd.DataFrame({c: pd.Series([], dtype=dtypes[k]) for c, k in kinds.items()})


def empty_tracks():
    """Return an empty tracks DataFrame with the standard columns and dtypes.

    Returns
    -------
    tracks : pandas.DataFrame
        Columns :data:`TRACK_COLUMNS`: ``camera`` (str), ``frame``, ``point`` (int64),
        ``x``, ``y`` (float64, px), ``score`` (float64), ``status`` (str: ok / flagged /
        lost / manual / interpolated).

    Examples
    --------
    >>> t = empty_tracks()
    >>> list(t.columns) == TRACK_COLUMNS, len(t), str(t["frame"].dtype)
    (True, 0, 'int64')
    """
    return _empty_table(_TRACK_KINDS)


def empty_points():
    """Return an empty 3D points DataFrame with the standard columns and dtypes.

    Returns
    -------
    points : pandas.DataFrame
        Columns :data:`POINT_COLUMNS`: ``frame``, ``point`` (int64), ``X``, ``Y``, ``Z``
        (float64, mm, left camera frame), ``reproj_err`` (float64, px).
    """
    return _empty_table(_POINT_KINDS)


def _coerce_table(df, kinds, what, source):
    """Check the standard columns and cast them to their dtypes (extra columns untouched)."""
    import pandas as pd

    if not isinstance(df, pd.DataFrame):
        raise ValueError(f"{what} must be a pandas DataFrame, got {type(df).__name__}")
    missing = [c for c in kinds if c not in df.columns]
    if missing:
        raise ValueError(f"{source} lacks the column(s) {missing}; a {what} table needs {list(kinds)}")
    out = df.copy()
    for col, kind in kinds.items():
        s = out[col]
        if kind == "str":
            out[col] = _as_strings(s)
            continue
        try:
            values = pd.to_numeric(s, errors="raise")
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{source}: column {col!r} must be numeric ({exc})") from exc
        values = np.asarray(values, dtype=np.float64)
        if kind == "int":
            if np.isnan(values).any():
                raise ValueError(
                    f"{source}: column {col!r} has missing values; frame and point numbers must "
                    f"be integers (drop those rows, or mark positions NaN instead)"
                )
            if np.any(values != np.round(values)):
                raise ValueError(f"{source}: column {col!r} must hold whole numbers")
            out[col] = values.astype(np.int64)
        else:
            out[col] = values
    return out


def _write_table(df, path):
    with atomic_write(path, "w", newline="", encoding="utf-8") as f:
        df.to_csv(f, index=False, lineterminator="\n", na_rep="")


def _read_table(path, kinds, what):
    import pandas as pd

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} file {path} not found; check the path")
    try:
        header = pd.read_csv(path, nrows=0, encoding="utf-8").columns
        na_values = {c: [""] if kinds.get(c) == "str" else ["", "NaN", "nan"] for c in header}
        dtype = {c: object for c, k in kinds.items() if k == "str" and c in header}
        # pandas >= 3 parses floats exactly by default and deprecates float_precision
        exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
        df = pd.read_csv(path, dtype=dtype, na_values=na_values, keep_default_na=False, encoding="utf-8", **exact)
    except Exception as exc:
        raise ValueError(f"cannot read {path} as a {what} CSV table ({exc}); check the file") from exc
    return _coerce_table(df, kinds, what, f"{what} file {path}")


def write_tracks_csv(tracks, path):
    """Write a tracks DataFrame to CSV, atomically.

    Parameters
    ----------
    tracks : pandas.DataFrame
        Columns :data:`TRACK_COLUMNS` (extra columns are kept); ``frame`` and ``point``
        must be whole numbers without gaps (NaN).
    path : str or Path
        Destination ``.csv``; the old file survives a failure.

    Notes
    -----
    Floats are written with full round-trip precision; NaN as an empty field.
    :func:`read_tracks_csv` restores the table exactly, dtypes included.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np, pandas as pd
    >>> t = pd.DataFrame({"camera": ["left"], "frame": [0], "point": [3], "x": [10.25],
    ...                   "y": [np.nan], "score": [0.9], "status": ["lost"]})
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "tracks.csv"
    >>> write_tracks_csv(t, p)
    >>> back = read_tracks_csv(p)
    >>> back.equals(t.astype(back.dtypes.to_dict()))
    True
    """
    _write_table(_coerce_table(tracks, _TRACK_KINDS, "tracks", "tracks"), path)


def read_tracks_csv(path):
    """Read a tracks CSV written by :func:`write_tracks_csv`.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    tracks : pandas.DataFrame
        ``camera`` and ``status`` as str, ``frame`` and ``point`` as int64, ``x``,
        ``y``, ``score`` as float64 (empty fields are NaN); an empty file keeps its
        columns and dtypes.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Not a CSV, a required column is missing, or frame/point are not whole numbers.
    """
    return _read_table(path, _TRACK_KINDS, "tracks")


def write_points_csv(points, path):
    """Write a 3D points DataFrame (frame, point, X, Y, Z, reproj_err) to CSV, atomically.

    Parameters
    ----------
    points : pandas.DataFrame
        Columns :data:`POINT_COLUMNS` (extra columns are kept); X, Y, Z in mm in the
        left camera frame, reproj_err in px.
    path : str or Path
        Destination ``.csv``; the old file survives a failure.
    """
    _write_table(_coerce_table(points, _POINT_KINDS, "points", "points"), path)


def read_points_csv(path):
    """Read a 3D points CSV written by :func:`write_points_csv`.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    points : pandas.DataFrame
        ``frame``, ``point`` as int64; ``X``, ``Y``, ``Z``, ``reproj_err`` as float64
        (empty fields are NaN).

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Not a CSV, a required column is missing, or frame/point are not whole numbers.
    """
    return _read_table(path, _POINT_KINDS, "points")


def find_samples(start=None, name="data-samples"):
    """Find the ``data-samples/`` folder from ``start`` or any of its parents.

    Notebooks run with their own folder as the working directory (nbmake, Jupyter) and
    scripts from the repository root; this finds the sample data from either.

    Parameters
    ----------
    start : str or Path, optional
        Where to start looking (default: the current working directory).
    name : str
        Folder name to look for.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    FileNotFoundError
        When no parent holds the folder.
    """
    start = Path.cwd() if start is None else Path(start)
    for folder in (start, *start.resolve().parents):
        if (folder / name).is_dir():
            return folder / name
    raise FileNotFoundError(
        f"no {name}/ folder in {start} or its parents; run from inside the wingphoto repository "
        "or regenerate the sample with `python data-samples/make_samples.py`"
    )
