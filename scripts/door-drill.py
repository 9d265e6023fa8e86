#!/usr/bin/env python3
"""The doors drill (docs/web.md "Hostile load", issue 34): floods a valvebench-server of its own, on loopback
only (127.0.0.1, its own temporary directory and ports), with the requests, connections and streams of issue 34,
each bounded in count and time, and prints per flood what the attacker got, the server's RSS and CPU, and the
page's latency for another client meanwhile (GET / and GET /api/benches every 50 ms). Then SIGTERM under slow
imports: the time until the process has exited.

Usage: scripts/door-drill.py [--build DIR] [--keep]
  --build  the build tree with bin/valvebench-server (default: build)
Exit 0 when every flood was bounded (page p99 < 100 ms where the issue asks it, the server up after each, SIGTERM
within 5 s); 1 otherwise; 2 bad usage; 3 the server did not start.
"""
import argparse
import hashlib
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time

VIEWER, OPERATOR = "drill-viewer-token", "drill-operator-token"
HOST = "127.0.0.1"  # loopback only, by construction: the server is this drill's own


def sha(t):
    return hashlib.sha256(t.encode()).hexdigest()


def rss_kib(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return -1


def cpu_s(pid):
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def fds(pid):
    return len(os.listdir(f"/proc/{pid}/fd"))


def connect(port, src=None, timeout=5.0):
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.settimeout(timeout)
    if src:
        s.bind((src, 0))
    s.connect((HOST, port))
    return s


def exchange(port, raw, timeout=5.0, src=None):
    """One request on a fresh connection: (status, bytes of the answer)."""
    try:
        s = connect(port, src, timeout)
        s.sendall(raw)
        data = bytearray()
        head_end, length = -1, None
        while True:
            if head_end < 0:
                head_end = data.find(b"\r\n\r\n")
                if head_end >= 0:
                    for line in data[:head_end].decode("latin-1").split("\r\n")[1:]:
                        k, _, v = line.partition(":")
                        if k.lower() == "content-length":
                            length = int(v.strip())
            if head_end >= 0 and (raw.startswith(b"HEAD") or (length is not None and len(data) >= head_end + 4 + length)):
                break
            chunk = s.recv(1 << 20)
            if not chunk:
                break
            data += chunk
        s.close()
        return int(data[9:12]) if data.startswith(b"HTTP/1.") else 0, len(data)
    except OSError:
        return 0, 0


class PageProbe:
    """Another client (127.0.0.9): GET / and GET /api/benches every 50 ms; latency of each pair."""

    def __init__(self, port):
        self.port, self.times, self.failed, self.stop = port, [], 0, threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def run(self):
        while not self.stop.is_set():
            t0 = time.monotonic()
            a, _ = exchange(self.port, b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", 5.0, "127.0.0.9")
            b, _ = exchange(self.port, f"GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {VIEWER}\r\n\r\n"
                            .encode(), 5.0, "127.0.0.9")
            if a == 200 and b == 200:
                self.times.append(time.monotonic() - t0)
            else:
                self.failed += 1
            self.stop.wait(0.05)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *a):
        self.stop.set()
        self.thread.join()

    def summary(self):
        if not self.times:
            return f"page: no answer ({self.failed} failed)", float("inf")
        t = sorted(self.times)
        p99 = t[min(len(t) - 1, int(0.99 * len(t)))]
        return (f"page p50 {statistics.median(t) * 1e3:.1f} ms, p99 {p99 * 1e3:.1f} ms, max {t[-1] * 1e3:.1f} ms, "
                f"{self.failed} failed of {len(t) + self.failed}"), p99


def start_server(build, work):
    cfg = {
        "listen_address": f"{HOST}:0", "database_path": os.path.join(work, "runs.db"),
        "benches": [{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}},
                    {"name": "emu-b", "kind": "emulated", "model": {"preset": "taghizadeh2009"}}],
        "tokens": [{"user": "viewer", "role": "viewer", "token_sha256": sha(VIEWER)},
                   {"user": "olga", "role": "operator", "token_sha256": sha(OPERATOR)}],
        "web": {"listen_address": f"{HOST}:0"},
    }
    with open(os.path.join(work, "server.json"), "w") as f:
        json.dump(cfg, f)
    log = open(os.path.join(work, "server.log"), "w+")
    proc = subprocess.Popen([os.path.join(build, "bin", "valvebench-server"), "--config",
                             os.path.join(work, "server.json")], stderr=log, stdout=subprocess.DEVNULL)
    grpc_port = web_port = 0
    for _ in range(400):
        log.seek(0)
        text = log.read()
        if "listening on " in text and "web dashboard on " in text:
            grpc_port = int(text.split("listening on ")[1].split()[0].rsplit(":", 1)[1])
            web_port = int(text.split("web dashboard on http://127.0.0.1:")[1].split("/")[0])
            break
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    return proc, grpc_port, web_port, log


def grpc_answers(port):
    """HTTP/2's preface and an empty SETTINGS: a listening gRPC server answers with its SETTINGS frame."""
    try:
        s = connect(port, timeout=3.0)
        s.sendall(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + b"\x00\x00\x00\x04\x00\x00\x00\x00\x00")
        data = s.recv(64)
        s.close()
        return len(data) >= 9 and data[3] == 4
    except OSError:
        return False


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default="build")
    ap.add_argument("--keep", action="store_true")
    args = ap.parse_args()
    work = tempfile.mkdtemp(prefix="door-drill-")
    proc, grpc_port, web_port, log = start_server(args.build, work)
    if not web_port:
        log.seek(0)
        print(log.read()[-3000:], file=sys.stderr)
        return 3
    pid, ok = proc.pid, True
    print(f"door-drill: server pid {pid}, gRPC {grpc_port}, web {web_port}, work {work}")

    def flood(name, body, page_limit_s=0.1):
        nonlocal ok
        r0, c0 = rss_kib(pid), cpu_s(pid)
        with PageProbe(web_port) as probe:
            time.sleep(0.2)
            what = body()
            time.sleep(0.2)
        r1, c1 = rss_kib(pid), cpu_s(pid)
        page, p99 = probe.summary()
        up = exchange(web_port, f"GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {VIEWER}\r\n\r\n"
                      .encode())[0] == 200
        bounded = up and p99 < page_limit_s
        ok &= bounded
        print(f"  {name}: {what}; RSS {r0 / 1024:.0f} -> {r1 / 1024:.0f} MiB, server CPU {c1 - c0:.2f} s; {page}; "
              f"{'up' if up else 'DOWN'}{'' if bounded else '  <-- NOT BOUNDED'}")

    def ranges():
        req = b"GET /dygraph.min.js HTTP/1.1\r\nHost: x\r\nRange: bytes=0-" + b",0-" * 2699 + b"\r\n\r\n"
        got = [exchange(web_port, req, 10.0) for _ in range(20)]
        return f"20 x 2,700 ranges, no token: status {sorted(set(g[0] for g in got))}, {max(g[1] for g in got)} bytes each"

    def slow_heads():
        socks = []
        for k in range(600):
            try:
                s = connect(web_port, f"127.0.0.{2 + k % 5}")
                s.sendall(b"GET /api/benches HTTP/1.1\r\nHost: x\r\n")
                socks.append(s)
            except OSError:
                pass
        time.sleep(2.0)
        for s in socks:
            s.close()
        return f"{len(socks)} slow heads from 5 addresses held 2 s"

    def trickled_bodies():
        socks = []
        for k in range(66):
            s = connect(web_port, f"127.0.0.{2 + k % 2}")
            s.sendall(f"POST /api/runs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nAuthorization: "
                      f"Bearer {OPERATOR}\r\nContent-Length: 100000\r\n\r\n{{".encode())
            socks.append(s)
        for _ in range(10):
            for s in socks:
                try:
                    s.send(b" ")
                except OSError:
                    pass
            time.sleep(0.3)
        for s in socks:
            s.close()
        return "66 bodies trickled from 2 addresses for 3 s"

    def unauthenticated_import():
        got = exchange(web_port, b"POST /api/import HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                                 b"Content-Length: 8000000\r\n\r\n{", 5.0)
        return f"an 8 MB import without a token: status {got[0]} before the body"

    def brotli():
        got = [exchange(web_port, b"GET /dygraph.min.js HTTP/1.1\r\nHost: x\r\nAccept-Encoding: br\r\n\r\n")
               for _ in range(50)]
        return f"50 asset requests asking for brotli: {got[0][1]} bytes each"

    def idle_grpc():
        socks, f0 = [], fds(pid)
        for _ in range(1100):
            try:
                socks.append(connect(grpc_port))
            except OSError:
                break
        time.sleep(0.5)
        f1 = fds(pid)
        answers = grpc_answers(grpc_port)
        for s in socks:
            s.close()
        nonlocal ok
        ok &= answers
        return f"{len(socks)} idle TCP connections to gRPC: server fds {f0} -> {f1}, gRPC answers: {answers}"

    def bearer_guesses():
        got = [exchange(web_port, f"GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer guess{k}\r\n\r\n"
                        .encode(), src="127.0.0.7")[0] for k in range(30)]
        return f"30 bearer guesses from one address: {got.count(401)} x 401, then {got.count(429)} x 429"

    print("door-drill: floods (each bounded in count and time; the page is another client's)")
    flood("ranges", ranges)
    flood("slow heads", slow_heads)
    flood("trickled bodies", trickled_bodies)
    flood("import without token", unauthenticated_import)
    flood("brotli", brotli)
    flood("idle gRPC", idle_grpc)
    flood("bearer guesses", bearer_guesses)

    # SIGTERM with slow imports in flight.
    socks = []
    for _ in range(8):
        s = connect(web_port)
        s.sendall(f"POST /api/import HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nAuthorization: Bearer "
                  f"{OPERATOR}\r\nContent-Length: 4000000\r\n\r\n{{\"dataset\": \"d\", \"files\": {{\"a.csv\": \""
                  .encode())
        socks.append(s)
    time.sleep(0.5)
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    try:
        rc = proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        rc = proc.wait()
    exit_s = time.monotonic() - t0
    for s in socks:
        s.close()
    ok &= rc == 0 and exit_s < 5.0
    print(f"  SIGTERM with 8 slow imports in flight: exit {rc} after {exit_s:.2f} s")
    print(f"door-drill: {'bounded' if ok else 'NOT BOUNDED'}")
    if not args.keep:
        subprocess.run(["rm", "-rf", work])
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
