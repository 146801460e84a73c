"""scene.toml's [[projector]] tables and ``softshadow render``'s projector options (docs/projector.md).

- The table is read, validated key by key with one-line messages, written back unchanged,
  and becomes the same ``softshadow.Projector`` as the command line's options.
- ``softshadow render`` with a projector writes the scene image; the slide shows where the
  projector points; bad options fail in one line with exit status 1.
"""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from scene import ProjectorSpec, SceneError, load_scene, scene_from_dict, scene_to_dict
from softshadow import sine_slide, spot_slide
from softshadow_cli.main import main

BASE = {"object": {"mesh": "pillar"}}


def _with(*projectors) -> dict:
    return dict(BASE, projector=list(projectors))


def test_projector_tables_are_read_and_written_back():
    table = {"position": [1.0, -2.0, 3.0], "target": [0.0, 0.0, 0.5], "fov_deg": 40.0, "slide": "sine",
             "frequency": 15.0, "amplitude": 0.5, "intensity": 2.0, "falloff": "none", "shadow_px": 256}
    spec = scene_from_dict(_with(table, {"position": [0, 0, 4], "direction": [0, 0.1, -1]}))
    assert len(spec.projectors) == 2
    p0, p1 = spec.projectors
    assert p0.target == (0.0, 0.0, 0.5) and p0.frequency == 15.0 and p0.amplitude == 0.5
    assert p1.slide == "spot" and p1.fov_deg == 30.0 and p1.falloff == "inverse-square"
    again = scene_from_dict(scene_to_dict(spec))
    assert again.projectors == spec.projectors
    proj = p0.projector()
    np.testing.assert_array_equal(proj.slide, sine_slide(15.0, 0.5))
    assert proj.intensity == 2.0 and proj.falloff == "none" and proj.shadow_px == 256
    # A direction: the target 1 m along it, so the intensity is the irradiance at 1 m.
    q = p1.projector()
    np.testing.assert_allclose(np.linalg.norm(q.target - q.position), 1.0)
    assert q.reference_distance_m == 1.0
    np.testing.assert_array_equal(q.slide, spot_slide())
    assert "projector" not in scene_to_dict(scene_from_dict(BASE)), "no projector, no table"


def test_an_image_slide_is_relative_to_the_folder(tmp_path):
    Image.fromarray(np.full((8, 8), 255, np.uint8)).save(tmp_path / "slide.png")
    (tmp_path / "scene.toml").write_text('[object]\nmesh = "pillar"\n[[projector]]\nposition = [0, 0, 4]\n'
                                         'target = [0, 0, 0]\nslide = "slide.png"\n')
    spec = load_scene(tmp_path / "scene.toml")
    np.testing.assert_allclose(spec.projectors[0].projector(spec.base_dir).slide, 1.0)


@pytest.mark.parametrize("table, message", [
    ({"target": [0, 0, 0]}, "needs position"),
    ({"position": [0, 0, 3]}, "exactly one of target"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "direction": [0, 0, -1]}, "exactly one of target"),
    ({"position": [0, 0, 3], "target": [0, 0, 3]}, "target must differ"),
    ({"position": [0, 0, 3], "direction": [0, 0, 0]}, "direction must not be zero"),
    ({"position": [0, 0], "target": [0, 0, 0]}, "position: expected 3 numbers"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "up": [0, 0, 1]}, "off the projector's axis"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "fov_deg": 0}, "fov_deg must be positive"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "fov_deg": 179}, "below 170"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "fov_deg": "wide"}, "fov_deg must be a number"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "slide": "sine"}, "needs frequency"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "slide": "sine", "frequency": -2}, "frequency must be >= 0"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "slide": "sine", "frequency": 4, "amplitude": 1.5},
     "amplitude must be in"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "frequency": 4}, "goes with slide"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "slide": 3}, "slide must be"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "intensity": -1}, "intensity must be >= 0"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "falloff": "linear"}, "falloff must be one of"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "shadow_px": 2.5}, "shadow_px must be a whole number"),
    ({"position": [0, 0, 3], "target": [0, 0, 0], "fov": 30}, "unknown key 'fov'; did you mean 'fov_deg'"),
])
def test_bad_projector_tables_are_refused_by_key(table, message):
    with pytest.raises(SceneError, match=message) as info:
        scene_from_dict(_with(table))
    assert "\n" not in str(info.value) and "[[projector]] #1" in str(info.value)


def test_a_single_projector_table_must_be_an_array_of_tables():
    with pytest.raises(SceneError, match=r"\[\[projector\]\]"):
        scene_from_dict(dict(BASE, projector={"position": [0, 0, 3], "target": [0, 0, 0]}))
    with pytest.raises(SceneError, match="did you mean \\[projector\\]"):
        scene_from_dict(dict(BASE, projectors=[]))


def test_spec_and_options_make_the_same_projector():
    spec = ProjectorSpec((1.0, 2.0, 3.0), target=(0.0, 0.0, 0.0), fov_deg=35.0, slide="sine", frequency=4.0)
    from softshadow_cli.render_command import _cli_projectors
    import argparse
    args = argparse.Namespace(projector=["1,2,3"], projector_target=["0,0,0"], projector_fov=[35.0],
                              slide=["sine:4"], projector_intensity=None)
    a, b = spec.projector(), _cli_projectors(args)[0]
    for key in ("position", "target", "up", "slide"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    assert a.fov_deg == b.fov_deg and a.intensity == b.intensity


# -- the command --------------------------------------------------------------------------------------
@pytest.fixture
def folder(tmp_path):
    (tmp_path / "scene.toml").write_text('[object]\nmesh = "pillar"\n')
    return tmp_path


def test_render_with_a_projector_lights_where_it_points(folder, capsys):
    out, npy = folder / "img.png", folder / "img.npy"
    camera = ["--camera-position", "0,-0.01,12", "--camera-target", "0,0,0", "--camera-fov", "40",
              "--size", "96x72"]
    code = main(["render", "--scene", str(folder / "scene.toml"), "--out", str(out), "--npy", str(npy),
                 "--no-sun", "--ambient", "0.1", "--projector=2,0,4", "--projector-target", "2,0,0",
                 "--projector-fov", "20", "--slide", "spot", *camera])
    assert code == 0, capsys.readouterr().err
    img = np.load(npy)
    assert img.shape == (72, 96, 3)
    png = np.asarray(Image.open(out))
    assert png.shape == (72, 96, 3)
    # The camera looks straight down on x in [-4.4, 4.4]: the spot (radius ~0.6 m) around x = 2 m
    # is lit, the ground at x = -2 m only by the ambient term (0.1 x paper albedo 0.85).
    f = 48 / np.tan(np.deg2rad(20))
    col = lambda x: int(round(47.5 + f * x / 12))
    assert img[36, col(2.0), 0] > 0.5
    np.testing.assert_allclose(img[36, col(-2.0)], 0.085, atol=1e-6)


@pytest.mark.parametrize("options, message, status", [
    # A value out of its range is refused before any work, with exit status 2 (softshadow_cli.validate).
    (["--projector", "1,2", "--projector-target", "0,0,0"], "--projector must be three numbers", 2),
    (["--projector", "1,2,3"], "one --projector-target", 2),
    (["--slide", "spot"], "--slide needs --projector", 2),
    (["--projector", "1,2,3", "--projector-target", "0,0,0", "--slide", "sine:x"], "sine:FREQ", 1),
    (["--projector", "1,2,3", "--projector-target", "0,0,0", "--slide", "nope.png"], "not found", 1),
    (["--projector", "1,2,3", "--projector-target", "0,0,0", "--projector-fov", "200"],
     "--projector-fov must be in (0, 170), got 200", 2),
    (["--projector", "1,2,3", "--projector", "2,2,3", "--projector-target", "0,0,0", "--projector-target",
      "0,0,0", "--slide", "spot", "--slide", "spot", "--slide", "spot"], "once per --projector", 2),
    (["--camera-position", "1,2,3"], "both --camera-position and --camera-target", 2),
    (["--projector", "1,2,3", "--projector-target", "0,0,0", "--silhouettes"], "--silhouettes", 1),
])
def test_bad_render_options_fail_in_one_line(folder, capsys, options, message, status):
    code = main(["render", "--scene", str(folder / "scene.toml"), "--out", str(folder / "x.png"), "--no-sun",
                 *options])
    err = capsys.readouterr().err
    assert code == status and message in err and len(err.strip().splitlines()) == 1, err
    assert not (folder / "x.png").exists()


def test_render_without_projectors_is_the_shadow_map_as_before(folder, capsys):
    npy = folder / "map.npy"
    code = main(["render", "--scene", str(folder / "scene.toml"), "--out", str(folder / "map.png"), "--npy", str(npy),
                 "--sun-azimuth", "124", "--sun-elevation", "40", "--size", "64x64", "--k", "0.02", "--rho", "0.3"])
    assert code == 0, capsys.readouterr().err
    shading = np.load(npy)
    assert shading.shape == (64, 64)
    # Lit ground 1, the umbra at rho away from the pillar; nearer, the sky the pillar hides darkens it
    # (0 on the ground under the pillar itself).
    assert shading.min() >= -1e-9 and shading.max() == pytest.approx(1.0, abs=1e-3)
    assert (np.abs(shading - 0.3) < 0.02).sum() > 100


def test_render_a_scene_toml_with_a_projector_a_mesh_receiver_and_the_sun(tmp_path, capsys):
    import trimesh
    trimesh.creation.box((6.0, 6.0, 0.2)).apply_translation((0, 0, -0.1)).export(tmp_path / "floor.ply")
    (tmp_path / "scene.toml").write_text(
        '[object]\nmesh = "pillar"\n[receiver]\nkind = "mesh"\nmesh = "floor.ply"\n'
        '[[projector]]\nposition = [2.0, -2.0, 4.0]\ntarget = [0.0, 0.0, 0.5]\nfov_deg = 50\n'
        'slide = "sine"\nfrequency = 4\n')
    npy = tmp_path / "scene.npy"
    code = main(["render", "--scene", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "s.png"), "--npy",
                 str(npy), "--sun-azimuth", "200", "--sun-elevation", "45", "--size", "80x60", "--smooth",
                 "--supersample", "2"])
    assert code == 0, capsys.readouterr().err
    img = np.load(npy)
    assert img.shape == (60, 80, 3) and np.all(np.isfinite(img))
    # Lit floor: ambient rho 0.3 + sun 0.7 + the projector's light on its brightest cells.
    assert img.max() > 0.85 * 1.5 and img.min() >= 0.0


def test_scene_image_through_the_scene_toml_camera(tmp_path, capsys):
    (tmp_path / "scene.toml").write_text(
        '[object]\nmesh = "ball"\n[camera]\nkind = "explicit"\n'
        'K = [[60.0, 0.0, 31.5], [0.0, 60.0, 23.5], [0.0, 0.0, 1.0]]\n'
        'R = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]\nt = [0.0, 0.0, 6.0]\n'
        '[[projector]]\nposition = [0.0, 0.0, 5.0]\ndirection = [0.0, 0.0, -1.0]\nfov_deg = 20\n')
    npy = tmp_path / "s.npy"
    code = main(["render", "--scene", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "s.png"), "--npy",
                 str(npy), "--no-sun", "--ambient", "0"])
    assert code == 0, capsys.readouterr().err
    img = np.load(npy)
    assert img.shape == (48, 64, 3)  # the image the principal point is the centre of
    # Looking straight down on the ball under a projector straight above: its top is lit, the
    # ground around it is in its shadow out to the beam's edge, and beyond the beam all is dark.
    assert img[24, 32, 0] > 0.01 and img[24, 2, 0] == 0.0 and img[2, 32, 0] == 0.0


def test_a_range_image_receiver_is_drawn_as_its_surface(tmp_path, capsys):
    """A range image of the ground with a 0.5 m step, seen straight down: the scene image sees the
    step's top 0.5 m nearer the projector above, so brighter by the inverse square."""
    K = [[60.0, 0.0, 31.5], [0.0, 60.0, 23.5], [0.0, 0.0, 1.0]]
    depth = np.full((48, 64), 6.0, np.float32)
    depth[:, 40:] = 5.5  # x > ~0.85 m is a step 0.5 m high
    np.save(tmp_path / "bg.depth.npy", depth)
    (tmp_path / "scene.toml").write_text(
        '[object]\nmesh = "ball"\nposition = [-1.5, 0.0, -1.0]\n[receiver]\nkind = "depth"\n'
        'depth = "bg.depth.npy"\n[camera]\nkind = "explicit"\n'
        f'K = {K}\nR = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]\nt = [0.0, 0.0, 6.0]\n'
        '[[projector]]\nposition = [0.0, 0.0, 3.0]\ntarget = [0.0, 0.0, 0.0]\nfov_deg = 120\n'
        'falloff = "inverse-square"\n')
    npy = tmp_path / "s.npy"
    code = main(["render", "--scene", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "s.png"), "--npy",
                 str(npy), "--no-sun", "--ambient", "0"])
    err = capsys.readouterr().err
    assert code == 0 and "ground plane" not in err, err
    img = np.load(npy)[..., 0]
    floor, step = img[24, 30], img[24, 50]
    x_floor, x_step = (30 - 31.5) / 60 * 6.0, (50 - 31.5) / 60 * 5.5
    cos_floor, cos_step = 3.0 / np.hypot(x_floor, 3.0), 2.5 / np.hypot(x_step, 2.5)
    expected = (cos_step / (x_step ** 2 + 2.5 ** 2)) / (cos_floor / (x_floor ** 2 + 3.0 ** 2))
    np.testing.assert_allclose(step / floor, expected, rtol=0.02)
