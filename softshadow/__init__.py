"""softshadow: a differentiable expanded-shadow-volume soft shadow renderer in JAX.

The model (Shoji, Murayama and Konno; definitions in CONVENTIONS and the
README): the hard shadow volume of a mesh under the sun, expanded and
contracted at its silhouette by moving the light direction to L +- k N, with
alpha ramping between the two silhouettes, and the umbra at brightness rho.
"""

from ._version import __version__
from .colour import linear_to_srgb, srgb_to_linear
from .compilation_cache import default_cache_dir, use_compilation_cache
from .camera import GroundGrid, PinholeCamera, look_at_camera
from .evaluate import plan_alpha, plan_alpha_jit, plan_coordinate, plan_coordinate_light
from .lod import PAPER_FACE_COUNTS, LodLevel, decimate, lod_series
from .meshes import BUILTIN_MESHES, MeshError, builtin_mesh, load_mesh
from .occluder import Occluder, Silhouette
from .params import (Pose, ShadowParams, Sun, brightness_to_paper, paper_to_range_k, paper_to_rho,
                     range_to_paper, rotation_matrix_xyz)
from .penumbra import (PROFILES, RULES, blurred_profile_alpha, footprint_profile_alpha, occluded_disk_fraction,
                       penumbra_coordinate, profile_alpha, profile_integral, shade)
from .plan import (BACKENDS, GridPlan, PointPlan, bucket_size, concatenate_plans, edge_band_widths,
                   light_band_widths, plan_grid, plan_points)
from .posed import PosedOccluder, pose_matrix, posed_vertices
from .raster import project_to_ground
from .sky import (SkyNodes, cosine_weighted_directions, hidden_sky_fraction, hidden_sky_map, hidden_sky_nodes,
                  open_sky_fraction)
from .shadowmap import BIAS_PX, LightFrame, ShadowMap, depth_bias, faces_away, rasterise_depth, shadow_map
from .render import CameraRender, SoftShadowModel, object_mask
from .slides import DEFAULT_SLIDE_PX, PAPER_SLIDES, SlideError, load_slide, sine_slide, slide_from_text, spot_slide
from .projector import FALLOFFS, Projector, ProjectorShadowMap, projector_shadow_map
from .visibility import GROUND, NOTHING, Surface, VisibleSurfaces, visible_surfaces
from .scene_render import SceneLights, SceneRender, SceneSetup, prepare_scene, render_scene, shade_scene
from .sun import SunBelowHorizonError, check_sun_above_horizon, light_direction, sun_direction
from .threads import one_blas_thread

__all__ = [
    "DEFAULT_SLIDE_PX", "PAPER_SLIDES", "SlideError", "load_slide", "sine_slide", "slide_from_text", "spot_slide",
    "FALLOFFS", "Projector", "ProjectorShadowMap", "projector_shadow_map",
    "GROUND", "NOTHING", "Surface", "VisibleSurfaces", "visible_surfaces",
    "SceneLights", "SceneRender", "SceneSetup", "prepare_scene", "render_scene", "shade_scene",
    "BACKENDS", "BIAS_PX", "LightFrame", "ShadowMap", "depth_bias", "faces_away", "light_band_widths",
    "rasterise_depth", "shadow_map",
    "PAPER_FACE_COUNTS", "LodLevel", "decimate", "lod_series",
    "BUILTIN_MESHES", "CameraRender", "GridPlan", "GroundGrid", "MeshError", "Occluder", "PROFILES",
    "PinholeCamera", "PointPlan", "Pose", "PosedOccluder", "RULES", "ShadowParams", "Silhouette",
    "SoftShadowModel", "Sun", "SunBelowHorizonError", "blurred_profile_alpha", "brightness_to_paper",
    "bucket_size", "builtin_mesh", "cosine_weighted_directions", "footprint_profile_alpha",
    "SkyNodes", "hidden_sky_fraction", "hidden_sky_map", "hidden_sky_nodes", "open_sky_fraction", "profile_integral", "check_sun_above_horizon", "concatenate_plans", "default_cache_dir",
    "edge_band_widths", "light_direction", "linear_to_srgb", "load_mesh", "look_at_camera", "object_mask",
    "occluded_disk_fraction", "one_blas_thread",
    "paper_to_range_k", "paper_to_rho", "penumbra_coordinate", "plan_alpha", "plan_alpha_jit",
    "plan_coordinate", "plan_coordinate_light", "plan_grid", "plan_points", "pose_matrix",
    "posed_vertices", "profile_alpha", "project_to_ground", "range_to_paper",
    "rotation_matrix_xyz", "shade", "srgb_to_linear", "sun_direction", "use_compilation_cache", "__version__",
]
