#!/usr/bin/env bash
# The whole test suite: installs what is missing, builds the release, asan (Address +
# UndefinedBehavior sanitizers) and tsan presets, and runs every test under release (including
# a smoke run of every benchmark and the install test, which builds, installs and runs the
# portable package) and asan, and the concurrency tests under tsan; in the portable preset it
# builds and runs only the tests labelled portable (each random-kernel copy forced by
# FASTSLAM_ISA and compared bit for bit, vmath's bounds without fma); then builds the fuzz preset
# and runs each libFuzzer target for 30 s over its seed corpus. Exits non-zero when
# anything fails; prints CTest's summaries.
set -uo pipefail
FASTSLAM_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$FASTSLAM_ROOT"
source tools/lib/setup.sh

fastslam_install_packages || exit 1
fastslam_setup_ccache
mkdir -p build

if [ ! -d ../shared ]; then
  echo "note: ../shared is absent; tests that need its data sets will skip"
fi

status=0
summary=()
for preset in release asan tsan portable; do
  start=$SECONDS
  targets=()
  ctest_args=()
  if [ "$preset" = portable ]; then
    targets=(random_stream_test random_dispatch_test vmath_test)
    ctest_args=(-L portable)
  fi
  if ! fastslam_build "$preset" "${targets[@]}"; then
    echo "== Build of preset '$preset' FAILED"
    summary+=("$preset: build FAILED")
    status=1
    continue
  fi
  echo "== Testing preset '$preset'"
  log="$FASTSLAM_ROOT/build/ctest-$preset.log"
  ctest --preset "$preset" "${ctest_args[@]}" 2>&1 | tee "$log"
  rc=${PIPESTATUS[0]}
  line=$(grep -E 'tests passed|tests failed' "$log" | tail -n 1)
  summary+=("$preset: ${line:-no CTest summary} ($((SECONDS - start)) s)")
  [ "$rc" -eq 0 ] || status=1
done

# The fuzzers (fuzz/): the fuzz preset, each target for FASTSLAM_FUZZ_SECONDS (30) over a copy
# of its seed corpus (the repository is not written); any crash fails the suite.
fuzzers=(log_format_fuzzer victoria_park_fuzzer utias_fuzzer config_json_fuzzer filter_load_fuzzer
  checkpoint_fuzzer)
start=$SECONDS
if ! fastslam_build fuzz "${fuzzers[@]}"; then
  echo "== Build of preset 'fuzz' FAILED"
  summary+=("fuzz: build FAILED")
  status=1
else
  echo "== Fuzzing"
  fuzz_failed=0
  for target in "${fuzzers[@]}"; do
    work=$(mktemp -d)
    cp -r "fuzz/corpus/$target" "$work/corpus"
    mkdir "$work/artifacts"
    (cd "$work" && "$FASTSLAM_ROOT/build/fuzz/fuzz/$target" -max_total_time="${FASTSLAM_FUZZ_SECONDS:-30}" \
      -print_final_stats=1 -rss_limit_mb=2048 -artifact_prefix=artifacts/ corpus >log.txt 2>&1)
    rc=$?
    runs=$(grep -o 'stat::number_of_executed_units: [0-9]*' "$work/log.txt" | grep -o '[0-9]*$')
    if [ "$rc" -eq 0 ]; then
      echo "$target: ${runs:-?} inputs, no crash"
    else
      echo "$target: CRASH after ${runs:-?} inputs; log and input kept in $work"
      grep -E 'ERROR|SUMMARY|artifact' "$work/log.txt" | head -n 5
      fuzz_failed=1
    fi
    [ "$rc" -eq 0 ] && rm -rf "$work"
  done
  if [ "$fuzz_failed" -eq 0 ]; then
    summary+=("fuzz: ${#fuzzers[@]} targets, no crash ($((SECONDS - start)) s)")
  else
    summary+=("fuzz: CRASH ($((SECONDS - start)) s)")
    status=1
  fi
fi

echo
echo "== Summary"
printf '%s\n' "${summary[@]}"
exit $status
