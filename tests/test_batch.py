"""wingphoto.batch: manifest, sequential vs Dask LocalCluster, failures, resume, CLI.

The batch is built from small trials: two cut from data-samples (8 frames each, calibrated
from 11 of the sample's checkerboard pairs), one rendered by wingphoto.synth with its true
rig as the calibration .mat, and one whose left sequence holds a truncated TIFF.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import wingphoto as wp
from wingphoto import batch, pipeline
from wingphoto.batch import load_manifest, run_batch
from wingphoto.cli import main as cli_main

SAMPLES = Path(__file__).resolve().parents[1] / "data-samples"
CALIB = SAMPLES / "calibration"  # 11 of its 21 pairs (odd numbers) in the test manifest
PAIRS = [(18, 19), (20, 21), (22, 23), (24, 25)]
TABLES = ("summary.csv", "trials.csv", "failures.csv")
TRIAL_FILES = ("tracks.csv", "points3d.csv", "lengths.csv")


def _true_lengths(points3d):
    P = points3d[0]
    return {f"{i}-{j}": float(np.linalg.norm(P[i] - P[j])) for i, j in PAIRS}


def _write_manifest(root, *, extra=""):
    """The test manifest (paths relative to it); returns its path."""
    truth = np.load(SAMPLES / "flapping" / "truth.npz")
    nominal = ", ".join(f'"{k}" = {v!r}' for k, v in _true_lengths(truth["points3d"]).items())
    text = f"""
[batch]
name = "test batch"
group_by = ["condition"]

[defaults]
left = "{SAMPLES}/flapping/left"
right = "{SAMPLES}/flapping/right"
picks = "{SAMPLES}/flapping/picks.json"

[defaults.calibration]
left = "{CALIB}/left/calib_*[13579].tif"
right = "{CALIB}/right/calib_*[13579].tif"
pattern_size = [9, 6]
square_size = 8.0

[defaults.analysis]
length_pairs = {[list(p) for p in PAIRS]}
nominal_lengths = {{{nominal}}}
reference_ids = [20, 21, 22, 23, 24, 25]

[[trial]]
id = "sample-a"
labels = {{condition = "open air", repeat = 1}}
frames = [0, 8]

[[trial]]
id = "sample-b"
labels = {{condition = "open air", repeat = 2}}
frames = [30, 38]
picks = "{SAMPLES}/batch/picks_frame30.csv"

[[trial]]
id = "synth"
labels = {{condition = "vacuum", repeat = 1}}
calibration = "synth/rig.mat"
left = "synth/left"
right = "synth/right"
picks = "synth/picks.csv"
analysis = {{nominal_lengths = {{"18-19" = {{synth_18_19}}}}}}

[[trial]]
id = "corrupt"
labels = {{condition = "vacuum", repeat = 2}}
calibration = "synth/rig.mat"
left = "corrupt/left"
right = "synth/right"
picks = "synth/picks.csv"
{extra}"""
    return text


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """A folder with the synthetic trial, the corrupt trial and the manifest."""
    if not (SAMPLES / "flapping" / "truth.npz").is_file() or not (SAMPLES / "batch" / "picks_frame30.csv").is_file():
        pytest.skip("data-samples not present")
    import tifffile

    root = tmp_path_factory.mktemp("study")
    seq = wp.synth.render_flapping(n_frames=8, seed=11, phase_deg=60.0)
    for side in ("left", "right"):
        (root / "synth" / side).mkdir(parents=True)
        for t, img in enumerate(getattr(seq, side)):
            tifffile.imwrite(root / "synth" / side / f"frame_{t:04d}.tif", img)
    rows = ["camera,point,frame,x,y,half_w,half_h"]
    for side in ("left", "right"):
        rows += [f"{side},{k},0,{x},{y},8,8" for k, (x, y) in enumerate(seq.picks(side))]
    (root / "synth" / "picks.csv").write_text("\n".join(rows) + "\n")
    wp.save_bouguet_stereo(seq.rig, root / "synth" / "rig.mat")
    # the corrupt trial: the synthetic left view with frame 5 cut short
    shutil.copytree(root / "synth" / "left", root / "corrupt" / "left")
    bad = root / "corrupt" / "left" / "frame_0005.tif"
    bad.write_bytes(bad.read_bytes()[:3000])
    synth_len = float(np.linalg.norm(seq.points3d[0, 18] - seq.points3d[0, 19]))
    text = _write_manifest(root).replace("{synth_18_19}", repr(synth_len))
    (root / "study.toml").write_text(text)
    return {"root": root, "manifest": root / "study.toml", "seq": seq}


@pytest.fixture(scope="module")
def sequential(study, tmp_path_factory):
    """The batch run in this process, one stage after the other."""
    out = tmp_path_factory.mktemp("sequential")
    return run_batch(study["manifest"], out=out, workers=1, progress=False)


# ----------------------------------------------------------------------------- manifest
def test_manifest_defaults_paths_and_labels(study):
    m = load_manifest(study["manifest"])
    assert [t.id for t in m.trials] == ["sample-a", "sample-b", "synth", "corrupt"]
    assert m.group_by == ("condition",)
    a, b, s, _ = m.trials
    assert a.frames == (0, 8, 1) and b.frames == (30, 38, 1) and s.frames is None
    assert a.labels == {"condition": "open air", "repeat": "1"}
    assert a.calibration == b.calibration and a.calibration.key() == b.calibration.key()
    assert s.calibration.mat == str(study["root"] / "synth" / "rig.mat")  # relative to the manifest
    assert s.left == str(study["root"] / "synth" / "left")
    # analysis tables merge key by key over the defaults
    assert s.settings().reference_ids == (20, 21, 22, 23, 24, 25)
    assert set(s.settings().nominal_lengths) == {(18, 19)}
    assert len(a.settings().nominal_lengths) == 4
    assert a.fingerprint() != b.fingerprint()


@pytest.mark.parametrize("edit, message", [
    ('[[trial]]\nid = "x"\nlabels = {condition = "c"}\nspeed = 3\n', "unknown key(s) ['speed']"),
    ('[[trial]]\nid = "sample-a"\n', "used twice"),
    ('[[trial]]\nid = "bad id"\n', "needs an id"),
    ('[[trial]]\nid = "x"\nframes = [10, 5]\n', "frames must be [start, stop]"),
    ('[[trial]]\nid = "x"\nanalysis = {lenght_pairs = [[1, 2]]}\n', "unknown analysis setting(s) ['lenght_pairs']"),
    ('[[trial]]\nid = "x"\ncalibration = "rig.txt"\n', "give a toolbox Calib_Results_stereo.mat"),
    ('[[trial]]\nid = "x"\npoints = [18, 19]\n', "not in points"),
])
def test_manifest_errors_name_the_trial_and_key(study, tmp_path, edit, message):
    text = study["manifest"].read_text() + edit
    path = tmp_path / "m.toml"
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        load_manifest(path)
    assert message in str(err.value)
    assert str(path) in str(err.value)


def test_manifest_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="docs/batch.md"):
        load_manifest(tmp_path / "none.toml")


# ----------------------------------------------------------------------------- results
def test_sequential_batch_matches_truth_and_isolates_the_failure(study, sequential):
    r = sequential
    assert set(r.done) == {"sample-a", "sample-b", "synth"} and r.skipped == ()
    # the corrupt trial is reported, with its stage and the file, and stopped nothing else
    assert list(r.failures["trial"]) == ["corrupt"]
    f = r.failures.iloc[0]
    assert f["stage"] == "check sequences"  # the check reads every frame first
    assert "frame_0005.tif" in f["error"]
    assert f["log"].startswith(".cache/checks/check-")  # the shared check of its recordings failed
    assert (r.out / f["log"]).is_file() and "Traceback" in (r.out / f["log"]).read_text()
    assert not (r.out / "trials" / "corrupt").exists()
    # one row per condition and pair, pooled over the condition's trials
    s = r.summary.set_index(["condition", "i", "j"])
    assert list(r.summary.columns[:2]) == ["condition", "n_trials"]
    assert s.loc[("open air", 18, 19), "n_trials"] == 2
    assert s.loc[("open air", 18, 19), "n_frames"] == 16 and s.loc[("vacuum", 18, 19), "n_frames"] == 8
    # lengths of rigid pairs against the true lengths: triangulation noise is ~1e-3 mm here
    assert np.all(np.abs(r.summary["bias"].dropna()) < 0.05)
    assert np.all(r.summary["std"] < 0.01)
    assert r.summary.loc[r.summary["condition"] == "vacuum", "nominal"].notna().sum() == 1
    assert np.all(r.summary["ok_share"] > 0.95)
    # pooled statistics equal those of the concatenated per-frame lengths
    la = pd.read_csv(r.out / "trials" / "sample-a" / "lengths.csv")
    lb = pd.read_csv(r.out / "trials" / "sample-b" / "lengths.csv")
    both = pd.concat([la, lb]).query("i == 20 and j == 21")["length"]
    assert sorted(pd.read_csv(r.out / "trials" / "sample-b" / "tracks.csv")["frame"].unique()) == list(range(30, 38))
    row = s.loc[("open air", 20, 21)]
    assert row["mean"] == pytest.approx(both.mean(), abs=1e-12)
    assert row["std"] == pytest.approx(both.std(ddof=1), abs=1e-12)
    assert (row["min"], row["max"]) == (both.min(), both.max())
    # per-trial table: one row per trial and pair, labels as columns
    assert list(r.trials["trial"].unique()) == ["sample-a", "sample-b", "synth"]
    assert {"condition", "repeat"} <= set(r.trials.columns)
    # the written tables are the returned ones
    for name, df in (("summary.csv", r.summary), ("trials.csv", r.trials)):
        back = pd.read_csv(r.out / name)
        assert back.shape == df.shape
    # one shared calibration, computed once and cached by content
    mats = list((r.out / ".cache" / "calibration").glob("*.mat"))
    assert len(mats) == 1
    rec = json.loads((r.out / "trials" / "sample-b" / "trial.json").read_text())
    assert rec["calibration"]["mat"] == str(mats[0])
    log = (r.out / "trials" / "synth" / "log.txt").read_text()
    assert "track left done" in log and "analyse done" in log
    assert not (r.out / ".partial" / "synth").exists()


def test_local_cluster_gives_identical_tables(study, sequential, tmp_path):
    # threads in this process (processes=False): starts in ~3 s against ~10 s for worker
    # processes on this shared 2-core machine; the worker code path is the same
    r = run_batch(study["manifest"], out=tmp_path / "dask", workers=2, progress=False,
                  cluster_options={"processes": False, "dashboard_address": None})
    assert r.engine == "local cluster (2 workers)"
    assert set(r.done) == set(sequential.done)
    for name in TABLES:
        assert (r.out / name).read_bytes() == (sequential.out / name).read_bytes(), name
    for tid in sequential.done:
        for name in TRIAL_FILES:
            a = (r.out / "trials" / tid / name).read_bytes()
            assert a == (sequential.out / "trials" / tid / name).read_bytes(), (tid, name)


def test_resume_after_interrupt(study, sequential, tmp_path, monkeypatch):
    real = pipeline.track_folder
    calls = []

    def interrupted(frames, picks, *, camera="left", checkpoint=None, **kw):
        trial = Path(checkpoint).parent.name
        if (trial, camera) == ("sample-b", "right"):
            raise KeyboardInterrupt  # Ctrl-C in the middle of the second trial
        calls.append((trial, camera))
        return real(frames, picks, camera=camera, checkpoint=checkpoint, **kw)

    out = tmp_path / "batch"
    cache = sequential.out / ".cache" / "calibration"  # the cluster test recalibrates; this one need not
    monkeypatch.setattr(pipeline, "track_folder", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_batch(study["manifest"], out=out, workers=1, progress=False, cache=cache)
    assert calls == [("sample-a", "left"), ("sample-a", "right"), ("sample-b", "left")]
    assert (out / "trials" / "sample-a" / "trial.json").is_file()
    assert (out / ".partial" / "sample-b" / "tracks_left.csv").is_file()
    assert not (out / "trials" / "sample-b").exists() and not (out / "summary.csv").exists()

    calls.clear()
    def counted(*args, **kw):
        calls.append(Path(kw["checkpoint"]).parent.name)
        return real(*args, **kw)

    monkeypatch.setattr(pipeline, "track_folder", counted)
    r = run_batch(study["manifest"], out=out, workers=1, progress=False, cache=cache)
    # finished trial skipped, the half-done trial tracked only its right view
    assert r.skipped == ("sample-a",)
    assert calls == ["sample-b", "synth", "synth"]  # the corrupt trial fails on opening its frames
    rec = json.loads((out / "trials" / "sample-b" / "trial.json").read_text())
    assert rec["resumed"] is True
    for name in TABLES:
        assert (out / name).read_bytes() == (sequential.out / name).read_bytes(), name

    # a third run has nothing left to do but the failed trial; a changed trial is redone
    calls.clear()
    text = study["manifest"].read_text().replace("frames = [0, 8]", "frames = [0, 6]")
    changed = study["root"] / "changed.toml"
    changed.write_text(text)
    r = run_batch(changed, out=out, workers=1, progress=False, cache=cache)
    assert r.skipped == ("sample-b", "synth") and calls == ["sample-a", "sample-a"]
    assert r.summary.set_index(["condition", "i", "j"]).loc[("open air", 18, 19), "n_frames"] == 14


def test_cli_batch(study, sequential, tmp_path, capsys):
    out = tmp_path / "cli"
    shutil.copytree(sequential.out, out)  # finished trials are skipped: only the failure runs again
    code = cli_main(["batch", str(study["manifest"]), "--out", str(out), "--workers", "1", "--no-progress"])
    text = capsys.readouterr()
    assert code == 1  # a trial failed
    assert "FAILED corrupt at check sequences" in text.out
    assert "1 of 4 trial(s) to run (sequential)" in text.err
    assert (out / "summary.csv").read_bytes() == (sequential.out / "summary.csv").read_bytes()
    with pytest.raises(SystemExit):
        cli_main(["batch", str(study["manifest"]), "--out", str(out), "--workers", "0"])
    assert "--workers must be a whole number >= 1" in capsys.readouterr().err
    assert cli_main(["batch", str(tmp_path / "missing.toml"), "--out", str(out)]) == 1
    assert "not found" in capsys.readouterr().err


def test_batch_module_api():
    assert wp.run_batch is batch.run_batch and wp.load_manifest is batch.load_manifest
    assert "batch" in __import__("wingphoto.cli", fromlist=["COMMANDS"]).COMMANDS
