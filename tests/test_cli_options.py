"""Every option of ``softshadow render`` and ``softshadow fit`` is checked before any work: a value out
of its range is one line naming the option, exit status 2, and nothing is read, rendered, fitted or
written (softshadow_cli/validate.py)."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

SCENE = """
[object]
mesh = "pillar"

[camera]
kind = "topdown"
pixel_m = 0.01
origin_m = [-1.0, 1.0]

[photos."a.jpg"]
sun_azimuth_deg = 120.0
sun_elevation_deg = 40.0
"""


@pytest.fixture
def cli(monkeypatch, capsys):
    """main(argv) -> (status, stderr), with work that must not happen made to fail loudly."""
    main = importlib.import_module("softshadow_cli.main")
    monkeypatch.setattr(main, "_use_compilation_cache", lambda: None)
    import fitting
    import softshadow_cli.render_command as render_command

    def no_work(*args, **kwargs):
        raise AssertionError("work started before the options were checked")

    monkeypatch.setattr(fitting, "fit_and_report", no_work)
    monkeypatch.setattr(fitting, "fit_many", no_work)
    monkeypatch.setattr(render_command.SoftShadowModel, "from_mesh", no_work)

    def run(argv):
        code = main.main(argv)
        return code, capsys.readouterr().err
    return run


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture
def scene(tmp_path) -> Path:
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    return path


@pytest.mark.parametrize("extra, words", [
    (["--k", "-0.01"], "--k must be in [0, 1], got -0.01"),
    (["--k", "nan"], "--k must be a finite number"),
    (["--rho", "2"], "--rho must be in (0, 1], got 2"),
    (["--rho", "0"], "--rho must be in (0, 1], got 0"),
    (["--k", "-0.01", "--rho", "2"], "--k must be"),
    (["--range", "-1"], "--range must be in [0, 100], got -1 (paper units, 100 k)"),
    (["--brightness", "300"], "--brightness must be in (0, 255], got 300"),
    (["--sun-elevation", "95", "--sun-azimuth", "10"], "--sun-elevation must be in (0, 90], got 95"),
    (["--sun-elevation", "-5", "--sun-azimuth", "10"], "--sun-elevation must be in (0, 90], got -5"),
    (["--size", "0x0"], "--size must be from 1x1 to"),
    (["--size", "640"], "--size must look like 640x480"),
    (["--pixel-m", "0"], "--pixel-m must be > 0, got 0"),
    (["--supersample", "0"], "--supersample must be from 1 to 16, got 0"),
    (["--exposure", "-1"], "--exposure must be > 0, got -1"),
    (["--ambient", "-0.1"], "--ambient must be >= 0, got -0.1"),
    (["--camera-fov", "180"], "--camera-fov must be in (0, 180)"),
    (["--projector-fov", "0"], "--projector-fov must be in (0, 170)"),
    (["--camera-position", "1,2"], "--camera-position must be three numbers X,Y,Z"),
])
def test_render_refuses_values_out_of_range(cli, scene, tmp_path, extra, words):
    out = tmp_path / "x.png"
    code, err = cli(["render", "--scene", str(scene), "--out", str(out)] + extra)
    line = _one_line(err)
    assert code == 2 and line.startswith("softshadow render: ") and words in line, line
    assert not out.exists()


@pytest.mark.parametrize("out, npy, words", [
    ("missing_dir/x.png", None, "the folder {tmp}/missing_dir does not exist"),
    ("x.txt", None, "must end in one of"),
    (".", None, "is a folder; give a file name"),
    ("x.png", "missing_dir/x.npy", "--npy {tmp}/missing_dir/x.npy: the folder"),
    ("x.png", "x.bin", "--npy {tmp}/x.bin must end in one of .npy"),
])
def test_render_checks_its_output_files_before_rendering(cli, scene, tmp_path, out, npy, words):
    argv = ["render", "--scene", str(scene), "--out", str(tmp_path / out)]
    if npy:
        argv += ["--npy", str(tmp_path / npy)]
    code, err = cli(argv)
    line = _one_line(err)
    assert code == 2 and words.format(tmp=tmp_path) in line, line


def test_render_names_a_photo_that_is_not_in_the_scene(cli, scene, tmp_path):
    code, err = cli(["render", "--scene", str(scene), "--out", str(tmp_path / "x.png"), "--photo", "A.jpg"])
    line = _one_line(err)
    assert code == 2 and "--photo 'A.jpg' is not a [photos] entry" in line and "did you mean 'a.jpg'?" in line


def test_render_of_valid_options_writes_the_image(scene, tmp_path, monkeypatch, capsys):
    main = importlib.import_module("softshadow_cli.main")
    monkeypatch.setattr(main, "_use_compilation_cache", lambda: None)
    out = tmp_path / "x.png"
    code = main.main(["render", "--scene", str(scene), "--out", str(out), "--size", "32x24", "--k", "0",
                      "--rho", "1"])
    assert code == 0 and out.stat().st_size > 0, capsys.readouterr().err


@pytest.mark.parametrize("extra, words", [
    (["--range-k-max", "-1"], "--range-k-max must be in (0, 1], got -1"),
    (["--range-k-max", "0"], "--range-k-max must be in (0, 1], got 0"),
    (["--range-k-max", "inf"], "--range-k-max must be a finite number"),
    (["--jobs", "0"], "--jobs must be from 1 to 64, got 0"),
    (["--lod-tolerance", "-1"], "--lod-tolerance must be >= 0, got -1"),
    (["--lod", "off", "--lod-tolerance", "0.2"], "--lod-tolerance goes with --lod auto, not --lod off"),
    (["--no-plots", "--overlays", "all"], "--overlays chooses plots; it does not go with --no-plots"),
    (["--workers", "2"], "--scheduler and --workers go with --recursive"),
    (["--recursive", "--workers", "0"], "--workers must be from 1 to 1024, got 0"),
])
def test_fit_refuses_options_before_reading_the_folder(cli, tmp_path, extra, words):
    out = tmp_path / "out"
    code, err = cli(["fit", str(tmp_path), "--out", str(out)] + extra)
    line = _one_line(err)
    assert code == 2 and line.startswith("softshadow fit: ") and words in line, line
    assert not out.exists()


def test_fit_refuses_a_file_where_the_groups_or_the_summary_go(cli, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "groups").write_text("not a folder")
    code, err = cli(["fit", str(tmp_path), "--out", str(out)])
    assert code == 2 and "holds a file named groups where the finished groups are kept" in _one_line(err)
    (out / "summary.csv").mkdir()
    code, err = cli(["fit", str(tmp_path), "--out", str(out), "--recursive"])
    assert code == 2 and "holds a folder named summary.csv" in _one_line(err)


def test_fit_passes_half_size_and_jobs_to_every_folder(monkeypatch, tmp_path, capsys):
    """--half-size and --jobs are not dropped with --recursive."""
    import pandas as pd

    import fitting
    from fitting import SUMMARY_COLUMNS
    from softshadow_cli.main import main
    seen = {}

    def fake_fit_many(root, out, **kwargs):
        seen.update(kwargs)
        return pd.DataFrame([dict.fromkeys(SUMMARY_COLUMNS)], columns=list(SUMMARY_COLUMNS))

    monkeypatch.setattr(fitting, "fit_many", fake_fit_many)
    main(["fit", str(tmp_path), "--out", str(tmp_path / "out"), "--recursive", "--half-size", "--jobs", "2"])
    assert seen["half_size"] is True and seen["jobs"] == 2


@pytest.mark.parametrize("argv, words", [
    (["synth", "{tmp}/s", "--seed", "-1"], "softshadow synth: --seed must be a whole number >= 0, got -1"),
    (["synth", "{tmp}/s", "--quality", "0"], "softshadow synth: --quality must be from 1 to 100, got 0"),
    (["synth", "{tmp}/file/s"], "softshadow synth: OUT_DIR {tmp}/file/s cannot be created: {tmp}/file is a file"),
    (["demo", "--out", "{tmp}/d", "--seed", "-2"], "softshadow demo: --seed must be a whole number >= 0, got -2"),
    (["demo", "--out", "{tmp}/d", "--size", "0x0"], "softshadow demo: --size: size must be at least 16x16"),
    (["demo", "--out", "{tmp}/file"], "softshadow demo: --out {tmp}/file is a file, not a folder"),
    (["board", "{tmp}/b.pdf", "--dpi", "inf"], "softshadow board: --dpi must be a finite number"),
    (["board", "{tmp}/b.pdf", "--dpi", "100000"], "softshadow board: --dpi must be in [10, 2400], got 100000"),
    # The bench makes a missing folder for its outputs (docs/ of a fresh checkout), not one under a file.
    (["bench", "--json", "{tmp}/file/x.json"], "softshadow bench: --json {tmp}/file is a file, not a folder"),
    (["bench", "--report", "{tmp}/file/x.md"], "softshadow bench: --report {tmp}/file is a file, not a folder"),
])
def test_synth_demo_board_and_bench_check_their_options_first(cli, tmp_path, argv, words):
    (tmp_path / "file").write_text("a file")
    code, err = cli([a.format(tmp=tmp_path) for a in argv])
    line = _one_line(err)
    assert code == 2 and line.startswith(words.format(tmp=tmp_path)), line
    assert not any((tmp_path / n).exists() for n in ("s", "d", "b.pdf"))
