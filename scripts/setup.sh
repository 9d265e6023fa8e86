#!/usr/bin/env bash
# Installs every Debian 12 package valvebench needs (toolchain included), then configures and builds.
# Idempotent: packages already present are left alone; an existing build/ is reused.
#   scripts/setup.sh            install + configure + build (Release)
#   scripts/setup.sh --deps     install only
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
packages=(
  # toolchain
  g++ cmake ninja-build make pkg-config git ca-certificates ccache
  # RPC and specs
  libgrpc++-dev libprotobuf-dev protobuf-compiler protobuf-compiler-grpc libssl-dev
  # numerics: Eigen for small linear algebra, Boost.Odeint for the dense-output Runge-Kutta stepper,
  # NLopt for bounded fitting in the gap diagnosis
  libeigen3-dev libboost-dev libnlopt-cxx-dev
  # hardware
  libusb-1.0-0-dev libhidapi-dev
  # storage, CLI, JSON
  libsqlite3-dev sqlite3 libcli11-dev nlohmann-json3-dev openssl
  # compressed trace chunks (docs/store.md, "Trace encoding")
  libzstd-dev
  # the PostgreSQL store for a lab of hosts (libpq), and the server its tests start (docs/store.md, "PostgreSQL")
  libpq-dev postgresql
  # text formatting ({fmt}) and the server's log (spdlog)
  libfmt-dev libspdlog-dev
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
  # the foreign-client integration test (a gRPC client built only from our .proto files)
  python3 python3-grpcio python3-protobuf
  # the Python package (python/), its pytest plugin, notebooks, HDF5/MAT export (docs/python.md)
  python3-numpy python3-pandas python3-pytest python3-matplotlib python3-h5py python3-scipy
  jupyter-nbconvert python3-nbformat python3-nbclient python3-ipykernel python3-venv python3-pip
  python3-setuptools libhdf5-dev libmatio-dev
  # the HTML report test: the page must render without errors in a headless browser
  chromium
  # the web dashboard (docs/web.md): HTTP server, the chart library it serves and the reports inline, and its
  # browser test (chromium driven through chromium-driver by selenium)
  libcpp-httplib-dev libjs-dygraphs chromium-driver python3-selenium
  # the Debian package (packaging/, CPack): dpkg-shlibdeps computes its Depends; its test installs it, which
  # runs its maintainer scripts (adduser)
  dpkg-dev adduser
  # packaging/bare_install_check.sh (by hand): the package on a debootstrapped bare Debian 12
  debootstrap
  # fuzzing (fuzz/, scripts/fuzz.sh): clang with libFuzzer and the sanitizer runtimes
  clang libclang-rt-14-dev
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update
  $SUDO apt-get install -y --no-install-recommends "${missing[@]}"
fi

[ "${1:-}" = "--deps" ] && exit 0

# ccache keys on the compiler's command line: with the checkout as its base directory, paths are relative to it,
# so a second clone or worktree (CI's fresh clone on a developer's machine) reuses the objects already built.
export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$here}"
cd "$here"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release
cmake --build build
