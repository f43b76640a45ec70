"""Photron ``.mraw`` recordings with their ``.cih`` (text) or ``.cihx`` (XML) header.

pyMRAW (ladisk) is the field's reference reader and the tests compare this reader with it
frame for frame. It is not used at run time because it is GPL-3 licensed (wingphoto is
BSD-3), pulls in the unmaintained ``nose`` and ``py`` packages, and unpacks a 12-bit file
whole into memory; here headers are parsed with the standard library and each frame is
cut from a read-only memory map on access, so recordings larger than memory stay lazy.

Layout: the ``.mraw`` holds the frames back to back, each ``H * W * bits / 8`` bytes;
8-bit and 16-bit (little-endian) pixels are plain, 12-bit pixels are packed 2 in 3 bytes
MSB-first. ``EffectiveBit Side = Higher`` (data in the upper bits of 16-bit words) is
shifted down so values are always ``0 .. 2**EffectiveBitDepth - 1``. The header's start
frame (``Start Frame`` / ``<startFrame>``, the trigger-relative number of the first saved
frame, often negative) gives :attr:`frame_numbers`.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ._base import FileStore, unpack_bits_msb

__all__ = ["MrawStore", "read_cih", "mraw_pair"]

_CIHX_FIELDS = {
    "Record Rate(fps)": "recordInfo/recordRate",
    "Shutter Speed(s)": "recordInfo/shutterSpeed",
    "Total Frame": "frameInfo/totalFrame",
    "Start Frame": "frameInfo/startFrame",
    "Image Width": "imageDataInfo/resolution/width",
    "Image Height": "imageDataInfo/resolution/height",
    "Color Type": "imageDataInfo/colorInfo/type",
    "Color Bit": "imageDataInfo/colorInfo/bit",
    "EffectiveBit Depth": "imageDataInfo/effectiveBit/depth",
    "EffectiveBit Side": "imageDataInfo/effectiveBit/side",
    "File Format": "imageFileInfo/fileFormat",
    "Camera Type": "deviceInfo/deviceName",
    "Date": "fileInfo/date",
}


def mraw_pair(path):
    """Return ``(header_path, mraw_path)`` for a ``.mraw``, ``.cih`` or ``.cihx`` path."""
    path = Path(path)
    if path.suffix.lower() == ".mraw":
        for suffix in (".cihx", ".cih", ".CIHX", ".CIH"):
            header = path.with_suffix(suffix)
            if header.is_file():
                return header, path
        raise FileNotFoundError(
            f"{path} has no header beside it ({path.with_suffix('.cihx').name} or "
            f"{path.with_suffix('.cih').name}); copy the header saved with the recording next to it"
        )
    mraw = path.with_suffix(".mraw")
    if not mraw.is_file():
        upper = path.with_suffix(".MRAW")
        if upper.is_file():
            return path, upper
        raise FileNotFoundError(f"header {path} has no {mraw.name} beside it; copy the .mraw next to it")
    return path, mraw


def _number(text):
    text = str(text).strip()
    try:
        return int(text)
    except ValueError:
        try:
            return float(text)
        except ValueError:
            return text


def read_cih(path):
    """Read a Photron ``.cih`` (``Key : Value`` lines) or ``.cihx`` (XML) header into a dict.

    The keys are the ``.cih`` names (``"Record Rate(fps)"``, ``"Total Frame"``, ``"Start
    Frame"``, ``"Image Width"``, ``"Image Height"``, ``"Color Bit"``, ``"EffectiveBit
    Depth"``, ``"EffectiveBit Side"``, ``"File Format"``, ``"Color Type"``, ...) whichever
    file they come from; numbers are converted.
    """
    path = Path(path)
    data = path.read_bytes()
    start = data.find(b"<cih>")
    cih = {}
    if start >= 0:
        end = data.rfind(b"</cih>")
        if end < 0:
            raise ValueError(f"{path}: the XML header is cut short (no </cih>); re-copy the file")
        try:
            root = ET.fromstring(data[start : end + 6].decode("utf-8", errors="replace"))
        except ET.ParseError as exc:
            raise ValueError(f"{path}: the XML header is corrupt ({exc}); re-copy the file") from exc
        for key, where in _CIHX_FIELDS.items():
            node = root.find(where)
            if node is not None and node.text is not None:
                cih[key] = _number(node.text)
    else:
        text = data.decode("latin-1")
        for line in text.splitlines():
            m = re.match(r"^\s*([^#:][^:]*?)\s*:\s*(.*?)\s*$", line)
            if m:
                cih.setdefault(m.group(1), _number(m.group(2)))
    missing = [k for k in ("Total Frame", "Image Width", "Image Height", "Color Bit") if k not in cih]
    if missing:
        raise ValueError(
            f"{path} is not a Photron .cih/.cihx header (missing {', '.join(missing)}); check the file"
        )
    return cih


class MrawStore(FileStore):
    """Frames of a Photron ``.mraw`` recording (see the module docstring)."""

    kind = "Photron .mraw"

    def __init__(self, path, *, memmap=True):
        header, mraw = mraw_pair(path)
        super().__init__(mraw, memmap=memmap)
        self.header_path = header
        cih = read_cih(header)
        fmt = str(cih.get("File Format", "MRaw")).lower()
        if fmt != "mraw":
            raise ValueError(f"{header} describes a {cih.get('File Format')} recording, not MRaw; read those files directly")
        colour = str(cih.get("Color Type", "Mono")).lower()
        if colour.startswith("color"):
            raise ValueError(
                f"{header} describes a colour recording ({cih.get('Color Type')}); wingphoto reads grey "
                f"(Mono/Raw) .mraw files: save the recording as monochrome in PFV"
            )
        n, w, h = int(cih["Total Frame"]), int(cih["Image Width"]), int(cih["Image Height"])
        bits = int(cih["Color Bit"])
        if bits not in (8, 12, 16):
            raise ValueError(f"{header}: {bits}-bit .mraw is not supported; wingphoto reads 8-, 12- and 16-bit files")
        if n <= 0 or w <= 0 or h <= 0:
            raise ValueError(f"{header}: header declares {n} frames of {w}x{h} pixels; re-copy the header")
        self.bits = bits
        self.effective_bits = int(cih.get("EffectiveBit Depth", bits if bits != 16 else 16))
        self.shift = 0
        if bits == 16 and str(cih.get("EffectiveBit Side", "Lower")).lower() == "higher":
            self.shift = 16 - self.effective_bits
        self.frame_bytes = h * w * bits // 8
        size = self.signature[0]
        if size < n * self.frame_bytes:
            raise ValueError(
                f"{mraw} is truncated: {header.name} declares {n} frames of {self.frame_bytes} bytes "
                f"({n * self.frame_bytes} bytes) but the file has {size}, i.e. {size // self.frame_bytes} "
                f"complete frames; re-copy the recording"
            )
        self.shape = (h, w)
        self.dtype = np.dtype(np.uint8 if bits == 8 else np.uint16)
        start = cih.get("Start Frame", 0)
        start = int(start) if isinstance(start, (int, float)) else 0
        self.frame_numbers = np.arange(start, start + n, dtype=np.int64)
        fps = cih.get("Record Rate(fps)")
        self.fps = float(fps) if isinstance(fps, (int, float)) and fps > 0 else None
        self.info = {"format": "mraw", "header": str(header), "bits": bits,
                     "effective bits": self.effective_bits, "camera": cih.get("Camera Type")}
        self.description = f"Photron .mraw file {mraw} ({header.name})"
        self._finish(n)

    def decode(self, j):
        raw = self.bytes_at(j * self.frame_bytes, self.frame_bytes)
        h, w = self.shape
        if self.bits == 8:
            return np.array(raw, dtype=np.uint8).reshape(h, w)
        if self.bits == 16:
            img = raw.view("<u2").reshape(h, w).astype(np.uint16)
            return img >> self.shift if self.shift else img
        return unpack_bits_msb(raw, h * w, 12).reshape(h, w)
