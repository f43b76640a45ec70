"""Vision Research Phantom ``.cine`` files: 8-bit, 16-bit, packed 10-bit (P10) and packed 12-bit (P12L).

The reader is written here from the published Cine File Format specification rather than
taken from a library: the Python readers on PyPI (``pycine``, ``python-cine``) read whole
frames through ``struct`` and file seeks without memory mapping, do not expose the trigger
and per-image time stamps in the form needed here, and do not all handle P10's
linearisation table. The format is simple and documented; the reader is tested frame for
frame against reference images written by hypercine (Sandia's C++ reader).

Layout (all little-endian)::

    CINEFILEHEADER (44 B)  Type "CI", Headersize, Compression, Version, FirstMovieImage,
                           TotalImageCount, FirstImageNo, ImageCount, OffImageHeader,
                           OffSetup, OffImageOffsets, TriggerTime (TIME64)
    BITMAPINFOHEADER (40 B) at OffImageHeader: biWidth, biHeight, biBitCount,
                           biCompression (0 plain, 256 = P10, 1024 = P12L), biSizeImage, ...
    SETUP at OffSetup:     FrameRate16 (u16) at 0, Length (u16) at 142, FrameRate (u32) at 768
    tagged blocks          from OffSetup + Length to OffImageOffsets: (BlockSize u32,
                           Type u16, Reserved u16, data); type 1002 holds one TIME64 per image
    image offsets          ImageCount int64 at OffImageOffsets; each image starts with an
                           annotation (its first u32 is the annotation size) then the pixels,
                           rows stored bottom-up as in a BMP (biHeight > 0) for 8-bit, 16-bit
                           and P12L; P10 frames are top-down (as Phantom's and hypercine's
                           reference images show: flipping them breaks the exact match).

TIME64 is (fractions u32, seconds u32): seconds since 1970 plus fractions / 2**32.
"""
from __future__ import annotations

import struct

import numpy as np

from ._base import FileStore, unpack_12bit_lsb, unpack_bits_msb
from ._phantom_lut import LINLUT_10_TO_12

__all__ = ["CineStore", "LINLUT_10_TO_12"]

_HEADER = struct.Struct("<2sHHHiIiIIII")  # without TriggerTime
_BITMAP = struct.Struct("<IiiHHIIiiII")
_BI_PACKED_10 = 256
_BI_PACKED_12L = 1024
_TAG_TIME_ONLY = 1002
_TAG_EXPOSURE_ONLY = 1003


def _time64(fractions, seconds):
    return np.asarray(seconds, np.float64) + np.asarray(fractions, np.float64) / 2.0**32


class CineStore(FileStore):
    """Frames of one ``.cine`` file (see the module docstring for the layout).

    Parameters
    ----------
    path : Path
    memmap : bool
        Memory-map the file (default) or read each frame with a plain file read.
    values : {"linear", "raw"}
        For P10 files: "linear" (default) returns the 12-bit linear intensities
        (Vision Research's table, 0..4095), "raw" the stored 10-bit codes (0..1023).
        Other bit depths store linear values and ignore this option.
    """

    kind = "Phantom .cine"

    def __init__(self, path, *, memmap=True, values="linear"):
        super().__init__(path, memmap=memmap)
        if values not in ("linear", "raw"):
            raise ValueError(f"values must be 'linear' or 'raw', got {values!r}")
        self.values = values
        size = self.signature[0]
        with open(self.data_path, "rb") as fh:
            head = fh.read(44)
            if len(head) < 44:
                raise ValueError(f"{self.path} is not a Phantom .cine file: only {len(head)} bytes")
            (kind, header_size, compression, _version, first_movie, total, first_no, count,
             off_bitmap, off_setup, off_offsets) = _HEADER.unpack(head[:36])
            trig_frac, trig_sec = struct.unpack("<II", head[36:44])
            if header_size != 44 or kind not in (b"CI", b"\x00\x00") or off_bitmap + 40 > size:
                raise ValueError(
                    f"{self.path} is not a Phantom .cine file (header {kind!r}, size {header_size}); "
                    f"check the file and its extension"
                )
            if compression != 0:
                raise ValueError(
                    f"{self.path} holds colour (compression {compression}) frames; wingphoto reads "
                    f"grey .cine files: export the recording as grey in the camera software"
                )
            fh.seek(off_bitmap)
            (_, width, height, _planes, bit_count, bi_compression, size_image, _xm, _ym, _used,
             clr_important) = _BITMAP.unpack(fh.read(40))
            if count == 0:
                raise ValueError(f"{self.path} holds no images (ImageCount is 0)")
            if off_offsets + 8 * count > size:
                raise ValueError(f"{self.path} is truncated: its table of {count} image offsets is cut short; re-copy it")
            fh.seek(off_offsets)
            offsets = np.frombuffer(fh.read(8 * count), dtype="<i8").astype(np.int64)
            setup = b""
            if off_setup:
                fh.seek(off_setup)
                setup = fh.read(max(0, min(off_offsets, size) - off_setup))
        self.bottom_up = height > 0
        h, w = abs(int(height)), int(width)
        npix = h * w
        if bi_compression == _BI_PACKED_10 or (size_image * 8 == npix * 10):
            self.packing, self.bits = "P10", 10
            dtype = np.uint16
        elif bi_compression == _BI_PACKED_12L or (size_image * 8 == npix * 12):
            self.packing, self.bits = "P12L", 12
            dtype = np.uint16
        elif bit_count == 8 and size_image in (0, npix):
            self.packing, self.bits = "8", 8
            dtype = np.uint8
        elif bit_count == 16 and size_image in (0, 2 * npix):
            self.packing, self.bits = "16", 16
            dtype = np.uint16
        else:
            raise ValueError(
                f"{self.path}: unsupported pixel format (biBitCount {bit_count}, biCompression "
                f"{bi_compression}, {size_image} bytes for {w}x{h} pixels); wingphoto reads 8-bit, "
                f"16-bit, P10 and P12L grey .cine files"
            )
        self.frame_bytes = size_image or npix * bit_count // 8
        self.shape = (h, w)
        self.dtype = np.dtype(dtype)
        self.first_image_no = int(first_no)
        self.frame_numbers = np.arange(first_no, first_no + count, dtype=np.int64)
        self.trigger_time = float(_time64(trig_frac, trig_sec))  # seconds since 1970 (UTC)
        self._trigger = (int(trig_sec), int(trig_frac))
        # annotation before each image: its first u32 holds the annotation size; files written
        # by other tools (no setup, type 0) leave it undefined and pack images back to back
        self.data_offsets = self._pixel_offsets(offsets, size)
        self._parse_setup(setup, off_setup, off_offsets, count)
        self.description = f"Phantom .cine file {self.path}"
        lut = np.asarray(LINLUT_10_TO_12, dtype=np.uint16)
        lut.setflags(write=False)
        self._lut = lut
        self.info = {
            "format": "cine",
            "pixel format": self.packing,
            "first image number": self.first_image_no,
            "image count": int(count),
            "total images recorded": int(total),
            "first movie image": int(first_movie),
            "white level": int(clr_important) - 1 if clr_important else None,
            "values": "12-bit linear (P10 table)" if self.packing == "P10" and values == "linear"
            else ("raw 10-bit codes" if self.packing == "P10" else "as stored"),
        }
        if self.packing == "P10" and values == "linear":
            self.info["white level"] = 4095
        # image number 0 is the trigger; its position in this file, when the file holds it
        self.info["trigger index"] = int(-first_no) if first_no <= 0 < first_no + count else None
        self.info["trigger time (s since 1970, UTC)"] = self.trigger_time
        self._finish(count)

    def _pixel_offsets(self, offsets, size):
        n = len(offsets)
        out = np.empty(n, dtype=np.int64)
        stride = np.diff(offsets)
        uniform = n > 1 and np.all(stride == stride[0]) and stride[0] >= self.frame_bytes
        with open(self.data_path, "rb") as fh:
            for k, p in enumerate(offsets):
                if p < 0 or p + 4 > size:
                    raise ValueError(f"{self.path} is truncated or corrupt: image {k} starts at byte {p}, the file has {size}")
                fh.seek(int(p))
                annot = struct.unpack("<I", fh.read(4))[0]
                if not (8 <= annot <= 65536) or (uniform and annot != stride[0] - self.frame_bytes):
                    annot = int(stride[0] - self.frame_bytes) if uniform else 0
                out[k] = p + annot
                if out[k] + self.frame_bytes > size:
                    raise ValueError(
                        f"{self.path} is truncated: image number {self.first_image_no + k} needs bytes up to "
                        f"{out[k] + self.frame_bytes} but the file has {size}; re-copy it"
                    )
        return out

    def _parse_setup(self, setup, off_setup, off_offsets, count):
        if len(setup) < 772:
            return
        fps16 = struct.unpack_from("<H", setup, 0)[0]
        length = struct.unpack_from("<H", setup, 142)[0]
        fps32 = struct.unpack_from("<I", setup, 768)[0]
        fps = fps32 or fps16
        self.fps = float(fps) if fps else None
        p = length
        while p + 8 <= len(setup):
            block_size, tag = struct.unpack_from("<IH", setup, p)
            if block_size < 8:
                break
            data = setup[p + 8 : p + block_size]
            if tag == _TAG_TIME_ONLY and len(data) >= 8 * count:
                t = np.frombuffer(data[: 8 * count], dtype="<u4").reshape(count, 2)
                # seconds relative to the trigger, exact in float64 to ~0.1 us
                secs = t[:, 1].astype(np.int64) - self._trigger[0]
                frac = t[:, 0].astype(np.int64) - self._trigger[1]
                self.timestamps = secs.astype(np.float64) + frac.astype(np.float64) / 2.0**32
            elif tag == _TAG_EXPOSURE_ONLY and len(data) >= 4 * count:
                self.info["exposure (s)"] = float(np.median(np.frombuffer(data[: 4 * count], "<u4")) / 2.0**32)
            p += block_size

    def decode(self, j):
        raw = self.bytes_at(int(self.data_offsets[j]), self.frame_bytes)
        h, w = self.shape
        if self.packing == "8":
            img = np.array(raw, dtype=np.uint8).reshape(h, w)
        elif self.packing == "16":
            img = raw.view("<u2").reshape(h, w).astype(np.uint16)
        elif self.packing == "P10":
            codes = unpack_bits_msb(raw, h * w, 10)
            img = (self._lut[codes] if self.values == "linear" else codes).reshape(h, w)
        else:
            img = unpack_12bit_lsb(raw, h * w).reshape(h, w)
        if self.bottom_up and self.packing != "P10":
            img = img[::-1]
        return np.ascontiguousarray(img)
