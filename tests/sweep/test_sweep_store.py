"""Parquet datasets: fixed schemas, atomic partitions, what counts as finished; read back with
pandas and Dask."""

from __future__ import annotations

from datetime import UTC, datetime

import dask.dataframe as dd
import numpy as np
import pandas as pd

from popdispatch.sweep import store


def _steps() -> pd.DataFrame:
    """Three steps of one generator, every column of the schema (the last minute infeasible)."""
    table = pd.DataFrame({"minute": [1, 2, 3], "generator": "G1", "bus": 1})
    table["setpoint_kw"] = [1.0, 2.0, 3.0]
    table["opf_kw"] = [1.0, 2.5, np.nan]
    for name in store.STEPS_SCHEMA.names[5:]:
        kind = store.STEPS_SCHEMA.field(name).type
        table[name] = "converged" if kind == "string" else (True if kind == "bool" else 0)
    return table


def test_partitions_read_back_with_pandas_and_dask(tmp_path):
    now = datetime.now(UTC)
    row = {"status": "converged", "max_abs_error_kw": 0.5, "scenario_index": 0, "started_at": now}
    store.write_scenario(tmp_path, "sa", row, _steps())
    store.write_scenario(tmp_path, "sb", {"status": "failed", "error": "E: x", "scenario_index": 1})
    summary = store.read_summary(tmp_path)
    assert list(summary.scenario_id) == ["sa", "sb"]
    assert summary.max_abs_error_kw.iloc[0] == 0.5 and np.isnan(summary.max_abs_error_kw.iloc[1])
    assert summary.error.iloc[1] == "E: x"
    assert set(store.SUMMARY_SCHEMA.names) <= set(summary.columns)
    steps = pd.read_parquet(tmp_path / store.STEPS)
    assert len(steps) == 3 and set(steps.scenario_id.astype(str)) == {"sa"}
    lazy = dd.read_parquet(tmp_path / store.SUMMARY)
    assert sorted(lazy.compute().status) == ["converged", "failed"]
    assert dd.read_parquet(tmp_path / store.STEPS).setpoint_kw.sum().compute() == 6.0


def test_finished_skips_failed_and_ignores_half_written(tmp_path):
    store.write_scenario(tmp_path, "sa", {"status": "converged"}, _steps())
    store.write_scenario(tmp_path, "sb", {"status": "failed", "error": "E: x"})
    # a worker killed while writing leaves a hidden temporary file and no part file
    half = store.partition(tmp_path, store.SUMMARY, "sc")
    half.mkdir(parents=True)
    (half / ".part-0.parquet.abc.tmp.parquet").write_bytes(b"PAR1 truncated")
    assert store.finished_ids(tmp_path) == {"sa"}
    assert store.finished_ids(tmp_path, retry_failed=False) == {"sa", "sb"}
    assert len(store.read_summary(tmp_path)) == 2  # readers skip the hidden file
