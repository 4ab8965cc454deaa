#!/usr/bin/env python3
"""Seeded procedural bumpy surface for the scaling benchmark (docs/scaling.md).

    bumpy_grid.py --side S [--seed K] [--bumps B] --out PREFIX

Writes PREFIX.off (an S × S vertex grid over [0, 1]², two triangles a cell,
heights a sum of B Gaussian bumps drawn from the seed), PREFIX.sel
(Botsch–Sorkine per-vertex status: 0 fixed for x < 0.1, 2 handle for
x > 0.9, 1 free elsewhere) and PREFIX.def (the handle lifted by 0.25 and
shifted by −0.1 in x), i.e. the Bumpy Plane's layout at any size:
S = 201 is the Bumpy Plane's 40,401 vertices, S = 1000 is 10⁶.
Deterministic in (side, seed, bumps); pure Python, no NumPy needed.
"""
import argparse
import math
import random


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--side", type=int, required=True, help="vertices per grid side (≥ 3)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--bumps", type=int, default=60, help="Gaussian bumps summed into the heights")
    ap.add_argument("--out", required=True, help="output prefix: PREFIX.off, PREFIX.sel, PREFIX.def")
    a = ap.parse_args()
    if a.side < 3:
        ap.error(f"--side: expected at least 3, got {a.side}")
    if a.bumps < 0:
        ap.error(f"--bumps: expected at least 0, got {a.bumps}")
    rng = random.Random(a.seed)
    bumps = [(rng.random(), rng.random(), rng.uniform(-0.04, 0.04), rng.uniform(0.02, 0.08)) for _ in range(a.bumps)]
    S = a.side
    h = 1.0 / (S - 1)
    with open(a.out + ".off", "w") as off, open(a.out + ".sel", "w") as sel:
        off.write(f"OFF\n{S * S} {2 * (S - 1) * (S - 1)} 0\n")
        sel.write(f"# per vertex status: 0=fixed, 1=deformable-region, 2=handle\n# {S * S} vertices\n")
        for j in range(S):
            y = j * h
            for i in range(S):
                x = i * h
                z = sum(amp * math.exp(-((x - bx) ** 2 + (y - by) ** 2) / (2 * r * r)) for bx, by, amp, r in bumps)
                off.write(f"{x:.9f} {y:.9f} {z:.9f}\n")
                sel.write("0\n" if x < 0.1 else "2\n" if x > 0.9 else "1\n")
        for j in range(S - 1):
            for i in range(S - 1):
                v = j * S + i
                off.write(f"3 {v} {v + 1} {v + S + 1}\n3 {v} {v + S + 1} {v + S}\n")
    with open(a.out + ".def", "w") as d:
        d.write("# 4x4 handle transformation matrix\n"
                "1.000000 0.000000 0.000000 -0.100000\n"
                "0.000000 1.000000 0.000000 0.000000\n"
                "0.000000 0.000000 1.000000 0.250000\n"
                "0.000000 0.000000 0.000000 1.000000\n")


if __name__ == "__main__":
    main()
