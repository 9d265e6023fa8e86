#!/usr/bin/env bash
# The spool drill (docs/lab.md, "The spool"; issue 39): does a database that stops answering reach the control
# loop? One valvebench-server host with --benches paced emulated benches on a private PostgreSQL runs realtime
# closed-loop runs (seed 001's PI current law, recording at --rate-hz, --run-s long) twice:
#   phase 1, fault-free: --benches runs;
#   phase 2, the same runs while every PostgreSQL process is SIGSTOPped for --db-stop-s seconds, from
#            --stop-after-s seconds into them;
# then compares the loop's figures the host logs for each run ("run N: loop: ... overruns, jitter p99 ...") and
# counts from the database that every run is done exactly once with its whole trace. The last line is
#   spool-drill: runs=R done=R once=R trace_complete=R overruns_fault_free=A overruns_db_stopped=B
#                p99_us_fault_free=X p99_us_db_stopped=Y p99_ratio=Y/X waits=W
# (p99: the median over the phase's runs of each run's p99 tick lateness.) Exit 0 when every run is done once
# with its whole trace, the stopped database added no overrun beyond the fault-free phase's count and changed
# the p99 by less than --max-p99-change (0.2); 1 otherwise; 2 bad usage; 3 environment.
#
# Usage: scripts/spool-drill.sh [--benches B] [--run-s S] [--rate-hz HZ] [--db-stop-s S] [--stop-after-s S]
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

NICE="" CONTROLLER=pi BENCHES=2 RUN_S=20 RATE_HZ=20000 DB_STOP_S=30 STOP_AFTER_S=3 SPOOL=1 MAX_CHANGE=0.2 BUILD="" KEEP=0 BEHAVIOUR=0
while [[ $# -gt 0 ]]; do
  case "$1" in
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
    -h|--help) sed -n 2,29p "$0"; exit 0 ;;
    *) echo "spool-drill: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[[ $BENCHES =~ ^[0-9]+$ && $BENCHES -gt 0 ]] || { echo "spool-drill: --benches: must be a whole number > 0, got '$BENCHES'" >&2; exit 2; }
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
command -v psql >/dev/null || { echo "spool-drill: psql is needed to count the runs" >&2; exit 3; }

WORK=$(mktemp -d "${TMPDIR:-/tmp}/spool-drill.XXXXXX")
PG_DIR="" PID="" PG_STOPPED=()
cleanup() {
  for p in "${PG_STOPPED[@]:-}"; do [[ -n $p ]] && kill -CONT "$p" 2>/dev/null || true; done
  if [[ -n $PID ]]; then kill -TERM "$PID" 2>/dev/null || true; wait "$PID" 2>/dev/null || true; fi
  [[ -z $PG_DIR ]] || "${PG_STOP[@]}" >/dev/null 2>&1 || true
  if [[ $KEEP == 1 ]]; then echo "spool-drill: kept $WORK" >&2; else rm -rf "$WORK"; fi
}
trap cleanup EXIT
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

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
cat > "$WORK/host.json" <<EOF
{"listen_address": "127.0.0.1:$PORT", "database_path": "$DB_URL", "spool_dir": "$spool_dir",
 "benches": [$benches],
 "tokens": [{"user": "drill", "role": "operator", "token_sha256": "$TOKEN_SHA"}],
 "limits": {"max_duration_s": 3600, "max_trace_MB_per_run": 4000, "max_disk_MB_per_user": 0},
 "lab": {"host": "drill-host", "lease_ttl_s": 10}}
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
    local pm
    pm=$(head -1 "$PG_DIR/data/postmaster.pid")
    mapfile -t PG_STOPPED < <(echo "$pm"; children_of "$pm")
    t=$(date +%s.%N)
    kill -STOP "${PG_STOPPED[@]}"
    sleep "$DB_STOP_S"
    kill -CONT "${PG_STOPPED[@]}"
    PG_STOPPED=()
    echo "spool-drill: database stopped for $(python3 -c "import time; print(f'{time.time() - $t:.1f}')") s" >&2
  fi
  local limit=$(python3 -c "print(int(($RUN_S * 3 + $DB_STOP_S + 120) * 10))")
  for ((k = 0; k < limit; k++)); do
    [[ $(db_query "SELECT count(*) FROM runs WHERE batch_id = $batch AND status IN ('queued', 'running', 'interrupted')") == 0 ]] && break
    sleep 0.1
  done
  echo "$batch"
}

echo "spool-drill: $BENCHES bench(es), runs of $RUN_S s at $RATE_HZ Hz, spool $spool_dir" >&2
B1=$(phase 0)
B2=$(phase 1)

# Per run: its loop figures from the host's log, its history and its stored samples from the database.
grep -E "run [0-9]+: loop:" "$WORK/host.log" > "$WORK/loop.log" || true
db_query "SELECT r.id, r.batch_id, r.status,
                 (SELECT count(*) FROM status_history h WHERE h.run_id = r.id AND h.status = 'done'),
                 coalesce((SELECT sum(samples) FROM trace_chunks c WHERE c.run_id = r.id), 0)
          FROM runs r WHERE r.batch_id IN ($B1, $B2) ORDER BY r.id" > "$WORK/runs.txt"
python3 - "$WORK/runs.txt" "$WORK/loop.log" "$B1" "$B2" "$RUN_S" "$RATE_HZ" "$MAX_CHANGE" "$BEHAVIOUR" <<'PY'
import re, statistics, sys
runs_file, loop_file, b1, b2, run_s, rate, max_change, behaviour = sys.argv[1:]
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
if behaviour == "1":
    ok = ok and w1 + w2 == 0
else:
    ok = ok and o2 <= o1 and abs(ratio - 1) < float(max_change)
sys.exit(0 if ok else 1)
PY
