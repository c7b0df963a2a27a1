"""The agents as separate OS processes over TCP on localhost or over MQTT (``agents launch``).

:func:`launch` starts one process per agent (``python -m popdispatch.agents.launch --id AID
CONFIG``), each building the same problem and agents (:func:`popdispatch.agents.system.
build_agents`) and keeping its own, in a mango TCP container on ``127.0.0.1:<port>`` with
mango's real-time clock. Every agent acts at absolute deadlines from a start time the launcher
fixes once every process is ready, ``tick_s`` seconds a tick; the
plant learns the generators' outputs from ``Output`` messages (it shares no memory with the
inverters). Every process stops after the agreed number of rounds; the plant prints its
recorded set points as JSON. The launcher starts the children in their own process group and
on Ctrl-C (or any error) terminates the group and waits for every child: no orphans.

Start-up is a barrier, not a guess: a real-time run is only as good as its slowest agent's
first tick, and a process that is still importing or compiling when round 0 begins misses its
ticks (a fresh install compiles the kernels for tens of seconds). So the launcher first runs
the agents for a few rounds in mango's simulation (:func:`warm_up`, which compiles and caches
every kernel they use), then starts the processes; each builds its agent, runs the same warm-up
(loading those kernels into memory), and says it is ready (a file in the run's folder). When
all are ready the launcher writes the start time ``t0`` (``START_MARGIN_S`` ahead, for the
containers to open their sockets) and every process starts its container and waits for it.

Over MQTT (``transport="mqtt"``) each process is a mango MQTT container on a broker, its inbox
the topic ``popdispatch/<run id>/<agent id>``; the launcher starts a local broker when none
is given (:mod:`popdispatch.agents.transport`); with a given broker the launcher first tries
the agents' login (user, password, TLS) once, and every agent process gets the password in
its environment (never on its command line or in the run's files). On either transport every
agent keeps the gate of :func:`popdispatch.agents.transport.guard`: messages with another run
id or from a sender off the run's roster are dropped and counted (``rejected``).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from popdispatch.agents.schedule import TICKS_PER_ROUND
from popdispatch.agents.transport import (
    PASSWORD_ENV,
    TRANSPORTS,
    Broker,
    BrokerLogin,
    check_broker,
)
from popdispatch.errors import PopdispatchError

HOST = "127.0.0.1"

#: Seconds between the launcher's go and round 0 (every process opens its TCP container).
START_MARGIN_S = 2.0

#: Rounds of the simulated warm-up run (:func:`warm_up`).
WARM_UP_ROUNDS = 3

#: Seconds past the agreed end of the run after which a process that has not exited is stopped.
END_GRACE_S = 60.0


class LaunchError(PopdispatchError):
    """A launched run failed: an agent process was not ready in time, failed, or hung."""


@dataclass(frozen=True)
class LaunchConfig:
    """What every process of a launched run agrees on. Powers in kW where people give them.

    ``limits``: path limits ``[a, b, kW]``; ``ports``: agent id -> TCP port; ``folder``: the
    run's folder (ready files, the go file with ``t0``, epoch seconds of round 0's first
    tick); ``startup_s``: longest wait for the go, s; ``tick_s``: seconds per tick;
    ``rounds``: rounds to run;
    ``step_s``: the round's Euler step (s); ``loss``: probability that a message is dropped
    by its sender (fault injection over TCP, each process with its own seeded draws);
    ``seed``: of those draws; ``transport``: ``tcp`` or ``mqtt``; ``broker``: ``[host,
    port]`` of the MQTT broker; ``run_id``: stamped on every message (the gate's);
    ``login``: :meth:`popdispatch.agents.transport.BrokerLogin.public` of the agents'
    login to the broker (user, TLS files; the password is in each process's environment,
    :data:`popdispatch.agents.transport.PASSWORD_ENV`), None: anonymous, no TLS."""

    minute: int
    limits: list
    mode: str
    dynamics: str
    graph: str
    ports: dict
    folder: str
    startup_s: float
    tick_s: float
    rounds: int
    step_s: float
    loss: float = 0.0
    seed: int = 0
    transport: str = "tcp"
    broker: list | None = None
    run_id: str = ""
    login: dict | None = None


def _codec():
    from mango import JSON

    from popdispatch.agents.messages import ALL_MESSAGES

    codec = JSON()
    for kind in ALL_MESSAGES:
        codec.add_serializer(*kind.__serializer__())
    return codec


def _system(config: LaunchConfig):
    """The problem and the agents, built the same way in every process."""
    from popdispatch.agents.network import Faults
    from popdispatch.agents.population import build_agents
    from popdispatch.agents.system import AgentSettings
    from popdispatch.online import RunSettings
    from popdispatch.runs import FeederSource, load_run

    limits = [tuple(limit) for limit in config.limits]
    problem, _ = load_run(FeederSource(), None, config.minute, limits)
    settings = RunSettings(dynamics=config.dynamics, mode=config.mode, graph=config.graph)
    faults = Faults(loss=config.loss, seed=config.seed)
    copies = AgentSettings().copies_for(faults)
    system = build_agents(problem, config.minute, settings, config.step_s, Faults(),
                          copies=copies, engine_limiter=False)  # fmt: skip
    return problem, system


def warm_up(config: LaunchConfig) -> None:
    """Run the agents of ``config`` for :data:`WARM_UP_ROUNDS` rounds in mango's simulation:
    every kernel they call is compiled (and cached on disk) or loaded before the clock runs."""
    from popdispatch.agents.network import Faults
    from popdispatch.agents.population import world_options
    from popdispatch.agents.system import AgentSettings
    from popdispatch.agents.world import run_world

    _, system = _system(config)
    opts = AgentSettings(max_rounds=WARM_UP_ROUNDS, drain_rounds=0, tol_kw=0.0)
    run_world(system, world_options(opts, Faults()))


def agent_ids(system) -> dict:
    """Agent id -> agent of a built system (plant, controllers, generators by name)."""
    ids = {"plant": system.plant, **system.controllers}
    ids.update(zip(system.graph.nodes, system.generators, strict=True))
    return ids


def _wait_for_go(config: LaunchConfig, aid: str) -> float:
    """Say ``aid`` is ready, then wait for the launcher's start time (epoch s)."""
    folder = Path(config.folder)
    (folder / f"ready-{aid}").touch()
    deadline = time.monotonic() + config.startup_s + 60.0
    go = folder / "go"
    while not go.exists():
        if time.monotonic() > deadline:
            raise LaunchError(f"agent {aid}: no start from the launcher")
        time.sleep(0.02)
    return float(go.read_text())


def _roster(config: LaunchConfig) -> dict:
    """Agent id -> its address on the run's transport (an MQTT topic, or ``[host, port]``)."""
    from popdispatch.agents.transport import topic

    if config.transport == "mqtt":
        return {a: topic(config.run_id, a) for a in config.ports}
    return {a: [HOST, port] for a, port in config.ports.items()}


def _container(aid: str, config: LaunchConfig):
    """The agent's mango container on the run's transport."""
    from mango import create_tcp_container

    from popdispatch.agents.transport import mqtt_container, topic

    if config.transport == "mqtt":
        return mqtt_container(tuple(config.broker), f"{config.run_id}-{aid}",
                              topic(config.run_id, aid), _codec(), _login(config))  # fmt: skip
    return create_tcp_container((HOST, config.ports[aid]), codec=_codec())


def _login(config: LaunchConfig) -> BrokerLogin | None:
    """The run's login to its broker, the password from this process's environment."""
    if config.login is None:
        return None
    password = os.environ.get(PASSWORD_ENV) if config.login["user"] is not None else None
    return BrokerLogin(**config.login, password=password)


async def _serve(aid: str, config: LaunchConfig) -> None:
    from mango import AgentAddress, activate

    from popdispatch.agents.transport import guard

    problem, system = _system(config)
    agent = agent_ids(system)[aid]
    agent.network = None
    t0 = _wait_for_go(config, aid)
    agent.t0, agent.tick_s, agent.wall_clock = t0, config.tick_s, True
    if config.loss:
        import random

        agent.loss, agent.drop = config.loss, random.Random(f"{config.seed}/{aid}")
    if aid in system.graph.nodes:
        agent.plant_id = "plant"
    container = _container(aid, config)
    container.register(agent, suggested_aid=aid)
    roster = _roster(config)
    address = tuple if config.transport == "tcp" else str
    agent.addresses = {a: AgentAddress(address(where), a) for a, where in roster.items()}
    guard(agent, config.run_id, roster)
    end = t0 + (config.rounds + 1) * agent.round_ticks * config.tick_s
    async with activate(container):
        await asyncio.sleep(max(0.0, end - time.time()))
    if agent.error is not None:
        raise LaunchError(f"agent {aid} failed: {agent.error!r}")
    if agent.missed_ticks:
        print(f"agent {aid} missed {agent.missed_ticks} ticks (started late or fell behind; "
              "a longer --startup-s or --tick-ms helps)", file=sys.stderr)  # fmt: skip
    counts = {"sent": agent.sent, "dropped": agent.dropped, "missed_ticks": agent.missed_ticks,
              "rejected": agent.rejected}  # fmt: skip
    if aid == "plant":
        counts["setpoints_mw"] = [list(map(float, p)) for p in agent.history]
    print(json.dumps(counts))


@dataclass(frozen=True)
class LaunchResult:
    """Set points (kW) the plant saw at the start of every round, the run's wall time (s,
    start-up included), the number of agent processes, messages sent and dropped, and the
    ticks the agents missed (deadlines already past when they got to them: a loaded machine;
    0 in a sound run), the messages the agents' gates rejected, the transport, the broker
    (``host:port``, MQTT) and the run id."""

    generators: list
    trajectory_kw: np.ndarray
    wall_seconds: float
    processes: int
    messages: int = 0
    lost: int = 0
    missed_ticks: int = 0
    rejected: int = 0
    transport: str = "tcp"
    broker: str | None = None
    run_id: str = ""


def launch(minute: int, limits, mode: str = "exact", dynamics: str = "smith",
           graph: str = "complete", rounds: int = 200, tick_s: float = 0.05,
           step_s: float | None = None, base_port: int = 0, startup_s: float = 180.0,
           loss: float = 0.0, seed: int = 0, transport: str = "tcp",
           broker: tuple[str, int] | None = None, run_id: str | None = None,
           login: BrokerLogin | None = None, on_start=None) -> LaunchResult:  # fmt: skip
    """Run the agents of one minute as separate processes over TCP (module docstring).

    ``base_port``: first TCP port (0: free ports the OS hands out); ``startup_s``: longest
    wait, s, for every process to be ready (round 0 starts as soon as all are); ``step_s``:
    the round's Euler step
    (None: :func:`popdispatch.agents.population.default_step`); ``loss``: probability
    that each message is dropped by its sender (``seed``: of the draws; decisions then go out
    in 3 copies, as in the simulation); ``transport``: ``tcp`` (localhost) or ``mqtt``
    (``broker``: ``(host, port)``; None: a mosquitto started for the run on 127.0.0.1);
    ``run_id``: the run's id (default random); ``login``: with ``broker``, how every agent
    logs in (user name and password, TLS; None: anonymous, no TLS); ``on_start``: called with the
    :class:`LaunchConfig` once the start time is fixed (a test's hook).
    """
    from popdispatch.runs import FeederSource, load_run

    if transport not in TRANSPORTS:
        raise ValueError(f"unknown transport {transport!r} (known: {', '.join(TRANSPORTS)})")
    if login is not None and (transport != "mqtt" or broker is None):
        raise ValueError("a login (user, TLS) needs the MQTT transport and a broker given")
    if transport == "mqtt" and broker is not None:
        check_broker(broker, login)  # before any work: a refused login is one line at once
    problem, _ = load_run(FeederSource(), None, minute, [tuple(x) for x in limits])
    from popdispatch.agents.network import Faults
    from popdispatch.agents.population import build_agents
    from popdispatch.online import RunSettings

    settings = RunSettings(dynamics=dynamics, mode=mode, graph=graph)
    if step_s is None:
        from popdispatch.agents.population import default_step

        step_s = default_step(problem, settings, minute)
    ids = list(agent_ids(build_agents(problem, minute, settings, step_s, Faults())))
    ports = _ports(len(ids), base_port) if transport == "tcp" else [0] * len(ids)
    run_id = run_id or uuid.uuid4().hex[:12]
    start = time.perf_counter()
    with contextlib.ExitStack() as stack:
        stack.enter_context(_sigterm_unwinds())  # the broker and the children are stopped
        if transport == "mqtt" and broker is None:
            broker = stack.enter_context(Broker()).address
        folder = stack.enter_context(tempfile.TemporaryDirectory(prefix="popdispatch-launch-"))
        config = LaunchConfig(minute, [list(x) for x in limits], mode, dynamics, graph,
                              dict(zip(ids, ports, strict=True)), folder, float(startup_s),
                              tick_s, rounds, step_s, float(loss), int(seed), transport,
                              None if broker is None else list(broker), run_id,
                              None if login is None else login.public())  # fmt: skip
        warm_up(config)
        env = _child_environment(login)
        outputs = {aid: json.loads(out.strip().splitlines()[-1])
                   for aid, out in _run_children(ids, config, on_start, env).items()}  # fmt: skip
    history = outputs["plant"]["setpoints_mw"]
    wall = time.perf_counter() - start
    counts = {key: sum(o[key] for o in outputs.values())
              for key in ("sent", "dropped", "missed_ticks", "rejected")}  # fmt: skip
    return LaunchResult(list(problem.generators), np.array(history) * 1000.0, wall, len(ids),
                        counts["sent"], counts["dropped"], counts["missed_ticks"],
                        counts["rejected"], transport,
                        None if broker is None else f"{broker[0]}:{broker[1]}",
                        run_id)  # fmt: skip


def _ports(n: int, base: int) -> list[int]:
    """``n`` TCP ports: ``base``, ``base + 1``, ... or free ones from the OS."""
    if base:
        return [base + i for i in range(n)]
    import socket

    sockets = [socket.socket() for _ in range(n)]
    try:
        for s in sockets:
            s.bind((HOST, 0))
        return [s.getsockname()[1] for s in sockets]
    finally:
        for s in sockets:
            s.close()


def _child_environment(login: BrokerLogin | None) -> dict[str, str]:
    """This process's environment, with the broker password (if any) in
    :data:`PASSWORD_ENV` (an environment is readable by its user only, a command line by
    every user)."""
    env = dict(os.environ)
    env.pop(PASSWORD_ENV, None)
    if login is not None and login.user is not None and login.password is not None:
        env[PASSWORD_ENV] = login.password
    return env


def _run_children(ids: list[str], config: LaunchConfig, on_start=None,
                  env: dict[str, str] | None = None) -> dict[str, str]:  # fmt: skip
    """Start one process per agent in a new process group; when all are ready, write the
    start time; wait for all (each until the run's agreed end plus :data:`END_GRACE_S`); on
    Ctrl-C, SIGTERM or an error terminate the group and wait, so no child outlives the
    launcher. The children write into files in the run's folder, not pipes (a pipe nobody reads
    while the launcher waits would block a child that writes much); ``env``: their
    environment (None: this process's)."""
    folder = Path(config.folder)
    path = folder / "config.json"
    path.write_text(json.dumps(asdict(config)))
    children, group = {}, None
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminated) if main_thread else None
    try:
        for aid in ids:
            with open(folder / f"{aid}.out", "w") as out, open(folder / f"{aid}.err", "w") as err:
                child = subprocess.Popen(
                    [sys.executable, "-m", "popdispatch.agents.launch", "--id", aid, str(path)],
                    stdout=out, stderr=err, text=True, process_group=group or 0, env=env,
                )  # fmt: skip
            group = group or child.pid
            children[aid] = child
        _wait_until_ready(children, config)
        t0 = time.time() + START_MARGIN_S
        staged = folder / "go.tmp"
        staged.write_text(repr(t0))
        os.replace(staged, folder / "go")
        if on_start is not None:
            on_start(config)
        finish = t0 + (config.rounds + 1) * TICKS_PER_ROUND * config.tick_s + END_GRACE_S
        for aid, child in children.items():
            try:
                child.wait(timeout=max(0.0, finish - time.time()))
            except subprocess.TimeoutExpired:
                raise LaunchError(f"agent process {aid} did not finish {END_GRACE_S:g} s "
                                  "after the run's end") from None  # fmt: skip
            _check_exit(aid, child, config)
        return {aid: (folder / f"{aid}.out").read_text() for aid in children}
    finally:
        _stop(children, group)
        if main_thread:
            signal.signal(signal.SIGTERM, previous)


@contextlib.contextmanager
def _sigterm_unwinds():
    """SIGTERM raises SystemExit inside the block (in the main thread): every ``finally`` and
    context manager of the launch runs, so no child process or broker outlives it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _terminated(signum, frame) -> None:
    """SIGTERM to the launcher: unwind (its ``finally`` stops the children), exit 143."""
    raise SystemExit(128 + signum)


def _wait_until_ready(children: dict, config: LaunchConfig) -> None:
    """Wait until every child has written its ready file (at most ``config.startup_s``)."""
    folder = Path(config.folder)
    deadline = time.monotonic() + config.startup_s
    waiting = set(children)
    while waiting:
        waiting = {aid for aid in waiting if not (folder / f"ready-{aid}").exists()}
        for aid in waiting:
            if children[aid].poll() is not None:
                _check_exit(aid, children[aid], config)
        if waiting and time.monotonic() > deadline:
            raise LaunchError(f"agent process {sorted(waiting)[0]} not ready after "
                              f"{config.startup_s:g} s (--startup-s)")  # fmt: skip
        time.sleep(0.05)


def _check_exit(aid: str, child: subprocess.Popen, config: LaunchConfig) -> None:
    """Raise with the last line of a child's standard error if it failed."""
    if child.returncode not in (0, None):
        err = (Path(config.folder) / f"{aid}.err").read_text()
        last = err.strip().splitlines()[-1] if err.strip() else "no message"
        raise LaunchError(f"agent process {aid} exited {child.returncode}: {last}")


def _stop(children: dict, group: int | None) -> None:
    """Terminate what is still running in the group (SIGTERM, then SIGKILL after 5 s), then
    wait for every child. Nothing is sent once every child has exited (the group's id may
    then belong to someone else)."""
    if group is None or all(c.poll() is not None for c in children.values()):
        return
    with contextlib.suppress(ProcessLookupError):
        os.killpg(group, signal.SIGTERM)
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline and any(c.poll() is None for c in children.values()):
        time.sleep(0.05)
    if any(c.poll() is None for c in children.values()):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(group, signal.SIGKILL)
    for child in children.values():
        child.wait()


def main(argv=None) -> int:
    """A child process: ``--id AID CONFIG``."""
    parser = argparse.ArgumentParser(description="one agent of a launched run")
    parser.add_argument("--id", required=True)
    parser.add_argument("config", type=Path)
    args = parser.parse_args(argv)
    config = LaunchConfig(**json.loads(args.config.read_text()))
    # stop at once on the launcher's SIGTERM (a clean asyncio shutdown of the container could
    # take seconds, and the launcher waits for every child)
    signal.signal(signal.SIGTERM, lambda *_: os._exit(143))
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the launcher decides; it sends SIGTERM
    warm_up(config)
    asyncio.run(_serve(args.id, config))
    return 0


if __name__ == "__main__":
    sys.exit(main())
