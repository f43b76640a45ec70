"""Diagnostic figures: every function takes ax=None and returns the axes it drew on."""
import functools

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pytest

from wingphoto.calibrate import board_points, calibrate_camera, calibrate_stereo, find_corners
from wingphoto.camera import Camera, StereoRig, rodrigues
from wingphoto.plots import plot_corners, plot_coverage, plot_residuals, plot_view_errors

PATTERN = (9, 6)
SIZE = (400, 300)  # non-square, catches x/y swaps


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _poses(n, rng):
    centre = np.array([4 * 30.0, 2.5 * 30.0, 0.0])
    out = []
    for _ in range(n):
        om = np.concatenate([rng.uniform(-0.35, 0.35, 2), rng.uniform(-0.2, 0.2, 1)])
        R = rodrigues(om)
        out.append((R, np.array([rng.uniform(-20, 20), rng.uniform(-15, 15), 900.0]) - R @ centre))
    return out


@functools.lru_cache(maxsize=None)
def _mono():
    """Six views, 0.1 px noise; view 'img3.png' has 1.5 px errors."""
    rng = np.random.default_rng(0)
    cam = Camera(fc=[700, 705], cc=[199.5, 149.5], kc=[-0.1, 0.05, 0, 0, 0], image_size=SIZE)
    X = board_points(PATTERN, 30.0)
    corners = []
    for k, (R, T) in enumerate(_poses(6, rng)):
        c = cam.project(X @ R.T + T) + rng.normal(0, 0.1, (54, 2))
        if k == 3:
            c = c + rng.normal(0, 1.5, (54, 2))
        corners.append(c)
    corners[1][:5] = np.nan  # missing corners
    return calibrate_camera(corners, PATTERN, 30.0, image_size=SIZE, names=[f"img{i}.png" for i in range(6)])


@functools.lru_cache(maxsize=None)
def _stereo():
    rng = np.random.default_rng(1)
    left = Camera(fc=[700, 700], cc=[199.5, 149.5], image_size=SIZE)
    right = Camera(fc=[710, 708], cc=[205, 150], image_size=SIZE)
    rig = StereoRig(left, right, om=[0.0, 0.2, 0.0], T=[-150.0, 0.0, 15.0])
    X = board_points(PATTERN, 30.0)
    cl, cr = [], []
    for R, T in _poses(5, rng):
        xl, xr = rig.project(X @ R.T + T)
        cl.append(xl + rng.normal(0, 0.1, xl.shape))
        cr.append(xr + rng.normal(0, 0.1, xr.shape))
    return calibrate_stereo(cl, cr, PATTERN, 30.0, image_size=SIZE, estimate_tangential=False)


def test_plot_residuals_one_colour_per_used_view():
    cal = _mono()
    ax = plot_residuals(cal)
    assert isinstance(ax, matplotlib.axes.Axes)
    assert len(ax.collections) == int(cal.used.sum()) == 6
    assert [c.get_label() for c in ax.collections] == list(cal.views)
    # a compact colour scale names the views, not a legend over the data
    assert ax.get_legend() is None
    bar = ax.child_axes[0]
    assert [t.get_text() for t in bar.get_xticklabels()] == ["0", "1", "2", "3", "4", "5"]
    assert bar.get_xlabel() == "view (img….png, 6 used)"
    # the scatter is the residuals, observed - projected, missing corners left out
    off = np.ma.getdata(ax.collections[1].get_offsets())
    np.testing.assert_allclose(off[np.isfinite(off[:, 0])], cal.residuals[1][5:])
    colours = {tuple(np.round(c.get_facecolor()[0], 6)) for c in ax.collections}
    assert len(colours) == 6
    assert "Reprojection error" in ax.get_title() and "RMS" in ax.get_title()


def test_plot_residuals_draws_on_the_given_axes_and_picks_the_camera():
    st = _stereo()
    fig, (a, b) = plt.subplots(1, 2)
    assert plot_residuals(st, camera="left", ax=a) is a
    assert plot_residuals(st, camera="right", ax=b) is b
    np.testing.assert_allclose(np.ma.getdata(b.collections[0].get_offsets()), st.residuals_right[0])
    assert "right camera" in b.get_title()
    with pytest.raises(ValueError, match="camera must be 'left' or 'right'"):
        plot_residuals(st, camera="middle")
    with pytest.raises(ValueError, match="must be a CameraCalibration or StereoCalibration"):
        plot_residuals(object())


def test_plot_view_errors_names_the_worst_view():
    cal = _mono()
    ax = plot_view_errors(cal, worst=1)
    bars = ax.patches
    assert len(bars) == 6
    heights = np.array([b.get_height() for b in bars])
    np.testing.assert_allclose(heights, cal.view_errors)
    assert int(np.argmax(heights)) == 3
    notes = [t.get_text() for t in ax.texts]
    assert notes == ["img3.png"]
    red = matplotlib.colors.to_rgba("tab:red")
    assert bars[3].get_facecolor() == red and bars[0].get_facecolor() != red  # suggest_suppress
    assert [t.get_text() for t in ax.get_xticklabels()] == list(cal.views)
    assert ax.get_title().endswith("1 suggested for suppression (red)")


def test_plot_view_errors_has_no_red_when_nothing_is_suggested():
    st = _stereo()
    red = matplotlib.colors.to_rgba("tab:red")
    from wingphoto.calibrate import suggest_suppress

    assert suggest_suppress(st) == []
    fig, (a, b) = plt.subplots(1, 2)
    plot_view_errors(st, camera="left", ax=a)
    plot_view_errors(st, camera="right", ax=b)
    for ax, cam in ((a, "left"), (b, "right")):
        assert ax.get_title() == f"Reprojection error per view, {cam} camera\nnone suggested for suppression"
        assert len(ax.texts) == 0 and all(bar.get_facecolor() != red for bar in ax.patches)
        tops = [bar.get_height() + 0 for bar in ax.patches]
        assert ax.get_ylim()[1] >= max(tops)


def test_plot_view_errors_stereo_shows_both_cameras():
    st = _stereo()
    ax = plot_view_errors(st)
    assert len(ax.patches) == 2 * len(st.pairs)
    heights = np.array([b.get_height() for b in ax.patches]).reshape(2, -1).T
    np.testing.assert_allclose(heights, st.view_errors)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["left camera", "right camera"]
    assert len(plot_view_errors(st, camera="right").patches) == len(st.pairs)


def test_plot_coverage_shows_every_used_corner_in_the_image_frame():
    cal = _mono()
    ax = plot_coverage(cal)
    pts = [line for line in ax.lines if line.get_marker() == "."]
    assert len(pts) == 6
    n = sum(int(np.isfinite(line.get_xdata()).sum()) for line in pts)
    assert n == cal.n_points == 6 * 54 - 5
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    assert x0 < -0.5 and x1 > SIZE[0] - 0.5 and x1 < SIZE[0] * 1.1
    assert y0 > y1  # y drawn downwards, image convention
    assert y0 > SIZE[1] - 0.5 and y0 < SIZE[1] * 1.1
    assert "324 corners" not in ax.get_title() and f"{n} corners in 6 views" in ax.get_title()


def test_plot_coverage_marks_unused_views():
    cal = _mono().suppress("img3.png")
    ax = plot_coverage(cal)
    grey = [line for line in ax.lines if line.get_marker() == "x"]
    assert len(grey) == 1
    np.testing.assert_allclose(grey[0].get_xdata(), cal.corners[3][:, 0])
    assert len(plot_coverage(cal, show_unused=False).lines) == len(ax.lines) - 1


def test_plot_corners_marks_the_first_corner():
    img = np.full((300, 400), 220, np.uint8)
    yy, xx = np.mgrid[0:300, 0:400]
    u, v = (xx - 60) // 30, (yy - 50) // 30
    inside = (u >= 0) & (u < 10) & (v >= 0) & (v < 7)
    img[inside & ((u + v) % 2 == 0)] = 30
    det = find_corners(img, PATTERN)
    assert det.found
    ax = plot_corners(img, det)
    assert ax.images[0].get_array().shape == (300, 400)
    first = [line for line in ax.lines if line.get_marker() == "o"][0]
    np.testing.assert_allclose([first.get_xdata()[0], first.get_ydata()[0]], det.corners[0])
    # the dark square touching corner 0 is the first board square: corner 0 at (89.5, 79.5)
    np.testing.assert_allclose(det.corners[0], [89.5, 79.5], atol=0.05)
    assert [t.get_text() for t in ax.texts] == ["0"]


def test_contact_sheet_lays_out_images_row_by_row():
    import matplotlib.pyplot as plt

    from wingphoto.plots import plot_contact_sheet

    rng = np.random.default_rng(0)
    imgs = [rng.integers(0, 255, (21, 23), dtype=np.uint8) for _ in range(10)]
    axes = plot_contact_sheet(imgs, titles=[f"v{k}" for k in range(10)], ncols=4)
    assert axes.shape == (3, 4)
    assert axes[0, 1].get_title() == "v1" and axes[2, 1].get_title() == "v9"
    assert axes[2, 1].images[0].get_array().shape == (21, 23)
    assert not axes[2, 2].images  # unused cells stay empty
    with pytest.raises(ValueError, match="one entry per image"):
        plot_contact_sheet(imgs, titles=["a"])
    with pytest.raises(ValueError, match="empty"):
        plot_contact_sheet([])
    plt.close("all")


def test_plot_length_statistics_shows_deviation_per_pair_with_std_in_the_label():
    import pandas as pd

    from wingphoto.plots3d import plot_length_statistics

    # six pairs of 10-94 mm with a 0.4 um spread: on one 0-100 mm axis the spread is invisible
    rows = []
    rng = np.random.default_rng(4)
    for k, L in enumerate([10.77, 88.02, 93.64, 89.82, 93.63, 88.08]):
        for cond in ("still", "flapping"):
            m = L + rng.normal(0, 2e-4)
            rows.append((cond, 18 + k, 19 + k, 60, m, 4e-4, m - 1e-3, m + 1e-3))
    stats = pd.DataFrame(rows, columns=["condition", "i", "j", "n", "mean", "std", "min", "max"])
    ax = plot_length_statistics(stats)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert len(labels) == 7  # one per pair and one for the bars, not 13
    assert labels[0] == "thin bar: min to max; dot ± std"
    assert labels[1].startswith("points 18-19: 10.770 mm, std 0.4 µm")
    assert ax.get_ylabel() == "length − pair mean (µm)"
    lo, hi = ax.get_ylim()
    assert -3 < lo < -0.5 and 0.5 < hi < 3  # the micrometre spread fills the axis
    assert "deviation from each pair's mean" in ax.get_title()


def test_plot_points_3d_has_a_colour_bar_and_few_ticks():
    from wingphoto.plots3d import plot_points_3d

    rng = np.random.default_rng(2)
    P = rng.normal([0, 0, 400], [20, 15, 5], size=(5, 9, 3))
    ax = plot_points_3d(P, frames=[0, 2, 4])
    bars = [a for a in ax.figure.axes if a is not ax]
    assert len(bars) == 1 and bars[0].get_ylabel() == "frame"
    ax.figure.canvas.draw()
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        assert len(axis.get_major_locator()()) <= 6
    one = plot_points_3d(P, frames=1)
    assert [a.get_ylabel() for a in one.figure.axes if a is not one] == ["depth Z (mm)"]


def test_plot_picks_numbers_every_pick_on_both_views():
    import pandas as pd

    from wingphoto.plots import plot_picks

    rng = np.random.default_rng(6)
    images = {c: rng.integers(0, 255, (120, 160), dtype=np.uint8) for c in ("left", "right")}
    picks = pd.DataFrame({"camera": ["left"] * 3 + ["right"] * 2, "point": [0, 1, 2, 0, 1],
                          "x": [40.0, 60.0, 80.0, 42.0, 61.0], "y": [50.0, 52.0, 54.0, 50.0, 52.0],
                          "half_w": 6.0, "half_h": 5.0})
    fig = plot_picks(images, picks)
    left, right = fig.axes
    assert left.get_title() == "left view, frame 0: 3 markers picked"
    assert [(t.get_text(), t.xy) for t in right.texts] == [("0", (42.0, 50.0)), ("1", (61.0, 52.0))]
    assert [p.get_width() for p in left.patches] == [12.0] * 3
    with pytest.raises(ValueError, match="'left' and/or 'right'"):
        plot_picks({"top": images["left"]}, picks)
