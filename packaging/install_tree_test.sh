#!/usr/bin/env bash
# `cmake --install BUILD --prefix DIR` gives a tree that runs from DIR (CTest: Package.InstallTreeRunsFromItsPrefix,
# label "package"; any user): the installed unit's ExecStart runs the installed server on the installed config
# (once a token is set), its store lands in DIR/var/lib/valvebench, the installed benchctl runs an installed
# example through it, the installed Python package finds DIR/bin by itself, and installing again keeps the
# operator's config (the new default goes beside it as server.json.new).
# Usage: install_tree_test.sh BUILD_DIR WORK_DIR
set -euo pipefail

build="$(cd "$1" && pwd)"
work="$2"
fail() { echo "install_tree_test: FAIL: $*" >&2; exit 1; }
rm -rf "$work"
mkdir -p "$work"
tree="$work/tree"
cmake --install "$build" --prefix "$tree" >"$work/install.log" 2>&1 || { cat "$work/install.log"; fail "cmake --install"; }

unit="$tree/lib/systemd/system/valvebench.service"
exec_start=$(sed -n 's/^ExecStart=//p' "$unit")
[ "$exec_start" = "$tree/bin/valvebench-server --config $tree/etc/valvebench/server.json" ] ||
  fail "ExecStart is not the tree's: $exec_start"
[ -f "$tree/lib/udev/rules.d/60-valvebench.rules" ] || fail "no udev rules"
[ -f "$tree/share/doc/valvebench/server.md" ] || fail "no docs"
[ -d "$tree/var/lib/valvebench" ] || fail "no store directory"

token="tree-test-token-$$"
/usr/bin/python3 - "$tree/etc/valvebench/server.json" "$token" <<'EOF'
import hashlib, json, sys
p = sys.argv[1]
c = json.load(open(p))
assert c["tokens"] == [], c["tokens"]
assert c["database_path"] == p.rsplit("/etc/", 1)[0] + "/var/lib/valvebench/runs.db", c["database_path"]
c["tokens"] = [{"user": "ci", "role": "operator", "token_sha256": hashlib.sha256(sys.argv[2].encode()).hexdigest()}]
c["listen_address"] = "127.0.0.1:0"
c["web"]["listen_address"] = "127.0.0.1:0"
open(p, "w").write(json.dumps(c, indent=2) + "\n")
EOF

(cd / && exec $exec_start) 2>"$work/server.log" >/dev/null &
pid=$!
trap 'kill -KILL $pid 2>/dev/null || true' EXIT
addr=""
for _ in $(seq 1 200); do
  addr=$(sed -n 's/.*listening on \([^ ]*\) .*/\1/p' "$work/server.log" | head -1)
  [ -n "$addr" ] && break
  kill -0 "$pid" 2>/dev/null || { cat "$work/server.log"; fail "the installed server exited"; }
  sleep 0.1
done
[ -n "$addr" ] || { cat "$work/server.log"; fail "the installed server did not listen"; }
out=$(cd / && env -u VALVEBENCH_SERVER -u VALVEBENCH_DB "$tree/bin/benchctl" run \
        "$tree/share/valvebench/examples/standard/e1.json" --server "$addr" --token "$token" --wait) ||
  fail "benchctl run: $out"
[ -s "$tree/var/lib/valvebench/runs.db" ] || fail "the store is not in the tree"
py=$(cd / && env -i PATH=/usr/bin:/bin PYTHONPATH="$tree/lib/python3/dist-packages" /usr/bin/python3 -c \
       'import valvebench.local as l; print(l.find_tool("benchctl"))') || fail "python: $py"
[ "$py" = "$tree/bin/benchctl" ] || fail "the installed Python package finds $py, not the tree's benchctl"
kill -TERM "$pid"
code=0
wait "$pid" || code=$?
[ "$code" -eq 0 ] || fail "SIGTERM: exit $code"

cmake --install "$build" --prefix "$tree" >"$work/install-2.log" 2>&1 || fail "second cmake --install"
grep -q "$token" "$tree/etc/valvebench/server.json" 2>/dev/null ||
  grep -q "$(printf %s "$token" | sha256sum | cut -d' ' -f1)" "$tree/etc/valvebench/server.json" ||
  fail "a second install replaced the operator's config"
[ -f "$tree/etc/valvebench/server.json.new" ] || fail "no server.json.new beside the kept config"
echo "install_tree_test: $tree runs from itself: server, benchctl run, Python, config kept on reinstall"
