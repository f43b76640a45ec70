"""The standing bad-input suite (issue 13): every bad file, parameter or mismatch gets a
clear one-line error naming the file or argument, and nothing on disk is lost.

Mostly in-process through ``wingphoto.cli.main([...])`` and the public API; a few cases
run the real command in a subprocess to check the exit code and that no traceback
reaches the user. Random inputs come from hypothesis (few examples, no deadline: the
whole file stays well under a minute).
"""
from __future__ import annotations

import errno
import logging
import os
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import wingphoto as wp  # noqa: E402
from wingphoto.camera import Camera, StereoRig  # noqa: E402
from wingphoto.cli import main  # noqa: E402
from wingphoto.io import atomic as atomic_mod  # noqa: E402
from wingphoto.io import atomic_write, read_tracks_csv, save_bouguet_stereo, write_tracks_csv  # noqa: E402

needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
FEW = settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
IMAGE = (512, 480)


# ============================================================================ fixtures
def _rig(T=(-272.7, -1.5, 108.7), om=(0.026, 0.733, 0.003)):
    """The thesis rig's geometry: two cameras converging at ~42 degrees, optical axes meeting at ~410 mm."""
    cam = Camera(fc=[1840.0, 1845.0], cc=[255.5, 239.5], kc=[-0.1, 0.05, 0, 0, 0], image_size=IMAGE)
    return StereoRig(cam, cam, om=om, T=T)


#: A calibration of another setup (the cameras moved after calibrating).
OTHER = dict(T=(-250.0, 8.0, 125.0), om=(0.04, 0.70, 0.01))


def _scene(n_frames=12, n_points=8, seed=0):
    """Moving points seen by both cameras: (T, N, 3) mm, left camera frame."""
    rng = np.random.default_rng(seed)
    base = rng.uniform([-12, -12, 395], [12, 12, 425], (n_points, 3))
    t = np.arange(n_frames)[:, None, None]
    return base[None] + np.concatenate([3 * np.sin(0.5 * t), 2.5 * np.cos(0.4 * t), 2 * np.sin(0.3 * t)], axis=2)


def _tracks(rig, X, camera, noise=0.0, seed=1, sigma=None):
    rng = np.random.default_rng(seed)
    T, N, _ = X.shape
    xl, xr = rig.project(X.reshape(-1, 3))
    xy = (xl if camera == "left" else xr) + rng.normal(0, noise, (T * N, 2)) * (noise > 0)
    t = pd.DataFrame({
        "camera": camera, "frame": np.repeat(np.arange(T), N), "point": np.tile(np.arange(N), T),
        "x": xy[:, 0], "y": xy[:, 1], "score": 0.95, "status": "ok", "reason": "",
    })
    if sigma is not None:
        t["sigma"] = float(sigma)
    return t


@pytest.fixture(scope="module")
def rig():
    return _rig()


@pytest.fixture(scope="module")
def scene():
    return _scene()


@pytest.fixture
def files(tmp_path, rig, scene):
    """A calibration .mat, left/right tracks CSV and an existing output file."""
    calib = tmp_path / "Calib_Results_stereo.mat"
    save_bouguet_stereo(rig, calib)
    left, right = tmp_path / "tracks_left.csv", tmp_path / "tracks_right.csv"
    write_tracks_csv(_tracks(rig, scene, "left", 0.05), left)
    write_tracks_csv(_tracks(rig, scene, "right", 0.05, seed=2), right)
    out = tmp_path / "points3d.csv"
    out.write_text("old result\n")
    return {"calib": calib, "left": left, "right": right, "out": out, "dir": tmp_path}


def _cli(capsys, *argv):
    code = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _triangulate(f, left=None, right=None, *extra, calib=None, out=None):
    return ["triangulate", "--calib", calib or f["calib"], "--left", left or f["left"],
            "--right", right or f["right"], "--out", out or f["out"], *extra]


def _one_line_error(err, *names):
    """A single 'wingphoto X: error: ...' line naming each of ``names``."""
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "error:" in lines[0] and "Traceback" not in err, err
    for name in names:
        assert str(name) in lines[0], (name, err)
    return lines[0]


def _no_temp_files(folder):
    left = [p.name for p in Path(folder).iterdir() if p.name.endswith(".tmp")]
    assert not left, left


# ====================================================================== atomic writer
def test_new_file_gets_umask_permissions(tmp_path):
    old = os.umask(0o027)
    try:
        with atomic_write(tmp_path / "a.csv", "w") as f:
            f.write("x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a.csv").stat().st_mode) == 0o640
    with atomic_write(tmp_path / "b.csv", "w") as f:  # and under the session's umask
        f.write("x")
    assert stat.S_IMODE((tmp_path / "b.csv").stat().st_mode) == 0o666 & ~old


@pytest.mark.parametrize("mode", [0o600, 0o644, 0o755])
def test_overwritten_file_keeps_its_mode(tmp_path, mode):
    p = tmp_path / "out.csv"
    p.write_text("old")
    os.chmod(p, mode)
    with atomic_write(p, "w") as f:
        f.write("new")
    assert p.read_text() == "new" and stat.S_IMODE(p.stat().st_mode) == mode


def test_output_that_is_a_folder_is_refused(tmp_path):
    d = tmp_path / "results"
    d.mkdir()
    (d / "keep.txt").write_text("keep")
    with pytest.raises(IsADirectoryError, match="is a folder, not a file"):
        with atomic_write(d, "w") as f:
            f.write("x")
    assert d.is_dir() and (d / "keep.txt").read_text() == "keep"
    _no_temp_files(tmp_path)


@needs_fifo
def test_output_that_is_a_fifo_is_refused_and_kept(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(OSError, match=r"FIFO \(named pipe\), not a regular file"):
        with atomic_write(fifo, "wb") as f:
            f.write(b"x")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    _no_temp_files(tmp_path)


@pytest.mark.skipif(not os.path.exists("/dev/null"), reason="no /dev/null")
def test_output_that_is_a_device_is_refused():
    with pytest.raises(OSError, match="character device, not a regular file"):
        with atomic_write("/dev/null", "w") as f:
            f.write("x")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_full_disk_is_one_line_and_keeps_the_old_file(tmp_path, monkeypatch):
    p = tmp_path / "tracks.csv"
    p.write_text("old content")

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(atomic_mod.os, "fsync", full)
    with pytest.raises(OSError) as info:
        with atomic_write(p, "w") as f:
            f.write("new content")
    msg = str(info.value)
    assert info.value.errno == errno.ENOSPC and "\n" not in msg
    assert str(p) in msg and "disk is full" in msg and "unchanged" in msg
    assert p.read_text() == "old content"
    _no_temp_files(tmp_path)


def test_write_error_inside_the_block_is_named(tmp_path):
    p = tmp_path / "out.bin"
    with pytest.raises(OSError, match=r"cannot write .*out\.bin: the disk quota is exceeded \(nothing was written\)"):
        with atomic_write(p) as f:
            f.write(b"abc")
            raise OSError(errno.EDQUOT, "Disk quota exceeded")
    assert not p.exists()
    _no_temp_files(tmp_path)


def test_symlink_keeps_the_link_and_replaces_its_target(tmp_path):
    target = tmp_path / "real.csv"
    target.write_text("old")
    link = tmp_path / "link.csv"
    link.symlink_to(target)
    with atomic_write(link, "w") as f:
        f.write("new")
    assert link.is_symlink() and target.read_text() == "new"


def test_folder_path_through_a_file_is_one_line(tmp_path):
    (tmp_path / "afile").write_text("keep")
    with pytest.raises(NotADirectoryError, match="not a folder|is a file"):
        with atomic_write(tmp_path / "afile" / "out.csv", "w") as f:
            f.write("x")
    assert (tmp_path / "afile").read_text() == "keep"


def test_no_permission_is_one_line(tmp_path, monkeypatch):
    """The folder refuses the temporary file (as a read-only folder does for a normal user)."""
    p = tmp_path / "out.csv"
    p.write_text("old")

    def denied(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", str(tmp_path / ".out.csv.x.tmp"))

    monkeypatch.setattr(atomic_mod.tempfile, "mkstemp", denied)
    with pytest.raises(OSError) as info:
        with atomic_write(p, "w") as f:
            f.write("new")
    assert str(info.value) == (f"cannot write {p}: permission denied (the existing file is unchanged); "
                               f"check the permissions of {tmp_path} or write elsewhere")
    assert p.read_text() == "old"


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root ignores folder permissions")
def test_read_only_folder_is_one_line(tmp_path):
    d = tmp_path / "ro"
    d.mkdir()
    (d / "out.csv").write_text("old")
    d.chmod(0o555)
    try:
        with pytest.raises(OSError, match=r"cannot write .*out\.csv: permission denied \(the existing file is unchanged\)"):
            with atomic_write(d / "out.csv", "w") as f:
                f.write("new")
        assert (d / "out.csv").read_text() == "old"
    finally:
        d.chmod(0o755)


@needs_fifo
def test_cli_output_folder_and_fifo_refused(files, capsys):
    code, _, err = _cli(capsys, *_triangulate(files, out=files["dir"]))
    assert code == 1
    _one_line_error(err, files["dir"], "is a folder")
    fifo = files["dir"] / "fifo.csv"
    os.mkfifo(fifo)
    code, _, err = _cli(capsys, *_triangulate(files, out=fifo))
    assert code == 1 and stat.S_ISFIFO(os.lstat(fifo).st_mode)
    _one_line_error(err, fifo, "not a regular file")


def _run(*args, preamble=""):
    """Run ``wingphoto ARGS`` in a fresh interpreter; returns (exit code, stderr)."""
    code = textwrap.dedent(preamble) + f"\nimport sys\nfrom wingphoto.cli import main\nsys.exit(main({[str(a) for a in args]!r}))\n"
    env = dict(os.environ, MPLBACKEND="Agg", WINGPHOTO_HEADLESS="1")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    return r.returncode, r.stderr


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_FSIZE semantics")
def test_subprocess_file_size_limit_keeps_old_output(files):
    """A real write failure (the file-size limit, as a full disk would) mid-output."""
    big = pd.concat([_tracks(_rig(), _scene(100, 20), cam, 0.05) for cam in ("left", "right")])
    write_tracks_csv(big, files["left"])  # a combined file as both: split by camera
    code, err = _run(*_triangulate(files, right=files["left"]), preamble="""
        import resource, signal
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (50_000, 50_000))
    """)
    assert code == 1 and "Traceback" not in err, err
    assert str(files["out"]) in err and "unchanged" in err, err
    assert files["out"].read_text() == "old result\n"
    _no_temp_files(files["dir"])


# ============================================================================ tables
def test_reason_comes_back_as_text_and_corrections_apply(tmp_path, rig, scene):
    t = _tracks(rig, scene, "left", sigma=0.05)
    t.loc[3, ["status", "reason"]] = ["flagged", "jump"]
    p = tmp_path / "t.csv"
    write_tracks_csv(t, p)
    back = read_tracks_csv(p)
    assert back["reason"].tolist() == t["reason"].tolist()  # "" stays "", not NaN
    assert back["reason"].map(type).eq(str).all()
    np.testing.assert_array_equal(back["sigma"].to_numpy(), 0.05)
    fixed = wp.apply_corrections(back, [(int(t.point[3]), int(t.frame[3]), 100.5, 50.25)])
    row = fixed.iloc[3]
    assert (row.x, row.y, row.status, row.reason) == (100.5, 50.25, "manual", "")


@FEW
@given(data=st.binary(max_size=400))
def test_random_bytes_as_tracks_csv(tmp_path_factory, data):
    p = tmp_path_factory.mktemp("csv") / "tracks.csv"
    p.write_bytes(data)
    try:
        t = read_tracks_csv(p)
    except ValueError as exc:
        assert str(p) in str(exc) and "\n" not in str(exc)
    else:  # only a well-formed table may come back
        assert list(t.columns[:7]) == wp.TRACK_COLUMNS and t["frame"].dtype == np.int64


@FEW
@given(data=st.binary(max_size=600))
def test_random_bytes_as_calibration_mat(tmp_path_factory, data):
    p = tmp_path_factory.mktemp("mat") / "Calib_Results_stereo.mat"
    p.write_bytes(data)
    with pytest.raises(ValueError, match=str(p.name)):
        wp.load_bouguet_stereo(p)


def test_truncated_mat_names_the_file(files, capsys):
    data = files["calib"].read_bytes()
    files["calib"].write_bytes(data[: len(data) // 2])
    code, _, err = _cli(capsys, *_triangulate(files))
    assert code == 1
    _one_line_error(err, files["calib"])
    assert files["out"].read_text() == "old result\n"


# ================================================================ Bouguet .mat checks
def _edited_mat(path, **changes):
    import scipy.io

    m = scipy.io.loadmat(path)
    m = {k: v for k, v in m.items() if not k.startswith("__")}
    m.update(changes)
    scipy.io.savemat(path, m)


@pytest.mark.parametrize("change, match", [
    ({"R": np.ones((3, 3)), "om": None}, "R is not a rotation matrix"),
    ({"R": -np.eye(3), "om": None}, r"not a rotation matrix .*det\(R\) = -1"),
    ({"R": np.eye(3)}, "om and R disagree"),
    ({"T": np.array([[np.nan], [0.0], [0.0]])}, "T is not finite"),
    ({"T": np.zeros((3, 1))}, "T is zero"),
    ({"fc_left": np.array([[np.nan], [1000.0]])}, "fc must be finite"),
])
def test_invalid_calibration_values_refused_on_load(files, capsys, change, match):
    import scipy.io

    m = {k: v for k, v in scipy.io.loadmat(files["calib"]).items() if not k.startswith("__")}
    for k, v in change.items():
        if v is None:
            m.pop(k)
        else:
            m[k] = v
    scipy.io.savemat(files["calib"], m)
    with pytest.raises(ValueError, match=match):
        wp.load_bouguet_stereo(files["calib"])
    code, _, err = _cli(capsys, *_triangulate(files))
    assert code == 1
    _one_line_error(err, files["calib"])
    assert files["out"].read_text() == "old result\n"


# ================================================================ triangulate checks
def test_good_files_triangulate(files, capsys, rig, scene):
    code, out, err = _cli(capsys, *_triangulate(files))
    assert code == 0, err
    pts = wp.read_points_csv(files["out"])
    assert len(pts) == scene.shape[0] * scene.shape[1]
    d = np.linalg.norm(pts[["X", "Y", "Z"]].to_numpy() - scene.reshape(-1, 3), axis=1)
    assert np.median(d) < 0.1  # 0.05 px noise -> a few hundredths of a mm


def test_swapped_files_refused(files, capsys):
    code, _, err = _cli(capsys, *_triangulate(files, left=files["right"], right=files["left"]))
    assert code == 1
    _one_line_error(err, "tracks_left holds the tracks of camera 'right'", "swapped", files["right"])
    assert files["out"].read_text() == "old result\n"


@pytest.mark.parametrize("which", ["left", "right"])
def test_one_file_as_both_refused(files, capsys, which):
    code, _, err = _cli(capsys, *_triangulate(files, left=files[which], right=files[which]))
    assert code == 1
    _one_line_error(err, "given twice")
    assert files["out"].read_text() == "old result\n"


def test_combined_two_camera_file_is_split(files, capsys, rig, scene):
    both = pd.concat([read_tracks_csv(files["left"]), read_tracks_csv(files["right"])], ignore_index=True)
    combined = files["dir"] / "tracks.csv"
    write_tracks_csv(both, combined)
    assert _cli(capsys, *_triangulate(files))[0] == 0
    separate = wp.read_points_csv(files["out"])
    out2 = files["dir"] / "p2.csv"
    code, _, err = _cli(capsys, *_triangulate(files, left=combined, right=combined, out=out2))
    assert code == 0, err
    pd.testing.assert_frame_equal(wp.read_points_csv(out2), separate)


def _no_camera(t):
    return t.drop(columns="camera")


def test_swapped_without_camera_column_is_diagnosed(rig, scene):
    tl, tr = _tracks(rig, scene, "left", 0.05), _tracks(rig, scene, "right", 0.05, seed=2)
    with pytest.raises(ValueError, match=r"(?s)median reprojection error .* exceeds 2 px.*cameras are swapped"):
        wp.triangulate_tracks(_no_camera(tr), _no_camera(tl), rig)


def test_frame_offset_is_diagnosed(rig):
    X = _scene(40, 10)
    tl, tr = _tracks(rig, X, "left", 0.05), _tracks(rig, X, "right", 0.05, seed=2)
    tr["frame"] = tr["frame"] + 3  # the right sequence starts 3 frames early
    with pytest.raises(ValueError, match=r"right frames shifted by -3 .*offset by 3 frame"):
        wp.triangulate_tracks(tl, tr, rig)


def test_wrong_calibration_names_likely_causes_and_force_goes_on(rig, scene, caplog):
    tl, tr = _tracks(rig, scene, "left"), _tracks(rig, scene, "right")
    other = _rig(**OTHER)
    with pytest.raises(ValueError, match=r"Likely causes: swapped cameras .*frame offset.*another setup.*force=True"):
        wp.triangulate_tracks(tl, tr, other)
    with caplog.at_level(logging.WARNING, logger="wingphoto.triangulate"):
        pts = wp.triangulate_tracks(tl, tr, other, force=True)
    assert pts["X"].notna().all() and "median reprojection error" in caplog.text


def test_cli_force_writes_despite_the_check(files, capsys):
    other = files["dir"] / "other.mat"
    save_bouguet_stereo(_rig(**OTHER), other)
    code, _, err = _cli(capsys, *_triangulate(files, calib=other))
    assert code == 1
    _one_line_error(err, "--force", "median reprojection error")
    assert files["out"].read_text() == "old result\n"
    code, out, err = _cli(capsys, *_triangulate(files, calib=other), "--force")
    assert code == 0 and "wrote" in out
    assert len(wp.read_points_csv(files["out"])) > 0


def test_reprojection_limit_follows_the_tracks_sigma(rig, scene):
    """2 px noise (median reprojection error ~0.9 px): refused when the tracks claim sigma
    0.05 px, accepted when they say 1 px."""
    for sigma, ok in ((0.05, False), (1.0, True)):
        tl = _tracks(rig, scene, "left", 2.0, sigma=sigma)
        tr = _tracks(rig, scene, "right", 2.0, seed=2, sigma=sigma)
        if ok:
            assert wp.triangulate_tracks(tl, tr, rig)["X"].notna().all()
        else:
            with pytest.raises(ValueError, match=r"exceeds 0\.50 px \(10x the tracks' median sigma 0\.050 px"):
                wp.triangulate_tracks(tl, tr, rig)


@pytest.mark.parametrize("edit, match", [
    (lambda tl, tr: (tl, tr.assign(point=tr["point"] + 100)), "share no point number"),
    (lambda tl, tr: (tl, tr.assign(frame=tr["frame"] + 1000)), "share no frame"),
    (lambda tl, tr: (tl.assign(status="OK"), tr), r"unknown status value\(s\) \['OK'\] \(statuses are lower case\)"),
    (lambda tl, tr: (tl.assign(frame=tl["frame"].astype(str)), tr), "column 'frame' must hold integer frame numbers"),
    (lambda tl, tr: (tl.assign(frame=tl["frame"] + 0.5), tr), "whole frame numbers"),
    (lambda tl, tr: (tl.assign(x=tl["x"].astype(str) + "px"), tr), "column 'x' must hold pixel coordinates"),
    (lambda tl, tr: (tl.to_numpy(), tr), "tracks_left must be a tracks DataFrame"),
    (lambda tl, tr: (tl[["x", "y"]].to_numpy(), tr), r"use stereo_triangulation\(xL, xR, rig\)"),
    (lambda tl, tr: (tl.drop(columns="frame"), tr), r"lacks columns \['frame'\]"),
    (lambda tl, tr: (tl.assign(x=tl["x"] * 1000), tr), r"outside the 512x480 image by more than its size"),
    (lambda tl, tr: (tl.assign(status="lost"), tr), r"no \(frame, point\) has a trusted position"),
    (lambda tl, tr: (tl.iloc[:0], tr), "tracks_left has no rows"),
    (lambda tl, tr: (tl.assign(camera="cam0"), tr.assign(camera="cam0", x=tl["x"], y=tl["y"])), "both camera 'cam0'"),
    (lambda tl, tr: (_no_camera(tl), _no_camera(tl)), "identical positions"),
    (lambda tl, tr: (tl.assign(x=np.nan), tr), r"no \(frame, point\) has a trusted position"),
    (lambda tl, tr: (pd.concat([tl, tl]), tr), r"repeating a \(frame, point\) .*concatenated"),
])
def test_mismatched_tracks_are_refused(rig, scene, edit, match):
    tl, tr = edit(_tracks(rig, scene, "left"), _tracks(rig, scene, "right"))
    with pytest.raises(ValueError, match=match):
        wp.triangulate_tracks(tl, tr, rig)


def test_degenerate_rig_gives_no_silent_nan_result(rig, scene):
    flat = StereoRig(rig.left, rig.right, om=[0, 0, 0], T=[0, 0, 0])  # no baseline: no depth anywhere
    tl, tr = _tracks(rig, scene, "left"), _tracks(rig, scene, "right")
    with pytest.raises(ValueError, match="no trusted pair could be triangulated .*baseline"):
        wp.triangulate_tracks(tl, tr, flat)


def test_cli_mismatches_name_the_files(files, capsys, rig, scene):
    tr = read_tracks_csv(files["right"])
    write_tracks_csv(tr.assign(point=tr["point"] + 50), files["right"])
    code, _, err = _cli(capsys, *_triangulate(files))
    assert code == 1
    _one_line_error(err, "share no point number", files["left"], files["right"])
    write_tracks_csv(tr.assign(status="OK"), files["right"])
    code, _, err = _cli(capsys, *_triangulate(files))
    assert code == 1
    _one_line_error(err, "'OK'", files["right"])
    assert files["out"].read_text() == "old result\n"


@pytest.mark.parametrize("variant, match", [
    ("semicolons", "separated by semicolons; wingphoto reads comma-separated files"),
    ("tabs", "separated by tabs"),
    ("points", "looks like a 3D points file, not tracks"),
    ("latin1", "cannot read .* as a tracks CSV table"),
    ("header", "tracks_left has no rows"),
    ("truncated", r"unknown status value\(s\) \['<empty>'\]"),
    ("bom", None),
    ("crlf", None),
])
def test_tracks_csv_variants(files, capsys, rig, scene, variant, match):
    t = read_tracks_csv(files["left"])
    text = t.to_csv(index=False)
    lines = text.splitlines()  # "truncated": cut in the middle of a row, after its x
    data = {
        "semicolons": t.to_csv(index=False, sep=";", decimal=",").encode(),
        "tabs": t.to_csv(index=False, sep="\t").encode(),
        "points": wp.triangulate_tracks(t, read_tracks_csv(files["right"]), rig).to_csv(index=False).encode(),
        "latin1": text.replace("left", "l\xe9ft").encode("latin1"),
        "header": (text.splitlines()[0] + "\n").encode(),
        "truncated": "\n".join(lines[: len(lines) // 2] + [",".join(lines[len(lines) // 2].split(",")[:4])]).encode(),
        "bom": ("\ufeff" + text).encode(),
        "crlf": text.replace("\n", "\r\n").encode(),
    }[variant]
    files["left"].write_bytes(data)
    code, out, err = _cli(capsys, *_triangulate(files))
    if match is None:  # harmless variants are read as they are
        assert code == 0, err
        return
    assert code == 1 and files["out"].read_text() == "old result\n"
    assert re_search(match, _one_line_error(err, files["left"])), err


_STATUSES = st.sampled_from(["ok", "flagged", "lost", "manual", "interpolated"])


@FEW
@given(
    n_frames=st.integers(0, 6), n_points=st.integers(1, 5),
    nan_share=st.floats(0, 1), statuses=st.lists(_STATUSES, min_size=1, max_size=4), seed=st.integers(0, 2**16),
)
def test_random_tracks_give_a_result_or_a_clear_error(n_frames, n_points, nan_share, statuses, seed):
    rig = _rig()
    rng = np.random.default_rng(seed)
    X = _scene(max(n_frames, 1), n_points, seed)[:n_frames]
    tables = []
    for t in (_tracks(rig, X, "left"), _tracks(rig, X, "right")):
        t.loc[rng.random(len(t)) < nan_share, ["x", "y"]] = np.nan
        t["status"] = rng.choice(statuses, len(t))
        tables.append(t[rng.random(len(t)) >= 0.2])
    tl, tr = tables
    try:
        pts = wp.triangulate_tracks(tl, tr, rig)
    except ValueError as exc:
        assert "\n" not in str(exc)
        return
    assert list(pts.columns) == wp.POINT_COLUMNS and pts["frame"].dtype == np.int64
    good = pts["X"].notna()
    if good.any():
        truth = X[pts.loc[good, "frame"], pts.loc[good, "point"]]
        np.testing.assert_allclose(pts.loc[good, ["X", "Y", "Z"]].to_numpy(), truth, atol=1e-6)


# ======================================================================= parameters
@pytest.mark.parametrize("window, match", [
    (-1, "between 0 and"), (1000, "between 0 and 9"), (2.5, "whole number"), ("7", "whole number"), (True, "whole number"),
])
def test_find_corners_window_out_of_range(window, match):
    with pytest.raises(ValueError, match=f"window must be .*{match}"):
        wp.find_corners(np.zeros((40, 50), np.uint8), (9, 6), window=window)


def _tiny_pairs(folder, n=3):
    import tifffile

    for side in ("left", "right"):
        (folder / side).mkdir(parents=True)
        for k in range(n):
            tifffile.imwrite(folder / side / f"c{k}.tif", np.full((48, 64), 40 * k, np.uint8))


@pytest.mark.parametrize("square", ["1e-300", "0", "-30", "nan", "inf", "1e300"])
def test_cli_square_out_of_range(tmp_path, capsys, square):
    _tiny_pairs(tmp_path)
    out = tmp_path / "calib.mat"
    code, _, err = _cli(capsys, "calibrate", "--left", tmp_path / "left", "--right", tmp_path / "right",
                        "--pattern", "9x6", "--square", square, "--out", out)
    assert code == 1 and not out.exists()
    _one_line_error(err, "square_size")


# ============================================================== reference stillness
def _still_references(n_frames, sigma_z, seed, n_refs=6):
    """References at rest with noise mostly in depth, as a stereo rig measures them."""
    rng = np.random.default_rng(seed)
    rest = rng.uniform([-50, -50, 590], [50, 50, 610], (n_refs, 3))
    noise = rng.normal(0, 1, (n_frames, n_refs, 3)) * [0.2 * sigma_z, 0.2 * sigma_z, sigma_z]
    return rest[None] + noise


def test_stillness_default_fails_a_bumped_camera_and_passes_a_still_one():
    P = _still_references(60, 0.0015, seed=3)
    assert wp.reference_stillness(P, range(6)).valid
    bumped = P.copy()
    bumped[30:, :, 2] += 0.37  # notebook 09: a 1 px bump moves the references ~0.37 mm in depth
    res = wp.reference_stillness(bumped, range(6))
    assert not res.valid and res.tol_derived and res.tol_mm < 0.05
    assert wp.reference_stillness(bumped, range(6), tol_mm=0.5).valid  # the old default hid it


@pytest.mark.parametrize("seed", range(5))
def test_stillness_default_does_not_fail_long_still_recordings(seed):
    """No false alarm over 3000 frames of pure noise (1-D depth noise: the tightest case)."""
    P = _still_references(3000, 0.002, seed=seed)
    P[..., :2] = P[0, :, :2]
    res = wp.reference_stillness(P, range(6))
    assert res.valid, res.summary()
    assert res.table["max_displacement"].max() < 0.8 * res.tol_mm


def test_stillness_default_fails_a_slow_drift():
    P = _still_references(300, 0.002, seed=9)
    P[:, :, 0] += np.linspace(0, 0.05, 300)[:, None]  # the mount creeps 0.05 mm
    assert not wp.reference_stillness(P, range(6)).valid


def test_stillness_min_frames_nan_refused():
    with pytest.raises(ValueError, match="min_frames must be a number of frames >= 1"):
        wp.reference_stillness(np.zeros((20, 2, 3)), [0], min_frames=np.nan)


# ===================================================== options reaching OpenCV / numpy
@pytest.mark.parametrize("call, match", [
    (lambda: wp.bpass(np.zeros((20, 20)), np.nan, 5), "lnoise, lobject must be finite"),
    (lambda: wp.bpass(np.zeros((20, 20)), 1, np.inf), "lnoise, lobject must be finite"),
    (lambda: wp.pkfnd(np.zeros((20, 20)), np.nan), "threshold must be a grey level"),
    (lambda: wp.pkfnd(np.zeros((20, 20)), 0.5, -3), "sz must be a marker size >= 1"),
    (lambda: Camera(fc=[1000, 1000], cc=[1, 1], alpha_c=np.nan), "alpha_c must be a finite"),
    (lambda: Camera(fc=[1000, 1000], cc=[1, 1], image_size=(-5, 10)), "image_size must be"),
    (lambda: Camera(fc=[1000, 1000], cc=[1, 1], image_size=(np.nan, 10)), "image_size must be"),
])
def test_numeric_options_are_checked(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def _tracks_for_video():
    return pd.DataFrame({"camera": "left", "frame": [0, 1], "point": 0, "x": 10.0, "y": 10.0, "score": 1.0,
                         "status": "ok"})


@needs_fifo
def test_video_refuses_folder_fifo_and_huge_scale(tmp_path):
    frames = [np.zeros((40, 50), np.uint8)] * 2
    with pytest.raises(IsADirectoryError, match="is a folder"):
        wp.write_tracking_video(frames, _tracks_for_video(), tmp_path, progress=False)
    fifo = tmp_path / "v.mp4"
    os.mkfifo(fifo)
    with pytest.raises(OSError, match="not a regular file"):
        wp.write_tracking_video(frames, _tracks_for_video(), fifo, progress=False)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.mp4"]  # no sibling .avi written
    with pytest.raises(ValueError, match=r"more than video codecs take .*use scale <= 327"):
        wp.write_tracking_video(frames, _tracks_for_video(), tmp_path / "w.mp4", scale=10**4, progress=False)
    with pytest.raises(ValueError, match="fps must be positive"):
        wp.write_tracking_video(frames, _tracks_for_video(), tmp_path / "w.mp4", fps=np.inf, progress=False)


def test_pantilt_absurd_stop_count_is_refused(capsys):
    code, _, err = _cli(capsys, "pantilt", "--pans", "1000000000")
    assert code == 1
    _one_line_error(err, "pan stops must be at most 1000")


# ============================================ other issues' fixes, through the public CLI
def _moving_frames(folder, n=6, dtype=np.uint8):
    import tifffile

    folder.mkdir()
    for k in range(n):
        im = np.zeros((64, 80), np.uint8)
        im[20:26, 30 + k:36 + k] = 200
        im[40:44, 10:14] = 120 + k
        tifffile.imwrite(folder / f"f{k:03d}.tif", im.astype(dtype))
    return folder


@pytest.fixture
def track_inputs(tmp_path):
    frames = _moving_frames(tmp_path / "frames")
    picks = tmp_path / "picks.csv"
    picks.write_text("camera,point,frame,x,y\nleft,0,0,32.5,22.5\n")
    out = tmp_path / "tracks.csv"
    out.write_text("old tracks\n")
    return {"frames": frames, "picks": picks, "out": out, "dir": tmp_path}


def _track(inp, *extra, picks=None, frames=None, out=None):
    return ["track", "--frames", frames or inp["frames"], "--picks", picks or inp["picks"],
            "--out", out or inp["out"], *extra]


def test_track_output_folder_refused_before_tracking(track_inputs, capsys):
    code, _, err = _cli(capsys, *_track(track_inputs, out=track_inputs["dir"]))
    assert code == 1
    _one_line_error(err, track_inputs["dir"], "is a folder")
    code, _, err = _cli(capsys, *_track(track_inputs, "--checkpoint", track_inputs["dir"]))
    assert code == 1 and track_inputs["out"].read_text() == "old tracks\n"
    _one_line_error(err, "is a folder")


@pytest.mark.parametrize("text, match", [
    ("camera,point,frame,x,y\nright,0,0,32.5,22.5\n", "has no picks for the left camera"),
    ("camera,point,frame,x,y\nleft,0,0,32.5,22.5\nleft,1,0,32.5,22.5\n", "points 0 and 1 .* on the same spot"),
    ("camera,point,frame,x,y\nleft,0,0,nan,22.5\nleft,1,0,50,22.5\n", "left point 0 has no valid position"),
    ("camera,point,frame,x,y\nleft,0,0,5000,22.5\n", "outside the 80x64 image"),
    ("camera,point,frame,x,y\nleft,0,99,32.5,22.5\n", r"point 0 was picked in frame 99, but the sequence has frames 0\.\.5"),
])
def test_bad_picks_are_named(track_inputs, capsys, text, match):
    """Issue 13 item 6 (wingphoto.picks): the picks file and the point are named."""
    track_inputs["picks"].write_text(text)
    code, _, err = _cli(capsys, *_track(track_inputs))
    assert code == 1 and track_inputs["out"].read_text() == "old tracks\n"
    line = _one_line_error(err)
    assert re_search(match, line), line


def re_search(pattern, text):
    import re

    return re.search(pattern, text) is not None


def test_int16_frames_name_the_file(track_inputs, capsys):
    """Issue 13 item 5 (sequences): signed 16-bit frames are refused, naming the file."""
    frames = _moving_frames(track_inputs["dir"] / "i16", dtype=np.int16)
    code, _, err = _cli(capsys, *_track(track_inputs, frames=frames))
    assert code == 1
    _one_line_error(err, frames / "f000.tif", "int16")


def test_file_replaced_after_opening_is_detected(track_inputs):
    """Issue 13 item 6 (sequences): a frame file replaced after read_sequence is not read garbled."""
    import tifffile

    seq = wp.read_sequence(track_inputs["frames"])
    _ = seq[0]
    tifffile.imwrite(track_inputs["frames"] / "f003.tif", np.zeros((32, 40), np.uint8))
    with pytest.raises(ValueError, match=r"f003\.tif changed on disk after the sequence was opened"):
        [seq[k] for k in range(len(seq))]


def test_max_coast_negative_refused():
    """Issue 13 item 5 (tracker options)."""
    frames = [np.pad(np.full((5, 5), 200, np.uint8), 10)] * 3
    with pytest.raises(ValueError, match="max_coast must be >= 0"):
        wp.track_markers(frames, pd.DataFrame({"point": [0], "x": [12.0], "y": [12.0]}), max_coast=-1, progress=False)


@FEW
@given(data=st.binary(max_size=300))
def test_random_bytes_as_tiff(tmp_path_factory, data):
    p = tmp_path_factory.mktemp("tif") / "frame.tif"
    p.write_bytes(data)
    with pytest.raises((ValueError, OSError)) as info:
        seq = wp.read_sequence(p)
        [seq[k] for k in range(len(seq))]
    assert str(p) in str(info.value) and "\n" not in str(info.value)


def test_random_bytes_tiff_as_the_frames_on_the_cli(track_inputs, capsys):
    """A random-bytes TIFF given as the frames: exit code 1, one line naming it, old output kept.

    In-process (an escaping exception fails the test as a traceback would reach the user);
    the real interpreter's exit code and stderr through the same ``sys.exit(main(...))`` are
    checked once, by test_subprocess_file_size_limit_keeps_old_output.
    """
    bad = track_inputs["dir"] / "bad.tif"
    bad.write_bytes(np.random.default_rng(13).bytes(500))
    code, _, err = _cli(capsys, *_track(track_inputs, frames=bad))
    assert code == 1
    _one_line_error(err, bad)
    assert track_inputs["out"].read_text() == "old tracks\n"


_COORD = st.one_of(st.floats(-100, 150), st.just(float("nan")), st.just(float("inf")))


@FEW
@given(picks=st.lists(st.tuples(st.integers(-1, 3), _COORD, _COORD, st.integers(-2, 40)), min_size=1, max_size=4))
def test_random_picks_give_tracks_or_a_clear_error(picks):
    """Random picks tables (NaN, inf, outside the image, repeated numbers, bad sizes) through track_markers."""
    frames = [np.pad(np.full((5, 5), 200, np.uint8), 20)] * 3  # a 45 x 45 image, one marker at (22, 22)
    table = pd.DataFrame(picks, columns=["point", "x", "y", "half_size"])
    try:
        tracks = wp.track_markers(frames, table, progress=False)
    except ValueError as exc:
        assert "\n" not in str(exc) and str(exc)
        return
    assert set(wp.TRACK_COLUMNS) <= set(tracks.columns)
    assert len(tracks) == 3 * table["point"].nunique()
    assert set(tracks["status"]) <= {"ok", "flagged", "lost", "manual", "interpolated"}
    ok = tracks[tracks["status"] == "ok"]
    assert np.isfinite(ok[["x", "y"]].to_numpy()).all()
    assert ((ok[["x", "y"]] >= -0.5) & (ok[["x", "y"]] <= 44.5)).all().all()


def test_output_folder_that_is_a_file(tmp_path):
    (tmp_path / "results").write_text("keep")
    with pytest.raises(NotADirectoryError, match=r"results/run cannot be created: .*results exists and is not a folder"):
        wp.pipeline.analyse_points(wp.empty_points(), {}, out=tmp_path / "results" / "run")
    assert (tmp_path / "results").read_text() == "keep"


@FEW
@given(data=st.binary(max_size=300), suffix=st.sampled_from([".json", ".csv"]))
def test_random_bytes_as_picks(tmp_path_factory, data, suffix):
    p = tmp_path_factory.mktemp("picks") / f"picks{suffix}"
    p.write_bytes(data)
    try:
        table = wp.load_picks(p, "left")
    except (ValueError, FileNotFoundError) as exc:
        assert str(p) in str(exc) and "\n" not in str(exc), str(exc)
    else:  # only a well-formed table may come back
        assert {"point", "x", "y"} <= set(table.columns) and np.isfinite(table[["x", "y"]].to_numpy()).all()


@pytest.mark.parametrize("ddof", [-1, 0.5, True])
def test_length_statistics_ddof_checked(ddof):
    with pytest.raises(ValueError, match="ddof must be a whole number >= 0"):
        wp.length_statistics(np.zeros((5, 2, 3)), [(0, 1)], ddof=ddof)


# ---------------------------------------------- tracker checkpoints and corrections (issue 13 items 2, 4)
def _checkpoint_bytes(kind, track_inputs, capsys):
    if kind == "empty":
        return b""
    if kind == "random":
        return np.random.default_rng(5).bytes(500)
    if kind == "foreign":
        import io

        buf = io.BytesIO()
        np.savez(buf, a=np.arange(3))
        return buf.getvalue()
    full = track_inputs["dir"] / "full.npz"  # "truncated": the first half of a real checkpoint
    assert _cli(capsys, *_track(track_inputs, "--checkpoint", full, out=track_inputs["dir"] / "t0.csv"))[0] == 0
    data = full.read_bytes()
    return data[: len(data) // 2]


@pytest.mark.parametrize("kind", ["empty", "random", "foreign", "truncated"])
def test_bad_checkpoint_names_the_file_and_the_way_out(track_inputs, capsys, kind):
    ck = track_inputs["dir"] / "ck.npz"
    ck.write_bytes(_checkpoint_bytes(kind, track_inputs, capsys))
    code, _, err = _cli(capsys, *_track(track_inputs, "--checkpoint", ck))
    assert code == 1 and track_inputs["out"].read_text() == "old tracks\n"
    line = _one_line_error(err, ck)
    assert "delete" in line or "another" in line, line


@FEW
@given(data=st.binary(max_size=300))
def test_random_bytes_as_checkpoint(tmp_path_factory, data):
    d = tmp_path_factory.mktemp("ck")
    ck = d / "ck.npz"
    ck.write_bytes(data)
    frames = [np.pad(np.full((5, 5), 200, np.uint8), 20)] * 3
    with pytest.raises(ValueError) as info:
        wp.track_markers(frames, pd.DataFrame({"point": [0], "x": [22.0], "y": [22.0]}), checkpoint=ck, progress=False)
    assert str(ck) in str(info.value) and "\n" not in str(info.value)


def test_checkpoint_every_on_the_cli(track_inputs, capsys):
    ck = track_inputs["dir"] / "ck.npz"
    code, _, err = _cli(capsys, *_track(track_inputs, "--checkpoint", ck, "--checkpoint-every", "2"))
    assert code == 0, err
    with pytest.raises(SystemExit) as info:  # argparse: usage and one error line, exit code 2
        main([str(a) for a in _track(track_inputs, "--checkpoint", ck, "--checkpoint-every", "0")])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "--checkpoint-every" in err and "Traceback" not in err


@pytest.mark.parametrize("data", [
    b"", b"\x00\x9d\xff binary \x01", b"point,frame\n1\n", b"point,frame,x,y\nnan,0,1,2\n", b"point,frame,x,y\n0,,1,2\n",
])
def test_bad_corrections_file_names_the_file(tmp_path, data):
    p = tmp_path / "corrections.csv"
    p.write_bytes(data)
    with pytest.raises(ValueError) as info:
        wp.load_corrections(p)
    assert str(p) in str(info.value) and "\n" not in str(info.value)


def test_ctrl_c_saves_a_checkpoint_and_the_rerun_matches(track_inputs, capsys, monkeypatch):
    """Ctrl-C mid-sequence: exit 130 with one line, a checkpoint on disk, and a resumed run equal to a clean one."""
    import inspect

    import wingphoto.pipeline as pipeline

    real = pipeline.read_sequence

    class Frames:  # Ctrl-C at the tracker's first read of frame 4 (the sequence checks read it before)
        armed = True

        def __init__(self, seq):
            self.seq = seq

        def __len__(self):
            return len(self.seq)

        def __getitem__(self, k):
            if Frames.armed and isinstance(k, (int, np.integer)) and k == 4 and any(
                    f.function == "track_markers" for f in inspect.stack(0)):
                Frames.armed = False
                raise KeyboardInterrupt
            return self.seq[k]

        def __getattr__(self, name):
            return getattr(self.seq, name)

    clean = track_inputs["dir"] / "clean.csv"
    assert _cli(capsys, *_track(track_inputs, out=clean))[0] == 0
    monkeypatch.setattr(pipeline, "read_sequence", lambda *a, **k: Frames(real(*a, **k)))
    ck = track_inputs["dir"] / "ck.npz"
    code, _, err = _cli(capsys, *_track(track_inputs, "--checkpoint", ck, "--checkpoint-every", "1000"))
    said = [ln for ln in err.replace("\r", "\n").splitlines() if ln.startswith("wingphoto track")]
    assert code == 130 and "Traceback" not in err and len(said) == 1 and "interrupted" in said[0], err
    assert not Frames.armed and ck.is_file() and track_inputs["out"].read_text() == "old tracks\n"
    monkeypatch.setattr(pipeline, "read_sequence", real)
    assert _cli(capsys, *_track(track_inputs, "--checkpoint", ck))[0] == 0
    pd.testing.assert_frame_equal(read_tracks_csv(track_inputs["out"]), read_tracks_csv(clean))
