"""``agents launch --transport mqtt --broker`` on a broker that wants a login, TLS and a client
certificate (a mosquitto with a password file and a TLS listener whose certificate the test's
own CA signed; ``require_certificate``): with the user, the password (from the environment),
the CA and the client certificate the congestion minute reaches the DC-OPF (Clarabel) within
0.01 kW, and the password is on no process's command line and in no file of the run. A wrong
password, no login, no TLS, no client certificate or another CA: exit 1 in one line naming the
broker and the refusal, before any agent starts. Usage errors: exit 2 in one line."""

from __future__ import annotations

import json
import os
import shutil
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
for tool in ("openssl", "mosquitto_passwd"):
    if shutil.which(tool) is None:
        pytest.skip(f"no {tool} (apt-get install openssl mosquitto)",
                    allow_module_level=True)  # fmt: skip

from popdispatch.agents.transport import PASSWORD_ENV, Broker  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402

USER, PASSWORD = "agent", "s3cret-Pw"


def _openssl(folder: Path, *args: str) -> None:
    subprocess.run(["openssl", *args], cwd=folder, check=True, capture_output=True)


def _ca(folder: Path, name: str) -> None:
    """A self-signed CA: ``name.pem``, ``name.key``."""
    _openssl(folder, "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj",
             f"/CN={name}", "-keyout", f"{name}.key", "-out", f"{name}.pem")  # fmt: skip


def _signed(folder: Path, name: str, subject: str, extensions: str = "") -> None:
    """A key and a certificate ``name.pem`` for ``subject`` signed by ``ca.pem``."""
    _openssl(folder, "req", "-newkey", "rsa:2048", "-nodes", "-subj", subject, "-keyout",
             f"{name}.key", "-out", f"{name}.csr")  # fmt: skip
    (folder / f"{name}.ext").write_text(extensions + "\n")
    _openssl(folder, "x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
             "-CAcreateserial", "-days", "1", "-extfile", f"{name}.ext", "-out",
             f"{name}.pem")  # fmt: skip


@pytest.fixture(scope="module")
def secured(tmp_path_factory):
    """A mosquitto on 127.0.0.1 over TLS only, asking for a client certificate and a user
    name and password (no anonymous login); yields ``(broker, files)``."""
    folder = tmp_path_factory.mktemp("secured-broker")
    _ca(folder, "ca")
    _ca(folder, "other-ca")  # a CA that signed nothing of this broker's
    _signed(folder, "server", "/CN=127.0.0.1", "subjectAltName=IP:127.0.0.1")
    _signed(folder, "client", f"/CN={USER}")
    _openssl(folder, "pkey", "-in", "client.key", "-aes256", "-passout", "pass:key-pw", "-out",
             "encrypted.key")  # fmt: skip
    passwords = folder / "passwords"
    passwords.touch()
    subprocess.run(["mosquitto_passwd", "-b", str(passwords), USER, PASSWORD], check=True,
                   capture_output=True)  # fmt: skip
    files = {name: str(folder / name) for name in ("ca.pem", "other-ca.pem", "client.pem",
                                                   "client.key", "encrypted.key")}  # fmt: skip
    options = (f"allow_anonymous false\npassword_file {passwords}\ncafile {folder / 'ca.pem'}\n"
               f"certfile {folder / 'server.pem'}\nkeyfile {folder / 'server.key'}\n"
               "require_certificate true")  # fmt: skip
    if os.geteuid() == 0:  # mosquitto started as root reads the files as its own user
        options += "\nuser root"
    with Broker(options=options) as broker:
        yield broker, files


def _login_args(files: dict) -> list[str]:
    return ["--broker-user", USER, "--tls-ca", files["ca.pem"], "--tls-cert",
            files["client.pem"], "--tls-key", files["client.key"]]  # fmt: skip


def _launch(broker, args: list[str], tmp: Path, password: str | None = PASSWORD,
            rounds: int = 160) -> subprocess.Popen:  # fmt: skip
    """``agents launch`` over MQTT on ``broker`` as a process; its run folders in ``tmp``."""
    env = {k: v for k, v in os.environ.items() if k != PASSWORD_ENV} | {"TMPDIR": str(tmp)}
    if password is not None:
        env[PASSWORD_ENV] = password
    command = [sys.executable, "-m", "popdispatch.cli", "agents", "launch", "--minute", "566",
               "--limit", "505:666=28", "--rounds", str(rounds), "--startup-s", "300",
               "--transport", "mqtt", "--broker", f"{broker.host}:{broker.port}", "--json",
               "-q", *args]  # fmt: skip
    return subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)  # fmt: skip


def _left(tmp: Path) -> int:
    """Processes whose command line names ``tmp`` (this test's agent processes)."""
    found = subprocess.run(["pgrep", "-f", str(tmp)], capture_output=True, text=True)
    return len(found.stdout.split())


class Watcher:
    """While a launch runs: the command lines of the launcher and its children and the run's
    files, as seen from outside (``ps``, the file system)."""

    def __init__(self, launcher: subprocess.Popen, tmp: Path):
        self.launcher, self.tmp = launcher, tmp
        self.command_lines: dict[int, str] = {}
        self.files: dict[str, str] = {}
        self.thread = threading.Thread(target=self._watch, daemon=True)
        self.thread.start()

    def _watch(self) -> None:
        while self.launcher.poll() is None:
            pids = [self.launcher.pid] + [int(p) for p in subprocess.run(
                ["pgrep", "-P", str(self.launcher.pid)], capture_output=True, text=True
            ).stdout.split()]  # fmt: skip
            for pid in pids:
                try:
                    line = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ")
                except OSError:
                    continue
                if line.strip():  # empty once the process has exited
                    self.command_lines[pid] = line.decode()
            for path in self.tmp.glob("popdispatch-launch-*/*"):
                try:
                    self.files[str(path)] = path.read_text(errors="replace")
                except OSError:
                    continue
            time.sleep(0.5)


def test_launch_with_login_tls_and_client_certificate(secured, congestion_problem, tmp_path):
    broker, files = secured
    launcher = _launch(broker, _login_args(files), tmp_path)
    watcher = Watcher(launcher, tmp_path)
    out, err = launcher.communicate(timeout=600)
    watcher.thread.join(timeout=10)
    assert launcher.returncode == 0, err
    s = json.loads(out)
    assert s["transport"] == "mqtt" and s["broker"] == f"{broker.host}:{broker.port}"
    # every round the plant was asked for happened or is reported missed (real time: a
    # loaded machine can make a process miss a tick)
    assert s["processes"] == 12 and s["rounds"] + s["missed_ticks"] >= 160
    setpoints = np.array([g["setpoint_kw"] for g in s["generators"]])
    opf = solve_opf(congestion_problem, 566)
    assert np.abs(setpoints - opf.p_kw).max() < 0.01, f"{s['missed_ticks']} ticks missed"  # kW
    assert setpoints.sum() == pytest.approx(congestion_problem.demand[565] * 1e3, abs=1e-6)
    # every agent process seen; the password on no command line and in no file of the run
    agents = [line for line in watcher.command_lines.values()
              if "popdispatch.agents.launch --id" in line]  # fmt: skip
    assert len(agents) == 12
    assert any(f"--broker-user {USER} " in line for line in watcher.command_lines.values())
    assert not [line for line in watcher.command_lines.values() if PASSWORD in line]
    config = next(text for path, text in watcher.files.items() if path.endswith("config.json"))
    assert f'"user": "{USER}"' in config
    assert not [path for path, text in watcher.files.items() if PASSWORD in text]
    assert _left(tmp_path) == 0


@pytest.mark.parametrize(
    ("case", "says"),
    [
        ("wrong password", "refused the login: Not authorized (user agent;"),
        ("no login", "refused the login: Not authorized (user none: anonymous;"),
        ("no TLS", "closed the connection or did not answer the login within 5 s (a TLS "
         "listener? give --tls-ca)"),
        ("no client certificate", "give --tls-cert)"),
        ("another CA", "TLS handshake failed (CERTIFICATE_VERIFY_FAILED)"),
    ],
)  # fmt: skip
def test_refused_login_is_one_line(secured, tmp_path, case, says):
    broker, files = secured
    args, password = _login_args(files), PASSWORD
    if case == "wrong password":
        password = "wrong"
    elif case == "no login":
        args = args[2:]
    elif case == "no TLS":
        args = args[:2]
    elif case == "no client certificate":
        args = args[:4]
    elif case == "another CA":
        args[3] = files["other-ca.pem"]
    launcher = _launch(broker, args, tmp_path, password)
    out, err = launcher.communicate(timeout=120)
    assert launcher.returncode == 1 and out == ""
    assert len(err.strip().splitlines()) == 1, err
    assert f"MQTT broker {broker.host}:{broker.port}" in err and says in err
    assert not list(tmp_path.glob("popdispatch-launch-*"))  # refused before any agent started
    assert _left(tmp_path) == 0


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--broker-user", USER], "--broker-user needs --broker"),
        (["--broker", "127.0.0.1:1", "--broker-user", USER],
         f"--broker-user needs the password in the environment variable {PASSWORD_ENV}"),
        (["--broker", "127.0.0.1:1", "--tls-ca", "no-such-ca.pem"],
         "--tls-ca: File 'no-such-ca.pem' does not exist"),
        (["--broker", "127.0.0.1:1", "--tls-ca", __file__], "no CA certificate ssl can read"),
        (["--broker", "127.0.0.1:1", "--tls-cert", __file__], "--tls-cert needs --tls-ca"),
        (["--broker", "127.0.0.1:1", "--tls-ca", "CA", "--tls-key", __file__],
         "--tls-key needs --tls-cert"),
        (["--broker", "127.0.0.1:1", "--tls-ca", "CA", "--tls-cert", __file__],
         "no certificate and key ssl can read"),
        (["--broker", "127.0.0.1:1", "--tls-ca", "CA", "--tls-cert", "CERT", "--tls-key",
          "ENCRYPTED"], "encrypted.key: the key is encrypted"),
    ],
)  # fmt: skip
def test_bad_login_options_are_usage_errors(secured, args, says):
    _, files = secured
    named = {"CA": "ca.pem", "CERT": "client.pem", "ENCRYPTED": "encrypted.key"}
    args = [files[named[a]] if a in named else a for a in args]
    env = {k: v for k, v in os.environ.items() if k != PASSWORD_ENV}
    done = subprocess.run(
        [sys.executable, "-m", "popdispatch.cli", "agents", "launch", "--minute", "566", "-q",
         "--transport", "mqtt", *args], capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip
    assert done.returncode == 2
    assert len(done.stderr.strip().splitlines()) == 1 and says in done.stderr, done.stderr


def test_login_is_the_starting_containers_own(secured):
    """Two agents' containers start at once in one process, one with the login, one without
    (both with TLS and the client certificate): the first is connected as the user, the
    broker refuses the second; a container started afterwards without the login is refused
    too (the login does not stay behind)."""
    import asyncio

    from popdispatch.agents.launch import _codec
    from popdispatch.agents.transport import BrokerLogin, mqtt_container

    broker, files = secured
    tls = {"tls_ca": files["ca.pem"], "tls_cert": files["client.pem"],
           "tls_key": files["client.key"]}  # fmt: skip

    def container(name: str, login: BrokerLogin):
        return mqtt_container(broker.address, name, f"test/{name}", _codec(), login)

    async def start_both():
        with_login = container("with", BrokerLogin(USER, PASSWORD, **tls))
        without = container("without", BrokerLogin(**tls))
        started = await asyncio.gather(with_login.start(), without.start(),
                                       return_exceptions=True)  # fmt: skip
        user = with_login.mqtt_client.username
        connected = with_login.mqtt_client.is_connected()
        await with_login.shutdown()
        later = await asyncio.gather(container("later", BrokerLogin(**tls)).start(),
                                     return_exceptions=True)  # fmt: skip
        return started, user, connected, later[0]

    started, user, connected, later = asyncio.run(start_both())
    assert started[0] is None and connected and user == USER
    for refused in (started[1], later):
        assert isinstance(refused, ConnectionError) and "Not authorized" in str(refused)
