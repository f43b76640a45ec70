"""Checkerboard calibration of one camera or a stereo rig, compatible with Bouguet's toolbox.

The steps follow the Camera Calibration Toolbox for Matlab (Bouguet) that the thesis
used: extract the grid corners (:func:`find_corners`, the toolbox's "Extract grid
corners"), calibrate each camera (:func:`calibrate_camera`, "Calibration"), analyse the
errors and suppress bad views (:meth:`CameraCalibration.suppress`,
:func:`suggest_suppress` and the figures in :mod:`wingphoto.plots`), then calibrate the
rig (:func:`calibrate_stereo`, the toolbox's ``stereo_gui``).

Parameters keep the toolbox's names (``fc, cc, alpha_c, kc``, ``om, T``; see
``docs/conventions.md``) and its definitions of the reported numbers:

* ``pixel_error`` (the toolbox's ``err_std``): per-axis standard deviation of the
  reprojection residuals ``observed - projected`` over every used corner;
* ``uncertainty`` (the toolbox's ``fc_error`` etc.): ``3 * sqrt(diag((J^T J)^-1)) * sigma``
  with ``J`` the Jacobian of the residuals at the solution with respect to every
  estimated parameter (intrinsics and the per-view board poses) and ``sigma`` the
  standard deviation of all residual components (``std(ex(:))``), i.e. about three
  standard deviations.

The refinement is a least-squares fit of the toolbox's camera model
(:meth:`wingphoto.camera.Camera.project`) by :func:`scipy.optimize.least_squares`,
started from OpenCV's Zhang initialisation (``cv2.calibrateCamera``).

Board frame and corner order
----------------------------
``pattern_size = (n_cols, n_rows)`` counts *inner* corners as OpenCV does (e.g. (9, 6)).
Corners are returned row by row, ``n_cols`` per row; corner ``k`` has board coordinates
``(k % n_cols * dX, k // n_cols * dY, 0)`` mm (:func:`board_points`). The order is chosen
from the board itself, so that the same physical corner comes first in every view:

1. the board axes appear right-handed in the image (walking along a row, the next row
   lies clockwise, as image x to image y) -- true of any printed board seen from the
   front, so it removes the mirror ambiguity;
2. the square between corners 0, 1, ``n_cols`` and ``n_cols + 1`` is the *dark* one.
   When ``n_cols + n_rows`` is odd (e.g. 9 x 6) the board's two ends differ in colour
   and this fixes the 180 degree ambiguity, whatever the board's orientation in the
   image;
3. on a board that looks the same after a half turn (``n_cols + n_rows`` even) the
   remaining choice is the one whose first corner is nearest the image's top-left
   corner (smallest x + y). Such boards are only consistent between the two cameras
   of a rig if both see the board in a similar orientation; prefer an odd/even board.
"""
# One module per step: checks (arguments, board points), corners (detection), views
# (gathering and screening), model (projection, least squares, covariance), mono (one
# camera), stereo (the rig), report (summaries), suppress (the error analysis).
from .checks import board_points
from .corners import CornerDetection, find_corners
from .mono import CameraCalibration, calibrate_camera
from .stereo import RIG_PARAMETER_NAMES, StereoCalibration, calibrate_stereo
from .suppress import suggest_suppress

__all__ = [
    "CornerDetection",
    "find_corners",
    "board_points",
    "CameraCalibration",
    "calibrate_camera",
    "StereoCalibration",
    "RIG_PARAMETER_NAMES",
    "calibrate_stereo",
    "suggest_suppress",
]
