#!/usr/bin/env python3
"""Every repository path that README.md, docs/ and tests/ mention exists.

A path is a word that starts with one of the tree's top folders (qpreduce/,
plugins/, apps/, docs/, tests/, ...). It exists when it names a file or
folder from the repository's root, from the mentioning file's folder (links
between docs pages), or under one of the tree's include/ folders (headers
written as they are included, e.g. qpreduce/deform/mesh/mesh.h). Globs and
placeholders (*, <...>, {...}) are not checked.

Usage: repository_paths.py ROOT   (exit 1 and a list of stale paths, file:line)
"""

import os
import re
import sys

TOPS = ("qpreduce", "plugins", "apps", "bench", "tests", "docs", "scripts", "python", "examples", "cmake", ".ci")
PATH = re.compile(r"(?<![\w./+-])((?:%s)/[\w./+-]*[\w+])" % "|".join(re.escape(t) for t in TOPS))
TEXT = (".md", ".cpp", ".h", ".py", ".txt", ".sh", ".cmake")


def mentioning_files(root):
    yield "README.md"
    for top in ("docs", "tests"):
        for folder, _, names in os.walk(os.path.join(root, top)):
            for name in sorted(names):
                if name.endswith(TEXT):
                    yield os.path.relpath(os.path.join(folder, name), root)


def include_roots(root):
    out = []
    for folder, dirs, _ in os.walk(root):
        dirs[:] = [d for d in dirs if d not in (".git", "build", "build-sanitize") and not d.startswith("build")]
        if os.path.basename(folder) == "include":
            out.append(folder)
    return out


def exists(root, mentioned_in, path, includes):
    candidates = [os.path.join(root, path), os.path.join(root, os.path.dirname(mentioned_in), path)]
    candidates += [os.path.join(inc, path) for inc in includes]
    return any(os.path.exists(c) for c in candidates)


def main():
    if len(sys.argv) != 2:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    root = sys.argv[1]
    includes = include_roots(root)
    stale, checked = [], 0
    for rel in mentioning_files(root):
        with open(os.path.join(root, rel), encoding="utf-8", errors="replace") as f:
            for number, line in enumerate(f, 1):
                for match in PATH.finditer(line):
                    path = match.group(1).rstrip(".")
                    if any(c in line[match.start():match.end() + 1] for c in "*<>{}"):
                        continue
                    checked += 1
                    if not exists(root, rel, path, includes):
                        stale.append(f"{rel}:{number}: {path}")
    if stale:
        print(f"{len(stale)} of {checked} repository paths mentioned in README.md, docs/ and tests/ do not exist:")
        print("\n".join(stale))
        return 1
    print(f"all {checked} repository paths mentioned in README.md, docs/ and tests/ exist")
    return 0


if __name__ == "__main__":
    sys.exit(main())
