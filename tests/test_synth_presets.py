"""Presets and synthesize(): folder contents, scene.toml, truth.json, renderers, CLI."""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math

import cv2
import numpy as np
import pytest

import data_synth
from data_synth import PRESETS, SunSky, synthesize
from softshadow_cli.synth_command import add_arguments, run
from data_synth.receivers import PlaneReceiver
from data_synth.renderers import ModelRenderer, PhysicalRenderer, RenderQuality, SynthScene
from data_synth.textures import GroundAppearance
from data_synth.tracing import topdown_rays
from softshadow.camera import GroundGrid
from softshadow.meshes import builtin_mesh
from scene import load_scene, parse_time
from scene import solar_position

SMALL = (160, 120)
FAST = RenderQuality(sun_samples=16, sky_samples=256, sky_fine_nodes=48, object_sky_samples=16)


@pytest.fixture(scope="module")
def table2_dir(tmp_path_factory):  # noqa: D103
    return synthesize(tmp_path_factory.mktemp("t2") / "out", "table2", seed=3, size=SMALL, progress=False,
                      render_quality=FAST)


def test_table2_folder_scene_and_truth(table2_dir):
    import piexif
    names = sorted(p.name for p in table2_dir.glob("*.jpg"))
    assert names == [f"IMG_{i:04d}.jpg" for i in range(1, 10)]
    scene = load_scene(table2_dir / "scene.toml")
    assert scene.site is not None and scene.site.latitude == pytest.approx(39.70)
    assert scene.site.timezone == "Asia/Tokyo" and scene.object.mesh == "pillar"
    assert scene.camera.kind == "markers" and scene.camera.origin_m is not None
    truth = json.loads((table2_dir / "truth.json").read_text())
    assert truth["renderer"] == "physical" and truth["preset"] == "table2"
    by_label = {g["label"]: g for g in truth["groups"]}
    assert list(by_label) == ["09:20", "13:21", "16:21"]
    for label, paper in (("09:20", 110), ("13:21", 120), ("16:21", 180)):
        g = by_label[label]
        assert len(g["photos"]) == 3
        assert 255 * g["rho"] ** (1 / 2.2) == pytest.approx(paper, abs=1.0)
        assert 0.004 < g["range_k"] < 0.01  # the real sun widened a little by haze, not the paper's 6
        assert g["range_k"] == pytest.approx(math.tan(math.radians(g["sun_radius_deg"])))
    for name in names:
        spec = scene.photos[name]
        assert spec.camera.kind == "explicit"
        cam = spec.camera.pinhole(*SMALL)
        assert cam.width == SMALL[0]
        assert spec.sun_azimuth_deg is None and spec.time is None  # the fitter derives the sun from EXIF + site
        exif = piexif.load(str(table2_dir / name))["Exif"]
        stamp = exif[piexif.ExifIFD.DateTimeOriginal].decode().replace(":", "-", 2).replace(" ", "T")
        when = parse_time(stamp + exif[piexif.ExifIFD.OffsetTimeOriginal].decode())
        az, el = solar_position(when, 39.70, 141.13)
        detail = truth["photos_detail"][name]
        assert detail["sun_azimuth_deg"] == pytest.approx(az, abs=1e-6)
        assert detail["sun_elevation_deg"] == pytest.approx(el, abs=1e-6)
        group = by_label[detail["group"]]
        assert name in group["photos"]
        assert abs(group["sun_elevation_deg"] - el) < 0.5  # photos of a group are under two minutes apart
    days = {by_label[k]["photos"][0]: v for k, v in (("09:20", 27), ("13:21", 20), ("16:21", 20))}
    for name, day in days.items():
        assert dt.datetime.fromisoformat(truth["photos_detail"][name]["time"]).day == day


def test_umbra_over_lit_paper_in_a_written_image_is_rho(tmp_path):
    """Whole pipeline (render, exposure, vignetting, blur, 16-bit file): umbra / lit paper on the
    top-down photo equals rho, up to the sky the pillar hides (a few %)."""
    import tifffile
    out = synthesize(tmp_path / "p", "pillar", size=(320, 240), fmt="tiff", noise=False, progress=False,
                     render_quality=FAST)
    truth = json.loads((out / "truth.json").read_text())
    g = truth["groups"][0]
    name = "IMG_0003.tiff"
    detail = truth["photos_detail"][name]
    grid = load_scene(out / "scene.toml").photos[name].camera.grid(320, 240)
    img = tifffile.imread(out / name).astype(float).mean(-1) / 65535
    sun = SunSky(g["sun_azimuth_deg"], g["sun_elevation_deg"])
    d = -sun.direction[:2] / np.linalg.norm(sun.direction[:2])
    side = np.array([-d[1], d[0]])
    vig = detail["sensor"]["vignetting"]

    def level(xy):
        col, row = np.round(grid.to_pixel(np.asarray(xy))).astype(int)
        r2 = ((col - 159.5) ** 2 + (row - 119.5) ** 2) / (159.5 ** 2 + 119.5 ** 2)
        return img[row, col] / (1 - vig * r2)  # undo the recorded vignetting

    ratios = [level(d * s) / level(d * s + side * 0.35) for s in (0.8, 1.0, 1.2)]
    assert np.all(np.array(ratios) < g["rho"] * 1.01)
    assert np.allclose(ratios, g["rho"], rtol=0.05)


def test_refuses_non_empty_folder_and_force_removes_only_its_own_files(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    with pytest.raises(data_synth.OutputExistsError, match="--force"):
        synthesize(out, "pillar", size=(48, 36), progress=False, render_quality=FAST)
    synthesize(out, "pillar", size=(48, 36), progress=False, render_quality=FAST, force=True)
    (out / "IMG_0001.jpg").rename(out / "old.jpg")  # pretend an earlier run's listed file is gone
    synthesize(out, "pillar", size=(48, 36), progress=False, render_quality=FAST, force=True, fmt="png")
    left = sorted(p.name for p in out.iterdir())
    assert "keep.txt" in left and "old.jpg" in left
    assert not any(n.startswith("IMG_") and n.endswith(".jpg") for n in left)
    scene = load_scene(out / "scene.toml")
    assert all(p.time is not None for p in scene.photos.values())  # PNG has no EXIF: time in scene.toml


def test_model_renderer_umbra_is_exactly_rho_and_agrees_with_physics():
    mesh = builtin_mesh("pillar")
    scene = SynthScene(mesh, (0.5, 0.5, 0.5), PlaneReceiver())
    sun = SunSky.from_rho(200.0, 50.0, 0.3, 0.5)
    grid = GroundGrid.around((0.6, 1.3), 3.0, 120)
    ground = GroundAppearance(np.full((4, 4, 3), 0.8, np.float32))
    rays = topdown_rays(grid)
    model = ModelRenderer(scene).render(rays, sun, ground, np.random.default_rng(0))
    phys = PhysicalRenderer(scene, FAST).render(rays, sun, ground, np.random.default_rng(0))
    shade_m = model.irradiance / sun.lit_irradiance
    shade_p = phys.irradiance / sun.lit_irradiance
    ok = model.kind == 1
    assert np.nanmin(shade_m[ok]) == pytest.approx(0.3, abs=1e-6)
    assert np.nanmax(shade_m[ok]) == pytest.approx(1.0, abs=1e-6)
    dark_m, dark_p = ok & (shade_m < 0.65), ok & (shade_p < 0.65)
    iou = (dark_m & dark_p).sum() / (dark_m | dark_p).sum()
    assert iou > 0.9


def test_hard_cases(tmp_path):
    import piexif
    out = synthesize(tmp_path / "h", "hard-cases", size=SMALL, progress=False, render_quality=FAST)
    truth = json.loads((out / "truth.json").read_text())
    scene = load_scene(out / "scene.toml")
    assert scene.site is None
    skipped = [s["photo"] for s in truth["expected_skipped"]]
    assert len(skipped) == 1 and cv2.imread(str(out / skipped[0])) is None
    assert skipped[0] not in scene.photos
    labels = {g["label"]: g for g in truth["groups"]}
    assert {"low-sun", "zenith", "subpixel", "out-of-frame", "clutter"} <= set(labels)
    assert labels["low-sun"]["sun_elevation_deg"] == pytest.approx(5.0)
    assert labels["zenith"]["sun_elevation_deg"] > 85
    assert truth["photos_detail"][labels["subpixel"]["photos"][0]]["penumbra_px"] < 1.0
    notime = [n for n, d in truth["photos_detail"].items() if d["time"] is None]
    assert len(notime) == 1
    assert piexif.ExifIFD.DateTimeOriginal not in piexif.load(str(out / notime[0]))["Exif"]
    assert scene.photos[notime[0]].time is None and scene.photos[notime[0]].group is None
    for _name, spec in scene.photos.items():  # no site: every photo carries its sun
        assert spec.sun_azimuth_deg is not None and spec.sun_elevation_deg is not None


def test_depth_background_writes_range_images(tmp_path):
    from data_synth import bank_terrain
    out = synthesize(tmp_path / "d", "depth-background", size=SMALL, progress=False, render_quality=FAST)
    scene = load_scene(out / "scene.toml")
    assert scene.receiver.kind == "depth"
    for _name, spec in scene.photos.items():
        assert spec.depth.endswith(".depth.npy")
        depth = np.load(out / spec.depth)
        assert depth.shape == SMALL[::-1] and depth.dtype == np.float32
        finite = np.isfinite(depth)
        assert finite.mean() > 0.5 and np.all(depth[finite] > 0)
        # the bank rises away from the camera: further rows up the image are deeper
        col = depth[:, SMALL[0] // 2]
        assert np.nanmedian(col[: SMALL[1] // 3]) > np.nanmedian(col[-SMALL[1] // 3:])
        # each value is z_cam: back-projected through the photo's camera it lies on the bank
        cam = spec.camera.pinhole(*SMALL)
        rows, cols = np.nonzero(finite)
        x_cam = depth[rows, cols, None] * (np.column_stack([cols, rows, np.ones(len(rows))])
                                            @ np.linalg.inv(cam.K).T)
        world = (x_cam - cam.t) @ cam.R
        assert np.max(np.abs(world[:, 2] - bank_terrain().height(world[:, :2]))) < 2e-3
    with pytest.raises(ValueError, match="plane"):
        synthesize(tmp_path / "d2", "depth-background", size=SMALL, progress=False, renderer="model")


@pytest.mark.parametrize("preset", ["steps", "wall"])
def test_mesh_receiver_presets_write_their_mesh(tmp_path, preset):
    import trimesh
    out = synthesize(tmp_path / preset, preset, size=(96, 72), progress=False, render_quality=FAST)
    scene = load_scene(out / "scene.toml")
    assert scene.receiver.kind == "mesh"
    mesh = trimesh.load(out / scene.receiver.mesh, force="mesh")
    assert mesh.bounds[1, 2] > (0.6 if preset == "steps" else 2.0)  # the steps / the wall stand up
    truth = json.loads((out / "truth.json").read_text())
    assert truth["receiver"]["kind"] == "mesh" and scene.receiver.mesh in truth["files"]
    g = truth["groups"][0]
    assert len(g["photos"]) == 2 and 0 < g["rho"] < 1 and g["range_k"] > 0


@pytest.mark.parametrize("preset", ["ball", "dragon"])
def test_object_presets_write_valid_folders(tmp_path, preset):
    out = synthesize(tmp_path / preset, preset, size=(96, 72), progress=False, render_quality=FAST,
                     renderer="model" if preset == "dragon" else "physical")
    scene = load_scene(out / "scene.toml")
    assert scene.object.mesh == preset
    kinds = sorted(spec.camera.kind for spec in scene.photos.values())
    assert kinds == ["explicit", "explicit", "topdown"]
    for name in scene.photos:
        img = cv2.imread(str(out / name))
        assert img is not None and img.shape == (72, 96, 3)
        assert 30 < img.mean() < 230


def test_cli_runs_and_refuses_to_overwrite(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    out = tmp_path / "cli"
    args = parser.parse_args([str(out), "--preset", "pillar", "--seed", "2", "--size", "64x48",
                              "--renderer", "model", "--format", "tiff", "--no-progress"])
    assert run(args) == 0
    assert sorted(p.suffix for p in out.glob("IMG_*")) == [".tiff"] * 3
    assert run(args) == 1
    assert "--force" in capsys.readouterr().err
    args.force = True
    assert run(args) == 0
    with pytest.raises(SystemExit):
        parser.parse_args([str(out), "--size", "64by48"])
    assert set(PRESETS) == {"table2", "pillar", "ball", "dragon", "depth-background", "steps", "wall", "hard-cases",
                            "street"}
