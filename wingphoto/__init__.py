"""wingphoto: high-speed stereo photogrammetry of flapping wings.

Calibration, marker tracking, triangulation and analysis as a flat API
(``wp.calibrate_stereo``, ``wp.track_markers``, ``wp.stereo_triangulation``).
Conventions (pixel origin, frames, units, parameter names): ``docs/conventions.md``.
"""
from .camera import Camera, StereoRig, rodrigues
from .triangulate import reprojection_error, stereo_triangulation, triangulate_tracks

__version__ = "0.1.0"
from .io import (
    POINT_COLUMNS,
    TRACK_COLUMNS,
    BouguetCalib,
    Sequence,
    atomic_write,
    find_samples,
    empty_points,
    empty_tracks,
    load_bouguet_calib,
    load_bouguet_stereo,
    read_points_csv,
    read_sequence,
    read_tracks_csv,
    save_bouguet_calib,
    save_bouguet_stereo,
    write_points_csv,
    write_tracks_csv,
)
from .analysis import (
    ReferenceStillness,
    StrokeAngle,
    align_rigid,
    find_reversals,
    tracking_error,
    length_statistics,
    pairwise_distance,
    points_to_array,
    reference_stillness,
    stroke_angle,
)
from .plots3d import plot_length_statistics, plot_points_3d, plot_reference_stillness, plot_stroke_angle
from . import widgets
from .ncc import FrameCorrelator, normxcorr2
from .centroid import CntrdResult, bpass, cntrd, matlab_round, pkfnd
from .thesis import ThesisResult, track_thesis
from . import synth
from .calibrate import (
    CameraCalibration,
    CornerDetection,
    StereoCalibration,
    board_points,
    calibrate_camera,
    calibrate_stereo,
    find_corners,
    suggest_suppress,
)
from .calibcheck import cross_validate
from .capture import Selection, select_calibration_frames
from . import pantilt
from . import plots
from .track import (
    apply_corrections,
    check_stereo,
    load_corrections,
    match_windows,
    refine_centroids,
    retrack_from,
    save_corrections,
    track_markers,
    TrackOptions,
)
from .video import write_tracking_video
from .pipeline import calibrate_folders, load_picks, run_demo, track_folder, track_stereo, triangulate_files
from .batch import load_manifest, run_batch
from .integrity import SequenceReport, SequenceWarning, StereoSequenceReport, check_sequence, check_stereo_sequences
from .io.exchange import (
    fit_dlt,
    read_dltdv,
    read_parquet,
    read_thesis_mat,
    write_dlt_coefficients,
    write_dltdv,
    write_parquet,
    write_thesis_mat,
)
from .config import AnalysisSettings, load_analysis_settings
from .kinematics import (
    WingSurface,
    compare_interpolation,
    fit_wing_surface,
    kinematic_reversals,
    kinematics_wide,
    phase_average,
    plot_kinematics,
    resample_phase,
    stroke_phase,
    wing_kinematics,
)
from .stitch import Stitched, stitch_tests
from .uncertainty import add_point_uncertainty, calibration_covariance, propagate_point_covariance
from .planner import ViewPlan, compare_placements, plan_views
from .pipeline import analyse_points
