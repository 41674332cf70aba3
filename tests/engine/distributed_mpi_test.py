#!/usr/bin/python3
"""The Filter over MPI ranks: distributed_mpi_test (a gtest binary) under `mpirun` on this
machine for ranks x threads 1x1, 1x2, 2x1, 2x2 and 4x1 (oversubscribed), each rank checking
its bits against the one-process filter. Skipped (exit 77, with the reason) without `mpirun`,
in a build without MPI (no binary given), and under ThreadSanitizer (Open MPI's progress
threads are not instrumented); under AddressSanitizer without leak detection (Open MPI's
plugins keep allocations to the end)."""
import os
import shutil
import subprocess
import sys

LAYOUTS = [(1, 1), (1, 2), (2, 1), (2, 2), (4, 1)]


def main():
    binary = sys.argv[1] if len(sys.argv) > 1 else ""
    if not binary or not os.path.exists(binary):
        print("SKIP: the Filter over MPI: fastslam was built without MPI (libopenmpi-dev)")
        return 77
    if shutil.which("mpirun") is None:
        print("SKIP: the Filter over MPI: no mpirun on PATH (Debian: openmpi-bin)")
        return 77
    sanitize = os.environ.get("FASTSLAM_SANITIZE", "")
    if "thread" in sanitize:
        print("SKIP: the Filter over MPI: ThreadSanitizer build (Open MPI is not instrumented)")
        return 77
    env = dict(os.environ)
    if "address" in sanitize:
        env["ASAN_OPTIONS"] = env.get("ASAN_OPTIONS", "") + ":detect_leaks=0"
    failed = []
    for ranks, threads in LAYOUTS:
        env["FASTSLAM_TEST_THREADS"] = str(threads)
        cmd = ["mpirun", "--oversubscribe", "-x", "FASTSLAM_TEST_THREADS"]
        if "ASAN_OPTIONS" in env:
            cmd += ["-x", "ASAN_OPTIONS"]
        if os.geteuid() == 0:
            cmd.append("--allow-run-as-root")
        cmd += ["-n", str(ranks), binary, "--gtest_brief=1"]
        print(f"== {ranks} rank(s) x {threads} thread(s): {' '.join(cmd)}", flush=True)
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
        print(r.stdout[-4000:], r.stderr[-4000:], sep="\n", flush=True)
        if r.returncode != 0:
            failed.append(f"{ranks}x{threads} (exit {r.returncode})")
    if failed:
        print("FAILED layouts: " + ", ".join(failed))
        return 1
    print("every layout gave the one-process bits")
    return 0


if __name__ == "__main__":
    sys.exit(main())
