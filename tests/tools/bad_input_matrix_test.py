#!/usr/bin/python3
"""Bad input, one defect at a time, as one table: what `fastslam` and the Python module do with it.

Each row of CASES names a defect, how its input is made, the command line, the exit code, a
fragment of standard error (naming FILE:LINE for a log), the files the --out directory must
hold or must not hold afterwards, the run's "status" in metrics.json, and whether an earlier
run's results in --out must be left as they were ("kept") or replaced by this run's
("replaced"). Every row also checks that no input file changed, that no temporary
(.NAME.tmp-PID) is left behind, that every result file present is whole, and that standard
error stays short whatever the size of the bad input.

The rows: a valid log (made by `fastslam convert` from the built-in simulator) with one defect
each (NaN, infinity, a hex float, 1e400, a NUL byte, a line cut short, a count of 10^9, time
going backwards, a repeated header line, an unknown record, a line over 4 MiB, a scan over
65536 observations, a 10^6-byte token, ...), an empty, missing or directory --data, a world
CSV with a 10^6-byte field; bad options; bad --config files; --out targets that cannot be written (a file, /dev/null,
/dev/full, a 0555 directory, the input); SIGINT and SIGTERM mid-run; a full disk (a 64 KiB
tmpfs); and refused calls of the Python module, whose filter state (to_bytes) must not change.
A row that cannot run here (no root for the tmpfs, no Python module) prints why and is
skipped.

Usage: bad_input_matrix_test.py FASTSLAM_BINARY [--python-path DIR]
Prints one line per row; exits 1 if any row failed.
"""
import argparse
import dataclasses
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from typing import Callable, Optional

FASTSLAM = None
PYTHON_PATH = None
BASE = None  # the valid log's lines, without their newlines
EARLIER = None  # a directory holding an earlier run (and a notes.txt of the user's)

# What `fastslam run --out` may write (tools/cli/run_output.h, kRunFileNames).
RUN_FILES = ["metrics.json", "trajectory.csv", "trajectory.tum", "truth.csv", "gps.csv",
             "dead_reckoning.csv", "landmarks.csv", "true_landmarks.csv", "map.svg", "map.png"]
LOG_RUN = ["run", "--source", "log", "--data", "{log}", "--out", "{out}", "--no-progress",
           "--no-plot"]
SMALL = ["run", "--world", "grid", "--landmarks", "100", "--max-steps", "20", "--no-progress",
         "--no-plot", "--out", "{out}"]
# The built-in stress run, long enough to be stopped.
LONG = ["run", "--max-steps", "100000000", "--no-progress", "--no-plot", "--out", "{out}"]
WRITTEN = ["metrics.json", "trajectory.csv", "trajectory.tum", "truth.csv", "landmarks.csv",
           "dead_reckoning.csv", "true_landmarks.csv"]


class Skip(Exception):
    """A row that cannot run here; its message says why."""


# ---- inputs ----

def first(kind, lines, nonempty_scan=False):
    """The index of the first `kind` record (a scan with observations when asked)."""
    for i, line in enumerate(lines):
        t = line.split(" ")
        if t[0] == kind and not (nonempty_scan and int(t[2]) == 0):
            return i
    raise AssertionError("the base log has no " + kind)


def write_log(d, text):
    with open(os.path.join(d, "in.log"), "wb") as f:
        f.write(text.encode("latin-1") if isinstance(text, str) else text)


def log_with(edit):
    """A maker: the base log with `edit(lines)` applied, which returns (text or lines, index
    of the line it broke[, more placeholders]); the row's {line} is that line's number."""
    def make(d):
        result, index, *more = edit(list(BASE))
        write_log(d, result if isinstance(result, (str, bytes)) else "\n".join(result) + "\n")
        return dict({"line": index + 1}, **(more[0] if more else {}))
    return make


def token(kind, k, value, nonempty_scan=False):
    """The base log with token `k` of the first `kind` record replaced by `value`."""
    def edit(lines):
        i = first(kind, lines, nonempty_scan)
        t = lines[i].split(" ")
        t[k] = value
        lines[i] = " ".join(t)
        return lines, i
    return log_with(edit)


def truncated(lines):
    # The file ends inside the first scan's eighth field, without a newline.
    i = first("scan", lines, nonempty_scan=True)
    t = lines[i].split(" ")
    n = int(t[2])
    return ("\n".join(lines[:i]) + "\n" + " ".join(t[:7]) + " " + t[7][:3], i,
            {"n": n, "fields": 3 + 3 * n})


def time_backwards(lines):
    i = first("control", lines)
    i = first("control", lines[i + 1:]) + i + 1  # the second control, before the first
    t = lines[i].split(" ")
    t[1] = "-1"
    lines[i] = " ".join(t)
    return lines, i


def repeated_header(lines):
    i = first("sensor", lines)
    return lines[:i + 1] + lines[i:], i + 1


def unknown_record(lines):
    i = first("control", lines)
    lines[i] = "odometry 0.1 0.5 0.5"
    return lines, i


def long_line(lines):
    # A comment, which a reader skips, is bounded all the same.
    i = first("control", lines)
    return lines[:i] + ["# " + "x" * (4 << 20)] + lines[i:], i


def huge_scan(lines):
    i = first("scan", lines, nonempty_scan=True)
    lines[i] = ("scan " + lines[i].split(" ")[1] + " 65537 "
                + " ".join(["5.5 0.25 -"] * 65537))
    return lines, i


def scan_count(count):
    def make(lines):
        i = first("scan", lines, nonempty_scan=True)
        t = lines[i].split(" ")
        t[2] = count
        lines[i] = " ".join(t)
        return lines, i
    return log_with(make)


def repeated_landmark(lines):
    i = first("landmark", lines)
    return lines[:i + 2] + [lines[i]] + lines[i + 2:], i + 2


def no_end_header(lines):
    i = first("end_header", lines)
    return "\n".join(lines[:i]) + "\n", i - 1  # the error names the last line read


def empty(d):
    write_log(d, "")
    return {}


def directory(d):
    os.makedirs(os.path.join(d, "in.log"))
    return {}


def nothing(d):
    return {}


def base_log(d):
    write_log(d, "\n".join(BASE) + "\n")
    return {}


def config(text):
    def make(d):
        with open(os.path.join(d, "c.json"), "w") as f:
            f.write(text)
        return {}
    return make


def world_csvs(d):
    # A world CSV's route with a 10^6-byte bad field on its third line.
    with open(os.path.join(d, "lm.csv"), "w") as f:
        f.write("id,x_m,y_m\n0,0,0\n1,5,0\n")
    with open(os.path.join(d, "wp.csv"), "w") as f:
        f.write("index,x_m,y_m\n0,0,0\n1," + "7" * 10**6 + "x,0\n")
    return {}


def regular_file(d):
    with open(os.path.join(d, "file"), "w") as f:
        f.write("the user's file\n")
    return {}


def duplicate_id(d):
    # Landmark 3 twice in one scan: known association refuses it mid-run.
    write_log(d, "fastslam-log 1\nmotion unicycle\ncontrol_noise 0.1 0.1\n"
                 "sensor 0.1 0.01 30 3.14159 0 0 0\nstart 0 0 0 0\nend_header\n"
                 "landmark 3 5 0\nlandmark 6 5 1\n"
                 "control 0.1 0.1 1 0\nscan 0.1 1 5 0.1 3\ncontrol 0.2 0.1 1 0\n"
                 "scan 0.2 2 5 0.1 3 6 0.2 3\n")
    return {"line": 12}


# ---- the table ----

@dataclasses.dataclass
class Case:
    name: str
    make: Callable  # make(scratch dir) -> extra placeholders, e.g. {"line": 130}
    args: list  # {dir}: scratch, {log}: {dir}/in.log, {out}: {dir}/out, {line}, ...
    code: int
    fragment: Optional[str]  # must be in stderr (after substitution); None: no check
    present: tuple = ()  # files --out must hold afterwards
    absent: tuple = ()  # files --out must not hold; ("*",): --out must not exist at all
    earlier: Optional[str] = None  # "kept" or "replaced": --out holds an earlier run first
    status: Optional[str] = None  # metrics.json's "status" starts with this
    max_stderr: int = 1000  # bytes
    kind: str = "cli"  # cli, signal, api
    sig: int = 0  # kind signal: sent once the run is writing
    setup: Optional[Callable] = None  # setup(case, dir, out) -> preexec_fn or None; may Skip
    call: str = ""  # kind api: the refused call on `f` (a filter after one step)
    unmount: Optional[str] = None  # set by a setup that mounted something


NOTHING = ("*",)
REFUSED = dict(absent=tuple(RUN_FILES))  # the run writes none of its files
KEPT = dict(earlier="kept")  # and an earlier run's are left as they were


def unwritable(case, d, out):
    """--out an existing 0555 directory. Root writes there anyway; then the run is made as
    nobody, or the row is skipped."""
    os.chmod(out, 0o555)
    probe = os.path.join(out, ".probe")
    try:
        with open(probe, "w"):
            pass
    except PermissionError:
        return None  # permissions apply to this user
    os.remove(probe)
    if os.geteuid() != 0:
        raise Skip("0555 does not stop this user writing")

    def as_nobody():
        os.setgroups([])
        os.setgid(65534)
        os.setuid(65534)
    os.chmod(d, 0o755)
    r = subprocess.run([FASTSLAM, "--version"], capture_output=True, preexec_fn=as_nobody)
    if r.returncode != 0:
        raise Skip("root bypasses 0555 and nobody cannot run " + FASTSLAM)
    print("     (root bypasses 0555: this row runs as nobody)")
    return as_nobody


def file_first(case, d, out):
    """{dir}/file exists before the run (and must be left as it was)."""
    regular_file(d)


def full_disk(case, d, out):
    """--out on a 64 KiB tmpfs mounted at {dir}/disk; skipped where mounting is refused."""
    if os.geteuid() != 0:
        raise Skip("not root: cannot mount a tmpfs")
    disk = os.path.join(d, "disk")
    os.makedirs(disk)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", disk],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise Skip("cannot mount a tmpfs: " + r.stderr.strip())
    case.unmount = disk
    return None


CASES = [
    # -- logs: the valid one, then one defect each --
    Case("valid log", base_log, LOG_RUN, 0, None, present=tuple(WRITTEN), earlier="replaced",
         status="complete"),
    Case("NaN", token("control", 3, "nan"), LOG_RUN, 1, "{log}:{line}: u0: 'nan' is not finite",
         **REFUSED, **KEPT),
    Case("infinity", token("scan", 3, "inf", True), LOG_RUN, 1,
         "{log}:{line}: range: 'inf' is not finite", **REFUSED, **KEPT),
    Case("hex float", token("control", 2, "0x1.8p-5"), LOG_RUN, 1,
         "{log}:{line}: dt: '0x1.8p-5' is not a number", **REFUSED, **KEPT),
    Case("1e400", token("control", 4, "1e400"), LOG_RUN, 1,
         "{log}:{line}: u1: '1e400' is out of a double's range", **REFUSED, **KEPT),
    Case("NUL byte", token("control", 3, "1\0"), LOG_RUN, 1,
         "{log}:{line}: u0: '1\\x00' is not a number", **REFUSED, **KEPT),
    Case("truncated mid-line", log_with(truncated), LOG_RUN, 1,
         "{log}:{line}: scan of {n} observations needs {fields} fields, found 8",
         **REFUSED, **KEPT),
    Case("count of 10^9", scan_count("1000000000"), LOG_RUN, 1,
         "{log}:{line}: scan of 1000000000 observations: more than the format's limit of 65536",
         **REFUSED, **KEPT),
    Case("count beyond 2^64", scan_count("99999999999999999999"), LOG_RUN, 1,
         "{log}:{line}: observation count: '99999999999999999999' is not a non-negative integer",
         **REFUSED, **KEPT),
    Case("time going backwards", log_with(time_backwards), LOG_RUN, 1,
         "{log}:{line}: time goes backwards: -1 after 0.025", **REFUSED, **KEPT),
    Case("repeated header line", log_with(repeated_header), LOG_RUN, 1,
         "{log}:{line}: header line 'sensor' is repeated", **REFUSED, **KEPT),
    Case("no end_header", log_with(no_end_header), LOG_RUN, 1,
         "{log}:{line}: end of file inside the header (no 'end_header')", **REFUSED, **KEPT),
    Case("unknown record", log_with(unknown_record), LOG_RUN, 1,
         "{log}:{line}: unknown record 'odometry' (control, scan, pose, gps, landmark or end)",
         **REFUSED, **KEPT),
    Case("repeated landmark id", log_with(repeated_landmark), LOG_RUN, 1,
         "{log}:{line}: landmark id 0 is repeated", **REFUSED, **KEPT),
    Case("negative dt", token("control", 2, "-0.5"), LOG_RUN, 1,
         "{log}:{line}: dt is negative (-0.5)", **REFUSED, **KEPT),
    Case("zero range", token("scan", 3, "0", True), LOG_RUN, 1,
         "{log}:{line}: range must be > 0 (got 0)", **REFUSED, **KEPT),
    Case("line over 4 MiB", log_with(long_line), LOG_RUN, 1,
         "{log}:{line}: line longer than 4194304 bytes", **REFUSED, **KEPT),
    Case("scan of 65537 observations", log_with(huge_scan), LOG_RUN, 1,
         "{log}:{line}: scan of 65537 observations: more than the format's limit of 65536",
         **REFUSED, **KEPT),
    Case("10^6-byte token", token("control", 3, "7" * 10**6 + "x"), LOG_RUN, 1,
         "{log}:{line}: u0: '" + "7" * 80 + "...' (1000001 bytes) is not a number",
         max_stderr=200, **REFUSED, **KEPT),
    Case("empty file", empty, LOG_RUN, 1, "{log}:0: empty file, expected 'fastslam-log 1'",
         **REFUSED, **KEPT),
    Case("missing file", nothing, LOG_RUN, 1,
         "{log}: cannot open for reading: No such file or directory", absent=NOTHING),
    Case("missing file, --out three levels new", nothing,
         [a if a != "{out}" else "{dir}/new/deeper/out" for a in LOG_RUN], 1,
         "{log}: cannot open for reading: No such file or directory", absent=NOTHING),
    Case("directory as --data", directory, LOG_RUN, 1, "{log}: is a directory, not a log file",
         **REFUSED, **KEPT),
    Case("world CSV with a 10^6-byte field", world_csvs,
         SMALL + ["--landmarks-csv", "{dir}/lm.csv", "--waypoints-csv", "{dir}/wp.csv"], 1,
         "{dir}/wp.csv:3: column 'x_m': '" + "7" * 80 + "...' (1000001 bytes) is not a number",
         max_stderr=300, **REFUSED, **KEPT),
    Case("engine refuses a record mid-run", duplicate_id, LOG_RUN + ["--association", "known"], 1,
         "{log}:{line} (scan 2, t = 0.200 s): ", present=("metrics.json", "trajectory.csv"),
         earlier="replaced", status="failed: "),
    # -- options --
    Case("unknown option", nothing, SMALL + ["--bogus"], 109,
         "The following argument was not expected: --bogus", **REFUSED, **KEPT),
    Case("--particles 0", nothing, SMALL + ["--particles", "0"], 105,
         "--particles: Value 0 not in range 1 to 100000000", **REFUSED, **KEPT),
    Case("--particles -1", nothing, SMALL + ["--particles", "-1"], 105,
         "--particles: '-1' is out of range (0 to 4294967295)", **REFUSED, **KEPT),
    Case("--seed 2^64", nothing, SMALL + ["--seed", "18446744073709551616"], 105,
         "--seed: '18446744073709551616' is out of range (0 to 18446744073709551615)",
         **REFUSED, **KEPT),
    Case("--seed -1", nothing, SMALL + ["--seed", "-1"], 105,
         "--seed: '-1' is out of range (0 to 18446744073709551615)", **REFUSED, **KEPT),
    Case("--threads 100000", nothing, SMALL + ["--threads", "100000"], 105,
         "--threads: Value 100000 not in range 0 to 4096", **REFUSED, **KEPT),
    Case("--trace-every 0", nothing, SMALL + ["--trace", "{dir}/t.csv", "--trace-every", "0"],
         105, "--trace-every: Value 0 not in range 1 to 1099511627776", **REFUSED, **KEPT),
    Case("--max-seconds nan", nothing, SMALL + ["--max-seconds", "nan"], 105,
         "--max-seconds: 'nan' is not a finite number", **REFUSED, **KEPT),
    Case("--max-seconds -1", nothing, SMALL + ["--max-seconds", "-1"], 105,
         "--max-seconds: '-1' must be > 0", max_stderr=200, **REFUSED, **KEPT),
    Case("--spacing of 10^5 digits", nothing, SMALL + ["--spacing", "9" * 10**5], 105,
         "--spacing: '" + "9" * 80 + "... (100000 bytes)' is out of a double's range",
         max_stderr=300, **REFUSED, **KEPT),
    Case("--out \"\"", nothing, SMALL[:-1] + [""], 1, '--out "" names no path'),
    # -- --config FILE.json --
    Case("malformed JSON", config('{"particles": 5,'), SMALL + ["--config", "{dir}/c.json"], 1,
         "{dir}/c.json: not valid JSON: [json.exception.parse_error.101] parse error at line 1, "
         "column 17", **REFUSED, **KEPT),
    Case("unknown key", config('{"particle": 5}'), SMALL + ["--config", "{dir}/c.json"], 1,
         "{dir}/c.json: key 'particle': unknown option", **REFUSED, **KEPT),
    Case("repeated key", config('{"particles": 5, "seed": 2, "particles": 6}'),
         SMALL + ["--config", "{dir}/c.json"], 1,
         "{dir}/c.json: key 'particles' is repeated: give each option once", **REFUSED, **KEPT),
    Case("wrong type (string)", config('{"particles": "many"}'),
         SMALL + ["--config", "{dir}/c.json"], 1,
         "{dir}/c.json: key 'particles': --particles: 'many' is not a decimal integer",
         **REFUSED, **KEPT),
    Case("wrong type (array)", config('{"seed": [1, 2]}'), SMALL + ["--config", "{dir}/c.json"],
         1, "{dir}/c.json: key 'seed': value must be a number, a string or a boolean",
         **REFUSED, **KEPT),
    Case("not an object", config('[1, 2]'), SMALL + ["--config", "{dir}/c.json"], 1,
         "{dir}/c.json: expected one JSON object", **REFUSED, **KEPT),
    Case("missing config", nothing, SMALL + ["--config", "{dir}/none.json"], 105,
         "--config: File does not exist: {dir}/none.json", **REFUSED, **KEPT),
    # -- --out targets --
    Case("--out a regular file", regular_file, SMALL[:-1] + ["{dir}/file"], 1,
         "--out {dir}/file: exists and is not a directory"),
    Case("--out /dev/null", nothing, SMALL[:-1] + ["/dev/null"], 1,
         "--out /dev/null: exists and is not a directory"),
    Case("--out /dev/full", nothing, SMALL[:-1] + ["/dev/full"], 1,
         "--out /dev/full: exists and is not a directory"),
    Case("--out the input log", base_log, LOG_RUN[:-3] + ["{log}", "--no-progress"], 1,
         "--out {log}: exists and is not a directory"),
    Case("--out a 0555 directory", nothing, SMALL, 1,
         "--out {out}: cannot write there: Permission denied", setup=unwritable, **KEPT),
    Case("convert --out /dev/full", nothing,
         ["convert", "--world", "grid", "--landmarks", "100", "--out", "/dev/full"], 1,
         "/dev/full: is a device; refusing to replace it"),
    Case("convert --out its input", base_log,
         ["convert", "--source", "log", "--data", "{log}", "--out", "{log}"], 1,
         "--out {log} is the input --data {log}: give another file"),
    Case("convert a bad log over a file", token("control", 3, "nan"),
         ["convert", "--source", "log", "--data", "{log}", "--out", "{dir}/file"], 1,
         "{log}:{line}: u0: 'nan' is not finite", setup=file_first),
    # -- signals --
    Case("SIGINT mid-run", nothing, LONG, 130, None, present=tuple(WRITTEN),
         earlier="replaced", status="interrupted", kind="signal", sig=signal.SIGINT),
    Case("SIGTERM mid-run", nothing, LONG, 143, None, present=tuple(WRITTEN),
         earlier="replaced", status="interrupted", kind="signal", sig=signal.SIGTERM),
    # -- a full disk --
    Case("full disk", nothing,
         ["run", "--world", "grid", "--landmarks", "1000", "--max-steps", "20000",
          "--no-progress", "--no-plot", "--out", "{dir}/disk/out"], 1,
         "No space left on device", present=("metrics.json",), status="failed: ",
         setup=full_disk),
    # -- the Python module: refused, and the filter's state unchanged --
    Case("api: observe a NaN range", nothing, [], 0, "ValueError: ", kind="api",
         call="f.observe([math.nan], [0.1], [2])"),
    Case("api: observe a NaN bearing", nothing, [], 0, "ValueError: ", kind="api",
         call="f.observe([5.0], [math.nan], [2])"),
    Case("api: predict with a negative dt", nothing, [], 0, "ValueError: ", kind="api",
         call="f.predict([1.0, 0.0], -0.1)"),
    Case("api: predict with an infinite control", nothing, [], 0, "ValueError: ", kind="api",
         call="f.predict([math.inf, 0.0], 0.1)"),
    Case("api: predict before the clock", nothing, [], 0, "ValueError: ", kind="api",
         call="f.predict([1.0, 0.0], 0.1, t=0.5)"),
    Case("api: observe a repeated id", nothing, [], 0, "ValueError: ", kind="api",
         call="f.observe([5.0, 6.0], [0.1, 0.2], [3, 3])"),
    Case("api: observe ranges and bearings of different lengths", nothing, [], 0,
         "ValueError: ", kind="api", call="f.observe([5.0, 6.0], [0.1], [3, 4])"),
    Case("api: set_map with a covariance not positive definite", nothing, [], 0,
         "ValueError: ", kind="api",
         call='f.set_map({"x": [0.0], "y": [0.0], "sxx": [1.0], "sxy": [2.0], "syy": [1.0]})'),
    Case("api: read_log of a NaN log", token("control", 3, "nan"), [], 0,
         "RuntimeError: {log}:{line}: u0: 'nan' is not finite", kind="api",
         call="fastslam.read_log(LOG)"),
    Case("api: read_log of a directory", directory, [], 0,
         "RuntimeError: {log}: is a directory, not a log file", kind="api",
         call="fastslam.read_log(LOG)"),
]

# The API rows' script: a filter after one step, its state, the refused call, the state again.
# Exit 0: refused with the state unchanged; 2: the state changed; 3: not refused.
API_SCRIPT = """
import math, sys
import fastslam
BASE, LOG = sys.argv[1], sys.argv[2]
f = fastslam.Filter(fastslam.run_config(BASE, particles=10))
f.predict([3.0, 0.01], 0.025, t=1.0)
f.observe([10.0, 12.0], [0.2, -0.3], ids=[0, 1], t=1.0)
before = f.to_bytes()
try:
    {call}
except Exception as e:
    print(type(e).__name__ + ": " + str(e), file=sys.stderr)
    if f.to_bytes() != before:
        print("the filter's state changed", file=sys.stderr)
        sys.exit(2)
    sys.exit(0)
print("not refused", file=sys.stderr)
sys.exit(3)
"""


# ---- the checks ----

def sha256(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def snapshot(directory, skip=None):
    """{relative path: hash} of every file under `directory`, `skip` left out."""
    hashes = {}
    for root, dirs, files in os.walk(directory):
        if skip is not None:
            dirs[:] = [x for x in dirs if os.path.join(root, x) != skip]
        for name in files:
            path = os.path.join(root, name)
            if os.path.isfile(path):
                hashes[os.path.relpath(path, directory)] = sha256(path)
    return hashes


def check(ok, what):
    if not ok:
        raise AssertionError(what)


def check_whole(out):
    """Every result file present is whole: metrics.json parses, each CSV row ends its line."""
    for name in os.listdir(out):
        check(".tmp-" not in name, "a temporary left behind: " + name)
        path = os.path.join(out, name)
        if name == "metrics.json":
            with open(path) as f:
                json.load(f)
        elif name.endswith((".csv", ".tum")) and os.path.getsize(path) > 0:
            with open(path, "rb") as f:
                check(f.read().endswith(b"\n"), name + " ends inside a line")


def run_signal(case, command, preexec):
    out = command[command.index("--out") + 1]

    def signals():
        # The tool keeps an ignored signal ignored; a test may run where SIGINT is ignored.
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    p = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=signals)
    temp = os.path.join(out, ".trajectory.csv.tmp-%d" % p.pid)
    deadline = time.monotonic() + 30
    while not (os.path.exists(temp) and os.path.getsize(temp) > 0):
        if p.poll() is not None or time.monotonic() > deadline:
            p.kill()
            _, stderr = p.communicate()
            raise AssertionError("the run ended or never wrote before the signal: " + stderr)
        time.sleep(0.02)
    p.send_signal(case.sig)
    try:
        _, stderr = p.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        p.kill()
        p.communicate()
        raise AssertionError("still running 30 s after the signal")
    return p.returncode, stderr


def run_case(case):
    with tempfile.TemporaryDirectory(prefix="fastslam_matrix_") as d:
        case.unmount = None
        try:
            return check_case(case, d)
        finally:
            if case.unmount:
                subprocess.run(["umount", case.unmount], check=True)
            if os.path.isdir(os.path.join(d, "out")):
                os.chmod(os.path.join(d, "out"), 0o755)  # so it can be removed


def check_case(case, d):
    values = {"dir": d, "log": os.path.join(d, "in.log"), "out": os.path.join(d, "out")}
    values.update({k: str(v) for k, v in case.make(d).items()})
    sub = lambda text: text.format(**values) if "{" in text else text
    args = [sub(a) for a in case.args]
    out = args[args.index("--out") + 1] if "--out" in args else values["out"]
    if case.earlier:
        shutil.copytree(EARLIER, out)
    preexec = case.setup(case, d, out) if case.setup else None
    if case.earlier:
        earlier = snapshot(out)
    inputs = snapshot(d, skip=out)

    if case.kind == "api":
        if PYTHON_PATH is None:
            raise Skip("the Python module is not built (no --python-path)")
        env = dict(os.environ, PYTHONPATH=PYTHON_PATH, PYTHONDONTWRITEBYTECODE="1")
        script = API_SCRIPT.replace("{call}", case.call)
        r = subprocess.run([sys.executable, "-c", script, os.path.join(d, "base.log"),
                            values["log"]], capture_output=True, text=True, timeout=60,
                           env=env, cwd=d)
        if "ModuleNotFoundError: No module named 'fastslam" in r.stderr:
            raise Skip("the Python module is not built in " + PYTHON_PATH)
        code, stderr = r.returncode, r.stderr
    elif case.kind == "signal":
        code, stderr = run_signal(case, [FASTSLAM] + args, preexec)
    else:
        r = subprocess.run([FASTSLAM] + args, capture_output=True, text=True, timeout=60,
                           preexec_fn=preexec, errors="replace")
        code, stderr = r.returncode, r.stderr

    check(code == case.code, "exit code %d, expected %d: %s" % (code, case.code, stderr[:500]))
    if case.fragment is not None:
        check(sub(case.fragment) in stderr,
              "stderr lacks %r: %s" % (sub(case.fragment)[:200], stderr[:500]))
    check(len(stderr.encode()) <= case.max_stderr,
          "stderr of %d bytes (at most %d): %s" % (len(stderr.encode()), case.max_stderr,
                                                    stderr[:300]))
    check(snapshot(d, skip=out) == inputs, "an input file changed")
    if case.kind == "api":
        return
    if case.absent == NOTHING:
        # Nor any missing parent the run created on the way (--out a/b/c).
        level = out
        while os.path.dirname(level) != d and level != d and level != "/":
            level = os.path.dirname(level)
        check(not os.path.exists(out), out + " was created")
        check(level == d or not os.path.exists(level), level + " was created")
        return
    if os.path.isdir(out):
        check_whole(out)
    listing = os.listdir(out) if os.path.isdir(out) else []
    for name in case.present:
        check(name in listing, name + " is missing from --out")
    for name in case.absent:
        check(case.earlier == "kept" or name not in listing, name + " is in --out")
    if case.earlier == "kept":
        check(snapshot(out) == earlier, "the earlier run's files changed")
    elif case.earlier == "replaced":
        now = snapshot(out)
        check(now.get("notes.txt") == earlier["notes.txt"], "the user's notes.txt changed")
        for name in RUN_FILES:
            if name in earlier:
                check(now.get(name) != earlier[name], name + " is still the earlier run's")
    if case.status is not None:
        with open(os.path.join(out, "metrics.json")) as f:
            status = json.load(f)["status"]
        check(status.startswith(case.status), "status %r, expected %r" % (status, case.status))


def main():
    global FASTSLAM, PYTHON_PATH, BASE, EARLIER
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("fastslam")
    parser.add_argument("--python-path", help="the directory holding the fastslam package")
    parser.add_argument("-k", help="only the rows whose name holds this")
    a = parser.parse_args()
    FASTSLAM = os.path.abspath(a.fastslam)
    PYTHON_PATH = os.path.abspath(a.python_path) if a.python_path else None
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="fastslam_matrix_base_") as base:
        # The valid log: a 200 m loop of the built-in simulator, every detection with its id.
        log = os.path.join(base, "base.log")
        r = subprocess.run([FASTSLAM, "convert", "--world", "loop", "--loop-length", "200",
                            "--seed", "7", "--out", log], capture_output=True, text=True,
                           timeout=60)
        if r.returncode != 0:
            sys.exit("fastslam convert failed: " + r.stderr)
        with open(log) as f:
            BASE = f.read().split("\n")[:-1]
        # The earlier run: on another world, so every file differs from a new run's; notes.txt
        # is the user's and must survive every row.
        other = os.path.join(base, "other.log")
        r = subprocess.run([FASTSLAM, "convert", "--world", "loop", "--loop-length", "250",
                            "--seed", "8", "--out", other], capture_output=True, text=True,
                           timeout=60)
        if r.returncode != 0:
            sys.exit("fastslam convert failed: " + r.stderr)
        EARLIER = os.path.join(base, "earlier")
        r = subprocess.run([FASTSLAM, "run", "--source", "log", "--data", other, "--seed", "99",
                            "--particles", "7", "--out", EARLIER, "--no-progress", "--no-plot"],
                           capture_output=True, text=True, timeout=60)
        if r.returncode != 0:
            sys.exit("the earlier run failed: " + r.stderr)
        with open(os.path.join(EARLIER, "notes.txt"), "w") as f:
            f.write("the user's notes\n")

        failed = skipped = 0
        rows = [c for c in CASES if a.k is None or a.k in c.name]
        for case in rows:
            original = case.make
            if case.kind == "api":
                # The API rows also read the valid log (the filter's configuration).
                def make(d, original=original):
                    shutil.copy(log, os.path.join(d, "base.log"))
                    return original(d)
                case.make = make
            t = time.monotonic()
            try:
                run_case(case)
                print("ok    %-55s %5.2f s" % (case.name, time.monotonic() - t))
            except Skip as e:
                skipped += 1
                print("skip  %-55s %s" % (case.name, e))
            except Exception as e:  # every row runs, whatever one of them raises
                failed += 1
                print("FAIL  %-55s %s" % (case.name, e))
            finally:
                case.make = original
            sys.stdout.flush()
    print("%d rows: %d passed, %d failed, %d skipped in %.1f s" %
          (len(rows), len(rows) - failed - skipped, failed, skipped, time.monotonic() - start))
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
