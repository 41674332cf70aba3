#!/usr/bin/env bash
# A run's memory is bounded by its map, not by its length: the same world driven for 10^6 and
# for 10^7 controls (one particle, known ids, no output files) must peak at the same resident
# set size within 4 MB. Held in memory, the trajectory, its times and the truth alone would
# add about 700 MB over the longer run.
#
# usage: bounded_memory_test.sh FASTSLAM_BINARY
set -euo pipefail
fastslam=$1

peak_mb() {
  local out
  out=$("$fastslam" run --world loop --loop-length 2000 --loops 1000 --particles 1 --threads 1 \
    --no-progress --max-steps "$1")
  printf '%s\n' "$out" >&2
  printf '%s\n' "$out" | grep -q "$1 steps" || { echo "FAILED: the run did not take $1 steps" >&2; exit 1; }
  printf '%s\n' "$out" | sed -n 's/.*peak RSS \([0-9.]*\) MB.*/\1/p'
}

short=$(peak_mb 1000000)
long=$(peak_mb 10000000)
echo "peak RSS: $short MB after 10^6 controls, $long MB after 10^7"
awk -v a="$short" -v b="$long" 'BEGIN { exit !(a > 0 && b <= a + 4) }' || {
  echo "FAILED: peak RSS grew from $short MB to $long MB with the run's length"
  exit 1
}
echo "ok"
