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
    # KNOWN WEAK SPOT (below the >= 95 % target): a specular highlight leaves a shape bias
    # the image terms of sigma under-estimate. Guards the level measured on DEV seed 0
    # (see docs/tracker.md) against getting worse; raise it when sigma learns the bias.
    s = _score("specular_markers", "left")
    assert s["confident_errors"] == 0
    assert s["ok_share"] > 0.99, s
    assert s["within_3_sigma"] >= LEVEL_SPECULAR, s
    assert 0.5 <= s["median_error_over_sigma"] <= 2.5, s


#: measured 0.738 (median error/sigma 1.48) at commit 06a00c5
LEVEL_SPECULAR = 0.70


#: diagnostics (noise, spread, bgres, peak, score, rb, dshape) of the ok points more than
#: 1 px from the truth on the EXTRA dev seeds of edge_on before the blur term of sigma
#: (seed 7 left frame 68 point 5, 1.17 px; seed 10 left 17/5, 1.22 px; seed 11 left
#: 16/5, 1.10 px; seed 11 right 19/2, 1.42 px): their sigma was 0.16-0.23 px
_BIASED_SMEARS = np.array([
    [1.048384, 0.010402, 0.031444, 177.503245, 0.657363, 4.886025, 0.252144],
    [2.096749, 0.010690, 0.031104, 180.789697, 0.637908, 4.787307, 0.276177],
    [2.096749, 0.010163, 0.033909, 179.566147, 0.658941, 4.548642, 0.200159],
    [3.145162, 0.009363, 0.034429, 143.298239, 0.617510, 4.068429, 0.034651],
])


def test_sigma_flags_thin_mismatched_smears():
    # a blob both thin (spread * peak ~1.3-1.9, a sharp disk ~0.5) and unlike the marker
    # (score ~0.62-0.66) is biased beyond its noise: its sigma must exceed max_sigma (it
    # becomes imprecise, not a confident error); both engines agree
    from wingphoto.track.options import TrackOptions
    from wingphoto.track.sigma import point_sigma, sigma_numpy

    max_sigma = TrackOptions().max_sigma
    s = sigma_numpy(*_BIASED_SMEARS.T)
    assert np.all(s > max_sigma), s
    for row, si in zip(_BIASED_SMEARS, s):
        assert point_sigma(*row) == pytest.approx(si, rel=1e-12)


def test_blur_term_leaves_sharp_matched_blobs():
    # a sharp disk (spread * peak 0.47) matching well: no blur term, sigma as before
    from wingphoto.track import sigma as sg

    row = np.array([1.05, 0.0024, 0.005, 200.0, 0.97, 4.5, 0.03])
    s_all = sg.sigma_numpy(*row)
    saved = sg.SIGMA_BLUR
    try:
        sg.SIGMA_BLUR = 0.0
        s_none = sg.sigma_numpy(*row)
    finally:
        sg.SIGMA_BLUR = saved
    assert s_all == s_none
    assert np.isnan(sg.sigma_numpy(*np.where(np.arange(7) == 1, np.nan, row)))


def test_no_confident_error_on_edge_on_extra_seed():
    # EXTRA dev seed 10 of edge_on (not a TEST seed): one ok point 1.22 px off before the
    # blur term of sigma; it is now imprecise
    s = _score("edge_on", "left", seed=10)
    assert s["confident_errors"] == 0, s
    assert s["ok_share"] > 0.5, s
