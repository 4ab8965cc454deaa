"""Theorem 4.10 on random problems: the reduced answer's error against its bound.

For seeded random problems (qpreduce.generators.theorem_problem: dense PSD/PD
and grid Laplacian families, design spaces C, D and a demand A, q that leaves
them by a relative ε), qpreduce.check_theorem solves the full problem (X_min),
the reduced one (X*) and evaluates every term of the bound (Eq. 39). The bound
must hold: d_H(X*, X_min) ≤ bound whenever the theorem applies (ρ < 1). The
figure shows the error against the bound (above the diagonal: the bound holds)
and the histogram of η = bound / error.

    PYTHONPATH=build/python python3 python/examples/theorem_bound.py [--trials 120] [--out theorem.png]
"""

import argparse

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import qpreduce  # noqa: E402
from qpreduce import generators  # noqa: E402

EPSILONS = [1e-5, 1e-4, 1e-3, 1e-2, 3e-2, 0.1, 0.3]
SIZES = [40, 64, 100]


def run(trials, seed):
    """(family, error, bound) per trial where the theorem applies; the count of violations."""
    families = generators.theorem_families()
    rows, violations = [], 0
    for t in range(trials):
        family = families[t % len(families)]
        size = SIZES[(t // len(families)) % len(SIZES)]
        epsilon = EPSILONS[t % len(EPSILONS)]
        trial = generators.theorem_problem(family, size, epsilon, seed + t)
        check = qpreduce.check_theorem(trial.H, trial.C, trial.D, trial.A, trial.b, trial.q)
        if check.status != qpreduce.TheoremStatus.Applies or not check.practical_error > 0:
            continue
        violations += check.practical_violation() or check.theorem_violation()
        rows.append((family.name, check.practical_error, check.bound.bound))
    return rows, violations


def plot(rows, path):
    fig, (scatter, hist) = plt.subplots(1, 2, figsize=(11, 4.5))
    for name in sorted({r[0] for r in rows}):
        error = [r[1] for r in rows if r[0] == name]
        bound = [r[2] for r in rows if r[0] == name]
        scatter.loglog(error, bound, ".", label=name)
    lo = min(min(r[1], r[2]) for r in rows)
    hi = max(max(r[1], r[2]) for r in rows)
    scatter.loglog([lo, hi], [lo, hi], "k-", lw=1, label="bound = error")
    scatter.set(xlabel="true error d_H(X*, X_min)", ylabel="bound (Eq. 39)", title="Theorem 4.10: error vs bound")
    scatter.legend(fontsize=8, loc="lower right")
    eta = np.array([r[2] / r[1] for r in rows])
    bins = np.logspace(np.floor(np.log10(min(0.5, eta.min())) * 4) / 4, np.ceil(np.log10(max(10, eta.max())) * 4) / 4,
                       int(4 * np.log10(max(10, eta.max()) / min(0.5, eta.min()))) + 2)
    hist.hist(eta, bins=bins)
    hist.axvline(1.0, color="#e15759", label="η = 1 (bound = error)")
    hist.set(xscale="log", xlabel="η = bound / error", ylabel="trials",
             title=f"η: median {np.median(eta):.3g}, min {eta.min():.3g} ({len(eta)} trials)")
    hist.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=120)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", default="theorem.png", help="the figure (PNG, SVG or PDF by the extension)")
    args = parser.parse_args(argv)
    rows, violations = run(args.trials, args.seed)
    plot(rows, args.out)
    eta = [r[2] / r[1] for r in rows]
    print(f"{len(rows)} of {args.trials} trials where the theorem applies; violations: {violations}; "
          f"η min {min(eta):.3g}, median {np.median(eta):.3g}; figure: {args.out}")
    return rows, violations


if __name__ == "__main__":
    main()
