"""``sweep-report``: a sweep's summary as a table and figures.

The table has one row per group of scenarios sharing case, steps, mode, dynamics, graph and
limits (over profile assignments and events): counts by status, the error against the DC-OPF
(kW), the cost gap to the DC-OPF (EUR over the compared minutes) and the iterations per minute.
The figure shows their distributions per mode and dynamics.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.sweep.store import FAILED, read_summary

GROUP = ["case", "steps", "mode", "dynamics", "graph", "limits"]


def group_table(summary: pd.DataFrame) -> pd.DataFrame:
    """One row per group (:data:`GROUP`): ``scenarios``, ``failed``, ``infeasible``,
    ``converged``, ``max_abs_error_kw`` (worst), ``median_max_abs_error_kw`` (median over the
    scenarios of each one's worst error), ``median_cost_gap_eur``, ``mean_iterations``."""
    grouped = summary.groupby(GROUP, sort=False, dropna=False)
    status = summary["status"]
    return (
        grouped.agg(
            scenarios=("status", "size"),
            failed=("status", lambda s: int((s == FAILED).sum())),
            infeasible=("status", lambda s: int((s == "infeasible").sum())),
            converged=("status", lambda s: int((s == "converged").sum())),
            max_abs_error_kw=("max_abs_error_kw", "max"),
            median_max_abs_error_kw=("max_abs_error_kw", "median"),
            median_cost_gap_eur=("cost_gap_eur", "median"),
            mean_iterations=("mean_iterations", "mean"),
        ).reset_index()
        if len(status)
        else pd.DataFrame(columns=GROUP)
    )


def report_text(summary: pd.DataFrame, table: pd.DataFrame) -> str:
    """What ``sweep-report`` prints: totals, the group table, the failures' messages."""
    counts = summary["status"].value_counts()
    lines = [
        f"{len(summary)} scenarios: " + ", ".join(f"{n} {s}" for s, n in counts.items()),
        "",
        table.to_string(index=False, float_format=lambda v: f"{v:.4g}"),
    ]
    failed = summary[summary["status"] == FAILED]
    if len(failed):
        lines += ["", "failed:"]
        lines += [f"  {row.scenario_id}: {row.error}" for row in failed.itertuples()]
    return "\n".join(lines) + "\n"


def _labels(summary: pd.DataFrame) -> pd.Series:
    return summary["mode"] + "\n" + summary["dynamics"]


def sweep_figure(summary: pd.DataFrame):
    """Four panels: worst error per scenario (kW, log scale) and cost gap (EUR) per mode and
    dynamics, mean iterations per minute, and the scenarios' statuses."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 7), layout="constrained")
    axes = fig.subplots(2, 2)
    ran = summary[summary["status"] != FAILED]
    labels = _labels(ran)
    groups = sorted(labels.unique())
    _box(axes[0, 0], ran, labels, groups, "max_abs_error_kw", "worst |set point - DC-OPF| (kW)")
    axes[0, 0].set_yscale("log")
    _box(axes[0, 1], ran, labels, groups, "cost_gap_eur", "cost - DC-OPF cost (EUR)")
    _box(axes[1, 0], ran, labels, groups, "mean_iterations", "mean iterations per minute")
    counts = summary.groupby(["mode", "status"]).size().unstack(fill_value=0)
    counts.plot.bar(ax=axes[1, 1], rot=0)
    axes[1, 1].set_ylabel("scenarios")
    axes[1, 1].set_title("status (infeasible: no DC-OPF at some step)")
    return fig


def _box(ax, frame: pd.DataFrame, labels: pd.Series, groups: list[str], column: str, title: str):
    data = [frame.loc[labels == g, column].dropna().to_numpy() for g in groups]
    data = [d if len(d) else np.array([np.nan]) for d in data]
    positive = [np.maximum(d, 1e-12) if column == "max_abs_error_kw" else d for d in data]
    ax.boxplot(positive, tick_labels=groups)
    ax.set_title(title)


def write_report(sweep_dir: str | Path, out: str | Path | None = None) -> tuple[str, Path]:
    """Write ``groups.csv``, ``report.txt`` and the figure (``sweep.png``, ``sweep.pdf``) to
    ``out`` (default ``SWEEP_DIR/report``), staged then moved into place; returns the text
    and the folder."""
    from popdispatch.report.figures import save_figure
    from popdispatch.report.output import staged_folder

    summary = read_summary(sweep_dir)
    table = group_table(summary)
    text = report_text(summary, table)
    out = Path(out) if out is not None else Path(sweep_dir) / "report"
    with staged_folder(out) as folder:
        folder.write_csv("groups.csv", table)
        folder.write_text("report.txt", text)
        save_figure(sweep_figure(summary), folder.file("sweep"))
    return text, out
