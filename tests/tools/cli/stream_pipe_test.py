#!/usr/bin/python3
"""`fastslam run --source log --data - --stream -` behind a pipe, as a live producer drives it.

A producer writes a simulated log into the run's standard input a few records at a time,
sleeping between them. The test checks that per-scan JSON lines come out while the producer is
still writing (the input is read incrementally, not first read whole), that the lines hold what
docs/streaming.md promises and agree with the trajectory file, that the run equals the same log
read from a file, and that a malformed line in the middle ends the run with
"<stdin>:<line>: <reason>" while the results up to it are kept.

Usage: stream_pipe_test.py FASTSLAM_BINARY
"""
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
import unittest

FASTSLAM = None


def run_args(out_dir):
    return [FASTSLAM, "run", "--source", "log", "--data", "-", "--stream", "-", "--out", out_dir,
            "--no-plot", "--no-progress"]


class LineCollector(threading.Thread):
    """Reads the run's standard output as it comes, noting when each line arrived (a reader
    that fell behind would block the run's writes, and with them its reading)."""

    def __init__(self, stream):
        super().__init__(daemon=True)
        self.stream = stream
        self.lines = []  # (arrival time, parsed line)

    def run(self):
        for line in self.stream:
            self.lines.append((time.monotonic(), json.loads(line)))


class StreamPipeTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        cls.log = os.path.join(cls.tmp.name, "loop.log")
        subprocess.run([FASTSLAM, "convert", "--source", "sim", "--world", "loop",
                        "--loop-length", "500", "--out", cls.log],
                       check=True, capture_output=True)
        with open(cls.log) as f:
            cls.lines = f.read().splitlines(keepends=True)
        cls.header_end = next(i for i, l in enumerate(cls.lines) if l.startswith("end_header")) + 1

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def test_lines_come_out_while_the_producer_writes(self):
        out = os.path.join(self.tmp.name, "live")
        proc = subprocess.Popen(run_args(out), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE)
        collector = LineCollector(proc.stdout)
        collector.start()
        body = self.lines[self.header_end:]
        proc.stdin.write("".join(self.lines[:self.header_end]).encode())
        # The first half a few hundred records at a time with pauses, as a live robot would;
        # then, with the input still open, estimates must come out (a reader that read the
        # whole input first would give none until the end).
        half = len(body) // 2
        for start in range(0, half, 500):
            proc.stdin.write("".join(body[start:min(start + 500, half)]).encode())
            proc.stdin.flush()
            time.sleep(0.02)
        deadline = time.monotonic() + 120
        while not collector.lines and time.monotonic() < deadline:
            time.sleep(0.05)
        early = len(collector.lines)
        proc.stdin.write("".join(body[half:]).encode())
        proc.stdin.close()
        err = proc.stderr.read()
        proc.wait(timeout=300)
        collector.join(timeout=60)
        proc.stdout.close()
        proc.stderr.close()
        self.assertEqual(proc.returncode, 0, err.decode())
        self.assertGreater(early, 0, "no scan line came out while the input was still open")
        received = [line for _, line in collector.lines]
        scans = sum(1 for l in body if l.startswith("scan"))
        self.assertEqual(len(received), scans)
        self.assertEqual([r["scan"] for r in received], list(range(scans)))
        for r in received:
            for key in ("t", "pose", "covariance", "n_eff", "landmarks", "associations",
                        "latency_ms"):
                self.assertIn(key, r)
            self.assertEqual(len(r["pose"]), 3)
            self.assertEqual(len(r["covariance"]), 9)
            self.assertGreaterEqual(r["latency_ms"], 0)
            for a in r["associations"]:
                self.assertIn(a["outcome"], ("associated", "new", "discarded"))
        self.assertTrue(any(a["outcome"] == "associated" for r in received
                            for a in r["associations"]))
        # The summary went to stderr, not into the stream.
        self.assertIn(b"wrote", err)
        # The same log from a file: the same path, bit for bit.
        direct = os.path.join(self.tmp.name, "direct")
        subprocess.run([FASTSLAM, "run", "--source", "log", "--data", self.log, "--out", direct,
                        "--no-plot", "--no-progress"], check=True, capture_output=True)
        with open(os.path.join(out, "trajectory.csv")) as a, \
                open(os.path.join(direct, "trajectory.csv")) as b:
            self.assertEqual(a.read(), b.read())
        # The last line's pose is the run's final estimate.
        with open(os.path.join(out, "metrics.json")) as f:
            metrics = json.load(f)
        self.assertEqual(metrics["ended_by"], "end of data")
        self.assertEqual(metrics["world"], "<stdin>")

    def test_a_malformed_line_ends_the_run_and_keeps_the_results(self):
        out = os.path.join(self.tmp.name, "broken")
        body = self.lines[self.header_end:]
        cut = len(body) // 3
        bad_line = self.header_end + cut + 1  # 1-based line of the inserted record
        text = "".join(self.lines[:self.header_end] + body[:cut]) + "scan 1e9 2 5.0\n" + \
            "".join(body[cut:])
        proc = subprocess.run(run_args(out), input=text.encode(), capture_output=True,
                              timeout=120)
        err = proc.stderr.decode()
        self.assertNotEqual(proc.returncode, 0)
        self.assertIn("<stdin>:%d: " % bad_line, err)
        self.assertIn("scan of 2 observations needs 9 fields", err)
        streamed = [json.loads(l) for l in proc.stdout.splitlines() if l]
        scans_before = sum(1 for l in body[:cut] if l.startswith("scan"))
        self.assertEqual(len(streamed), scans_before)
        with open(os.path.join(out, "metrics.json")) as f:
            metrics = json.load(f)
        self.assertEqual(metrics["ended_by"], "input error")
        self.assertIn("<stdin>:%d:" % bad_line, metrics["input_error"])
        with open(os.path.join(out, "trajectory.csv")) as f:
            rows = f.read().splitlines()
        controls_before = sum(1 for l in body[:cut] if l.startswith("control"))
        self.assertEqual(len(rows) - 1, controls_before)

    def test_a_landmark_after_the_first_event_is_refused_from_a_pipe(self):
        # After the first scan with detections (the pipe's read-ahead stops there).
        body = self.lines[self.header_end:]
        scan = next(i for i, l in enumerate(body) if l.startswith("scan") and l.split()[2] != "0")
        text = "".join(self.lines[:self.header_end] + body[:scan + 5]) + \
            "landmark 999999 1 2\n" + "".join(body[scan + 5:scan + 50])
        proc = subprocess.run(run_args(os.path.join(self.tmp.name, "late")),
                              input=text.encode(), capture_output=True, timeout=60)
        self.assertNotEqual(proc.returncode, 0)
        self.assertIn("'landmark' records must come before the events", proc.stderr.decode())


if __name__ == "__main__":
    FASTSLAM = sys.argv.pop(1)
    unittest.main()
