#!/usr/bin/env python3
"""The refine's default stop against a tightly converged refine, on the
Botsch–Sorkine suite and the shared references (docs/quality.md, "The
refine's default stop").

    refine_stop_study.py [--qpr build/bin/qpr] [--data ../shared/data] [--work DIR] [--models a,b,…]

For every model: `qpr deform --frames 8 --refine` (the default stop) and
`--refine=0` (no distance test: to the reference test, step 1e-10 of the
diagonal and energy change 1e-13), both from the same settled reduced pose;
prints the rounds and seconds of each (and the default's Newton steps and
their CG products), the default's estimated distance and
its RMS and largest distance to the tight shape, over the bounding-box
diagonal, as a Markdown table.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

MODELS = {
    "cylinder": ("meshes/botsch-sorkine/cylinder.off", "meshes/botsch-sorkine/cylinder"),
    "cactus": ("meshes/botsch-sorkine/cactus.off", "meshes/botsch-sorkine/cactus"),
    "bar": ("meshes/botsch-sorkine/bar.off", "meshes/botsch-sorkine/bar"),
    "bumpy_plane": ("meshes/botsch-sorkine/bumpy_plane.off", "meshes/botsch-sorkine/bumpy_plane"),
    "solid_cylinder": ("tets/solid_cylinder.node", "meshes/botsch-sorkine/cylinder"),
    "armadillo": ("meshes/armadillo.obj", "references/armadillo"),
}


def vertices(path):
    lines = [l for l in open(path) if l.strip() and not l.startswith("#")]
    if lines[0].startswith("OFF"):
        n = int(lines[1].split()[0])
        return [tuple(map(float, l.split()[:3])) for l in lines[2:2 + n]]
    return [tuple(map(float, l.split()[1:4])) for l in lines if l.startswith("v ")]


def run(qpr, data, work, name, refine):
    mesh, scenario = MODELS[name]
    out = os.path.join(work, f"{name}_{refine or 'default'}.off")
    report = os.path.join(work, f"{name}_{refine or 'default'}.json")
    args = [qpr, "deform", os.path.join(data, mesh), "--sel", os.path.join(data, scenario + ".sel"), "--def",
            os.path.join(data, scenario + ".def"), "--frames", "8", "--refine" + (f"={refine}" if refine else ""),
            "--out", out, "--report", report]
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, env=dict(os.environ, OMP_NUM_THREADS="2"))
    return vertices(out), json.load(open(report))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qpr", default="build/bin/qpr")
    ap.add_argument("--data", default=os.environ.get("QPREDUCE_SHARED_DATA", "../shared/data"))
    ap.add_argument("--work", default=None)
    ap.add_argument("--models", default=",".join(MODELS))
    a = ap.parse_args()
    work = a.work or tempfile.mkdtemp(prefix="refine_stop_")
    os.makedirs(work, exist_ok=True)
    print("| model | default: rounds | Newton steps / CG products | s | estimated | tight: rounds | s | RMS default→tight | max |")
    print("|---|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for name in a.models.split(","):
        V, r = run(a.qpr, a.data, work, name, None)
        T, t = run(a.qpr, a.data, work, name, "0")
        diag = r["bounding_box_diagonal"]
        d = [math.dist(u, v) / diag for u, v in zip(V, T)]
        rms = math.sqrt(sum(x * x for x in d) / len(d))
        worst = max(worst, rms)
        rd, rt = r["refine"], t["refine"]
        est = rd["estimated_distance"]
        print(f"| {name} | {rd['rounds']} | {rd.get('newton_steps', 0)} / {rd.get('cg_iterations', 0)} | "
              f"{rd['seconds']:.2f} | {est if est is None else f'{est:.1e}'} | "
              f"{rt['rounds']}{'' if rt['converged'] else ' (limit)'} | {rt['seconds']:.2f} | {100 * rms:.4f} % | "
              f"{100 * max(d):.4f} % |")
        sys.stdout.flush()
    print(f"\nlargest RMS from the tight shape: {100 * worst:.4f} % of the diagonal (work: {work})")


if __name__ == "__main__":
    main()
