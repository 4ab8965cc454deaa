#!/usr/bin/env python3
"""Rounds of the reduced alternation to a relative fixed-point residual, plain
against Anderson-accelerated (issue: converged quality), on the
Botsch–Sorkine .sel/.def suite in ../shared/data.

    python3 scripts/convergence_study.py [--qpr build/bin/qpr] [--tolerance 1e-6]
        [--windows 0,2,3,5,8] [--models cactus,cylinder,bar,bumpy_plane] [--out F.md]

For each model and window it runs `qpr deform MESH --sel --def --frames 1
--iterations CAP --tolerance TOL --anderson W` and reads the JSON report:
rounds to the tolerance (CAP when not reached), the residual reached, the
median cost of a round, and the classic ARAP energy of the pose. A second
pass at a fixed round count (no tolerance) measures the cost of a round for
each window in one run, windows alternated. Prints a Markdown table.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile


def run(qpr, mesh, sel, deff, iterations, tolerance, window, work):
    rep = os.path.join(work, "r.json")
    cache = os.path.join(work, os.path.basename(mesh) + ".cache")  # one precompute per model
    cmd = [qpr, "deform", mesh, "--sel", sel, "--def", deff, "--frames", "1", "--iterations", str(iterations),
           "--tolerance", str(tolerance), "--anderson", str(window), "--report", rep, "--cache", cache]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(rep) as f:
        return json.load(f)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    here = os.path.dirname(os.path.abspath(__file__))
    ap.add_argument("--qpr", default=os.path.normpath(os.path.join(here, "..", "build", "bin", "qpr")))
    ap.add_argument("--data", default=os.path.normpath(os.path.join(here, "..", "..", "shared", "data")))
    ap.add_argument("--tolerance", type=float, default=1e-6)
    ap.add_argument("--cap", type=int, default=20000)
    ap.add_argument("--windows", default="0,2,3,5,8")
    ap.add_argument("--models", default="cactus,cylinder,bar,bumpy_plane")
    ap.add_argument("--cost-rounds", type=int, default=200, help="rounds of the cost pass")
    ap.add_argument("--repeats", type=int, default=5, help="alternated repeats of the cost pass")
    ap.add_argument("--out", default="")
    a = ap.parse_args()
    bs = os.path.join(a.data, "meshes", "botsch-sorkine")
    if not os.path.isdir(bs):
        sys.exit("convergence_study: %s is absent (the shared data); nothing to measure" % bs)
    windows = [int(w) for w in a.windows.split(",")]
    rows = []
    with tempfile.TemporaryDirectory() as work:
        for model in a.models.split(","):
            base = os.path.join(bs, model)
            args = (a.qpr, base + ".off", base + ".sel", base + ".def")
            conv = {w: run(*args, a.cap, a.tolerance, w, work) for w in windows}
            cost = {w: [] for w in windows}
            for _ in range(a.repeats):
                for w in windows:
                    cost[w].append(run(*args, a.cost_rounds, 0.0, w, work)["iteration_us"])
            for w in windows:
                r = conv[w]
                rows.append((model, w, r["rounds"], r["fixed_point_residual"], statistics.median(cost[w]),
                             r["arap_energy"], r.get("rejected_steps", 0)))
    lines = ["| model | window | rounds to %.0e | residual reached | µs per round (median) | round cost vs plain "
             "| ARAP energy | rejected |" % a.tolerance, "|---|---|---|---|---|---|---|---|"]
    plain_cost = {m: c for (m, w, _, _, c, _, _) in rows if w == 0}
    plain_rounds = {m: n for (m, w, n, _, _, _, _) in rows if w == 0}
    for (m, w, n, res, c, e, rej) in rows:
        capped = " (cap)" if n >= a.cap else ""
        lines.append("| %s | %s | %d%s | %.2e | %.2f | %.2f | %.6g | %d |" % (
            m, "plain" if w == 0 else w, n, capped, res, c, c / plain_cost[m], e, rej))
    speed = {}
    for w in windows:
        if w == 0:
            continue
        speed[w] = statistics.median(plain_rounds[m] / n for (m, ww, n, _, _, _, _) in rows if ww == w)
    lines.append("")
    lines.append("Median over the models of plain rounds / accelerated rounds: " +
                 ", ".join("window %d: %.1f×" % (w, s) for w, s in speed.items()))
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        with open(a.out, "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()
