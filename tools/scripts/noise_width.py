#!/usr/bin/python3
"""Finds how much wider than a sensor's own scatter the filter's sensor noise must be for the
innovations to follow the model: the smallest width k (a multiple of the source's range and
bearing sigmas, on a grid of --step) at which, with known landmark ids, the pooled fraction of
associations whose squared Mahalanobis distance lies beyond the chi-square law's --quantile
point is at most what the law gives (5 % beyond its 95 % point).

Why: a calibration against ground truth measures the sensor alone. A filter's innovation also
carries the error of the particle's pose and map, which a model of independent noises leaves
out when the odometry's error is correlated in time; innovations beyond the gate then start
new landmarks under unknown association. The rule looks at the innovations only (metrics.json
`innovations`, docs/evaluation.md), never at a pose error, so it needs ids but no ground truth.

Each case is one `fastslam run` argument string (e.g. "--source utias --data DIR --robot 1"),
run with `--association known` over --seeds; the base sigmas are the source's own (the first
run's resolved `sigma-range` and `sigma-bearing`) unless --sigma-range and --sigma-bearing are
given. Owns no state; costs one sweep per case and width tried (runs go --jobs at a time).

Usage: tools/scripts/noise_width.py --case "ARGS" [--case "ARGS" ...] [--seeds 1-3]
       [--quantile 50|95|99] [--step 0.25] [--max-width 5] [--sigma-range M --sigma-bearing RAD]
       [--fastslam BIN] [--jobs 2] [--json FILE]
       (standard library only; run with /usr/bin/python3)
"""
import argparse
import concurrent.futures
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile

QUANTILES = {50: "beyond_chi2_50", 95: "beyond_chi2_95", 99: "beyond_chi2_99"}


class RunError(Exception):
    """A run that failed or reported nothing usable: the message names the case and why."""


def sweep(fastslam, case, seeds, sigmas, workdir):
    """One `fastslam run CASE --association known --seeds SEEDS` with the sensor sigmas `sigmas`
    (None: the source's): (resolved (sigma_range, sigma_bearing), per-seed innovations)."""
    out = tempfile.mkdtemp(prefix="width-", dir=workdir)
    command = [fastslam, "run"] + shlex.split(case) + [
        "--association", "known", "--seeds", seeds, "--threads", "1", "--no-plot",
        "--no-progress", "--out", out]
    if sigmas is not None:
        command += ["--sigma-range", repr(sigmas[0]), "--sigma-bearing", repr(sigmas[1])]
    try:
        done = subprocess.run(command, capture_output=True, text=True)
        if done.returncode != 0:
            tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
            raise RunError("case '{}': fastslam run exited {}: {}".format(
                case, done.returncode, " | ".join(tail)))
        with open(os.path.join(out, "sweep.json")) as f:
            result = json.load(f)
    finally:
        shutil.rmtree(out, ignore_errors=True)
    options = result["options"]
    innovations = [seed.get("innovations") for seed in result["per_seed"]]
    if any(i is None or i.get("associated", 0) <= 0 for i in innovations):
        raise RunError("case '{}': a seed reports no associations with known ids (does the "
                       "source give landmark ids?)".format(case))
    return (options["sigma-range"], options["sigma-bearing"]), innovations


def pooled(innovations, key):
    """The fraction beyond the quantile over every association of `innovations` (a list of
    metrics.json `innovations` objects), and the number of associations."""
    total = sum(i["associated"] for i in innovations)
    beyond = sum(i[key] * i["associated"] for i in innovations)
    return beyond / total, total


def widths(step, max_width):
    """1, 1 + step, ... up to max_width, computed without accumulating rounding."""
    count = int(round((max_width - 1) / step))
    return [1 + n * step for n in range(count + 1)]


def find_width(fastslam, cases, seeds, quantile, step, max_width, base=None, jobs=2,
               log=sys.stderr):
    """The search: a JSON-ready dict with every width tried (per case and pooled) and the
    chosen one (None when no width up to max_width meets the law)."""
    key = QUANTILES[quantile]
    target = 1 - quantile / 100
    workdir = tempfile.mkdtemp(prefix="noise-width-")
    try:
        with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            def run_all(sigmas_of):
                futures = [pool.submit(sweep, fastslam, case, seeds, sigmas_of(n), workdir)
                           for n, case in enumerate(cases)]
                return [f.result() for f in futures]

            first = run_all(lambda n: base)
            bases = [base if base is not None else s for s, _ in first]
            rows, chosen = [], None
            for k in widths(step, max_width):
                runs = first if k == 1 else run_all(
                    lambda n: (bases[n][0] * k, bases[n][1] * k))
                per_case = [pooled(innovations, key)[0] for _, innovations in runs]
                every = [i for _, innovations in runs for i in innovations]
                fraction, associations = pooled(every, key)
                rows.append({"width": k, "pooled": fraction, "associations": associations,
                             "per_case": per_case})
                print("width {:5.2f}: {:.4f} beyond the {}% point ({})".format(
                    k, fraction, quantile, " ".join("{:.4f}".format(p) for p in per_case)),
                    file=log)
                if fraction <= target:
                    chosen = k
                    break
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return {"cases": cases, "seeds": seeds, "quantile": quantile, "target": target,
            "base_sigmas": [list(b) for b in bases], "widths": rows, "width": chosen}


def main(argv=None):
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", action="append", required=True,
                        help="fastslam run arguments of one data set (repeat to pool)")
    parser.add_argument("--seeds", default="1-3", help="seeds of every run (fastslam's form)")
    parser.add_argument("--quantile", type=int, choices=sorted(QUANTILES), default=95)
    parser.add_argument("--step", type=float, default=0.25)
    parser.add_argument("--max-width", type=float, default=5.0)
    parser.add_argument("--sigma-range", type=float, help="base range sigma, m")
    parser.add_argument("--sigma-bearing", type=float, help="base bearing sigma, rad")
    parser.add_argument("--fastslam", default=os.path.join(root, "build", "release", "tools",
                                                           "fastslam"))
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--json", help="write the search as JSON here")
    args = parser.parse_args(argv)
    if (args.sigma_range is None) != (args.sigma_bearing is None):
        parser.error("--sigma-range and --sigma-bearing go together")
    if not args.step > 0 or not args.max_width >= 1:
        parser.error("--step must be > 0 and --max-width >= 1")
    if not os.access(args.fastslam, os.X_OK):
        parser.error("{}: no fastslam executable (build it, or pass --fastslam)".format(
            args.fastslam))
    base = None if args.sigma_range is None else (args.sigma_range, args.sigma_bearing)
    try:
        result = find_width(args.fastslam, args.case, args.seeds, args.quantile, args.step,
                            args.max_width, base, args.jobs)
    except RunError as e:
        print("noise_width.py: {}".format(e), file=sys.stderr)
        return 1
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)
    if result["width"] is None:
        print("no width up to {:g} brings the innovations within the law".format(
            args.max_width))
        return 2
    sigmas = sorted({(b[0] * result["width"], b[1] * result["width"])
                     for b in result["base_sigmas"]})
    print("width {:g}: {}".format(result["width"], "; ".join(
        "--sigma-range {:.4g} --sigma-bearing {:.4g}".format(*s) for s in sigmas)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
