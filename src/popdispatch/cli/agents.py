"""``popdispatch agents``: one minute dispatched by agents exchanging messages (mango-agents).

``--algorithm`` picks the agents' algorithm (:mod:`popdispatch.agents.algorithms`: the
population dynamics by default, dual decomposition and its fast variant). The snapshot's
options (minute, limits, dynamics, mode, x0, graph, feeder) plus the simulated
network's faults (``--loss``, ``--delay-max``, ``--duplicate``, ``--noise-kw``, ``--seed``) and
the round's Euler step (``--step-s``). The output is the snapshot's (``--json``: the snapshot
keys, with ``iterations`` counting rounds) plus what the messages did: ``messages``, ``lost``,
``max_imbalance_w`` (committed state), ``max_transient_w`` (taken up by the source bus),
``final_imbalance_w``, ``open_transactions``, ``rounds``, ``agents``, ``scalars_sent`` (the
real numbers the messages carried) and ``messages_per_agent_round``. ``agents launch`` runs
the agents as one OS process each over TCP on localhost (:mod:`popdispatch.agents.launch`).
Register the group in the main one with ``cli.add_command(agents)``
(:mod:`popdispatch.cli.commands`).
"""

from __future__ import annotations

from typing import NamedTuple

import click

from popdispatch.agents.algorithms import ALGORITHMS, DEFAULT_ALGORITHM
from popdispatch.cli.clock import Failure, stamp
from popdispatch.cli.options import (
    duplicate_option,
    feeder_options,
    json_option,
    limit_option,
    loss_option,
    option,
    profiles_option,
    quiet_option,
    run_options,
    settings_from,
)
from popdispatch.cli.render import emit
from popdispatch.progress import Progress


@click.group(
    short_help="One minute dispatched by agents over a lossy network (mango).",
    invoke_without_command=True,
)
@option("--minute", "--step", "minute", type=click.IntRange(1),
        help="1-based minute of the day (566 = the peak); required.")  # fmt: skip
@limit_option
@option("--algorithm", type=click.Choice(list(ALGORITHMS)), default=DEFAULT_ALGORITHM,
        show_default=True,
        help="The agents' algorithm: population dynamics, or dual decomposition (plain or "
        "fast) or consensus ADMM (exact mode: the DC-OPF) with the comparison's parameters "
        "(docs/agents.md).")  # fmt: skip
@run_options
@loss_option
@option("--delay-max", type=click.IntRange(0), default=0, show_default=True,
        help="Largest extra message delay, rounds (uniform in whole ticks).")  # fmt: skip
@duplicate_option
@option("--noise-kw", type=click.FloatRange(0.0), default=0.0, show_default=True,
        help="Standard deviation of each line-flow measurement, kW.")  # fmt: skip
@option("--seed", type=int, default=0, show_default=True, help="Seed of every random draw.")
@option("--trip", "trips", multiple=True, metavar="GEN@ROUND",
        help="DG GEN trips at ROUND: output 0 at once, for good (repeatable).")  # fmt: skip
@option("--crash", "crashes", multiple=True, metavar="GEN@ROUND[+ROUNDS]",
        help="DG GEN's agent stops at ROUND (restarts after ROUNDS); its inverter holds "
        "its set point (repeatable).")  # fmt: skip
@option("--controller-crash", "controller_crashes", multiple=True,
        metavar="CONTROLLER@ROUND[+ROUNDS]",
        help="Node controller (C<bus>, e.g. C505) stops at ROUND (restarts after ROUNDS) "
        "(repeatable).")  # fmt: skip
@option("--step-s", type=click.FloatRange(0.0, min_open=True), default=None,
        help="Euler step of one round, s (default: exact mode 1.5 over the larger of the "
        "line prices' and the economic dispatch's rates, each DG damping its own steps; "
        "paper mode the engine's substep 1e-4).")  # fmt: skip
@option("--max-rounds", type=click.IntRange(1), default=4000, show_default=True,
        help="Horizon, rounds.")  # fmt: skip
@option("--pace/--no-pace", default=True, show_default=True,
        help="Pace rounds to the longest delay (agents act on this round's messages only) "
        "or act on the latest messages however old.")  # fmt: skip
@profiles_option
@feeder_options
@json_option
@quiet_option
@click.pass_context
def agents(ctx, minute, limits, algorithm, dynamics, mode, x0, graph, loss, delay_max, duplicate,
           noise_kw, seed, trips, crashes, controller_crashes, step_s, max_rounds, pace, profiles,
           source, as_json, quiet, constants=None, price_law="plain",
           eta=None) -> int:  # fmt: skip
    """One minute dispatched by agents: one per generator, one per node controller and the
    plant, exchanging messages in mango's simulated world with seeded loss, delay and
    duplication; power moves only in pairwise transactions (offer, accept, commit), compared
    with the DC-OPF. ``agents launch`` runs them as separate processes over TCP instead.
    """
    if ctx.invoked_subcommand is not None:
        _refuse_group_options(ctx)
        return 0
    if minute is None:
        raise click.MissingParameter(param_hint="'--minute'", param_type="option")
    progress = Progress(quiet)
    events = {"trip": trips, "crash": crashes, "controller-crash": controller_crashes}
    faults = _faults(loss, delay_max, duplicate, noise_kw, seed, events)
    from popdispatch.agents.algorithms import get_algorithm, refuse_mode, refuse_options

    chosen = get_algorithm(algorithm)
    _refuse_unread(ctx, chosen)
    mode = _mode_of(ctx, chosen, mode)
    refuse_mode(chosen, mode)  # before the mode's own options are asked for (--vmin)
    settings = settings_from(dynamics, mode, x0, graph, None, constants, price_law, eta=eta)
    options = AgentOptions(step_s, max_rounds, pace)
    refuse_options(chosen, settings, _agent_settings(options), faults)  # before any work
    problem = _problem(source, profiles, minute, limits, progress)
    what = f"{dynamics} dynamics" if algorithm == DEFAULT_ALGORITHM else algorithm
    with progress.step(f"minute {minute}: {what} by agents"):
        summary = agents_summary(problem, minute, settings, faults, options, limits, algorithm)
    emit(stamp(summary), as_json, agents_text(summary))
    if summary["status"] == "infeasible":
        raise Failure(f"the DC-OPF of minute {minute} is infeasible with the given limits")
    if summary["status"] != "converged":
        raise Failure(f"the agents did not converge on minute {minute} "
                      f"({summary['dynamics_status']}): "
                      f"{summary['stall_reason'] or summary['horizon_reason']}")  # fmt: skip
    return 0


#: The run options (:func:`~popdispatch.cli.options.run_options`) an algorithm may not read.
RUN_OPTION_NAMES = ("dynamics", "eta", "mode", "x0", "graph", "constants", "price_law")


def _refuse_unread(ctx: click.Context, algorithm) -> None:
    """Usage error naming the first run option given on the command line that the
    algorithm does not read (its ``RUN_OPTIONS``; absent: it reads them all)."""
    reads = getattr(algorithm, "RUN_OPTIONS", None)
    if reads is None:
        return
    typed = click.core.ParameterSource.COMMANDLINE
    for param in ctx.command.params:
        if param.name in RUN_OPTION_NAMES and param.name not in reads \
                and ctx.get_parameter_source(param.name) == typed:  # fmt: skip
            raise click.BadParameter(f"the {algorithm.NAME} agents do not use it (population "
                                     "dynamics only)", param_hint=f"'{param.opts[0]}'")


def _mode_of(ctx: click.Context, algorithm, mode: str) -> str:
    """The mode to run: the one given, else the default if the algorithm runs it, else the
    algorithm's own (dual decomposition runs exact mode only)."""
    given = ctx.get_parameter_source("mode") == click.core.ParameterSource.COMMANDLINE
    return mode if given or mode in algorithm.MODES else algorithm.MODES[0]


def _refuse_group_options(ctx: click.Context) -> None:
    """Usage error (exit 2) for options given to the group before its subcommand, which the
    subcommand would not see (``agents --mode exact launch ...``)."""
    typed = click.core.ParameterSource.COMMANDLINE
    given = [p.opts[0] for p in ctx.command.params if ctx.get_parameter_source(p.name) == typed]
    if given:
        raise click.UsageError(
            f"{', '.join(given)} given before '{ctx.invoked_subcommand}' would be ignored: "
            f"put the options after it (popdispatch agents {ctx.invoked_subcommand} ...)"
        )


def _faults(loss, delay_max, duplicate, noise_kw, seed, events=None):
    """The run's :class:`~popdispatch.agents.network.Faults` (one-line error without mango);
    ``events``: ``{kind: ("AGENT@ROUND[+ROUNDS]", ...)}``."""
    try:
        from popdispatch.agents import require_mango

        require_mango()
    except ImportError as exc:
        raise Failure(str(exc)) from None
    from popdispatch.agents.network import FaultEvent, Faults

    parsed = tuple(
        FaultEvent.parse(kind, text) for kind, texts in (events or {}).items() for text in texts
    )
    if any(e.kind == "trip" and e.rounds is not None for e in parsed):
        raise click.BadParameter("a trip is for good: GEN@ROUND", param_hint="'--trip'")
    return Faults(loss, delay_max, duplicate, noise_kw, seed, parsed)


def _problem(source, profiles, minute, limits, progress):
    from popdispatch.errors import OptionError
    from popdispatch.game.problem import check_online
    from popdispatch.runs import load_run

    try:
        problem, _ = load_run(source, profiles, minute, limits, progress)
    except OptionError as exc:  # a bad --limit reads as click's own usage errors
        if exc.option != "--limit":
            raise
        raise click.BadParameter(str(exc), param_hint="'--limit'") from None
    check_online(problem, [minute])
    return problem


class AgentOptions(NamedTuple):
    """The command's own run options: round step (s, None: the default), horizon (rounds),
    paced rounds."""

    step_s: float | None
    max_rounds: int
    paced: bool


def _local_step(settings) -> bool:
    """Whether the agents' local step is in force (docs/agents.md, "The local step"): the
    default in exact mode's curvature-scaled field."""
    from popdispatch.agents.system import AgentSettings
    from popdispatch.dynamics.fields import Field

    return (AgentSettings().local_step and settings.mode == "exact"
            and settings.field == Field.CAPACITY_NEWTON)  # fmt: skip


def _agent_settings(options: AgentOptions):
    """The :class:`~popdispatch.agents.system.AgentSettings` of the command's options."""
    from popdispatch.agents.system import AgentSettings

    return AgentSettings(step_s=options.step_s, max_rounds=options.max_rounds,
                         paced=options.paced)  # fmt: skip


def agents_summary(problem, minute, settings, faults, options: AgentOptions, limits,
                   algorithm: str = DEFAULT_ALGORITHM) -> dict:  # fmt: skip
    """The snapshot summary of the agents' run against the DC-OPF, plus the messages' keys
    (``algorithm``: a name of :data:`popdispatch.agents.algorithms.ALGORITHMS`)."""
    import numpy as np

    from popdispatch.agents.system import run_agents, without
    from popdispatch.compare import SnapshotComparison
    from popdispatch.modes import get_mode
    from popdispatch.modes.exact import price_weights
    from popdispatch.online import SnapshotResult, limited_flows_mw, overflow_kw
    from popdispatch.online.kkt import net_prices
    from popdispatch.opf import solve_opf
    from popdispatch.report.summaries import snapshot_summary
    from popdispatch.runs import check_x0

    check_x0(settings.x0, problem.generators)
    run = run_agents(problem, minute, settings, faults, _agent_settings(options),
                     algorithm=algorithm)  # fmt: skip
    final_mw = run.setpoints_kw / 1000.0
    line_prices = voltage_prices = None
    if run.line_price_eur_per_mwh is not None:  # the algorithm's own prices (no voltage rows)
        line_prices, voltage_prices = run.line_price_eur_per_mwh, np.zeros(0)
    elif get_mode(settings.mode).claims_dc_opf:  # the prices the controllers broadcast at the end
        weight = price_weights(problem, settings.exact.price_law,
                               settings.game_constants(problem).C, np.array([minute - 1]))
        line_prices, voltage_prices = (
            prices[0] for prices in net_prices(problem, np.array([minute]), final_mw[None],
                                               run.line_states(len(problem.limit))[None], weight)
        )  # fmt: skip
    overflow = [overflow_kw(problem, row / 1000.0, minute).max(initial=0.0) > 0.0
                for row in run.trajectory_kw]  # fmt: skip
    result = SnapshotResult(
        minute=minute,
        demand_kw=float(problem.demand[minute - 1] * 1000.0),
        settings=settings,
        generators=problem.generators,
        trajectory_kw=np.vstack([run.trajectory_kw, run.setpoints_kw]),
        converged_at=_converged_at(run),
        first_congestion=next((i for i, o in enumerate(overflow) if o), None),
        overflow_kw=overflow_kw(problem, final_mw, minute),
        flows_kw=limited_flows_mw(problem, final_mw, minute) * 1000.0,
        wall_seconds=run.wall_seconds,
        profile_source=problem.profile_source,
        stall_reason=run.stall_reason,
        rest_at=run.rest_round,
        infeasible=run.infeasible,
        line_price_eur_per_mwh=line_prices,
        voltage_price_eur_per_mwh=voltage_prices,
        distance_bound_kw=run.distance_bound_kw,
        accuracy_kw=run.accuracy_kw,
    )
    # the yardstick: the DC-OPF without the tripped DGs
    remaining = without(problem, minute, [e.agent for e in faults.events if e.kind == "trip"])
    comparison = SnapshotComparison(result, solve_opf(remaining, minute))
    summary = snapshot_summary(remaining, comparison, limits)
    population = algorithm == DEFAULT_ALGORITHM
    summary.update(
        algorithm=algorithm,
        iterations=run.rounds,
        rounds=run.rounds,
        step_s=run.step_s if population else None,
        step_source=("given" if options.step_s is not None else "default") if population
        else None,
        local_step=_local_step(settings) and population,
        horizon_reason=run.horizon_reason,
        paced=options.paced,
        phase_ticks=run.phase_ticks,
        loss=faults.loss,
        delay_max=faults.delay_max,
        duplicate=faults.duplicate,
        noise_kw=faults.noise_kw,
        seed=faults.seed,
        agents=run.agents,
        messages=run.messages,
        scalars_sent=run.scalars_sent,
        lost=run.lost,
        messages_per_agent_round=run.messages_per_agent_round,
        max_imbalance_w=run.max_imbalance_w,
        max_transient_w=run.max_transient_w,
        final_imbalance_w=run.final_imbalance_w,
        open_transactions=run.open_transactions,
        faults=[
            {"kind": e.kind, "agent": e.agent, "round": e.round, "rounds": e.rounds}
            for e in faults.events
        ],
        events=run.events,
        source_kw=run.source_kw,
    )
    return summary


def _converged_at(run) -> int | None:
    """The round a converged run is reported converged at (its rest round, else its last
    round: proved without coming to rest), None if it is not converged."""
    if run.status != "converged":
        return None
    return run.rest_round if run.rest_round is not None else run.rounds


def _proved_text(s: dict) -> str:
    """The distance certificate's bound against the accuracy (modes that claim the DC-OPF)."""
    if s.get("accuracy_kw") is None:
        return ""
    bound = s.get("distance_bound_kw")
    shown = "nothing (unbounded)" if bound is None else f"within {bound:.3g} kW"
    return f"; proved {shown} of the DC-OPF, accuracy {s['accuracy_kw']:.3g} kW"


def agents_text(s: dict) -> str:
    """What people read: set points against the DC-OPF and what the messages did."""
    from popdispatch.report.text import limits_text

    population = s["algorithm"] == DEFAULT_ALGORITHM
    by = (f"{s['dynamics']} dynamics, {s['mode']} mode, by {s['agents']} agents "
          f"({s['graph']} graph)" if population else f"{s['algorithm']} by {s['agents']} agents")
    step = (f" of {s['step_s']:.4g} s ({s['step_source']} step"
            + ("; each generator damps its own by its curvature, and a line's controller "
               "hastens its price while its flow stands still over its limit and nets its two "
               "prices once its flow settles inside"
               if s["local_step"] else "")
            + ")") if population else ""  # fmt: skip
    lines = [
        f"minute {s['minute']}, demand {s['demand_kw']:.3f} kW: {by}",
        f"network: loss {s['loss']:g}, delays up to {s['delay_max']} rounds, duplicates "
        f"{s['duplicate']:g}, noise {s['noise_kw']:g} kW, seed {s['seed']}"
        + (f"; rounds paced to {s['phase_ticks']} ticks per phase" if s["phase_ticks"] > 1 else ""),
        limits_text(s["limits"], s["limits_in_force"]),
        f"status: {s['dynamics_status']} after {s['rounds']} rounds{step}"
        + (
            f" (at rest from round {s['rest_iteration']})"
            if s["rest_iteration"] is not None
            else ""
        )
        + _proved_text(s)
        + (f"\nstalled: {s['stall_reason']}" if s["stall_reason"] else "")
        + (f"\n{s['horizon_reason']}" if s["horizon_reason"] else ""),
        f"{'generator':>10} {'setpoint_kw':>12} {'opf_kw':>10}",
    ]
    for g in s["generators"]:
        opf = "null" if g["opf_kw"] is None else f"{g['opf_kw']:.3f}"
        lines.append(f"{g['name']:>10} {g['setpoint_kw']:>12.3f} {opf:>10}")
    error = s["max_abs_error_kw"]
    lines += [
        "max |error| vs DC-OPF: "
        + ("null" if error is None else f"{error:.4f} kW")
        + f", max overflow {s['max_overflow_kw']:.4f} kW",
        *_price_lines(s["line_prices"]),
        f"messages {s['messages']} ({s['lost']} lost, {s['messages_per_agent_round']:.2f} per "
        f"agent per round; {s['scalars_sent']} scalars sent); imbalance: committed max "
        f"{s['max_imbalance_w']:.3g} W, source bus "
        f"max {s['max_transient_w']:.3g} W, final {s['final_imbalance_w']:.3g} W, open "
        f"transactions {s['open_transactions']}",
    ]
    lines += [_event_text(e) for e in s["events"]]
    if abs(s["source_kw"]) > 0.0005:
        lines.append(f"source bus still carries {s['source_kw']:.3f} kW after the trips")
    return "\n".join(lines)


def _price_lines(prices: list[dict] | None) -> list[str]:
    """Each limited line's price at the end against the DC-OPF's dual (exact mode)."""
    lines = []
    for row in prices or ():
        dual = row["opf_price_eur_per_mwh"]
        lines.append(f"line {row['from_bus']}-{row['to_bus']}: price "
                     f"{row['price_eur_per_mwh']:.4f} EUR/MWh (DC-OPF "
                     + ("null" if dual is None else f"{dual:.4f}") + ")")  # fmt: skip
    return lines


def _broker(value: str | None) -> tuple[str, int] | None:
    """``--broker HOST:PORT`` as ``(host, port)``; a usage error naming the option otherwise."""
    if value is None:
        return None
    from popdispatch.agents.transport import parse_broker

    try:
        return parse_broker(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="'--broker'") from None


def _login(broker, user, tls_ca, tls_cert, tls_key):
    """The agents' :class:`~popdispatch.agents.transport.BrokerLogin` (None: anonymous, no
    TLS); a usage error naming the option for a login without a broker of one's own, a
    missing password, a client certificate without TLS or TLS files ssl cannot load."""
    import os

    from popdispatch.agents.transport import PASSWORD_ENV, BrokerLogin

    given = {"--broker-user": user, "--tls-ca": tls_ca, "--tls-cert": tls_cert,
             "--tls-key": tls_key}  # fmt: skip
    given = {name: value for name, value in given.items() if value is not None}
    if not given:
        return None
    first = next(iter(given))
    if broker is None:
        raise click.BadParameter(f"{first} needs --broker (the broker the launch starts "
                                 "listens on 127.0.0.1, anonymous, without TLS)",
                                 param_hint=f"'{first}'")  # fmt: skip
    for option_, needs in (("--tls-key", "--tls-cert"), ("--tls-cert", "--tls-ca")):
        if option_ in given and needs not in given:
            raise click.BadParameter(f"{option_} needs {needs}", param_hint=f"'{option_}'")
    if user is not None and PASSWORD_ENV not in os.environ:
        raise click.BadParameter(f"--broker-user needs the password in the environment "
                                 f"variable {PASSWORD_ENV} (never on the command line)",
                                 param_hint="'--broker-user'")  # fmt: skip
    if tls_ca is not None:
        _check_tls_files(tls_ca, tls_cert, tls_key)
    password = os.environ[PASSWORD_ENV] if user is not None else None
    return BrokerLogin(user, password, tls_ca, tls_cert, tls_key)


def _check_tls_files(tls_ca: str, tls_cert: str | None, tls_key: str | None) -> None:
    """A usage error naming the option whose PEM file ssl cannot load."""
    import ssl

    context = ssl.create_default_context()
    try:
        context.load_verify_locations(cafile=tls_ca)
    except ssl.SSLError as exc:
        raise click.BadParameter(f"{tls_ca}: no CA certificate ssl can read ({exc.reason})",
                                 param_hint="'--tls-ca'") from None  # fmt: skip
    if tls_cert is None:
        return

    def encrypted() -> str:  # ssl asks only for an encrypted key (else it would prompt)
        raise click.BadParameter(f"{tls_key or tls_cert}: the key is encrypted (the agents "
                                 "need it unencrypted)", param_hint="'--tls-key'")  # fmt: skip

    try:
        context.load_cert_chain(tls_cert, tls_key, password=encrypted)
    except ssl.SSLError as exc:
        files = tls_cert + (f" with {tls_key}" if tls_key else "")
        raise click.BadParameter(f"{files}: no certificate and key ssl can read "
                                 f"({exc.reason})", param_hint="'--tls-cert'") from None


def _event_text(e: dict) -> str:
    """One fault event as a line."""
    extra = ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                      for k, v in e.items() if k not in ("round", "event", "agent"))  # fmt: skip
    return f"round {e['round']}: {e['event']} {e['agent']}" + (f" ({extra})" if extra else "")


@agents.command(short_help="The agents as separate processes over TCP on localhost.")
@option("--minute", "--step", "minute", type=click.IntRange(1), required=True,
        help="1-based minute of the day (566 = the peak).")  # fmt: skip
@limit_option
@option("--mode", type=click.Choice(["paper", "exact"]), default="exact", show_default=True,
        help="How node controllers turn flows into fitness signals.")  # fmt: skip
@option("--rounds", type=click.IntRange(1), default=200, show_default=True,
        help="Rounds to run.")  # fmt: skip
@option("--tick-ms", type=click.FloatRange(1.0), default=50.0, show_default=True,
        help="Real time per tick, ms (6 ticks a round).")  # fmt: skip
@option("--startup-s", type=click.FloatRange(1.0), default=180.0, show_default=True,
        help="Longest wait, s, for every process to load its data (round 0 starts when all are "
             "ready).")  # fmt: skip
@option(
    "--loss",
    type=click.FloatRange(0.0, 1.0, max_open=True),
    default=0.0,
    show_default=True,
    help="Probability that a message is dropped by its sender (0-1).",
)
@option("--seed", type=int, default=0, show_default=True, help="Seed of the drops.")
@option("--transport", type=click.Choice(["tcp", "mqtt"]), default="tcp", show_default=True,
        help="tcp: every agent a TCP server on 127.0.0.1; mqtt: every agent an MQTT client "
        "of a broker, inbox topic popdispatch/RUN_ID/AGENT (docs/cosim.md).")  # fmt: skip
@option("--broker", metavar="HOST:PORT", callback=lambda ctx, param, value: _broker(value),
        help="MQTT broker to use (default: a mosquitto started for the run on 127.0.0.1, "
        "stopped at the end).")  # fmt: skip
@option("--broker-user", metavar="NAME",
        help="With --broker: every agent logs in as NAME, with the password in the "
        "environment variable POPDISPATCH_BROKER_PASSWORD (never an option: a command line "
        "is visible to every user in ps).")  # fmt: skip
@option("--tls-ca", type=click.Path(exists=True, dir_okay=False),
        help="With --broker: connect over TLS, checking the broker's certificate against "
        "these CA certificates (PEM; a public CA's: the system bundle, e.g. "
        "/etc/ssl/certs/ca-certificates.crt).")  # fmt: skip
@option("--tls-cert", type=click.Path(exists=True, dir_okay=False),
        help="With --tls-ca: the agents' client certificate (PEM), its key in --tls-key or "
        "in the same file.")  # fmt: skip
@option("--tls-key", type=click.Path(exists=True, dir_okay=False),
        help="With --tls-cert: the client certificate's private key (PEM, unencrypted).")
@option("--run-id", metavar="ID", help="The run's id, stamped on every message (default "
        "random); agents drop messages with another.")  # fmt: skip
@json_option
@quiet_option
def launch(minute, limits, mode, rounds, tick_ms, startup_s, loss, seed, transport, broker,
           broker_user, tls_ca, tls_cert, tls_key, run_id, as_json, quiet) -> int:  # fmt: skip
    """One OS process per agent (plant, node controllers, generators) on localhost, talking
    over TCP or MQTT (mango), on the built-in ieee-elv case; compared with the DC-OPF. Every
    agent drops messages from senders off the run's roster or with another run id (counted in
    rejected). Ctrl-C stops every process and a broker the command started (exit 130). A
    broker of your own may ask for a login (--broker-user) and TLS (--tls-ca)."""
    import numpy as np

    from popdispatch.agents.launch import launch as run_launch
    from popdispatch.opf import solve_opf
    from popdispatch.runs import FeederSource, load_run

    progress = Progress(quiet)
    if broker is not None and transport != "mqtt":
        raise click.BadParameter("--broker needs --transport mqtt", param_hint="'--broker'")
    login = _login(broker, broker_user, tls_ca, tls_cert, tls_key)
    _faults(0.0, 0, 0.0, 0.0, 0)  # the agents extra is installed
    problem, _ = load_run(FeederSource(), None, minute, limits, progress)
    over = transport.upper()
    with progress.step(f"minute {minute}: {rounds} rounds by agent processes over {over}"):
        result = run_launch(minute, [list(x) for x in limits], mode=mode, rounds=rounds,
                            tick_s=tick_ms / 1000.0, startup_s=startup_s, loss=loss,
                            seed=seed, transport=transport, broker=broker,
                            run_id=run_id, login=login)  # fmt: skip
    opf = solve_opf(problem, minute)
    final = result.trajectory_kw[-1]
    error = float(np.abs(final - opf.p_kw).max()) if opf.status == "optimal" else None
    summary = {
        "minute": minute,
        "mode": mode,
        "rounds": len(result.trajectory_kw) - 1,
        "processes": result.processes,
        "generators": [
            {"name": g, "setpoint_kw": float(p), "opf_kw": float(o)}
            for g, p, o in zip(result.generators, final, opf.p_kw, strict=True)
        ],
        "max_abs_error_kw": error,
        "wall_seconds": result.wall_seconds,
        "loss": loss,
        "seed": seed,
        "messages": result.messages,
        "lost": result.lost,
        "missed_ticks": result.missed_ticks,
        "rejected": result.rejected,
        "transport": result.transport,
        "broker": result.broker,
        "run_id": result.run_id,
        "supply_kw": float(final.sum()),
        "demand_kw": float(problem.demand[minute - 1] * 1000.0),
    }
    text = "\n".join(
        [f"minute {minute}, {mode} mode: {summary['rounds']} rounds by agent processes over "
         f"{over}" + (f" (broker {result.broker}, run {result.run_id})" if result.broker else "")]
        + [
            f"{g['name']:>10} {g['setpoint_kw']:>10.3f} {g['opf_kw']:>10.3f}"
            for g in summary["generators"]
        ]
        + ["max |error| vs DC-OPF: " + ("null" if error is None else f"{error:.4f} kW")]
        + [f"messages {result.messages} ({result.lost} dropped, loss {loss:g}; "
           f"{result.rejected} rejected: another run or a sender off the roster)"]
        + [
            f"missed ticks {result.missed_ticks} (agents that fell behind the clock: a loaded "
            "machine; a longer --tick-ms helps)"
        ]
        * bool(result.missed_ticks)
    )
    emit(stamp(summary), as_json, text)
    return 0
