"""A small SVG line-plot writer (standard library only) for the quality study's
figures (scripts/quality_study.py)."""
import math


PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#17becf"]


def nice_ticks(lo, hi, log):
    """Axis ticks: 1-2-5 steps on a linear axis (from 0 when all values are ≥ 0), decades on a log axis."""
    if log:
        k0, k1 = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
        mult = [1, 2, 5] if k1 - k0 <= 2 else [1]
        t = [m * 10 ** k for k in range(k0, k1 + 1) for m in mult]
        inside = [v for v in t if lo <= v <= hi]
        below = [v for v in t if v < lo]
        above = [v for v in t if v > hi]
        return (below[-1:] + inside + above[:1]) or [lo, hi]
    lo = min(0.0, lo)
    span = hi - lo if hi > lo else 1.0
    raw = span / 5
    e = 10 ** math.floor(math.log10(raw))
    step = next(m * e for m in (1, 2, 5, 10) if m * e >= raw)
    t, v = [], math.floor(lo / step) * step
    while v < hi + step * 0.999:
        t.append(round(v, 12))
        v += step
    return t


def svg_plot(path, title, xlabel, panels, series_names, logx=False, hlines=None, styles=None):
    """panels: list of (ylabel, {series: [(x, y), …]}, logy). Hand-written SVG line plots."""
    W, H = (440, 300) if len(panels) > 1 else (720, 340)
    ml, mr, mt, mb = 76, 14, 34, 46
    cols = 3 if len(panels) > 1 else 2
    legend_h = 18 * ((len(series_names) + cols - 1) // cols) + 8
    total_w, total_h = W * len(panels), H + legend_h
    out = ['<svg xmlns="http://www.w3.org/2000/svg" width="%d" height="%d" viewBox="0 0 %d %d" '
           'font-family="DejaVu Sans, Arial, sans-serif" font-size="12">' % (total_w, total_h, total_w, total_h),
           '<rect width="100%" height="100%" fill="white"/>']
    for pi, (ylabel, data, logy) in enumerate(panels):
        ox = pi * W
        xs = [x for s in data.values() for x, _ in s]
        ys = [y for s in data.values() for _, y in s]
        if hlines and hlines.get(pi) is not None:
            ys.append(hlines[pi])
        if not xs:
            continue
        fx = (lambda x: math.log10(x)) if logx else (lambda x: x)
        x0, x1 = fx(min(xs)), fx(max(xs))
        if x1 == x0:
            x1 += 1
        lo, hi = min(ys), max(ys)
        if logy == "auto":
            logy = lo > 0 and hi / lo > 20
        fy = (lambda y: math.log10(y)) if logy else (lambda y: y)
        yticks = nice_ticks(lo, hi, logy)
        y0, y1 = fy(min(yticks[0], lo)), fy(max(yticks[-1], hi))
        if y1 == y0:
            y1 += 1

        def px(x):
            return ox + ml + (fx(x) - x0) / (x1 - x0) * (W - ml - mr)

        def py(y):
            return mt + (1 - (fy(y) - y0) / (y1 - y0)) * (H - mt - mb)

        out.append('<rect x="%d" y="%d" width="%d" height="%d" fill="none" stroke="#444"/>'
                   % (ox + ml, mt, W - ml - mr, H - mt - mb))
        for x in sorted(set(xs)):
            out.append('<line x1="%.1f" y1="%d" x2="%.1f" y2="%d" stroke="#ddd"/>' % (px(x), mt, px(x), H - mb))
            out.append('<text x="%.1f" y="%d" text-anchor="middle">%s</text>' % (px(x), H - mb + 15, "%g" % x))
        for y in yticks:
            out.append('<line x1="%d" y1="%.1f" x2="%d" y2="%.1f" stroke="#eee"/>' % (ox + ml, py(y), ox + W - mr, py(y)))
            out.append('<text x="%d" y="%.1f" text-anchor="end">%s</text>' % (ox + ml - 4, py(y) + 4, "%g" % y))
        if hlines and hlines.get(pi) is not None:
            yv = hlines[pi]
            out.append('<line x1="%d" y1="%.1f" x2="%d" y2="%.1f" stroke="#000" stroke-dasharray="5,4"/>'
                       % (ox + ml, py(yv), ox + W - mr, py(yv)))
            out.append('<text x="%d" y="%.1f" text-anchor="end" font-size="10">target</text>'
                       % (ox + W - mr - 3, py(yv) - 3))
        out.append('<text x="%.1f" y="%d" text-anchor="middle">%s</text>' % (ox + ml + (W - ml - mr) / 2, H - 8, xlabel))
        out.append('<text transform="translate(%d,%.1f) rotate(-90)" text-anchor="middle">%s</text>'
                   % (ox + 13, mt + (H - mt - mb) / 2, ylabel))
        out.append('<text x="%.1f" y="20" text-anchor="middle" font-weight="bold">%s</text>'
                   % (ox + ml + (W - ml - mr) / 2, title if pi == 0 or len(panels) == 1 else ""))
        for si, name in enumerate(series_names):
            pts = data.get(name)
            if not pts:
                continue
            c, dash = (styles or {}).get(name, (PALETTE[si % len(PALETTE)], ""))
            out.append('<polyline fill="none" stroke="%s" stroke-width="2"%s points="%s"/>'
                       % (c, ' stroke-dasharray="6,4"' if dash else "", " ".join("%.1f,%.1f" % (px(x), py(y)) for x, y in pts)))
            for x, y in pts:
                out.append('<circle cx="%.1f" cy="%.1f" r="3" fill="%s"/>' % (px(x), py(y), c))
    for si, name in enumerate(series_names):
        lx = 20 + (si % cols) * (total_w - 20) / cols
        ly = H + 14 + 18 * (si // cols)
        c, dash = (styles or {}).get(name, (PALETTE[si % len(PALETTE)], ""))
        out.append('<line x1="%.1f" y1="%d" x2="%.1f" y2="%d" stroke="%s" stroke-width="3"%s/>'
                   % (lx, ly - 4, lx + 22, ly - 4, c, ' stroke-dasharray="6,4"' if dash else ""))
        out.append('<text x="%.1f" y="%d">%s</text>' % (lx + 28, ly, name))
    out.append("</svg>")
    with open(path, "w") as f:
        f.write("\n".join(out) + "\n")
