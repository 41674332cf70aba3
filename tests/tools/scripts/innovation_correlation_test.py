#!/usr/bin/python3
"""tools/scripts/innovation_correlation.py on synthetic --stream files whose innovations are
known: whitened two-dimensional AR(1) innovations of coefficient rho for landmarks each seen over
a run of consecutive scans. The estimate recovers rho (0, 0.5, 0.9); only consecutive scans pair;
new and unscored associations are left out; bad input is refused naming file and line.
"""
import json
import math
import os
import random
import subprocess
import sys
import tempfile

from script_checks import check, finish, load, script_path

SCRIPT = script_path("innovation_correlation")
ic = load("innovation_correlation")



def synthetic(path, rho, seed, landmarks=2000, run=20, gap_every=0):
    """Writes a stream: landmark k is seen in scans [k * run / 4, + run) (four in view at once),
    its whitened innovation an AR(1) of coefficient rho; every scan also starts one landmark.
    With gap_every, every such scan is missing from the file."""
    rng = random.Random(seed)
    scale = math.sqrt(1 - rho * rho)
    state = {}
    scans = landmarks * run // 4 + run
    with open(path, "w") as f:
        for scan in range(scans):
            associations = [{"observation": 0, "outcome": "new", "id": 10 ** 9 + scan,
                             "mahalanobis2": None}]
            first = max(0, (scan - run) * 4 // run)
            for k in range(first, min(landmarks, scan * 4 // run + 1)):
                if not (k * run // 4 <= scan < k * run // 4 + run):
                    continue
                if k not in state:
                    state[k] = (rng.gauss(0, 1), rng.gauss(0, 1))
                else:
                    a, b = state[k]
                    state[k] = (rho * a + scale * rng.gauss(0, 1),
                                rho * b + scale * rng.gauss(0, 1))
                a, b = state[k]
                associations.append({"observation": len(associations), "outcome": "associated",
                                     "id": k, "mahalanobis2": a * a + b * b})
            if gap_every and scan % gap_every == 0:
                continue
            f.write(json.dumps({"t": 0.2 * scan, "scan": scan, "associations": associations})
                    + "\n")


def test_recovers_rho(tmp):
    for rho in (0.0, 0.5, 0.9):
        path = os.path.join(tmp, "rho{}.jsonl".format(rho))
        synthetic(path, rho, seed=int(rho * 10) + 1)
        result = ic.estimate(ic.pairs_of(path))
        print("rho {}: {}".format(rho, result))
        check(abs(result["rho"] - rho) <= (0.06 if rho == 0 else 0.03),
              "rho {}: estimated {:.3f}".format(rho, result["rho"]))
        check(abs(result["weight_scale"] - (1 + result["rho"]) / (1 - result["rho"])) < 1e-12,
              "weight scale of rho {}".format(rho))
        # 2000 landmarks over 20 scans each: 19 pairs apiece.
        check(result["pairs"] == 2000 * 19, "rho {}: {} pairs".format(rho, result["pairs"]))


def test_only_consecutive_scans_pair(tmp):
    path = os.path.join(tmp, "gaps.jsonl")
    synthetic(path, 0.9, seed=5, landmarks=200, gap_every=3)
    pairs = ic.pairs_of(path)
    full = os.path.join(tmp, "full.jsonl")
    synthetic(full, 0.9, seed=5, landmarks=200)
    check(0 < len(pairs) < len(ic.pairs_of(full)) * 0.5,
          "a missing scan breaks the pairs: {} of {}".format(len(pairs), len(ic.pairs_of(full))))


def test_errors(tmp):
    def refused(lines, expected):
        path = os.path.join(tmp, "bad.jsonl")
        with open(path, "w") as f:
            f.write(lines)
        done = subprocess.run([sys.executable, SCRIPT, path], capture_output=True, text=True)
        check(done.returncode == 1 and expected.format(path=path) in done.stderr,
              "{!r}: exit {}, stderr {}".format(lines, done.returncode, done.stderr))

    good = json.dumps({"scan": 0, "associations": []}) + "\n"
    refused(good + "{not json\n", "{path}:2: not a --stream record")
    refused(good + json.dumps({"scan": 1}) + "\n", "{path}:2: not a --stream record")
    refused(json.dumps({"scan": 0, "associations": [{"outcome": "associated"}]}) + "\n",
            "{path}:1: an association without")
    refused(good, "only 0 pairs")
    done = subprocess.run([sys.executable, SCRIPT, os.path.join(tmp, "missing.jsonl")],
                          capture_output=True, text=True)
    check(done.returncode == 1 and "missing.jsonl" in done.stderr,
          "missing file: {} {}".format(done.returncode, done.stderr))
    # The command line prints the estimate and the flag.
    path = os.path.join(tmp, "cli.jsonl")
    synthetic(path, 0.5, seed=9, landmarks=300)
    done = subprocess.run([sys.executable, SCRIPT, path, "--json", path + ".json"],
                          capture_output=True, text=True)
    check(done.returncode == 0 and "--error-correlation" in done.stdout,
          "command line: {} {}".format(done.stdout, done.stderr))
    with open(path + ".json") as f:
        check(json.load(f)["pairs"] == 300 * 19, "the JSON's pairs")


def main():
    with tempfile.TemporaryDirectory() as tmp:
        test_recovers_rho(tmp)
        test_only_consecutive_scans_pair(tmp)
        test_errors(tmp)
    return finish()


if __name__ == "__main__":
    sys.exit(main())
