"""Camera-file readers against reference frames (../shared/data/formats) and synthetic round trips."""
from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from wingphoto.io import read_sequence
from wingphoto.io.formats.cine import LINLUT_10_TO_12

FORMATS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "formats"
CINE = FORMATS / "phantom-cine"
MRAW = FORMATS / "photron-mraw"


def need(path):
    if not path.exists():
        pytest.skip(f"{path} not available")
    return path


def ref_tiff(path):
    img = cv2.imread(str(need(path)), cv2.IMREAD_UNCHANGED)  # LZW: tifffile needs imagecodecs
    assert img is not None
    return img.astype(np.int64)


# ----------------------------------------------------------------------------- .cine
def test_cine_8bit_matches_reference_exactly():
    seq = read_sequence(need(CINE / "example_8bpp.cine"))
    assert seq.shape == (11, 128, 256) and seq.dtype == np.uint8
    assert seq.frame_numbers.tolist() == list(range(11))
    ref = ref_tiff(CINE / "example_8bpp_frame_11.tiff")
    # the reference is the file's 11th image, image number 10 (hypercine's data(10)); the
    # file holds image numbers 0..10, so there is no image number 11
    diffs = [int(np.abs(seq[k].astype(np.int64) - ref).max()) for k in range(len(seq))]
    assert diffs[10] == 0 and min(diffs[:10]) > 50
    roi = ref_tiff(CINE / "example_8bpp_frame_10_roi_0.tiff")  # 100 x 60 window at x=70, y=30
    np.testing.assert_array_equal(seq[10][30:90, 70:170], roi)


@pytest.mark.parametrize("memmap", [True, False])
def test_cine_p10_raw_codes_match_reference_and_linear_uses_the_table(memmap):
    path = need(CINE / "packed_12bpp.cine")
    raw = read_sequence(path, values="raw", memmap=memmap)
    assert raw.frame_numbers.tolist() == list(range(60, 66)) and raw.fps == 100.0
    ref = ref_tiff(CINE / "packed_12bpp_frame_60.tiff")
    codes = raw[0].astype(np.int64)
    assert codes.max() <= 1023
    np.testing.assert_array_equal(np.floor(codes * 255 / 1023 + 0.5).astype(np.int64), ref)
    assert not np.array_equal(np.floor(raw[1] * 255 / 1023 + 0.5), ref)
    linear = read_sequence(path, memmap=memmap)
    assert linear.dtype == np.uint16
    np.testing.assert_array_equal(linear[0], np.asarray(LINLUT_10_TO_12)[codes])
    assert linear.info["white level"] == 4095
    # time stamps: 100 frames/s, one interval per image
    np.testing.assert_allclose(np.diff(raw.timestamps), 0.01, atol=1e-6)


def test_cine_16bit_numbers_start_at_header_and_match_reference():
    seq = read_sequence(need(CINE / "phantom_v7_raw_16bpp.cine"))
    assert seq.dtype == np.uint16 and seq.fps == 80.0
    assert seq.frame_numbers[0] == 238292 and len(seq) == 6
    ref = ref_tiff(CINE / "phantom_v7_raw_16bpp_frame_238292.tiff")
    np.testing.assert_array_equal(seq[0].astype(np.int64) * 255 // 4095, ref)
    assert seq[0].max() <= 4095
    np.testing.assert_allclose(np.diff(seq.timestamps), 1 / 80, atol=1e-6)
    sub = seq[2:4]
    assert sub.frame_numbers.tolist() == [238294, 238295] and sub.timestamps.shape == (2,)


def test_cine_truncated_and_not_a_cine(tmp_path):
    data = need(CINE / "phantom_v7_raw_16bpp.cine").read_bytes()
    (tmp_path / "cut.cine").write_bytes(data[: len(data) - 1000])
    with pytest.raises(ValueError, match=r"cut\.cine is truncated: image number 238297"):
        read_sequence(tmp_path / "cut.cine")
    (tmp_path / "junk.cine").write_bytes(b"hello" * 20)
    with pytest.raises(ValueError, match=r"junk\.cine is not a Phantom \.cine file"):
        read_sequence(tmp_path / "junk.cine")


def test_cine_replaced_after_opening_is_detected(tmp_path):
    data = need(CINE / "phantom_v7_raw_16bpp.cine").read_bytes()
    path = tmp_path / "a.cine"
    path.write_bytes(data)
    seq = read_sequence(path)
    first = seq[0]
    other = bytearray(data)
    other[-5000:] = bytes(5000)
    tmp = tmp_path / "b.cine"
    tmp.write_bytes(bytes(other))
    os.replace(tmp, path)
    with pytest.raises(ValueError, match=r"a\.cine changed on disk after the sequence was opened"):
        seq[0]
    np.testing.assert_array_equal(read_sequence(path)[0], first)


# ----------------------------------------------------------------------------- .mraw
@pytest.mark.parametrize("name", ["ball_12bit", "beam"])
def test_mraw_matches_pymraw(name):
    pymraw = pytest.importorskip("pyMRAW")
    header = need(MRAW / f"{name}.cihx")
    ref, cih = pymraw.load_video(str(header))
    for source in (header, MRAW / f"{name}.mraw"):
        seq = read_sequence(source)
        assert seq.shape == ref.shape and seq.dtype == np.uint16
        assert seq.fps == cih["Record Rate(fps)"]
        for k in range(len(ref)):
            np.testing.assert_array_equal(seq[k], ref[k])
    if name == "ball_12bit":
        assert seq.frame_numbers[0] == 52 and seq.frame_numbers[-1] == 66  # <startFrame> 52


@pytest.mark.parametrize("bits", [8, 12, 16])
def test_old_style_cih_round_trip(tmp_path, bits):
    rng = np.random.default_rng(bits)
    top = 2**bits - 1 if bits < 16 else 4095
    frames = rng.integers(0, top + 1, (5, 6, 10)).astype(np.uint8 if bits == 8 else np.uint16)
    if bits == 12:
        v = frames.reshape(-1, 2).astype(np.uint32)
        packed = np.stack([v[:, 0] >> 4, ((v[:, 0] & 15) << 4) | (v[:, 1] >> 8), v[:, 1] & 255], 1).astype(np.uint8)
        (tmp_path / "rec.mraw").write_bytes(packed.tobytes())
    else:
        (tmp_path / "rec.mraw").write_bytes(frames.astype("<u2" if bits == 16 else np.uint8).tobytes())
    (tmp_path / "rec.cih").write_text(
        "#Camera Information Header\nRecord Rate(fps) : 5000\nStart Frame : -3\nTotal Frame : 5\n"
        f"Image Width : 10\nImage Height : 6\nColor Type : Mono\nColor Bit : {bits}\nFile Format : MRaw\n"
        "EffectiveBit Depth : 12\nEffectiveBit Side : Lower\n"
    )
    seq = read_sequence(tmp_path / "rec.cih")
    assert seq.fps == 5000 and seq.frame_numbers.tolist() == [-3, -2, -1, 0, 1]
    np.testing.assert_array_equal(seq.to_array(), frames)
    pymraw = pytest.importorskip("pyMRAW")
    ref, _ = pymraw.load_video(str(tmp_path / "rec.cih"))
    np.testing.assert_array_equal(seq.to_array(), ref)


def test_mraw_errors(tmp_path):
    (tmp_path / "lone.mraw").write_bytes(bytes(100))
    with pytest.raises(FileNotFoundError, match=r"lone\.mraw has no header beside it"):
        read_sequence(tmp_path / "lone.mraw")
    (tmp_path / "short.mraw").write_bytes(bytes(100))
    (tmp_path / "short.cih").write_text("Total Frame : 5\nImage Width : 10\nImage Height : 6\nColor Bit : 8\n")
    with pytest.raises(ValueError, match=r"short\.mraw is truncated: short\.cih declares 5 frames"):
        read_sequence(tmp_path / "short.cih")


# ----------------------------------------------------------------------------- video
def _marked(k, shape=(48, 64)):
    """A frame carrying its index as big blocks (survives lossy coding)."""
    img = np.full(shape, 40, np.uint8)
    for bit in range(6):
        if (k >> bit) & 1:
            img[4:20, 4 + 10 * bit : 12 + 10 * bit] = 220
    img[30:44, (k * 3) % 50 : (k * 3) % 50 + 10] = 160
    return img


def _decode_index(img):
    return sum(1 << b for b in range(6) if img[12, 8 + 10 * b] > 128)


def _write_video(path, frames, codec, *, pix_fmt="gray", rate=25, pts=None, options=None):
    av = pytest.importorskip("av")
    with av.open(str(path), "w") as c:
        s = c.add_stream(codec, rate=rate)
        s.width, s.height = frames[0].shape[1], frames[0].shape[0]
        s.pix_fmt = pix_fmt
        if options:
            s.codec_context.options = options
        for k, f in enumerate(frames):
            if pix_fmt == "gray":
                vf = av.VideoFrame.from_ndarray(f, format="gray")
            else:  # yuv420p: our grey levels as the luma plane, neutral chroma
                h, w = f.shape
                vf = av.VideoFrame.from_ndarray(np.concatenate([f, np.full((h // 2, w), 128, np.uint8)]), format="yuv420p")
            if pts is not None:
                from fractions import Fraction

                vf.pts = pts[k]
                vf.time_base = Fraction(1, rate)
            for packet in s.encode(vf):
                c.mux(packet)
        for packet in s.encode():
            c.mux(packet)


@pytest.mark.parametrize("suffix,codec", [("avi", "ffv1"), ("mkv", "ffv1")])
def test_lossless_video_round_trip_random_access(tmp_path, suffix, codec):
    frames = [_marked(k) for k in range(40)]
    path = tmp_path / f"v.{suffix}"
    _write_video(path, frames, codec, options={"g": "8"})
    seq = read_sequence(path)
    assert len(seq) == 40 and seq.dtype == np.uint8 and seq.fps == pytest.approx(25)
    assert not seq.variable_frame_rate
    for k in [0, 1, 39, 5, 20, 21, 3, 38, 9, 8]:  # backwards, forwards, across key frames
        np.testing.assert_array_equal(seq[k], frames[k])
    np.testing.assert_array_equal(seq[::7].to_array(), np.stack(frames[::7]))


def test_mp4_with_b_frames_counts_and_orders_frames(tmp_path):
    frames = [_marked(k) for k in range(50)]
    path = tmp_path / "v.mp4"
    _write_video(path, frames, "mpeg4", pix_fmt="yuv420p", options={"g": "10", "bf": "2", "qscale": "2"})
    seq = read_sequence(path)
    assert len(seq) == 50
    order = [49, 0, 17, 16, 30, 31, 32, 2, 45]
    assert [_decode_index(seq[k]) for k in order] == [k % 64 for k in order]
    sequential = [_decode_index(f) for f in seq]
    assert sequential == list(range(50))


def test_variable_frame_rate_is_reported(tmp_path):
    frames = [_marked(k) for k in range(12)]
    pts = [0, 1, 2, 3, 5, 6, 7, 9, 10, 11, 12, 13]
    path = tmp_path / "vfr.mkv"
    _write_video(path, frames, "ffv1", rate=100, pts=pts)
    seq = read_sequence(path)
    assert len(seq) == 12 and seq.variable_frame_rate
    np.testing.assert_allclose(seq.timestamps, np.asarray(pts) / 100)
    np.testing.assert_array_equal(seq[4], frames[4])


# ------------------------------------------------------------------------- image files
def test_signed_integer_frames_are_refused_naming_the_file(tmp_path):
    import tifffile

    tifffile.imwrite(tmp_path / "f0.tif", np.zeros((5, 7), np.int16))
    with pytest.raises(ValueError, match=r"f0\.tif holds signed int16 pixels"):
        read_sequence(tmp_path)


def test_replaced_tiff_frame_is_detected_not_read_garbled(tmp_path):
    import tifffile

    for k in range(3):
        tifffile.imwrite(tmp_path / f"f{k}.tif", np.full((5, 7), k, np.uint16))
    seq = read_sequence(tmp_path)
    replacement = tmp_path / "new.tif"
    tifffile.imwrite(replacement, np.full((5, 7), 99, np.uint16))
    os.replace(replacement, tmp_path / "f1.tif")
    with pytest.raises(ValueError, match=r"f1\.tif changed on disk after the sequence was opened"):
        seq[1]
    assert int(seq[2][0, 0]) == 2
