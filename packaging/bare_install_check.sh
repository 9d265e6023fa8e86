#!/usr/bin/env bash
# By hand, with network (not in CTest): does `apt install ./valvebench_*.deb` on a bare Debian 12 pull what the
# package needs? debootstraps a minimal bookworm into a temporary directory, installs the package there with
# apt (its Depends and Recommends from the Debian archive), runs the installed benchctl on the embedded
# emulator, the installed server with the shipped config (expecting the refusal for the missing tokens) and the
# installed Python package, then deletes the directory. Root only.
# Usage: packaging/bare_install_check.sh path/to/valvebench_VERSION_ARCH.deb [MIRROR]
set -euo pipefail
deb="$(readlink -f "$1")"
mirror="${2:-http://deb.debian.org/debian}"
[ "$(id -u)" -eq 0 ] || { echo "bare_install_check: needs root (debootstrap, chroot)" >&2; exit 2; }
command -v debootstrap >/dev/null || { echo "bare_install_check: apt-get install debootstrap" >&2; exit 2; }

root="$(mktemp -d /tmp/vb-bare-XXXXXX)"
cleanup() {
  umount "$root/proc" 2>/dev/null || true
  rm -rf --one-file-system "$root"
}
trap cleanup EXIT
t0=$(date +%s)
debootstrap --variant=minbase bookworm "$root" "$mirror" >"$root.debootstrap.log" 2>&1 ||
  { tail -20 "$root.debootstrap.log"; exit 1; }
rm -f "$root.debootstrap.log"
mount -t proc proc "$root/proc"
cp "$deb" "$root/tmp/"
name="$(basename "$deb")"
echo "bare_install_check: minimal bookworm in $(( $(date +%s) - t0 )) s; installing $name with apt"
chroot "$root" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin DEBIAN_FRONTEND=noninteractive bash -euo pipefail -c "
  apt-get update -qq
  apt-get install -y -qq ./tmp/$name >/tmp/apt.log 2>&1 || { tail -30 /tmp/apt.log; exit 1; }
  echo \"bare_install_check: apt installed \$(grep -c '^Setting up' /tmp/apt.log) packages\"
  id -nG valvebench | grep -qw plugdev
  test -d /var/lib/valvebench
  benchctl run --local /usr/share/valvebench/examples/standard/e1.json --db /tmp/local.db >/dev/null
  set +e
  valvebench-server --config /etc/valvebench/server.json 2>/tmp/server.log
  code=\$?
  set -e
  test \$code -eq 2 && grep -q tokens /tmp/server.log
  python3 -c 'import valvebench, valvebench.local as l; assert l.find_tool(\"benchctl\") == \"/usr/bin/benchctl\"'
  apt-get purge -y -qq valvebench >/dev/null
  test ! -e /var/lib/valvebench
"
echo "bare_install_check: OK: installed with apt on a bare bookworm, benchctl ran, the server refused the" \
  "token-less config, Python imported, purged; $(( $(date +%s) - t0 )) s"
