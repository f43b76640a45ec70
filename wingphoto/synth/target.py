"""A rigid two-marker target swept by the pan-tilt device."""
from __future__ import annotations


import numpy as np

from .board import _pan_tilt_rotation, pan_tilt_schedule
from .flapping import _check_rig, _render_sequence
from .raster import _check_common
from .rig import LEVELS, scene_frame
from .wing import StereoSequence, _Scene




def render_rigid_target(
    rig=None,
    *,
    n_frames=21,
    distance_mm=53.2,
    marker_diameter_mm=2.5,
    n_tilts=3,
    n_pans=7,
    tilt_deg=20.0,
    pan_deg=30.0,
    noise_std=1.0,
    blur_sigma=0.6,
    supersample=4,
    dtype=np.uint8,
    seed=0,
):
    """Render the rigid-body test: two markers ``distance_mm`` apart on the pan-tilt.

    Parameters
    ----------
    rig : StereoRig, optional
        Default :func:`thesis_rig`.
    n_frames : int, optional
        Number of stereo pairs. With ``n_tilts * n_pans`` frames (default 21) each
        frame is one stop of :func:`pan_tilt_schedule`; otherwise the frames are spread
        evenly along the raster path through the stops (pan sweeping back and forth,
        one tilt row after the other).
    distance_mm : float, optional
        Distance between the two marker centres, mm (the thesis' target: 53.2).
    marker_diameter_mm : float, optional
        Painted diameter of both markers, mm (2.5 mm: about 11 px).
    n_tilts, n_pans, tilt_deg, pan_deg : optional
        The pan-tilt schedule (see :func:`pan_tilt_schedule`).
    noise_std, blur_sigma, supersample, dtype, seed : optional
        As for :func:`render_flapping`.

    Returns
    -------
    StereoSequence
        Two points of kind ``"target"``; ``fps`` is 1 (one frame per stop, no motion);
        ``points3d[:, 1] - points3d[:, 0]`` has length ``distance_mm`` exactly.

    Notes
    -----
    The markers are white discs on a black bar held at the rig's working point
    (:func:`scene_frame`), at ``(-distance/2, 0, 0)`` and ``(+distance/2, 0, 0)`` in
    the bar's frame, which the pan-tilt unit turns like the calibration board.

    Examples
    --------
    >>> seq = render_rigid_target(n_frames=3)
    >>> d = np.linalg.norm(seq.points3d[:, 1] - seq.points3d[:, 0], axis=1)
    >>> np.allclose(d, 53.2)
    True
    """
    rig = _check_rig(rig)
    _check_common(noise_std, blur_sigma, dtype)
    n_frames = int(n_frames)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    if not (distance_mm > 0 and marker_diameter_mm > 0):
        raise ValueError(f"distance_mm and marker_diameter_mm must be positive, got {distance_mm}, {marker_diameter_mm}")
    if marker_diameter_mm >= distance_mm:
        raise ValueError("marker_diameter_mm must be smaller than distance_mm (the markers would overlap)")
    stops = pan_tilt_schedule(n_tilts, n_pans, tilt_deg=tilt_deg, pan_deg=pan_deg)
    # raster path: reverse every other tilt row so the pan sweeps back and forth
    rows = stops.reshape(int(n_tilts), int(n_pans), 2).copy()
    rows[1::2] = rows[1::2, ::-1]
    path = rows.reshape(-1, 2)
    if n_frames == len(stops):
        angles = stops
    elif len(path) == 1:
        angles = np.repeat(path, n_frames, axis=0)
    else:
        seg = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))]
        u = np.linspace(0.0, seg[-1], n_frames)
        angles = np.column_stack([np.interp(u, seg, path[:, 0]), np.interp(u, seg, path[:, 1])])
    S, B = scene_frame(rig)
    local = np.array([[-0.5 * distance_mm, 0.0, 0.0], [0.5 * distance_mm, 0.0, 0.0]])

    def points(t):
        k = int(round(t))
        R = _pan_tilt_rotation(B, *angles[k])
        return S + local @ R.T, np.tile(-R[:, 2], (2, 1))

    light = B @ np.array([0.2, -0.4, -1.0])
    light /= np.linalg.norm(light)
    diam = np.full(2, float(marker_diameter_mm))
    scene = _Scene(points=points, diameters=diam, static=np.zeros(2, bool), paint=LEVELS["paint"], light=light)
    times = np.arange(n_frames, dtype=np.float64)
    rng = np.random.default_rng(seed)
    imgs, pts3d, pts2d, vis = _render_sequence(
        rig, scene, times, fps=1.0, blur_sigma=float(blur_sigma), noise_std=float(noise_std), dtype=dtype,
        rng=rng, motion_blur=False, exposure=0.0, supersample=int(supersample), edge_on_deg=72.0,
        merge_gap_px=1.5,
    )
    params = dict(n_frames=n_frames, distance_mm=float(distance_mm), marker_diameter_mm=float(marker_diameter_mm),
                  n_tilts=int(n_tilts), n_pans=int(n_pans), tilt_deg=float(tilt_deg), pan_deg=float(pan_deg),
                  noise_std=float(noise_std), blur_sigma=float(blur_sigma), supersample=int(supersample),
                  dtype=np.dtype(dtype).name, seed=seed, angles_deg=angles.tolist(),
                  edge_on_deg=72.0, merge_gap_px=1.5)
    return StereoSequence(
        left=imgs["left"], right=imgs["right"], rig=rig, points3d=pts3d,
        points_left=pts2d["left"], points_right=pts2d["right"],
        visible_left=vis["left"], visible_right=vis["right"], kinds=np.array(["target", "target"]),
        marker_diameter_mm=diam, fps=1.0, times=times, noise_std=float(noise_std),
        blur_sigma=float(blur_sigma), stroke_angle_deg=np.full(n_frames, np.nan),
        pitch_angle_deg=np.full(n_frames, np.nan), params=params,
    )
