"""``softshadow bench --what scene --json F``: the file's rows (the full dragon and its levels at
640 x 480, their frame times, the level drawn), with the levels cut to one and few frames.
Timings are not checked (the machine is shared)."""

from __future__ import annotations

import json

import numpy as np

from softshadow_cli.main import main


def test_scene_bench_writes_a_row_per_level(tmp_path, monkeypatch, capsys):
    from benchmarks import scene

    monkeypatch.setattr(scene, "SCENE_LEVELS", (300,))
    out = tmp_path / "scene.json"
    assert main(["bench", "--what", "scene", "--quick", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    rows = result["scene"]
    assert [r["level"] for r in rows] == [41384, 300]
    for row in rows:
        assert row["faces"] == 41384 and (row["width"], row["height"]) == (640, 480)
        for key in ("frame_ms", "frame_ms_one_thread", "frame_ms_projector_moves", "frame_ms_camera_moves"):
            assert 0 < row[key.replace("frame_ms", "frame_min_ms")] <= row[key] <= \
                row[key.replace("frame_ms", "frame_max_ms")], key
        assert set(row["steps_ms"]) == {"visibility", "sun_plan", "sun_band", "shading"}
    summary = result["summary"]
    assert summary["full_frame_ms"] == rows[0]["frame_ms"] and summary["coarsest_level"] == 300
    assert summary["coarsest_over_full"] == round(rows[1]["frame_ms"] / rows[0]["frame_ms"], 3)
    interleaved = result["settings"]["interleaved_frames"]
    for row in rows:  # a median per round of the interleaved timing
        assert len(row["frame_ms_rounds"]) == interleaved // result["settings"]["block"]
        assert min(row["frame_ms_rounds"]) <= row["frame_ms"] <= max(row["frame_ms_rounds"])
    assert summary["coarsest_over_full_rounds"] == [round(c / f, 3) for c, f in
                                                    zip(rows[1]["frame_ms_rounds"], rows[0]["frame_ms_rounds"])]
    # What the machine gave of a second core, after each round: a time ratio, about 1 to 2.
    assert len(summary["two_thread_slowdown_rounds"]) == interleaved // result["settings"]["block"]
    assert all(0.5 < x < 10 for x in summary["two_thread_slowdown_rounds"])
    assert summary["two_thread_slowdown"] == round(float(np.median(summary["two_thread_slowdown_rounds"])), 2)
    assert summary["warnings"] == scene.machine_warnings(summary["two_thread_slowdown_rounds"]) \
        + scene.spell_warnings(rows[1]["frame_ms_rounds"])
    assert result["render_scene_ms"] > 0
    assert "scene" in capsys.readouterr().out  # the tables on stdout


def test_scene_bench_says_when_the_machine_gave_one_core():
    """The bench's warnings from the core probe: none with two cores free, one naming the rounds
    (or the whole run) with about one core's worth."""
    from benchmarks.scene import machine_warnings

    assert machine_warnings([1.04, 1.1, 1.3, 1.06]) == []
    [some] = machine_warnings([1.04, 2.0, 1.1, 1.06])
    assert "1 of 4 rounds" in some
    [whole] = machine_warnings([2.0, 1.98, 1.1, 2.02])
    assert "about one core's worth (two_thread_slowdown 1.99" in whole


def test_scene_bench_says_when_a_slow_spell_covered_many_rounds():
    """A slow spell (rounds of the coarsest level over SLOW_ROUND times its lower quartile) is named when it
    covers a quarter of the rounds or more, not for a round or two."""
    from benchmarks.scene import spell_warnings

    assert spell_warnings([9.0, 9.2, 9.1, 13.5, 9.0, 9.3, 9.1, 9.2]) == []
    [spell] = spell_warnings([9.0, 13.2, 14.0, 9.1, 9.0, 9.3, 13.8, 9.2])
    assert spell.startswith("3 of 8 rounds were slow")
