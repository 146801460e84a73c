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


def test_folder_key_covers_photos_scene_options_half_size_and_software(root, tmp_path):
    from fitting.folder.resume import folder_key
    folder = tmp_path / "f"
    shutil.copytree(root / "2026-04-21", folder)
    software = {"softshadow": "1", "jax": "1", "optimistix": "1"}
    options = FitOptions(plots=False)
    base = folder_key(folder, options, software)
    assert base == folder_key(folder, FitOptions(plots=True, verbose=True), software)  # display only
    assert base != folder_key(folder, FitOptions(range_k_max=0.05), software)
    assert base != folder_key(folder, options, dict(software, jax="2"))
    assert base != folder_key(folder, options, software, half_size=True)
    scene = (folder / "scene.toml").read_text()
    (folder / "scene.toml").write_text(scene.replace("scale = 1.0", "scale = 1.3"))
    assert folder_key(folder, options, software) != base
    (folder / "scene.toml").write_text(scene)
    assert folder_key(folder, options, software) == base
    photo = next(folder.glob("*.jpg"))
    data = photo.read_bytes()
    photo.write_bytes(data[:-100] + bytes([data[-100] ^ 1]) + data[-99:])  # another file, the same name
    assert folder_key(folder, options, software) != base


def test_recursive_refits_folders_that_changed_since_they_were_done(root, first_run, tmp_path):
    """A folder done before, then edited (its scene.toml's scale, or every photo replaced by a
    gray frame): the same command refits it and says so; an unchanged folder is reused."""
    import numpy as np
    import piexif
    from dask.distributed import LocalCluster
    from PIL import Image
    done_out, table_before = first_run
    edited, out = tmp_path / "root", tmp_path / "out"
    shutil.copytree(root, edited)
    shutil.copytree(done_out, out)
    scene = edited / "2026-04-20" / "a" / "scene.toml"
    scene.write_text(scene.read_text().replace("scale = 1.0", "scale = 1.3"))
    for photo in (edited / "2026-04-21").glob("*.jpg"):
        exif = piexif.dump(piexif.load(str(photo)))
        with Image.open(photo) as im:
            size = im.size
        Image.fromarray(np.full((size[1], size[0], 3), 128, np.uint8)).save(photo, exif=exif, quality=92)
    kept = (out / "2026-04-20" / "b" / "results.json").stat().st_mtime_ns
    notes = []
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                      dashboard_address=None) as cluster:
        table = fit_many(edited, out, scheduler=cluster.scheduler_address, options=FitOptions(plots=False),
                         progress=False, log=notes.append)
    assert notes[0].startswith("2 finished folders changed since their results") and \
        notes[0].endswith("refitted: 2026-04-20/a, 2026-04-21"), notes
    assert (out / "2026-04-20" / "b" / "results.json").stat().st_mtime_ns == kept

    def row(t, name):
        (r,) = t[t["folder"] == name].itertuples()
        return r
    assert row(table, "2026-04-20/b").rho == row(table_before, "2026-04-20/b").rho
    assert row(table, "2026-04-20/a").range_k != row(table_before, "2026-04-20/a").range_k
    gray = row(table, "2026-04-21")
    assert not gray.reliable and gray.rho != row(table_before, "2026-04-21").rho
    # Run again: nothing changed now, nothing is refitted.
    notes.clear()
    again = fit_many(edited, out, options=FitOptions(plots=False), progress=False, log=notes.append)
    assert notes == [] and again["rho"].equals(table["rho"])


_CLUSTER_DRIVER = """
import signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)  # as a shell starts it
import dask.distributed

class Marked(dask.distributed.LocalCluster):
    def __init__(self, *args, **kwargs):
        print("test: cluster starting", file=sys.stderr, flush=True)
        super().__init__(*args, **kwargs)
        print("test: cluster started", file=sys.stderr, flush=True)

dask.distributed.LocalCluster = Marked
from softshadow_cli.main import run
run(sys.argv[1:])
"""


@pytest.mark.parametrize("marker, delay_s", [("test: cluster starting", 1.0), ("test: cluster started", 2.0)])
def test_ctrl_c_to_the_process_group_during_a_recursive_run(root, tmp_path, marker, delay_s):
    """Ctrl-C sent to the whole process group, as a terminal sends it, while the local cluster
    starts or while its two workers fit: one line, exit status 130 within seconds, no traceback
    (the workers ignore it; the command stops them), and no process of the group left."""
    import os
    import signal
    import subprocess
    import sys
    import threading
    import time
    from pathlib import Path
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    cmd = [sys.executable, "-c", _CLUSTER_DRIVER, "fit", str(root), "--out", str(tmp_path / "out"), "--recursive",
           "--workers", "2", "--no-plots"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, start_new_session=True)
    err = bytearray()
    reader = threading.Thread(target=lambda: [err.extend(c) for c in iter(lambda: proc.stderr.read1(4096), b"")],
                              daemon=True)
    reader.start()
    deadline = time.monotonic() + 300
    while marker.encode() not in err and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert marker.encode() in err, err.decode(errors="replace")
    time.sleep(delay_s)
    os.killpg(proc.pid, signal.SIGINT)
    sent = time.monotonic()
    proc.wait(timeout=120)
    waited = time.monotonic() - sent
    reader.join(timeout=10)
    text = err.decode(errors="replace")
    assert proc.returncode == 130, text
    for word in ("Traceback", "Exception ignored", "KeyboardInterrupt", "CancelledError", "ERROR"):
        assert word not in text, text
    lines = [ln for ln in text.replace("\r", "\n").splitlines()
             if ln.strip() and not ln.startswith(("test: ", "folders:"))]
    assert len(lines) == 1 and lines[0].startswith("softshadow fit: interrupted: "), text
    assert waited < 10, waited  # the cluster's start, when it lands there, included
    gone = time.monotonic() + 10
    while time.monotonic() < gone:
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.2)
    else:
        pytest.fail("worker processes of the interrupted run are still alive")
