"""The independent renderer's truth agrees with its images (wingphoto.synth.independent)."""
import numpy as np
import pytest

from wingphoto.synth import independent as ind


def _coverage_centroids(seed, t, ss):
    """Centroid of each wing marker's unblurred coverage and its truth, at time t, left camera."""
    sc = ind._scene(seed, "clean")
    cam = ind.IndependentCamera(*sc.cams["left"], 512)
    eu, ev, n, _, _ = ind._pose(sc, t)
    cw, _ = ind._marker_world(sc, t)
    truth = cam.project(cw)
    depth = cam.R[2] @ np.zeros(3) + cam.t[2]
    out = []
    for k in range(len(sc.markers)):
        one = ind._Scene(sc.markers[k:k + 1], sc.paint[k:k + 1], sc.motion, sc.psi0, sc.tex, sc.veins,
                         sc.glare_path)
        cov, _ = ind._marker_cover(one, cam, truth[k:k + 1], cw[k:k + 1], eu, ev, n, ss, depth)
        ys, xs = np.nonzero(cov)
        w = cov[ys, xs]
        out.append((np.sum(w * xs) / w.sum(), np.sum(w * ys) / w.sum()))
    return np.array(out), truth, ind._pose(sc, t)


def test_marker_centroid_matches_projected_centre():
    """An isolated, unblurred marker's intensity centroid is within 0.05 px of the projected disk centre."""
    # psi = -psi0: mid-stroke, the plate nearly face-on to the cameras
    sc = ind._scene(0, "clean")
    t = -sc.psi0 / (2 * np.pi * ind.FLAP_HZ)
    cen, truth, _ = _coverage_centroids(0, t, ss=8)
    err = np.hypot(*(cen - truth).T)
    assert err.max() < 0.05, err
    assert err.max() > 0  # the supersampled ellipse is not the truth by construction


def test_blob_in_noiseless_frame_is_at_truth():
    """In a rendered (PSF, blur, glare) noiseless frame each face-on marker's blob is near its truth."""
    seq = ind.render_independent("clean16", seed=1, camera="right", n_frames=1, noise=False)
    img = seq.images[0].astype(float)
    wing = np.flatnonzero(seq.point_kind == "wing")
    errs = []
    for p in wing:
        if not seq.visible[0, p] or seq.view_angle[0, p] > 45:
            continue
        x, y = seq.points[0, p]
        xi, yi = int(round(x)), int(round(y))
        win = img[yi - 4: yi + 5, xi - 4: xi + 5]
        w = np.clip(win - (win.min() + 0.5 * (win.max() - win.min())), 0, None)
        yy, xx = np.mgrid[yi - 4: yi + 5, xi - 4: xi + 5]
        errs.append(np.hypot((w * xx).sum() / w.sum() - x, (w * yy).sum() / w.sum() - y))
    assert len(errs) >= 10
    assert np.median(errs) < 0.15 and max(errs) < 0.5, errs


def test_seeds_reproducible_and_distinct():
    a = ind.render_independent("clean", seed=3, camera="left", n_frames=2)
    b = ind.render_independent("clean", seed=3, camera="left", n_frames=2)
    c = ind.render_independent("clean", seed=4, camera="left", n_frames=2)
    assert np.array_equal(a.images, b.images) and np.array_equal(a.points, b.points)
    assert not np.array_equal(a.images, c.images)
    assert not np.allclose(a.points, c.points)
    assert set(ind.DEV_SEEDS).isdisjoint(ind.TEST_SEEDS)


def test_visibility_flags():
    # only the truth is used (points, view angles, visibility), the same however the images
    # are rendered: noise-free images without supersampling keep the 100 frames cheaper
    seq = ind.render_independent("hard", seed=0, camera="right", n_frames=100, n_sub=1, supersample=1, noise=False)
    wing = seq.point_kind == "wing"
    inside = np.all((seq.points >= -0.5) & (seq.points <= 511.5), axis=2)
    expect = inside & (seq.view_angle < 90)
    assert np.array_equal(seq.visible[:, wing], expect[:, wing])
    # the hard stroke turns the plate away from this camera at a reversal: some markers go invisible
    assert (~seq.visible[:, wing]).any() and seq.visible[:, wing].any()
    assert seq.visible[:, ~wing].sum() >= 0.8 * seq.visible[:, ~wing].size  # static dots mostly seen
    p = seq.picks()
    assert np.isnan(p[~seq.visible[0]]).all() and np.isfinite(p[seq.visible[0]]).all()


@pytest.mark.parametrize("kind", ["dropped", "repeated", "black", "bumped"])
def test_glitches(kind):
    seq = ind.render_independent(kind, seed=1, camera="right", n_frames=40, n_sub=1)
    g = seq.glitch
    assert seq.images.shape[0] == 40 and seq.points.shape[:2] == (40, 26)
    step = np.diff(seq.time_index)
    if kind == "dropped":
        assert sorted(step.tolist()).count(1) == 38 and step.max() == g["n_dropped"] + 1
        assert 1 <= g["n_dropped"] <= 3
    elif kind == "repeated":
        k1, k2 = g["identical_repeat"], g["renoised_repeat"]
        assert np.array_equal(seq.images[k1], seq.images[k1 - 1])
        assert not np.array_equal(seq.images[k2], seq.images[k2 - 1])
        assert np.abs(seq.images[k2].astype(int) - seq.images[k2 - 1]).mean() < 5  # same scene, new noise
        assert np.array_equal(seq.points[k2], seq.points[k2 - 1])
    elif kind == "black":
        k = g["black"]
        assert seq.images[k].max() == 0 and not seq.visible[k].any() and seq.visible[k - 1].any()
    else:
        k, (dx, dy) = g["bumped_from"], g["shift"]
        static = seq.point_kind != "wing"
        move = seq.points[k, static] - seq.points[k - 1, static]
        np.testing.assert_allclose(move, np.tile([dx, dy], (static.sum(), 1)), atol=1e-3)
        assert 3 <= abs(dx) <= 6 and 3 <= abs(dy) <= 6
        # the image moved with the truth: each reference dot's blob centroid moves by the shift
        for p in np.flatnonzero(seq.point_kind == "reference"):
            if not (seq.visible[k - 1, p] and seq.visible[k, p]):
                continue
            c = []
            for j in (k - 1, k):
                x, y = np.round(seq.points[j, p]).astype(int)
                win = seq.images[j, y - 5: y + 6, x - 5: x + 6].astype(float)
                w = np.clip(win - np.median(win) - 0.3 * (win.max() - np.median(win)), 0, None)
                yy, xx = np.mgrid[y - 5: y + 6, x - 5: x + 6]
                c.append(((w * xx).sum() / w.sum(), (w * yy).sum() / w.sum()))
            np.testing.assert_allclose(np.subtract(c[1], c[0]), [dx, dy], atol=0.25)


def test_bad_input():
    with pytest.raises(ValueError, match="kind must be one of"):
        ind.render_independent("cloudy", seed=0)
    with pytest.raises(ValueError, match="camera must be"):
        ind.render_independent("clean", seed=0, camera="middle")
    with pytest.raises(ValueError, match="bits must be 8 or 12"):
        ind.render_independent("clean", seed=0, bits=10, n_frames=1)
