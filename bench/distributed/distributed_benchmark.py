#!/usr/bin/python3
"""The distributed particle filter on this machine: `fastslam bench scaling` (a grid world, every
particle sharing the true map as a prior, then --updates scans timed) for each M x N, on 1 rank
(one process, no MPI) and on R ranks under `mpirun --oversubscribe`, one thread a rank. Prints
a markdown table: time per update split into compute, reductions and exchange (rank 0's wall
time: compute = the rest), bytes sent per resampling against sending every copy whole, and the
transport's measured latency and per-byte cost; writes every run's JSON beside it.

Usage: distributed_benchmark.py FASTSLAM OUTDIR [--particles 10000,100000]
       [--landmarks 10000,1000000] [--ranks 1,2,4] [--updates 50] [--association known]
"""
import argparse
import json
import os
import subprocess
import sys


def run(fastslam, out, m, n, ranks, updates, association):
    path = os.path.join(out, f"M{m}_N{n}_R{ranks}.json")
    cmd = [fastslam, "bench", "scaling", "--particles", str(m), "--landmarks", str(n),
           "--updates", str(updates), "--threads", "1", "--association", association,
           "--json", path]
    if ranks > 1:
        mpi = ["mpirun", "--oversubscribe"] + (["--allow-run-as-root"] if os.geteuid() == 0 else [])
        cmd = mpi + ["-n", str(ranks)] + cmd
    print("$ " + " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    with open(path) as f:
        return json.load(f)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("fastslam")
    p.add_argument("out")
    p.add_argument("--particles", default="10000,100000")
    p.add_argument("--landmarks", default="10000,1000000")
    p.add_argument("--ranks", default="1,2,4")
    p.add_argument("--updates", type=int, default=50)
    p.add_argument("--association", default="known")
    a = p.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows = []
    transport = {}
    for n in [int(x) for x in a.landmarks.split(",")]:
        for m in [int(x) for x in a.particles.split(",")]:
            for r in [int(x) for x in a.ranks.split(",")]:
                j = run(a.fastslam, a.out, m, n, r, a.updates, a.association)
                pt = j["points"][0]
                if "transport" in j:
                    transport[r] = j["transport"]
                total = pt["seconds_per_update"]
                gather = pt.get("gather_seconds_per_update", 0.0)
                exchange = pt.get("exchange_seconds_per_update", 0.0)
                transfer = pt.get("transfer_seconds_per_update", 0.0)
                rows.append((m, n, r, 1e3 * total, 1e3 * (total - gather - exchange), 1e3 * gather,
                             1e3 * exchange, 1e3 * transfer,
                             pt.get("exchange_bytes_per_resampling", 0.0) / 1024,
                             pt.get("exchange_naive_bytes_per_resampling", 0.0) / 1024))
    print()
    print("| M | N | ranks | ms/update | compute | reductions | exchange (transfer) "
          "| KiB sent / resampling | KiB whole copies / resampling |")
    print("|---|---|---|---|---|---|---|---|---|")
    for m, n, r, total, compute, gather, exchange, transfer, sent, naive in rows:
        print(f"| {m} | {n} | {r} | {total:.1f} | {compute:.1f} | {gather:.1f} | "
              f"{exchange:.1f} ({transfer:.1f}) | {sent:.0f} | {naive:.0f} |")
    for r, t in sorted(transport.items()):
        print(f"\ntransport, {r} ranks: {1e6 * t['latency_seconds']:.2f} us a message, "
              f"{1e9 * t['seconds_per_byte']:.3f} ns a byte")
    return 0


if __name__ == "__main__":
    sys.exit(main())
