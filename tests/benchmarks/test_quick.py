"""Every benchmark runs in quick mode and reports rows of the documented shape (guards against rot; the
figures themselves come from ``make bench``, never from timed unit tests)."""

import math

import pytest

from benchmarks.__main__ import discover

KEYS = {"name", "value", "unit", "baseline_name", "baseline_value", "ratio", "target", "ok"}


#: benchmarks that start no device (pure computation, files, or a Dask cluster): the parallel part of make test;
#: the others start a device and are marked realtime
DEVICE_FREE = {"bench_afrf", "bench_campaign", "bench_identification", "bench_long_run", "bench_plant",
               "bench_residual", "bench_results_table", "bench_runfile", "bench_skeleton"}


@pytest.mark.parametrize("name", [n if n in DEVICE_FREE else pytest.param(n, marks=pytest.mark.realtime)
                                  for n in discover()])
def test_benchmark_runs_quick_and_reports_ratios(name):
    import importlib

    rows = importlib.import_module(f"benchmarks.{name}").run(quick=True)
    assert rows, f"{name} reported nothing"
    for row in rows:
        assert KEYS <= set(row), (name, set(row))
        assert isinstance(row["value"], (int, float)) and math.isfinite(row["value"]), row
        if row["baseline_value"] is not None and row["baseline_value"] != 0 and row["ratio"] is not None:
            assert row["ratio"] == pytest.approx(row["value"] / row["baseline_value"], rel=1e-9), row
