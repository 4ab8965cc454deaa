#!/usr/bin/env python3
"""Rounds per frame: how far the last frame of a `.sel/.def` scenario is from
converged classic ARAP with the paper's 8 rounds a frame, with rounds to the
tolerance and no budget, and with the defaults (tolerance and time budget).

For each model, `qpr deform MESH --sel --def --frames 8` runs once per
setting (one cache per model) and once with `--refine=1e-9` for the
converged shape; the table gives the RMS vertex distance of each setting's
last pose from it over the bounding-box diagonal, the rounds of each frame and
what ended them (docs/deform.md, "Rounds per frame").

    build/bin/qpreduce-python scripts/rounds_study.py [--models cylinder,cactus,bar,bumpy_plane]
        [--qpr build/bin/qpr] [--data ../shared/data] [--work /tmp/qpreduce-rounds] [--threads 1]
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SETTINGS = [  # name, extra arguments
    ("8 rounds a frame", ["--iterations", "8", "--tolerance", "0", "--time-budget-ms", "0"]),
    ("to 1e-6, no budget", ["--iterations", "1000", "--tolerance", "1e-6", "--time-budget-ms", "0"]),
    ("defaults", []),
]


def read_off(path):
    words = open(path).read().split()
    if words[0] != "OFF":
        sys.exit("%s: not an OFF file" % path)
    n = int(words[1])
    return np.array(words[4:4 + 3 * n], float).reshape(n, 3)


def run(cmd, threads):
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        sys.exit("failed (%d): %s\n%s%s" % (p.returncode, " ".join(cmd), p.stdout, p.stderr))


def suite_arguments(description, work, threads):
    """The options the suite studies share (--models, --qpr, --data, --work, --threads)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--models", default="cylinder,cactus,bar,bumpy_plane")
    ap.add_argument("--qpr", default=os.path.join(ROOT, "build", "bin", "qpr"))
    ap.add_argument("--data", default=os.path.join(os.path.dirname(ROOT), "shared", "data"))
    ap.add_argument("--work", default=work)
    ap.add_argument("--threads", type=int, default=threads)
    return ap


def main():
    a = suite_arguments(__doc__.split("\n\n")[0], "/tmp/qpreduce-rounds", 1).parse_args()
    os.makedirs(a.work, exist_ok=True)
    folder = os.path.join(a.data, "meshes", "botsch-sorkine")
    print("| model | " + " | ".join(name for name, _ in SETTINGS) + " | rounds per frame (defaults) |")
    print("|---" * (len(SETTINGS) + 2) + "|")
    for model in a.models.split(","):
        mesh = os.path.join(folder, model + ".off")
        if not os.path.exists(mesh):
            sys.exit("%s: no such model (the shared data's botsch-sorkine folder)" % mesh)
        base = [a.qpr, "deform", mesh, "--sel", os.path.join(folder, model + ".sel"), "--def",
                os.path.join(folder, model + ".def"), "--frames", "8", "--cache", os.path.join(a.work, model + ".cache")]
        converged = os.path.join(a.work, model + "_converged.off")
        run(base + ["--refine=1e-9", "--out", converged], a.threads)
        rest = read_off(mesh)
        diagonal = np.linalg.norm(rest.max(0) - rest.min(0))
        target = read_off(converged)
        cells, rounds = [], ""
        for i, (name, extra) in enumerate(SETTINGS):
            pose, report = (os.path.join(a.work, "%s_%d.%s" % (model, i, ext)) for ext in ("off", "json"))
            run(base + extra + ["--out", pose, "--report", report], a.threads)
            rms = np.sqrt(((read_off(pose) - target) ** 2).sum(1).mean()) / diagonal
            cells.append("%.2f %%" % (100 * rms))
            r = json.load(open(report))
            rounds = ", ".join("%d%s" % (n, "" if s == "tolerance" else " (%s)" % s)
                               for n, s in zip(r["rounds_per_frame"], r["stop_per_frame"]))
        print("| %s | %s | %s |" % (model, " | ".join(cells), rounds))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
