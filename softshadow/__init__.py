"""softshadow: a differentiable expanded-shadow-volume soft shadow renderer in JAX.

The model (Shoji, Murayama and Konno; definitions in CONVENTIONS and the
README): the hard shadow volume of a mesh under the sun, expanded and
contracted at its silhouette by moving the light direction to L +- k N, with
alpha ramping between the two silhouettes, and the umbra at brightness rho.
"""

from .camera import GroundGrid, PinholeCamera, look_at_camera, project_points
from .meshes import BUILTIN_MESHES, MeshError, builtin_mesh, load_mesh
from .occluder import Occluder
from .params import (Pose, ShadowParams, Sun, brightness_to_paper, paper_to_range_k, paper_to_rho,
                     range_to_paper, rotation_matrix_xyz)
from .penumbra import PROFILES, RULES, occluded_disk_fraction, penumbra_coordinate, profile_alpha, shade
from .plan import GridPlan, PointPlan, plan_alpha, plan_grid, plan_points
from .render import CameraRender, SoftShadowModel, object_mask
from .scene_io import SceneError, SceneSpec, dump_scene, load_scene
from .sun import SunBelowHorizonError, light_direction, solar_position, sun_direction

__version__ = "0.1.0"

__all__ = [
    "BUILTIN_MESHES", "CameraRender", "GridPlan", "GroundGrid", "MeshError", "Occluder", "PROFILES",
    "PinholeCamera", "PointPlan", "Pose", "RULES", "SceneError", "SceneSpec", "ShadowParams",
    "SoftShadowModel", "Sun", "SunBelowHorizonError", "brightness_to_paper", "builtin_mesh",
    "dump_scene", "light_direction", "load_mesh", "load_scene", "look_at_camera", "object_mask",
    "occluded_disk_fraction", "paper_to_range_k", "paper_to_rho", "penumbra_coordinate", "plan_alpha",
    "plan_grid", "plan_points", "profile_alpha", "project_points", "range_to_paper",
    "rotation_matrix_xyz", "shade", "solar_position", "sun_direction", "__version__",
]
