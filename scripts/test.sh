#!/usr/bin/env bash
# Runs the whole test suite: installs what is missing and builds (scripts/setup.sh), then CTest on 2 cores.
# JUnit XML lands in build/test-results.xml for CI systems that read it.
#
# It runs in the environment a fresh Debian 12 gives a login (issue 41, docs/ci.md): whatever the calling shell
# sets (PYTHONDONTWRITEBYTECODE, PYTHONPATH, proxies, a virtualenv's PATH, LC_ALL, ...) is dropped, and only a
# standard PATH (without /usr/local, which is empty on a fresh Debian), LANG=C.UTF-8 and HOME are kept, so a test
# that passes only thanks to a developer's or a CI machine's variables fails here too. VB_FUZZ_SECONDS (the fuzz
# campaign's seconds per target; unset: no campaign, below) is passed on.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ "${VB_TEST_CLEAN_ENV:-}" != 1 ]; then
  home="${HOME:-$(getent passwd "$(id -u)" | cut -d: -f6)}"
  exec env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8 HOME="$home" \
    VB_TEST_CLEAN_ENV=1 ${VB_FUZZ_SECONDS:+VB_FUZZ_SECONDS="$VB_FUZZ_SECONDS"} \
    bash "$here/scripts/test.sh" "$@"
fi
bash "$here/scripts/setup.sh"
cd "$here/build"
ctest --output-on-failure -j "$(nproc)" --output-junit test-results.xml "$@"
# The fuzz targets' seeds and fixed-seed mutations ran in CTest (Fuzz.*, the normal build). The coverage-guided
# campaign (clang, ASan, UBSan; its own instrumented build, 7.4 minutes from scratch on 2 cores) runs when
# VB_FUZZ_SECONDS (seconds per target) is set: any crash fails. docs/fuzzing.md says when to run it.
if [ -n "${VB_FUZZ_SECONDS:-}" ] && [ "${VB_FUZZ_SECONDS}" != 0 ]; then
  bash "$here/scripts/fuzz.sh" "$VB_FUZZ_SECONDS"
fi
