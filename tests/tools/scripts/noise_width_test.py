#!/usr/bin/python3
"""tools/scripts/noise_width.py against the built fastslam. The oracle is the simulator, whose
sensor noise is known: Bailey's webmap (../shared) with the filter given the simulated noise
needs width 1, and given half of it needs width 2 (the model is then exact). The grid and the
pooling are checked against hand sums, and bad cases are refused naming the case.
With --real: pooled over the five MRCLAM robots from the calibration's sigmas, the width found
is tools/datasets/utias.h's kUtiasSensorWidth.
Either needs ../shared (exit 77, skipped, when it is absent).

Usage: noise_width_test.py FASTSLAM [--real]
"""
import io
import math
import os
import re
import subprocess
import sys

from script_checks import ROOT, check, finish, load, script_path

SCRIPT = script_path("noise_width")
HEADER = os.path.join(ROOT, "tools", "datasets", "utias.h")
nw = load("noise_width")



def shared_dir():
    shared = os.environ.get("FASTSLAM_SHARED_DIR", os.path.join(ROOT, "..", "shared"))
    if not os.path.isdir(os.path.join(shared, "data")):
        print("{}/data is absent (set FASTSLAM_SHARED_DIR): skipped".format(shared))
        sys.exit(77)
    return shared


def test_arithmetic():
    check(nw.widths(0.25, 2) == [1, 1.25, 1.5, 1.75, 2], "widths {}".format(nw.widths(0.25, 2)))
    check(nw.widths(0.1, 1.3)[-1] == 1 + 3 * 0.1, "widths end {}".format(nw.widths(0.1, 1.3)))
    check(nw.widths(1, 1) == [1], "a single width {}".format(nw.widths(1, 1)))
    seeds = [{"associated": 100, "beyond_chi2_95": 0.1}, {"associated": 300,
                                                          "beyond_chi2_95": 0.02}]
    fraction, total = nw.pooled(seeds, "beyond_chi2_95")
    check(total == 400 and abs(fraction - (10 + 6) / 400) < 1e-15,
          "pooled {} of {}".format(fraction, total))


def test_simulated(fastslam, shared):
    bailey = os.path.join(shared, "data", "bailey_sim")
    case = "--landmarks-csv {}/example_webmap_landmarks.csv --waypoints-csv " \
           "{}/example_webmap_waypoints.csv".format(bailey, bailey)
    log = io.StringIO()
    exact = nw.find_width(fastslam, [case], "1-3", 95, 0.25, 4, log=log)
    check(exact["width"] == 1, "the simulated noise needs width {}".format(exact["width"]))
    check(exact["base_sigmas"] == [[0.1, math.radians(1)]],
          "the source's sigmas {}".format(exact["base_sigmas"]))
    half = nw.find_width(fastslam, [case], "1-3", 95, 0.25, 4, base=(0.05, math.radians(0.5)),
                         log=log)
    print(log.getvalue())
    check(half["width"] == 2, "half the simulated noise needs width {}".format(half["width"]))
    fractions = [row["pooled"] for row in half["widths"]]
    check(all(a > b for a, b in zip(fractions, fractions[1:])),
          "the tail shrinks as the model widens: {}".format(fractions))
    check(fractions[0] > 0.25, "at half the noise {} beyond the 95 % point".format(fractions[0]))
    # Width 2 from half the noise is the exact model: the same runs as width 1 from the truth.
    check(half["widths"][-1]["pooled"] == exact["widths"][0]["pooled"],
          "width 2 of half {} against the truth's {}".format(half["widths"][-1]["pooled"],
                                                            exact["widths"][0]["pooled"]))
    # The command line: the width and the sigmas it gives, exit 0; a bound too low, exit 2.
    done = subprocess.run([sys.executable, SCRIPT, "--fastslam", fastslam, "--case", case,
                           "--sigma-range", "0.05", "--sigma-bearing", repr(math.radians(0.5))],
                          capture_output=True, text=True)
    check(done.returncode == 0 and "width 2: --sigma-range 0.1 --sigma-bearing 0.01745"
          in done.stdout, "command line: {} {} {}".format(done.returncode, done.stdout,
                                                          done.stderr))
    done = subprocess.run([sys.executable, SCRIPT, "--fastslam", fastslam, "--case", case,
                           "--sigma-range", "0.05", "--sigma-bearing", repr(math.radians(0.5)),
                           "--max-width", "1.5"], capture_output=True, text=True)
    check(done.returncode == 2 and "no width up to 1.5" in done.stdout,
          "no width within the bound: {} {}".format(done.returncode, done.stdout))
    return case


def test_errors(fastslam, case):
    def refused(args, expected, code=1):
        done = subprocess.run([sys.executable, SCRIPT, "--fastslam", fastslam] + args,
                              capture_output=True, text=True)
        check(done.returncode == code and expected in done.stderr,
              "{}: exit {}, stderr {}".format(args, done.returncode, done.stderr))

    refused(["--case", case + " --no-such-flag"], "case '{} --no-such-flag': fastslam run "
            "exited".format(case))
    # A source that never sees a landmark with an id: nothing to measure.
    refused(["--case", case + " --max-steps 5"], "reports no associations")
    refused(["--case", case, "--sigma-range", "0.1"], "go together", code=2)
    refused(["--case", case, "--step", "0"], "--step must be > 0", code=2)
    missing = os.path.join(ROOT, "no-such-fastslam")
    done = subprocess.run([sys.executable, SCRIPT, "--fastslam", missing, "--case", case],
                          capture_output=True, text=True)
    check(done.returncode == 2 and "no fastslam executable" in done.stderr,
          "missing executable: {} {}".format(done.returncode, done.stderr))


def shipped_constants():
    with open(HEADER) as f:
        text = f.read()
    return {name: float(value) for name, value in re.findall(
        r"inline constexpr double (kUtias\w+) = ([-+0-9.e]+);", text)}


def test_real(fastslam, shared):
    data = os.path.join(shared, "data", "utias_mrclam", "dataset1")
    c = shipped_constants()
    cases = ["--source utias --data {} --robot {}".format(data, r) for r in range(1, 6)]
    result = nw.find_width(fastslam, cases, "1-3", 95, 0.25, 5,
                           base=(c["kUtiasSigmaRange"], c["kUtiasSigmaBearing"]))
    check(result["width"] == c["kUtiasSensorWidth"],
          "the pooled rule gives width {}, utias.h has {}".format(result["width"],
                                                                 c["kUtiasSensorWidth"]))
    check(result["widths"][0]["pooled"] > 0.2, "the calibration's width leaves {} beyond the "
          "95 % point".format(result["widths"][0]["pooled"]))


def main():
    args = sys.argv[1:]
    if len(args) not in (1, 2) or (len(args) == 2 and args[1] != "--real"):
        print(__doc__)
        return 2
    fastslam = args[0]
    shared = shared_dir()
    if args[1:] == ["--real"]:
        test_real(fastslam, shared)
    else:
        test_arithmetic()
        case = test_simulated(fastslam, shared)
        test_errors(fastslam, case)
    return finish()


if __name__ == "__main__":
    sys.exit(main())
