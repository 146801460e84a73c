"""fitting: range k and brightness rho of outdoor soft shadows, per time of day, from photos.

Photos are read linearly (``photos``), timed and grouped (``exif``, ``grouping``),
registered (scene cameras or a ChArUco board, ``markers``), sampled near the
predicted shadow boundary (``samples``) and fitted with the differentiable
renderer and optimistix (``model``, ``solve``); ``api`` runs whole folders, ``many``
runs many folders on Dask, and
``report``/``plots`` write the Table-2 report. Fits run in float64, scoped to
the fitting call (``jax.enable_x64``), so the caller's own precision is kept.
"""

from .api import FolderError, fit_and_report, fit_folder, fit_photos
from .edge_measure import EdgeMeasurement, measure_shadow_edges
from .exif import intrinsics_from_exif, photo_time_from_exif, read_exif
from .grouping import NO_TIME_REASON, PhotoGroup, group_photos, photo_time
from .many import DONE_MARKER, SUMMARY_COLUMNS, find_photo_folders, fit_many, write_summary
from .markers import (Registration, RegistrationError, board_from_spec, board_outline_world,
                      board_world_points, register_board)
from .pair_reference import attenuation_image, reference_at_profiles
from .problem import GroupProblem, SolveOutcome, group_problem
from .photos import (IMAGE_EXTENSIONS, RAW_EXTENSIONS, Photo, PhotoError, linear_to_srgb, list_photos,
                     read_photo, srgb_to_linear)
from .report import PAPER_TABLE2, format_table, write_report, write_results_json, write_table2
from .results import FitResults, GroupResult
from .samples import NoShadowInView
from .solve import FitOptions, fit_group
from .views import PhotoView

__all__ = [
    "attenuation_image", "reference_at_profiles",
    "DONE_MARKER", "EdgeMeasurement", "FitOptions", "fit_and_report", "FitResults", "FolderError", "GroupResult",
    "IMAGE_EXTENSIONS",
    "NO_TIME_REASON", "NoShadowInView", "PAPER_TABLE2", "Photo", "PhotoError", "PhotoGroup",
    "PhotoView", "RAW_EXTENSIONS", "Registration", "RegistrationError", "board_from_spec",
    "board_outline_world", "board_world_points", "find_photo_folders", "fit_folder", "fit_group", "fit_many",
    "fit_photos", "GroupProblem", "group_problem", "SolveOutcome",
    "format_table", "group_photos", "intrinsics_from_exif", "linear_to_srgb", "list_photos",
    "measure_shadow_edges", "photo_time", "photo_time_from_exif", "read_exif", "read_photo",
    "register_board", "srgb_to_linear", "SUMMARY_COLUMNS", "write_report", "write_results_json", "write_summary",
    "write_table2",
]
