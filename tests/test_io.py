"""Tests for wingphoto.io: image sequences, Bouguet .mat interop, tracks/points CSV, atomic writes.

Images are written to ``tmp_path`` with tifffile / cv2; frames are 23 rows x 21 columns
(non-square, to catch x/y swaps) and each frame's pixels encode its index, so order and
content are checked exactly.
"""
import hashlib
import pickle

import cv2
import numpy as np
import pandas as pd
import pytest
import scipy.io
import tifffile

import wingphoto.io as wio
from wingphoto.camera import Camera, StereoRig, rodrigues
from wingphoto.io import (
    POINT_COLUMNS,
    TRACK_COLUMNS,
    BouguetCalib,
    Sequence,
    atomic_write,
    empty_points,
    empty_tracks,
    load_bouguet_calib,
    load_bouguet_stereo,
    read_points_csv,
    read_sequence,
    read_tracks_csv,
    save_bouguet_calib,
    save_bouguet_stereo,
    write_points_csv,
    write_tracks_csv,
)

H, W = 23, 21


# ----------------------------------------------------------------------------- helpers
def frame(t, dtype=np.uint8, shape=(H, W)):
    """A frame whose pixels identify frame ``t`` (and use the high byte for uint16)."""
    rng = np.random.default_rng(t)
    hi = 255 if dtype == np.uint8 else 65535
    img = rng.integers(0, hi + 1, size=shape).astype(dtype)
    img[0, 0] = t
    return img


def write_tiff(path, img, **kw):
    tifffile.imwrite(path, img, photometric="minisblack", **kw)
    return path


def write_png(path, img):
    assert cv2.imwrite(str(path), img)
    return path


def sha256(paths):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in paths}


@pytest.fixture
def tiff_folder(tmp_path):
    """Frames 1, 2, 3, 10, 11 as single-page uint16 TIFFs, written out of order."""
    folder = tmp_path / "frames"
    folder.mkdir()
    for t in (10, 2, 11, 1, 3):
        write_tiff(folder / f"frame{t}.tif", frame(t, np.uint16))
    return folder


# ------------------------------------------------------------------ sources and order
def test_folder_natural_sort(tiff_folder):
    seq = read_sequence(tiff_folder)
    assert [p.name for p in seq.paths] == ["frame1.tif", "frame2.tif", "frame3.tif", "frame10.tif", "frame11.tif"]
    assert [int(f[0, 0]) for f in seq] == [1, 2, 3, 10, 11]
    assert seq.shape == (5, H, W)
    assert seq.frame_size == (W, H)
    assert seq.dtype == np.uint16
    assert isinstance(seq, Sequence)


def test_glob_pattern_natural_sort_and_filter(tmp_path):
    for t in (12, 3, 1, 20):
        write_png(tmp_path / f"cam_left_{t}.png", frame(t))
    write_png(tmp_path / "cam_right_5.png", frame(5))
    (tmp_path / "notes.txt").write_text("not an image")
    seq = read_sequence(str(tmp_path / "cam_left_*.png"))
    assert [int(f[0, 0]) for f in seq] == [1, 3, 12, 20]
    assert len(seq.paths) == 4


def test_list_of_files_keeps_given_order(tiff_folder):
    files = [tiff_folder / "frame10.tif", tiff_folder / "frame1.tif"]
    seq = read_sequence(files)
    assert [int(f[0, 0]) for f in seq] == [10, 1]
    assert seq.paths == files


@pytest.mark.parametrize("memmap", [True, False])
@pytest.mark.parametrize("compression", [None, "zlib"])
def test_multipage_tiff(tmp_path, memmap, compression):
    stack = np.stack([frame(t, np.uint16) for t in range(7)])
    path = write_tiff(tmp_path / "stack.tif", stack, compression=compression)
    seq = read_sequence(path, memmap=memmap)
    assert seq.shape == (7, H, W)
    assert seq.paths == [path]
    np.testing.assert_array_equal(seq.to_array(), stack)
    np.testing.assert_array_equal(seq[-2], stack[5])
    assert seq.locate(-2) == (path, 5)
    seq.close()
    np.testing.assert_array_equal(seq[3], stack[3])  # reopens after close


def test_pages_appended_one_by_one_and_list_of_stacks(tmp_path):
    """Files written frame by frame (append=True) and several stacks concatenate."""
    a = tmp_path / "a.tif"
    for t in range(3):
        write_tiff(a, frame(t, np.uint16), append=True)
    b = write_tiff(tmp_path / "b.tif", np.stack([frame(t, np.uint16) for t in (3, 4)]))
    seq = read_sequence([a, b])
    assert len(seq) == 5
    assert [int(f[0, 0]) for f in seq] == [0, 1, 2, 3, 4]
    assert seq.locate(3) == (b, 0)


def test_big_endian_tiff(tmp_path):
    stack = np.stack([frame(t, np.uint16) for t in range(3)])
    path = write_tiff(tmp_path / "be.tif", stack, byteorder=">")
    seq = read_sequence(path)
    assert seq.dtype == np.dtype("uint16")
    np.testing.assert_array_equal(seq.to_array(), stack)


@pytest.mark.parametrize("fmt", ["tif", "png"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_bit_depth_preserved(tmp_path, fmt, dtype):
    frames = [frame(t, dtype) for t in range(3)]
    frames[1][5, 7] = np.iinfo(dtype).max  # full range kept, no rescaling
    writer = write_tiff if fmt == "tif" else write_png
    for t, img in enumerate(frames):
        writer(tmp_path / f"f{t}.{fmt}", img)
    seq = read_sequence(tmp_path)
    assert seq.dtype == dtype
    for t, img in enumerate(frames):
        got = seq[t]
        assert got.dtype == dtype
        np.testing.assert_array_equal(got, img)


def test_bouguet_jpegs(bouguet_dir):
    seq = read_sequence(bouguet_dir / "left*.jpg")
    assert seq.shape == (14, 480, 640)
    assert seq.frame_size == (640, 480)
    assert seq.dtype == np.uint8
    assert [p.name for p in seq.paths] == [f"left{k:02d}.jpg" for k in range(1, 15)]


# ------------------------------------------------------------------------- indexing
def test_indexing_negative_slicing_and_masks(tiff_folder):
    seq = read_sequence(tiff_folder)
    values = [1, 2, 3, 10, 11]
    assert int(seq[-1][0, 0]) == 11 and int(seq[np.int64(-5)][0, 0]) == 1
    sub = seq[1::2]
    assert isinstance(sub, Sequence) and sub.shape == (2, H, W)
    assert [int(f[0, 0]) for f in sub] == [2, 10]
    assert [p.name for p in sub.paths] == ["frame2.tif", "frame10.tif"]
    assert int(sub[-1][0, 0]) == 10 and int(sub[::-1][0][0, 0]) == 10  # slice of a slice
    assert [int(f[0, 0]) for f in seq[[4, 0, -2]]] == [11, 1, 10]
    mask = np.array([True, False, False, True, False])
    assert [int(f[0, 0]) for f in seq[mask]] == [1, 10]
    assert seq[5:].shape == (0, H, W) and seq[5:].to_array().shape == (0, H, W)
    assert [int(f[0, 0]) for f in seq[-3:]] == values[-3:]
    with pytest.raises(IndexError, match="frame index 5 is out of range for a sequence of 5 frames"):
        seq[5]
    with pytest.raises(IndexError, match="out of range"):
        seq[-6]
    with pytest.raises(IndexError, match="out of range"):
        seq[[0, 7]]
    with pytest.raises(TypeError, match=r"seq\[i\]\[rows, cols\]"):
        seq[0, 1:3]
    with pytest.raises(TypeError, match="Sequence indices must be integers"):
        seq[1.5]


def test_to_array_asarray_iteration_agree(tiff_folder):
    seq = read_sequence(tiff_folder)
    stacked = seq.to_array()
    assert stacked.shape == seq.shape and stacked.dtype == np.uint16
    np.testing.assert_array_equal(np.asarray(seq), stacked)
    np.testing.assert_array_equal(np.stack(list(seq)), stacked)
    assert np.asarray(seq, dtype=np.float32).dtype == np.float32
    assert seq.ndim == 3 and "5 frames" in repr(seq)


def test_pickled_slice_reads_the_same(tiff_folder):
    seq = read_sequence(tiff_folder)[1:4]
    clone = pickle.loads(pickle.dumps(seq))
    np.testing.assert_array_equal(clone.to_array(), seq.to_array())


# ------------------------------------------------------- laziness, files never touched
def test_source_files_unchanged_and_frames_writable(tmp_path):
    stack = np.stack([frame(t, np.uint16) for t in range(4)])
    files = [write_tiff(tmp_path / "stack.tif", stack)]
    files += [write_png(tmp_path / f"p{t}.png", frame(t)) for t in range(2)]
    files += [write_tiff(tmp_path / "z.tif", stack, compression="zlib")]
    before = sha256(files)
    for source in (files[0], files[1:3], files[3]):
        seq = read_sequence(source)
        for f in seq:
            f += 1  # frames are private, writable copies
        first = seq[0]
        first[:] = 0
        assert seq[0].any()
        seq.close()
    assert sha256(files) == before


def test_no_pixel_decode_at_open(tmp_path, monkeypatch):
    path = write_tiff(tmp_path / "z.tif", np.stack([frame(t) for t in range(6)]), compression="zlib")
    calls = []
    original = tifffile.TiffPage.asarray

    def counting(self, *args, **kwargs):
        calls.append(self.index)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(tifffile.TiffPage, "asarray", counting)
    seq = read_sequence(path)
    assert calls == []  # headers only
    assert int(seq[4][0, 0]) == 4
    assert calls == [4]


def test_no_pixel_read_at_open_uncompressed(tiff_folder, monkeypatch):
    reads = []
    original = wio.sequence._FrameStore.read
    monkeypatch.setattr(wio.sequence._FrameStore, "read", lambda self, j: reads.append(int(j)) or original(self, j))
    seq = read_sequence(tiff_folder)
    assert reads == [] and seq.shape == (5, H, W)
    sub = seq[::2]
    assert reads == []  # slicing is lazy too
    assert int(sub[1][0, 0]) == 3 and reads == [2]


def test_file_corrupted_after_opening_fails_only_when_read(tmp_path):
    for t in range(4):
        write_png(tmp_path / f"f{t}.png", frame(t))
        write_tiff(tmp_path / f"g{t}.tif", frame(t))
    pngs = read_sequence(tmp_path / "f*.png")
    tiffs = read_sequence(tmp_path / "g*.tif")
    (tmp_path / "f2.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 10)
    data = (tmp_path / "g2.tif").read_bytes()
    (tmp_path / "g2.tif").write_bytes(data[: len(data) // 2])
    assert int(pngs[1][0, 0]) == 1 and int(tiffs[3][0, 0]) == 3
    with pytest.raises(ValueError, match=r"f2\.png is truncated"):
        pngs[2]
    with pytest.raises(ValueError, match=r"g2\.tif is truncated"):
        tiffs[2]


# --------------------------------------------------------------------------- errors
def test_error_nothing_matches_pattern(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"no files match the pattern .*frame\*\.tif"):
        read_sequence(str(tmp_path / "frame*.tif"))


def test_error_empty_folder(tmp_path):
    (tmp_path / "readme.txt").write_text("no images here")
    with pytest.raises(FileNotFoundError, match=rf"no image files .* in folder {tmp_path}"):
        read_sequence(tmp_path)


def test_error_missing_path_and_bad_sources(tmp_path):
    with pytest.raises(FileNotFoundError, match="is not an existing file or folder"):
        read_sequence(tmp_path / "nowhere")
    with pytest.raises(FileNotFoundError, match=r"missing\.tif in the source list does not exist"):
        read_sequence([tmp_path / "missing.tif"])
    with pytest.raises(ValueError, match="empty list of files"):
        read_sequence([])
    with pytest.raises(ValueError, match="frames already in memory"):
        read_sequence(np.zeros((2, H, W)))


def test_error_folder_mixes_types(tmp_path):
    write_tiff(tmp_path / "a.tif", frame(0))
    write_png(tmp_path / "b.png", frame(1))
    with pytest.raises(ValueError, match=r"mixes image types \(PNG, TIFF\); pass a glob pattern"):
        read_sequence(tmp_path)


def test_error_not_a_tiff(tmp_path):
    write_tiff(tmp_path / "a0.tif", frame(0))
    (tmp_path / "a1.tif").write_bytes(b"this is not an image" * 5)
    with pytest.raises(ValueError, match=r"cannot read TIFF file .*a1\.tif: it is not a TIFF"):
        read_sequence(tmp_path)


def test_error_truncated_tiff_at_open(tmp_path):
    path = write_tiff(tmp_path / "a.tif", frame(0, shape=(230, 210)))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 1000])
    with pytest.raises(ValueError, match=r"TIFF file .*a\.tif is truncated"):
        read_sequence(path)


@pytest.mark.parametrize("keep", [0.3, 0.6, 0.9])
def test_error_truncated_multipage_tiff(tmp_path, keep):
    path = write_tiff(tmp_path / "stack.tif", np.stack([frame(t) for t in range(8)]))
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(ValueError, match=r"stack\.tif is truncated"):
        read_sequence(path)


@pytest.mark.parametrize("ext", ["png", "jpg"])
def test_error_truncated_png_jpeg(tmp_path, ext):
    path = tmp_path / f"a.{ext}"
    assert cv2.imwrite(str(path), frame(0, shape=(230, 210)))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(ValueError, match=rf"image file .*a\.{ext} is truncated"):
        read_sequence(path)


def test_error_undecodable_image(tmp_path):
    (tmp_path / "a.bmp").write_bytes(b"BM" + b"\x00" * 4 + b"junk" * 20)
    with pytest.raises(ValueError, match=r"cannot decode image file .*a\.bmp"):
        read_sequence(tmp_path)


def test_error_mixed_sizes_tiff_at_open_without_decoding(tmp_path, monkeypatch):
    for t in range(3):
        write_tiff(tmp_path / f"f{t}.tif", frame(t))
    write_tiff(tmp_path / "f3.tif", frame(3, shape=(W, H)))  # transposed: the x/y-swap case
    write_tiff(tmp_path / "f4.tif", frame(4, shape=(5, 5)))
    monkeypatch.setattr(tifffile.TiffPage, "asarray", lambda *a, **k: pytest.fail("pixels decoded"))
    monkeypatch.setattr(wio.sequence._FrameStore, "read", lambda *a, **k: pytest.fail("pixels read"))
    with pytest.raises(ValueError, match=rf"f3\.tif has frames of shape \(H, W\) = \({W}, {H}\) but .*f0\.tif has \({H}, {W}\)"):
        read_sequence(tmp_path)


def test_error_mixed_sizes_inside_multipage_tiff(tmp_path):
    path = tmp_path / "stack.tif"
    with tifffile.TiffWriter(path) as tw:
        tw.write(frame(0), photometric="minisblack")
        tw.write(frame(1, shape=(H + 1, W)), photometric="minisblack")
    with pytest.raises(ValueError, match=rf"stack\.tif \(page 1\) has frames of shape \(H, W\) = \({H + 1}, {W}\) but page 0"):
        read_sequence(path)


def test_error_mixed_sizes_png_lazy_and_validate(tmp_path):
    for t in range(3):
        write_png(tmp_path / f"f{t}.png", frame(t))
    write_png(tmp_path / "f3.png", frame(3, shape=(H, W + 2)))
    seq = read_sequence(tmp_path)  # only the first PNG is decoded at opening
    assert len(seq) == 4 and int(seq[2][0, 0]) == 2
    message = rf"f3\.png has frames of shape \(H, W\) = \({H}, {W + 2}\) but .*f0\.png has \({H}, {W}\)"
    with pytest.raises(ValueError, match=message):
        seq[3]
    with pytest.raises(ValueError, match=message):
        seq.validate()
    assert seq[:3].validate() is not None


def test_error_mixed_bit_depth(tmp_path):
    write_tiff(tmp_path / "f0.tif", frame(0, np.uint8))
    write_tiff(tmp_path / "f1.tif", frame(1, np.uint16))
    with pytest.raises(ValueError, match=r"f1\.tif holds uint16 pixels but .*f0\.tif holds uint8"):
        read_sequence(tmp_path)


def test_error_colour_frames_and_as_gray(tmp_path):
    rng = np.random.default_rng(7)
    rgb = rng.integers(0, 256, size=(H, W, 3), dtype=np.uint8)
    tifffile.imwrite(tmp_path / "c.tif", rgb, photometric="rgb")
    assert cv2.imwrite(str(tmp_path / "c.png"), rgb[..., ::-1])  # cv2 writes BGR
    for name in ("c.tif", "c.png"):
        with pytest.raises(ValueError, match=rf"{name} holds colour frames .*convert the files to grayscale, or pass as_gray=True"):
            read_sequence(tmp_path / name)
        gray = read_sequence(tmp_path / name, as_gray=True)[0]
        assert gray.dtype == np.uint8 and gray.shape == (H, W)
        expected = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)  # BT.601, fixed-point rounding
        assert np.abs(gray.astype(int) - expected).max() <= 1


def test_as_gray_16bit_planar_tiff(tmp_path):
    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 65536, size=(3, H, W), dtype=np.uint16)
    tifffile.imwrite(tmp_path / "p.tif", rgb, photometric="rgb", planarconfig="separate")
    gray = read_sequence(tmp_path / "p.tif", as_gray=True)[0]
    expected = np.rint(0.299 * rgb[0] + 0.587 * rgb[1] + 0.114 * rgb[2]).astype(np.uint16)
    assert gray.dtype == np.uint16
    np.testing.assert_array_equal(gray, expected)


# ------------------------------------------------------------------ Bouguet: one camera
def test_load_bouguet_calib_real_file(bouguet_dir):
    calib = load_bouguet_calib(bouguet_dir / "Calib_Results_left.mat")
    assert isinstance(calib, BouguetCalib)
    cam = calib.camera
    np.testing.assert_allclose(cam.fc, [533.00371, 533.15259591], rtol=0, atol=1e-8)
    np.testing.assert_allclose(cam.cc, [341.58612161, 234.25940057], rtol=0, atol=1e-8)
    np.testing.assert_allclose(cam.kc[:2], [-2.89471388e-01, 1.03255226e-01], rtol=0, atol=1e-9)
    assert cam.image_size == (640, 480) == calib.image_size
    assert calib.n_views == 14 and calib.active.all()
    assert all(c.shape == (54, 2) for c in calib.corners)
    assert all(g.shape == (54, 3) for g in calib.grid)
    assert calib.dX == 30.0 and calib.dY == 30.0
    assert set(calib.n_sq_x) == {5, 8} and calib.n_sq_x[0] == 5 and calib.n_sq_y[0] == 8
    np.testing.assert_allclose(calib.uncertainty["fc"], [1.07629077, 1.10913302], atol=1e-8)
    assert set(calib.uncertainty) == {"fc", "cc", "alpha_c", "kc"}
    np.testing.assert_allclose(calib.err_std, [0.13403685, 0.13007012], atol=1e-8)
    assert "14 active of 14 views" in calib.summary()
    with pytest.raises(ValueError):
        calib.corners[0][0, 0] = 0.0  # read-only


def test_bouguet_corners_reproject_with_toolbox_residuals(bouguet_dir):
    """Our projection of X_k with (omc_k, Tc_k) equals the toolbox's x_k - ex_k: same pixel origin."""
    path = bouguet_dir / "Calib_Results_left.mat"
    calib = load_bouguet_calib(path)
    raw = scipy.io.loadmat(path)
    for k in range(calib.n_views):
        Xc = calib.grid[k] @ rodrigues(calib.omc[k]).T + calib.Tc[k]
        residual = calib.corners[k] - calib.camera.project(Xc)
        np.testing.assert_allclose(residual, raw[f"ex_{k + 1}"].T, rtol=0, atol=1e-6)  # px


def test_load_bouguet_calib_inactive_and_missing_views(tmp_path):
    cam = Camera(fc=[800, 805], cc=[10.5, 11.0], kc=[0.1, -0.01, 0, 0, 0])
    x = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])  # toolbox columns (2, N)
    X = np.array([[0.0, 30.0, 60.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    extra = {
        "n_ima": 3, "active_images": np.array([[1, 0, 1]]),
        "x_1": x, "X_1": X, "omc_1": np.array([[0.1], [0.2], [0.3]]), "Tc_1": np.array([[1.0], [2.0], [300.0]]),
        "x_2": x, "X_2": X,
        "x_3": np.full((2, 1), np.nan), "X_3": np.full((3, 1), np.nan),
        "dX": 30.0, "dY": 25.0,
    }
    save_bouguet_calib(cam, tmp_path / "c.mat", extra=extra)
    calib = load_bouguet_calib(tmp_path / "c.mat")
    np.testing.assert_array_equal(calib.corners[0], x.T)
    np.testing.assert_array_equal(calib.grid[0], X.T)
    np.testing.assert_array_equal(calib.omc[0], [0.1, 0.2, 0.3])
    assert calib.corners[1] is None and calib.grid[1] is None  # inactive
    assert calib.corners[2] is None and calib.omc[2] is None  # NaN placeholders
    assert calib.active.tolist() == [True, False, True]
    assert (calib.dX, calib.dY) == (30.0, 25.0)
    assert calib.image_size is None and np.isnan(calib.err_std).all() and calib.uncertainty == {}


def test_save_bouguet_calib_round_trip_and_names(tmp_path):
    cam = Camera(fc=[1843.25, 1851.5], cc=[255.125, 250.75], kc=[-0.21, 0.15, 1e-3, -2e-4, 0.01],
                 alpha_c=1e-4, image_size=(512, 480))
    unc = {"fc": [1.5, 1.6], "cc": [2.0, 2.1], "alpha_c": 3e-4, "kc": [0.01, 0.02, 1e-4, 1e-4, 0.0]}
    path = tmp_path / "Calib_Results.mat"
    save_bouguet_calib(cam, path, uncertainty=unc, err_std=[0.12, 0.13])
    calib = load_bouguet_calib(path)
    assert calib.camera == cam
    assert calib.uncertainty["alpha_c"] == 3e-4
    for key in ("fc", "cc", "kc"):
        np.testing.assert_array_equal(calib.uncertainty[key], unc[key])
    np.testing.assert_array_equal(calib.err_std, [0.12, 0.13])
    m = scipy.io.loadmat(path)
    shapes = {k: v.shape for k, v in m.items() if not k.startswith("__")}
    assert shapes == {
        "fc": (2, 1), "cc": (2, 1), "kc": (5, 1), "alpha_c": (1, 1), "KK": (3, 3),
        "fc_error": (2, 1), "cc_error": (2, 1), "kc_error": (5, 1), "alpha_c_error": (1, 1),
        "err_std": (2, 1), "nx": (1, 1), "ny": (1, 1),
    }
    assert all(v.dtype == np.float64 for k, v in m.items() if not k.startswith("__"))
    np.testing.assert_array_equal(m["KK"], cam.K)
    assert m["KK"][0, 1] == cam.alpha_c * cam.fc[0]


def test_bouguet_calib_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nope\.mat not found"):
        load_bouguet_calib(tmp_path / "nope.mat")
    (tmp_path / "junk.mat").write_bytes(b"not a mat file at all" * 20)
    with pytest.raises(ValueError, match=r"cannot read .*junk\.mat as a MATLAB \.mat file"):
        load_bouguet_calib(tmp_path / "junk.mat")
    scipy.io.savemat(tmp_path / "other.mat", {"a": 1.0})
    with pytest.raises(ValueError, match=r"other\.mat lacks the variable\(s\) fc, cc"):
        load_bouguet_calib(tmp_path / "other.mat")
    cam = Camera(fc=[1, 1], cc=[0, 0])
    with pytest.raises(ValueError, match="camera must be a wingphoto.Camera"):
        save_bouguet_calib("camera", tmp_path / "c.mat")
    with pytest.raises(ValueError, match="err_std must have 2 elements"):
        save_bouguet_calib(cam, tmp_path / "c.mat", err_std=[1, 2, 3])
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['om'\]"):
        save_bouguet_calib(cam, tmp_path / "c.mat", uncertainty={"om": [1, 2, 3]})
    assert not (tmp_path / "c.mat").exists()


# ------------------------------------------------------------------- Bouguet: stereo
@pytest.fixture
def rig():
    left = Camera(fc=[1843.25, 1851.5], cc=[255.125, 250.75], kc=[-0.21, 0.15, 1e-3, -2e-4, 0.01], image_size=(512, 512))
    right = Camera(fc=[1838.0, 1840.5], cc=[260.5, 249.0], kc=[-0.19, 0.11, -1e-3, 3e-4, 0.0], alpha_c=2e-4, image_size=(512, 512))
    return StereoRig(left, right, om=[0.026, 0.733, 0.003], T=[-272.7, -1.5, 108.7])


STEREO_UNCERTAINTY = {
    "fc_left": [1.1, 1.2], "cc_left": [2.1, 2.2], "alpha_c_left": 0.0, "kc_left": [0.01, 0.02, 1e-4, 2e-4, 0.0],
    "fc_right": [1.3, 1.4], "cc_right": [2.3, 2.4], "alpha_c_right": 1e-4, "kc_right": [0.03, 0.04, 3e-4, 4e-4, 0.0],
    "om": [0.001, 0.002, 0.0005], "T": [0.5, 0.1, 0.9],
}


def test_save_load_bouguet_stereo_round_trip(tmp_path, rig):
    path = tmp_path / "Calib_Results_stereo.mat"
    save_bouguet_stereo(rig, path, uncertainty=STEREO_UNCERTAINTY, extra={"note": "from wingphoto"})
    rig2, unc = load_bouguet_stereo(path)
    assert rig2 == rig
    assert set(unc) == set(STEREO_UNCERTAINTY)
    for key, value in STEREO_UNCERTAINTY.items():
        np.testing.assert_array_equal(unc[key], value)
    m = scipy.io.loadmat(path)
    names = {k: v.shape for k, v in m.items() if not k.startswith("__")}
    expected = {"om": (3, 1), "R": (3, 3), "T": (3, 1), "nx": (1, 1), "ny": (1, 1), "note": (1,),
                "om_error": (3, 1), "T_error": (3, 1)}
    for side in ("left", "right"):
        expected.update({f"fc_{side}": (2, 1), f"cc_{side}": (2, 1), f"kc_{side}": (5, 1),
                         f"alpha_c_{side}": (1, 1), f"KK_{side}": (3, 3),
                         f"fc_{side}_error": (2, 1), f"cc_{side}_error": (2, 1),
                         f"kc_{side}_error": (5, 1), f"alpha_c_{side}_error": (1, 1)})
    assert names == expected
    np.testing.assert_allclose(m["R"], rig.R, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(m["KK_right"], rig.right.K)
    assert (m["nx"][0, 0], m["ny"][0, 0]) == (512, 512)


def test_bouguet_stereo_without_uncertainty_or_size(tmp_path, rig):
    bare = StereoRig(rig.left.replace(image_size=None), rig.right.replace(image_size=None), rig.om, rig.T)
    path = tmp_path / "s.mat"
    save_bouguet_stereo(bare, path)
    names = {k for k in scipy.io.loadmat(path) if not k.startswith("__")}
    assert not any(n.endswith("_error") for n in names) and "nx" not in names
    rig2, unc = load_bouguet_stereo(path)
    assert rig2 == bare and unc == {}


def test_load_bouguet_stereo_toolbox_variants(tmp_path, rig):
    """R without om, 4-element kc, integer-typed storage as MATLAB writes it."""
    data = {"R": rig.R, "T": rig.T.reshape(3, 1), "nx": np.uint16(512), "ny": np.uint16(512)}
    for side, cam in (("left", rig.left), ("right", rig.right)):
        data.update({f"fc_{side}": cam.fc.reshape(2, 1), f"cc_{side}": cam.cc.reshape(2, 1),
                     f"kc_{side}": cam.kc[:4].reshape(4, 1), f"alpha_c_{side}": np.uint8(0)})
    scipy.io.savemat(tmp_path / "s.mat", data)
    rig2, _ = load_bouguet_stereo(tmp_path / "s.mat")
    np.testing.assert_allclose(rig2.om, rig.om, rtol=0, atol=1e-12)
    assert rig2.left.kc.tolist() == rig.left.kc[:4].tolist() + [0.0]
    assert rig2.left.image_size == (512, 512) and rig2.left.alpha_c == 0.0


def test_bouguet_stereo_errors(tmp_path, rig):
    scipy.io.savemat(tmp_path / "left_only.mat", {"fc": [[1.0], [1.0]], "cc": [[0.0], [0.0]]})
    with pytest.raises(ValueError, match=r"lacks the variable\(s\) fc_left, cc_left"):
        load_bouguet_stereo(tmp_path / "left_only.mat")
    path = tmp_path / "s.mat"
    with pytest.raises(ValueError, match="rig must be a wingphoto.StereoRig"):
        save_bouguet_stereo(rig.left, path)
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['fc'\]"):
        save_bouguet_stereo(rig, path, uncertainty={"fc": [1, 1]})
    with pytest.raises(ValueError, match=r"uncertainty\['T'\] must have 3 element"):
        save_bouguet_stereo(rig, path, uncertainty={"T": [1, 1]})
    with pytest.raises(ValueError, match="would overwrite a calibration variable"):
        save_bouguet_stereo(rig, path, extra={"om": [1, 2, 3]})
    with pytest.raises(ValueError, match="not a valid MATLAB name"):
        save_bouguet_stereo(rig, path, extra={"_private": 1})
    odd = rig.replace(right=rig.right.replace(image_size=(640, 480)))
    with pytest.raises(ValueError, match="left and right image sizes differ"):
        save_bouguet_stereo(odd, path)
    assert not path.exists()


def test_save_bouguet_stereo_keeps_old_file_on_failure(tmp_path, rig, monkeypatch):
    path = tmp_path / "s.mat"
    save_bouguet_stereo(rig, path)
    before = path.read_bytes()

    def broken(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(scipy.io, "savemat", broken)
    with pytest.raises(RuntimeError, match="disk full"):
        save_bouguet_stereo(rig.replace(T=[1.0, 2.0, 3.0]), path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["s.mat"]  # no temporary left behind


# ---------------------------------------------------------------------------- tables
def make_tracks(n=40, seed=0):
    rng = np.random.default_rng(seed)
    status = np.array(["ok", "flagged", "lost", "manual", "interpolated"])[rng.integers(0, 5, n)]
    x, y = rng.normal(256, 80, n), rng.normal(256, 80, n)
    x[status == "lost"] = np.nan
    y[status == "lost"] = np.nan
    return pd.DataFrame({
        "camera": np.where(np.arange(n) % 2, "left", "NA"),  # "NA" must stay a string
        "frame": np.arange(n, dtype=np.int64) // 4,
        "point": np.arange(n, dtype=np.int64) % 4,
        "x": x, "y": y,
        "score": rng.uniform(0, 1, n),
        "status": status,
        "note": np.where(np.arange(n) % 3 == 0, "checked", "x"),  # extra column kept
    })


def test_empty_tables_dtypes():
    t = empty_tracks()
    assert list(t.columns) == TRACK_COLUMNS and len(t) == 0
    assert t.dtypes.to_dict() == {"camera": pd.Series(["a"]).dtype, "frame": np.int64, "point": np.int64,
                                  "x": np.float64, "y": np.float64, "score": np.float64,
                                  "status": pd.Series(["a"]).dtype}
    p = empty_points()
    assert list(p.columns) == POINT_COLUMNS
    assert p.dtypes.to_dict() == {"frame": np.int64, "point": np.int64, "X": np.float64,
                                  "Y": np.float64, "Z": np.float64, "reproj_err": np.float64}


def test_tracks_csv_round_trip_exact_with_nan(tmp_path):
    tracks = make_tracks()
    assert tracks["x"].isna().any()
    write_tracks_csv(tracks, tmp_path / "t.csv")
    back = read_tracks_csv(tmp_path / "t.csv")
    pd.testing.assert_frame_equal(back, tracks, check_exact=True)
    assert (back["camera"] == "NA").sum() == 20


def test_tracks_csv_round_trip_empty(tmp_path):
    write_tracks_csv(empty_tracks(), tmp_path / "t.csv")
    back = read_tracks_csv(tmp_path / "t.csv")
    pd.testing.assert_frame_equal(back, empty_tracks())


def test_tracks_csv_casts_and_missing_strings(tmp_path):
    t = make_tracks(6).drop(columns="note")
    t["frame"] = t["frame"].astype(np.int32)
    t["x"] = t["x"].astype(np.float32)
    t.loc[2, "status"] = np.nan
    write_tracks_csv(t, tmp_path / "t.csv")
    back = read_tracks_csv(tmp_path / "t.csv")
    assert back["frame"].dtype == np.int64 and back["x"].dtype == np.float64
    assert pd.isna(back.loc[2, "status"])
    np.testing.assert_array_equal(back["x"], t["x"].astype(np.float64))


def test_points_csv_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    pts = pd.DataFrame({"frame": np.repeat(np.arange(5), 3), "point": np.tile(np.arange(3), 5),
                        "X": rng.normal(0, 50, 15), "Y": rng.normal(0, 50, 15), "Z": rng.normal(800, 50, 15),
                        "reproj_err": rng.uniform(0, 0.5, 15)})
    pts.loc[[3, 7], ["X", "Y", "Z", "reproj_err"]] = np.nan
    write_points_csv(pts, tmp_path / "p.csv")
    pd.testing.assert_frame_equal(read_points_csv(tmp_path / "p.csv"), pts, check_exact=True)
    write_points_csv(empty_points(), tmp_path / "e.csv")
    pd.testing.assert_frame_equal(read_points_csv(tmp_path / "e.csv"), empty_points())


def test_table_errors_leave_existing_file(tmp_path):
    path = tmp_path / "t.csv"
    write_tracks_csv(make_tracks(4), path)
    before = path.read_bytes()
    with pytest.raises(ValueError, match=r"tracks lacks the column\(s\) \['status'\]"):
        write_tracks_csv(make_tracks(4).drop(columns="status"), path)
    bad = make_tracks(4)
    bad["frame"] = [0.0, np.nan, 1.0, 1.0]
    with pytest.raises(ValueError, match="column 'frame' has missing values"):
        write_tracks_csv(bad, path)
    bad["frame"] = [0.0, 0.5, 1.0, 1.0]
    with pytest.raises(ValueError, match="column 'frame' must hold whole numbers"):
        write_tracks_csv(bad, path)
    with pytest.raises(ValueError, match="tracks must be a pandas DataFrame"):
        write_tracks_csv({"camera": []}, path)
    assert path.read_bytes() == before
    with pytest.raises(ValueError, match=r"points file .*t\.csv lacks the column\(s\) \['X', 'Y', 'Z', 'reproj_err'\]"):
        read_points_csv(path)
    with pytest.raises(FileNotFoundError, match=r"tracks file .*none\.csv not found"):
        read_tracks_csv(tmp_path / "none.csv")


# ------------------------------------------------------------------------ atomic_write
def test_atomic_write_keeps_old_file_on_exception(tmp_path):
    path = tmp_path / "out.txt"
    path.write_text("old")
    with pytest.raises(RuntimeError, match="interrupted"):
        with atomic_write(path, "w") as f:
            f.write("new, half written")
            raise RuntimeError("interrupted")
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]
    with atomic_write(path, "w") as f:
        f.write("new")
    assert path.read_text() == "new"
    with pytest.raises(ValueError, match="mode must be 'wb' or 'w'"):
        with atomic_write(path, "a"):
            pass
