#!/usr/bin/env bash
# Smoke run of `fastslam bench scaling` (tiny sizes), so the command line of the studies in
# docs/scaling.md cannot rot: both engines, lists of N, M and threads, JSON and CSV with one
# line per point, and tools/scripts/plot_scaling.py on the result (when matplotlib is installed).
# Usage: bench_scaling_smoke.sh FASTSLAM_BINARY SOURCE_DIR
set -euo pipefail
fastslam=$1
source_dir=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$fastslam" bench scaling --landmarks 100,1000 --particles 1,10 --threads 1,2 --grain 4 \
  --updates 10 --repeats 2 --association known --json "$tmp/tree.json" --csv "$tmp/tree.csv"
"$fastslam" bench scaling --engine linear --landmarks 100,1000 --particles 10 --updates 10 \
  --algorithm fastslam1 --association ml --json "$tmp/linear.json" --csv "$tmp/linear.csv"
[ "$(wc -l <"$tmp/tree.csv")" -eq 9 ] || { echo "tree.csv: expected 9 lines"; exit 1; }
[ "$(wc -l <"$tmp/linear.csv")" -eq 3 ] || { echo "linear.csv: expected 3 lines"; exit 1; }
if "$fastslam" bench scaling --engine linear --landmarks 100 --threads 1,2 --updates 1 \
  >"$tmp/refused.txt" 2>&1; then
  echo "the linear engine accepted two thread counts"
  exit 1
fi
if /usr/bin/python3 -c 'import matplotlib' 2>/dev/null; then
  /usr/bin/python3 "$source_dir/tools/scripts/plot_scaling.py" "$tmp/tree.json" "$tmp/linear.json" \
    --out "$tmp/images"
  for png in time memory phases particles threads; do
    [ -s "$tmp/images/scaling_$png.png" ] || { echo "scaling_$png.png missing"; exit 1; }
  done
fi
echo "bench scaling smoke: ok"
