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
