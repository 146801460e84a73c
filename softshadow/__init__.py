"""softshadow: a differentiable expanded-shadow-volume soft shadow renderer in JAX.

The model (Shoji, Murayama and Konno): the hard shadow volume of a mesh under the sun, expanded and
contracted at its silhouette by moving the light direction to L +- k N, with alpha ramping between the
two silhouettes, and the umbra at brightness rho (docs/renderer.md). Projector scenes with shadow maps
and levels of detail follow Dowling (docs/projector.md).

The names here are the public API. ``softshadow.internal`` holds the building blocks the fitter and the
synthesiser use (plans, occluders, shadow maps): usable, but they may change between releases.
"""

import lazy_loader as _lazy

from ._version import __version__

# Each module is imported when one of its names is first used (PEP 562, ``lazy_loader``): a process
# that needs only the NumPy/OpenCV steps (a photo without geometry, ``--help``) never loads JAX or
# trimesh, which take seconds.
__getattr__, __dir__, __all__ = _lazy.attach(__name__, submodules=["internal"], submod_attrs={
    "colour": ["linear_to_srgb", "srgb_to_linear"],
    "compilation_cache": ["use_compilation_cache"],
    "camera": ["GroundGrid", "PinholeCamera", "look_at_camera"],
    "lod": ["LodLevel", "PAPER_FACE_COUNTS", "decimate", "lod_series"],
    "meshes": ["BUILTIN_MESHES", "MeshError", "builtin_mesh", "load_mesh"],
    "params": ["Pose", "ShadowParams", "Sun"],
    "penumbra": ["occluded_disk_fraction", "profile_alpha"],
    "pixel_profile": ["blurred_profile_alpha"],
    "projector": ["Projector"],
    "render": ["CameraRender", "SoftShadowModel"],
    "scene_render": ["SceneLights", "SceneRender", "SceneSetup", "prepare_scene", "render_scene",
                     "shade_scene"],
    "slides": ["PAPER_SLIDES", "SlideError", "load_slide", "sine_slide", "slide_from_text", "spot_slide"],
    "threads": ["one_blas_thread"],
    "sun": ["SunBelowHorizonError", "light_direction", "sun_direction"],
    "units": ["brightness_to_paper", "paper_to_range_k", "paper_to_rho", "range_to_paper"],
})
__all__ = [n for n in __all__ if n != "internal"] + ["__version__"]
