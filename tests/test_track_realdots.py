"""Tracking real dot texture (``wingphoto.synth.realdots``): skipped without ../shared."""
import logging

import numpy as np
import pytest

from wingphoto import track_markers
from wingphoto.synth import realdots
from wingphoto.track.refine import refine_centroids
from wingphoto.validation import point_errors

pytestmark = pytest.mark.skipif(not (realdots.default_folder() / "cal1.tif").is_file(),
                                reason="real-dot photographs (../shared/data/real-dots) not available")


def _photo(camera):
    import tifffile

    img_name = {"cam1": "cal1.tif", "cam2": "cal2.tif"}[camera]
    folder = realdots.default_folder()
    img = np.asarray(tifffile.imread(folder / img_name)).astype(np.float32)
    if img.ndim == 3:
        img = img[..., 0]
    ref = np.loadtxt(folder / f"{camera}_cal_points", ndmin=2)[:, :2]
    H, W = img.shape
    ref = ref[np.all((ref > 12) & (ref < np.array([W, H]) - 13), axis=1)]
    return img, ref


def _glitched_errors(kind, camera, seed):
    """Per point-frame errors (:func:`point_errors`) of a 60-frame real-dot sequence with
    glitch ``kind`` ('none': as rendered), tracked from frame-0 picks of the picked dots."""
    base = realdots.render_realdots(camera, seed=seed, n_frames=65)
    seq = realdots.with_glitch(base, kind, seed=seed, n_frames=60) if kind != "none" else base
    picks = base.picks(camera)
    tr = track_markers(seq.images, picks, camera=camera, progress=False)
    return point_errors(tr, seq, camera, points=np.flatnonzero(np.all(np.isfinite(picks), axis=1)))


def _confident_errors(a):
    """(frame, point) of the ok point-frames of :func:`_glitched_errors` ``a`` more than
    1 px from the truth."""
    return np.argwhere(a["ok"] & (a["error"] > 1.0))


def test_highlight_does_not_set_the_centroid():
    # cam1's dots carry a specular spot (~200 DN) on a ~35 DN face: a cut at a fifth of
    # the spot's peak dropped the face (90th percentile 0.61 px, worst 2.1 px off the
    # reference); the cut from the face's contrast keeps the shape's centre (measured
    # 0.31 / 0.54 px; the reference itself is good to ~0.1-0.15 px)
    img, ref = _photo("cam1")
    xy, _ = refine_centroids(img, np.rint(ref), 4.0)
    err = np.hypot(*(xy - ref).T)
    assert np.percentile(err, 90) < 0.4
    assert err.max() < 0.8


def test_real_dots_tracked_without_confident_errors():
    # DEV seed 0 of cam2 (faint dots, ~5 DN of fixed-pattern noise): no ok point more than
    # 1 px from the truth, and the picked dots are followed (ok or flagged with a
    # position) through most of the frames where they are visible instead of coasting
    # into lost_track (measured 0.75 at commit e54d535, 0.74 with the shape term of sigma;
    # a shape gain of 1.0 instead of 0.5 gave 20 ok points ~35 px off here: a dot
    # re-acquired one grid pitch off, then ok when few neighbours were ok to vouch;
    # 0.63 since a lost dot is re-predicted only from neighbours that moved like it,
    # 87fc030, which re-acquires fewer dots and none onto another; ~0.3 before e54d535;
    # 0.885 since dots flagged only imprecise, and certain on the last 5 frames, serve as
    # neighbours for re-acquisition: dots that leave the view and come back are found again)
    seq = realdots.render_realdots("cam2", seed=0)
    picks = seq.picks("cam2")
    tr = track_markers(seq.frames("cam2"), picks, camera="cam2", progress=False)
    picked = np.flatnonzero(np.all(np.isfinite(picks), axis=1))
    a = point_errors(tr, seq, "cam2", points=picked)
    ok = a["ok"] & a["visible"]
    assert not (a["error"][ok] > 1.0).any()
    followed = np.isfinite(a["error"]) & a["visible"]
    share = followed.sum() / a["visible"].sum()
    assert share > 0.85, f"followed share {share:.3f}"
    # and followed on their own dot (a re-acquisition one grid pitch off is ~25-70 px)
    assert not (a["error"][followed] > 3.0).any()


@pytest.mark.parametrize("camera, seed", [("cam2", 21), ("cam1", 32)])
def test_dots_leaving_the_view_early_do_not_take_the_next_grid_dot(camera, seed):
    # the dots lie on a regular grid about 30 px apart and move 10-13 px a frame. cam2
    # seed 21, frame 1 (no velocity yet): a dot leaving the view took its grid neighbour's
    # blob 20 px away while its neighbours did not move together: ok 30 px off (now
    # flagged, ``unvouched``). cam1 seed 32, frame 2: four dots of a row near the edge,
    # flagged on frame 1, searched wide again, took the next dots along their row and
    # vouched for each other: ok 34 px off (now checked against the moving dots with a
    # motion model around them)
    seq = realdots.render_realdots(camera, seed=seed, n_frames=65)  # (65: the sweep's dots)
    picks = seq.picks(camera)
    first = seq.head(5)
    tr = track_markers(first.images, picks, camera=camera, progress=False)
    a = point_errors(tr, first, camera, points=np.flatnonzero(np.all(np.isfinite(picks), axis=1)))
    assert a["ok"][:, :].any(axis=1)[1:].all()  # dots are followed
    assert not _confident_errors(a).size, _confident_errors(a)


@pytest.mark.parametrize("seed", [31, 0])
def test_a_grid_moved_one_spacing_by_dropped_frames_is_not_followed_on_the_wrong_dots(seed):
    # three frames dropped while the grid (about 33 px a dot) moved 34-49 px: no glitch
    # hypothesis explained two frames in a row, and every dot then resumed ok on the dot
    # one spacing behind it, 33 px off for the rest of the sequence (seed 31: 933 ok
    # points; seed 0: a dot re-acquired just before, 72 px off). Now the markers that
    # coasted over two unexplained frames are lost until found again
    # (GlitchStage._lose_unchecked)
    base = realdots.render_realdots("cam1", seed=seed, n_frames=65)
    seq = realdots.with_glitch(base, "dropped", seed=seed, n_frames=60)
    picks = base.picks("cam1")
    tr = track_markers(seq.images, picks, camera="cam1", progress=False)
    a = point_errors(tr, seq, "cam1", points=np.flatnonzero(np.all(np.isfinite(picks), axis=1)))
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"][:8].any(axis=1).all()  # followed before the drop


@pytest.mark.parametrize("seed", [5, 29, 86, 88])
def test_a_highlight_streak_does_not_leave_a_dot_ok_a_pixel_off(seed):
    # cam1's dots carry a specular spot that motion blur draws into a streak: the centre
    # followed it, ok 1.37 px (seed 5, frame 8) and 1.15 px (seed 29, frame 31) off at
    # sigma 0.22-0.25; the shape's own centre now enters sigma (refine.SHAPE_BIN_GAIN).
    # Fresh DEV seeds 86 and 88: dots ~1.2 px off on every frame, flagged at sigma
    # 0.24-0.65, ok on one frame at 0.21 and 0.24 next to the sequence's ends (frames 1
    # and 0); the frames around now judge it too (sigma.flag_persistent_imprecision)
    seq = realdots.render_realdots("cam1", seed=seed, n_frames=65).head(60)
    picks = seq.picks("cam1")
    tr = track_markers(seq.images, picks, camera="cam1", progress=False)
    a = point_errors(tr, seq, "cam1", points=np.flatnonzero(np.all(np.isfinite(picks), axis=1)))
    assert not _confident_errors(a).size, _confident_errors(a)
    assert a["ok"].sum() > 200  # and the dots stay followed (measured 266 and 315)


@pytest.mark.parametrize("kind, camera, seed", [("bumped", "cam2", 0), ("repeated", "cam1", 6),
                                                 ("dropped", "cam1", 101), ("dropped", "cam1", 65)])
def test_no_dot_followed_one_grid_spacing_off_after_a_glitch(kind, camera, seed):
    # bumped cam2 seed 0: a bump nothing explained (frame 41) was taken on frame 42 for
    # three dropped frames, which explained the slow dots and not the moving ones; flagged
    # on that frame only, the moving dots followed the grid one spacing off, and dots
    # re-acquired from them were ok 35 px off (now lost: GlitchStage._lose_unchecked with
    # ``among``).
    # repeated cam1 seed 6: a dot that coasted out of view had its motion model's copy
    # moved back three frames by the three repeated frames; re-acquired 25 frames later
    # from that copy with its neighbours' motion since the frame it left, it landed on the
    # next dot, and two dots re-acquired from it followed (7 points ok 35 px off; now the
    # last written position is mapped: reacquire._last_written).
    # dropped cam1 seeds 101 and 65: three neighbours 100 px from a dot of the rotating
    # grid moved it by their mean displacement over 23 frames, 34 px from where it was,
    # onto the next dot (seed 101: 11 points ok 30-64 px off; seed 65: 1 point 31 px off,
    # once _last_written mapped its written position; now refused: reacquire._REACH_SPACING)
    a = _glitched_errors(kind, camera, seed)
    assert not (a["error"][a["ok"]] > 3.0).any(), np.argwhere(a["ok"] & (a["error"] > 3.0))[:10]
    assert a["ok"][:8].any(axis=1).all()  # followed before the glitch


@pytest.mark.parametrize("camera, seed, run", [("cam1", 13, 3), ("cam2", 26, 4)])
def test_a_reversal_after_unseen_dropped_frames_is_not_taken_for_a_repeat(camera, seed, run):
    # source frames 5-7 (cam1 seed 13) or 10-13 (cam2 seed 26) dropped just before the
    # stroke reversed: the drop passed unseen, the dots came back 2-3 px against a
    # prediction 7 px on, and "a repeated frame" (the history one frame back) put them
    # within the motion model's limit; kept for two frames, it left the model a stroke
    # behind, and the next frame put the grid one spacing off (seed 13: ok 35-72 px off;
    # seed 26: 139 points ok up to 70 px off). A repeat leaves no marker behind where it
    # was: GlitchStage._repeat_holds
    base = realdots.render_realdots(camera, seed=seed, n_frames=68)
    start = {13: 5, 26: 10}[seed]
    keep = np.flatnonzero(~np.isin(np.arange(len(base)), np.arange(start, start + run)))[:60]
    seq = realdots.RealDotSequence(camera=camera, images=base.images[keep], points=base.points[keep],
                                   visible=base.visible[keep], homographies=base.homographies[keep],
                                   params=dict(base.params))
    picks = base.picks(camera)
    tr = track_markers(seq.images, picks, camera=camera, progress=False)
    a = point_errors(tr, seq, camera, points=np.flatnonzero(np.all(np.isfinite(picks), axis=1)))
    assert not (a["error"][a["ok"]] > 3.0).any(), np.argwhere(a["ok"] & (a["error"] > 3.0))[:10]
    assert a["ok"][:start].any(axis=1).all()  # followed before the drop


def test_a_hypothesis_must_explain_most_markers_checkable_as_predicted(caplog):
    # source frames 10-13 dropped (cam1 seed 53): 22 dots checkable as predicted, 1 where
    # predicted; "6 frames dropped" sent most predictions off the image or off any blob
    # and won on 4 of the 7 it left checkable: a dot ok on the next dot of the grid, 34 px
    # off (hidden since by sigma.flag_persistent_imprecision, hence the log check)
    base = realdots.render_realdots("cam1", seed=53, n_frames=68)
    keep = np.flatnonzero(~np.isin(np.arange(len(base)), np.arange(10, 14)))[:60]
    seq = realdots.RealDotSequence(camera="cam1", images=base.images[keep], points=base.points[keep],
                                   visible=base.visible[keep], homographies=base.homographies[keep],
                                   params=dict(base.params))
    picks = base.picks("cam1")
    with caplog.at_level(logging.INFO, logger="wingphoto.track"):
        tr = track_markers(seq.images, picks, camera="cam1", progress=False)
    assert "frame 10: constellation restored" not in caplog.text
    a = point_errors(tr, seq, "cam1", points=np.flatnonzero(np.all(np.isfinite(picks), axis=1)))
    assert not _confident_errors(a).size, _confident_errors(a)[:10]



def test_a_grid_is_not_re_acquired_one_spacing_off():
    # dropped cam2 fresh DEV seed 147, frame 40 (dots lost 15 frames): the constellation fit
    # took 33 inliers one grid spacing off, its true placement (31) never proposed by the
    # triangle hypotheses ("second 19"): 385 ok points 29-36 px off. A fit now counts its
    # aliases as second best (relocate._alias_inliers)
    base = realdots.render_realdots("cam2", seed=147, n_frames=65)
    seq = realdots.with_glitch(base, "dropped", seed=147, n_frames=60)
    picks = base.picks("cam2")
    tr = track_markers(seq.images, picks, camera="cam2", progress=False)
    a = point_errors(tr, seq, "cam2", points=np.flatnonzero(np.all(np.isfinite(picks), axis=1)))
    assert not (a["error"][a["ok"]] > 3.0).any(), np.argwhere(a["ok"] & (a["error"] > 3.0))[:10]


@pytest.mark.parametrize("seed, point", [(186, 28), (189, 9)])
def test_a_faint_dot_a_person_would_click_is_accepted_as_a_pick(seed, point):
    # cam2's faintest dots stand ~15 grey levels out of a noise of ~4 per pixel: no single
    # pixel clears 4 noise, but the dot as a whole does; it used to be refused as "not on a marker"
    seq = realdots.render_realdots("cam2", seed=seed, n_frames=20)
    tr = track_markers(seq.frames("cam2"), seq.picks("cam2"), camera="cam2", progress=False)
    a = point_errors(tr, seq, "cam2")
    assert not (a["error"][a["ok"] & a["visible"]] > 1.0).any()
    followed = np.isfinite(a["error"][:, point]) & a["visible"][:, point]
    assert followed.sum() >= 10 and (a["error"][:, point][followed] < 3.0).all()


@pytest.mark.parametrize("kind, camera, seed", [("bumped", "cam1", 189), ("none", "cam1", 205),
                                                 ("repeated", "cam2", 254), ("repeated", "cam2", 236),
                                                 ("dropped", "cam1", 162), ("black", "cam2", 195)])
def test_a_dot_whose_identity_was_in_doubt_does_not_resume_ok_on_the_next_dot(kind, camera, seed):
    # fresh real-dot DEV seeds 201-260 and 141-200, session 22:
    # bumped cam1 189: a dot went no_signal, ambiguous, then followed the dot behind as
    # 'imprecise' (identity rules passed, too few neighbours for the jump rule) and served
    # re-acquisition as an anchor; its neighbour was put on the next dot (29 points ok
    # ~34 px off). An imprecise path that hopped is now flagged 'jump' (Tracker._update).
    # none cam1 205: a dot lost a conflict on frame 1; the dot one spacing behind, moving
    # half a spacing per frame, stood on its place on frame 2, and the stay rule took it
    # ok without neighbours (33 px off). Not after a conflict since the last ok frame.
    # repeated cam2 254: a dot back from the image edge on the next grid dot after one
    # out-of-frame frame ran a grid diagonal per frame, ok 105-243 px off; the hop over
    # the frame without a position was not judged (identity._hopped); dropped cam1 162:
    # lost two frames after an 'ambiguous' one, found on the dot behind by its own
    # prediction, ok 46 px off (a step over two frames without a position); black cam2
    # 195: re-acquired, a black frame and two lost ones, found on the dot behind on its
    # own prediction, ok 35 px off (identity._coasted).
    # repeated cam2 236: re-acquired from its 'ambiguous' position of frame 1, one spacing
    # off, 27 frames later (reacquire._last_written takes only certain positions).
    a = _glitched_errors(kind, camera, seed)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]


@pytest.mark.parametrize("camera, seed", [("cam1", 279), ("cam2", 286)])
def test_dropped_frames_do_not_move_a_dot_onto_the_next_one(camera, seed):
    # fresh real-dot DEV seeds 261-320, session 22, dropped: cam1 279, a dot re-acquired on
    # the frame before three dropped frames, its model one point and a borrowed step, was
    # found on the dot behind (12 ok points 34 px off; GlitchStage._lose_unmoved); cam2
    # 286, "5 dropped" won over the true 3 by 4 markers of 7 to 3 and a dot went ok one
    # spacing ahead (12 points 35 px off; glitch._drop_count_in_doubt, the markers lost at once)
    a = _glitched_errors("dropped", camera, seed)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]


@pytest.mark.parametrize("kind, camera, seed", [("dropped", "cam2", 386), ("repeated", "cam1", 430),
                                                 ("repeated", "cam1", 434), ("dropped", "cam1", 434),
                                                 ("dropped", "cam1", 160)])
def test_a_glitch_that_leaves_the_dots_far_from_their_predictions_is_not_explained(kind, camera, seed):
    # fresh real-dot DEV seeds 381-440, session 23: dropped cam2 386, three frames dropped
    # after earlier glitches had grown the dots' residual rms to ~3 px: the whole grid moved
    # onto the dots behind, a median 7.5 px from their predictions but within each dot's
    # own limit of 4 rms, and passed as where predicted (3 points ok 34 px off); repeated
    # cam1 430, three dots leaving the view passed as "1 frame dropped" at a median of
    # 7.2 px (2 points ok 33-66 px off). Now neither passes: glitch._MEDIAN_RESID_PX.
    # repeated cam1 434: a dot re-acquired on a repeated frame borrowed its neighbours'
    # step, nil on a repeat, as its velocity, stood still and was found on the dot behind
    # (2 points ok 33 px off). Nothing is re-acquired on a repeat now (Tracker._update).
    # dropped cam1 434: with that median rule alone, a camera shift that put 8 of 8 dots
    # "where predicted", as did the motion model, won by a smaller median (7 points ok
    # 33-66 px off): a frame broken by its median alone now needs more markers explained.
    # dropped cam1 160 (fresh DEV 141-200, session 22): after a frame no glitch explained,
    # "a repeated frame" explained the next one on 3 of 4 dots - a repeat of a frame no
    # glitch explained (4 points ok 33 px off; GlitchStage._repeat_holds).
    a = _glitched_errors(kind, camera, seed)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"].sum() > 100  # (followed, not lost)


@pytest.mark.parametrize("camera, seed, min_ok", [("cam2", 610, 1100), ("cam2", 509, 1500)])
def test_a_drop_counted_short_at_a_reversal_is_counted_again(camera, seed, min_ok):
    # DEV stress seeds 441-640, session 24, dropped. cam2 610: three frames dropped just
    # before a stroke reversal were taken for two; at the reversal "a repeated frame" won
    # twice, each moving the history a frame back and, the frame not fed, adding a frame
    # to every marker's gap, until no dot was checkable (gap > 2) and the grid, flagged
    # 'jump' on its right dots, resumed ok one spacing off (72 points 34-72 px off; cam2
    # 509: 14 points up to 49 px off). Now a repeat keeps the gaps (_relabel_repeat), the
    # history behind the frames dropped is the measured one (_keep_measured), and frames
    # dropped before the last frame are a hypothesis: the count is mended. min_ok: ok
    # point-frames - a mend that only flagged the frames (the repeat kept alone: 894 in
    # 610) is none (before: 1060 and 1227 ok visible, with the errors; now 1301 and 1930).
    a = _glitched_errors("dropped", camera, seed)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"].sum() >= min_ok


def test_no_late_drop_is_read_into_the_frames_after_an_unexplained_one():
    # real dots, bumped, DEV seed 474 cam1 (found in session 24's review run): a bump no
    # hypothesis explained on frame 27, then "1 frame dropped before the last one" on frame
    # 28 - a retiming of frames whose markers no hypothesis had placed - and 2 dots ok one
    # spacing off (33-34 px). Refused after an unexplained frame, as a repeat is.
    a = _glitched_errors("bumped", "cam1", 474)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]


@pytest.mark.parametrize("camera, seed", [("cam1", 11), ("cam1", 573)])
def test_a_dot_alone_is_flagged_when_dropped_frames_would_put_it_on_another_dot(camera, seed):
    # the lone-dot alias (real dots, dropped): one or two dots followed, too few for the
    # constellation check; three frames dropped unseen, and the dot behind stood where the
    # next step was predicted (DEV seed 11 cam1: 8 points ok 33 px off) or 6 px from it,
    # ok as a lone marker's short jump (stress seed 573 cam1: 1 point 34 px off).
    # GlitchStage._few_in_doubt solves the frame for each count of dropped frames and flags
    # a dot that one of them puts on another blob as near its prediction.
    a = _glitched_errors("dropped", camera, seed)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]


@pytest.mark.parametrize("seed, min_ok", [(568, 500), (631, 30)])
def test_a_dim_face_behind_a_streaked_highlight_is_seen(seed, min_ok):
    # DEV stress seeds 441-640, session 25, dropped cam1: fast dots whose specular spot,
    # streaked by motion blur, outshone their dim face at every cut taken from the
    # contrast; the centre followed the streak, ok 1.1-1.4 px off at sigma 0.17-0.24 (568:
    # 4 points, 631: 5). The centre of the whole face, faint pixels included
    # (refine.LOW_CUT_NOISE), enters sigma: imprecise, not ok. min_ok: the other dots stay
    # ok (measured 610 and 40; before, 647 and 48 with the errors).
    a = _glitched_errors("dropped", "cam1", seed)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"].sum() >= min_ok


def test_a_grid_moving_half_its_spacing_is_not_aliased_on_the_first_frame():
    # fresh DEV seed 680 cam1 (session 25), as rendered: dots at the view's edge moved
    # ~15 px from frame 0 to 1 on a 29 px grid. With no velocity yet, those leaving the
    # view took the next dots 19-23 px away, unambiguous, anchored their neighbours'
    # consensus, and a whole corner started one spacing back (ok 31-92 px off, in every
    # glitch kind). A wide match half a spacing or more from where the marker was now
    # anchors no other marker's consensus (IdentityStage._consensus).
    a = _glitched_errors("none", "cam1", 680)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"].sum() > 600  # (measured 783)


def test_a_grid_moving_more_than_half_its_spacing_does_not_start_on_the_dot_behind():
    # fresh DEV seed 780 cam1 (session 26), as rendered: the grid moved 19.6 px from frame 0
    # to 1 at a 33 px spacing. Dot 53 matched the dot behind it, 14 px back, unambiguous;
    # its neighbours that moved with the grid were 'far' (anchoring nothing) or ambiguous,
    # so the near, aliased matches vouched for it; flagged only 'imprecise', it fed its
    # motion model and went ok 100.9 px off on frame 3. A near match that most of its
    # wide-searched neighbours contradict by half a spacing is contested
    # (IdentityStage._contested): flagged, not fed.
    a = _glitched_errors("none", "cam1", 780)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"].sum() > 450  # (measured 528; 559 before, one of them 100.9 px off)


@pytest.mark.parametrize("kind, seed, min_ok", [("dropped", 931, 450), ("bumped", 940, 520)])  # (measured 546, 634)
def test_a_glitch_left_unexplained_does_not_pass_the_next_frame_on_the_dots_behind(kind, seed, min_ok):
    # fresh DEV seeds 931 and 940 cam1 (session 27). dropped: three dropped source frames
    # moved the grid about one 33 px spacing; no hypothesis explained the frame (flagged),
    # and the next passed as predicted, its median residual 5.1 px but 6 of 10 dots within
    # their limits - on the dots behind: 335 points ok 33 px off. bumped: a (-5, 2) px bump
    # nothing explained; on the next frame "3 frames dropped" won with 10 of 17 dots at
    # 3.8 px: 324 points ok 34 px off. After an unexplained frame the next must be as
    # predicted by its median too, and a hypothesis must put two thirds of the dots
    # where predicted (GlitchStage._recover).
    a = _glitched_errors(kind, "cam1", seed)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"].sum() >= min_ok


def test_a_glitch_hypothesis_needs_three_markers_where_predicted():
    # fresh DEV seed 964 cam1 (session 27), bumped by (7, -5) px: with three markers to
    # check, "3 frames dropped" won on two (no bump hypothesis was tried), and one dot went
    # ok on the dot behind, 33 px off for 10 frames (GlitchStage._recover).
    a = _glitched_errors("bumped", "cam1", 964)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"].sum() > 120  # (measured 147)


@pytest.mark.parametrize("seed, min_ok", [(946, 900), (1011, 1250)])  # (measured 1047, 1455)
def test_a_dot_at_the_view_edge_does_not_start_on_the_dot_behind(seed, min_ok):
    # fresh DEV seeds 946 and 1011 cam1 (session 27). 946: a dot 8 px from the left edge,
    # the grid moving 20 px on frame 1 at a 32 px spacing, took the dot behind it 18 px
    # away (0.93 against 0.36: its own blob lay where the template does not fit); its
    # neighbours were all ambiguous, no anchor to check it, and it was ok one spacing
    # further off on every frame, 32-128 px. 1011: a dot 6 px from the top edge, leaving
    # the view, the same, ok 28 and 55 px off. Such a match is provisional
    # (IdentityStage._beyond_view): flagged, but it feeds the motion model, and the
    # marker resumes ok only where its neighbours vouch for its path.
    a = _glitched_errors("none", "cam1", seed)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"].sum() > min_ok


def test_a_grid_left_ambiguous_does_not_resume_on_the_dots_behind():
    # fresh DEV seed 1011 cam1 with two black frames (session 27): frame 1 left the whole
    # grid ambiguous, unfed; on frame 2 the grid had moved 24 px at a 28 px spacing, and
    # the wide search found the dots behind, 4 px from where the dots had been, each
    # vouching for the others: dot 59 ok 28 px off. Frame 1, the previous image, shows no
    # dot on a constant-velocity path to them (IdentityStage._off_path).
    a = _glitched_errors("black", "cam1", 1011)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"].sum() > 1100  # (measured 1290; 1200 before, 3 of them 28-55 px off)


def test_a_dot_is_not_reacquired_by_four_neighbours_one_of_them_a_spacing_off():
    # fresh DEV seed 1072 cam2, dropped (session 28): after three dropped frames moved the
    # grid more than a spacing, dot 33 was followed one spacing off, flagged imprecise, and
    # served as one of four neighbours whose reference-frame map re-acquired dot 40 on the
    # dot behind it: ok 35 px off for 9 frames. Four neighbours one of which alone places
    # the marker (its hinge, here 33, ambiguous on frame 29) predict it only if that one's
    # identity was not in doubt since the marker was last ok (reacquire._hinges,
    # ReacquireStage._sure_since).
    a = _glitched_errors("dropped", "cam2", 1072)
    assert not _confident_errors(a).size, _confident_errors(a)[:10]
    assert a["ok"].sum() > 380  # (measured 452; 444 before, 9 of them 35 px off)
