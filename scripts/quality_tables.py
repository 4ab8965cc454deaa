"""The Markdown tables and figures of docs/quality.md from a quality study's
results (scripts/quality_study.py): the acceptance targets, one fragment per
`<!-- quality_study:NAME -->` marker, spliced into the page, and the sweep
and convergence plots."""
import os
import re

from plots import PALETTE, line_plot  # noqa: E402 (scripts/ is the script's own folder)

# Acceptance targets: RMS deviation (fraction of the bounding-box diagonal),
# energy ratio (reduced / reference) and speed-up over the full-space solve.
TARGET_RMS, TARGET_RATIO, TARGET_SPEEDUP = 0.02, 1.5, 100.0


def pct(x, digits=2):
    return ("%." + str(digits) + "f %%") % (100 * x)


def g(x, digits=4):
    return ("%." + str(digits) + "g") % x


def label(kind, name):
    return name.replace("_", " ") + {"sel": " `.sel/.def`", "tet": " (tets) `.sel/.def`", "anim": " `.anim`"}[kind]


def short(kind, name):
    return name.replace("_hansel", "") + {"sel": " (sel/def)", "tet": " (tets)", "anim": " (anim)"}[kind]


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def _main_fragments(st, R, frag):
    """Every scenario against its local-global reference."""
    rows = []
    for row in R["main"]:
        rep = row["rep"]
        red, ref = rep["reduced"], rep["references"]["local-global"]
        rows.append([label(row["kind"], row["name"]), rep["vertices"], g(red["arap_energy"]),
                     g(ref["arap_energy"]) + ("" if ref["converged"] else " (cap)"),
                     ("%.2f" % rep["energy_ratio"]) if ref["arap_energy"] > 1e-8 else "— (rest pose)",
                     pct(rep["rms_deviation"]), pct(rep["max_deviation"]),
                     "%.0e / %.0e" % (red["handle_residual"], ref["handle_residual"]),
                     "%.2f" % red["frame_ms"],
                     "%.0f (%d)" % (ref["solve_ms"], ref["iterations"]),
                     "%.0f×" % rep["speedup"],
                     "%.2f" % (red["frame_ms"] / (ref["solve_ms"] / ref["iterations"])),
                     pct(row["rms_cgal"][0]) if "rms_cgal" in row else "—",
                     pct(row["lg_vs_cgal"][0], 3) if "lg_vs_cgal" in row else "—"])
    frag["main"] = table(["scenario", "n", "reduced E", "reference E", "E ratio", "RMS dev.", "max dev.",
                          "handle res. red. / ref.", "reduced frame ms", "reference ms (rounds)", "speedup",
                          "ref. rounds per frame", "RMS vs CGAL/libigl", "ref. vs CGAL/libigl"], rows)


def _ceres_fragments(st, R, frag):
    """The Ceres reference table."""
    rows = []
    for row in R.get("ceres", []):
        c, lg = row["ceres"], row["lg"]
        rows.append([row["model"] + " `.sel/.def`", "%d%s" % (c["iterations"], "" if c["converged"] else " (cap)"),
                     "%.1f" % (c["solve_ms"] / 1000), g(c["arap_energy"]), g(lg["arap_energy"]),
                     pct(c.get("rms_deviation", float("nan"))),
                     pct(row["ceres_vs_lg"][0], 3) if "ceres_vs_lg" in row else "—",
                     "%.0f×" % (c["solve_ms"] / row["rep"]["reduced"]["frame_ms"])])
    frag["ceres"] = table(["scenario", "Ceres LM iterations", "Ceres s", "Ceres E", "local-global E",
                           "RMS reduced vs Ceres", "RMS Ceres vs local-global", "speedup vs Ceres"], rows)


def _ladder_fragments(st, R, frag):
    """Local-global stopped after k rounds."""
    rows = []
    for row in R.get("ladder", []):
        ref, fin = row["rep"]["references"]["local-global"], row["main"]["references"]["local-global"]
        rows.append([label("sel", row["model"]), row["rounds"], "%.0f" % ref["solve_ms"],
                     g(ref["arap_energy"]), "%.4f" % (ref["arap_energy"] / fin["arap_energy"]),
                     "%s / %s" % (pct(row["vs_final"][0], 3), pct(row["vs_final"][1], 3)),
                     pct(row["vs_cgal"][0], 3) if row["vs_cgal"] else "—",
                     "%.0f×" % (ref["solve_ms"] / row["main"]["reduced"]["frame_ms"])])
    frag["ladder"] = table(["scenario", "local-global rounds", "solve ms", "classic E", "E / E(cap)",
                            "RMS / max dev. from the capped run", "RMS dev. from CGAL",
                            "÷ reduced frame (main table)"], rows)


def _modified_fragments(st, R, frag):
    """The modified energy E′ against the classic one."""
    rows = []
    for row in R.get("modified", []):
        rep = row["rep"]
        ref = rep["references"]["local-global"]
        setting = ", ".join("%s = %s" % (k, v) for k, v in row["extra"].items()) or "defaults"
        rows.append([label(row["kind"], row["name"]), setting,
                     "%d%s" % (ref["iterations"], "" if ref["converged"] else " (cap)"),
                     g(ref["arap_energy"]), g(rep["reduced"]["arap_energy"]), g(row["classic_energy"]),
                     pct(row["emin_vs_classic"][0]), pct(row["reduced_vs_emin"][0]), pct(row["reduced_vs_classic"][0])])
    frag["modified"] = table(["scenario", "setting", "E′ rounds", "classic E of E′ minimiser", "classic E reduced",
                              "classic E reference", "RMS E′ min. vs classic", "RMS reduced vs E′ min.",
                              "RMS reduced vs classic"], rows)


def _sweeps_fragments(st, R, frag):
    """The proxy-count and α, β sweeps, one table each."""
    for what, col in (("rot", "d"), ("lin", "m"), ("alpha", "α"), ("beta", "β")):
        if what not in R:
            continue
        rows = []
        for (kind, name), pts in R[what].items():
            for p in pts:
                rep = p["rep"]
                rows.append([label(kind, name), p["value"],
                             "%d / %d" % (rep["linear_proxies"], rep["rotational_proxies"]),
                             "%.2f" % p["ratio"], pct(p["rms"]), pct(p["max"]), "%.0e" % rep["handle_residual_max"],
                             "%.2f" % rep["frame_ms"], "%.1f" % rep["precompute_s"]])
        frag[what] = table(["scenario", col, "linear / rotational proxies", "E ratio", "RMS dev.", "max dev.",
                            "handle res.", "frame ms", "precompute s"], rows)


def _paper_proxies_fragments(st, R, frag):
    """The paper demo's own proxies."""
    rows = []
    for p in R.get("paper_ids", []):
        rep = p["rep"]
        main = next(r for r in R["main"] if r["kind"] == "anim" and r["name"] == p["name"])
        rows.append([label("anim", p["name"]), "`%s`" % p["files"].replace(", ", "`, `"),
                     "%d / %d" % (rep["linear_proxies"], rep["rotational_proxies"]),
                     "%.2f (%.2f)" % (p["ratio"], main["rep"]["energy_ratio"]),
                     "%s (%s)" % (pct(p["rms"]), pct(main["rep"]["rms_deviation"])), pct(p["max"]),
                     "%.2f" % rep["frame_ms"]])
    frag["paper_ids"] = table(["scenario", "linear groups, rotational clusters", "linear / rotational proxies",
                               "E ratio (defaults)", "RMS dev. (defaults)", "max dev.", "frame ms"], rows)


def _convergence_fragments(st, R, frag):
    """Frames and rounds against the converged pose."""
    rows = []
    for (kind, name, lab), (extra, pts) in R.get("conv", {}).items():
        setting = ", ".join("%s = %s" % (k, v) for k, v in extra.items()) or "defaults"
        for p in pts:
            rows.append([label(kind, name), setting, p["frames"], p["iterations"], "%.2f" % p["ratio"], pct(p["rms"]),
                         pct(p["max"]), "%.2f" % p["rep"]["frame_ms"]])
    frag["conv"] = table(["scenario", "setting", "frames", "iterations / frame", "E ratio", "RMS dev.", "max dev.",
                          "frame ms"], rows)


def _timing_fragments(st, R, frag):
    """Frame and round timings against local-global."""
    rows = []
    for t in R.get("timing", []):
        rep, ref = t["rep"], t["main"]["references"]["local-global"]
        rows.append([label("sel", t["model"]), rep["vertices"], "1" if t["threads"] else "all (%d)" % os.cpu_count(),
                     "%.3f" % rep["frame_ms"], "%.1f" % rep["iteration_us"], "%.3f" % rep["reconstruction_ms"],
                     "%.1f" % (ref["solve_ms"] / ref["iterations"]),
                     "%.0f (%d%s)" % (ref["solve_ms"], ref["iterations"], "" if ref["converged"] else ", cap"),
                     "%.0f×" % (ref["solve_ms"] / rep["frame_ms"])])
    frag["timing"] = table(["scenario", "n", "threads", "reduced frame ms", "iteration µs", "reconstruction ms",
                            "local-global ms / round", "local-global solve ms (rounds)", "speedup"], rows)


def _targets_fragments(st, R, frag):
    """The issue's quality targets, met or not."""
    rows = []
    for row in R["main"]:
        if row["kind"] != "sel":
            continue
        rep = row["rep"]
        ok_r = rep["rms_deviation"] <= TARGET_RMS
        ok_e = rep["energy_ratio"] <= TARGET_RATIO
        cells = [label("sel", row["name"]), "%s %s" % (pct(rep["rms_deviation"]), "✓" if ok_r else "✗"),
                 "%.2f %s" % (rep["energy_ratio"], "✓" if ok_e else "✗")]
        if row["name"] == "bumpy_plane":
            cells.append("%.0f× %s" % (rep["speedup"], "✓" if rep["speedup"] >= TARGET_SPEEDUP else "✗"))
            one = [t for t in R.get("timing", []) if t["model"] == "bumpy_plane" and t["threads"] == 1]
            if one:
                ref = rep["references"]["local-global"]
                cells[-1] += " (one thread, 64 frames: %.0f×)" % (ref["solve_ms"] / one[0]["rep"]["frame_ms"])
        else:
            cells.append("(%.0f×)" % rep["speedup"])
        rows.append(cells)
    frag["targets"] = table(["scenario (defaults, %d frames)" % st.cfg["frames"], "RMS dev. ≤ 2 %", "E ratio ≤ 1.5",
                             "speedup ≥ 100× (Bumpy Plane)"], rows)


def fragments(st, info):
    """Every table of quality.md as Markdown, by key."""
    R = st.results
    frag = {"run": table(["", ""], [[k, v] for k, v in info])}
    _main_fragments(st, R, frag)
    _ceres_fragments(st, R, frag)
    _ladder_fragments(st, R, frag)
    _modified_fragments(st, R, frag)
    _sweeps_fragments(st, R, frag)
    _paper_proxies_fragments(st, R, frag)
    _convergence_fragments(st, R, frag)
    _timing_fragments(st, R, frag)
    _targets_fragments(st, R, frag)
    return frag


def figures(st, figdir):
    R = st.results
    made = []
    for what, xlabel, logx, fname, title in (
            ("rot", "rotational proxies d", True, "quality_rotational_proxies.png", "Rotational proxy sweep (Fig. 4)"),
            ("lin", "linear proxies m (point handles)", True, "quality_linear_proxies.png", "Linear proxy sweep"),
            ("alpha", "α", True, "quality_alpha.png", "α sweep (Fig. 3)")):
        if what not in R:
            continue
        names = [short(k, n) for (k, n) in R[what]]
        ratio = {short(k, n): [(p["value"], p["ratio"]) for p in pts] for (k, n), pts in R[what].items()}
        rms = {short(k, n): [(p["value"], 100 * p["rms"]) for p in pts] for (k, n), pts in R[what].items()}
        path = os.path.join(figdir, fname)
        line_plot(path, title, xlabel, [("energy ratio (reduced / reference)", ratio, "auto"),
                                       ("RMS deviation, % of bbox diagonal", rms, "auto")], names, logx=logx,
                 hlines={0: TARGET_RATIO, 1: 100 * TARGET_RMS})
        made.append(path)
    if "conv" in R:
        names, rms, styles = [], {}, {}
        for si, ((kind, name, lab), (extra, pts)) in enumerate(R["conv"].items()):
            its = sorted(set(p["iterations"] for p in pts))
            for ii, it in enumerate(its):
                nm = short(kind, name) + "".join(", %s %s" % ({"rotational-proxies": "d", "alpha": "α"}.get(k, k), v)
                                                 for k, v in extra.items()) + ", %d it." % it
                names.append(nm)
                styles[nm] = (PALETTE[si % len(PALETTE)], ii > 0)
                rms[nm] = [(p["frames"], 100 * p["rms"]) for p in pts if p["iterations"] == it]
        path = os.path.join(figdir, "quality_frames.png")
        line_plot(path, "Frames to the pose (warm start)", "frames from rest to the pose",
                 [("RMS deviation, % of bbox diagonal", rms, "auto")], names, logx=True, hlines={0: 100 * TARGET_RMS},
                 styles=styles)
        made.append(path)
    return made


def splice(doc, frag):
    text = open(doc).read()
    missing = []
    for name, body in frag.items():
        pat = re.compile(r"(<!-- quality_study:%s -->\n)(?:.*?\n)?(<!-- /quality_study:%s -->)" % (name, name), re.S)
        if not pat.search(text):
            missing.append(name)
            continue
        text = pat.sub(lambda m: m.group(1) + body + "\n" + m.group(2), text)
    open(doc, "w").write(text)
    return missing
