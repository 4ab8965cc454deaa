"""The Markdown tables of docs/quality.md from a quality study's results
(scripts/quality_study.py): the acceptance targets and one fragment per
`<!-- quality_study:NAME -->` marker."""
import os

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


def fragments(st, info):
    R = st.results
    frag = {}
    # run info
    frag["run"] = table(["", ""], [[k, v] for k, v in info])
    # main table
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
    # ceres
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
    # local-global ladder
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
    # modified energy
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
    # sweeps
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
    # the paper demo's proxies
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
    # convergence
    rows = []
    for (kind, name, lab), (extra, pts) in R.get("conv", {}).items():
        setting = ", ".join("%s = %s" % (k, v) for k, v in extra.items()) or "defaults"
        for p in pts:
            rows.append([label(kind, name), setting, p["frames"], p["iterations"], "%.2f" % p["ratio"], pct(p["rms"]),
                         pct(p["max"]), "%.2f" % p["rep"]["frame_ms"]])
    frag["conv"] = table(["scenario", "setting", "frames", "iterations / frame", "E ratio", "RMS dev.", "max dev.",
                          "frame ms"], rows)
    # timing
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
    # targets
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
    return frag
