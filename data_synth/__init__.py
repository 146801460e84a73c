"""data_synth: synthetic photo folders with known truth, rendered by physics or by the model.

``synthesize(out_dir, preset="table2", ...)`` writes a photo folder in the
format of docs/formats.md (images, scene.toml, truth.json). The default renderer casts
rays against the mesh for a sun disk of finite angular radius plus a uniform
sky (``data_synth.physical``), independent of the project's shadow model; the
``model`` renderer uses softshadow.render.SoftShadowModel. ``draw_scene(rng, prior, out_dir)``
draws a group at random from a documented prior (``ScenePrior``) and renders it, for calibration
studies. See docs/data_synth.md.
"""

from .camera_pipeline import (SensorSettings, camera_pipeline, fit_handheld_camera, handheld_camera,
                              topdown_grid)
from .image_io import FORMATS, PhotoMetadata, dng_available, exif_bytes, write_photo
from .lighting import SUN_RADIUS_DEG, SunSky
from .physical import (SkyVisibilityMap, irradiance, shadow_reach, sky_visibility, sky_visibility_map,
                       sun_visibility)
from .presets import PRESETS, PresetPlan, build_preset
from .receivers import (HeightfieldReceiver, MeshReceiver, PlaneReceiver, bank_terrain, rising_bank,
                        steps_receiver, texture_coordinates, wall_receiver)
from .same_model import model_topdown_folder
from .renderers import RENDERERS, ModelRenderer, PhysicalRenderer, RenderQuality, SynthScene, make_renderer
from .synth import OutputExistsError, posed_mesh, synthesize, synthesize_plan
from .misdescription import Misdescription
from .draw import SceneDraw, ScenePrior, draw_parameters, draw_scene, synthesize_draw
from .textures import BoardSpec, GroundAppearance, PaperSheet, procedural_texture

__all__ = [
    "BoardSpec", "FORMATS", "GroundAppearance", "HeightfieldReceiver", "MeshReceiver", "ModelRenderer", "OutputExistsError",
    "PRESETS", "PaperSheet", "PhotoMetadata", "PhysicalRenderer", "PlaneReceiver", "PresetPlan", "RENDERERS",
    "RenderQuality", "SUN_RADIUS_DEG", "SensorSettings", "SkyVisibilityMap", "SunSky", "SynthScene",
    "bank_terrain", "build_preset", "camera_pipeline", "dng_available", "exif_bytes", "fit_handheld_camera",
    "handheld_camera", "irradiance", "make_renderer", "model_topdown_folder", "posed_mesh", "procedural_texture",
    "shadow_reach", "sky_visibility", "sky_visibility_map", "steps_receiver",
    "sun_visibility", "synthesize", "texture_coordinates", "topdown_grid", "wall_receiver", "write_photo",
    "Misdescription", "SceneDraw", "ScenePrior", "draw_parameters", "draw_scene", "synthesize_draw", "synthesize_plan",
    "rising_bank",
]
