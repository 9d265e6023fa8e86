#!/usr/bin/python3
"""The doors drill (docs/web.md "Hostile load", issue 34): floods a valvebench-server of its own, on loopback
only (127.0.0.1, its own temporary directory and ports), with the requests, connections and streams of issue 34,
each bounded in count and time, and prints per flood what the attacker got, the server's RSS and CPU, and the
page's latency for another client meanwhile (GET / and GET /api/benches every 50 ms) and, for the gRPC floods, an
authenticated ListBenches's latency. A second server of its own serves the dashboard over TLS (a fresh RSA-2048
certificate, openssl) for the handshake flood. Then SIGTERM under slow imports: the time until the process has
exited. Needs Debian's python3-grpcio (scripts/setup.sh) for the gRPC floods: run it with /usr/bin/python3.

Usage: scripts/door-drill.py [--build DIR] [--keep] [--only NAME]
  --build  the build tree with bin/valvebench-server (default: build)
Exit 0 when every flood was bounded (page p99 < 100 ms where the issue asks it, the server up after each, SIGTERM
within 5 s); 1 otherwise; 2 bad usage; 3 the server did not start.
"""
import argparse
import hashlib
import json
import multiprocessing
import os
import resource
import signal
import socket
import ssl
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


TLS_CLIENT = ssl.create_default_context()
TLS_CLIENT.check_hostname = False
TLS_CLIENT.verify_mode = ssl.CERT_NONE


def connect(port, src=None, timeout=5.0, tls=False):
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.settimeout(timeout)
    if src:
        s.bind((src, 0))
    s.connect((HOST, port))
    return TLS_CLIENT.wrap_socket(s) if tls else s


def exchange(port, raw, timeout=5.0, src=None, tls=False):
    """One request on a fresh connection: (status, bytes of the answer)."""
    try:
        s = connect(port, src, timeout, tls)
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


class Background:
    """A thread that calls self.tick() every self.every_s while the `with` block runs."""

    every_s = 0.05

    def __init__(self):
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def run(self):
        while not self.stop.is_set():
            self.tick()
            self.stop.wait(self.every_s)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *a):
        self.stop.set()
        self.thread.join()


class PageProbe(Background):
    """Another client (127.0.0.9): GET / and GET /api/benches every 50 ms, each on a new connection (over TLS: a
    handshake each); latency of each pair."""

    def __init__(self, port, tls=False):
        super().__init__()
        self.port, self.tls, self.times, self.failed = port, tls, [], 0

    def probe(self):
        a, _ = exchange(self.port, b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", 5.0, "127.0.0.9", self.tls)
        b, _ = exchange(self.port, f"GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {VIEWER}\r\n\r\n"
                        .encode(), 5.0, "127.0.0.9", self.tls)
        return a == 200 and b == 200

    def tick(self):
        t0 = time.monotonic()
        if self.probe():
            self.times.append(time.monotonic() - t0)
        else:
            self.failed += 1

    def summary(self):
        if not self.times:
            return f"{self.name}: no answer ({self.failed} failed)", float("inf")
        t = sorted(self.times)
        p99 = t[min(len(t) - 1, int(0.99 * len(t)))]
        return (f"{self.name} p50 {statistics.median(t) * 1e3:.1f} ms, p99 {p99 * 1e3:.1f} ms, max {t[-1] * 1e3:.1f} ms, "
                f"{self.failed} failed of {len(t) + self.failed}"), p99

    name = "page"


class GrpcProbe(PageProbe):
    """Another gRPC client: an authenticated ListBenches on its own channel every 50 ms."""

    name = "gRPC ListBenches"

    def __init__(self, port):
        super().__init__(port)
        self.why = {}
        import grpc
        self.channel = grpc.insecure_channel(f"{HOST}:{port}")
        self.call = self.channel.unary_unary("/valvebench.v1.BenchService/ListBenches")

    def probe(self):
        try:
            self.call(b"", metadata=[("authorization", "Bearer " + VIEWER)], timeout=5.0)
            return True
        except Exception as e:  # grpc.RpcError: counted as failed, its code and words kept
            why = f"{e.code().name}: {e.details()}" if hasattr(e, "code") else str(e)
            self.why[why] = self.why.get(why, 0) + 1
            return False

    def summary(self):
        text, p99 = super().summary()
        return text + "".join(f" ({n} x {why})" for why, n in self.why.items()), p99

    def __exit__(self, *a):
        super().__exit__(*a)
        self.channel.close()


class PeakRss(Background):
    """The server's peak RSS, sampled every 20 ms."""

    every_s = 0.02

    def __init__(self, pid):
        super().__init__()
        self.pid, self.peak = pid, rss_kib(pid)

    def tick(self):
        self.peak = max(self.peak, rss_kib(self.pid))


def idle_connections(grpc_port, server_pid):
    """1,100 TCP connections to gRPC that never speak, from 5 addresses, held 0.5 s (an attacker's process); the
    drill's server has 1,024 descriptors at most, so it runs out of them. Whether gRPC answers another address
    while they are held and after they are closed, and the server's descriptors before and during."""
    socks, f0 = [], fds(server_pid)
    for k in range(1100):
        try:
            socks.append(connect(grpc_port, f"127.0.0.{2 + k % 5}"))
        except OSError:
            break
    time.sleep(0.5)
    f1 = fds(server_pid)
    during = grpc_answers(grpc_port)
    for s in socks:
        s.close()
    time.sleep(0.5)
    return len(socks), f0, f1, during, grpc_answers(grpc_port)


def big_message_call(grpc_port):
    """One unauthenticated 60 MB ImportRuns call (an attacker's process); its status code."""
    import grpc
    ch = grpc.insecure_channel(f"{HOST}:{grpc_port}", options=[("grpc.max_send_message_length", -1)])
    try:
        ch.unary_unary("/valvebench.v1.BenchService/ImportRuns")(b"\x0a" + b"\0" * 59_999_999, timeout=30)
        return "OK"
    except grpc.RpcError as e:
        return e.code().name
    finally:
        ch.close()


def handshake_attacker(args):
    """TLS handshakes one after another from one address for `seconds` (an attacker's process); how many."""
    port, src, seconds = args
    done, stop = 0, time.monotonic() + seconds
    while time.monotonic() < stop:
        try:
            connect(port, src, 5.0, tls=True).close()
            done += 1
        except OSError:
            pass
    return done


def start_server(build, work, tls=False):
    cfg = {
        "listen_address": f"{HOST}:0", "database_path": os.path.join(work, "runs.db"),
        "benches": [{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}},
                    {"name": "emu-b", "kind": "emulated", "model": {"preset": "taghizadeh2009"}}],
        "tokens": [{"user": "viewer", "role": "viewer", "token_sha256": sha(VIEWER)},
                   {"user": "olga", "role": "operator", "token_sha256": sha(OPERATOR)}],
        "web": {"listen_address": f"{HOST}:0"},
    }
    if tls:
        cfg["tls"] = {"cert_file": os.path.join(work, "cert.pem"), "key_file": os.path.join(work, "key.pem")}
    with open(os.path.join(work, "server.json"), "w") as f:
        json.dump(cfg, f)
    log = open(os.path.join(work, "server.log"), "w+")
    # At most 1,024 descriptors (soft and hard), as a shell's default soft limit: the idle-connection flood
    # runs the server out of them.
    proc = subprocess.Popen([os.path.join(build, "bin", "valvebench-server"), "--config",
                             os.path.join(work, "server.json")], stderr=log, stdout=subprocess.DEVNULL,
                            preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_NOFILE, (1024, 1024)))
    grpc_port = web_port = 0
    for _ in range(400):
        log.seek(0)
        text = log.read()
        if "listening on " in text and "web dashboard on " in text:
            grpc_port = int(text.split("listening on ")[1].split()[0].rsplit(":", 1)[1])
            web_port = int(text.split("web dashboard on http" + ("s" if tls else "") + "://127.0.0.1:")[1]
                           .split("/")[0])
            break
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    return proc, grpc_port, web_port, log


def grpc_answers(port):
    """HTTP/2's preface and an empty SETTINGS from 127.0.0.9: a listening gRPC server answers with its SETTINGS."""
    try:
        s = connect(port, "127.0.0.9", timeout=3.0)
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
    ap.add_argument("--only", help="run only the floods whose names contain this (e.g. 'TLS', 'gRPC')")
    args = ap.parse_args()
    work = tempfile.mkdtemp(prefix="door-drill-")
    proc, grpc_port, web_port, log = start_server(args.build, work)
    if not web_port:
        log.seek(0)
        print(log.read()[-3000:], file=sys.stderr)
        return 3
    pid, ok = proc.pid, True
    print(f"door-drill: server pid {pid}, gRPC {grpc_port}, web {web_port}, work {work}")

    def flood(name, body, page_limit_s=0.1, server_pid=None, port=None, tls=False, grpc_probe=False):
        nonlocal ok
        if args.only and args.only not in name:
            return
        server_pid, port = server_pid or pid, port or web_port
        r0, c0 = rss_kib(server_pid), cpu_s(server_pid)
        with PageProbe(port, tls) as probe, PeakRss(server_pid) as peak:
            gprobe = GrpcProbe(grpc_port).__enter__() if grpc_probe else None
            time.sleep(0.2)
            what = body()
            time.sleep(0.2)
            if gprobe:
                gprobe.__exit__()
        r1, c1 = rss_kib(server_pid), cpu_s(server_pid)
        page, p99 = probe.summary()
        if gprobe:
            gpage, gp99 = gprobe.summary()
            page += "; " + gpage
            p99 = max(p99, gp99)
        up = exchange(port, f"GET /api/benches HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {VIEWER}\r\n\r\n"
                      .encode(), tls=tls)[0] == 200
        bounded = up and p99 < page_limit_s
        ok &= bounded
        print(f"  {name}: {what}; RSS {r0 / 1024:.0f} -> {r1 / 1024:.0f} MiB (peak {peak.peak / 1024:.0f}), server CPU "
              f"{c1 - c0:.2f} s; {page}; {'up' if up else 'DOWN'}{'' if bounded else '  <-- NOT BOUNDED'}")

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
        with multiprocessing.get_context("spawn").Pool(1) as pool:
            held, f0, f1, during, after = pool.apply(idle_connections, (grpc_port, pid))
        nonlocal ok
        ok &= after
        return (f"{held} idle TCP connections to gRPC from 5 addresses, the server limited to 1,024 descriptors: "
                f"server fds {f0} -> {f1}, gRPC answers another address while they are held: {during}, after: {after}")

    def grpc_big_messages():
        # Attackers in processes of their own (not threads of the probes' interpreter, whose lock they would hold),
        # started fresh ("spawn": gRPC's Python library does not survive a fork once it has a channel).
        with multiprocessing.get_context("spawn").Pool(8) as pool:
            codes = pool.map(big_message_call, [grpc_port] * 100, chunksize=1)
        return f"100 unauthenticated 60 MB gRPC calls, 8 at once: {sorted(set(codes))}"

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
    flood("big gRPC messages", grpc_big_messages, grpc_probe=True)

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

    # TLS handshakes: a server of its own with the dashboard over TLS.
    tls_work = os.path.join(work, "tls")
    os.makedirs(tls_work)
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2", "-subj", "/CN=localhost",
                    "-keyout", os.path.join(tls_work, "key.pem"), "-out", os.path.join(tls_work, "cert.pem")],
                   check=True, capture_output=True)
    tproc, _, tls_port, tlog = start_server(args.build, tls_work, tls=True)
    if not tls_port:
        tlog.seek(0)
        print(tlog.read()[-3000:], file=sys.stderr)
        return 3

    def handshakes():
        with multiprocessing.get_context("spawn").Pool(4) as pool:
            done = pool.map(handshake_attacker, [(tls_port, f"127.0.0.{2 + k}", 3.0) for k in range(4)])
        return f"{sum(done)} TLS handshakes in 3 s from 4 addresses ({sum(done) / 3:.0f}/s)"

    flood("TLS handshakes", handshakes, server_pid=tproc.pid, port=tls_port, tls=True)
    tproc.send_signal(signal.SIGTERM)
    tproc.wait(timeout=30)
    print(f"door-drill: {'bounded' if ok else 'NOT BOUNDED'}")
    if not args.keep:
        subprocess.run(["rm", "-rf", work])
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
