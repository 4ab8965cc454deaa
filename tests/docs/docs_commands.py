#!/usr/bin/env python3
"""Runs the command blocks of README.md and docs/**/*.md as smoke tests, so
that the documented commands cannot rot.

    docs_commands.py SOURCE_DIR BUILD_DIR [--list] [--only FILE[:LINE]]

Every fenced block whose info string is `sh`, `bash` or `python` is run, in
a scratch copy of the checkout's layout (symlinks to the source folders,
`build` to BUILD_DIR, `../shared/data` to the shared test data when it is
present), with bash (`set -eo pipefail`) or with BUILD_DIR/bin/qpreduce-python.
An HTML comment on the line before the fence (blank lines between are
allowed) changes that:

    <!-- docs-test: illustration: WHY -->    not run (a synopsis, a template
                                             the text fills in, what CI itself
                                             runs); WHY is required
    <!-- docs-test: smoke: FROM => TO; ... -->  run with these substitutions
                                             (smaller inputs, fewer rounds)
    <!-- docs-test: set NAME=VALUE ... -->   run with these variables
                                             exported first (sh blocks)
    <!-- docs-test: needs-data -->           reads the shared test data
                                             without naming ../shared (a
                                             script's default)

`smoke` and `set` may share one comment, separated by " | "; an
illustration's reason is the rest of its comment. A block that
reads ../shared (in its text, its substitutions or its variables) or is
marked needs-data is skipped with a message when the shared data is absent
($QPREDUCE_SHARED_DATA, when set, names its folder: tests/shared_data.h).
Exit status: 0 when every runnable block passed (or was skipped), 1 otherwise.
"""
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

FENCE = re.compile(r"^```(\w*)\s*$")
DIRECTIVE = re.compile(r"^<!--\s*docs-test:\s*(.*?)\s*-->\s*$")
RUNNABLE = {"sh": "sh", "bash": "sh", "python": "python"}
TIMEOUT = 600  # seconds per block


class Block:
    def __init__(self, path, line, kind, text, directive):
        self.path, self.line, self.kind, self.text, self.directive = path, line, kind, text, directive
        self.illustration = None
        self.substitutions = []
        self.variables = []
        self.needs_data = False
        if directive.startswith("illustration:"):  # the rest of the comment is the reason
            self.illustration = directive[len("illustration:"):].strip()
            if not self.illustration:
                raise ValueError(f"{self.where()}: an illustration needs its reason")
            directive = ""
        for part in [p.strip() for p in directive.split(" | ")] if directive else []:
            if part.startswith("smoke:"):
                for pair in part[len("smoke:"):].split(";"):
                    if pair.strip():
                        if "=>" not in pair:
                            raise ValueError(f"{self.where()}: smoke substitution without '=>': {pair!r}")
                        old, new = (x.strip() for x in pair.split("=>", 1))
                        self.substitutions.append((old, new))
            elif part == "needs-data":
                self.needs_data = True
            elif part.startswith("set "):
                self.variables.extend("export " + v for v in part[4:].split())
            else:
                raise ValueError(f"{self.where()}: unknown docs-test directive {part!r}")

    def where(self):
        return f"{self.path}:{self.line}"

    def script(self):
        text = self.text
        for old, new in self.substitutions:
            if old not in text:
                raise ValueError(f"{self.where()}: smoke substitution {old!r} matches nothing")
            text = text.replace(old, new)
        if self.kind == "sh":
            return "set -eo pipefail\n" + "".join(v + "\n" for v in self.variables) + text
        return text


def blocks_of(source, relative):
    lines = open(os.path.join(source, relative), encoding="utf-8").read().split("\n")
    out, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        kind, start = m.group(1), i
        j = i + 1
        while j < len(lines) and not lines[j].startswith("```"):
            j += 1
        if kind in RUNNABLE:
            directive, k = "", start - 1
            while k >= 0 and lines[k].strip() == "":
                k -= 1
            if k >= 0:
                d = DIRECTIVE.match(lines[k].strip())
                if d:
                    directive = d.group(1)
            out.append(Block(relative, start + 1, RUNNABLE[kind], "\n".join(lines[start + 1:j]) + "\n", directive))
        i = j + 1
    return out


def documents(source):
    out = ["README.md"]
    for root, _, files in os.walk(os.path.join(source, "docs")):
        out += [os.path.relpath(os.path.join(root, f), source) for f in sorted(files) if f.endswith(".md")]
    return sorted(out, key=lambda p: (p != "README.md", p))


def shared_data(source):
    return os.environ.get("QPREDUCE_SHARED_DATA", os.path.join(os.path.dirname(source), "shared", "data"))


def scratch_checkout(source, build, data):
    """A folder laid out as the checkout (symlinks), with ../shared/data."""
    top = tempfile.mkdtemp(prefix="qpreduce-docs-")
    root = os.path.join(top, "checkout")
    os.mkdir(root)
    for entry in os.listdir(source):
        if entry in (".git", "build") or entry.startswith("build-"):
            continue
        os.symlink(os.path.join(source, entry), os.path.join(root, entry))
    os.symlink(os.path.abspath(build), os.path.join(root, "build"))
    if os.path.isdir(data):
        os.makedirs(os.path.join(top, "shared"))
        os.symlink(os.path.abspath(data), os.path.join(top, "shared", "data"))
    return root


def run(block, root, build, data_present):
    if (block.needs_data or "../shared" in block.script()) and not data_present:
        return "skipped", "the shared test data is absent"
    env = dict(os.environ)
    env.pop("QPREDUCE_SHARED_DATA", None)  # the scratch tree's ../shared/data is what the block reads
    if block.kind == "sh":
        command = ["bash", "-c", block.script()]
        stdin = None
    else:
        command = [os.path.join(build, "bin", "qpreduce-python"), "-"]
        stdin = block.script()
    start = time.monotonic()
    try:
        p = subprocess.run(command, cwd=root, env=env, input=stdin, capture_output=True, text=True, timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return "failed", f"timed out after {TIMEOUT} s"
    seconds = time.monotonic() - start
    if p.returncode != 0:
        tail = "\n".join((p.stdout + p.stderr).strip().split("\n")[-25:])
        return "failed", f"exit {p.returncode} after {seconds:.1f} s:\n{tail}"
    return "passed", f"{seconds:.1f} s"


def main(argv):
    if len(argv) < 3:
        sys.exit(__doc__)
    source, build = os.path.abspath(argv[1]), os.path.abspath(argv[2])
    listing = "--list" in argv
    only = argv[argv.index("--only") + 1] if "--only" in argv else None
    blocks = []
    try:
        for doc in documents(source):
            blocks += blocks_of(source, doc)
        for b in blocks:
            b.script()  # substitutions that match nothing are errors
    except ValueError as e:
        print(f"FAILED: {e}")
        return 1
    if only:
        if ":" not in only and not os.path.isfile(os.path.join(source, only)):
            print(f"FAILED: no page {only}")
            return 1
        blocks = [b for b in blocks if b.where() == only or b.path == only]
        if not blocks and ":" not in only:
            print(f"{only}: no sh or python blocks")
            return 0
    if listing:
        for b in blocks:
            print(f"{b.where()}: {b.kind}" + (f" (illustration: {b.illustration})" if b.illustration else ""))
        return 0
    if not blocks:
        print(f"FAILED: no command block matches {only}")
        return 1
    data = shared_data(source)
    root = scratch_checkout(source, build, data)
    failed = 0
    try:
        for b in blocks:
            if b.illustration:
                print(f"{b.where()}: not run (illustration: {b.illustration})")
                continue
            status, detail = run(b, root, build, os.path.isdir(data))
            print(f"{b.where()}: {status} ({detail})" if status != "failed" else f"{b.where()}: FAILED, {detail}")
            sys.stdout.flush()
            failed += status == "failed"
    finally:
        shutil.rmtree(os.path.dirname(root), ignore_errors=True)
    print(f"{len(blocks)} blocks, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
