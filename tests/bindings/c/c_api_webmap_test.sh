#!/usr/bin/env bash
# The C API against the C++ API on Bailey's simulated webmap: the CLI writes the run's log,
# c_api_webmap_driver (C, through libfastslam) and c_api_webmap_reference (C++, engine::Filter)
# run it, and their outputs (every scan's estimate and associations, the final map and
# counters, as hex floats) must be equal byte for byte; so must the driver's when it replaces
# its filter by a saved and restored copy every few scans.
#
# usage: c_api_webmap_test.sh FASTSLAM DRIVER REFERENCE SHARED_DIR WORK_DIR
# Exits 77 (skipped) when SHARED_DIR has no data sets.
set -euo pipefail

fastslam=$1
driver=$2
reference=$3
shared=$4
work=$5

data=$shared/data/bailey_sim
if [ ! -f "$data/example_webmap_landmarks.csv" ]; then
  echo "SKIP: $data is absent: this test needs ../shared's webmap (set up ../shared beside the repository)"
  exit 77
fi

rm -rf "$work"
mkdir -p "$work"
log=$work/webmap.log
"$fastslam" convert --source sim --landmarks-csv "$data/example_webmap_landmarks.csv" \
  --waypoints-csv "$data/example_webmap_waypoints.csv" --seed 3 --out "$log" >"$work/convert.out"

# compare NAME ALGORITHM ASSOCIATION PARTICLES: the driver, plain and reloading, against the
# reference.
compare() {
  local name=$1
  shift
  "$reference" "$log" "$@" 3 2 >"$work/$name.reference"
  "$driver" "$log" "$@" 3 2 >"$work/$name.c"
  cmp "$work/$name.reference" "$work/$name.c" || {
    echo "FAILED: $name: the C API's output differs from the C++ API's" >&2
    diff "$work/$name.reference" "$work/$name.c" | head -n 20 >&2
    exit 1
  }
  "$reference" "$log" "$@" 3 2 reloaded >"$work/$name.reference-reloaded"
  "$driver" "$log" "$@" 3 2 17 "$work/$name.state" >"$work/$name.c-reloaded"
  cmp "$work/$name.reference-reloaded" "$work/$name.c-reloaded" || {
    echo "FAILED: $name: a filter saved and restored every 17 scans diverges" >&2
    diff "$work/$name.reference-reloaded" "$work/$name.c-reloaded" | head -n 20 >&2
    exit 1
  }
  echo "$name: $(grep -c '^scan' "$work/$name.c") scans, identical"
}

compare fs1_known fastslam1 known 50
compare fs2_ml fastslam2 ml 30
compare fs2_das fastslam2 das 30
