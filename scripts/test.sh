#!/usr/bin/env bash
# Runs the whole test suite: installs what is missing and builds (scripts/setup.sh), then CTest on 2 cores.
# JUnit XML lands in build/test-results.xml for CI systems that read it.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$here/scripts/setup.sh"
cd "$here/build"
ctest --output-on-failure -j "$(nproc)" --output-junit test-results.xml "$@"
# The fuzz targets, a short bounded run each (VB_FUZZ_SECONDS, default 12 s per target): any crash fails CI.
bash "$here/scripts/fuzz.sh" "${VB_FUZZ_SECONDS:-12}"
