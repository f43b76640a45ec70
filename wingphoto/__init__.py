"""wingphoto: high-speed stereo photogrammetry of flapping wings.

Calibration, marker tracking, triangulation and analysis as a flat API
(``wp.calibrate_stereo``, ``wp.track_markers``, ``wp.stereo_triangulation``).
Conventions (pixel origin, frames, units, parameter names): ``docs/conventions.md``.
"""
from .camera import Camera, StereoRig, rodrigues
from .triangulate import reprojection_error, stereo_triangulation, triangulate_tracks

__version__ = "0.1.0"
