"""matplotlib figures of the studies (scripts/quality_study.py, scripts/theorem_figure.py).

line_plot() draws the quality study's sweeps: one panel per measured quantity,
one line per scenario, a dashed target line per panel, the legend below.
"""
import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib import ticker  # noqa: E402

PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#17becf"]


def line_plot(path, title, xlabel, panels, series_names, logx=False, hlines=None, styles=None):
    """Writes `path` (PNG, SVG or PDF by its extension).

    panels: list of (ylabel, {series name: [(x, y), …]}, logy) with logy True,
            False or "auto" (log when all values are positive and span more
            than a factor 20);
    series_names: the series in legend order (missing ones are skipped);
    hlines: {panel index: y} dashed target lines;
    styles: {series name: (colour, dashed)}; otherwise PALETTE in order, solid.
    """
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels) if len(panels) > 1 else 8.5, 4.2),
                             squeeze=False)
    for pi, (ylabel, data, logy) in enumerate(panels):
        ax = axes[0][pi]
        ys = [y for pts in data.values() for _, y in pts]
        if logy == "auto":
            logy = bool(ys) and min(ys) > 0 and max(ys) / min(ys) > 20
        for si, name in enumerate(series_names):
            pts = data.get(name)
            if not pts:
                continue
            colour, dashed = (styles or {}).get(name, (PALETTE[si % len(PALETTE)], False))
            ax.plot([x for x, _ in pts], [y for _, y in pts], "o-" if not dashed else "o--", color=colour,
                    label=name if pi == 0 else None, lw=1.8, ms=4)
        if hlines and hlines.get(pi) is not None:
            ax.axhline(hlines[pi], color="black", ls=(0, (5, 4)), lw=1)
            ax.annotate("target", (1.0, hlines[pi]), xycoords=("axes fraction", "data"), ha="right", va="bottom",
                        fontsize=8)
        ax.set(xlabel=xlabel, ylabel=ylabel, xscale="log" if logx else "linear", yscale="log" if logy else "linear")
        ax.set_xticks(sorted({x for pts in data.values() for x, _ in pts}))  # the measured settings
        ax.xaxis.set_major_formatter(ticker.FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(ticker.NullFormatter())
        ax.grid(True, color="#e5e5e5")
    fig.suptitle(title, fontweight="bold")
    fig.legend(loc="lower center", ncol=3 if len(panels) > 1 else 2, fontsize=8, frameon=False)
    rows = (len([n for n in series_names if any(n in d for _, d, _ in panels)]) + 2) // 3
    fig.tight_layout(rect=(0, min(0.45, 0.06 * rows + 0.02), 1, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
