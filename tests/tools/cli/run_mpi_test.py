#!/usr/bin/python3
"""`fastslam run` under `mpirun`: the run's particles spread over 2, 3 and 4 ranks
(oversubscribed) write, from rank 0 alone, every file the one-process run writes, byte for byte,
and metrics.json too but for the fields that measure the process; --max-seconds and SIGINT stop
every rank at the same event; ranks that read different input all stop with the reason; what is
refused over ranks (--checkpoint, --trace, the EKF
baseline, fewer particle blocks than ranks) makes every rank exit 1 with the reason, none left
waiting.

Skipped (exit 77, with the reason) without `mpirun`, when the binary was built without MPI, and
under ThreadSanitizer; under AddressSanitizer without leak detection.

Usage: run_mpi_test.py FASTSLAM_BINARY
"""
import os
import signal
import subprocess
import sys
import tempfile
import time
import unittest

import checkpoint_resume_test as crt
import sweep_mpi_test

FASTSLAM = None
TIMEOUT = 300
# A grid world with false alarms and unknown association (landmarks made and removed, particles
# with different maps moving between ranks): about 3 s on one core.
WORLD = ["run", "--world", "grid", "--landmarks", "400", "--scan-period", "0.1", "--clutter", "1",
         "--no-progress", "--plot", "none", "--max-steps", "300"]
ML = ["--association", "ml", "--particles", "600"]
FS2_KNOWN = ["--algorithm", "fastslam2", "--association", "known", "--particles", "600"]


def mpirun(n, args, **kw):
    cmd = ["mpirun", "--oversubscribe"]
    if "ASAN_OPTIONS" in os.environ:
        cmd += ["-x", "ASAN_OPTIONS"]
    if os.geteuid() == 0:
        cmd.append("--allow-run-as-root")
    cmd += ["-n", str(n), FASTSLAM] + args
    return subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT, **kw)


class RunOverRanksTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.dir = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def path(self, name):
        return os.path.join(self.dir, name)

    def check_same_as_one_process(self, args, ranks):
        one = self.path("one")
        r = crt.run(args + ["--out", one])
        self.assertEqual(r.returncode, 0, r.stderr)
        summary_lines = len(r.stdout.splitlines())
        for n in ranks:
            with self.subTest(ranks=n):
                out = self.path(f"ranks{n}")
                r = mpirun(n, args + ["--out", out])
                self.assertEqual(r.returncode, 0, r.stdout + r.stderr)
                # One summary (rank 0's), not one per rank.
                self.assertEqual(len(r.stdout.splitlines()), summary_lines, r.stdout)
                a, b = crt.tree_digest(one), crt.tree_digest(out)
                self.assertEqual(sorted(a), sorted(b))
                for name in a:
                    if name != "metrics.json":
                        self.assertEqual(a[name], b[name], name)
                m1 = crt.comparable_metrics(os.path.join(one, "metrics.json"))
                mn = crt.comparable_metrics(os.path.join(out, "metrics.json"))
                self.assertEqual(mn.pop("ranks"), n)
                self.assertEqual(m1, mn)

    def test_ml_with_clutter_gives_the_one_process_files(self):
        self.check_same_as_one_process(WORLD + ML, [2, 3])

    def test_fastslam2_known_ids_gives_the_one_process_files(self):
        self.check_same_as_one_process(WORLD + FS2_KNOWN, [2])

    def test_refusals_end_every_rank(self):
        cases = [
            (["--checkpoint", self.path("c.bin")], "--checkpoint is not available"),
            (["--trace", self.path("t.csv")], "--trace"),
            (["--algorithm", "ekf"], "--algorithm ekf"),
            (["--particles", "300"], "use at least 513 particles or at most 2 rank(s)"),
        ]
        for extra, needle in cases:
            with self.subTest(extra=extra):
                out = self.path("refused")
                base = WORLD + (ML if extra[0] != "--particles" else ["--association", "ml"])
                r = mpirun(3, base + ["--out", out] + extra)
                self.assertNotEqual(r.returncode, 0)
                self.assertIn(needle, r.stderr)
                self.assertFalse(os.path.exists(os.path.join(out, "metrics.json")))

    def test_ranks_that_read_different_input_stop_together_with_the_reason(self):
        # An MPMD launch: rank 1 simulates another seed (as a data file that differs between
        # nodes would), or ends its run early.
        assert WORLD[-2:] == ["--max-steps", "300"]
        cases = [(WORLD + ["--seed", "2"], "'s events differ from rank 0's"),
                 (WORLD[:-2] + ["--max-steps", "150"], "'s run ended where rank 0's did not")]
        for rank1, needle in cases:
            with self.subTest(rank1=rank1[-2:]):
                out = self.path("differ")
                cmd = ["mpirun", "--oversubscribe"] + (
                    ["--allow-run-as-root"] if os.geteuid() == 0 else [])
                cmd += ["-n", "1", FASTSLAM] + WORLD + ML + ["--out", out]
                cmd += [":", "-n", "1", FASTSLAM] + rank1 + ML + ["--out", out + "1"]
                r = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT)
                self.assertNotEqual(r.returncode, 0, r.stdout)
                self.assertIn("the ranks read different input", r.stderr)
                self.assertIn(needle, r.stderr)
                self.assertIn("the same source with the same options", r.stderr)

    def test_max_seconds_stops_every_rank_together(self):
        out = self.path("stopped")
        args = ["run", "--world", "grid", "--landmarks", "2000", "--association", "ml", "--particles",
                "1000", "--no-progress", "--plot", "none", "--max-seconds", "1.5", "--out", out]
        start = time.monotonic()
        r = mpirun(2, args)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertLess(time.monotonic() - start, 60)
        m = crt.comparable_metrics(os.path.join(out, "metrics.json"))
        self.assertEqual(m["ended_by"], "--max-seconds")

    def test_sigint_stops_every_rank_together(self):
        out = self.path("interrupted")
        args = ["run", "--world", "grid", "--landmarks", "2000", "--association", "ml", "--particles",
                "1000", "--no-progress", "--plot", "none", "--out", out]
        cmd = ["mpirun", "--oversubscribe"] + (["--allow-run-as-root"] if os.geteuid() == 0 else [])
        p = subprocess.Popen(cmd + ["-n", "2", FASTSLAM] + args, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
        # Signalled before the ranks install their handlers (MPI's start-up under a sanitizer on
        # a loaded machine takes seconds), the ranks would just die: wait until rank 0 has
        # opened its output files, which it does after installing them, then a second more.
        deadline = time.monotonic() + TIMEOUT / 2
        while not (os.path.isdir(out) and os.listdir(out)) and p.poll() is None:
            self.assertLess(time.monotonic(), deadline, "the run never opened its outputs")
            time.sleep(0.1)
        time.sleep(1)
        p.send_signal(signal.SIGINT)  # mpirun forwards it to every rank
        _, err = p.communicate(timeout=TIMEOUT)
        self.assertTrue(os.path.exists(os.path.join(out, "metrics.json")), err)
        m = crt.comparable_metrics(os.path.join(out, "metrics.json"))
        self.assertEqual(m["status"], "interrupted", err)


if __name__ == "__main__":
    FASTSLAM = os.path.abspath(sys.argv.pop(1))
    crt.FASTSLAM = FASTSLAM
    sweep_mpi_test.FASTSLAM = FASTSLAM
    if "address" in os.environ.get("FASTSLAM_SANITIZE", ""):
        os.environ["ASAN_OPTIONS"] = os.environ.get("ASAN_OPTIONS", "") + ":detect_leaks=0"
    reason = sweep_mpi_test.skip_reason()
    if reason:
        print("SKIP: run under mpirun: " + reason)
        sys.exit(77)
    unittest.main()
