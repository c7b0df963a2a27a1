"""A sweep's results on disk: two Parquet datasets partitioned by scenario, written atomically.

::

    OUT/summary.parquet/scenario_id=s1a2b3c4d5e6/part-0.parquet   one row per scenario
    OUT/steps.parquet/scenario_id=s1a2b3c4d5e6/part-0.parquet     one row per step and generator

``pandas.read_parquet(OUT / "summary.parquet")`` and ``dask.dataframe.read_parquet`` read each
folder as one table (hive partitioning adds ``scenario_id``). A scenario's files are written
under a hidden temporary name in their partition folder and renamed into place (readers skip
names starting with ``.``), the steps before the summary: a summary file is the mark of a
finished scenario, so a sweep killed at any moment leaves only complete scenarios and a rerun
(:func:`finished_ids`) skips them. Fixed schemas (:data:`SUMMARY_SCHEMA`, :data:`STEPS_SCHEMA`)
keep every partition alike, whatever a scenario leaves null.
"""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from popdispatch.report.output import atomic_write

SUMMARY, STEPS = "summary.parquet", "steps.parquet"
PART = "part-0.parquet"
PARTITION = "scenario_id"
#: A finished scenario's status when it raised (the others are the ``day`` statuses).
FAILED = "failed"

_I32, _F64, _STR = pa.int32(), pa.float64(), pa.string()
_TIME = pa.timestamp("us", tz="UTC")

#: One row per scenario: its parameters, the ``day`` summary's keys (nested ones as JSON text,
#: ``*_json``; deprecated unit-less twins left out) and how it ran.
SUMMARY_SCHEMA = pa.schema(
    [
        ("scenario_index", _I32),
        ("case", _STR),
        ("steps", _STR),
        ("mode", _STR),
        ("dynamics", _STR),
        ("graph", _STR),
        ("x0", _STR),
        ("warm_start", _STR),
        ("limits", _STR),
        ("events", _STR),
        ("assignment", _STR),
        ("profile_numbers", pa.list_(pa.int16())),
        ("status", _STR),
        ("error", _STR),
        ("profile_source", _STR),
        ("minutes", _I32),
        ("first_minute", _I32),
        ("last_minute", _I32),
        ("compared_minutes", _I32),
        ("converged_minutes", _I32),
        ("minutes_within_0_1_kw", _I32),
        ("infeasible_minutes", pa.list_(_I32)),
        ("price_runaway_minutes", pa.list_(_I32)),
        ("stalled_minutes", pa.list_(_I32)),
        ("max_abs_error_kw", _F64),
        ("mean_abs_error_kw", _F64),
        ("median_max_abs_error_kw", _F64),
        ("cost_eur", _F64),
        ("opf_cost_eur", _F64),
        ("cost_gap_eur", _F64),
        ("cost_all_minutes_eur", _F64),
        ("minutes_outside_limits", _I32),
        ("max_outside_limits_kw", _F64),
        ("max_overflow_kw", _F64),
        ("mean_iterations", _F64),
        ("max_iterations", _I32),
        ("energy_kwh_json", _STR),
        ("opf_energy_kwh_json", _STR),
        ("energy_all_minutes_kwh_json", _STR),
        ("minutes_outside_limits_by_generator_json", _STR),
        ("wall_seconds", _F64),
        ("scenario_seconds", _F64),
        ("worker", _STR),
        ("started_at", _TIME),
        ("finished_at", _TIME),
    ]
)

#: One row per step and generator (the ``day.csv`` columns in long form).
STEPS_SCHEMA = pa.schema(
    [
        ("minute", _I32),
        ("generator", _STR),
        ("bus", _I32),
        ("setpoint_kw", _F64),
        ("opf_kw", _F64),
        ("abs_error_kw", _F64),
        ("demand_kw", _F64),
        ("max_abs_error_kw", _F64),
        ("status", _STR),
        ("opf_feasible", pa.bool_()),
        ("converged", pa.bool_()),
        ("outside_limits", pa.bool_()),
        ("iterations", _I32),
        ("cost_eur_per_h", _F64),
        ("opf_cost_eur_per_h", _F64),
        ("max_overflow_kw", _F64),
    ]
)


def partition(out: Path, table: str, scenario_id: str) -> Path:
    return Path(out) / table / f"{PARTITION}={scenario_id}"


def _write(table: pa.Table, folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write(folder / PART, lambda tmp: pq.write_table(table, tmp))


def write_scenario(out: Path, scenario_id: str, summary: dict, steps=None) -> None:
    """Write one scenario: its steps (a DataFrame in :data:`STEPS_SCHEMA`'s columns, or None)
    then its summary row (a dict, :data:`SUMMARY_SCHEMA`; missing keys are null)."""
    if steps is not None:
        table = pa.Table.from_pandas(steps, schema=STEPS_SCHEMA, preserve_index=False)
        _write(table, partition(out, STEPS, scenario_id))
    row = pa.Table.from_pylist([summary], schema=SUMMARY_SCHEMA)
    _write(row, partition(out, SUMMARY, scenario_id))


def status_of(out: Path, scenario_id: str) -> str | None:
    """The recorded status of one scenario, None if it has no summary yet."""
    part = partition(out, SUMMARY, scenario_id) / PART
    if not part.is_file():
        return None
    return pq.read_table(part, columns=["status"])["status"][0].as_py()


def finished_ids(out: Path, retry_failed: bool = True) -> set[str]:
    """Ids of the scenarios already written in ``out`` (``retry_failed``: not those that
    failed, so a rerun runs them again)."""
    root = Path(out) / SUMMARY
    if not root.is_dir():
        return set()
    done = set()
    for folder in root.glob(f"{PARTITION}=*"):
        part = folder / PART
        if not part.is_file():
            continue
        if retry_failed and status_of(out, folder.name.partition("=")[2]) == FAILED:
            continue
        done.add(folder.name.partition("=")[2])
    return done


def read_summary(out: Path):
    """The summary table as a pandas DataFrame (one row per finished scenario), in the
    spec's order."""
    import pandas as pd

    from popdispatch.errors import OptionError

    if not any((Path(out) / SUMMARY).glob(f"{PARTITION}=*/{PART}")):
        raise OptionError(f"no sweep results in {out} ({SUMMARY} missing or empty)", "DIR")
    table = pd.read_parquet(Path(out) / SUMMARY)
    table[PARTITION] = table[PARTITION].astype(str)
    return table.sort_values("scenario_index", kind="stable").reset_index(drop=True)
