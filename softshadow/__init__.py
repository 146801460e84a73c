"""softshadow: a differentiable expanded-shadow-volume soft shadow renderer in JAX.

The model (Shoji, Murayama and Konno; definitions in CONVENTIONS and the
README): the hard shadow volume of a mesh under the sun, expanded and
contracted at its silhouette by moving the light direction to L +- k N, with
alpha ramping between the two silhouettes, and the umbra at brightness rho.
"""

import lazy_loader as _lazy

from ._version import __version__

# The public names, by the module that defines them. Each module is imported when one of its
# names is first used (PEP 562, ``lazy_loader``): a process that needs only the NumPy/OpenCV
# steps (a photo without geometry, ``--help``) never loads JAX or trimesh, which take seconds.
__getattr__, __dir__, __all__ = _lazy.attach(__name__, submod_attrs={
    "colour": ["linear_to_srgb", "srgb_to_linear"],
    "dense_plan": ["DensePlan", "plan_dense_points"],
    "compilation_cache": ["default_cache_dir", "use_compilation_cache", "SAVED_PROGRAMS_ENV"],
    "camera": ["GroundGrid", "PinholeCamera", "look_at_camera"],
    "evaluate": ["plan_alpha", "plan_alpha_jit", "plan_coordinate", "plan_coordinate_light"],
    "lod": ["PAPER_FACE_COUNTS", "LodLevel", "decimate", "lod_series"],
    "meshes": ["BUILTIN_MESHES", "MeshError", "builtin_mesh", "load_mesh"],
    "occluder": ["Occluder", "Silhouette"],
    "params": ["Pose", "ShadowParams", "Sun", "rotation_matrix_xyz"],
    "penumbra": ["PROFILES", "RULES", "footprint_profile_alpha", "occluded_disk_fraction",
                 "penumbra_coordinate", "profile_alpha", "profile_integral", "shade"],
    "pixel_profile": ["WIDE_BLUR_TAU", "blurred_profile_alpha"],
    "plan": ["BACKENDS", "GridPlan", "PointPlan", "bucket_size", "concatenate_plans", "edge_band_widths",
             "light_band_widths", "plan_grid", "plan_points"],
    "posed": ["PosedOccluder", "pose_matrix", "posed_vertices"],
    "projector": ["FALLOFFS", "Projector", "ProjectorShadowMap", "projector_shadow_map"],
    "raster": ["project_to_ground"],
    "render": ["CameraRender", "SoftShadowModel", "object_mask"],
    "scene_frame": ["FRAME_STEPS", "FrameRenderer", "SceneFrame", "band_alpha", "render_frame"],
    "scratch": ["Scratch"],
    "scene_render": ["SceneLights", "SceneRender", "SceneSetup", "prepare_scene", "projector_light", "render_scene",
                     "shade_scene"],
    "shadowmap": ["BIAS_PX", "LightFrame", "ShadowMap", "depth_bias", "faces_away", "rasterise_depth", "shadow_map"],
    "sky": ["SkyNodes", "SkyPatch", "cosine_weighted_directions", "hidden_sky_fraction", "hidden_sky_map", "hidden_sky_nodes",
            "open_sky_fraction"],
    "slides": ["DEFAULT_SLIDE_PX", "PAPER_SLIDES", "SlideError", "load_slide", "sine_slide", "slide_from_text",
               "spot_slide"],
    "sun": ["SunBelowHorizonError", "check_sun_above_horizon", "light_direction", "sun_direction"],
    "threads": ["one_blas_thread"],
    "units": ["brightness_to_paper", "paper_to_range_k", "paper_to_rho", "range_to_paper"],
    "visibility": ["GROUND", "NOTHING", "Surface", "VisibleSurfaces", "visible_surfaces"],
})
__all__ += ["__version__"]
