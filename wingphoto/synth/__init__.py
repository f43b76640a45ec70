"""Synthetic stereo photogrammetry with exact ground truth: rig, boards, flapping wing.

This is the library's ground-truth generator. It renders, through the full lens model
of :class:`~wingphoto.camera.Camera` (distortion included), what the thesis' two
high-speed cameras saw, and returns every image together with the truth that made it:

* :func:`thesis_rig` - a 512 x 512 stereo rig like the thesis' (optionally perturbed);
* :func:`render_calibration_set` - checkerboard pairs posed by a pan-tilt schedule;
* :func:`render_calibration_video` - both cameras recording the pan-tilt run (holds, moves);
* :func:`render_flapping` - a flapping, bending, pitching, cambered wing with white
  painted markers, a two-marker mount and six static reference dots, optionally with
  glare and motion blur (``preset="hard"`` switches on everything at once);
* :func:`render_rigid_target` - two markers a known distance apart swept by the pan-tilt;
* :func:`write_samples` - the committed ``data-samples/`` folder.

Frames and units (``docs/conventions.md``)
------------------------------------------
Everything 3D is in millimetres in the **left camera frame** (x right, y down, z
forward); the right camera sees ``X_right = R(om) X_left + T``. Pixels are (x, y) with
(0, 0) the centre of the top-left pixel. Grey levels are quoted on the 8-bit scale
(0-255) whatever the output dtype: ``uint16`` output is the same image times 257,
float output is the unrounded 8-bit-scale image.

The scene
---------
The two optical axes of the thesis rig converge about 407 mm in front of the left
camera. :func:`scene_frame` returns that convergence point ``S`` and an orthonormal
basis ``(a, b, n)``: ``n`` bisects the two viewing directions (pointing away from the
cameras), ``a`` is horizontal (image right) and ``b = n x a`` points image-down. Every
scene (board centre, wing hinge, reference dots) is placed in these coordinates, so it
stays in view of both cameras for perturbed rigs too. At ``S`` the common field of view
is about 108 mm (a) x 100 mm (b); one millimetre is about 4.5 px.

Rendering
---------
Each pixel is supersampled on a regular grid; each sample's viewing ray is obtained by
undistorting the sample position (:meth:`Camera.normalize`, the toolbox's 20-iteration
inverse, evaluated exactly at the pixel centres and interpolated bilinearly between
them, an error below 1e-4 px) and intersected with the object's plane. The edge of a
square or a disc is anti-aliased analytically within each sample (a linear coverage
ramp one sample wide across the edge), which makes the rendered edges unbiased to a
few thousandths of a pixel. The image is then blurred by a Gaussian (optics, in px),
receives additive Gaussian noise (grey levels) drawn from ``np.random.default_rng(seed)``,
and is clipped to 0-255 (sensor saturation) and rounded. Everything is deterministic
for a seed.
"""
from __future__ import annotations
# One module per kind of scene: rig (cameras, scene frame, rays), raster (discs, image
# finishing), board (pan-tilt checkerboards), wing (model, markers, sequence container),
# flapping (the wing's rendering), target (rigid two-marker target), samples (data-samples/).
from .board import CalibrationSet, pan_tilt_schedule, render_calibration_set
from .calib_video import CalibrationVideo, render_calibration_video
from .flapping import flapping_preset, render_flapping
from .raster import render_discs
from .rig import CAMERAS, IMAGE_SIZE, LEVELS, load_rig, rig_from_dict, rig_to_dict, scene_frame, thesis_rig
from .samples import write_samples
from .target import render_rigid_target
from .wing import StereoSequence, WingMotion, wing_motion

__all__ = [
    "CalibrationSet",
    "CalibrationVideo",
    "render_calibration_video",
    "StereoSequence",
    "WingMotion",
    "wing_motion",
    "thesis_rig",
    "scene_frame",
    "pan_tilt_schedule",
    "flapping_preset",
    "render_calibration_set",
    "render_flapping",
    "render_rigid_target",
    "write_samples",
    "rig_to_dict",
    "rig_from_dict",
    "load_rig",
    "render_discs",
    "CAMERAS",
    "IMAGE_SIZE",
    "LEVELS",
]
