"""Local mode: a private valvebench-server on loopback (a free port), with emulated benches and the user's
local store.

The Python client talks gRPC to it exactly as to a remote server, so local and remote share one code path
(docs/decisions.md). The server binary comes from $VALVEBENCH_BIN_DIR, the build tree this package was built
in, or PATH. The store is the one ``benchctl run --local`` uses: ``db`` if given, else $VALVEBENCH_DB, else
~/.local/share/valvebench/local.db, so runs made either way are listed, compared and exported together.

On an emulated bench the server runs the bench's configured model (docs/server.md); the private server
therefore gets one bench per preset and, on demand, one bench per distinct model a spec asks for (a preset with
params or effects), and the spec is pinned to that bench by name.

Sharing the store: a server start re-queues every run the store marks running (its crash recovery), which
would break a run that benchctl --local or another private server is executing at that moment. So one store
has at most one private server (an flock on <db>.server-lock; a second one is refused, naming the store), and
a start waits for runs benchctl --local is executing (bench kind "local") to finish.
"""
import atexit
import ctypes
import fcntl
import hashlib
import json
import os
import pwd
import re
import secrets
import shutil
import signal
import sqlite3
import subprocess
import tempfile
import threading
import time
import urllib.parse

from .errors import InvalidArgument, Unavailable

PRESETS = ("taghizadeh2009", "lunge2013", "ts98_coil")


def find_tool(name):
    """Path of a valvebench binary (valvebench-server, benchctl): $VALVEBENCH_BIN_DIR, the build tree, PATH."""
    candidates = []
    if os.environ.get("VALVEBENCH_BIN_DIR"):
        candidates.append(os.path.join(os.environ["VALVEBENCH_BIN_DIR"], name))
    try:
        from . import _build_paths
        candidates.append(os.path.join(_build_paths.BIN_DIR, name))
    except ImportError:
        pass
    for c in candidates:
        if os.access(c, os.X_OK):
            return c
    found = shutil.which(name)
    if found:
        return found
    raise Unavailable("%s not found: build the project (README) or set VALVEBENCH_BIN_DIR (looked in %s and PATH)"
                      % (name, ", ".join(candidates) or "no build tree"))


def default_store_path():
    """The local store benchctl --local uses: $VALVEBENCH_DB, else ~/.local/share/valvebench/local.db."""
    if os.environ.get("VALVEBENCH_DB"):
        return os.environ["VALVEBENCH_DB"]
    home = os.environ.get("HOME")
    if home:
        return os.path.join(home, ".local", "share", "valvebench", "local.db")
    return os.path.abspath("valvebench-local.db")


_SHARED = {}  # store path -> [LocalServer, number of clients]: one private server per store in a process
_SHARED_LOCK = threading.Lock()


def acquire(db=None):
    """The private server of a store for one more client of this process: started on first use, shared by
    every Client of the process on that store (re-running a notebook cell reuses it)."""
    path = os.path.abspath(db or default_store_path())
    with _SHARED_LOCK:
        entry = _SHARED.get(path)
        if entry is not None and entry[0].running():
            entry[1] += 1
            return entry[0]
        server = LocalServer(path)
        _SHARED[path] = [server, 1]
        return server


def release(server):
    """One client fewer; the last one stops the server."""
    with _SHARED_LOCK:
        entry = _SHARED.get(server.db)
        if entry is not None and entry[0] is server:
            entry[1] -= 1
            if entry[1] > 0:
                return
            del _SHARED[server.db]
    server.stop()


def _die_with_parent():
    # PR_SET_PDEATHSIG: the private server gets SIGTERM (safe state, exit) if this Python process dies. Linux
    # sends it when the *thread* that started the server ends, so a Client made in a short-lived worker thread
    # loses its private server with that thread (make local clients in a thread that lives as long as they do).
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)
    except Exception:
        pass


def model_key(model):
    """A short stable name for a model dict (preset + params + effects)."""
    text = json.dumps(model, sort_keys=True)
    return "model-" + hashlib.sha256(text.encode()).hexdigest()[:10]


class LocalServer:
    """A private valvebench-server on 127.0.0.1 (any free port), its config and log in a temporary directory,
    stopped by ``stop()``, at exit, or when this process dies. ``address`` and ``token`` are what a Client
    needs; the token is random and only this process knows it (the config stores its SHA-256).

    Not a Unix socket: the server accepts ``unix:PATH``, but with Debian's gRPC 1.51 its shutdown then stalls
    for seconds after trace streams (docs/decisions.md)."""

    def __init__(self, db=None, server_bin=None, start_timeout_s=20.0, benchctl_wait_s=30.0):
        self.db = os.path.abspath(db or default_store_path())
        os.makedirs(os.path.dirname(self.db), exist_ok=True)
        self.server_bin = server_bin or find_tool("valvebench-server")
        self.benchctl_wait_s = benchctl_wait_s
        self._lock = open(self.db + ".server-lock", "a+")
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._lock.close()
            raise Unavailable("local store %s: another process's private valvebench-server is using it (one per "
                              "store: its start would re-queue that server's running runs); pass db= another "
                              "file (or VALVEBENCH_DB), or share a valvebench-server via VALVEBENCH_SERVER"
                              % self.db) from None
        self.dir = tempfile.mkdtemp(prefix="valvebench-")
        self.address = None
        self.token = secrets.token_urlsafe(24)
        self.start_timeout_s = start_timeout_s
        self._benches = [{"name": "local-" + p, "kind": "emulated", "model": {"preset": p}} for p in PRESETS]
        self._models = {}
        self._proc = None
        self._log = None
        try:
            self._start()
        except BaseException:
            self.stop()
            raise
        atexit.register(self.stop)

    def _config(self):
        # $USER, else the account's name (a cron job or `env -i` has no $USER), as the C++ local service does.
        try:
            user = os.environ.get("USER") or pwd.getpwuid(os.getuid()).pw_name or "local"
        except KeyError:
            user = "local"
        return {
            "listen_address": "127.0.0.1:0",
            "database_path": self.db,
            "benches": self._benches,
            "tokens": [{"user": user, "role": "admin",
                        "token_sha256": hashlib.sha256(self.token.encode()).hexdigest()}],
        }

    def _benchctl_running(self):
        """Ids of runs benchctl --local is executing in the store now (read-only peek; [] without a store)."""
        if not os.path.exists(self.db):
            return []
        try:
            con = sqlite3.connect("file:%s?mode=ro" % urllib.parse.quote(self.db), uri=True, timeout=5)
            try:
                rows = con.execute("SELECT id FROM runs WHERE status = 'running' AND bench_kind = 'local'").fetchall()
            finally:
                con.close()
        except sqlite3.Error:  # an empty file or another schema: nothing of benchctl's to protect
            return []
        return [r[0] for r in rows]

    def _start(self):
        deadline = time.monotonic() + self.benchctl_wait_s
        busy = self._benchctl_running()
        while busy and time.monotonic() < deadline:
            time.sleep(0.05)
            busy = self._benchctl_running()
        if busy:
            raise Unavailable("local store %s: benchctl --local is still executing run(s) %s after %g s; starting "
                              "the private server now would re-queue them. Wait for them, or pass db= another file"
                              % (self.db, ", ".join(map(str, busy)), self.benchctl_wait_s))
        path = os.path.join(self.dir, "server.json")
        with open(path, "w") as f:
            json.dump(self._config(), f)
        self._log = open(os.path.join(self.dir, "server.log"), "a+")
        self._log_start = self._log.tell()
        self._proc = subprocess.Popen([self.server_bin, "--config", path], stdout=subprocess.DEVNULL,
                                      stderr=self._log, stdin=subprocess.DEVNULL, preexec_fn=_die_with_parent)
        deadline = time.monotonic() + self.start_timeout_s
        while time.monotonic() < deadline:
            if self._proc.poll() is not None:
                raise Unavailable("valvebench-server (local) exited with code %d: %s"
                                  % (self._proc.returncode, self.log_tail()))
            m = re.search(r"listening on (\S+)", self.log_tail(100000))
            if m:
                self.address = m.group(1)
                return
            time.sleep(0.01)
        self.stop()
        raise Unavailable("valvebench-server (local) did not start within %g s: %s"
                          % (self.start_timeout_s, self.log_tail()))

    def log_tail(self, n_chars=2000):
        """The end of the server's log (this start only)."""
        if self._log is None:
            return ""
        self._log.flush()
        with open(self._log.name) as f:
            f.seek(self._log_start)
            return f.read()[-n_chars:]

    def bench_for_model(self, model):
        """The bench name that runs ``model`` (a ModelSpec dict). A bare preset runs on that preset's bench; a
        model with params or effects gets its own bench (the server restarts once to add it; queued runs are
        durable and resume)."""
        preset = model.get("preset") or "taghizadeh2009"
        if preset not in PRESETS:
            raise InvalidArgument("bench.model.preset: '%s' is not one of %s" % (preset, ", ".join(PRESETS)))
        if not model.get("params") and not model.get("effects"):
            return "local-" + preset
        key = model_key(model)
        if key not in self._models:
            self._benches.append({"name": key, "kind": "emulated", "model": model})
            self._models[key] = model
            self._stop_process()
            self._start()
        return key

    def _stop_process(self):
        if self._proc is not None and self._proc.poll() is None:
            self._proc.send_signal(signal.SIGTERM)
            try:
                self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        if self._log is not None:
            self._log.close()
            self._log = None

    def stop(self):
        """SIGTERM (the benches go to their safe state), then remove the temporary directory."""
        self._stop_process()
        self._proc = None
        shutil.rmtree(self.dir, ignore_errors=True)
        if self._lock is not None:
            self._lock.close()  # releases the flock
            self._lock = None

    def running(self):
        return self._proc is not None and self._proc.poll() is None
