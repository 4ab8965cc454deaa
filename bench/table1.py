#!/usr/bin/env python3
"""The paper's Table 1 from bench_deform's JSON output, beside the paper's numbers.

Usage: bench/table1.py RESULT.json [RECON.json] [--chart FIGURE.png]

RESULT.json comes from
    build/bin/bench_deform --benchmark_out=RESULT.json --benchmark_out_format=json
Prints a Markdown table: per model our median iteration (µs), reconstruction
(ms), streaming read of the same bytes (ms) and their ratio, frame (ms),
precompute (s: the median over Precompute's repetitions, each a fresh
precompute) and peak resident memory (GB: of the first repetition), OP (ms), and in parentheses the
paper's figure for the same column (Table 1, i7-2670QM, serial). The read and
the ratio come from ReconstructionVsRead (the two sampled alternately, each
after a frame's rounds; ratio of the medians) when the run has it, otherwise
from Reconstruction and StreamRead (a back-to-back read: older runs). Then a table of the reconstruction against the stricter
floors (an AVX2 streaming read; the reconstruction and the plain read each
back to back), and the issue-3 targets, each marked met / missed.
With RECON.json (a second run, e.g.
--benchmark_filter='^(Reconstruction|StreamRead)'), the reconstruction and
streaming-read figures come from it (ReconstructionVsRead included).
With --chart, a matplotlib figure of the same measurements beside the
paper's (iteration, frame, precompute, OP; log scale) is written too.
"""
import json
import sys

# Paper Table 1: iteration µs, Df. ms, total ms, precompute s, GB, OP ms.
PAPER = {
    "Cylinder": (50, 1.4, 2, 14, 0.3, 14),
    "Cactus": (90, 2, 3, 18, 0.4, 16),
    "Bar": (93, 3.8, 4.8, 36, 0.5, 20),
    "BumpyPlane": (85, 14, 15, 200, 2.7, 38),
    "SolidCylinder": (110, 4, 5, 90, 0.8, 22),
    "Tree": (137, 3.5, 5, 34, 0.4, 10),
    "Fertility": (78, 5.2, 6, 148, 2.4, 28),
    "Dinosaur": (108, 12, 14, 115, 1.7, 24),
    "Dragon": (55, 14, 15, 198, 2.7, 64),
}


def chart(path, measured):
    """Grouped bars, ours against the paper's, one panel per Table 1 column.
    measured: [(model, iteration µs, frame ms, precompute s, OP ms)]."""
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt

    columns = [("iteration (µs)", 1, 0), ("frame (ms)", 2, 2), ("precompute (s)", 3, 3), ("OP (ms)", 4, 5)]
    models = [m[0] for m in measured]
    fig, axes = plt.subplots(1, len(columns), figsize=(4.2 * len(columns), 4.2))
    for ax, (title, ours, theirs) in zip(axes, columns):
        x = range(len(models))
        ax.bar([i - 0.2 for i in x], [m[ours] for m in measured], 0.4, label="qpreduce (this machine)")
        ax.bar([i + 0.2 for i in x], [PAPER[m[0]][theirs] for m in measured], 0.4, label="paper (i7-2670QM)")
        ax.set_xticks(list(x))
        ax.set_xticklabels(models, rotation=45, ha="right", fontsize=8)
        lowest = min(min(m[ours] for m in measured), min(PAPER[m[0]][theirs] for m in measured))
        ax.set(yscale="log", title=title, ylim=(lowest / 3, None))  # every bar visibly above the axis
    axes[0].legend(fontsize=8)
    fig.suptitle("Table 1: reduced ARAP deformer, ours against the paper's", fontweight="bold")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(path, recon_path=None, chart_path=None):
    runs = json.load(open(path))["benchmarks"]
    if recon_path:
        runs = [r for r in runs if not r["name"].startswith(("Reconstruction", "StreamRead"))]
        runs += json.load(open(recon_path))["benchmarks"]
    rows = {}
    for r in runs:
        if r.get("run_type") == "aggregate" or r.get("error_occurred"):
            continue
        kind, model = r["name"].split("/")[:2]
        row = rows.setdefault(model, {})
        row[kind] = r
        row.setdefault(kind + "_runs", []).append(r)
    print("| model | vertices | linear / rot. | iteration µs | reconstruction ms | stream read ms | recon ÷ read "
          "| frame ms | precompute s | peak GB | OP ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    targets, measured = [], []
    for model, paper in PAPER.items():
        row = rows.get(model)
        if not row or "Precompute" not in row:
            continue
        pre = row["Precompute"]
        med = lambda k: row[k]["median"] if k in row else float("nan")
        it, rec, rd, fr, op = med("Iteration"), med("Reconstruction"), med("StreamRead"), med("Frame"), med("OP")
        ratio = rec / rd
        if "ReconstructionVsRead" in row:
            pair = row["ReconstructionVsRead"]
            rd, ratio = pair["read_ms"], pair["ratio"]
        pre_runs = sorted(run["real_time"] for run in row["Precompute_runs"])  # unit: s
        pre_s = pre_runs[len(pre_runs) // 2]
        pre_note = ", ".join(f"{x:.2f}" for x in pre_runs)
        peak_gb = row["Precompute_runs"][0]["peak_MiB"] / 1024.0  # the first: no heap left over from a repetition
        print(f"| {model} | {int(pre['vertices']):,} | {int(pre['linear'])} / {int(pre['rotational'])} "
              f"| {it:.1f} ({paper[0]}) | {rec:.2f} ({paper[1]}) | {rd:.2f} | {ratio:.2f} "
              f"| {fr:.2f} ({paper[2]}) | {pre_s:.1f} ({paper[3]}) | {peak_gb:.2f} ({paper[4]}) "
              f"| {op:.2f} ({paper[5]}) |")
        measured.append((model, it, fr, pre_s, op))
        targets.append((f"{model}: OP ≤ 1 ms", op, op <= 1))
        targets.append((f"{model}: reconstruction ≤ 1.3 × streaming read", ratio, ratio <= 1.3))
        if model == "BumpyPlane":
            targets.append(("BumpyPlane: one iteration ≤ 15 µs", it, it <= 15))
            targets.append((f"BumpyPlane: precompute ≤ 10 s (median of {pre_note})", pre_s, pre_s <= 10))
            targets.append(("BumpyPlane: peak ≤ 1 GB", peak_gb, peak_gb <= 1))
        if model == "Dragon":
            targets.append((f"Dragon: precompute ≤ 15 s (median of {pre_note})", pre_s, pre_s <= 15))
    print()
    print("| model | recon. ms | plain read ms | AVX2 read ms | recon ÷ AVX2 read "
          "| recon. back to back ms | plain read back to back ms | ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for model in PAPER:
        row = rows.get(model)
        if not row or "ReconstructionVsRead" not in row:
            continue
        pair = row["ReconstructionVsRead"]
        med = lambda k: row[k]["median"] if k in row else float("nan")
        rec_b, read_b = med("ReconstructionBackToBack"), med("StreamRead")
        print(f"| {model} | {pair['recon_ms']:.3f} | {pair['read_ms']:.3f} | {pair['read_avx2_ms']:.3f} "
              f"| {pair['ratio_avx2']:.2f} | {rec_b:.3f} | {read_b:.3f} | {rec_b / read_b:.2f} |")
    print()
    print("| target | measured | |")
    print("|---|---|---|")
    for name, value, ok in targets:
        print(f"| {name} | {value:.3g} | {'met' if ok else '**missed**'} |")
    if chart_path and measured:
        chart(chart_path, measured)


if __name__ == "__main__":
    args = sys.argv[1:]
    chart_path = None
    if "--chart" in args:
        i = args.index("--chart")
        if i + 1 >= len(args):
            sys.exit(__doc__)
        chart_path = args[i + 1]
        del args[i : i + 2]
    if len(args) not in (1, 2):
        sys.exit(__doc__)
    main(*args, chart_path=chart_path)
