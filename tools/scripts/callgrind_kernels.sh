#!/usr/bin/env bash
# Instruction counts of the hot kernels (docs/scaling.md, "Where the time goes"): valgrind
# --tool=callgrind on
#   1. the bare 2x2 EKF floor (BM_BareEkfFloor's bare_ekf_update, bench/engine/
#      landmark_ekf_benchmark.cc) and the engine's own landmark update (update_landmark, called
#      through engine_ekf_update there): Ir per call, libm's atan2 and log included;
#   2. the association kernel (association_kernel, bench/engine/association_benchmark.cc: one
#      particle's candidate search and ML choice for a scan of 8 observations) with 10, 100 and
#      1000 landmarks in the sensor's range (BM_AssociationKernelInRange) and with about 10, 100
#      and 1000 landmarks inside each search disc (BM_AssociationKernel): Ir per
#      particle-observation and as a multiple of the floor;
#   3. `fastslam bench scaling` at N landmarks, M particles, FS1 or FS2, ML or known, with
#      collection switched on only inside Filter::observe (the pass runs the queued controls,
#      association, updates, then resampling): Ir per particle-observation, and the functions
#      with the most inclusive Ir.
# Builds the `callgrind` preset (release code for AVX2: valgrind 3.19 cannot run AVX-512).
# Usage: tools/scripts/callgrind_kernels.sh [N [M [UPDATES [fastslam1|fastslam2 [ml|known]]]]]
#        (defaults 1000000 100 100 fastslam1 ml). Writes into build/callgrind/cg/.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
cd "$root"
n=${1:-1000000}
m=${2:-100}
updates=${3:-100}
algorithm=${4:-fastslam1}
association=${5:-ml}
export CCACHE_BASEDIR=$root CCACHE_NOHASHDIR=1
cmake --preset callgrind >/dev/null
cmake --build --preset callgrind --target fastslam landmark_ekf_benchmark association_benchmark \
  -- -j2 >/dev/null
out=build/callgrind/cg
mkdir -p "$out"

# Ir per call of one function from a callgrind file: inclusive Ir over the calls made to it.
per_call() {  # file function-regex
  /usr/bin/python3 - "$1" "$2" <<'PY'
import re, subprocess, sys
path, pattern = sys.argv[1], sys.argv[2]
text = subprocess.run(["callgrind_annotate", "--tree=caller", "--inclusive=yes", path],
                      capture_output=True, text=True, check=True).stdout
calls, ir = 0, None
lines = text.splitlines()
for i, line in enumerate(lines):
    m = re.match(r"\s*([\d,]+) \([^)]*\)\s+\*\s+[^\s:]*:(.*?) \[", line)
    if m and re.search(pattern, m.group(2)):
        ir = int(m.group(1).replace(",", ""))
        j = i - 1
        while j >= 0 and "<" in lines[j]:  # the callers, each "(Kx)"
            c = re.search(r"\(([\d,]+)x\)", lines[j])
            calls += int(c.group(1).replace(",", "")) if c else 0
            j -= 1
        break
if ir is None or calls == 0:
    sys.exit(f"callgrind_kernels: {pattern} not found in {path}")
print(f"{ir / calls:.1f} Ir per call ({ir} Ir, {calls} calls)")
PY
}

echo "== the bare 2x2 EKF floor and the engine's landmark update"
valgrind --tool=callgrind --callgrind-out-file="$out/floor.out" \
  build/callgrind/bench/engine/landmark_ekf_benchmark \
  --benchmark_filter='BM_BareEkfFloor|BM_LandmarkEkfUpdate' --benchmark_min_time=0.02 \
  >"$out/floor.log" 2>&1
echo -n "bare_ekf_update: " && per_call "$out/floor.out" 'bench::bare_ekf_update\('
echo -n "update_landmark (engine_ekf_update): " && per_call "$out/floor.out" 'bench::engine_ekf_update\('

floor=$(per_call "$out/floor.out" 'bench::bare_ekf_update\(' | cut -d' ' -f1)
echo "== the association kernel (association_kernel, 8 observations a call), Ir per particle-observation"
for world in in_range in_disc; do
  case $world in
    in_range) bm=BM_AssociationKernelInRange; what="landmarks in range" ;;
    in_disc) bm=BM_AssociationKernel; what="landmarks in the disc" ;;
  esac
  for k in 10 100 1000; do
    valgrind --tool=callgrind --callgrind-out-file="$out/kernel_${world}_$k.out" \
      build/callgrind/bench/engine/association_benchmark \
      --benchmark_filter="$bm/$world:$k/" --benchmark_min_time=0.02 \
      >"$out/kernel_${world}_$k.log" 2>&1
    per_call "$out/kernel_${world}_$k.out" 'bench::association_kernel\(' |
      awk -v k="$k" -v f="$floor" -v what="$what" \
        '{ printf "~%s %s: %.0f Ir per particle-observation, %.1fx the floor\n",
           k, what, $1 / 8, $1 / 8 / f }'
  done
done

echo "== fastslam bench scaling: N = $n, M = $m, $updates updates, $algorithm, $association"
start=$SECONDS
valgrind --tool=callgrind --collect-atstart=no --toggle-collect='fastslam::engine::Filter::observe*' \
  --callgrind-out-file="$out/filter.out" build/callgrind/tools/fastslam bench scaling \
  --landmarks "$n" --particles "$m" --updates "$updates" --algorithm "$algorithm" \
  --association "$association" --threads 1 --json "$out/filter.json" >"$out/filter.log" 2>&1
echo "valgrind run: $((SECONDS - start)) s"
/usr/bin/python3 - "$out/filter.out" "$out/filter.json" <<'PY'
import json, re, subprocess, sys
cg, js = sys.argv[1], sys.argv[2]
p = json.load(open(js))["points"][0]
po = p["observations"] * p["particles"]
text = subprocess.run(["callgrind_annotate", "--auto=no", "--inclusive=yes", "--threshold=100", cg],
                      capture_output=True, text=True, check=True).stdout
rows = []
for line in text.splitlines():
    m = re.match(r"\s*([\d,]+) \(\s*([\d.]+)%\)\s+([^\s:]*):(.*?) \[", line)
    if m:
        rows.append((int(m.group(1).replace(",", "")), float(m.group(2)), m.group(4)))
total = next(ir for ir, _, name in rows if name.startswith("fastslam::engine::Filter::observe"))
print(f"{p['updates']} scans, {p['observations']} observations, M = {p['particles']}: "
      f"{po} particle-observations")
print(f"Filter::observe: {total} Ir, {total / po:.0f} Ir per particle-observation, "
      f"{total / p['updates'] / p['particles']:.0f} Ir per particle per scan")
print("inclusive Ir per particle-observation of the heaviest functions:")
def simplify(name):
    while True:  # drop template arguments, innermost first
        shorter = re.sub(r"<[^<>]*>", "", name)
        if shorter == name:
            break
        name = shorter
    return re.sub(r"\(.*", "", name)

seen = set()
for ir, pct, name in rows:
    short = simplify(name)
    # Recursive functions count above 100%; the callers of observe are not kernels.
    if short in seen or pct < 2.0 or ir > total or not short or short.startswith(
            ("main", "__libc", "0x", "fastslam::tools::run_scaling")):
        continue
    seen.add(short)
    print(f"  {ir / po:9.0f}  {pct:5.1f}%  {short[:120]}")

# Self (exclusive) Ir grouped by component, matched on "file:function" in this order (inlined
# code is charged to the file it came from, so the math inlined into the filter counts as math).
GROUPS = [
    ("libm (atan2, log, sincos, remainder)", r"libm\.so|^\./math/|sysdeps"),
    ("spatial index (candidate and footprint queries, moves)", r"spatial_index|BasicSpatialIndex"),
    ("landmark tree (lookups, path copies, releases)", r"landmark_tree|BasicLandmarkTree"),
    ("node heap (allocate, free, counters)",
     r"node_heap|NodeHeap|PoolHeap|jemalloc|je_|pthread_getspecific"),
    ("random normals (keyed Philox streams)", r"philox|random_stream|pair_run|normal_pairs"),
    ("motion (control steps)", r"motion|sample_block|advance_block|vmath"),
    ("EKF and association math",
     r"landmark_ekf|measurement_model|association\.cc|evaluate_observation|apply_update|"
     r"associate_maximum|Eigen|emmintrin"),
    ("resampling", r"[Rr]esampl|particle_store|ParticleStore"),
    ("TBB dispatch", r"tbb"),
    ("filter loop (filter.cc)", r"filter\.cc|Filter::"),
    ("C++ library (vectors, sorting)", r"/usr/include/c\+\+"),
]
text = subprocess.run(["callgrind_annotate", "--auto=no", "--threshold=100", cg], capture_output=True,
                      text=True, check=True).stdout
sums = {g: 0 for g, _ in GROUPS}
other = 0
body = text.split("file:function", 1)[1]
for line in body.splitlines():
    m = re.match(r"\s*([\d,]+) \(\s*([\d.]+)%\)\s+(.*)$", line)
    if not m:
        continue
    ir, name = int(m.group(1).replace(",", "")), m.group(3)
    for g, pattern in GROUPS:
        if re.search(pattern, name):
            sums[g] += ir
            break
    else:
        other += ir
print("self Ir per particle-observation by component:")
for g, _ in GROUPS:
    print(f"  {sums[g] / po:9.0f}  {100 * sums[g] / total:5.1f}%  {g}")
print(f"  {other / po:9.0f}  {100 * other / total:5.1f}%  other")
PY
