"""``popdispatch compare``: distributed algorithms on one minute, the same agents, faults and
message counter (:mod:`popdispatch.algorithms`; an in-process synchronous message runtime,
not the mango agents of ``popdispatch agents``).

Prints one row per algorithm (runs converged, median rounds and messages to convergence,
bytes, messages per agent and round, most partners, worst final distance to the DC-OPF and
worst imbalance of the applied set points), what each role reveals and how each algorithm
handles a lost message; ``--json`` one object with ``algorithms`` (those rows) and ``runs``
(one per algorithm and seed); ``--out`` writes compare.csv (one row per run), summary.json
and distance.png/.pdf (distance to the DC-OPF against rounds and against messages).
Register it with ``cli.add_command(compare)``.
"""

from __future__ import annotations

import click

from popdispatch.cli.clock import Failure, stamp
from popdispatch.cli.options import (
    GRAPH_CHOICE,
    Series,
    build,
    check_out,
    duplicate_option,
    feeder_options,
    json_option,
    limit_option,
    loss_option,
    minute_option,
    option,
    out_option,
    profiles_option,
    quiet_option,
)
from popdispatch.cli.render import emit
from popdispatch.progress import Progress

#: The registry's names (checked against :data:`popdispatch.algorithms.ALGORITHMS` by a test).
ALGORITHM_NAMES = ("smith", "distributed-smith", "dual-decomposition",
                   "fast-dual-decomposition", "admm", "consensus-admm", "smith-paper",
                   "distributed-smith-paper")  # fmt: skip
#: What ``--algorithms`` runs by default: each method in the mode that claims the DC-OPF.
DEFAULT_ALGORITHMS = ALGORITHM_NAMES[:6]


class AlgorithmsType(click.ParamType):
    """A comma-separated list of algorithm names."""

    name = "NAME,..."

    def convert(self, value, param, ctx) -> tuple[str, ...]:
        if isinstance(value, tuple):
            return value
        names = tuple(n.strip() for n in str(value).split(",") if n.strip())
        unknown = [n for n in names if n not in ALGORITHM_NAMES]
        if unknown or not names:
            self.fail(f"unknown algorithm {unknown[0]!r} (known: {', '.join(ALGORITHM_NAMES)})"
                      if unknown else "no algorithm given", param, ctx)  # fmt: skip
        return tuple(dict.fromkeys(names))


class CrashType(click.ParamType):
    """``GEN@ROUND``: the DG's agent stops at that round for good."""

    name = "GEN@ROUND"

    def convert(self, value, param, ctx) -> tuple[str, int]:
        if isinstance(value, tuple):
            return value
        name, _, at = str(value).partition("@")
        if not name or not at.isdigit() or int(at) < 1:
            self.fail(f"{value!r}: expected GEN@ROUND with ROUND >= 1, e.g. G114@50", param, ctx)
        return name, int(at)


@click.command(short_help="Dynamics against dual decomposition and ADMM, by messages.")
@option("--algorithms", type=AlgorithmsType(), default=",".join(DEFAULT_ALGORITHMS),
        show_default=True, help="Algorithms to run (comma-separated).")  # fmt: skip
@minute_option
@limit_option
@loss_option
@option("--delay-max", type=click.IntRange(0), default=0, show_default=True,
        help="Largest extra message delay, rounds.")  # fmt: skip
@duplicate_option
@option(
    "--crash",
    type=CrashType(),
    default=None,
    help="DG GEN's agent stops at ROUND for good; its inverter holds its set point.",
)
@option(
    "--graph",
    type=GRAPH_CHOICE,
    default="ring",
    show_default=True,
    help="Communication graph of distributed Smith (distributed-smith, "
    "distributed-smith-paper); circulant: four partners each, short across.",
)
@option("--seeds", type=click.IntRange(1), default=1, show_default=True,
        help="Runs per algorithm, seeds --seed, --seed + 1, ...")  # fmt: skip
@option("--seed", type=int, default=0, show_default=True, help="First seed.")
@option("--max-rounds", type=click.IntRange(1), default=6000, show_default=True,
        help="Horizon, rounds.")  # fmt: skip
@profiles_option
@feeder_options
@out_option
@json_option
@quiet_option
@click.pass_context
def compare(ctx, algorithms, minute, limits, loss, delay_max, duplicate, crash, graph, seeds,
            seed, max_rounds, profiles, source, out, as_json, quiet) -> int:  # fmt: skip
    """Population dynamics (Smith, distributed Smith on a ring or the --graph given), dual
    decomposition (plain and fast) and ADMM (proximal message passing; consensus ADMM, which
    runs on meshes too) on one minute, by messages through one simulated network with the same
    faults and counter, each measured every round against the DC-OPF. A run is converged only
    when its applied set points are within max(1e-3 kW, 1e-6 x demand) of the DC-OPF,
    balanced and within the line limits for 10 rounds in a row. smith-paper and
    distributed-smith-paper (not run unless named) follow the paper's rule, which rests away
    from the DC-OPF: their distance is the paper mode's error. The default list leaves out,
    with a note, what cannot run the network (ADMM by proximal message passing on a mesh, dual
    decomposition on a linear cost); a list given is refused instead."""
    check_out(out)
    from popdispatch.algorithms.comparison import on_graph

    graphed = ctx.get_parameter_source("graph") != click.core.ParameterSource.DEFAULT
    params = on_graph(algorithms, graph) if graphed else {}
    progress = Progress(quiet)
    problem, _ = build(source, Series(profiles), minute, limits, progress)
    if crash is not None and crash[0] not in [str(g) for g in problem.generators]:
        raise click.BadParameter(f"no generator {crash[0]!r} (the fleet: "
                                 f"{', '.join(map(str, problem.generators))})",
                                 param_hint="'--crash'")  # fmt: skip
    from popdispatch.algorithms import Faults, RunOptions
    from popdispatch.algorithms.comparison import (
        check_algorithms,
        compare_algorithms,
        runnable,
        runs_table,
        summary_table,
    )
    from popdispatch.opf import solve_opf

    left_out: list[str] = []
    if ctx.get_parameter_source("algorithms") == click.core.ParameterSource.DEFAULT:
        algorithms, left_out = runnable(problem, algorithms)  # the defaults that can run it
        for note in left_out:
            progress.note(note)
    else:
        check_algorithms(problem, algorithms)
    if solve_opf(problem, minute).status != "optimal":
        raise Failure(f"the DC-OPF of minute {minute} is infeasible with the given limits")
    faults = Faults(loss, delay_max, duplicate, seed, crash)
    with progress.step(f"minute {minute}: {len(algorithms)} algorithms x {seeds} seeds"):
        try:
            runs = compare_algorithms(problem, minute, algorithms, faults, seeds,
                                      RunOptions(max_rounds=max_rounds), params)  # fmt: skip
        except ValueError as exc:  # the DC-OPF with a crashed DG held is infeasible
            raise Failure(str(exc)) from None
    table = runs_table(runs, seed)
    summary = summary_table(table)
    payload = {"minute": minute, "faults": faults.label(), "graph": graph, "seeds": seeds,
               "max_rounds": max_rounds, "demand_kw": float(problem.demand[minute - 1] * 1e3),
               "algorithms": summary.to_dict(orient="records"), "left_out": left_out,
               "reveals": {n: g[0].reveals for n, g in runs.items()},
               "loss_handling": {n: g[0].loss_handling for n, g in runs.items()},
               "runs": table.to_dict(orient="records")}  # fmt: skip
    if out is not None:
        _write(out, table, payload, runs, progress)
    emit(stamp(payload), as_json, _text(payload, summary))
    return 0


def _write(out, table, payload, runs, progress) -> None:
    from popdispatch.algorithms.comparison import distance_figure
    from popdispatch.report.figures import save_figure
    from popdispatch.report.output import staged_folder

    with progress.step(f"writing {out}"), staged_folder(out) as folder:
        folder.write_csv("compare.csv", table)
        save_figure(distance_figure(runs), folder.file("distance"))
        folder.write_json("summary.json", stamp(payload))


def _text(payload: dict, summary) -> str:
    lines = [f"minute {payload['minute']}, {payload['faults']}, {payload['seeds']} seed(s), "
             f"horizon {payload['max_rounds']} rounds, distributed Smith on a "
             f"{payload['graph']} graph; converged = within max(1e-3 kW, 1e-6 x demand) of "
             "the DC-OPF for 10 rounds"]  # fmt: skip
    head = ("algorithm", "converged", "rounds", "messages", "bytes", "msg/agent/round",
            "partners", "distance kW", "|imbalance| kW")  # fmt: skip
    width = max(18, *(len(name) for name in summary.algorithm))
    lines.append("  ".join(f"{h:>{width}}" if i == 0 else f"{h:>15}" for i, h in enumerate(head)))
    for row in summary.itertuples(index=False):
        cells = (row.algorithm, row.converged, _num(row.rounds), _num(row.messages),
                 _num(row.bytes_total), f"{row.messages_per_agent_round:.3g}",
                 str(row.partners_max), f"{row.final_distance_kw:.3g}",
                 f"{row.max_abs_imbalance_kw:.3g}")  # fmt: skip
        lines.append("  ".join(f"{c:>{width}}" if i == 0 else f"{c:>15}"
                               for i, c in enumerate(cells)))  # fmt: skip
    lines.append("reveals:")
    for name, roles in payload["reveals"].items():
        lines.append(f"  {name}: " + "; ".join(f"{r}: {', '.join(w)}" for r, w in roles.items()))
    lines.append("on a lost message:")
    for name, how in payload["loss_handling"].items():
        lines.append(f"  {name}: {how}")
    return "\n".join(lines) + "\n"


def _num(value) -> str:
    return "-" if value != value else f"{value:.0f}"
