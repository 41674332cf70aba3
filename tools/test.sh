#!/usr/bin/env bash
# The whole test suite: installs what is missing, builds the release, asan (Address +
# UndefinedBehavior sanitizers) and tsan presets, and runs every test under release (including
# a smoke run of every benchmark and the install test, which builds, installs and runs the
# portable package) and asan, and the concurrency tests under tsan; in the portable preset it
# builds and runs only the tests labelled portable (each random-kernel copy forced by
# FASTSLAM_ISA and compared bit for bit, vmath's bounds without fma). Exits non-zero when
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

echo
echo "== Summary"
printf '%s\n' "${summary[@]}"
exit $status
