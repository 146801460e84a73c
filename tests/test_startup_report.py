"""``bench --what startup``'s page is made from its JSON alone: runs, medians and the API / CLI ratio."""

from benchmarks.startup import write_startup_report


def _result():
    runs = {"cli": [{"wall_s": 8.0, "cpu_s": 9.0, "load_before": 0.5}, {"wall_s": 8.4, "cpu_s": 9.2, "load_before": 0.6}],
            "api": [{"wall_s": 8.2, "cpu_s": 9.1, "load_before": 0.5}, {"wall_s": 8.6, "cpu_s": 9.3, "load_before": 0.7}]}
    startup = {k: {"runs": r, "median_wall_s": sum(x["wall_s"] for x in r) / 2,
                   "median_cpu_s": sum(x["cpu_s"] for x in r) / 2} for k, r in runs.items()}
    startup.update(api_over_cli_wall=1.02, api_over_cli_cpu=1.01)
    env = {"date_utc": "D", "run_minutes": 1.5, "load_average_at_end": [0.4, 0.5, 0.6],
           "machine": {"cpu": "CPU", "cores": 2, "memory_gb": 8.0, "platform": "P",
                       "load_average_1_5_15_min": [0.5, 0.5, 0.5]}}
    return {"environment": env, "startup": startup}


def test_startup_page_shows_each_run_the_medians_and_the_ratio(tmp_path):
    page = tmp_path / "docs" / "startup.md"
    write_startup_report(_result(), page, "startup.json")
    text = page.read_text()
    assert "| 1 | 8.00 / 9.00 | 8.20 / 9.10 | 0.5, 0.5 |" in text
    assert "| 2 | 8.40 / 9.20 | 8.60 / 9.30 | 0.6, 0.7 |" in text
    assert "| median | 8.20 / 9.10 | 8.40 / 9.20 | |" in text
    assert "1.02x in wall time, 1.01x in CPU" in text
    assert "[startup.json](startup.json)" in text and "Date: D" in text
