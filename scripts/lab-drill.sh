#!/usr/bin/env bash
# The lab drill (docs/lab.md, "The drill"): several valvebench-server hosts share one database, runs are
# submitted through different hosts, hosts are SIGKILLed (and restarted) and SIGSTOPped (and continued, after
# their leases lapsed) at random, the database itself fails (restarted, down for a while, the hosts' sessions
# terminated, stopped), and at the end every run must have finished exactly once. The last line is
#   lab-drill: hosts=3 benches=6 runs=1000 done=1000 lost=0 duplicated=0 failed=0 stuck=0 kills=K db_faults=F
#              interrupted=I stale_writes_refused=S throughput_x=X
# (interrupted: attempts that did not finish and were run again.)
# and each database fault gets a line with its length and the lab's stall around it (the longest gap between
# two runs finishing, from the last before the fault to the first after it).
# Exit 0 only if nothing was lost, run twice, failed or left stuck (and every fault asked for happened before the
# queue drained); 1 otherwise; 2 bad usage; 3 environment (a host did not start, a submission failed).
#
# Usage: scripts/lab-drill.sh [--runs N] [--kills K] [--hosts H] [--benches-per-host B] [--run-s S]
#                             [--kill-every S] [--db-faults LIST] [--outage-s S] [--db-stop-s S] [--drain-s S]
#                             [--build DIR] [--keep] [--seed N]
# (--kill-every: mean seconds between two faults, default 1.4. --kills 0: no host faults.
#  --db-faults: database faults, comma-separated, each once, in a random order among the host faults:
#    restart    pg_ctl restart -m fast
#    outage     pg_ctl stop -m fast, --outage-s seconds (default 4), pg_ctl start
#    terminate  pg_terminate_backend of every session of the hosts
#    sigstop    SIGSTOP of the postmaster and all its processes for --db-stop-s seconds (default 15), SIGCONT
#    sigstop-postmaster  the same for the postmaster alone (sessions go on; new connections wait)
#  or "all" (the first four); only with the drill's own PostgreSQL (LAB_DB_URL=postgres).
#  --drain-s: after the last fault the queue must drain within this many seconds (default 120), else the runs
#  left are reported as stuck.)
# Environment: LAB_DB_URL  the shared database: "postgres" (the default) starts a throw-away PostgreSQL
#              (initdb + pg_ctl in the work directory; as root it runs as `nobody`) and uses its URL; a
#              postgresql:// URL uses that server; "sqlite:PATH" shares one SQLite file (one machine only).
set -euo pipefail

RUNS=1000 KILLS=5 HOSTS=3 BENCHES=2 RUN_S=0.1 BUILD="" KEEP=0 SEED=$RANDOM KILL_MIN_S=0.8 KILL_MAX_S=2.0
LEASE_TTL_S=1.0 HEARTBEAT_S=0.25 DB_FAULTS="" OUTAGE_S=4 DB_STOP_S=15 DRAIN_S=120
while [[ $# -gt 0 ]]; do
  case "$1" in
    --runs) RUNS=$2; shift 2 ;;
    --kills) KILLS=$2; shift 2 ;;
    --hosts) HOSTS=$2; shift 2 ;;
    --benches-per-host) BENCHES=$2; shift 2 ;;
    --run-s) RUN_S=$2; shift 2 ;;
    --build) BUILD=$2; shift 2 ;;
    --seed) SEED=$2; shift 2 ;;
    --kill-every) KILL_MIN_S=$(python3 -c "print($2 * 0.6)"); KILL_MAX_S=$(python3 -c "print($2 * 1.4)"); shift 2 ;;
    --db-faults) DB_FAULTS=$2; shift 2 ;;
    --outage-s) OUTAGE_S=$2; shift 2 ;;
    --db-stop-s) DB_STOP_S=$2; shift 2 ;;
    --drain-s) DRAIN_S=$2; shift 2 ;;
    --keep) KEEP=1; shift ;;
    -h|--help) sed -n 2,29p "$0"; exit 0 ;;
    *) echo "lab-drill: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
for v in RUNS HOSTS BENCHES; do
  [[ ${!v} =~ ^[0-9]+$ && ${!v} -gt 0 ]] || { echo "lab-drill: --${v,,}: must be a whole number > 0, got '${!v}'" >&2; exit 2; }
done
[[ $KILLS =~ ^[0-9]+$ ]] || { echo "lab-drill: --kills: must be a whole number >= 0, got '$KILLS'" >&2; exit 2; }
for v in RUN_S OUTAGE_S DB_STOP_S DRAIN_S; do
  opt=${v,,}; opt=--${opt//_/-}
  [[ ${!v} =~ ^[0-9]*\.?[0-9]+$ ]] || { echo "lab-drill: $opt: must be a number of seconds > 0, got '${!v}'" >&2; exit 2; }
done
[[ $DB_FAULTS == all ]] && DB_FAULTS=restart,outage,terminate,sigstop
declare -a DB_FAULT_LIST=()
if [[ -n $DB_FAULTS ]]; then
  IFS=, read -r -a DB_FAULT_LIST <<< "$DB_FAULTS"
  for f in "${DB_FAULT_LIST[@]}"; do
    [[ $f =~ ^(restart|outage|terminate|sigstop|sigstop-postmaster)$ ]] ||
      { echo "lab-drill: --db-faults: '$f' is not one of restart, outage, terminate, sigstop, sigstop-postmaster (or all)" >&2; exit 2; }
  done
  [[ ${LAB_DB_URL:-postgres} == postgres ]] ||
    { echo "lab-drill: --db-faults needs the drill's own PostgreSQL (LAB_DB_URL=postgres), not '$LAB_DB_URL'" >&2; exit 2; }
fi
RANDOM=$SEED

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${BUILD:-$ROOT/build}
SERVER=$BUILD/bin/valvebench-server
BENCHCTL=$BUILD/bin/benchctl
for b in "$SERVER" "$BENCHCTL"; do
  [[ -x $b ]] || { echo "lab-drill: $b not built (cmake --build $BUILD)" >&2; exit 3; }
done
command -v python3 >/dev/null || { echo "lab-drill: python3 is needed to count the runs in the database" >&2; exit 3; }

WORK=$(mktemp -d "${TMPDIR:-/tmp}/lab-drill.XXXXXX")
LAB_DB_URL=${LAB_DB_URL:-postgres}
PG_DIR=""
declare -a PIDS PORTS PG_STOPPED
cleanup() {
  for pid in "${PIDS[@]:-}"; do
    [[ -n $pid ]] || continue
    kill -CONT "$pid" 2>/dev/null || true
    kill -TERM "$pid" 2>/dev/null || true
  done
  for pid in "${PIDS[@]:-}"; do [[ -n $pid ]] && wait "$pid" 2>/dev/null || true; done
  for pid in "${PG_STOPPED[@]:-}"; do [[ -n $pid ]] && kill -CONT "$pid" 2>/dev/null || true; done
  [[ -z $PG_DIR ]] || "${PG_STOP[@]}" >/dev/null 2>&1 || true
  if [[ $KEEP == 1 ]]; then echo "lab-drill: kept $WORK" >&2; else rm -rf "$WORK"; fi
}
trap cleanup EXIT
start_postgres() {  # a private PostgreSQL in $WORK/pg on a free port; sets LAB_DB_URL
  local bin port as=()
  bin=$(dirname "$(command -v pg_ctl || echo /usr/lib/postgresql/15/bin/pg_ctl)")
  [[ -x $bin/initdb && -x $bin/pg_ctl ]] || { echo "lab-drill: PostgreSQL's initdb/pg_ctl not found" >&2; exit 3; }
  PG_DIR=$WORK/pg
  mkdir -p "$PG_DIR"
  if [[ $(id -u) == 0 ]]; then  # postgres refuses to run as root
    chown -R nobody "$WORK"
    as=(setpriv --reuid=nobody --regid=nogroup --clear-groups --)
  fi
  port=$(free_port)
  "${as[@]}" "$bin/initdb" -D "$PG_DIR/data" -U valvebench --auth=trust >"$WORK/pg-initdb.log" 2>&1 ||
    { echo "lab-drill: initdb failed:" >&2; tail -5 "$WORK/pg-initdb.log" >&2; exit 3; }
  PG_START=("${as[@]}" "$bin/pg_ctl" -D "$PG_DIR/data" -l "$WORK/pg.log" -w
    -o "-p $port -k $PG_DIR -c listen_addresses=127.0.0.1 -c max_connections=200" start)
  "${PG_START[@]}" >/dev/null || { echo "lab-drill: PostgreSQL did not start:" >&2; tail -5 "$WORK/pg.log" >&2; exit 3; }
  PG_STOP=("${as[@]}" "$bin/pg_ctl" -D "$PG_DIR/data" -m fast stop)
  PG_RESTART=("${as[@]}" "$bin/pg_ctl" -D "$PG_DIR/data" -l "$WORK/pg.log" -m fast -w restart)
  LAB_DB_URL="postgresql://valvebench@127.0.0.1:$port/postgres"
}
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
[[ $LAB_DB_URL == postgres ]] && start_postgres
case "$LAB_DB_URL" in
  sqlite:*) DB_PATH=${LAB_DB_URL#sqlite:} ;;
  postgresql://*) DB_PATH=$LAB_DB_URL
    command -v psql >/dev/null || { echo "lab-drill: psql is needed to count the runs in PostgreSQL" >&2; exit 3; } ;;
  *) echo "lab-drill: LAB_DB_URL '$LAB_DB_URL': give sqlite:PATH, postgres or a postgresql:// URL" >&2; exit 2 ;;
esac


# One SQL query against the shared database, result on stdout (rows as "a|b").
db_query() {
  if [[ $DB_PATH == postgresql://* ]]; then
    psql -X -q -A -t -v ON_ERROR_STOP=1 -d "$DB_PATH" -c "$1"
    return
  fi
  python3 - "$DB_PATH" "$1" <<'PY'
import sqlite3, sys
con = sqlite3.connect(sys.argv[1], timeout=30)
for row in con.execute(sys.argv[2]):
    print("|".join(str(v) for v in row))
PY
}

TOKEN=lab-drill-operator
TOKEN_SHA=$(printf %s "$TOKEN" | sha256sum | cut -d' ' -f1)

write_config() {  # host index -> its config file
  local h=$1 benches="" b
  for ((b = 1; b <= BENCHES; b++)); do
    benches+="${benches:+,}{\"name\": \"h$h-emu-$b\", \"kind\": \"emulated\", \"pace\": \"realtime\",
      \"model\": {\"preset\": \"taghizadeh2009\"}, \"driver\": {\"kind\": \"low_side_flyback\"}}"
  done
  cat > "$WORK/host$h.json" <<EOF
{"listen_address": "127.0.0.1:${PORTS[$h]}", "database_path": "$DB_PATH",
 "benches": [$benches],
 "tokens": [{"user": "drill", "role": "operator", "token_sha256": "$TOKEN_SHA"}],
 "limits": {"max_queued_runs_per_user": 100000},
 "lab": {"host": "host$h", "lease_ttl_s": $LEASE_TTL_S, "heartbeat_s": $HEARTBEAT_S}}
EOF
}

start_host() {
  local h=$1
  "$SERVER" --config "$WORK/host$h.json" >>"$WORK/host$h.log" 2>&1 &
  PIDS[$h]=$!
  local k
  for ((k = 0; k < 200; k++)); do
    grep -q "listening on" "$WORK/host$h.log" 2>/dev/null && [[ $(grep -c "listening on" "$WORK/host$h.log") -ge ${STARTS[$h]} ]] && return 0
    kill -0 "${PIDS[$h]}" 2>/dev/null || break
    sleep 0.05
  done
  echo "lab-drill: host$h did not start; its log:" >&2
  tail -20 "$WORK/host$h.log" >&2
  exit 3
}

declare -a STARTS
for ((h = 1; h <= HOSTS; h++)); do
  PORTS[$h]=$(free_port)
  write_config "$h"
  STARTS[$h]=1
done
# The first host creates (migrates) the database; the others then open it.
start_host 1
for ((h = 2; h <= HOSTS; h++)); do start_host "$h"; done

# Short runs: RUN_S of bench time, paced by the benches to the wall clock; submitted in batches of 100 repeats
# through the hosts in turn.
cat > "$WORK/run.json" <<EOF
{"name": "drill", "bench": {"kind": "emulated", "model": {"preset": "taghizadeh2009"}, "driver": {"kind": "low_side_flyback"}},
 "conditions": {"supply_V": 24.0, "supply_pressure_Pa": 400000.0},
 "controller": {"open_loop_pwm": {"segments": [{"start_s": 0.0, "frequency_Hz": 200.0, "duty": 0.4}]}},
 "duration_s": $RUN_S, "recording": {"rate_Hz": 2000.0}, "tags": ["lab-drill"], "repeats": 100}
EOF
T0=$(date +%s.%N)
left=$RUNS
batch=0
while ((left > 0)); do
  per=$(( (RUNS + HOSTS - 1) / HOSTS ))
  per=$((per < 100 ? per : 100))
  n=$((left < per ? left : per))
  h=$((batch % HOSTS + 1))
  sed "s/\"repeats\": 100/\"repeats\": $n/" "$WORK/run.json" > "$WORK/batch.json"
  # A host may be stopped by the chaos below only after submission; all hosts are up here.
  VALVEBENCH_TOKEN=$TOKEN "$BENCHCTL" run "$WORK/batch.json" --server "127.0.0.1:${PORTS[$h]}" --json >/dev/null ||
    { echo "lab-drill: submitting through host$h failed" >&2; exit 3; }
  left=$((left - n))
  batch=$((batch + 1))
done
echo "lab-drill: $RUNS runs submitted through $HOSTS hosts in $batch batches" >&2

remaining() { db_query "SELECT count(*) FROM runs WHERE status IN ('queued', 'running', 'interrupted')"; }

children_of() {  # the ids of the processes whose parent is $1, from /proc (no procps on a bare Debian)
  local parent=$1 f line fields
  for f in /proc/[0-9]*/stat; do
    { read -r line < "$f"; } 2>/dev/null || continue
    read -r -a fields <<< "${line##*) }"
    if [[ ${fields[1]} == "$parent" ]]; then f=${f#/proc/}; echo "${f%/stat}"; fi
  done
  return 0
}

# The database's faults (docs/lab.md, "When the database fails"). Each appends "kind start end" (unix seconds:
# the fault's own span, e.g. from pg_ctl stop to pg_ctl start returning) to $WORK/db-faults.
db_fault() {
  local kind=$1 t0 t1 pm
  t0=$(date +%s.%N)
  case "$kind" in
    restart) "${PG_RESTART[@]}" >/dev/null 2>&1 || { echo "lab-drill: pg_ctl restart failed" >&2; exit 3; } ;;
    outage)
      "${PG_STOP[@]}" >/dev/null 2>&1 || { echo "lab-drill: pg_ctl stop failed" >&2; exit 3; }
      sleep "$OUTAGE_S"
      "${PG_START[@]}" >/dev/null 2>&1 || { echo "lab-drill: pg_ctl start failed" >&2; exit 3; } ;;
    terminate)
      db_query "SELECT count(pg_terminate_backend(pid)) FROM pg_stat_activity WHERE backend_type = 'client backend'
                AND pid <> pg_backend_pid()" >"$WORK/terminated" ;;
    sigstop|sigstop-postmaster)
      # The postmaster and every process it started (backends, checkpointer, ...), or the postmaster alone
      # (existing sessions go on, new connections wait), by their ids.
      pm=$(head -1 "$PG_DIR/data/postmaster.pid")
      if [[ $kind == sigstop ]]; then mapfile -t PG_STOPPED < <(echo "$pm"; children_of "$pm"); else PG_STOPPED=("$pm"); fi
      kill -STOP "${PG_STOPPED[@]}"
      sleep "$DB_STOP_S"
      kill -CONT "${PG_STOPPED[@]}"
      PG_STOPPED=() ;;
  esac
  t1=$(date +%s.%N)
  echo "$kind $t0 $t1" >>"$WORK/db-faults"
  local extra=""
  [[ $kind == terminate ]] && extra=": $(cat "$WORK/terminated") session(s) terminated"
  echo "lab-drill: database $kind ($(python3 -c "print(f'{$t1 - $t0:.1f}')") s)$extra" >&2
}

# Chaos: while runs remain (and until every fault happened), at random intervals: a random host is SIGKILLed
# and restarted, or SIGSTOPped for longer than the lease TTL (its leases lapse, another host re-queues its runs)
# and continued; the database faults asked for happen once each, in a random order among them.
declare -a EVENTS=()
for ((k = 0; k < KILLS; k++)); do EVENTS+=(host); done
EVENTS+=("${DB_FAULT_LIST[@]}")
if ((${#EVENTS[@]} > 1)); then
  mapfile -t EVENTS < <(printf '%s\n' "${EVENTS[@]}" | python3 -c "import random, sys; random.seed($SEED); e = sys.stdin.read().split(); random.shuffle(e); print('\n'.join(e))")
fi
: >"$WORK/db-faults"
kills=0 db_faults=0 event=0 stuck=0
DRAIN_T0=""
while :; do
  rem=$(remaining || echo unknown)
  if ((event >= ${#EVENTS[@]})) && [[ $rem == 0 ]]; then break; fi
  if [[ $rem == 0 ]]; then
    echo "lab-drill: the queue drained after $event of ${#EVENTS[@]} faults: use more runs or fewer faults" >&2
    break
  fi
  if ((event < ${#EVENTS[@]})); then
    sleep "$(python3 -c "import random; random.seed($SEED + $event); print(round(random.uniform($KILL_MIN_S, $KILL_MAX_S), 2))")"
    if [[ ${EVENTS[$event]} == host ]]; then
      h=$((RANDOM % HOSTS + 1))
      if ((RANDOM % 2 == 0)); then
        kill -KILL "${PIDS[$h]}"
        wait "${PIDS[$h]}" 2>/dev/null || true
        echo "lab-drill: SIGKILL host$h" >&2
        STARTS[$h]=$((STARTS[$h] + 1))
        start_host "$h"
      else
        kill -STOP "${PIDS[$h]}"
        echo "lab-drill: SIGSTOP host$h" >&2
        sleep "$(python3 -c "print($LEASE_TTL_S * 1.5 + 0.3)")"
        kill -CONT "${PIDS[$h]}"
      fi
      kills=$((kills + 1))
    else
      db_fault "${EVENTS[$event]}"
      db_faults=$((db_faults + 1))
    fi
    event=$((event + 1))
  else
    # Every fault happened: the queue must drain within DRAIN_S (a run stuck in running hangs nothing).
    [[ -n $DRAIN_T0 ]] || DRAIN_T0=$(date +%s)
    if (($(date +%s) - DRAIN_T0 > ${DRAIN_S%.*})); then
      stuck=$rem
      echo "lab-drill: the queue did not drain within $DRAIN_S s after the last fault: $rem run(s) left" >&2
      break
    fi
    sleep 0.1
  fi
done
T1=$(date +%s.%N)

# Stop the hosts cleanly, then count from the database.
for ((h = 1; h <= HOSTS; h++)); do kill -TERM "${PIDS[$h]}" 2>/dev/null || true; done
for ((h = 1; h <= HOSTS; h++)); do wait "${PIDS[$h]}" 2>/dev/null || true; PIDS[$h]=""; done

RUNS_Q="SELECT id FROM runs WHERE id IN (SELECT run_id FROM run_tags WHERE tag = 'lab-drill')"
stored=$(db_query "SELECT count(*) FROM ($RUNS_Q) AS drill_runs")
done_n=$(db_query "SELECT count(*) FROM runs WHERE status = 'done' AND id IN ($RUNS_Q)")
# Run twice: more than one 'done' in a run's history, or more than one attempt that stored a final state.
duplicated=$(db_query "SELECT count(*) FROM (SELECT run_id FROM status_history WHERE status IN ('done', 'failed', 'cancelled')
                       AND run_id IN ($RUNS_Q) GROUP BY run_id HAVING count(*) > 1) AS twice")
stale=$(db_query "SELECT count(*) FROM stale_writes WHERE run_id IN ($RUNS_Q)")
lost=$((RUNS - done_n))
failed=$(db_query "SELECT count(*) FROM runs WHERE status = 'failed' AND id IN ($RUNS_Q)")
# Attempts that did not finish (a killed or stopped host, a result dropped): each is an 'interrupted' in the
# run's history, and the run ran again.
interrupted=$(db_query "SELECT count(*) FROM status_history WHERE status = 'interrupted' AND run_id IN ($RUNS_Q)")
[[ $stored == "$RUNS" ]] || echo "lab-drill: $stored runs stored, $RUNS submitted" >&2
not_done=$(db_query "SELECT status || ' ' || count(*) FROM runs WHERE status != 'done' AND id IN ($RUNS_Q) GROUP BY status")
if [[ -n $not_done ]]; then
  # What happened to them, for the log: each such run's history (at most 10 runs).
  echo "lab-drill: not done: $not_done" >&2
  db_query "SELECT r.id, h.status, h.reason FROM runs r JOIN status_history h ON h.run_id = r.id
            WHERE r.id IN (SELECT id FROM runs WHERE status != 'done' AND id IN ($RUNS_Q) LIMIT 10)
            ORDER BY r.id, h.id" |
    sed 's/^/lab-drill:   run /' >&2
fi
# The drained rate (runs per wall second from the first submission to the empty queue) over one paced bench's
# (1 / RUN_S: it runs RUN_S of bench time per run in RUN_S of wall time, nothing else counted).
throughput_x=$(python3 -c "print(f'{$done_n / ($T1 - $T0) * $RUN_S:.2f}')")
wall=$(python3 -c "print(f'{$T1 - $T0:.1f}')")
echo "lab-drill: drained in $wall s; work directory $WORK" >&2
# Each database fault: its length, and the lab's stall around it: the longest gap between two consecutive
# finishes from the last finish before the fault began to the first after it ended.
if [[ -s $WORK/db-faults ]]; then
  db_query "SELECT at FROM status_history WHERE status = 'done' AND run_id IN ($RUNS_Q) ORDER BY at" >"$WORK/finishes"
  python3 - "$WORK/db-faults" "$WORK/finishes" "$T0" <<'PY' >&2
import bisect, sys
faults = [l.split() for l in open(sys.argv[1]) if l.strip()]
done = [float(x) for x in open(sys.argv[2]) if x.strip()]
t0 = float(sys.argv[3])
for kind, a, b in faults:
    a, b = float(a), float(b)
    i = bisect.bisect_right(done, a) - 1          # the last finish before the fault began
    j = bisect.bisect_left(done, b)               # the first finish after it ended
    if i < 0 or i + 1 >= len(done):
        print(f"lab-drill: db fault {kind} at +{a - t0:.1f} s: {b - a:.1f} s; no finish on both sides to measure the stall")
        continue
    drained = j >= len(done)  # the last run finished before the fault ended (runs went on during it)
    stall = max(done[k + 1] - done[k] for k in range(i, min(j, len(done) - 1)))
    print(f"lab-drill: db fault {kind} at +{a - t0:.1f} s: {b - a:.1f} s; the lab's stall {stall:.1f} s" +
          (" (the queue drained during the fault)" if drained else ""))
PY
fi
echo "lab-drill: hosts=$HOSTS benches=$((HOSTS * BENCHES)) runs=$RUNS done=$done_n lost=$lost duplicated=$duplicated failed=$failed stuck=$stuck kills=$kills db_faults=$db_faults interrupted=$interrupted stale_writes_refused=$stale throughput_x=$throughput_x"
if ((event < ${#EVENTS[@]})); then
  echo "lab-drill: FAILED: only $event of ${#EVENTS[@]} faults happened before the queue drained (the drill did not test them)" >&2
  exit 1
fi
if ((lost == 0 && duplicated == 0 && failed == 0 && stuck == 0)); then exit 0; else exit 1; fi
