"""A marker that hopped onto another blob while not ok does not resume ok on it without
neighbours to vouch."""
import pytest


@pytest.mark.parametrize("kind, seed, camera, n_frames, min_ok", [
    # marker 12 slowed to 0.4 px/frame at a reversal, then hopped 9 px onto its neighbour's
    # blob: the slow step was taken for a repeated frame's stall and dropped, which hid the
    # hop, and it resumed ok there 10 px off (frame 24); a stall is now dropped only if the
    # path resumes within half the hop limit (hop.STALL_RESUME)
    ("black", 57, "right", 60, 0.6),
])
def test_a_hop_is_not_hidden_as_a_stall(independent_case, kind, seed, camera, n_frames, min_ok):
    bad, share = independent_case(kind, seed, camera, n_frames)
    assert not bad
    assert share > min_ok, share
