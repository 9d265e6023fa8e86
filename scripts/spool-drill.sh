#!/usr/bin/env bash
# The spool drill (docs/lab.md, "The spool"; issue 39): does a store that stops answering reach the control
# loop? One valvebench-server host with --benches paced emulated benches runs realtime closed-loop runs (seed
# 001's PI current law, recording at --rate-hz, --run-s long) twice:
#   phase 1, fault-free: --benches runs;
#   phase 2, the same runs while the store is faulted for --db-stop-s seconds, from --stop-after-s seconds into
#            them, by --fault:
#     db-stop    (--store postgres, the default) every PostgreSQL process is SIGSTOPped;
#     disk-full  (--store sqlite; root: it mounts a tmpfs) the disk under the SQLite database is filled to the
#                last byte (SQLITE_FULL on every write), then freed; the spool is on another disk;
#     lock       (--store sqlite) another process holds the database's write lock (BEGIN EXCLUSIVE): a store
#                whose writes stall, as on a throttled disk;
# then compares the loop's figures the host logs for each run ("run N: loop: ... overruns, jitter p99 ...") and
# counts from the database that every run is done exactly once with its whole trace. The last line is
#   spool-drill: runs=R done=R once=R trace_complete=R overruns_fault_free=A overruns_db_stopped=B
#                p99_us_fault_free=X p99_us_db_stopped=Y p99_ratio=Y/X waits=W
# (p99: the median over the phase's runs of each run's p99 tick lateness; "db_stopped": the faulted phase,
# whatever the fault.) Exit 0 when every run is done once with its whole trace, the fault added no overrun beyond
# the fault-free phase's count and raised the p99 by less than --max-p99-change (0.2; one-sided: a faulted phase
# that runs better does not show the fault reaching the loop); 1 otherwise; 2 bad usage; 3 environment.
#
# Usage: scripts/spool-drill.sh [--store postgres|sqlite] [--fault db-stop|disk-full|lock]
#                               [--benches B] [--run-s S] [--rate-hz HZ] [--db-stop-s S] [--stop-after-s S]
#                               [--controller pi|pwm] [--no-spool] [--max-p99-change F] [--behaviour-only]
#                               [--server-nice N] [--build DIR] [--keep]
# (--controller pwm: open-loop PWM (200 Hz, duty 0.4) instead of the PI current law: the loop ticks at 1 kHz and
#  the carrier's edges, for a machine that cannot emulate the PI law at 20 kHz in real time.
#  --server-nice N: run the host under `nice -n N` (e.g. -10, as root), as a bench host's loop would run at a
#  raised priority, when other work shares the machine.
#  --no-spool: the host writes traces to the database directly (spool_dir "none"), the behaviour before the
#  spool, to see what the spool changes. --behaviour-only: the exit status ignores the timing figures (overruns,
#  p99) and asks instead that the loop never waited for its recording; the CTest variant, on a shared machine.)
set -euo pipefail

STORE=postgres FAULT="" NICE="" CONTROLLER=pi BENCHES=2 RUN_S=20 RATE_HZ=20000 DB_STOP_S=30 STOP_AFTER_S=3 SPOOL=1 MAX_CHANGE=0.2 BUILD="" KEEP=0 BEHAVIOUR=0
while [[ $# -gt 0 ]]; do
  case "$1" in
    --store) STORE=$2; shift 2 ;;
    --fault) FAULT=$2; shift 2 ;;
    --benches) BENCHES=$2; shift 2 ;;
    --run-s) RUN_S=$2; shift 2 ;;
    --rate-hz) RATE_HZ=$2; shift 2 ;;
    --db-stop-s) DB_STOP_S=$2; shift 2 ;;
    --stop-after-s) STOP_AFTER_S=$2; shift 2 ;;
    --no-spool) SPOOL=0; shift ;;
    --controller) CONTROLLER=$2; shift 2 ;;
    --server-nice) NICE=$2; shift 2 ;;
    --behaviour-only) BEHAVIOUR=1; shift ;;
    --max-p99-change) MAX_CHANGE=$2; shift 2 ;;
    --build) BUILD=$2; shift 2 ;;
    --keep) KEEP=1; shift ;;
    -h|--help) sed -n 2,36p "$0"; exit 0 ;;
    *) echo "spool-drill: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[[ $BENCHES =~ ^[0-9]+$ && $BENCHES -gt 0 ]] || { echo "spool-drill: --benches: must be a whole number > 0, got '$BENCHES'" >&2; exit 2; }
[[ $STORE =~ ^(postgres|sqlite)$ ]] || { echo "spool-drill: --store: postgres or sqlite, got '$STORE'" >&2; exit 2; }
[[ -n $FAULT ]] || { [[ $STORE == postgres ]] && FAULT=db-stop || FAULT=disk-full; }
case "$STORE/$FAULT" in
  postgres/db-stop|sqlite/disk-full|sqlite/lock) ;;
  *) echo "spool-drill: --fault $FAULT: not for --store $STORE (postgres: db-stop; sqlite: disk-full, lock)" >&2; exit 2 ;;
esac
[[ $FAULT != disk-full || $(id -u) == 0 ]] ||
  { echo "spool-drill: --fault disk-full mounts a tmpfs under the database: run it as root" >&2; exit 3; }
[[ $CONTROLLER =~ ^(pi|pwm)$ ]] || { echo "spool-drill: --controller: pi or pwm, got '$CONTROLLER'" >&2; exit 2; }
for v in RUN_S RATE_HZ DB_STOP_S STOP_AFTER_S MAX_CHANGE; do
  opt=${v,,}; opt=--${opt//_/-}
  [[ ${!v} =~ ^[0-9]*\.?[0-9]+$ ]] || { echo "spool-drill: $opt: must be a number > 0, got '${!v}'" >&2; exit 2; }
done

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${BUILD:-$ROOT/build}
SERVER=$BUILD/bin/valvebench-server
BENCHCTL=$BUILD/bin/benchctl
for b in "$SERVER" "$BENCHCTL"; do
  [[ -x $b ]] || { echo "spool-drill: $b not built (cmake --build $BUILD)" >&2; exit 3; }
done
[[ $STORE == sqlite ]] || command -v psql >/dev/null ||
  { echo "spool-drill: psql is needed to count the runs" >&2; exit 3; }

WORK=$(mktemp -d "${TMPDIR:-/tmp}/spool-drill.XXXXXX")
PG_DIR="" PID="" PG_STOPPED=() MOUNTED="" LOCKER=""
cleanup() {
  for p in "${PG_STOPPED[@]:-}"; do [[ -n $p ]] && kill -CONT "$p" 2>/dev/null || true; done
  [[ -z $LOCKER ]] || kill "$LOCKER" 2>/dev/null || true
  if [[ -n $PID ]]; then kill -TERM "$PID" 2>/dev/null || true; wait "$PID" 2>/dev/null || true; fi
  [[ -z $PG_DIR ]] || "${PG_STOP[@]}" >/dev/null 2>&1 || true
  [[ -z $MOUNTED ]] || umount "$MOUNTED" 2>/dev/null || true
  if [[ $KEEP == 1 ]]; then echo "spool-drill: kept $WORK" >&2; else rm -rf "$WORK"; fi
}
trap cleanup EXIT
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

if [[ $STORE == postgres ]]; then
  # A private PostgreSQL in $WORK/pg (as scripts/lab-drill.sh starts it; as `nobody` when run as root).
  bin=$(dirname "$(command -v pg_ctl || echo /usr/lib/postgresql/15/bin/pg_ctl)")
  [[ -x $bin/initdb && -x $bin/pg_ctl ]] || { echo "spool-drill: PostgreSQL's initdb/pg_ctl not found" >&2; exit 3; }
  PG_DIR=$WORK/pg
  mkdir -p "$PG_DIR"
  as=()
  if [[ $(id -u) == 0 ]]; then chown -R nobody "$WORK"; as=(setpriv --reuid=nobody --regid=nogroup --clear-groups --); fi
  pg_port=$(free_port)
  "${as[@]}" "$bin/initdb" -D "$PG_DIR/data" -U valvebench --auth=trust >"$WORK/pg-initdb.log" 2>&1 ||
    { echo "spool-drill: initdb failed" >&2; tail -5 "$WORK/pg-initdb.log" >&2; exit 3; }
  "${as[@]}" "$bin/pg_ctl" -D "$PG_DIR/data" -l "$WORK/pg.log" -w \
    -o "-p $pg_port -k $PG_DIR -c listen_addresses=127.0.0.1" start >/dev/null ||
    { echo "spool-drill: PostgreSQL did not start" >&2; tail -5 "$WORK/pg.log" >&2; exit 3; }
  PG_STOP=("${as[@]}" "$bin/pg_ctl" -D "$PG_DIR/data" -m fast stop)
  DB_URL="postgresql://valvebench@127.0.0.1:$pg_port/postgres"
  db_query() { psql -X -q -A -t -v ON_ERROR_STOP=1 -d "$DB_URL" -c "$1"; }

else
  # The SQLite database on a disk of its own: for disk-full a 64 MB tmpfs (the 20 s drill stores about 20 MB; the
  # smaller the disk, the less the filling itself costs the loops), filled to the last byte without touching the
  # machine's disks. The spool stays on $WORK's.
  mkdir -p "$WORK/store"
  if [[ $FAULT == disk-full ]]; then
    mount -t tmpfs -o size=64m,mode=0755 tmpfs "$WORK/store" ||
      { echo "spool-drill: cannot mount a tmpfs on $WORK/store" >&2; exit 3; }
    MOUNTED=$WORK/store
  fi
  DB_URL=$WORK/store/runs.db
  db_query() {  # read-only, '|' between columns, as psql -A -t prints them
    python3 - "$DB_URL" "$1" <<'PY'
import sqlite3, sys
c = sqlite3.connect("file:%s?mode=ro" % sys.argv[1], uri=True, timeout=30)
for row in c.execute(sys.argv[2]):
    print("|".join("" if v is None else str(v) for v in row))
PY
  }
fi

TOKEN=spool-drill-operator
TOKEN_SHA=$(printf %s "$TOKEN" | sha256sum | cut -d' ' -f1)
PORT=$(free_port)
benches=""
for ((b = 1; b <= BENCHES; b++)); do
  benches+="${benches:+,}{\"name\": \"emu-$b\", \"kind\": \"emulated\", \"pace\": \"realtime\",
    \"model\": {\"preset\": \"taghizadeh2009\"}, \"driver\": {\"kind\": \"low_side_flyback\"}}"
done
spool_dir="$WORK/spool"
[[ $SPOOL == 1 ]] || spool_dir=none
lab=""
[[ $STORE == sqlite ]] || lab=$',\n "lab": {"host": "drill-host", "lease_ttl_s": 10}'
cat > "$WORK/host.json" <<EOF
{"listen_address": "127.0.0.1:$PORT", "database_path": "$DB_URL", "spool_dir": "$spool_dir",
 "benches": [$benches],
 "tokens": [{"user": "drill", "role": "operator", "token_sha256": "$TOKEN_SHA"}],
 "limits": {"max_duration_s": 3600, "max_trace_MB_per_run": 4000, "max_disk_MB_per_user": 0}$lab}
EOF
wrap=()
[[ -z $NICE ]] || wrap=(nice -n "$NICE")
"${wrap[@]}" "$SERVER" --config "$WORK/host.json" >"$WORK/host.log" 2>&1 &
PID=$!
for ((k = 0; k < 200; k++)); do
  grep -q "listening on" "$WORK/host.log" 2>/dev/null && break
  kill -0 "$PID" 2>/dev/null || { echo "spool-drill: the host did not start:" >&2; tail -20 "$WORK/host.log" >&2; exit 3; }
  sleep 0.05
done

# Seed 001's PI current law holding 0.5 A after a 0.9 A pull-in, at 24 V and 4 bar, recorded at RATE_HZ (or
# open-loop PWM).
law='"reference": {"on_off_profile": {"switching_value": 0.9, "switching_time_s": 0.006, "holding_value": 0.5}},
 "controller": {"pi_current": {}},'
[[ $CONTROLLER == pwm ]] &&
  law='"controller": {"open_loop_pwm": {"segments": [{"start_s": 0.0, "frequency_Hz": 200.0, "duty": 0.4}]}},'
cat > "$WORK/run.json" <<EOF
{"name": "spool-drill", "bench": {"kind": "emulated", "model": {"preset": "taghizadeh2009"}, "driver": {"kind": "low_side_flyback"}},
 "conditions": {"supply_V": 24.0, "supply_pressure_Pa": 400000.0},
 $law
 "duration_s": $RUN_S, "recording": {"rate_Hz": $RATE_HZ}, "repeats": $BENCHES, "tags": ["spool-drill"]}
EOF

children_of() {  # the ids of the processes whose parent is $1, from /proc
  local parent=$1 f line fields
  for f in /proc/[0-9]*/stat; do
    { read -r line < "$f"; } 2>/dev/null || continue
    read -r -a fields <<< "${line##*) }"
    if [[ ${fields[1]} == "$parent" ]]; then f=${f#/proc/}; echo "${f%/stat}"; fi
  done
  return 0
}

# Near the end of an SQLite fault (its reads still work): how many of the batch's runs have ended their
# experiment and say so, "result waiting for the store since ..." (`benchctl show --json`), into $WORK/waiting.
waiting_runs() {
  local ids n=0 w=0 id
  ids=$(db_query "SELECT id FROM runs WHERE batch_id = $1 ORDER BY id")
  for id in $ids; do
    n=$((n + 1))
    VALVEBENCH_TOKEN=$TOKEN "$BENCHCTL" show "$id" --json --server "127.0.0.1:$PORT" 2>/dev/null |
      grep -q '"result_waiting_since_unix_s"' && w=$((w + 1))
  done
  echo "spool-drill: $w of $n runs say 'result waiting for the store' near the fault's end" >&2
  echo "$w $n" > "$WORK/waiting"
}

# One phase: submit, optionally stop the database from STOP_AFTER_S into the runs, wait until the runs are
# finished; prints the batch id.
phase() {
  local fault=$1 batch t
  VALVEBENCH_TOKEN=$TOKEN "$BENCHCTL" run "$WORK/run.json" --server "127.0.0.1:$PORT" >/dev/null ||
    { echo "spool-drill: submission failed" >&2; exit 3; }
  batch=$(db_query "SELECT max(batch_id) FROM runs")
  if [[ $fault == 1 ]]; then
    # Wait until every run of the batch is running, then STOP_AFTER_S more.
    for ((k = 0; k < 600; k++)); do
      [[ $(db_query "SELECT count(*) FROM runs WHERE batch_id = $batch AND status = 'running'") == "$BENCHES" ]] && break
      sleep 0.1
    done
    sleep "$STOP_AFTER_S"
    t=$(date +%s.%N)
    case $FAULT in
      db-stop)
        local pm
        pm=$(head -1 "$PG_DIR/data/postmaster.pid")
        mapfile -t PG_STOPPED < <(echo "$pm"; children_of "$pm")
        kill -STOP "${PG_STOPPED[@]}"
        sleep "$DB_STOP_S"
        kill -CONT "${PG_STOPPED[@]}"
        PG_STOPPED=() ;;
      disk-full)
        # fallocate reserves the free space without copying it in (dd of a whole tmpfs cost the loops a second of
        # system time: the fault's own price, not the store's); dd tops up the last pages.
        fallocate -l "$(df --output=avail -B1 "$WORK/store" | tail -1 | tr -d ' ')" "$WORK/store/filler" 2>/dev/null || true
        dd if=/dev/zero of="$WORK/store/filler2" bs=4k status=none 2>/dev/null || true
        echo "spool-drill: the database's disk is full ($(df --output=avail -B1 "$WORK/store" | tail -1 | tr -d ' ') bytes free)" >&2
        sleep "$DB_STOP_S"
        waiting_runs "$batch"
        rm -f "$WORK/store/filler" "$WORK/store/filler2" ;;
      lock)
        python3 - "$DB_URL" "$DB_STOP_S" <<'PY' &
import sqlite3, sys, time
c = sqlite3.connect(sys.argv[1], timeout=60, isolation_level=None)
c.execute("BEGIN EXCLUSIVE")
time.sleep(float(sys.argv[2]))
c.execute("ROLLBACK")
PY
        LOCKER=$!
        sleep "$(python3 -c "print(max(0.0, $DB_STOP_S - 1.0))")"
        waiting_runs "$batch"
        wait "$LOCKER" || echo "spool-drill: the lock holder failed" >&2
        LOCKER="" ;;
    esac
    echo "spool-drill: $FAULT for $(python3 -c "import time; print(f'{time.time() - $t:.1f}')") s" >&2
  fi
  local limit=$(python3 -c "print(int(($RUN_S * 3 + $DB_STOP_S + 120) * 10))")
  for ((k = 0; k < limit; k++)); do
    [[ $(db_query "SELECT count(*) FROM runs WHERE batch_id = $batch AND status IN ('queued', 'running', 'interrupted')") == 0 ]] && break
    sleep 0.1
  done
  echo "$batch"
}

echo "spool-drill: $BENCHES bench(es), runs of $RUN_S s at $RATE_HZ Hz, spool $spool_dir, $STORE, fault $FAULT" >&2
B1=$(phase 0)
B2=$(phase 1)

# Per run: its loop figures from the host's log, its history and its stored samples from the database.
grep -E "run [0-9]+: loop:" "$WORK/host.log" > "$WORK/loop.log" || true
db_query "SELECT r.id, r.batch_id, r.status,
                 (SELECT count(*) FROM status_history h WHERE h.run_id = r.id AND h.status = 'done'),
                 coalesce((SELECT sum(samples) FROM trace_chunks c WHERE c.run_id = r.id), 0)
          FROM runs r WHERE r.batch_id IN ($B1, $B2) ORDER BY r.id" > "$WORK/runs.txt"
python3 - "$WORK/runs.txt" "$WORK/loop.log" "$B1" "$B2" "$RUN_S" "$RATE_HZ" "$MAX_CHANGE" "$BEHAVIOUR" \
  "$WORK/waiting" "$STOP_AFTER_S" "$DB_STOP_S" <<'PY'
import os, re, statistics, sys
runs_file, loop_file, b1, b2, run_s, rate, max_change, behaviour, waiting_file, stop_after, stop_s = sys.argv[1:]
b1, b2, expected = int(b1), int(b2), int(round(float(run_s) * float(rate))) + 1
loop = {}
for line in open(loop_file):
    m = re.search(r"run (\d+): loop: (\d+) paced ticks, (\d+) overruns, jitter p50 ([\d.]+) us, p99 ([\d.]+) us, "
                  r"max ([\d.]+) us; (\d+) wait", line)
    if m:
        loop[int(m[1])] = dict(ticks=int(m[2]), overruns=int(m[3]), p99=float(m[5]), max=float(m[6]), waits=int(m[7]))
phases = {b1: [], b2: []}
done = once = complete = total = 0
for line in open(runs_file):
    rid, batch, status, dones, samples = line.strip().split("|")
    rid, batch = int(rid), int(batch)
    total += 1
    done += status == "done"
    once += int(dones) == 1
    complete += int(samples) == expected
    if int(samples) != expected:
        print(f"spool-drill: run {rid}: {samples} samples stored, {expected} expected", file=sys.stderr)
    if rid in loop:
        phases[batch].append(loop[rid])
    print(f"spool-drill: run {rid} ({'fault-free' if batch == b1 else 'db stopped'}): {status}, "
          f"{loop.get(rid)}", file=sys.stderr)
def agg(rs):
    return (sum(r["overruns"] for r in rs), statistics.median(r["p99"] for r in rs) if rs else float("nan"),
            sum(r["waits"] for r in rs))
o1, p1, w1 = agg(phases[b1])
o2, p2, w2 = agg(phases[b2])
ratio = p2 / p1 if p1 > 0 else float("nan")
print(f"spool-drill: runs={total} done={done} once={once} trace_complete={complete} overruns_fault_free={o1} "
      f"overruns_db_stopped={o2} p99_us_fault_free={p1:.1f} p99_us_db_stopped={p2:.1f} p99_ratio={ratio:.3f} "
      f"waits={w1 + w2}")
ok = done == total == once == complete and len(phases[b1]) + len(phases[b2]) == total
# On SQLite the runs that ended their experiment during the fault must say that their result waits (checked 1 s
# before the fault's end, when they ended 2 s before that or earlier).
if os.path.exists(waiting_file) and float(run_s) < float(stop_after) + float(stop_s) - 3:
    w, n = map(int, open(waiting_file).read().split())
    if w != n:
        print(f"spool-drill: {n - w} of {n} finished runs did not say their result waits for the store", file=sys.stderr)
    ok = ok and w == n
if behaviour == "1":
    ok = ok and w1 + w2 == 0
else:
    # One-sided: the drill asks whether the fault reaches the loop. A faulted phase that runs better (a store
    # that takes nothing leaves the uploader idle, and the upload's own work is what the loop competes with on a
    # 2-core host) does not show that.
    ok = ok and o2 <= o1 and ratio < 1 + float(max_change)
sys.exit(0 if ok else 1)
PY
