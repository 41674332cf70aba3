#!/usr/bin/env bash
# Golden outputs: fixed-seed runs whose trajectory and map files must not change by a single
# byte. A change meant to change results updates EXPECTED below in the same commit and says
# why in its message; `--update` prints the new table.
#
# The FastSLAM kernels give the same bits on any x86-64 vector width; the EKF's dense products
# (Eigen's blocked GEMM, -march=native) do not, so its trajectory has one value per width, the
# line's path suffixed @avx2 or @avx512 (this machine's: avx512f in /proc/cpuinfo).
#
# usage: golden_outputs_test.sh FASTSLAM_BINARY SHARED_DIR WORK_DIR [--update]
# Exits 77 (skipped) when SHARED_DIR has no data sets.
set -euo pipefail

fastslam=$1
shared=$2
work=$3
update=${4:-}

if [ ! -d "$shared/data" ]; then
  echo "SKIP: $shared/data is absent: the golden runs need ../shared's data sets"
  exit 77
fi

EXPECTED='
webmap_fs1_known/trajectory.csv aca7b11a22f356b1b7768f73d9c81b2431e85bd26536e6eeb7cc4d847d8c5cfa
webmap_fs1_known/trajectory.tum 68f8125127920ef42eead7492e6a4dae92e2a054ccdfcb8a272c49ded0e04978
webmap_fs1_known/landmarks.csv 19c0c52f46b1eea6386b0d1b76c3c47f990108674e52df230acc1436a44a0393
webmap_fs1_known_control/trajectory.csv 4c33374d043eba4f0bc04b4d3d92bab05c999a52177667f6a49cb24b4ad32a56
webmap_fs1_known_control/trajectory.tum 4836d887f1bd72af15c94a377f800459ba22f7c3be94f3080f7963efc297e1e3
webmap_fs1_known_control/landmarks.csv fbd4bcd4433a1fb90718043ee6c56d8473b732fa5e299ccb93b63a703a4ca32a
webmap_fs2_known/trajectory.csv 9b52dbd2f0bf875ea43afea195cf583ac21c05789231632aaa215079f54bf918
webmap_fs2_known/trajectory.tum 5c174c29866c20c8b81eb0051e5ee713ca938dd471f9b12fc41f460c510b3ff5
webmap_fs2_known/landmarks.csv c446fc3554d52b968a28b51d52e77dc9891422f38d4c51791cfbdc155af2d4f9
webmap_fs1_ml/trajectory.csv cd9f9e3d97a601c851709047120238e59d9f0fbf0763d3c90639b08cac77afbc
webmap_fs1_ml/trajectory.tum 6af195e654ccf614330415b28964a3003500ce80ffaf9ae588bc2aabb7d7c443
webmap_fs1_ml/landmarks.csv a9f36e3ae41abde33f71cf40d0841268ca7de30619d763514d6898bfa50681d2
webmap_fs2_das/trajectory.csv 014bfb055009597170816124ca9e5d139636130311a2cc0f380dabef1bb26106
webmap_fs2_das/trajectory.tum c94e1aad19938fcf54a40211d123b8f709dccd5db6c93fc0036b2426889ade45
webmap_fs2_das/landmarks.csv 81d9b3b93b891091bb676d5567a041c884d3e7f6b6dfdda430c59dd1b1fdccbd
webmap_ekf_ml/trajectory.csv@avx2 419cb225c15413c30bdf246acd828ba3f994f06696659dddcadca818e5cdec4a
webmap_ekf_ml/trajectory.csv@avx512 37425c36f23c0a87586ddcb608c8dfeba2402521abac63cc3ca3fde6cd16cdf6
webmap_ekf_ml/trajectory.tum@avx2 5c089734c56a4c2a580030ad77987be6bb64cfd02aa144a8f31f061e716a78bc
webmap_ekf_ml/trajectory.tum@avx512 be558131fd5147c8c259ba2dc333efbac163c8ab1c7278db33e3583e34c49033
webmap_ekf_ml/landmarks.csv 44ee0843c45b8696427fa74ede132c549f2077ceb25ce7a4423c42da99042d0a
loop_fs1_ml_clutter/trajectory.csv 6504b4caed1c1b5b9da5fbc6ddab65d21bfd90f86917ba454914c91f9ea88a1f
loop_fs1_ml_clutter/trajectory.tum c5c49e4a376f1f625562ae09411bdde3ac5f11fe51c84ec9b1b1aa84684f571f
loop_fs1_ml_clutter/landmarks.csv bc172f06660de3c254a3aa74057b5b57a8bbf6534255e15d441a8709b68ad347
grid_fs2_known/trajectory.csv 35882f177524c64cbfdca62662a721228e151f55f9d6d081d3305aa9b68005b2
grid_fs2_known/trajectory.tum 24f60879b43777f33a8cd55bae8a4a581c269aa9be77bb68a2df764411bf0af8
grid_fs2_known/landmarks.csv 874feab9a0be89db66e2762d1a45414f0612ed825af0dda47826d248d8ad43b1
victoria_park_fs1_ml/trajectory.csv d15da91f99301b9eb34fa919cb8c48c35ff396a6127fe9eca6f8cb53b5042c9e
victoria_park_fs1_ml/trajectory.tum e2bcb921e58320c9391fd374890d64567521f6064ac23b914315693edb550aa9
victoria_park_fs1_ml/landmarks.csv baae2b1ecad059aee05305d810edde6331aca38fe7ee866ffc96f4a810dcf6d8
victoria_park_fs1_ml_control/trajectory.csv 96f2e99e2a5b13c6e420517bf1f4a28804ee396f5c6cfef3aaa0aa5b9a8d0adb
victoria_park_fs1_ml_control/trajectory.tum 8ac2bff3f30e330df7550e94c27bc6ece4c639df2be1be5528ce1c2272877c39
victoria_park_fs1_ml_control/landmarks.csv cc65ca979f1e1533adddd3ca7ca721a6e30bd127bdd9bc31ab1b3e308920945f
victoria_park_fs2_none/trajectory.csv ecaf3c078f48b460826bf86d5289a49b3c87ddd1514e8be1c39bb875268080a4
victoria_park_fs2_none/trajectory.tum 8ebe5fe0636918888787223f413d024da269774f810a038da2488962fae0b358
victoria_park_fs2_none/landmarks.csv 228fd27356df6669204f0d432ab4e5eeb17f37bfd4b854576463cb9c81e22313
'

# run_case NAME ARGS...: one run into $work/NAME.
run_case() {
  local name=$1
  shift
  rm -rf "${work:?}/$name"
  "$fastslam" run "$@" --seed 7 --threads 2 --no-progress --no-plot --out "$work/$name" \
    >"$work/$name.log" 2>&1 || {
    cat "$work/$name.log" >&2
    echo "FAILED: $name: fastslam run exited non-zero" >&2
    exit 1
  }
}

mkdir -p "$work"
webmap=(--landmarks-csv "$shared/data/bailey_sim/example_webmap_landmarks.csv"
        --waypoints-csv "$shared/data/bailey_sim/example_webmap_waypoints.csv")
run_case webmap_fs1_known "${webmap[@]}" --algorithm fastslam1 --particles 100 --association known
run_case webmap_fs2_known "${webmap[@]}" --algorithm fastslam2 --particles 100 --association known
run_case webmap_fs1_known_control "${webmap[@]}" --algorithm fastslam1 --particles 100 \
  --association known --motion-draw control
run_case webmap_fs1_ml "${webmap[@]}" --algorithm fastslam1 --particles 50 --association ml
run_case webmap_fs2_das "${webmap[@]}" --algorithm fastslam2 --particles 50 --association das
run_case webmap_ekf_ml "${webmap[@]}" --algorithm ekf --association ml
run_case loop_fs1_ml_clutter --world loop --loops 1 --clutter 1 --algorithm fastslam1 \
  --particles 30 --association ml
run_case grid_fs2_known --world grid --landmarks 2000 --algorithm fastslam2 --particles 20
vp=(--source victoria-park --data "$shared/data/victoria_park")
run_case victoria_park_fs1_ml "${vp[@]}" --algorithm fastslam1 --particles 30 --association ml
run_case victoria_park_fs1_ml_control "${vp[@]}" --algorithm fastslam1 --particles 30 \
  --association ml --motion-draw control
run_case victoria_park_fs2_none "${vp[@]}" --algorithm fastslam2 --motion none --particles 20 \
  --association ml --sigma-range 0.7 --sigma-bearing 0.03

actual=""
for dir in webmap_fs1_known webmap_fs1_known_control webmap_fs2_known webmap_fs1_ml \
  webmap_fs2_das webmap_ekf_ml loop_fs1_ml_clutter grid_fs2_known victoria_park_fs1_ml \
  victoria_park_fs1_ml_control victoria_park_fs2_none; do
  for file in trajectory.csv trajectory.tum landmarks.csv; do
    sum=$(sha256sum "$work/$dir/$file" | cut -d' ' -f1)
    actual+="$dir/$file $sum"$'\n'
  done
done

if [ "$update" = "--update" ]; then
  printf '%s' "$actual"
  exit 0
fi

isa=avx2
if grep -qw avx512f /proc/cpuinfo 2>/dev/null; then isa=avx512; fi
status=0
while read -r path sum; do
  [ -n "$path" ] || continue
  want=$(printf '%s\n' "$EXPECTED" | awk -v p="$path" -v q="$path@$isa" '$1 == p || $1 == q {print $2}')
  if [ -z "$want" ]; then
    echo "FAILED: $path has no golden value (run with --update and record it)"
    status=1
  elif [ "$want" != "$sum" ]; then
    echo "FAILED: $path changed: sha256 $sum, golden $want"
    status=1
  else
    echo "ok: $path"
  fi
done <<<"$actual"
exit $status
