"""The command line's conventions: every option has help and shows its default, ``python -m softshadow``
works, and ``softshadow bench`` prints tables (the JSON with --json)."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from softshadow_cli.main import build_parser, main


def _subparsers():
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


@pytest.mark.parametrize("command", ["render", "fit", "synth", "demo", "board", "bench"])
def test_every_option_has_help_and_its_default(command):
    parser = _subparsers()[command]
    text = parser.format_help()
    for action in parser._actions:
        if action.help == argparse.SUPPRESS or isinstance(action, argparse._HelpAction):
            continue
        assert action.help, f"softshadow {command} {'/'.join(action.option_strings) or action.dest} has no help"
        if (action.option_strings and action.default not in (None, False)
                and not isinstance(action.default, bool)):
            shown = parser._get_formatter()._get_help_string(action) % {"default": action.default}
            assert "default" in shown, f"softshadow {command} {action.option_strings} hides its default"
    assert "usage: softshadow" in text


def test_python_dash_m_softshadow():
    out = subprocess.run([sys.executable, "-m", "softshadow", "--help"], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert "Measure outdoor soft shadows" in out.stdout and "layer above" not in out.stdout


def test_bench_tables_from_a_result():
    from benchmarks.output import format_tables
    result = {"environment": {"machine": "x", "load_average": [0.5, 0.4, 0.3]},
              "summary": [{"mesh": "pillar", "renderer": "softshadow", "median_ms": 4.25, "rms_band": 0.0118},
                          {"mesh": "dragon", "renderer": "mitsuba-64spp", "median_ms": 1700.0, "rms_band": 0.034}],
              "render": {"ground_512": {"median_ms": 7.0, "faces": 176}}}
    text = format_tables(result)
    lines = text.splitlines()
    assert lines[0].startswith("environment: machine x")
    assert "summary" in lines and "render.ground_512" in lines
    header = lines[lines.index("summary") + 1].split()
    assert header == ["mesh", "renderer", "median_ms", "rms_band"]
    assert "0.0118" in text and "1700" in text and "mitsuba-64spp" in text


def test_bench_prints_tables_and_writes_json(tmp_path, capsys):
    import json
    out = tmp_path / "b.json"
    assert main(["bench", "--what", "precision", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "shadow_map_precision" in printed and not printed.lstrip().startswith("{")
    assert "shadow_map_precision" in json.loads(out.read_text())
