"""Image sequences: folders, glob patterns, multi-page TIFFs and file lists as lazy grey frames."""
from __future__ import annotations

import contextlib
import io as _stdio
import logging
import operator
import os
import re
import threading
import warnings
import weakref
from collections import Counter, OrderedDict
from pathlib import Path

import numpy as np


logger = logging.getLogger(__name__)


IMAGE_EXTENSIONS = (".tif", ".tiff", ".png", ".jpg", ".jpeg", ".bmp")
_TIFF_SUFFIXES = {".tif", ".tiff"}
_SUFFIX_KIND = {".tif": "TIFF", ".tiff": "TIFF", ".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".bmp": "BMP"}
_GLOB_CHARS = re.compile(r"[*?\[]")
_MAX_OPEN_FILES = 8  # open TIFF handles / memory maps kept per sequence (least recently used)
#: Numbering gaps are warned about only when at least this many files follow one regular
#: numbering: with fewer, a jump in the numbers says little about a dropped frame.
GAP_WARNING_MIN_FILES = 10
_NUMBERED = re.compile(r"^(.*?)(\d+)(\D*)$")


class SequenceWarning(UserWarning):
    """A sequence looks wrong but can still be read: stray files, numbering gaps, ...

    Raised as a warning (``warnings.warn``) by :func:`read_sequence` and the pipeline;
    filter it with ``warnings.simplefilter("ignore", SequenceWarning)`` once checked, or
    make it an error with ``"error"``. :func:`wingphoto.check_sequence` reports the same
    findings (and more: duplicates, blank frames, jumps) as data.
    """


def parse_numbering(paths):
    """Find the numbering of a list of frame files from their names.

    The dominant name pattern is ``<prefix><number><tail><.ext>`` (the last run of digits
    is the frame number); zero-padded numbers also fix the width. A file that does not fit
    the pattern (``frame_0030 copy.tif``, ``frame_0030(1).tif``, ``notes.tif``) is a stray.

    Parameters
    ----------
    paths : list of Path

    Returns
    -------
    numbers : (T,) ndarray of int64 or None
        The number of each file, in the given order; a stray gets the number that follows
        the pattern's prefix in its name, or -1. None when the names follow no pattern
        (fewer than half of them share one).
    strays : list of Path
        Files whose names do not fit the pattern.
    gaps : list of int
        Numbers missing from the regular run of the pattern's files (step = the most
        common difference), in increasing order.
    """
    paths = [Path(p) for p in paths]
    keys = []
    for p in paths:
        m = _NUMBERED.match(p.stem)
        keys.append((m.group(1), m.group(3), p.suffix.lower(), m.group(2)) if m else None)
    counts = Counter(k[:3] for k in keys if k)
    if not counts:
        return None, [], []
    template, count = counts.most_common(1)[0]
    if count < max(2, 0.5 * len(paths)):
        return None, [], []
    members = [k for k in keys if k and k[:3] == template]
    widths = Counter(len(k[3]) for k in members)
    padded = any(k[3].startswith("0") and len(k[3]) > 1 for k in members)
    width = widths.most_common(1)[0][0] if padded else None
    numbers, strays, good = [], [], []
    for p, k in zip(paths, keys):
        fits = k is not None and k[:3] == template and (width is None or len(k[3]) == width)
        if fits:
            numbers.append(int(k[3]))
            good.append(int(k[3]))
            continue
        strays.append(p)
        m = re.match(re.escape(template[0]) + r"(\d+)", p.stem)
        numbers.append(int(m.group(1)) if m else -1)
    gaps = []
    uniq = np.unique(good)
    if uniq.size >= 3:
        diffs = np.diff(uniq)
        step = Counter(diffs.tolist()).most_common(1)[0][0]
        if step > 0 and np.all(diffs % step == 0):
            expected = np.arange(uniq[0], uniq[-1] + 1, step)
            gaps = [int(v) for v in np.setdiff1d(expected, uniq)]
    return np.asarray(numbers, dtype=np.int64), strays, gaps
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
                from .formats import is_container

                recordings = sorted(p.name for p in path.iterdir() if p.is_file() and is_container(p))
                if recordings:
                    raise FileNotFoundError(
                        f"no image files in folder {path}, but camera/video file(s) {', '.join(recordings[:5])}: "
                        f"open one of them, e.g. read_sequence('{path / recordings[0]}')"
                    )
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
        from .formats._base import file_signature

        self.signatures = [file_signature(p) for p in self.paths]
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
        # the camera's own numbering, from the file names when each file is one frame
        self.fps = None
        self.timestamps = None
        self.info = {"format": "image files"}
        numbers, self.strays, self.gaps = parse_numbering(self.paths)
        if numbers is not None and max(self.frames_in_file) == 1:
            self.frame_numbers = numbers
        else:
            self.frame_numbers = np.arange(len(self.file_of), dtype=np.int64)
            if max(self.frames_in_file) > 1:
                self.gaps = []
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
            if np.dtype(dtype).kind == "i":
                raise ValueError(
                    f"{where} holds signed {np.dtype(dtype)} pixels; wingphoto reads unsigned 8/16-bit "
                    f"(or float) grey frames: convert the files (e.g. to uint16 with the offset your "
                    f"camera software documents) before reading them"
                )
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

    def _check_unchanged(self, i):
        """Raise when file ``i`` was rewritten or replaced since the sequence was opened."""
        from .formats._base import changed_error, file_signature

        path = self.paths[i]
        before = self.signatures[i] if getattr(self, "signatures", None) else None
        if before is None:
            return
        try:
            now = file_signature(path)
        except FileNotFoundError:
            raise FileNotFoundError(f"frame file {path} no longer exists; it was moved or deleted after opening") from None
        if now == before:
            return
        with self._lock:  # drop a stale memory map / TIFF handle
            h = self._handles.pop(i, None)
            if h is not None and hasattr(h, "close"):
                with contextlib.suppress(Exception):
                    h.close()
        if self.is_tiff[i]:
            _scan_tiff(path, self.as_gray)  # raises its own message for a truncated/corrupt file
        else:
            _decode_image_file(path, self.as_gray)
        raise changed_error(path, before, now)

    def read(self, j):
        """Read global frame ``j`` as a new, writable (H, W) array."""
        i = int(self.file_of[j])
        path = self.paths[i]
        self._check_unchanged(i)
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
    def fps(self):
        """Frame rate in frames/s from the file's header (None when the files do not say)."""
        return getattr(self._store, "fps", None)

    @property
    def frame_numbers(self):
        """``(T,)`` int64: the camera's own image numbers of these frames.

        A ``.cine`` starts at its header's first image number (trigger-relative, may be
        large or negative), a ``.mraw`` at its start frame, numbered image files carry the
        number in their names (-1 for a stray file without one); otherwise 0, 1, 2, ...
        """
        numbers = getattr(self._store, "frame_numbers", None)
        if numbers is None:
            return self._index.copy()
        return np.asarray(numbers, dtype=np.int64)[self._index]

    @property
    def timestamps(self):
        """``(T,)`` float64 seconds of each frame where the file records them, else None.

        ``.cine``: relative to the trigger time; video: presentation time from the first
        frame.
        """
        ts = getattr(self._store, "timestamps", None)
        return None if ts is None else np.asarray(ts, dtype=np.float64)[self._index]

    @property
    def info(self):
        """Header values of the source (format, pixel format, camera, ...), as a dict."""
        return dict(getattr(self._store, "info", {}))

    @property
    def variable_frame_rate(self):
        """True when a video's frame intervals vary (then :attr:`timestamps` are the truth)."""
        return bool(getattr(self._store, "variable_frame_rate", False))

    @property
    def strays(self):
        """Files of the source whose names do not fit its numbering (see :func:`parse_numbering`)."""
        return list(getattr(self._store, "strays", []))

    @property
    def gaps(self):
        """Numbers missing from the source files' regular numbering."""
        return list(getattr(self._store, "gaps", []))

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


def read_sequence(source, *, as_gray=False, memmap=True, values="linear", strays="warn"):
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
        - a camera recording: Phantom ``.cine``, Photron ``.mraw`` (or its ``.cih`` /
          ``.cihx`` header), or a video (``.avi``, ``.mp4``, ``.mov``, ``.mkv``, ...)
          decoded frame-accurately (see ``docs/formats.md``);
        - a list of files, kept in the order given (multi-page TIFFs contribute all
          their pages).
    as_gray : bool, optional
        Convert colour (RGB/RGBA) frames to grayscale on reading with the ITU-R BT.601
        weights (0.299 R + 0.587 G + 0.114 B, rounded, dtype kept). Default False:
        colour frames raise a ValueError.
    memmap : bool, optional
        Memory-map uncompressed multi-page TIFFs, ``.cine`` and ``.mraw`` files (default
        True). False reads each frame with a plain file read instead.
    values : {"linear", "raw"}, optional
        Phantom packed 10-bit (P10) files only: "linear" (default) returns the 12-bit
        linear intensities through Vision Research's 10-to-12-bit table, "raw" the stored
        10-bit codes.
    strays : {"warn", "skip", "keep", "error"}, optional
        What to do with files whose names do not fit the sequence's numbering (a
        ``frame_0030 copy.tif`` among ``frame_0000.tif ...``): "warn" (default) keeps
        them in order and warns with :class:`SequenceWarning`, "skip" leaves them out
        (logged), "keep" keeps them silently, "error" raises. A regular numbering with
        missing numbers (a dropped frame) is warned about when at least
        :data:`GAP_WARNING_MIN_FILES` files follow it, unless ``strays="keep"``.

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
        shapes); frames are in colour and ``as_gray`` is False; frames hold signed
        integers; a file changed on disk after opening (on reading that frame).

    Warns
    -----
    SequenceWarning
        Stray files or numbering gaps (see ``strays``).

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
    if strays not in ("warn", "skip", "keep", "error"):
        raise ValueError(f"strays must be 'warn', 'skip', 'keep' or 'error', got {strays!r}")
    from .formats import is_container, open_store

    if isinstance(source, (str, os.PathLike)) and Path(os.fspath(source)).expanduser().is_file() \
            and is_container(source):
        store = open_store(Path(os.fspath(source)).expanduser(), as_gray=as_gray, memmap=memmap, values=values)
        logger.debug("opened %d frames of %s %s from %s", len(store.file_of), store.shape, store.dtype, store.description)
        return Sequence(store, np.arange(len(store.file_of)))
    paths, description = _resolve_source(source)
    containers = [p for p in paths if is_container(p)]
    if containers and len(paths) > 1:
        raise ValueError(
            f"{containers[0]} is a camera recording or video; open it on its own with "
            f"read_sequence({str(containers[0])!r}), not as part of a list of files"
        )
    if containers:
        return read_sequence(paths[0], as_gray=as_gray, memmap=memmap, values=values, strays=strays)
    if strays != "keep":
        _numbers, stray_paths, gaps = parse_numbering(paths)
        if stray_paths:
            names = ", ".join(repr(p.name) for p in stray_paths[:5]) + (" ..." if len(stray_paths) > 5 else "")
            if strays == "error":
                raise ValueError(
                    f"{len(stray_paths)} file(s) in {description} do not fit the sequence's numbering: "
                    f"{names}; remove them or pass strays='skip'"
                )
            if strays == "skip":
                logger.info("left out %d stray file(s) of %s: %s", len(stray_paths), description, names)
                skip = set(stray_paths)
                paths = [p for p in paths if p not in skip]
            else:
                warnings.warn(
                    f"{len(stray_paths)} file(s) in {description} do not fit the sequence's numbering "
                    f"and were sorted in among the frames: {names}; remove them, or pass "
                    f"strays='skip' to leave them out",
                    SequenceWarning,
                    stacklevel=2,
                )
    store = _FrameStore(paths, as_gray=as_gray, memmap=memmap, description=description)
    n_numbered = len(store.paths) - len(store.strays)
    if strays != "keep" and store.gaps and n_numbered >= GAP_WARNING_MIN_FILES:
        shown = ", ".join(str(g) for g in store.gaps[:8]) + (" ..." if len(store.gaps) > 8 else "")
        warnings.warn(
            f"{description}: {len(store.gaps)} number(s) missing from the file numbering ({shown}); "
            f"a frame may have been dropped: check the export, or run wingphoto.check_sequence",
            SequenceWarning,
            stacklevel=2,
        )
    logger.debug("opened %d frames of %s %s from %s", len(store.file_of), store.shape, store.dtype, description)
    return Sequence(store, np.arange(len(store.file_of)))


# =====================================================================================
# Bouguet Camera Calibration Toolbox .mat files
# =====================================================================================
