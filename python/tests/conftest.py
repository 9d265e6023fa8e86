"""Fixtures for the package's own tests: the checkout, a private local client on a temporary store, and a real
valvebench-server on loopback with viewer and operator tokens (as a remote user meets it)."""
import hashlib
import json
import os
import re
import signal
import subprocess
import time

import pytest

import valvebench

try:
    from valvebench import _build_paths
    SOURCE_DIR = _build_paths.SOURCE_DIR
except ImportError:
    SOURCE_DIR = os.environ["VALVEBENCH_SOURCE_DIR"]

OPERATOR, VIEWER = "py-operator-token", "py-viewer-token"


@pytest.fixture(scope="session")
def repo():
    return SOURCE_DIR


@pytest.fixture(scope="session")
def shared():
    path = os.path.join(SOURCE_DIR, "..", "shared")
    return os.path.abspath(path)


@pytest.fixture(scope="module")
def local_client(tmp_path_factory):
    db = tmp_path_factory.mktemp("store") / "local.db"
    with valvebench.Client.local(db=str(db)) as c:
        yield c


def start_server(work, config, *args):
    """Starts valvebench-server with `config` (a dict) in `work`: returns (process, log file, address)."""
    (work / "server.json").write_text(json.dumps(config))
    log = open(work / "server.log", "w+")
    proc = subprocess.Popen([valvebench.find_tool("valvebench-server"), "--config", str(work / "server.json"), *args],
                            stderr=log, stdout=subprocess.DEVNULL)
    address = None
    for _ in range(400):
        log.seek(0)
        m = re.search(r"listening on (\S+)", log.read())
        if m:
            address = m.group(1)
            break
        time.sleep(0.02)
    assert address, "server did not start"
    return proc, log, address


@pytest.fixture(scope="module")
def remote_server(tmp_path_factory):
    """A valvebench-server on 127.0.0.1 (free port): yields its address."""
    work = tmp_path_factory.mktemp("server")
    config = {"listen_address": "127.0.0.1:0", "database_path": "runs.db",
              "benches": [{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}},
                          {"name": "emu-b", "kind": "emulated", "model": {"preset": "taghizadeh2009"}}],
              "tokens": [{"user": "op", "role": "operator", "token_sha256": hashlib.sha256(OPERATOR.encode()).hexdigest()},
                         {"user": "view", "role": "viewer", "token_sha256": hashlib.sha256(VIEWER.encode()).hexdigest()}]}
    proc, _, address = start_server(work, config)
    yield address
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=10)
