"""Building blocks of the renderer for the layers above it (the fitter, the synthesiser, the benchmarks).

Plans (the discrete choices of a render), occluders and their silhouettes, shadow maps, visibility,
the hidden sky and the evaluation of a plan. Unlike ``softshadow``'s own names these may change
between releases.
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach("softshadow", submod_attrs={
    "compilation_cache": ["SAVED_PROGRAMS_ENV", "default_cache_dir"],
    "dense_plan": ["DensePlan", "PointBlocks", "plan_dense_points"],
    "evaluate": ["plan_alpha", "plan_alpha_jit", "plan_coordinate", "plan_coordinate_light"],
    "lod": ["decimate"],
    "masking": ["comparison_region", "render_level_image"],
    "occluder": ["Occluder", "Silhouette"],
    "params": ["rotation_matrix_xyz"],
    "penumbra": ["PROFILES", "RULES", "footprint_profile_alpha", "penumbra_coordinate", "profile_integral",
                 "shade"],
    "pixel_profile": ["WIDE_BLUR_TAU"],
    "plan": ["BACKENDS", "GridPlan", "PointPlan", "bucket_size", "concatenate_plans", "edge_band_widths",
             "light_band_widths", "plan_grid", "plan_points"],
    "posed": ["PosedOccluder", "pose_matrix", "posed_vertices"],
    "projector": ["FALLOFFS", "ProjectorShadowMap", "projector_shadow_map"],
    "raster": ["project_to_ground", "winding_fill"],
    "render": ["object_mask"],
    "scene_frame": ["FRAME_STEPS", "band_alpha"],
    "scene_render": ["projector_light"],
    "scratch": ["Scratch"],
    "shadowmap": ["BIAS_PX", "LightFrame", "ShadowMap", "depth_bias", "faces_away", "rasterise_depth",
                  "shadow_map"],
    "sky": ["SkyNodes", "SkyPatch", "cosine_weighted_directions", "hidden_sky_fraction", "hidden_sky_map",
            "hidden_sky_nodes", "open_sky_fraction"],
    "slides": ["DEFAULT_SLIDE_PX"],
    "sun": ["check_sun_above_horizon", "light_direction"],
    "visibility": ["GROUND", "NOTHING", "Surface", "VisibleSurfaces", "visible_surfaces"],
})
