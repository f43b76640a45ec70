"""A camera bump moves the picks' frame's layout (``ref_pos``) with the motion model."""
import numpy as np

from test_track import moving_discs
from wingphoto.track.options import TrackOptions
from wingphoto.track.tracker import Tracker


def test_camera_shift_hypothesis_moves_ref_pos_and_a_rejected_one_restores_it():
    frames, truth, _ = moving_discs(1, T=3)
    picks = np.rint(truth[0])
    tk = Tracker.from_picks(frames[0], picks, np.full(len(picks), -1, np.int64), TrackOptions(), True,
                            np.arange(len(picks)))
    ref0 = tk.ref_pos.copy()
    saved = (tk.hist_x.copy(), tk.hist_t.copy(), tk.lostflag.copy(), tk.ref_pos.copy())
    shared = tk.ref_pos  # a verify pass's shallow copy holds this array
    tk._set_model(saved, 0, 3.5, -2.0, 1)
    np.testing.assert_allclose(tk.ref_pos, ref0 + [3.5, -2.0])
    np.testing.assert_allclose(tk.hist_x[:, 0], saved[0][:, 0] + [3.5, -2.0])
    np.testing.assert_array_equal(shared, ref0)  # not changed in place
    tk._set_model(saved, 0, 0.0, 0.0, 1)
    np.testing.assert_array_equal(tk.ref_pos, ref0)
