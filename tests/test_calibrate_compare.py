"""CameraCalibration.compare / StereoCalibration.compare against known truth."""
import numpy as np

from wingphoto import synth
from wingphoto.calibrate import calibrate_camera, calibrate_stereo


def test_compare_tables_report_errors_in_sigma_units():
    rng = np.random.default_rng(21)
    rig = synth.thesis_rig(seed=4, jitter=1.0)
    # only the true corners are used, and they do not depend on how the images are rendered:
    # noise-free images without supersampling keep the 21 pairs cheap
    cs = synth.render_calibration_set(rig, seed=4, supersample=1, noise_std=0.0)
    # calibrate from the true corners plus 0.1 px noise: errors are then ~N(0, sigma)
    left = [c + rng.normal(0, 0.1, c.shape) for c in cs.corners_left]
    right = [c + rng.normal(0, 0.1, c.shape) for c in cs.corners_right]
    mono = calibrate_camera(left, cs.pattern_size, cs.square_size, image_size=(512, 512))
    t = mono.compare(rig.left)
    assert list(t["parameter"][:4]) == ["fc[0]", "fc[1]", "cc[0]", "cc[1]"]
    np.testing.assert_allclose(t["error"], t["estimate"] - t["truth"])
    np.testing.assert_allclose(t.loc[0, "estimate"], mono.camera.fc[0])
    est = t["three_sigma"] > 0
    assert t.loc[est, "inside_3sigma"].all()
    st = calibrate_stereo(left, right, cs.pattern_size, cs.square_size, image_size=(512, 512))
    ts = st.compare(rig)
    assert len(ts) == 2 * 10 + 6
    row = ts.set_index("parameter").loc["T[0]"]
    assert row["truth"] == rig.T[0] and row["estimate"] == st.rig.T[0]
    assert abs(row["error_in_sigma"]) == abs(3 * row["error"] / row["three_sigma"])
    assert ts.loc[ts["three_sigma"] > 0, "inside_3sigma"].mean() >= 0.9
