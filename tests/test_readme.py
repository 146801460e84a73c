"""Every code block of the README runs as written: the shell commands (but the two `pip install` set-up
lines, which CI itself runs), the Python snippets and the scene.toml snippet. ``my_photos`` stands for the
user's own photos: a small synthetic folder with explicit cameras."""

from __future__ import annotations

import re
import shlex
import shutil
import tomllib
from pathlib import Path

import pytest

from softshadow_cli.main import main

ROOT = Path(__file__).resolve().parents[1]


def _blocks(language: str) -> list[str]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    return [textwrap_dedent(b) for b in re.findall(rf"```{language}\n(.*?)```", text, re.S)]


def textwrap_dedent(block: str) -> str:
    import textwrap
    return textwrap.dedent(block)


@pytest.fixture(scope="module")
def user_folder(tmp_path_factory):
    """A working folder as a user's: the checkout's examples/ and a folder of photos, my_photos."""
    from data_synth import synthesize
    cwd = tmp_path_factory.mktemp("readme")
    shutil.copytree(ROOT / "examples", cwd / "examples", ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    synthesize(cwd / "my_photos", preset="table2", seed=1, size=(400, 300), progress=False)
    return cwd


def test_readme_has_the_two_commands():
    commands = [line for b in _blocks("bash") for line in b.splitlines()]
    assert "pip install . && softshadow demo" in commands
    assert "pip install -e '.[test]' && python -m pytest -q" in commands
    assert len((ROOT / "README.md").read_text().splitlines()) <= 150


def test_readme_shell_commands_run(user_folder, monkeypatch, capsys):
    monkeypatch.chdir(user_folder)
    ran = []
    for block in _blocks("bash"):
        for line in block.splitlines():
            for command in (c.strip() for c in line.split("&&")):
                if not command or command.startswith("pip install"):
                    continue
                argv = shlex.split(command)
                if argv[0] == "python":  # the test command itself
                    continue
                assert argv[0] == "softshadow", command
                assert main(argv[1:]) == 0, f"{command}: {capsys.readouterr()}"
                ran.append(argv[1])
    assert {"demo", "render", "board", "fit"} <= set(ran)
    out = capsys.readouterr().out
    assert "verdict: k and ρ within two stated errors of the truth in" in out
    assert (user_folder / "softshadow-demo" / "fit" / "index.html").exists()
    assert (user_folder / "my_results" / "index.html").exists() and (user_folder / "model.png").exists()


def test_readme_python_snippets_run(user_folder, monkeypatch):
    monkeypatch.chdir(user_folder)
    blocks = _blocks("python")
    assert len(blocks) >= 2
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {})


def test_readme_scene_toml_reads():
    from scene import scene_from_dict
    (block,) = _blocks("toml")
    scene = scene_from_dict(tomllib.loads(block))
    assert scene.object.mesh == "pillar" and scene.camera.kind == "markers" and scene.site is not None
