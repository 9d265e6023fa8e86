#!/usr/bin/env bash
# The Debian package, end to end (CTest: Package.InstallRunUpgradePurge, label "package"):
#   1. builds it with CPack from an existing, built build/ (no rebuild), and an older-versioned copy of it
#   2. inspects its fields, contents, conffiles, maintainer scripts and unit; every shared library the programs
#      load comes from a package it depends on
#   3. installs the older one on this machine (dpkg -i: root only), checks the user, the store directory, the
#      config's permissions, and that the shipped config (no tokens) is refused with exit 2
#   4. sets a token as an operator would, starts the installed server from the unit's ExecStart as the unit's
#      User, runs one emulated experiment through the installed benchctl, imports the installed Python package
#   5. upgrades to the current package: the operator's config is kept, the run is found again
#   6. removes it (the store stays), then purges it, and checks the machine is as it was before
# Usage: package_test.sh BUILD_DIR WORK_DIR. Exit 77 (skipped) when not root, without dpkg/cpack, or when this
# machine already has valvebench installed or a valvebench user (the test never touches an existing install).
set -euo pipefail

build="$(cd "$1" && pwd)"
work="$2"
say() { echo "package_test: $*"; }
fail() { echo "package_test: FAIL: $*" >&2; exit 1; }
skip() { echo "package_test: SKIPPED: $*"; exit 77; }

[ "$(id -u)" -eq 0 ] || skip "needs root (it installs the package with dpkg; CI runs as root)"
for tool in dpkg dpkg-deb cpack dpkg-shlibdeps setpriv readelf python3; do
  command -v "$tool" >/dev/null || skip "$tool not found (scripts/setup.sh installs dpkg-dev)"
done
if dpkg-query -W -f='${Status}' valvebench 2>/dev/null | grep -qv "not-installed"; then
  skip "the valvebench package is installed on this machine: not touching it"
fi
getent passwd valvebench >/dev/null && skip "a valvebench user exists on this machine: not touching it"
[ -e /etc/valvebench ] && skip "/etc/valvebench exists on this machine: not touching it"
[ -e /var/lib/valvebench ] && skip "/var/lib/valvebench exists on this machine: not touching it"

rm -rf "$work"
mkdir -p "$work"
# What "as it was" means: installed packages, users and groups, and the places the package writes.
snapshot() {
  {
    dpkg-query -W -f='${Package} ${Version} ${Status}\n' | sort
    getent passwd | cut -d: -f1 | sort
    getent group | cut -d: -f1,4 | sort
    find /etc/systemd/system -printf '%p %l\n' 2>/dev/null | sort
    ls /var/lib/systemd/deb-systemd-helper-enabled /var/lib/systemd/deb-systemd-helper-masked 2>/dev/null || true
    ls -d /etc/valvebench /var/lib/valvebench /usr/lib/python3/dist-packages/valvebench 2>/dev/null || true
  } >"$1"
}
snapshot "$work/before.txt"

server_pid=""
cleanup() {
  if [ -n "$server_pid" ]; then kill -KILL "$server_pid" 2>/dev/null || true; wait "$server_pid" 2>/dev/null || true; fi
  if dpkg-query -W -f='${Status}' valvebench 2>/dev/null | grep -qv "not-installed"; then
    dpkg --purge valvebench >/dev/null 2>&1 || true
  fi
}
trap cleanup EXIT

# ---- 1. build ---------------------------------------------------------------------------------------------
t0=$(date +%s)
version=$(sed -n 's/^set(CPACK_PACKAGE_VERSION "\(.*\)")$/\1/p' "$build/CPackConfig.cmake")
[ -n "$version" ] || fail "no CPACK_PACKAGE_VERSION in $build/CPackConfig.cmake"
(cd "$build" && cpack --config CPackConfig.cmake -G DEB -B "$work/pkg" >"$work/cpack.log" 2>&1) ||
  { cat "$work/cpack.log"; fail "cpack failed"; }
deb="$work/pkg/valvebench_${version}_$(dpkg --print-architecture).deb"
[ -f "$deb" ] || { ls -la "$work/pkg"; fail "cpack made no $deb"; }
# The previous version: the same files under an older version number (it sorts before $version).
old_version="${version}~previous1"
dpkg-deb -R "$deb" "$work/old"
sed -i "s/^Version: .*/Version: ${old_version}/" "$work/old/DEBIAN/control"
dpkg-deb -Zgzip -z1 -b "$work/old" "$work/valvebench_${old_version}.deb" >/dev/null
old_deb="$work/valvebench_${old_version}.deb"
say "built $(basename "$deb") ($(du -k "$deb" | cut -f1) kB) and $(basename "$old_deb") in $(( $(date +%s) - t0 )) s"

# ---- 2. inspect -------------------------------------------------------------------------------------------
field() { dpkg-deb -f "$deb" "$1"; }
[ "$(field Package)" = valvebench ] || fail "Package: $(field Package)"
[ "$(field Version)" = "$version" ] || fail "Version: $(field Version)"
depends="$(field Depends)"
for dep in adduser init-system-helpers libgrpc++ libprotobuf libsqlite3 libpq5 libzstd libusb-1.0 libc6; do
  grep -q "$dep" <<<"$depends" || fail "Depends lacks $dep: $depends"
done
grep -q python3-grpcio <<<"$(field Recommends)" || fail "Recommends lacks python3-grpcio"
dpkg-deb -c "$deb" | awk '{print $6}' | sed 's|^\./|/|' >"$work/contents.txt"
for f in /usr/bin/valvebench-server /usr/bin/benchctl /etc/valvebench/server.json \
         /usr/lib/systemd/system/valvebench.service /usr/lib/udev/rules.d/60-valvebench.rules \
         /usr/lib/python3/dist-packages/valvebench/__init__.py /usr/lib/python3/dist-packages/valvebench/_build_paths.py \
         /usr/lib/python3/dist-packages/valvebench/v1/api_pb2_grpc.py /usr/share/doc/valvebench/README.md \
         /usr/share/doc/valvebench/lab.md /usr/share/valvebench/examples/standard/e1.json \
         /usr/share/valvebench/examples/server/server.json; do
  grep -qx "$f" "$work/contents.txt" || fail "the package lacks $f"
done
if grep -E '__pycache__|\.pyc$|/var/lib/valvebench/.|\.new$' "$work/contents.txt"; then fail "stray files in the package"; fi
ctl="$work/control"
dpkg-deb -e "$deb" "$ctl"
[ "$(cat "$ctl/conffiles")" = /etc/valvebench/server.json ] || fail "conffiles: $(cat "$ctl/conffiles")"
for s in postinst prerm postrm; do
  [ -x "$ctl/$s" ] || fail "$s is not executable"
  sh -n "$ctl/$s" || fail "$s: shell syntax"
done
grep -q 'adduser --quiet --system --group' "$ctl/postinst" || fail "postinst does not create the system user"
grep -q 'adduser --quiet valvebench plugdev' "$ctl/postinst" || fail "postinst does not put the user in plugdev"
grep -q 'udevadm control --reload-rules' "$ctl/postinst" || fail "postinst does not reload udev"
grep -q 'rm -rf /var/lib/valvebench' "$ctl/postrm" || fail "postrm purge keeps the store"
dpkg-deb --fsys-tarfile "$deb" | tar -x -O ./usr/lib/systemd/system/valvebench.service >"$work/unit"
for line in 'User=valvebench' 'SupplementaryGroups=plugdev' 'Restart=on-failure' 'KillSignal=SIGTERM' \
            'ExecStart=/usr/bin/valvebench-server --config /etc/valvebench/server.json' 'StateDirectory=valvebench' \
            'NoNewPrivileges=yes' 'ProtectSystem=strict' 'WantedBy=multi-user.target'; do
  grep -qx "$line" "$work/unit" || fail "the unit lacks $line"
done
grep -q 'PrivateDevices=yes\|PrivateUsers=yes\|DevicePolicy=closed' "$work/unit" && fail "the unit hides USB devices"
dpkg-deb --fsys-tarfile "$deb" | tar -x -O ./etc/valvebench/server.json >"$work/shipped.json"
python3 - "$work/shipped.json" <<'EOF' || fail "the shipped config"
import json, sys
c = json.load(open(sys.argv[1]))
assert c["tokens"] == [], "demo tokens shipped: %r" % c["tokens"]
assert c["database_path"] == "/var/lib/valvebench/runs.db", c["database_path"]
EOF
# apt's resolver takes it as `apt install ./valvebench_*.deb` would (simulated: nothing is installed here).
if command -v apt-get >/dev/null; then
  apt-get install -s --no-install-recommends "$deb" >"$work/apt-sim.log" 2>&1 || { cat "$work/apt-sim.log"; fail "apt-get install -s"; }
  grep -q "^Inst valvebench ($version " "$work/apt-sim.log" || { cat "$work/apt-sim.log"; fail "apt would not install it"; }
fi
say "inspected: fields, $(wc -l <"$work/contents.txt") paths, conffiles, maintainer scripts, unit, config"

# ---- 3. install the previous version ----------------------------------------------------------------------
dpkg -i "$old_deb" >"$work/dpkg-install.log" 2>&1 || { cat "$work/dpkg-install.log"; fail "dpkg -i $old_deb"; }
getent passwd valvebench >/dev/null || fail "no valvebench user"
id -nG valvebench | tr ' ' '\n' | grep -qx plugdev || fail "valvebench is not in plugdev: $(id -nG valvebench)"
[ "$(stat -c '%U:%G %a' /var/lib/valvebench)" = "valvebench:valvebench 750" ] ||
  fail "/var/lib/valvebench: $(stat -c '%U:%G %a' /var/lib/valvebench)"
[ "$(stat -c '%U:%G %a' /etc/valvebench/server.json)" = "root:valvebench 640" ] ||
  fail "/etc/valvebench/server.json: $(stat -c '%U:%G %a' /etc/valvebench/server.json)"
grep -q "no tokens yet" "$work/dpkg-install.log" || fail "postinst did not say the config has no tokens"
# Every shared library the installed programs link (NEEDED) comes from a package the .deb depends on, so apt
# pulls it on a bare machine (the libraries those load are their packages' dependencies).
depends_names=$(sed 's/([^)]*)//g' <<<"$depends" | tr ',|' '\n\n' | tr -d ' ')
for bin in /usr/bin/valvebench-server /usr/bin/benchctl; do
  for soname in $(readelf -d "$bin" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p'); do
    lib=$(ldd "$bin" | awk -v s="$soname" '$1 == s {print $3}')
    [ -n "$lib" ] || fail "$bin needs $soname, which ldd does not find"
    owner=$(dpkg -S "$lib" 2>/dev/null || dpkg -S "$(readlink -f "$lib")" 2>/dev/null || true)
    owner=$(head -1 <<<"$owner" | cut -d: -f1)
    [ -n "$owner" ] || fail "$bin needs $lib, which no package owns"
    # The package itself, or a name it provides (libspdlog1.10 provides libspdlog1.10-fmt9), is depended on.
    names=$(printf '%s\n' "$owner"; dpkg-query -W -f='${Provides}' "$owner" | sed 's/([^)]*)//g' | tr ',' '\n' | tr -d ' ')
    grep -qxFf <(grep . <<<"$names") <<<"$depends_names" ||
      fail "$bin needs $lib from $owner, not in Depends: $depends"
  done
done

# The unit's command line and user, as systemd would run them.
exec_start=$(sed -n 's/^ExecStart=//p' /usr/lib/systemd/system/valvebench.service)
unit_user=$(sed -n 's/^User=//p' /usr/lib/systemd/system/valvebench.service)
[ -n "$exec_start" ] && [ "$unit_user" = valvebench ] || fail "ExecStart/User not found in the installed unit"
if command -v systemd-analyze >/dev/null; then
  systemd-analyze verify /usr/lib/systemd/system/valvebench.service >"$work/verify.log" 2>&1 ||
    { cat "$work/verify.log"; fail "systemd-analyze verify"; }
fi
# setpriv execs (runuser would stay in between and turn the server's SIGTERM exit into its own).
as_unit_user=(setpriv --reuid="$unit_user" --regid="$unit_user" --init-groups --no-new-privs --)
run_unit() {  # the unit's ExecStart as its user and groups, from / as systemd starts it, stderr to $1
  cd /
  exec "${as_unit_user[@]}" $exec_start 2>"$1" >/dev/null
}
set +e
(cd / && timeout 20 "${as_unit_user[@]}" $exec_start) 2>"$work/notokens.log" >/dev/null
code=$?
set -e
[ "$code" -eq 2 ] || { cat "$work/notokens.log"; fail "the shipped config (no tokens) gave exit $code, not 2"; }
grep -q "tokens" "$work/notokens.log" || fail "the refusal does not name tokens: $(cat "$work/notokens.log")"

# ---- 4. the operator sets a token; the installed server runs an experiment --------------------------------
token="package-test-token-$$"
python3 - "$token" <<'EOF'
import hashlib, json, sys
p = "/etc/valvebench/server.json"
c = json.load(open(p))
c["tokens"] = [{"user": "ci", "role": "operator", "token_sha256": hashlib.sha256(sys.argv[1].encode()).hexdigest()}]
c["listen_address"] = "127.0.0.1:0"          # any free port: tests run beside each other
c["web"]["listen_address"] = "127.0.0.1:0"
open(p, "w").write(json.dumps(c, indent=2) + "\n")
EOF

start_server() {  # $1: log; sets server_pid and addr
  (run_unit "$1") &
  server_pid=$!
  addr=""
  for _ in $(seq 1 200); do
    addr=$(sed -n 's/.*listening on \([^ ]*\) .*/\1/p' "$1" | head -1)
    [ -n "$addr" ] && return 0
    kill -0 "$server_pid" 2>/dev/null || { cat "$1"; fail "the installed server exited"; }
    sleep 0.1
  done
  cat "$1"; fail "the installed server did not listen in 20 s"
}
stop_server() {  # SIGTERM, as the unit's KillSignal: exit 0
  kill -TERM "$server_pid"
  local code=0
  wait "$server_pid" || code=$?
  server_pid=""
  [ "$code" -eq 0 ] || fail "the server exited $code on SIGTERM"
}

start_server "$work/server-1.log"
grep -q "database /var/lib/valvebench/runs.db" "$work/server-1.log" || fail "not on the installed store"
ran=$(cd / && env -u VALVEBENCH_DB -u VALVEBENCH_SERVER /usr/bin/benchctl run \
        /usr/share/valvebench/examples/standard/e1.json --server "$addr" --token "$token" --wait --json) ||
  fail "benchctl run through the installed server: $ran"
run_id=$(python3 -c 'import json,sys; d=json.loads(sys.argv[1]); r=d["runs"] if isinstance(d,dict) and "runs" in d else d; print(r[0]["id"] if isinstance(r,list) else r["id"])' "$ran") ||
  fail "no run id in: ${ran:0:400}"
show=$(/usr/bin/benchctl show "$run_id" --json --server "$addr" --token "$token") || fail "show $run_id: $show"
grep -q '"done"' <<<"$show" || fail "run $run_id is not done: ${show:0:400}"
[ "$(stat -c %U /var/lib/valvebench/runs.db)" = valvebench ] || fail "the store is not the service user's"
# The installed Python package, from a neutral directory and environment, finds the installed programs.
py=$(cd / && env -i PATH=/usr/bin:/bin python3 -c 'import valvebench, valvebench.local as l; print(valvebench.__file__, l.find_tool("benchctl"))') ||
  fail "the installed Python package: $py"
[ "$py" = "/usr/lib/python3/dist-packages/valvebench/__init__.py /usr/bin/benchctl" ] || fail "python: $py"
stop_server
say "installed $old_version: run $run_id done through the installed server and benchctl"

# ---- 5. upgrade ------------------------------------------------------------------------------------------
dpkg -i "$deb" >"$work/dpkg-upgrade.log" 2>&1 || { cat "$work/dpkg-upgrade.log"; fail "dpkg -i $deb (upgrade)"; }
[ "$(dpkg-query -W -f='${Version}' valvebench)" = "$version" ] || fail "not upgraded"
grep -q "$(printf %s "$token" | sha256sum | cut -d' ' -f1)" /etc/valvebench/server.json ||
  fail "the upgrade lost the operator's config"
[ ! -e /etc/valvebench/server.json.dpkg-dist ] || fail "dpkg asked about the config"
start_server "$work/server-2.log"
show=$(/usr/bin/benchctl show "$run_id" --json --server "$addr" --token "$token") || fail "after the upgrade: $show"
grep -q '"done"' <<<"$show" || fail "run $run_id lost in the upgrade: ${show:0:400}"
stop_server
say "upgraded to $version: config kept, run $run_id found again"

# ---- 6. remove, purge ------------------------------------------------------------------------------------
dpkg -r valvebench >"$work/dpkg-remove.log" 2>&1 || { cat "$work/dpkg-remove.log"; fail "dpkg -r"; }
[ ! -e /usr/bin/valvebench-server ] || fail "removal left the program"
[ -f /var/lib/valvebench/runs.db ] || fail "removal deleted the store"
[ -f /etc/valvebench/server.json ] || fail "removal deleted the config"
dpkg --purge valvebench >"$work/dpkg-purge.log" 2>&1 || { cat "$work/dpkg-purge.log"; fail "dpkg --purge"; }
[ ! -e /var/lib/valvebench ] || fail "purge kept /var/lib/valvebench"
[ ! -e /etc/valvebench ] || fail "purge kept /etc/valvebench"
snapshot "$work/after.txt"
diff -u "$work/before.txt" "$work/after.txt" || fail "the machine differs after the purge (above)"
say "removed (store kept), purged; the machine is as it was; $(( $(date +%s) - t0 )) s in all"
