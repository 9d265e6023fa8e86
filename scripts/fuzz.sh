#!/usr/bin/env bash
# Builds the libFuzzer targets of fuzz/ with clang (ASan + UBSan) into build-fuzz/ and runs each for a bounded
# time. Exit 1 if any target finds a crash, a leak, undefined behaviour, a timeout or an out-of-memory; the
# input that did it is in build-fuzz/artifacts/. docs/fuzzing.md has the targets and a longer campaign's figures.
#   scripts/fuzz.sh [SECONDS_PER_TARGET]     default 20; VB_FUZZ_SECONDS=N scripts/test.sh runs it after the suite
# (CI's suite replays the targets' seeds and fixed-seed mutations in CTest instead: docs/fuzzing.md, "In CI").
# Corpora grow in build-fuzz/corpus/<target>/ (kept between runs); the committed seeds are fuzz/corpus/<name>/.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
seconds="${1:-20}"
build="$here/build-fuzz"
jobs="${VB_FUZZ_BUILD_JOBS:-2}"

# ccache keys on the compiler's command line: with the checkout as its base directory, paths are relative to it,
# so a second clone or worktree (CI's fresh clone on a developer's machine) reuses the objects already built.
export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$here}"
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S "$here" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ \
  -DVB_FUZZ=ON -DBUILD_TESTING=OFF "${launcher[@]}" >/dev/null
cmake --build "$build" --target vb_fuzz_all -j "$jobs"

# target:seed folder:max input length
targets=(
  fuzz_spec:spec:8192
  fuzz_dataset:dataset:4096
  fuzz_readings_csv:readings_csv:4096
  fuzz_hid_protocol:hid_protocol:128
  fuzz_u3_protocol:u3_protocol:128
  fuzz_gateway:gateway:16384
  fuzz_scope_csv:scope_csv:8192
  fuzz_identify:identify:2048
  fuzz_hold:hold:20000
  fuzz_regress_records:regress_records:16384
)
mkdir -p "$build/artifacts"
failed=0
printf '%-20s %10s %8s %7s %7s %s\n' target executions exec/s cov ft result
for entry in "${targets[@]}"; do
  IFS=: read -r name seeds max_len <<<"$entry"
  corpus="$build/corpus/$name"
  mkdir -p "$corpus"
  log="$build/$name.log"
  dict=()
  [ -f "$here/fuzz/$seeds.dict" ] && dict=(-dict="$here/fuzz/$seeds.dict")
  set +e
  "$build/bin/$name" "$corpus" "$here/fuzz/corpus/$seeds" "${dict[@]}" -max_total_time="$seconds" \
    -max_len="$max_len" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$build/artifacts/$name-" >"$log" 2>&1
  rc=$?
  set -e
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  cov=$(grep -oE 'cov: [0-9]+' "$log" | tail -1 | cut -d' ' -f2)
  ft=$(grep -oE 'ft: [0-9]+' "$log" | tail -1 | cut -d' ' -f2)
  result=ok
  if [ "$rc" -ne 0 ]; then
    result="FAILED (exit $rc, log $log)"
    failed=1
  fi
  printf '%-20s %10s %8s %7s %7s %s\n' "$name" "${execs:-?}" "${rate:-?}" "${cov:-?}" "${ft:-?}" "$result"
done
if [ "$failed" -ne 0 ]; then
  echo "fuzz: a target failed; its input is in $build/artifacts/, the report in its log" >&2
  for entry in "${targets[@]}"; do
    name="${entry%%:*}"
    grep -q -E '^==[0-9]+==ERROR|runtime error|^SUMMARY' "$build/$name.log" 2>/dev/null &&
      { echo "--- $name" >&2; grep -E -A30 '^==[0-9]+==ERROR|runtime error' "$build/$name.log" | head -60 >&2; }
  done
  exit 1
fi
