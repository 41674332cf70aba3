#!/usr/bin/python3
"""Estimates how much one landmark's measurement errors repeat from scan to scan, from the
innovations a run reports: the lag-1 correlation rho that `fastslam run --error-correlation`
takes (engine/filter_config.h error_correlation; docs/engine-config.md).

Reads `fastslam run --stream FILE` output (one JSON line per scan; each association names its
landmark and its squared Mahalanobis distance m2). Every landmark associated in two consecutive
scans gives a pair (m2 then, m2 now). For a whitened two-dimensional Gaussian innovation whose
components follow an AR(1) of coefficient rho, corr(m2_t, m2_t+1) = rho^2, so rho = sqrt of
the pairs' Pearson correlation (0 when it is negative), each m2 clipped at the law's 99.9 %
point so that a few distances far outside the model cannot decide it. A filter whose noise model is the
data's has white innovations (rho near 0); a systematic error that stays while a landmark is in
view (a sensor's mounting, the odometry's drift) makes them repeat. The weight scale the filter
then uses is (1 + rho) / (1 - rho). So does a filter's own error once it has drifted, which the
weights should not discount: check that the estimate holds across seeds before using it
(docs/engine-config.md has both cases).

Owns no state; costs one pass over the files.
Usage: tools/scripts/innovation_correlation.py STREAM [STREAM ...] [--json FILE]
       (standard library only; run with /usr/bin/python3)
"""
import argparse
import json
import math
import sys


# The chi-square (2 degrees of freedom) 99.9 % point: under the model 0.1 % of the distances lie
# beyond it, so clipping there moves a consistent filter's correlation by little.
CLIP = 13.815510557964274


class StreamError(Exception):
    """Bad input: the message names the file, the line and the reason."""


def pairs_of(path):
    """The (m2 before, m2 after) pairs of one stream file."""
    pairs = []
    previous_scan, previous = None, {}
    try:
        f = open(path)
    except OSError as e:
        raise StreamError("{}: {}".format(path, e.strerror))
    with f:
        for number, line in enumerate(f, start=1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
                scan = record["scan"]
                associations = record["associations"]
            except (ValueError, KeyError, TypeError) as e:
                raise StreamError("{}:{}: not a --stream record ({})".format(path, number, e))
            current = {}
            for a in associations:
                try:
                    if a["outcome"] != "associated":
                        continue
                    m2 = a["mahalanobis2"]
                    landmark = a["id"]
                except (KeyError, TypeError) as e:
                    raise StreamError("{}:{}: an association without {}".format(path, number, e))
                if isinstance(m2, (int, float)) and math.isfinite(m2):
                    current[landmark] = float(m2)
            if previous_scan is not None and scan == previous_scan + 1:
                pairs.extend((previous[k], m2) for k, m2 in current.items() if k in previous)
            previous_scan, previous = scan, current
    return pairs


def estimate(pairs):
    """A JSON-ready dict: the pairs' count, the m2 correlation, rho and the weight scale. Each
    m2 is clipped at CLIP first, so that a few innovations far outside the model (a loop
    closing, a filter gone wrong) cannot decide the correlation."""
    pairs = [(min(x, CLIP), min(y, CLIP)) for x, y in pairs]
    n = len(pairs)
    if n < 3:
        raise StreamError("only {} pairs of consecutive sightings: too few to estimate".format(n))
    mx = sum(x for x, _ in pairs) / n
    my = sum(y for _, y in pairs) / n
    sxx = sum((x - mx) ** 2 for x, _ in pairs)
    syy = sum((y - my) ** 2 for _, y in pairs)
    sxy = sum((x - mx) * (y - my) for x, y in pairs)
    if sxx <= 0 or syy <= 0:
        raise StreamError("every distance is the same: no correlation to estimate")
    c = sxy / math.sqrt(sxx * syy)
    rho = math.sqrt(max(c, 0.0))
    return {"pairs": n, "m2_correlation": c, "rho": rho,
            "weight_scale": (1 + rho) / (1 - rho) if rho < 1 else math.inf}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("streams", nargs="+", help="fastslam run --stream files")
    parser.add_argument("--json", help="write the estimate as JSON here")
    args = parser.parse_args(argv)
    try:
        pairs = [p for path in args.streams for p in pairs_of(path)]
        result = estimate(pairs)
    except StreamError as e:
        print("innovation_correlation.py: {}".format(e), file=sys.stderr)
        return 1
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)
    print("{} pairs of consecutive sightings: corr(m2) {:.3f}, rho {:.3f} "
          "(--error-correlation {:.2f}), weight scale {:.1f}".format(
              result["pairs"], result["m2_correlation"], result["rho"], result["rho"],
              result["weight_scale"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
