"""Many folders on Dask (``fitting.fit_many``, ``softshadow fit ROOT --recursive``).

Four small folders (three model-rendered pillar folders and a broken one) on a local
cluster of two worker processes; then a run interrupted half-way resumes on an existing
cluster (its scheduler address), through the command line, refitting only what was not
done.
"""

from __future__ import annotations

import json
import shutil

import pandas as pd
import pytest

from fitting import DONE_MARKER, SUMMARY_COLUMNS, FitOptions, find_photo_folders, fit_many

CONTRACT = ["folder", "label", "time", "range_k", "range_stderr", "rho", "rho_stderr",
            "sun_azimuth_deg", "sun_elevation_deg", "reliable", "photos"]
GOOD = ["2026-04-20/a", "2026-04-20/b", "2026-04-21"]


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    """ROOT/2026-04-20/{a,b}, ROOT/2026-04-21 (synthetic, 160x120) and ROOT/broken."""
    from data_synth import synthesize
    base = tmp_path_factory.mktemp("many") / "root"
    for seed, name in enumerate(GOOD):
        synthesize(base / name, preset="pillar", seed=seed, renderer="model", size=(160, 120),
                   progress=False)
    (base / "broken").mkdir()
    (base / "broken" / "IMG_0001.jpg").write_text("not a JPEG")
    (base / "2026-04-20" / "notes.txt").write_text("a folder without photos is not fitted")
    return base


@pytest.fixture(scope="module")
def first_run(root, tmp_path_factory):
    """fit_many on a local cluster of two workers (the Python API)."""
    out = tmp_path_factory.mktemp("many_out") / "out"
    notes = []
    table = fit_many(root, out, scheduler="local", workers=2, options=FitOptions(plots=False),
                     progress=False, log=notes.append)
    return out, table


def test_finds_the_photo_folders_and_not_the_output(root, tmp_path):
    out = root / "out-inside"
    (out / "x").mkdir(parents=True)
    shutil.copy(root / "2026-04-21" / "IMG_0001.jpg", out / "x")
    names = [p.relative_to(root).as_posix() for p in find_photo_folders(root, exclude=out)]
    shutil.rmtree(out)
    assert names == sorted(GOOD + ["broken"])


def test_two_workers_fit_the_good_folders_and_record_the_broken_one(root, first_run):
    out, table = first_run
    truth = {name: json.loads((root / name / "truth.json").read_text())["groups"][0] for name in GOOD}
    assert list(table.columns) == list(SUMMARY_COLUMNS)
    assert list(SUMMARY_COLUMNS[:len(CONTRACT)]) == CONTRACT and SUMMARY_COLUMNS[-1] == "error"
    assert sorted(table["folder"]) == sorted(GOOD + ["broken"])
    for name in GOOD:
        (row,) = table[table["folder"] == name].itertuples()
        assert pd.isna(row.error), row.error
        assert abs(row.rho - truth[name]["rho"]) < 0.08
        assert 0 < row.range_k < 0.03 and row.range_stderr > 0
        assert row.photos == ";".join(truth[name]["photos"])
        assert (out / name / "results.json").exists() and (out / name / DONE_MARKER).exists()
    (broken,) = table[table["folder"] == "broken"].itertuples()
    assert "no readable photo" in broken.error and "broken" in broken.error
    assert not broken.reliable and pd.isna(broken.rho)
    assert not (out / "broken" / DONE_MARKER).exists()  # a failed folder is tried again next time
    on_disk = pd.read_csv(out / "summary.csv")
    assert list(on_disk.columns) == list(SUMMARY_COLUMNS)
    assert sorted(on_disk["folder"]) == sorted(table["folder"])


def test_a_failed_group_is_never_reliable_in_the_summary():
    from fitting import GroupResult
    from fitting.folder.many import folder_rows
    failed = GroupResult.failed("13:21", "13:21", ["a.jpg"], "fit failed: boom").to_json()
    # results.json written before a failed group was unreliable said reliable beside its error.
    old = dict(failed, reliable=True, identifiable=True)
    fitted = GroupResult.from_json({"label": "09:20", "time": "09:20", "photos": ["b.jpg"], "rho": 0.2}).to_json()
    rows = folder_rows("f", [failed, old, fitted])
    assert [r["reliable"] for r in rows] == [False, False, True]
    assert [r["error"] for r in rows] == ["fit failed: boom", "fit failed: boom", None]


def test_summary_plot_is_written(first_run):
    out, _ = first_run
    png = out / "summary.png"
    assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert png.stat().st_size > 10_000  # axes, three folders' points and a legend


def test_interrupted_run_resumes_on_an_existing_cluster_from_the_cli(root, first_run, tmp_path):
    from dask.distributed import LocalCluster

    from softshadow_cli.main import main
    done_out, _ = first_run
    out = tmp_path / "out"
    shutil.copytree(done_out, out)
    # Interrupted while fitting 2026-04-21: its group was kept, its report and marker not yet.
    (out / "2026-04-21" / DONE_MARKER).unlink()
    (out / "2026-04-21" / "results.json").unlink()
    kept = {name: (out / name / "results.json").stat().st_mtime_ns for name in GOOD[:2]}
    group_file = next((out / "2026-04-21" / "groups").glob("*.json"))
    group_before = json.loads(group_file.read_text())
    # An existing cluster reached by its tcp:// address (its worker a thread here, to start fast).
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                      dashboard_address=None) as cluster:
        code = main(["fit", str(root), "--out", str(out), "--recursive", "--no-plots",
                     "--scheduler", cluster.scheduler_address])
    assert code == 0
    for name, mtime in kept.items():  # done folders were not refitted (nor rewritten)
        assert (out / name / "results.json").stat().st_mtime_ns == mtime
    assert (out / "2026-04-21" / "results.json").exists() and (out / "2026-04-21" / DONE_MARKER).exists()
    # Its finished group was reused, not refitted: a refit would differ (in its seconds at least).
    assert json.loads(group_file.read_text()) == group_before
    assert json.loads((out / "2026-04-21" / "results.json").read_text())["groups"][0]["seconds"] == \
        group_before["group"]["seconds"]
    table = pd.read_csv(out / "summary.csv")
    assert sorted(table["folder"]) == sorted(GOOD + ["broken"])
    assert table[table["folder"] != "broken"]["rho"].notna().all()
    assert "no readable photo" in table[table["folder"] == "broken"]["error"].item()


def test_cli_refuses_scheduler_without_recursive_and_an_empty_root(tmp_path, capsys):
    from softshadow_cli.main import main
    assert main(["fit", str(tmp_path), "--out", str(tmp_path / "o"), "--workers", "2"]) == 2
    assert "--recursive" in capsys.readouterr().err
    assert main(["fit", str(tmp_path), "--out", str(tmp_path / "o"), "--recursive"]) == 1
    err = capsys.readouterr().err
    assert "no folder under" in err and "Traceback" not in err
    assert main(["fit", str(tmp_path), "--out", str(tmp_path / "o"), "--recursive",
                 "--scheduler", "localhost:8786"]) == 1
    assert "tcp://" in capsys.readouterr().err
