"""Sigma honesty of the tracker on synthetic scenarios (DEV seeds), against the exact truth."""
import numpy as np
import pytest

from wingphoto import track_markers
from wingphoto.synth import scenarios
from wingphoto.validation import point_errors, summarize_errors


def _score(name, camera, seed=0):
    seq = scenarios.render_scenario(name, seed=seed)
    tr = track_markers(seq.frames(camera), seq.picks(camera), camera=camera, progress=False)
    a = point_errors(tr, seq, camera)
    return summarize_errors(a["error"], a["ok"], a["visible"], a["sigma"])


def test_sigma_honest_under_glare():
    # honest: >= 95 % of ok points within 3 sigma, median error/sigma in [0.5, 2]; measured
    # 0.9986 and 0.63
    # (a Gaussian: 98.9 %, 1.18) on DEV seed 0, left camera
    s = _score("clean_glare", "left")
    assert s["confident_errors"] == 0
    assert s["ok_share"] > 0.99, s
    assert s["within_3_sigma"] >= 0.95, s
    assert 0.5 <= s["median_error_over_sigma"] <= 2.0, s


def test_sigma_on_specular_markers_at_measured_level():
    # A specular highlight leaves a shape bias the noise terms of sigma do not see; the
    # texture term (``tex``) and the shape term now carry it: the honesty target (>= 95 %
    # within 3 sigma) holds on DEV seed 0, left camera (measured 0.989, median error/sigma
    # 1.03; 0.863 and 1.32 at 7a1932a, before the texture term: this test fails there).
    s = _score("specular_markers", "left")
    assert s["confident_errors"] == 0
    assert s["ok_share"] > 0.99, s
    assert s["within_3_sigma"] >= LEVEL_SPECULAR, s
    assert 0.5 <= s["median_error_over_sigma"] <= 2.0, s


#: the honesty target; measured 0.989 (median error/sigma 1.03) at the texture term's commit
LEVEL_SPECULAR = 0.95


def _streak(length, rng, shape=(61, 53), centre=(26.3, 30.2), diameter=8.0):
    """A disc swept ``length`` px along y (a motion streak, the truth its middle) + noise."""
    from wingphoto.synth import render_discs

    offs = np.linspace(-0.5 * length, 0.5 * length, max(int(2 * length) + 1, 1))
    img = np.mean([render_discs(np.array([[centre[0], centre[1] + o]]), np.array([diameter]), shape, rng=rng,
                                dtype=np.float32) for o in offs], axis=0)
    return img + rng.normal(0.0, 1.0, img.shape).astype(np.float32), np.array(centre)


@pytest.mark.parametrize("use_numba", [False, True])
def test_sigma_says_when_the_disk_cuts_a_motion_streak(use_numba):
    # The mechanism of the confident errors under motion blur (1-1.9 px, status ok): at
    # ~27 px/frame a marker's streak is longer than its disk, the disk cuts it, and the
    # centroid along the streak is where the disk was put (the pixel nearest the estimate),
    # not the streak's middle: a start 1 px off gives a centre ~1 px off, with a small noise
    # sigma (many pixels). The rim term must make sigma exceed max_sigma there, and stay
    # negligible for a blob inside its disk (a short streak, a disc).
    from wingphoto.track import engine, refine
    from wingphoto.track.options import TrackOptions
    from wingphoto.track.sigma import point_sigma, sigma_numpy

    if use_numba and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    rng = np.random.default_rng(11)
    rb = 4.0  # the disc's radius; the tracker's disk is 3 px larger
    rd = rb + 3.0
    was = engine.use_numba()
    engine.try_numba(use_numba)
    try:
        out = {}
        for length in (0.0, 4.0, 26.0):
            img, c = _streak(length, rng)
            errs, sig = [], []
            for dy in (0.0, 1.0):
                x, y, m, inf = refine._refine(img, np.array([c[0]]), np.array([c[1] + dy]), np.array([rd]),
                                              np.ones(1), np.ones(1), None, 2, rmax=np.array([rd]))
                errs.append(y[0] - c[1])
                args = (1.0, inf["spread"][0], inf["bgres"][0], inf["peak"][0], 1.0, rb, inf["dshape"][0],
                        inf["rim"][0], inf["tex"][0], inf["valley"][0])
                s = float(sigma_numpy(*args))
                assert point_sigma(*args) == pytest.approx(s, rel=1e-9)
                sig.append(s)
            out[length] = (errs, sig, inf["rim"][0])
    finally:
        engine.try_numba(was)
    max_sigma = TrackOptions().max_sigma
    errs, sig, rim = out[26.0]
    assert abs(errs[1] - errs[0]) > 0.8, out  # the centre follows the disk, not the streak
    assert min(sig) > max_sigma, out  # ... and sigma says so: imprecise, not ok
    for length in (0.0, 4.0):
        errs, sig, rim = out[length]
        assert abs(errs[1] - errs[0]) < 0.05, out  # a blob inside its disk: the centre is the blob's
        assert rim < 0.01 and max(sig) < 0.1, out


@pytest.mark.parametrize("use_numba", [False, True])
def test_sigma_says_when_a_highlight_streak_pulls_the_centre(use_numba):
    # Real dots of cam1 (~5 px, a ~35 DN face) carry a specular spot; motion blur draws it
    # into a streak over a good part of the dot, above the clip level wherever it lies, so
    # clipping hardly moves the centre, the centre follows the spot, and the texture term
    # sees only the dot's central pixels: ok points 1.0-1.4 px off at sigma 0.21-0.25
    # (realdots cam1 DEV seeds 5, 6, 29, 30; here 0.97 px at sigma 0.205 without the term).
    # The shape's own centre (every weighted pixel alike) stays on the dot, and how far the
    # two differ enters sigma (refine.SHAPE_BIN_GAIN): imprecise, not ok. A uniform dot,
    # and the same dot with the spot at its centre, keep a small sigma.
    from wingphoto.synth import render_discs
    from wingphoto.track import engine, refine
    from wingphoto.track.options import TrackOptions
    from wingphoto.track.sigma import point_sigma, sigma_numpy

    if use_numba and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    rng = np.random.default_rng(5)
    shape, c = (41, 41), np.array([20.3, 19.8])

    def streak(centre_dy, diameter, length):
        offs = np.linspace(-0.5 * length, 0.5 * length, 13)
        return np.mean([render_discs(np.array([[c[0], c[1] + centre_dy + o]]), np.array([diameter]), shape, rng=rng,
                                     dtype=np.float32) for o in offs], axis=0)

    def dot(spot_dy):
        img = 50.0 + 35.0 * streak(0.0, 5.0, 6.0)  # a 5 px dot, a 6 px motion streak
        if spot_dy is not None:  # a 2 px spot, streaked over 3 px, inside the dot
            img = img + 150.0 * streak(spot_dy, 2.0, 3.0)
        return img + rng.normal(0.0, 2.0, shape).astype(np.float32)

    was = engine.use_numba()
    engine.try_numba(use_numba)
    out = {}
    try:
        for name, spot_dy in (("uniform", None), ("centred spot", 0.0), ("spot below", 2.0)):
            img = dot(spot_dy)
            x, y, m, inf = refine._refine(img, np.array([c[0]]), np.array([c[1]]), np.array([5.5]),
                                          np.ones(1), np.array([2.0]), None, 2, rmax=np.array([5.5]))
            args = (2.0, inf["spread"][0], inf["bgres"][0], inf["peak"][0], 1.0, 2.5, inf["dshape"][0],
                    inf["rim"][0], inf["tex"][0], inf["valley"][0])
            s = float(sigma_numpy(*args))
            assert point_sigma(*args) == pytest.approx(s, rel=1e-9)
            out[name] = (float(np.hypot(x[0] - c[0], y[0] - c[1])), s)
    finally:
        engine.try_numba(was)
    max_sigma = TrackOptions().max_sigma
    err, sig = out["spot below"]
    assert err > 0.7, out  # the spot pulls the centre ...
    assert sig > max_sigma, out  # ... and sigma says so
    for name in ("uniform", "centred spot"):
        err, sig = out[name]
        assert err < 0.15 and sig < 0.15, out


def test_persistent_imprecision_flags_the_dip_not_a_lone_spike():
    from wingphoto.track.sigma import flag_persistent_imprecision
    from wingphoto.track.status import _R, FLAGGED, OK

    sig = np.array([[0.30, 0.10], [0.40, 0.10], [0.22, 2.00], [0.35, 0.10], [0.30, 0.10], [np.nan, 0.10],
                     [np.nan, 0.10]])
    status = np.full(sig.shape, OK, np.int8)
    status[[0, 1, 3, 4], 0] = FLAGGED  # marker 0: imprecise on every frame but one dip to 0.22
    reason = np.zeros(sig.shape, np.int8)
    n = flag_persistent_imprecision(status, reason, sig, 0.25)
    assert n == 1 and status[2, 0] == FLAGGED and reason[2, 0] == _R["imprecise"]
    # marker 1: one frame at sigma 2 (capped at 0.5) among 0.1s flags no neighbour of it;
    # the spike itself stays as the tracker judged it (ok here: only ok points change)
    assert (status[:, 1] == OK).all()
    # a marker whose frames around average just above max_sigma (0.26): its ok point at
    # 0.24 stays ok, one that dips to 0.15 (below 0.7 of their mean) is flagged
    around = np.array([[0.26], [0.26], [0.24], [0.26], [0.26]])
    for own, flagged in ((0.24, False), (0.15, True)):
        around[2, 0] = own
        st = np.array([[FLAGGED], [FLAGGED], [OK], [FLAGGED], [FLAGGED]], np.int8)
        assert flag_persistent_imprecision(st, np.zeros_like(st), around, 0.25) == int(flagged)
    # a lone frame (no other finite sigma in its window) is left as it is
    lone = np.array([[0.2], [np.nan], [np.nan], [np.nan], [np.nan]])
    st = np.full(lone.shape, OK, np.int8)
    assert flag_persistent_imprecision(st, np.zeros_like(st), lone, 0.15) == 0


@pytest.mark.parametrize("use_numba", [False, True])
def test_sigma_sees_the_dim_face_a_streaked_highlight_outshines(use_numba):
    # Real dots of cam1 moved fast (dropped-frame stress seeds 454, 568, 631): the spot,
    # streaked by motion blur, outshines a dim ~7 px face at every cut taken from the
    # contrast, so the centroid and the shape above the cut both follow it; the disk, sized
    # on the bright blob, holds the face only in part. Ok points 1.0-1.4 px off at sigma
    # 0.17-0.24. The centre of every pixel a few noise sigmas above the background, the
    # ring's included (refine.LOW_CUT_NOISE), sees the face: here ~1.1 and ~1.8 px off at
    # sigma 0.20 and 0.19 without the term. A dim dot without a spot, and one beside a
    # membrane edge, keep their small sigma.
    from wingphoto.synth import render_discs
    from wingphoto.track import engine, refine
    from wingphoto.track.options import TrackOptions
    from wingphoto.track.sigma import sigma_numpy

    if use_numba and not engine.NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    shape, c = (41, 41), np.array([20.3, 19.8])

    def streak(rng, dx, dy, diameter, length=5.0):
        offs = np.linspace(-0.5 * length, 0.5 * length, 13)
        return np.mean([render_discs(np.array([[c[0] + dx, c[1] + dy + o]]), np.array([diameter]), shape, rng=rng,
                                     dtype=np.float32) for o in offs], axis=0)

    def measure(face, spot_off, edge=False):
        rng = np.random.default_rng(7)
        img = 55.0 + 30.0 * streak(rng, 0.0, 0.0, face)
        if spot_off is not None:  # a 2.5 px spot of 250 DN up and to the right, streaked too
            img = img + 250.0 * streak(rng, spot_off, -0.6 * spot_off, 2.5)
        if edge:
            img[:, 27:] -= 25.0  # the membrane ends 6.7 px to the side
        img = img + rng.normal(0.0, 4.0, shape).astype(np.float32)
        start = c + (0.0 if spot_off is None else np.array([spot_off, -0.6 * spot_off]))
        x, y, _, inf = refine._refine(img, start[:1], start[1:], np.array([4.95]), np.ones(1), np.array([4.0]), None,
                                      2, rmax=np.array([4.95]))
        sig = float(sigma_numpy(4.0, inf["spread"][0], inf["bgres"][0], inf["peak"][0], 1.0, 2.0, inf["dshape"][0],
                                inf["rim"][0], inf["tex"][0], inf["valley"][0]))
        return float(np.hypot(x[0] - c[0], y[0] - c[1])), sig

    was = engine.use_numba()
    engine.try_numba(use_numba)
    try:
        pulled = [measure(7.0, 1.2), measure(8.0, 1.6)]
        plain = [measure(7.0, None), measure(5.0, None, edge=True)]
    finally:
        engine.try_numba(was)
    max_sigma = TrackOptions().max_sigma
    for err, sig in pulled:
        assert err > 1.0 and sig > max_sigma, pulled
    for err, sig in plain:
        assert err < 0.15 and sig < 0.2, plain


def _highlighted_dot(T=8, seed=0):
    """A dim dot 13 px across (40 DN on 30) with a bright highlight (160 DN) 3.6 px off its
    centre, moving (1.5, 0.7) px a frame: frames (uint8) and the shape's centre per frame."""
    import cv2

    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:96, 0:96].astype(float)
    frames, truth = [], []
    for t in range(T):
        cx, cy = 40.3 + 1.5 * t, 47.6 + 0.7 * t
        img = 30.0 + 40.0 * np.clip(7.0 - np.hypot(xx - cx, yy - cy), 0, 1)
        img += 160.0 * np.exp(-((xx - cx + 3.5) ** 2 + (yy - cy - 1.0) ** 2) / (2 * 1.1**2))
        img = cv2.GaussianBlur(img, (0, 0), 1.0) + rng.normal(0, 3.0, img.shape)
        frames.append(np.clip(img, 0, 255).astype(np.uint8))
        truth.append((cx, cy))
    return np.stack(frames), np.array(truth)


def test_a_large_dot_is_centred_on_its_face_not_its_highlight():
    # the blob above half the contrast is the highlight: a disk sized to it (+ 3 px) left
    # most of the face out and centred the highlight, 3.7 px off, then lost the dot (real
    # dots upsampled 1.5-2x: ok 1-4 px off). The frame-0 disk now reaches beyond the face
    # (tracker._measure_pick's face radius, options._RD_FACE_MARGIN). (measured: every
    # frame found, 0.65-0.74 px off, flagged imprecise at sigma 0.41-0.49)
    frames, truth = _highlighted_dot()
    tr = track_markers(frames, np.round(truth[:1]), progress=False)
    err = np.hypot(tr["x"].to_numpy() - truth[:, 0], tr["y"].to_numpy() - truth[:, 1])
    assert np.isfinite(err).all()
    assert err.max() < 1.0
    ok = (tr["status"] == "ok").to_numpy()
    assert (err[~ok] < 3 * tr["sigma"].to_numpy()[~ok]).all()
