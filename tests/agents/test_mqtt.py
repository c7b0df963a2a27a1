"""``agents launch --transport mqtt``: the agents as processes on a mosquitto broker; the
congestion minute reaches the DC-OPF (Clarabel) within 0.01 kW with supply equal to demand,
while an outsider publishes forged messages on the agents' topics (a DG off the roster offering
power, a controller price from a stale run, a controller at a wrong address) and the broker
restarts: every forged message is rejected, the agents reconnect, the dispatch is unchanged.
Ctrl-C leaves no agent process or broker; bad --broker values are one line."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)
if shutil.which("mosquitto") is None and not Path("/usr/sbin/mosquitto").exists():
    pytest.skip("no mosquitto broker (apt-get install mosquitto)", allow_module_level=True)

from popdispatch.agents.launch import _codec, launch  # noqa: E402
from popdispatch.agents.messages import Offer, Signals  # noqa: E402
from popdispatch.agents.transport import topic  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402

FORGED_EACH = 10  # copies of each forged message


def _running(pattern: str) -> int:
    """Processes whose command line holds ``pattern`` (this run's own folder: other runs on
    the machine do not count)."""
    found = subprocess.run(["pgrep", "-f", pattern], capture_output=True, text=True)
    return len(found.stdout.split())


class Forger:
    """Publishes forged messages on the run's topics once the agents are up."""

    def __init__(self, brokers: list):
        self.published = 0
        self.thread: threading.Thread | None = None
        self.config = None
        self.brokers = brokers  # the run's broker; its restart appended
        self.restarted_at = None

    def __call__(self, config) -> None:  # the launch's on_start hook
        self.config = config
        self.thread = threading.Thread(target=self._run, args=(config,), daemon=True)
        self.thread.start()

    def _run(self, config) -> None:
        self._forge(config)
        self._restart_broker(config)

    def _restart_broker(self, config) -> None:
        """Stop the broker 6 s into the run; start it again on its port 1 s later."""
        from popdispatch.agents.transport import Broker

        t0 = float((Path(config.folder) / "go").read_text())
        time.sleep(max(0.0, t0 + 6.0 - time.time()))
        self.brokers[0].__exit__(None, None, None)
        time.sleep(1.0)
        self.brokers.append(Broker(port=self.brokers[0].port).__enter__())
        self.restarted_at = time.time() - t0

    def _forge(self, config) -> None:
        import paho.mqtt.client as paho
        from mango.messages.message import MangoMessage

        t0 = float((Path(config.folder) / "go").read_text())
        time.sleep(max(0.0, t0 + 1.0 - time.time()))  # every agent has subscribed
        codec, run = _codec(), config.run_id
        forged = [  # (to, content, sender, sender address, run id)
            ("G114", Offer(5, "G999/5/G114", 0.005), "G999", topic(run, "G999"), run),
            ("G578", Signals(5, {0: 1e6}), "C505", topic(run, "C505"), "stale-run"),
            ("G739", Signals(5, {0: -1e6}), "C505", "elsewhere/C505", run),
        ]
        client = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id="forger")
        client.connect(*config.broker)
        client.loop_start()
        for _ in range(FORGED_EACH):
            for to, content, sender, address, run_id in forged:
                meta = {"sender_id": sender, "sender_addr": address, "receiver_id": to,
                        "run_id": run_id}  # fmt: skip
                payload = codec.encode(MangoMessage(content, meta))
                client.publish(topic(run, to), payload, qos=1).wait_for_publish(5)
                self.published += 1
            time.sleep(0.1)
        client.loop_stop()
        client.disconnect()


def test_mqtt_launch_rejects_forged_messages_and_survives_a_broker_restart(congestion_problem):
    from popdispatch.agents.transport import Broker

    brokers = [Broker().__enter__()]
    forger = Forger(brokers)
    try:
        result = launch(566, [[505, 666, 28.0]], rounds=160, startup_s=300, transport="mqtt",
                        broker=brokers[0].address, on_start=forger)  # fmt: skip
        forger.thread.join(timeout=30)
    finally:
        for broker in brokers:
            broker.__exit__(None, None, None)
    assert result.transport == "mqtt" and result.broker == f"{brokers[0].host}:{brokers[0].port}"
    assert forger.published == 3 * FORGED_EACH
    assert result.rejected == forger.published  # each forged message, and nothing else
    assert forger.restarted_at is not None and len(brokers) == 2  # an agent that failed raises
    final = result.trajectory_kw[-1]
    opf = solve_opf(congestion_problem, 566)
    assert np.abs(final - opf.p_kw).max() < 0.01, f"{result.missed_ticks} ticks missed"  # kW
    assert final.sum() == pytest.approx(congestion_problem.demand[565] * 1e3, abs=1e-6)
    assert _running(forger.config.folder) == 0  # no agent process of this run is left


def test_ctrl_c_stops_agents_and_broker():
    """Ctrl-C (SIGINT) to a launch over MQTT during start-up: the launcher exits non-zero and
    its twelve agent processes and the mosquitto it started are gone."""
    code = (
        "from popdispatch.agents.launch import launch\n"
        "launch(566, [[505, 666, 28.0]], rounds=40, startup_s=120, transport='mqtt')\n"
    )
    launcher = subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE)

    def children() -> list[str]:
        found = subprocess.run(["pgrep", "-P", str(launcher.pid)], capture_output=True,
                               text=True)  # fmt: skip
        return found.stdout.split()

    deadline = time.time() + 150
    while len(children()) < 13 and time.time() < deadline:  # 12 agents and the broker
        time.sleep(0.5)
    started = children()
    assert len(started) == 13
    broker = [p for p in started if "mosquitto" in Path(f"/proc/{p}/cmdline").read_text()]
    assert len(broker) == 1  # the launch started its own
    os.kill(launcher.pid, signal.SIGINT)
    launcher.wait(timeout=60)
    assert launcher.returncode != 0
    alive = [p for p in started if Path(f"/proc/{p}").exists()
             and Path(f"/proc/{p}/stat").read_text().split()[2] != "Z"]  # fmt: skip
    assert alive == []


def test_gate_passes_the_roster_and_drops_the_rest():
    """The gate alone: a message of this run from a roster sender at its roster address is
    handed on; another run id, a sender off the roster or at another address is counted as
    rejected; what the agent sends carries the run id."""
    import asyncio

    from popdispatch.agents.transport import guard

    class Agent:
        def __init__(self):
            self.got, self.sent = [], []

        async def send_message(self, content, receiver_addr, **kwargs):
            self.sent.append(kwargs)

        def handle_message(self, content, meta):
            self.got.append(content)

    agent = Agent()
    roster = {"C505": topic("run1", "C505"), "G1": ["127.0.0.1", 4000]}
    guard(agent, "run1", roster)
    ok = {"sender_id": "C505", "sender_addr": topic("run1", "C505"), "run_id": "run1"}
    agent.handle_message("a", ok)
    agent.handle_message("b", {**ok, "run_id": "run0"})
    agent.handle_message("c", {**ok, "sender_id": "G999"})
    agent.handle_message("d", {**ok, "sender_addr": "elsewhere/C505"})
    agent.handle_message("e", {"sender_id": "G1", "sender_addr": ["127.0.0.1", 4000],
                               "run_id": "run1"})  # fmt: skip
    agent.handle_message("f", {"sender_id": "G1", "sender_addr": ["127.0.0.1", 4001],
                               "run_id": "run1"})  # fmt: skip
    assert agent.got == ["a", "e"] and agent.rejected == 4
    asyncio.run(agent.send_message("x", receiver_addr=None))
    assert agent.sent == [{"run_id": "run1"}]


@pytest.mark.parametrize(
    ("args", "code", "says"),
    [
        (["--transport", "mqtt", "--broker", "nohost"], 2, "'nohost' is not HOST:PORT"),
        (["--broker", "127.0.0.1:1883"], 2, "--broker needs --transport mqtt"),
        (["--transport", "mqtt", "--broker", "127.0.0.1:1"], 1, "MQTT broker 127.0.0.1:1 not"),
        (["--transport", "mqtt", "--tls-ca", __file__], 2, "--tls-ca needs --broker"),
    ],
)
def test_bad_broker_is_one_line(args, code, says):
    done = subprocess.run(
        [sys.executable, "-m", "popdispatch.cli", "agents", "launch", "--minute", "566", "-q",
         *args], capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == code
    assert len(done.stderr.strip().splitlines()) == 1 and says in done.stderr


def test_documented_type_ids_are_the_codecs():
    """docs/cosim.md's table of MQTT payload type ids is what the codec writes."""
    import re

    from mango.messages.message import MangoMessage

    from popdispatch.agents.messages import ALL_MESSAGES

    text = (Path(__file__).resolve().parents[2] / "docs" / "cosim.md").read_text()
    documented = {m: int(i) for m, i in re.findall(r"^\| `(\w+)` \| (-?\d+) \|", text, re.M)}
    codec = _codec()
    written = {kind.__name__: codec._serializers[kind][0] for kind in ALL_MESSAGES}
    assert documented == written
    assert f"`MangoMessage` (`{codec._serializers[MangoMessage][0]}`)" in text
