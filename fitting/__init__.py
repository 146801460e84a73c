"""fitting: range k and brightness rho of outdoor soft shadows, per time of day, from photos.

Photos are read linearly (``photos``), timed and grouped (``exif``, ``grouping``),
registered (scene cameras or a ChArUco board, ``markers``), sampled near the
predicted shadow boundary (``samples``) and fitted with the differentiable
renderer and optimistix (``model``, ``solve``); ``api`` runs whole folders, ``many``
runs many folders on Dask, and
``report``/``plots`` write the Table-2 report. Fits run in float64, scoped to
the fitting call (``jax.enable_x64``), so the caller's own precision is kept.
"""

import lazy_loader as _lazy

# The public names, by the module that defines them, each imported on first use (PEP 562,
# ``lazy_loader``): a folder of photos without geometry is measured without loading JAX,
# optimistix or trimesh, whose imports take seconds.
__getattr__, __dir__, __all__ = _lazy.attach(__name__, submod_attrs={
    "folder.api": ["FolderError", "fit_and_report", "fit_folder", "fit_photos"],
    "edges.measure": ["EdgeMeasurement", "measure_shadow_edges"],
    "photos.exif": ["intrinsics_from_exif", "photo_time_from_exif", "read_exif"],
    "photos.grouping": ["NO_TIME_REASON", "PhotoGroup", "group_photos", "photo_time"],
    "folder.many": ["DONE_MARKER", "SUMMARY_COLUMNS", "find_photo_folders", "fit_many", "write_summary"],
    "photos.markers": ["Registration", "RegistrationError", "board_from_spec", "board_outline_world", "board_world_points",
                "register_board"],
    "solve.options": ["FitOptions"],
    "photos.read": ["IMAGE_EXTENSIONS", "RAW_EXTENSIONS", "Photo", "PhotoError", "linear_to_srgb", "list_photos",
               "read_photo", "srgb_to_linear"],
    "solve.problem": ["GroupProblem", "SolveOutcome", "group_problem"],
    "report.write": ["PAPER_TABLE2", "format_table", "write_report", "write_results_json", "write_table2"],
    "report.results": ["FitResults", "GroupResult"],
    "samples.photo_samples": ["NoShadowInView"],
    "solve.group": ["fit_group"],
    "photos.views": ["PhotoView"],
})
