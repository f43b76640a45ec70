"""Video files (AVI, MP4, MOV, MKV) decoded frame-accurately with PyAV.

Why PyAV (``av`` on PyPI): it binds FFmpeg's libraries directly, so the demuxer's packet
time stamps and key-frame flags are available without decoding, and frames come out of
the decoder one by one in presentation order. That lets the reader count frames exactly
and never seek by time, which is how frame-server readers (and DLTdv's video loading)
lose or duplicate frames. imageio-ffmpeg pipes raw frames from an ffmpeg subprocess and
would need a process per random access.

How frames are found:

1. On opening, every packet of the video stream is demuxed (no decoding) and its
   presentation time stamp (pts) recorded; sorted pts give the frame order, the count is
   exact, and frame intervals show a variable frame rate.
2. ``seq[k]`` continues decoding when frame ``k`` follows the last one read; otherwise it
   seeks to the last key frame at or before frame ``k`` *by that key frame's exact pts*
   (taken from the index, not computed from a time) and decodes forward, checking each
   decoded frame's pts against the index. A frame whose pts does not appear raises.

Frames are returned as grey levels: the luma (Y) plane for YUV streams, as stored (8 bit,
or 16 bit for > 8-bit streams), gray/gray16 streams unchanged, and RGB streams through
``as_gray`` (ITU-R BT.601 weights), as for image files.
"""
from __future__ import annotations

import numpy as np

from ._base import FileStore

__all__ = ["VideoStore", "VIDEO_EXTENSIONS"]

VIDEO_EXTENSIONS = (".avi", ".mp4", ".mov", ".mkv", ".m4v", ".wmv", ".webm")
_LUMA = np.array([0.299, 0.587, 0.114])


def _import_av():
    try:
        import av
    except ImportError as exc:  # pragma: no cover - av is a dependency
        raise ImportError("reading video files needs PyAV: pip install av") from exc
    return av


class VideoStore(FileStore):
    """Frames of one video file (see the module docstring).

    Parameters
    ----------
    path : Path
    as_gray : bool
        Convert RGB streams to grey (YUV streams always give their luma plane).
    vfr_tolerance : float
        Relative spread of frame intervals above which the frame rate is reported as
        variable (default 1e-3).
    """

    kind = "video"

    def __init__(self, path, *, as_gray=False, vfr_tolerance=1e-3):
        super().__init__(path, memmap=False)
        av = _import_av()
        self.as_gray = bool(as_gray)
        try:
            container = av.open(self.data_path)
        except Exception as exc:
            raise ValueError(f"cannot open video file {self.path} ({exc}); check that it is a complete video") from exc
        try:
            if not container.streams.video:
                raise ValueError(f"{self.path} holds no video stream")
            stream = container.streams.video[0]
            self.time_base = stream.time_base
            pts, keys = [], []
            for packet in container.demux(stream):
                if packet.size == 0 and packet.pts is None:
                    continue  # flush packet
                pts.append(packet.pts if packet.pts is not None else packet.dts)
                keys.append(bool(packet.is_keyframe))
            self.codec = stream.codec_context.name
            self.pix_fmt = stream.codec_context.pix_fmt or ""
            w, h = stream.codec_context.width, stream.codec_context.height
            rate = stream.average_rate or stream.guessed_rate
        except ValueError:
            raise
        except Exception as exc:
            raise ValueError(f"cannot read the packets of video file {self.path} ({exc}); re-copy or re-encode it") from exc
        finally:
            container.close()
        if not pts:
            raise ValueError(f"video file {self.path} holds no frames")
        if any(p is None for p in pts):
            raise ValueError(
                f"video file {self.path} has packets without time stamps, so frames cannot be "
                f"located exactly; re-mux it (ffmpeg -i in -c copy out.mkv) or export an image sequence"
            )
        order = np.argsort(np.asarray(pts, dtype=np.int64), kind="stable")
        self.pts = np.asarray(pts, dtype=np.int64)[order]
        if np.any(np.diff(self.pts) == 0):
            raise ValueError(f"video file {self.path} has two frames with the same time stamp; re-encode it")
        self.key = np.asarray(keys, dtype=bool)[order]
        if not self.key[0]:
            self.key[0] = True  # decoding starts at the first packet regardless
        self.timestamps = (self.pts - self.pts[0]) * float(self.time_base)
        n = len(self.pts)
        self.frame_numbers = np.arange(n, dtype=np.int64)
        self.fps = float(rate) if rate else None
        dt = np.diff(self.timestamps)
        self.variable_frame_rate = bool(
            dt.size > 1 and (dt.max() - dt.min()) > vfr_tolerance * max(np.median(dt), 1e-12)
        )
        if dt.size and not self.variable_frame_rate:
            self.fps = 1.0 / float(np.mean(dt))
        self.shape = (int(h), int(w))
        deep = self.pix_fmt.startswith(("gray16", "gray10", "gray12")) or (
            self.pix_fmt.startswith("yuv") and any(tag in self.pix_fmt for tag in ("p10", "p12", "p16"))
        )
        self.dtype = np.dtype(np.uint16 if deep else np.uint8)
        self.info = {"format": "video", "codec": self.codec, "pixel format": self.pix_fmt,
                     "variable frame rate": self.variable_frame_rate}
        self.description = f"video file {self.path}"
        self._decoder = None  # (container, iterator over frames, index of the next frame)
        self._finish(n)

    # -- decoding --------------------------------------------------------------------
    def close(self):
        with self._lock:
            self._drop_decoder()

    def _drop_decoder(self):
        dec = self.__dict__.get("_decoder")
        if dec is not None:
            try:
                dec[0].close()
            except Exception:  # pragma: no cover
                pass
        self._decoder = None

    def __getstate__(self):
        state = super().__getstate__()
        state["_decoder"] = None
        return state

    def _open_at(self, j):
        """Start a decoder whose next frame is ``j``'s key frame; return the key frame index."""
        av = _import_av()
        self._drop_decoder()
        k = int(np.flatnonzero(self.key[: j + 1])[-1])
        container = av.open(self.data_path)
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        if k > 0:
            container.seek(int(self.pts[k]), stream=stream, backward=True, any_frame=False)
        self._decoder = [container, container.decode(stream), None]
        return k

    def _to_gray(self, frame):
        fmt = frame.format.name
        if fmt.startswith("gray"):
            arr = frame.to_ndarray()
        elif fmt.startswith(("yuv", "yuvj", "nv12", "nv21")):
            plane = frame.planes[0]
            deep = self.dtype == np.uint16
            raw = np.frombuffer(plane, dtype="<u2" if deep else np.uint8)
            stride = plane.line_size // (2 if deep else 1)
            arr = raw.reshape(-1, stride)[: frame.height, : frame.width]
        else:
            if not self.as_gray:
                raise ValueError(
                    f"{self.path} holds colour ({fmt}) frames; wingphoto works on grayscale frames: "
                    f"pass as_gray=True to read_sequence to convert them (ITU-R BT.601 luminance)"
                )
            rgb = frame.to_ndarray(format="rgb24").astype(np.float64)
            arr = np.clip(np.rint(rgb @ _LUMA), 0, 255).astype(np.uint8)
        return np.array(arr, dtype=self.dtype)

    def decode(self, j):
        self.check_unchanged()
        with self._lock:
            dec = self._decoder
            if dec is None or dec[2] is None or dec[2] > j or j - dec[2] > 64:
                self._open_at(j)
                dec = self._decoder
            target = int(self.pts[j])
            try:
                for frame in dec[1]:
                    p = frame.pts
                    pos = int(np.searchsorted(self.pts, p)) if p is not None else -1
                    if pos < 0 or pos >= len(self.pts) or self.pts[pos] != p:
                        raise ValueError(
                            f"{self.path}: the decoder produced a frame (pts {p}) that is not in the "
                            f"packet index; the file is damaged or variable in a way wingphoto cannot "
                            f"follow: re-encode it or export an image sequence"
                        )
                    dec[2] = pos + 1
                    if p == target:
                        return self._to_gray(frame)
                    if p > target:
                        break
            except ValueError:
                raise
            except Exception as exc:
                self._drop_decoder()
                raise ValueError(f"cannot decode frame {j} of video file {self.path} ({exc}); re-encode it") from exc
            self._drop_decoder()
            raise ValueError(
                f"{self.path}: frame {j} (pts {target}) was not produced by the decoder; the file is "
                f"damaged (a missing or undecodable frame): re-encode it or export an image sequence"
            )
