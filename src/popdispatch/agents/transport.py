"""How launched agents reach each other: TCP on localhost or MQTT through a broker, and the
gate every launched agent keeps (``agents launch --transport``; docs/cosim.md, "MQTT").

**MQTT.** Every agent is a mango MQTT container (paho-mqtt) whose inbox is the topic
:func:`topic` ``popdispatch/<run id>/<agent id>`` (agent ids: ``plant``, the node controllers
``C<bus>``, the generators by name, e.g. ``G114``); it publishes to the addressee's topic,
QoS 0. Payloads are mango's JSON codec: ``{"__type__": [TYPE_ID, DATA]}``, a ``MangoMessage``
whose data holds ``content`` (one of :mod:`popdispatch.agents.messages`, itself
``{"__type__": [TYPE_ID, {fields}]}``, powers in MW) and ``meta`` (``sender_id``,
``sender_addr``: the sender's topic, ``run_id``); the type ids are in docs/cosim.md.
Without ``--broker`` the launcher starts its own broker (:class:`Broker`, Debian's
``mosquitto``) on 127.0.0.1 at a free port and stops it at the end.

**A remote broker** (:class:`BrokerLogin`): every agent logs in with a user name and a
password (the password from the environment variable :data:`PASSWORD_ENV`, never from a
command line, which every user of the machine sees in ``ps``) and talks TLS, the broker's
certificate checked against a CA bundle, optionally with a client certificate. The launcher
tries the login once before any agent starts (:func:`check_broker`), so a refusal is one line.

**The gate** (:func:`guard`): a launched run has a random run id and a roster (every agent id
and its address). An agent stamps ``run_id`` on everything it sends and drops, counting them
as ``rejected``, messages whose run id is not the run's (a stale run) or whose sender is not
on the roster or not at its roster address. This keeps stray and stale messages out; it is
not authentication: anyone who can read the broker's traffic learns the run id, so keep the
broker on localhost (the default) or use a broker with TLS and credentials.
"""

from __future__ import annotations

import contextlib
import contextvars
import shutil
import socket
import ssl
import subprocess
import tempfile
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from popdispatch.errors import PopdispatchError

TRANSPORTS = ("tcp", "mqtt")
#: Topic prefix of a launched run's agents.
TOPIC_PREFIX = "popdispatch"
#: Seconds to wait for a started broker to accept connections.
BROKER_START_S = 10.0
#: The environment variable holding the password of ``--broker-user``.
PASSWORD_ENV = "POPDISPATCH_BROKER_PASSWORD"
#: Seconds to wait for a broker's answer to a login (:func:`check_broker`).
LOGIN_TIMEOUT_S = 5.0


class BrokerError(PopdispatchError):
    """The MQTT broker could not be started or reached."""


def topic(run_id: str, aid: str) -> str:
    """The inbox topic of agent ``aid`` in run ``run_id``."""
    return f"{TOPIC_PREFIX}/{run_id}/{aid}"


def parse_broker(text: str) -> tuple[str, int]:
    """``HOST:PORT`` as ``(host, port)``; ValueError naming the form otherwise."""
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"{text!r} is not HOST:PORT (e.g. 127.0.0.1:1883)")
    return host, int(port)


def guard(agent: Any, run_id: str, roster: dict[str, Any]) -> None:
    """Make ``agent`` stamp ``run_id`` on what it sends and drop (counting
    ``agent.rejected``) what arrives with another run id or from a sender not on ``roster``
    (agent id -> address: a topic, or ``[host, port]``) or not at its roster address."""
    send, handle = agent.send_message, agent.handle_message
    agent.rejected = 0

    async def send_message(content, receiver_addr, **kwargs):
        return await send(content, receiver_addr=receiver_addr, run_id=run_id, **kwargs)

    def handle_message(content, meta: dict) -> None:
        sender = meta.get("sender_id")
        if (meta.get("run_id") != run_id or sender not in roster
                or not _same_address(meta.get("sender_addr"), roster[sender])):  # fmt: skip
            agent.rejected += 1
            return
        handle(content, meta)

    agent.send_message = send_message
    agent.handle_message = handle_message


def _same_address(given: Any, expected: Any) -> bool:
    """A topic, or ``(host, port)`` as a tuple or (after JSON) a list."""
    if isinstance(expected, tuple | list):
        return isinstance(given, tuple | list) and list(given) == list(expected)
    return given == expected


@dataclass(frozen=True)
class BrokerLogin:
    """How every agent connects to a broker: ``user`` and ``password`` (None: anonymous) and
    TLS when ``tls_ca`` is given (a PEM file of the CA certificates the broker's certificate
    is checked against), with the client certificate ``tls_cert`` (PEM; its key in
    ``tls_key``, or in the same file). The password is left out of ``repr`` and of
    :meth:`public`."""

    user: str | None = None
    password: str | None = field(default=None, repr=False)
    tls_ca: str | None = None
    tls_cert: str | None = None
    tls_key: str | None = None

    def public(self) -> dict:
        """Everything but the password (what a launched run writes to its configuration)."""
        return {"user": self.user, "tls_ca": self.tls_ca, "tls_cert": self.tls_cert,
                "tls_key": self.tls_key}  # fmt: skip

    def tls_kwargs(self) -> dict | None:
        """paho's ``tls_set`` arguments (mango's ``tls_kwargs``); None without TLS."""
        if self.tls_ca is None:
            return None
        return {"ca_certs": self.tls_ca, "certfile": self.tls_cert, "keyfile": self.tls_key}

    def apply(self, client) -> None:
        """Set the user name, password and TLS of a paho client (before it connects)."""
        if self.user is not None:
            client.username_pw_set(self.user, self.password)
        if self.tls_ca is not None:
            client.tls_set(**self.tls_kwargs())


def check_broker(broker: tuple[str, int], login: BrokerLogin | None = None,
                 timeout_s: float = LOGIN_TIMEOUT_S) -> None:  # fmt: skip
    """Connect to ``broker`` once as the agents will (``login``) and disconnect; a
    BrokerError naming the broker and the cause if it is not reachable, the TLS handshake
    fails, it refuses the login or it does not answer within ``timeout_s``."""
    import paho.mqtt.client as paho

    where = f"MQTT broker {broker[0]}:{broker[1]}"
    client = paho.Client(paho.CallbackAPIVersion.VERSION2,
                         client_id=f"popdispatch-check-{uuid.uuid4().hex[:8]}")  # fmt: skip
    (login or BrokerLogin()).apply(client)
    answer: list = []
    client.on_connect = lambda _c, _u, _flags, code, _p: answer.append(code)
    try:
        client.connect(broker[0], broker[1], keepalive=int(timeout_s) + 5)
        deadline = time.monotonic() + timeout_s
        while not answer and time.monotonic() < deadline:
            if client.loop(timeout=0.1) not in (paho.MQTT_ERR_SUCCESS, paho.MQTT_ERR_AGAIN):
                break  # the broker closed the connection
    except ssl.SSLError as exc:
        raise BrokerError(f"{where}: TLS handshake failed ({exc.reason or exc}): is --tls-ca "
                          "the CA that signed the broker's certificate?") from None  # fmt: skip
    except OSError as exc:
        raise BrokerError(f"{where} not reachable ({exc}): start one, or leave out --broker "
                          "to let the launch start its own") from None  # fmt: skip
    finally:
        client.disconnect()
    if not answer:
        raise BrokerError(f"{where} closed the connection or did not answer the login within "
                          f"{timeout_s:g} s{_unanswered_hint(login or BrokerLogin())}")  # fmt: skip
    if answer[0].is_failure:
        raise BrokerError(f"{where} refused the login: {answer[0]} (user "
                          f"{(login or BrokerLogin()).user or 'none: anonymous'}; "
                          f"--broker-user, password in {PASSWORD_ENV})")  # fmt: skip


def _unanswered_hint(login: BrokerLogin) -> str:
    """What a login the broker leaves unanswered may lack."""
    if login.tls_ca is None:
        return " (a TLS listener? give --tls-ca)"
    if login.tls_cert is None:
        return " (does it require a client certificate? give --tls-cert)"
    return ""


def mqtt_container(broker: tuple[str, int], client_id: str, inbox_topic: str, codec,
                   login: BrokerLogin | None = None):  # fmt: skip
    """mango's MQTT container on ``broker`` with ``login``'s TLS (mango's ``tls_kwargs``) and
    user name and password. mango builds its paho client when the container starts and takes
    no credentials, so the container starts with :data:`_LOGIN` set, which the paho module
    mango's MQTT module sees (:class:`_PahoLoggingIn`) hands to the clients it builds."""
    from mango import create_mqtt_container

    login = login or BrokerLogin()
    tls = login.tls_kwargs()
    container = create_mqtt_container(broker, client_id=client_id, inbox_topic=inbox_topic,
                                      codec=codec,
                                      **({"tls_kwargs": tls} if tls else {}))  # fmt: skip
    if login.user is not None:
        start = container.start

        async def start_logged_in() -> None:
            _PahoLoggingIn.install()
            token = _LOGIN.set((login.user, login.password))
            try:
                await start()
            finally:
                _LOGIN.reset(token)

        container.start = start_logged_in
    return container


#: The user name and password of the MQTT container starting in this context (an asyncio
#: task's own), None: anonymous.
_LOGIN: contextvars.ContextVar[tuple[str, str | None] | None] = contextvars.ContextVar(
    "popdispatch_mqtt_login", default=None
)


class _PahoLoggingIn:
    """``paho.mqtt.client`` as mango's MQTT module sees it: its ``Client`` logs in with
    :data:`_LOGIN` when that is set (everything else, and every client without it, is
    paho's own)."""

    def __init__(self, paho):
        self._paho = paho

    def __getattr__(self, name: str):
        return getattr(self._paho, name)

    def Client(self, *args, **kwargs):  # noqa: N802 (paho's name)
        client = self._paho.Client(*args, **kwargs)
        login = _LOGIN.get()
        if login is not None:
            client.username_pw_set(*login)
        return client

    @classmethod
    def install(cls) -> None:
        """Make mango's MQTT module see paho through this class (once per process)."""
        from mango.container import mqtt

        if not isinstance(mqtt.paho, cls):
            mqtt.paho = cls(mqtt.paho)


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


class Broker:
    """A mosquitto broker on ``host`` (default 127.0.0.1: this machine only) at a free port,
    as a context manager: started and reachable on entry, stopped (and waited for) on exit.
    ``address``: ``(host, port)``; ``options``: more lines of its listener's configuration
    (e.g. ``cafile``, ``certfile``, ``keyfile`` for TLS)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, options: str = ""):
        self.host, self.port = host, port or free_port(host)
        self.options = options
        self.process: subprocess.Popen | None = None
        self._folder: tempfile.TemporaryDirectory | None = None

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port

    def __enter__(self) -> Broker:
        exe = shutil.which("mosquitto") or next(
            (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()),
            None,
        )
        if exe is None:
            raise BrokerError("no MQTT broker: install mosquitto (apt-get install mosquitto) "
                              "or give one with --broker HOST:PORT")  # fmt: skip
        self._folder = tempfile.TemporaryDirectory(prefix="popdispatch-broker-")
        config = Path(self._folder.name) / "mosquitto.conf"
        config.write_text(f"listener {self.port} {self.host}\nallow_anonymous true\n"
                          f"persistence false\n{self.options}\n")  # fmt: skip
        log = open(Path(self._folder.name) / "mosquitto.log", "w")  # noqa: SIM115
        with log:
            self.process = subprocess.Popen([exe, "-c", str(config)], stdout=log, stderr=log,
                                            stdin=subprocess.DEVNULL, start_new_session=True)
        try:
            self._wait_reachable()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _wait_reachable(self) -> None:
        deadline = time.monotonic() + BROKER_START_S
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise BrokerError(f"mosquitto exited {self.process.returncode} on "
                                  f"{self.host}:{self.port}: {self._log_tail()}")  # fmt: skip
            with contextlib.suppress(OSError), socket.create_connection(self.address, 0.2):
                return
            time.sleep(0.05)
        raise BrokerError(f"mosquitto not reachable on {self.host}:{self.port} after "
                          f"{BROKER_START_S:g} s")  # fmt: skip

    def _log_tail(self) -> str:
        log = Path(self._folder.name) / "mosquitto.log"
        lines = log.read_text().strip().splitlines() if log.exists() else []
        return lines[-1] if lines else "no message"

    def __exit__(self, *exc) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self._folder is not None:
            self._folder.cleanup()
