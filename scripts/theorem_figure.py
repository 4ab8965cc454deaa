#!/usr/bin/env python3
"""The Theorem 4.10 validation figure from `qpr theorem --csv` (matplotlib).

    build/bin/qpr theorem --csv /tmp/theorem.csv --json /tmp/theorem.json
    python3 scripts/theorem_figure.py /tmp/theorem.csv docs/figures/theorem.png

Left: the true error d_H(X*, X_min) of the engine's answer against the bound
(Eq. 39) per trial with ε > 0 where the theorem applies (ρ < 1), one colour per
family; above the diagonal the bound holds. Right: the histogram of
η = bound / error (4 bins per decade) with η = 1 marked.
"""
import argparse
import csv
import math

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402

from plots import PALETTE  # noqa: E402


def read_trials(path):
    """(family, error, bound) of the trials with ε > 0 where the theorem applies."""
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            error, bound = float(r["error"]), float(r["bound"])
            if float(r["epsilon"]) == 0 or r["status"] != "applies" or not error > 0:
                continue
            if not (bound > 0 and math.isfinite(bound)):
                continue
            rows.append((r["family"], error, bound))
    return rows


def figure(rows, path):
    fig, (scatter, hist) = plt.subplots(1, 2, figsize=(12, 4.8))
    families = sorted({f for f, _, _ in rows})
    for i, family in enumerate(families):
        scatter.loglog([e for f, e, _ in rows if f == family], [b for f, _, b in rows if f == family], ".",
                       color=PALETTE[i % len(PALETTE)], label=family)
    lo = 10 ** math.floor(math.log10(min(min(e, b) for _, e, b in rows)))
    hi = 10 ** math.ceil(math.log10(max(max(e, b) for _, e, b in rows)))
    scatter.loglog([lo, hi], [lo, hi], "-", color="#333", lw=1, label="bound = error")
    scatter.set(xlim=(lo, hi), ylim=(lo, hi), xlabel="true error d_H(X*, X_min)", ylabel="bound (Eq. 39)",
                title="Theorem 4.10: true error vs bound")
    scatter.legend(loc="lower right", fontsize=8)
    eta = sorted(b / e for _, e, b in rows)
    emin, emax = min(0.5, eta[0]), max(10.0, eta[-1])
    b0, b1 = math.floor(math.log10(emin) * 4), math.ceil(math.log10(emax) * 4)
    hist.hist(eta, bins=[10 ** (b / 4) for b in range(b0, b1 + 1)], color=PALETTE[0], label="trials")
    hist.axvline(1.0, color="#e15759", label="η = 1 (bound = error)")
    median = eta[len(eta) // 2] if len(eta) % 2 else (eta[len(eta) // 2 - 1] + eta[len(eta) // 2]) / 2
    hist.set(xscale="log", xlabel="η = bound / error (4 bins per decade)", ylabel="trials",
             title=f"η over {len(eta)} trials: median {median:.3g}, min {eta[0]:.3g}, max {eta[-1]:.3g}")
    hist.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv", help="the CSV of `qpr theorem --csv`")
    parser.add_argument("out", help="the figure (PNG, SVG or PDF by the extension)")
    args = parser.parse_args()
    rows = read_trials(args.csv)
    if not rows:
        raise SystemExit(f"{args.csv}: no trial with ε > 0 where the theorem applies")
    figure(rows, args.out)
    print(f"{args.out}: {len(rows)} trials")


if __name__ == "__main__":
    main()
