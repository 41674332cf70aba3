#!/usr/bin/python3
"""tools/scripts/plot_run.py on generated run directories: a small map (one panel) and a large one (a
second panel zoomed on ~150 landmarks on the path) both give a valid PNG; the zoom window holds
about the requested number of landmarks and is centred on the true path. With the fastslam
binary as argument, `fastslam run --plot png` draws map.png with it (and no map.svg), as the
FASTSLAM_PLOT_SCRIPT it names. Exits 77 (skipped) without matplotlib.

Usage: plot_run_test.py [FASTSLAM_BINARY]"""
import importlib.util
import json
import os
import random
import subprocess
import sys
import tempfile

try:
    import matplotlib  # noqa: F401
except ImportError:
    print("matplotlib not installed: skipped")
    sys.exit(77)

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..")
SCRIPT = os.path.join(ROOT, "tools", "scripts", "plot_run.py")


def write_run(out, side, spacing):
    """A lawnmower over side x side landmarks, one per spacing x spacing cell, with an estimate
    offset by 0.5 m."""
    os.makedirs(out)
    rng = random.Random(1)
    true_lm = [(i, (i % side + rng.random()) * spacing, (i // side + rng.random()) * spacing)
               for i in range(side * side)]
    with open(os.path.join(out, "true_landmarks.csv"), "w") as f:
        f.write("id,x,y\n")
        f.writelines("{},{},{}\n".format(*r) for r in true_lm)
    with open(os.path.join(out, "landmarks.csv"), "w") as f:
        f.write("id,x,y,sxx,sxy,syy\n")
        f.writelines("{},{},{},0.01,0.002,0.02\n".format(i, x + 0.5, y) for i, x, y in true_lm)
    poses = []
    t = 0.0
    for lane in range(side // 4 + 1):
        y = (lane * 4 + 0.5) * spacing
        xs = [k * 0.5 for k in range(int(side * spacing / 0.5))]
        for x in (xs if lane % 2 == 0 else xs[::-1]):
            t += 0.1
            poses.append((t, x, y, 0.0))
    for name, dx in (("truth.csv", 0.0), ("trajectory.csv", 0.5)):
        with open(os.path.join(out, name), "w") as f:
            f.write("t,x,y,theta\n")
            f.writelines("{},{},{},{}\n".format(p[0], p[1] + dx, p[2], p[3]) for p in poses)
    with open(os.path.join(out, "metrics.json"), "w") as f:
        json.dump({"algorithm": "fastslam1", "particles": 100, "association": "known", "seed": 1,
                   "pose_rmse_m": 0.5, "landmark_rmse_m": 0.5, "true_landmarks": len(true_lm),
                   "steps": len(poses)}, f)


def load_module():
    spec = importlib.util.spec_from_file_location("plot_run", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def check_run_plot_png(fastslam, tmp):
    """`fastslam run --plot png` runs the script (the default one, then $FASTSLAM_PLOT_SCRIPT)
    and draws no map.svg."""
    small = [fastslam, "run", "--world", "grid", "--landmarks", "100", "--max-steps", "20",
             "--no-progress", "--plot", "png"]
    out = os.path.join(tmp, "run_png")
    r = subprocess.run(small + ["--out", out], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "wrote " + os.path.join(out, "map.png") in r.stdout, r.stdout
    with open(os.path.join(out, "map.png"), "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    assert not os.path.exists(os.path.join(out, "map.svg"))
    with open(os.path.join(out, "metrics.json")) as f:
        assert json.load(f)["options"]["plot"] == "png"
    marker = os.path.join(tmp, "script_ran")
    script = os.path.join(tmp, "my_plot.py")
    with open(script, "w") as f:
        f.write("import sys\nopen(%r, 'w').write(sys.argv[1])\n" % marker)
    r = subprocess.run(small + ["--out", out], capture_output=True, text=True,
                       env=dict(os.environ, FASTSLAM_PLOT_SCRIPT=script))
    assert r.returncode == 0, r.stderr
    with open(marker) as f:
        assert f.read() == out
    assert not os.path.exists(os.path.join(out, "map.png"))  # the earlier run's, removed


def main():
    plot_run = load_module()
    with tempfile.TemporaryDirectory() as tmp:
        for name, side in (("small", 20), ("large", 60)):  # 400 and 3600 landmarks
            out = os.path.join(tmp, name)
            write_run(out, side, 3.0)
            r = subprocess.run([sys.executable, SCRIPT, out], capture_output=True, text=True)
            assert r.returncode == 0, r.stderr
            path = os.path.join(out, "map.png")
            with open(path, "rb") as f:
                head = f.read(24)
            assert head[:8] == b"\x89PNG\r\n\x1a\n", f"{name}: map.png is not a PNG"
            width = int.from_bytes(head[16:20], "big")
            height = int.from_bytes(head[20:24], "big")
            # One panel is about square; the zoom panel doubles the width.
            if name == "small":
                assert width < 1.3 * height, (width, height)
            else:
                assert width > 1.6 * height, (width, height)
        out = os.path.join(tmp, "large")
        true_lm = plot_run.read(os.path.join(out, "true_landmarks.csv"))
        truth = plot_run.read(os.path.join(out, "truth.csv"))
        x0, x1, y0, y1 = plot_run.zoom_box(true_lm, truth)
        inside = sum(1 for r in true_lm if x0 <= r["x"] <= x1 and y0 <= r["y"] <= y1)
        assert 100 <= inside <= 200, inside
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        assert any(abs(r["x"] - cx) < 1e-9 and abs(r["y"] - cy) < 1e-9 for r in truth)
        assert abs(cx - 90) < 10 and abs(cy - 90) < 10, (cx, cy)  # near the map's middle
        if len(sys.argv) > 1:
            check_run_plot_png(sys.argv[1], tmp)
    print("plot_run: ok")


if __name__ == "__main__":
    main()
