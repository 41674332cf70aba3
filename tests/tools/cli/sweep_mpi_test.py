#!/usr/bin/python3
"""`fastslam sweep` under `mpirun` on this machine: 1, 2 and 3 ranks (oversubscribed) give the
table `--jobs 1` gives; a rerun under another rank count skips the runs already complete; a rank
that cannot read an input, ranks given different sweeps, and a run that fails each end every
rank with exit code 1 and a message naming the rank or the run, within seconds.

Skipped (exit 77, with the reason) without `mpirun`, when the binary was built without MPI
(`fastslam --version` says "mpi no") or under ThreadSanitizer. Under AddressSanitizer leak
detection is off in the ranks: Open MPI's plugins keep allocations to the end of the process.

Usage: sweep_mpi_test.py FASTSLAM_BINARY [SHARED_DIR]
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweep_test  # noqa: E402  the grid and the table, shared with the local test

FASTSLAM = None
# Each mpirun here, start to end.
TIMEOUT = 60


def mpirun(n, args, extra=()):
    """mpirun of `fastslam ARGS` on N ranks; `extra` are more MPMD apps (lists of arguments).
    mpirun does not kill the other ranks when one exits non-zero, so each rank is seen to end
    by itself (and mpirun then exits 0: the ranks' codes are read from recorded())."""
    cmd = ["mpirun", "--oversubscribe", "--mca", "orte_abort_on_non_zero_status", "0"]
    if "ASAN_OPTIONS" in os.environ:
        cmd += ["-x", "ASAN_OPTIONS"]
    if os.geteuid() == 0:
        cmd.append("--allow-run-as-root")
    cmd += ["-n", str(n)] + args
    for app in extra:
        cmd += [":"] + app
    return subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT)


def recorded(rcdir, args):
    """`fastslam ARGS` in a shell that records its exit code in RCDIR/rc.RANK."""
    script = ('"$0" "$@"; c=$?; echo $c > "%s/rc.$OMPI_COMM_WORLD_RANK"; exit $c' % rcdir)
    return ["sh", "-c", script, FASTSLAM] + args


def exit_codes(rcdir, n):
    codes = []
    for r in range(n):
        with open(os.path.join(rcdir, "rc.%d" % r)) as f:
            codes.append(int(f.read()))
    return codes


class SweepMpi(unittest.TestCase):
    def test_ranks_change_no_result_and_resume(self):
        with tempfile.TemporaryDirectory() as d:
            config = sweep_test.sweep_file(d, "grid.json")
            local = os.path.join(d, "local")
            r = sweep_test.run(["sweep", "--config", config, "--out", local, "--jobs", "1"])
            self.assertEqual(r.returncode, 0, r.stderr)
            expected = sweep_test.table(local)
            self.assertEqual(len(expected), 12)
            for n in (1, 2, 3):
                out = os.path.join(d, "ranks%d" % n)
                r = mpirun(n, [FASTSLAM, "sweep", "--config", config, "--out", out])
                self.assertEqual(r.returncode, 0, r.stdout + r.stderr)
                self.assertIn("%d rank" % n, r.stdout)
                self.assertEqual(sweep_test.table(out), expected, n)
                with open(os.path.join(out, "sweep.json")) as f:
                    self.assertEqual(json.load(f)["sweep"]["ranks"], n)
            # Two runs lost; three ranks redo only those.
            out = os.path.join(d, "ranks2")
            with open(os.path.join(out, "sweep.json")) as f:
                runs = json.load(f)["runs"]
            shutil.rmtree(os.path.join(out, runs[0]["dir"]))
            os.remove(os.path.join(out, runs[5]["dir"], "metrics.json"))
            r = mpirun(3, [FASTSLAM, "sweep", "--config", config, "--out", out])
            self.assertEqual(r.returncode, 0, r.stdout + r.stderr)
            self.assertIn("(10 done before)", r.stdout)
            self.assertEqual(sweep_test.table(out), expected)

    def test_a_rank_without_an_input_stops_every_rank(self):
        with tempfile.TemporaryDirectory() as d:
            # Rank 0 works in d/a, which has the world's files; rank 1 in d/b, which lacks one.
            for sub in ("a", "b", "rc"):
                os.mkdir(os.path.join(d, sub))
            with open(os.path.join(d, "a", "lm.csv"), "w") as f:
                f.write("id,x_m,y_m\n1,10,0\n2,0,10\n3,-10,0\n")
            for sub in ("a", "b"):
                with open(os.path.join(d, sub, "wp.csv"), "w") as f:
                    f.write("index,x_m,y_m\n0,0,0\n1,20,0\n2,20,20\n")
            with open(os.path.join(d, "rel.json"), "w") as f:
                json.dump({"base": {"landmarks-csv": "lm.csv", "waypoints-csv": "wp.csv",
                                    "max-steps": 50, "no-plot": True},
                           "seeds": "1-2", "grid": {"particles": [5, 10]}}, f)
            rc = os.path.join(d, "rc")
            args = ["sweep", "--config", "../rel.json", "--out", "../out"]
            r = mpirun(1, ["-wdir", os.path.join(d, "a")] + recorded(rc, args),
                       [["-n", "1", "-wdir", os.path.join(d, "b")] + recorded(rc, args)])
            self.assertEqual(exit_codes(rc, 2), [1, 1])
            self.assertIn("rank 1: ../rel.json (configuration particles-5): key 'landmarks-csv'",
                          r.stderr)
            self.assertIn("File does not exist: lm.csv", r.stderr)
            self.assertIn("sweep not started: rank(s) 1 could not plan it", r.stderr)
            self.assertFalse(os.path.exists(os.path.join(d, "out", "sweep.json")))

    def test_ranks_given_different_sweeps_stop(self):
        with tempfile.TemporaryDirectory() as d:
            a = sweep_test.sweep_file(d, "a.json")
            b = sweep_test.sweep_file(d, "b.json", base={"max-steps": 200})
            rc = os.path.join(d, "rc")
            os.mkdir(rc)
            out = os.path.join(d, "out")
            r = mpirun(2, recorded(rc, ["sweep", "--config", a, "--out", out]),
                       [["-n", "1"] + recorded(rc, ["sweep", "--config", b, "--out", out])])
            self.assertEqual(exit_codes(rc, 3), [1, 1, 1])
            self.assertIn("ranks disagree on the sweep: rank 2 read another sweep file", r.stderr)
            self.assertNotIn("rank 1 read", r.stderr)

    def test_a_failed_run_stops_every_rank(self):
        with tempfile.TemporaryDirectory() as d:
            # Landmark 3 twice in one scan: known association refuses the log at its line 10.
            with open(os.path.join(d, "dup.log"), "w") as f:
                f.write("fastslam-log 1\nmotion unicycle\ncontrol_noise 0.1 0.1\n"
                        "sensor 0.1 0.01 30 3.14159 0 0 0\nstart 0 0 0 0\nend_header\n"
                        "control 0.1 0.1 1 0\nscan 0.1 1 5 0.1 3\ncontrol 0.2 0.1 1 0\n"
                        "scan 0.2 2 5 0.1 3 6 0.2 3\n")
            config = os.path.join(d, "fail.json")
            with open(config, "w") as f:
                json.dump({"base": {"no-plot": True, "max-steps": 100}, "seeds": "1-3",
                           "sources": [{"name": "good", "world": "loop"},
                                       {"name": "bad", "source": "log",
                                        "data": os.path.join(d, "dup.log"),
                                        "association": "known"}]}, f)
            rc = os.path.join(d, "rc")
            os.mkdir(rc)
            out = os.path.join(d, "out")
            r = mpirun(2, recorded(rc, ["sweep", "--config", config, "--out", out]))
            self.assertEqual(exit_codes(rc, 2), [1, 1])
            self.assertIn("fastslam: error: sweep: bad seed ", r.stderr)
            self.assertIn("landmark id 3 appears twice in one scan", r.stderr)
            with open(os.path.join(out, "sweep.json")) as f:
                s = json.load(f)
            self.assertTrue(s["status"].startswith("failed: bad seed "), s["status"])
            self.assertEqual(s["runs_complete"], 3)


def skip_reason():
    if shutil.which("mpirun") is None:
        return "no mpirun on PATH (Debian: openmpi-bin)"
    if "thread" in os.environ.get("FASTSLAM_SANITIZE", ""):
        return "ThreadSanitizer build: Open MPI's progress threads are not instrumented"
    version = subprocess.run([FASTSLAM, "--version"], capture_output=True, text=True).stdout
    if "\nmpi yes" not in version:
        return "fastslam was built without MPI (libopenmpi-dev)"
    return None


if __name__ == "__main__":
    FASTSLAM = os.path.abspath(sys.argv.pop(1))
    sweep_test.FASTSLAM = FASTSLAM
    if len(sys.argv) > 1:
        sweep_test.SHARED = sys.argv.pop(1)
    if "address" in os.environ.get("FASTSLAM_SANITIZE", ""):
        os.environ["ASAN_OPTIONS"] = os.environ.get("ASAN_OPTIONS", "") + ":detect_leaks=0"
    reason = skip_reason()
    if reason:
        print("SKIP: sweep under mpirun: " + reason)
        sys.exit(77)
    unittest.main()
