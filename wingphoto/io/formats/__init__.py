"""Camera and video file formats behind :func:`wingphoto.io.read_sequence`.

One module per format, each a *store* that :class:`wingphoto.io.Sequence` indexes lazily:

- :mod:`.cine` - Vision Research Phantom ``.cine`` (8-bit, 16-bit, packed P10/P12L;
  trigger-relative image numbers and per-image time stamps);
- :mod:`.mraw` - Photron ``.mraw`` with its ``.cih``/``.cihx`` header (8/12/16-bit);
- :mod:`.video` - AVI/MP4/MOV/MKV through PyAV, decoded sequentially with exact frame
  counting (never seeking by time); a variable frame rate is reported.

See ``docs/formats.md`` for what each reader returns and how it was checked.
"""
from __future__ import annotations

from pathlib import Path

from .video import VIDEO_EXTENSIONS

__all__ = ["CAMERA_EXTENSIONS", "VIDEO_EXTENSIONS", "open_store", "is_container"]

#: Single-file recordings read_sequence opens directly (besides TIFF stacks).
CAMERA_EXTENSIONS = (".cine", ".mraw", ".cih", ".cihx")


def is_container(path):
    """True when ``path`` names a camera recording or video file (by its extension)."""
    return Path(path).suffix.lower() in CAMERA_EXTENSIONS + VIDEO_EXTENSIONS


def open_store(path, *, as_gray=False, memmap=True, values="linear"):
    """Open the store for one camera recording or video file, chosen by extension."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".cine":
        from .cine import CineStore

        return CineStore(path, memmap=memmap, values=values)
    if suffix in (".mraw", ".cih", ".cihx"):
        from .mraw import MrawStore

        return MrawStore(path, memmap=memmap)
    if suffix in VIDEO_EXTENSIONS:
        from .video import VideoStore

        return VideoStore(path, as_gray=as_gray)
    raise ValueError(f"{path}: not a camera recording or video file ({', '.join(CAMERA_EXTENSIONS + VIDEO_EXTENSIONS)})")
