"""Scenario sweeps: many online days against the DC-OPF from one TOML spec, on Dask, with
results in Parquet, resumable (``popdispatch sweep``; see docs/sweeps.md).

- :mod:`~popdispatch.sweep.spec`: parse, validate and expand a spec into scenarios (stable ids);
- :mod:`~popdispatch.sweep.assign`: the official profiles assigned to the loads by seed;
- :mod:`~popdispatch.sweep.scenario`: one scenario's run and its result rows;
- :mod:`~popdispatch.sweep.store`: the Parquet datasets, atomic writes, what is finished;
- :mod:`~popdispatch.sweep.execute`: running on a Dask cluster with a progress bar;
- :mod:`~popdispatch.sweep.report`: the summary as a table and figures.

Dask and pyarrow are the optional ``sweep`` extra: this package imports them only where used.
"""

from __future__ import annotations

from pathlib import Path

from popdispatch.sweep.spec import Scenario, StepRange, SweepSpec, load_spec, parse_spec


def run(spec: str | Path | dict | SweepSpec | list[Scenario], out: str | Path, **options):
    """Run a sweep: ``spec`` a TOML file, a dict (its table), a parsed :class:`SweepSpec` or
    a list of its scenarios;
    results in ``out``. ``options`` as :func:`popdispatch.sweep.execute.run_sweep`
    (``profiles``, ``scheduler``, ``workers``, ``quiet``). Returns its ``SweepResult``."""
    from popdispatch.sweep.execute import run_sweep

    if isinstance(spec, list):
        return run_sweep(spec, out, **options)
    if isinstance(spec, dict):
        spec = parse_spec(spec)
    elif not isinstance(spec, SweepSpec):
        spec = load_spec(spec)
    return run_sweep(spec.scenarios, out, **options)


__all__ = ["Scenario", "StepRange", "SweepSpec", "load_spec", "parse_spec", "run"]
