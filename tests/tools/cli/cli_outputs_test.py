#!/usr/bin/python3
"""`fastslam run --out` and `fastslam convert --out` when things go wrong.

A table of output directories refused before any work (each within seconds, though the run
would take minutes): a file, a path under a file, an input, a directory inside an input, one
holding an input under a name the run writes, a read-only file system. Then: an earlier run's
files removed and nothing else; SIGINT and SIGTERM mid-run (exit 130 / 143, "status":
"interrupted", the trajectory so far well formed); a second SIGINT killing at once; a full disk
(a 64 KiB tmpfs, root only: skipped otherwise) ending with "status": "failed: ...", no
temporaries; an evaluation problem kept as a warning; convert through a symlink, refusing a
device, a link to one and a directory, and leaving nothing when stopped; the end marker convert
writes, a log cut before it run with a warning (from a file and from a pipe), a record after it
refused. And the picture: map.svg unless --plot says otherwise, for each seed of a sweep too.

Usage: cli_outputs_test.py FASTSLAM_BINARY
"""
import contextlib
import json
import os
import signal
import stat
import subprocess
import sys
import tempfile
import time
import unittest

FASTSLAM = None

HEADER = ("fastslam-log 1\nmotion unicycle\ncontrol_noise 0.1 0.1\n"
          "sensor 0.1 0.01 30 3.14159 0 0 0\nstart 0 0 0 0\nend_header\n")
# Scans see landmark 7, which the landmark lines do not have.
UNKNOWN_ID = HEADER + ("landmark 3 5 0\ncontrol 0.1 0.1 1 0\nscan 0.1 1 5 0.1 3\n"
                       "control 0.2 0.1 1 0\nscan 0.2 2 5 0.1 3 6 0.2 7\nend 5\n")
NO_END_WARNING = "the log has no end marker ('end N'), so it may be truncated"
SMALL = ["--world", "grid", "--landmarks", "100", "--max-steps", "20", "--no-progress",
         "--no-plot"]
# The built-in stress run, long enough to be stopped.
LONG = ["run", "--max-steps", "100000000", "--no-progress", "--no-plot"]
RUN_FILES = ["metrics.json", "trajectory.csv", "trajectory.tum", "truth.csv", "gps.csv",
             "dead_reckoning.csv", "landmarks.csv", "true_landmarks.csv", "map.svg", "map.png"]

# (name, arguments ({dir}: a scratch directory), files made first (a name ending in / is a
# directory), fragment of stderr). Each must exit 1 within 5 s.
REFUSED = [
    ("--out is a file", ["run", "--out", "{dir}/file"], {"file": "x"},
     "--out {dir}/file: exists and is not a directory"),
    ("--out under a file", ["run", "--out", "{dir}/file/out"], {"file": "x"},
     "--out {dir}/file/out: cannot create it: Not a directory"),
    ("--out is the input directory",
     ["run", "--source", "victoria-park", "--data", "{dir}/data", "--out", "{dir}/data"],
     {"data/": None}, "--out {dir}/data: is the input {dir}/data"),
    ("--out inside the input directory",
     ["run", "--source", "victoria-park", "--data", "{dir}/data", "--out", "{dir}/data/o"],
     {"data/": None}, "is inside the input {dir}/data"),
    ("--out holds an input the run would replace",
     ["run", "--landmarks-csv", "{dir}/o/truth.csv", "--out", "{dir}/o"],
     {"o/": None, "o/truth.csv": "id,x_m,y_m\n1,0,0\n"},
     "the run would replace its input {dir}/o/truth.csv"),
    ("--trace is an input",
     ["run", "--source", "log", "--data", "{dir}/in.log", "--trace", "{dir}/in.log"],
     {"in.log": "x"}, "--trace {dir}/in.log: is the input {dir}/in.log"),
    ("--trace is one of the run's files",
     ["run", "--out", "{dir}", "--trace", "{dir}/metrics.json"], {},
     "--trace {dir}/metrics.json: is the run's own metrics.json"),
]


def run(args, **kwargs):
    return subprocess.run([FASTSLAM] + args, capture_output=True, text=True, timeout=300,
                          **kwargs)


def default_signals():
    # The test may itself run where SIGINT is ignored (a background job); the tool keeps an
    # ignored signal ignored, so give it the default.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def temporaries(directory):
    return [n for n in os.listdir(directory) if ".tmp-" in n]


@contextlib.contextmanager
def tmpfs(directory, options):
    """A tmpfs mounted on `directory`, or unittest.SkipTest when this is not possible."""
    if os.geteuid() != 0:
        raise unittest.SkipTest("not root: cannot mount a tmpfs")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", directory],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise unittest.SkipTest("cannot mount a tmpfs: " + r.stderr.strip())
    try:
        yield directory
    finally:
        subprocess.run(["umount", directory], check=True)


def read_metrics(out):
    with open(os.path.join(out, "metrics.json")) as f:
        return json.load(f)


def check_trajectory(test, out, steps):
    with open(os.path.join(out, "trajectory.csv")) as f:
        lines = f.read().split("\n")
    test.assertEqual(lines[0], "t,x,y,theta")
    test.assertEqual(lines[-1], "")  # every row whole, ending its line
    rows = [[float(v) for v in line.split(",")] for line in lines[1:-1]]
    test.assertEqual(len(rows), steps)
    test.assertTrue(all(len(row) == 4 for row in rows))
    times = [row[0] for row in rows]
    test.assertEqual(times, sorted(times))


class Outputs(unittest.TestCase):
    def test_refused_before_any_work(self):
        for name, args, files, fragment in REFUSED:
            with self.subTest(name), tempfile.TemporaryDirectory() as d:
                for file, text in files.items():
                    if text is None:
                        os.makedirs(os.path.join(d, file), exist_ok=True)
                    else:
                        with open(os.path.join(d, file), "w") as f:
                            f.write(text)
                before = sorted(os.listdir(d))
                start = time.monotonic()
                r = run([a.replace("{dir}", d) for a in args])
                self.assertEqual(r.returncode, 1, r.stderr)
                self.assertIn(fragment.replace("{dir}", d), r.stderr)
                self.assertLess(time.monotonic() - start, 5)
                self.assertEqual(sorted(os.listdir(d)), before)

    def test_read_only_file_system_refused_before_any_work(self):
        with tempfile.TemporaryDirectory() as d, tmpfs(d, "ro,size=64k"):
            start = time.monotonic()
            r = run(["run", "--no-progress", "--out", d])
            self.assertEqual(r.returncode, 1, r.stderr)
            self.assertIn("--out " + d + ": cannot write there: Read-only file system", r.stderr)
            self.assertLess(time.monotonic() - start, 5)

    def test_earlier_runs_files_removed_and_nothing_else(self):
        with tempfile.TemporaryDirectory() as d:
            log = os.path.join(d, "no_truth.log")
            with open(log, "w") as f:
                f.write(HEADER + "control 0.1 0.1 1 0\nscan 0.1 1 5 0.1 -\n")
            out = os.path.join(d, "out")
            os.makedirs(out)
            stale = RUN_FILES + [".trajectory.csv.tmp-1", ".map.png.tmp-77", ".map.svg.tmp-78"]
            for name in stale + ["notes.txt", ".truth.csv.bak"]:
                with open(os.path.join(out, name), "w") as f:
                    f.write("an earlier run\n")
            r = run(["run", "--source", "log", "--data", log, "--out", out, "--no-progress",
                     "--no-plot"])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertEqual(sorted(os.listdir(out)),
                             [".truth.csv.bak", "dead_reckoning.csv", "landmarks.csv",
                              "metrics.json", "notes.txt", "trajectory.csv", "trajectory.tum"])
            for name in ["dead_reckoning.csv", "trajectory.csv", "landmarks.csv"]:
                with open(os.path.join(out, name)) as f:
                    self.assertNotIn("an earlier run", f.read())
            with open(os.path.join(out, "notes.txt")) as f:
                self.assertEqual(f.read(), "an earlier run\n")
            self.assertEqual(read_metrics(out)["status"], "complete")

    def interrupt(self, sig, out, extra=(), watch="."):
        """Starts the long run, sends `sig` once it is writing, returns the finished process."""
        p = subprocess.Popen([FASTSLAM] + LONG + ["--out", out] + list(extra),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=default_signals)
        temp = os.path.join(out, watch, ".trajectory.csv.tmp-%d" % p.pid)
        deadline = time.monotonic() + 120
        while not (os.path.exists(temp) and os.path.getsize(temp) > 0):
            self.assertIsNone(p.poll(), "the run ended before it was interrupted")
            self.assertLess(time.monotonic(), deadline)
            time.sleep(0.05)
        p.send_signal(sig)
        stdout, stderr = p.communicate(timeout=120)
        return p.returncode, stdout, stderr

    def test_sigint_and_sigterm_write_the_run_so_far(self):
        for sig, code, name in [(signal.SIGINT, 130, "SIGINT"), (signal.SIGTERM, 143, "SIGTERM")]:
            with self.subTest(name), tempfile.TemporaryDirectory() as d:
                out = os.path.join(d, "out")
                trace = os.path.join(d, "trace.csv")
                returncode, stdout, stderr = self.interrupt(
                    sig, out, ["--trace", trace, "--trace-every", "20"])
                self.assertEqual(returncode, code, stderr)
                m = read_metrics(out)
                self.assertEqual(m["status"], "interrupted")
                self.assertEqual(m["ended_by"], name)
                self.assertGreater(m["steps"], 0)
                self.assertLess(m["steps"], 100000000)
                self.assertIn("(stopped by " + name + ")", stdout)
                check_trajectory(self, out, m["steps"])
                for name_ in ["trajectory.tum", "truth.csv", "landmarks.csv",
                              "true_landmarks.csv"]:
                    self.assertTrue(os.path.exists(os.path.join(out, name_)), name_)
                self.assertEqual(temporaries(out), [])
                # The trace so far, in place and whole.
                self.assertEqual(temporaries(d), [])
                with open(trace) as f:
                    rows = f.read().split("\n")
                self.assertTrue(rows[0].startswith("t,scan,pose_error_m,"))
                self.assertEqual(rows[-1], "")
                self.assertGreater(len(rows), 2)
                self.assertTrue(all(len(r.split(",")) == 13 for r in rows[1:-1]))

    def test_interrupted_sweep_summarises_the_seeds_so_far(self):
        with tempfile.TemporaryDirectory() as out:
            returncode, stdout, stderr = self.interrupt(signal.SIGINT, out,
                                                        ["--seeds", "1-3"], "seed-1")
            self.assertEqual(returncode, 130, stderr)
            self.assertEqual(sorted(os.listdir(out)), ["seed-1", "sweep.csv", "sweep.json"])
            with open(os.path.join(out, "sweep.json")) as f:
                sweep = json.load(f)
            self.assertEqual(sweep["status"], "interrupted")
            self.assertEqual(len(sweep["per_seed"]), 1)
            self.assertEqual(sweep["per_seed"][0]["status"], "interrupted")
            self.assertEqual(read_metrics(os.path.join(out, "seed-1"))["status"], "interrupted")

    def test_refused_sweep_keeps_the_earlier_sweep(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "out")
            r = run(["run"] + SMALL + ["--seeds", "1-2", "--out", out])
            self.assertEqual(r.returncode, 0, r.stderr)
            before = {}
            for name_ in ["sweep.json", "sweep.csv"]:
                with open(os.path.join(out, name_)) as f:
                    before[name_] = f.read()
            bad = os.path.join(d, "bad.log")
            with open(bad, "w") as f:
                f.write("not a log\n")
            r = run(["run", "--source", "log", "--data", bad, "--seeds", "1-2", "--no-progress",
                     "--no-plot", "--out", out])
            self.assertEqual(r.returncode, 1, r.stderr)
            self.assertIn(bad + ":1:", r.stderr)
            for name_, text in before.items():
                with open(os.path.join(out, name_)) as f:
                    self.assertEqual(f.read(), text, name_)

    def test_failed_seed_is_in_the_sweep(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "out")
            log = os.path.join(d, "twice.log")
            # The second scan sees landmark 3 twice, which the filter refuses mid-run.
            with open(log, "w") as f:
                f.write(HEADER + "landmark 3 5 0\ncontrol 0.1 0.1 1 0\nscan 0.1 1 5 0.1 3\n"
                        "control 0.2 0.1 1 0\nscan 0.2 2 5 0.1 3 6 0.2 3\n")
            r = run(["run", "--source", "log", "--data", log, "--association", "known",
                     "--seeds", "4-5", "--no-progress", "--no-plot", "--out", out])
            self.assertEqual(r.returncode, 1, r.stderr)
            self.assertIn("fastslam: error: seed 4: " + log + ":", r.stderr)
            self.assertEqual(temporaries(out), [])
            with open(os.path.join(out, "sweep.json")) as f:
                sweep = json.load(f)
            self.assertTrue(sweep["status"].startswith("failed: seed 4: "), sweep["status"])
            self.assertEqual(len(sweep["per_seed"]), 1)
            self.assertEqual(sweep["per_seed"][0]["seed"], 4)
            self.assertTrue(sweep["per_seed"][0]["status"].startswith("failed: "))
            self.assertEqual(read_metrics(os.path.join(out, "seed-4"))["status"],
                             sweep["per_seed"][0]["status"])
            self.assertFalse(os.path.exists(os.path.join(out, "seed-5")))
            self.assertTrue(os.path.exists(os.path.join(out, "sweep.csv")))

    def test_second_sigint_kills_at_once(self):
        with tempfile.TemporaryDirectory() as out:
            p = subprocess.Popen([FASTSLAM] + LONG + ["--out", out], stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, preexec_fn=default_signals)
            temp = os.path.join(out, ".trajectory.csv.tmp-%d" % p.pid)
            while not (os.path.exists(temp) and os.path.getsize(temp) > 0):
                self.assertIsNone(p.poll())
                time.sleep(0.05)
            p.send_signal(signal.SIGINT)
            time.sleep(0.01)
            p.send_signal(signal.SIGINT)
            self.assertEqual(p.wait(timeout=60), -signal.SIGINT)

    def test_full_disk_fails_with_what_fits(self):
        with tempfile.TemporaryDirectory() as d, tmpfs(d, "size=64k"):
            out = os.path.join(d, "out")
            r = run(["run", "--world", "grid", "--landmarks", "1000", "--max-steps", "20000",
                     "--no-progress", "--no-plot", "--out", out])
            self.assertEqual(r.returncode, 1, r.stderr)
            self.assertIn("No space left on device", r.stderr)
            self.assertNotIn("wrote " + out + "/{metrics.json,trajectory.csv,trajectory.tum,"
                             "truth.csv,dead_reckoning.csv,landmarks.csv", r.stdout)
            m = read_metrics(out)
            self.assertTrue(m["status"].startswith("failed: "), m["status"])
            self.assertIn("No space left on device", m["status"])
            self.assertEqual(m["ended_by"], "error")
            self.assertEqual(temporaries(out), [])
            # What was written is whole.
            if os.path.exists(os.path.join(out, "trajectory.csv")):
                with open(os.path.join(out, "trajectory.csv")) as f:
                    self.assertTrue(f.read().endswith("\n"))

    def test_evaluation_problem_is_a_warning(self):
        with tempfile.TemporaryDirectory() as d:
            log = os.path.join(d, "unknown_id.log")
            with open(log, "w") as f:
                f.write(UNKNOWN_ID)
            out = os.path.join(d, "out")
            r = run(["run", "--source", "log", "--data", log, "--association", "known",
                     "--out", out, "--no-progress", "--no-plot"])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertIn("warning: landmark evaluation: estimated landmark id 7 is not a true "
                          "landmark", r.stderr)
            m = read_metrics(out)
            self.assertEqual(m["status"], "complete")
            self.assertEqual(m["landmarks"], 2)
            # Where the id first appears, then what the evaluation could not do.
            self.assertEqual(m["warnings"], [
                log + ":11 (scan 2, t = 0.200 s): landmark id 7 is not among the source's true "
                "landmarks",
                "landmark evaluation: estimated landmark id 7 is not a true landmark"])


    def test_the_picture_is_svg_unless_told(self):
        """map.svg by default (also for each seed of a sweep), map.png only on request (not
        drawn here: plot_run_test covers it), none with --plot none; metrics.json says which."""
        import xml.etree.ElementTree as ElementTree
        small = [a for a in SMALL if a != "--no-plot"]
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "out")
            r = run(["run"] + small + ["--out", out])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertIn("wrote " + out + "/map.svg", r.stdout)
            self.assertFalse(os.path.exists(os.path.join(out, "map.png")))
            root = ElementTree.parse(os.path.join(out, "map.svg")).getroot()
            self.assertEqual(root.tag, "{http://www.w3.org/2000/svg}svg")
            self.assertEqual(read_metrics(out)["options"]["plot"], "svg")
            self.assertFalse(read_metrics(out)["options"]["no-plot"])
            r = run(["run"] + small + ["--out", out, "--plot", "none"])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertNotIn("map.svg", r.stdout)
            self.assertFalse(os.path.exists(os.path.join(out, "map.svg")))
            self.assertEqual(read_metrics(out)["options"]["plot"], "none")
            sweep = os.path.join(d, "sweep")
            r = run(["run"] + small + ["--seeds", "1-2", "--out", sweep])
            self.assertEqual(r.returncode, 0, r.stderr)
            for seed in ("seed-1", "seed-2"):
                ElementTree.parse(os.path.join(sweep, seed, "map.svg"))
            r = run(["run"] + small + ["--out", out, "--plot", "png", "--no-plot"])
            self.assertNotEqual(r.returncode, 0)  # CLI11's own code for a usage error
            self.assertIn("--plot excludes --no-plot", r.stderr)


class Convert(unittest.TestCase):
    def test_writes_through_a_symlink(self):
        with tempfile.TemporaryDirectory() as d:
            target = os.path.join(d, "real.log")
            with open(target, "w") as f:
                f.write("old\n")
            link = os.path.join(d, "link.log")
            os.symlink("real.log", link)
            r = run(["convert", "--world", "grid", "--landmarks", "100", "--out", link])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertTrue(os.path.islink(link))
            with open(target) as f:
                self.assertTrue(f.read().startswith("fastslam-log 1\n"))
            self.assertEqual(sorted(os.listdir(d)), ["link.log", "real.log"])

    def test_refuses_devices_and_directories(self):
        with tempfile.TemporaryDirectory() as d:
            os.symlink("/dev/full", os.path.join(d, "full"))
            os.makedirs(os.path.join(d, "dir"))
            for out, kind in [("/dev/full", "a device"), (os.path.join(d, "full"), "a device"),
                              (os.path.join(d, "dir"), "a directory")]:
                with self.subTest(out):
                    r = run(["convert", "--world", "grid", "--landmarks", "100", "--out", out])
                    self.assertEqual(r.returncode, 1, r.stderr)
                    self.assertIn(out + ": is " + kind + "; refusing to replace it", r.stderr)
            self.assertTrue(stat.S_ISCHR(os.stat("/dev/full").st_mode))
            self.assertTrue(os.path.islink(os.path.join(d, "full")))
            self.assertEqual(os.listdir(os.path.join(d, "dir")), [])
            self.assertEqual(sorted(os.listdir(d)), ["dir", "full"])

    def test_stopped_leaves_nothing(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "big.log")
            p = subprocess.Popen([FASTSLAM, "convert", "--world", "grid", "--landmarks",
                                  "1000000", "--out", out], stdout=subprocess.DEVNULL,
                                 stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
            temp = os.path.join(d, ".big.log.tmp-%d" % p.pid)
            while not (os.path.exists(temp) and os.path.getsize(temp) > 0):
                self.assertIsNone(p.poll())
                time.sleep(0.05)
            p.send_signal(signal.SIGINT)
            _, stderr = p.communicate(timeout=60)
            self.assertEqual(p.returncode, 130, stderr)
            self.assertIn("SIGINT: stopped; " + out + " left as it was", stderr)
            self.assertEqual(os.listdir(d), [])


class EndMarker(unittest.TestCase):
    def test_convert_ends_the_log_and_a_cut_log_runs_with_a_warning(self):
        with tempfile.TemporaryDirectory() as d:
            log = os.path.join(d, "loop.log")
            r = run(["convert", "--world", "loop", "--loop-length", "200", "--out", log])
            self.assertEqual(r.returncode, 0, r.stderr)
            with open(log) as f:
                text = f.read()
            lines = text.split("\n")
            records = [l for l in lines[lines.index("end_header") + 1:-2] if l and l[0] != "#"]
            self.assertEqual(lines[-2], "end %d" % len(records))
            self.assertEqual(lines[-1], "")
            args = ["--no-progress", "--no-plot", "--max-steps", "200"]

            whole = os.path.join(d, "whole")
            r = run(["run", "--source", "log", "--data", log, "--out", whole] + args)
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertNotIn(NO_END_WARNING, r.stderr)
            self.assertEqual(read_metrics(whole)["warnings"], [])

            cut = os.path.join(d, "cut.log")
            with open(cut, "w") as f:
                f.write(text[:text.rindex("end ")])
            warning = (cut + ": " + NO_END_WARNING + "; regenerate it from its data with "
                       "`fastslam convert`, which ends it with one (docs/log-format.md)")
            out = os.path.join(d, "cut")
            r = run(["run", "--source", "log", "--data", cut, "--out", out] + args)
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertIn("warning: " + warning + "\n", r.stderr)
            m = read_metrics(out)
            self.assertEqual(m["status"], "complete")
            self.assertEqual(m["warnings"], [warning])
            # The same run otherwise.
            with open(os.path.join(out, "trajectory.csv")) as f1, \
                    open(os.path.join(whole, "trajectory.csv")) as f2:
                self.assertEqual(f1.read(), f2.read())

            # From a pipe, the warning comes at its end (a run stopped before it cannot tell).
            piped = ["run", "--source", "log", "--data", "-", "--no-progress", "--no-plot"]
            r = run(piped, input=text[:text.rindex("end ")])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertIn("warning: <stdin>: " + NO_END_WARNING, r.stderr)
            r = run(piped + ["--max-steps", "200"], input=text[:text.rindex("end ")])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertNotIn(NO_END_WARNING, r.stderr)
            r = run(piped, input=text)
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertNotIn(NO_END_WARNING, r.stderr)

            # Converting a cut log passes the warning on.
            r = run(["convert", "--source", "log", "--data", cut, "--out",
                     os.path.join(d, "again.log")])
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertIn("warning: " + warning, r.stderr)

    def test_a_record_after_the_marker_is_refused(self):
        with tempfile.TemporaryDirectory() as d:
            log = os.path.join(d, "more.log")
            with open(log, "w") as f:
                f.write(UNKNOWN_ID + "control 0.3 0.1 1 0\n")
            r = run(["run", "--source", "log", "--data", log, "--no-progress", "--no-plot"])
            self.assertEqual(r.returncode, 1, r.stderr)
            self.assertIn(log + ":13: 'control' after the end marker (line 12): the log ends "
                          "there", r.stderr)
            with open(log, "w") as f:
                f.write(UNKNOWN_ID.replace("end 5", "end 4"))
            r = run(["run", "--source", "log", "--data", log, "--no-progress", "--no-plot"])
            self.assertEqual(r.returncode, 1, r.stderr)
            self.assertIn(log + ":12: the end marker counts 4 records, but the log has 5 before "
                          "it", r.stderr)


if __name__ == "__main__":
    FASTSLAM = sys.argv.pop(1)
    unittest.main()
