#!/usr/bin/env python3
"""Every numeric option of every qpr subcommand states its range and refuses
what lies outside it (docs/robustness.md).

    option_ranges.py QPR [--sample]

Generated from the command-line definitions: `qpr CMD --help` shows each
numeric option's type with its range in interval notation ("INT:[1, 10000]",
"FLOAT:(0, inf)", apps/qpr/validators.cpp). A numeric option without a range
fails. Each is then given, with the subcommand's required arguments filled
in, values just below its minimum and above its maximum (when finite), NaN,
±infinity, an overflowing literal, a fraction for whole numbers and text:
each must end qpr with CLI11's option-check exit code (105) and a message
naming the option, before any work starts.

--sample (the sanitizer build, where each start of qpr costs ~0.5 s) gives
each option the first two of its values: NaN and, for a finite range, the
nearest value outside it (else infinity). The parsing code is the same for
every value; the Release build runs the whole set.
"""
import math
import re
import subprocess
import sys

OPTION_CHECK = 105
# What a subcommand needs to get past its required arguments to the checks.
REQUIRED = {
    "qp": ["--H", "H.mtx", "--C", "C.mtx", "--demands", "demands"],
    "precompute": ["mesh.off", "--cache", "c.cache"],
    "deform": ["mesh.off"],
    "compare": ["mesh.off"],
    "view": ["mesh.off"],
    "check": ["mesh.off"],
}
LINE = re.compile(r"^\s+(--[a-z0-9-]+)(?:,\s*-\w)?\s+(INT|UINT|FLOAT|NUMBER|DOUBLE)(?::([\[(][^\])]*[\])])|(?=\s|$))")
RANGE = re.compile(r"^([\[(])([^,]+), ([^\])]+)([\])])$")


def subcommands(qpr):
    text = subprocess.run([qpr, "--help"], capture_output=True, text=True).stdout
    block = text.split("Subcommands:", 1)[1] if "Subcommands:" in text else ""
    return [m.group(1) for m in re.finditer(r"^\s+([a-z][a-z-]*)\s", block, re.M)]


def numeric_options(qpr, cmd):
    text = subprocess.run([qpr, cmd, "--help"], capture_output=True, text=True).stdout
    out = []
    for line in text.split("\n"):
        m = LINE.match(line)
        if m:
            out.append((m.group(1), m.group(2), m.group(3)))
    return out


def hostile_values(kind, interval):
    m = RANGE.match(interval)
    if not m:
        return None
    lo_open, lo, hi, hi_open = m.group(1) == "(", float(m.group(2)), float(m.group(3)), m.group(4) == ")"
    whole = kind in ("INT", "UINT")
    outside = []
    if whole:
        if math.isfinite(lo):
            outside.append(str(int(lo) - 1))
        if math.isfinite(hi):
            outside.append(str(int(hi) + 1))
    else:
        if math.isfinite(lo):
            outside.append(repr(lo) if lo_open else repr(lo - max(abs(lo) * 1e-3, 1e-9)))
        if math.isfinite(hi):
            outside.append(repr(hi) if hi_open else repr(hi + max(abs(hi) * 1e-3, 1e-9)))
    # The order matters for --sample: NaN and the nearest value outside first.
    values = ["nan", *(outside or ["inf"]), "inf", "-inf", "1e999", "abc", "3x", *outside]
    if whole:
        values.append("1.5")
    return list(dict.fromkeys(values))


def main(argv):
    sample = "--sample" in argv[2:]
    if len(argv) not in (2, 3) or (len(argv) == 3 and not sample):
        sys.exit(__doc__)
    qpr = argv[1]
    problems, tried = [], 0
    commands = subcommands(qpr)
    if not commands:
        sys.exit("FAILED: no subcommands listed by qpr --help")
    for cmd in commands:
        for option, kind, interval in numeric_options(qpr, cmd):
            values = hostile_values(kind, interval) if interval else None
            if values is None:
                problems.append(f"qpr {cmd} {option} ({kind}) shows no range in --help: add a check "
                                f"(apps/qpr/validators.h)")
                continue
            for v in values[:2] if sample else values:
                tried += 1
                p = subprocess.run([qpr, cmd, *REQUIRED.get(cmd, []), f"{option}={v}"], capture_output=True,
                                   text=True, timeout=60)
                said = p.stdout + p.stderr
                if p.returncode != OPTION_CHECK or option not in said:
                    problems.append(f"qpr {cmd} {option}={v} (range {interval}): exit {p.returncode}, "
                                    f"expected {OPTION_CHECK} and a message naming {option}: {said.strip()[:200]!r}")
    for p in problems:
        print("FAILED:", p)
    print(f"{tried} out-of-range values tried on {len(commands)} subcommands, {len(problems)} problems")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
