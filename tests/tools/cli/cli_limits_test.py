#!/usr/bin/python3
"""`fastslam` at its limits and its provenance, as a user meets them on the command line.

A table of cases, each a command (with files it makes first), the exit code it must end with,
fragments its standard error must hold, and a bound on its time: out-of-range integers refused
rather than clamped or wrapped, `--out ""`, too many threads, a repeated --config key, input
that is not a log (/dev/zero, a long token) stopped within the line limit, an engine error
naming the record and the scan, a run whose filter would not fit in memory refused at once with
its figure. Then the memory estimate against a run's measured peak, `--version`, metrics.json's
provenance (its input hashes recomputed here with hashlib) and sweep.json's, once.

Usage: cli_limits_test.py FASTSLAM_BINARY
"""
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
import unittest

FASTSLAM = None

HEADER = ("fastslam-log 1\nmotion unicycle\ncontrol_noise 0.1 0.1\n"
          "sensor 0.1 0.01 30 3.14159 0 0 0\nstart 0 0 0 0\nend_header\n")
# Landmark 3 twice in the second scan (line 10): known association refuses it.
DUPLICATE = HEADER + ("control 0.1 0.1 1 0\nscan 0.1 1 5 0.1 3\ncontrol 0.2 0.1 1 0\n"
                      "scan 0.2 2 5 0.1 3 6 0.2 3\n")
LONG_TOKEN = HEADER + "control 0.1 0.1 " + "7" * 100000 + "x 0\n"
SMALL = ["--world", "grid", "--landmarks", "100", "--max-steps", "20", "--no-progress",
         "--no-plot"]

# (name, arguments ({dir} is a scratch directory), files to write first, exit code,
#  fragments of stderr, seconds it may take)
CASES = [
    ("seed beyond 2^64 - 1", ["run", "--seed", "18446744073709551616"], {}, 105,
     ["--seed: '18446744073709551616' is out of range (0 to 18446744073709551615)"], 5),
    ("negative seed", ["run", "--seed", "-1"], {}, 105,
     ["--seed: '-1' is out of range"], 5),
    ("seed in hex", ["run", "--seed", "0x10"], {}, 105,
     ["--seed: '0x10' is not a decimal integer"], 5),
    ("particles beyond 32 bits", ["run", "--particles", "4294967296"], {}, 105,
     ["--particles: '4294967296' is out of range"], 5),
    ("long bad integer quoted briefly", ["run", "--seed", "9" * 5000], {}, 105,
     ["'" + "9" * 80 + "... (5000 bytes)'"], 5),
    ("empty --out", ["run", "--out", ""] + SMALL, {}, 1, ['--out "" names no path'], 5),
    ("threads beyond what can start", ["run", "--threads", "4096"] + SMALL, {}, 1,
     ["--threads 4096: more than this process can usefully start", "or 0 for one per core"], 5),
    ("repeated config key", ["run", "--config", "{dir}/twice.json"] + SMALL,
     {"twice.json": '{"particles": 5, "seed": 1, "particles": 6}'}, 1,
     ["twice.json: key 'particles' is repeated: give each option once"], 5),
    ("/dev/zero as a log", ["run", "--source", "log", "--data", "/dev/zero", "--no-progress"],
     {}, 1, ["/dev/zero:1: line longer than 4194304 bytes"], 10),
    ("a long bad token", ["run", "--source", "log", "--data", "{dir}/long.log", "--no-progress",
                          "--no-plot"],
     {"long.log": LONG_TOKEN}, 1,
     ["long.log:7: u0: '" + "7" * 80 + "...' (100001 bytes) is not a number"], 10),
    ("engine error names record and scan",
     ["run", "--source", "log", "--data", "{dir}/dup.log", "--association", "known",
      "--no-progress", "--no-plot"],
     {"dup.log": DUPLICATE}, 1,
     ["dup.log:10 (scan 2, t = 0.200 s): ", "landmark id 3 appears twice in one scan"], 10),
    # 10^7 particles on the built-in stress world once died of std::bad_alloc after 14 s at
    # 9.3 GB; now refused before the filter is built.
    ("particles beyond --max-memory",
     ["run", "--particles", "10000000", "--max-memory", "1G", "--no-progress", "--no-plot"],
     {}, 1,
     ["fastslam: error: --particles 10000000: the filter needs about ", " GiB (",
      " KiB per particle, for scans of 40 controls and ",
      "17.2 MiB for a map of 100000 landmarks), more than the 1.0 GiB allowed by --max-memory: "
      "use fewer particles or raise --max-memory"], 5),
    ("particles beyond the machine",
     ["run", "--particles", "100000000", "--no-progress", "--no-plot"], {}, 1,
     ["--particles 100000000: the filter needs about ", "or give --max-memory SIZE to run anyway"],
     5),
    ("--max-memory not a size", ["run", "--max-memory", "4X"], {}, 105,
     ["--max-memory: '4X' is not a size (unknown unit): give bytes, or a number with K, M, G or "
      "T (512M, 4G)"], 5),
]


def run(args, stdin=None):
    return subprocess.run([FASTSLAM] + args, input=stdin, capture_output=True, text=True,
                          timeout=120)


def sha256(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


class Limits(unittest.TestCase):
    def test_table(self):
        for name, args, files, code, fragments, seconds in CASES:
            with self.subTest(name), tempfile.TemporaryDirectory() as d:
                for file, text in files.items():
                    with open(os.path.join(d, file), "w") as f:
                        f.write(text)
                start = time.monotonic()
                r = run([a.replace("{dir}", d) for a in args])
                took = time.monotonic() - start
                self.assertEqual(r.returncode, code, r.stderr[:2000])
                for fragment in fragments:
                    self.assertIn(fragment, r.stderr)
                # Messages quote bad input briefly, whatever its size.
                self.assertLess(len(r.stderr), 1000, r.stderr[:2000])
                self.assertLess(took, seconds)


class Memory(unittest.TestCase):
    @unittest.skipIf(os.environ.get("FASTSLAM_SANITIZE"),
                     "peak RSS under a sanitizer's allocator (shadow memory, red zones) is not "
                     "the engine's")
    def test_a_run_that_fits_runs_and_its_estimate_follows_the_measured_peak(self):
        """The estimate's growth from 1 to 2000 particles against peak RSS's (fastslam1, known
        ids, the stress world's density: the case memory_budget.cc measured)."""
        peaks = {}
        with tempfile.TemporaryDirectory() as d:
            for particles in [1, 2000]:
                out = os.path.join(d, str(particles))
                r = run(["run", "--world", "grid", "--landmarks", "10000", "--max-steps", "2000",
                         "--particles", str(particles), "--threads", "1", "--max-memory", "1G",
                         "--no-progress", "--no-plot", "--out", out])
                self.assertEqual(r.returncode, 0, r.stderr)
                with open(os.path.join(out, "metrics.json")) as f:
                    m = json.load(f)
                self.assertEqual(m["options"]["max-memory"], 1 << 30)
                peaks[particles] = (m["peak_rss_bytes"], m["memory_estimate_bytes"])
        measured = peaks[2000][0] - peaks[1][0]
        estimated = peaks[2000][1] - peaks[1][1]
        self.assertGreater(estimated / measured, 0.67, peaks)
        self.assertLess(estimated / measured, 1.5, peaks)


class Provenance(unittest.TestCase):
    def test_version(self):
        r = run(["--version"])
        self.assertEqual(r.returncode, 0, r.stderr)
        lines = r.stdout.splitlines()
        self.assertRegex(lines[0], r"^fastslam \d+\.\d+\.\d+$")
        self.assertRegex(lines[1], r"^commit ([0-9a-f]{40}|unknown)")
        self.assertRegex(lines[2], r"^build type \S+")
        self.assertRegex(lines[3], r"^compiler \S+ \S+")
        self.assertRegex(lines[4], r"^simd (native|baseline|avx2|avx512) ")

    def test_metrics_carry_build_options_and_input_hashes(self):
        with tempfile.TemporaryDirectory() as d:
            config = os.path.join(d, "c.json")
            with open(config, "w") as f:
                f.write('{"particles": 7}')
            log = os.path.join(d, "run.log")
            r = run(["convert", "--world", "loop", "--loop-length", "200", "--out", log])
            self.assertEqual(r.returncode, 0, r.stderr)
            out = os.path.join(d, "out")
            r = run(["run", "--source", "log", "--data", log, "--config", config, "--out", out,
                     "--no-progress", "--no-plot"])
            self.assertEqual(r.returncode, 0, r.stderr)
            with open(os.path.join(out, "metrics.json")) as f:
                m = json.load(f)
            self.assertEqual(m["schema_version"], 1)
            version = run(["--version"]).stdout.splitlines()
            self.assertEqual(version[0], "fastslam " + m["build"]["version"])
            self.assertTrue(version[1].startswith("commit " + m["build"]["commit"]))
            self.assertEqual(m["options"]["particles"], 7)
            self.assertEqual(m["options"]["data"], log)
            self.assertEqual(m["options"]["max-steps"], None)
            self.assertEqual(m["inputs"], [
                {"option": "--config", "path": config, "bytes": os.path.getsize(config),
                 "sha256": sha256(config)},
                {"option": "--data", "path": log, "bytes": os.path.getsize(log),
                 "sha256": sha256(log)}])
            # The options object, as a --config file, repeats the run.
            again = os.path.join(d, "again.json")
            options = dict(m["options"])
            options["out"] = os.path.join(d, "out2")
            with open(again, "w") as f:
                json.dump(options, f)
            r = run(["run", "--config", again])
            self.assertEqual(r.returncode, 0, r.stderr)
            with open(os.path.join(d, "out2", "trajectory.csv")) as f2, \
                    open(os.path.join(out, "trajectory.csv")) as f1:
                self.assertEqual(f1.read(), f2.read())

            # Standard input is named, not hashed.
            with open(log) as f:
                text = f.read()
            r = run(["run", "--source", "log", "--data", "-", "--out", os.path.join(d, "in"),
                     "--no-progress", "--no-plot"], stdin=text)
            self.assertEqual(r.returncode, 0, r.stderr)
            with open(os.path.join(d, "in", "metrics.json")) as f:
                inputs = json.load(f)["inputs"]
            self.assertEqual(inputs, [{"option": "--data", "path": "-", "sha256": None,
                                       "not_hashed": "standard input is read once, by the run"}])

    def test_sweep_carries_provenance_once(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "sweep")
            r = run(["run", "--seeds", "1-2", "--out", out] + SMALL)
            self.assertEqual(r.returncode, 0, r.stderr)
            with open(os.path.join(out, "sweep.json")) as f:
                sweep = json.load(f)
            for key in ("schema_version", "build", "options", "inputs"):
                self.assertIn(key, sweep)
                for seed in sweep["per_seed"]:
                    self.assertNotIn(key, seed)
                self.assertFalse(any(k.startswith(key + ".") for k in sweep["summary"]), key)
            self.assertEqual(sweep["options"]["seeds"], [1, 2])
            self.assertIsNone(sweep["options"]["seed"])
            self.assertEqual(sweep["options"]["out"], out)


if __name__ == "__main__":
    FASTSLAM = sys.argv.pop(1)
    unittest.main()
