#!/usr/bin/env python3
"""A report's top-level keys against the list docs/formats.md ("Reports")
gives for it: every key listed without a condition is there, and every key
there is listed (with or without one).

    python3 tests/docs/report_keys.py docs/formats.md deform report.json
"""
import json
import re
import sys


def documented(formats, name):
    """(required, optional) keys of the table under `<!-- report-keys: name -->`."""
    text = open(formats, encoding="utf-8").read()
    marker = "<!-- report-keys: %s -->" % name
    if marker not in text:
        sys.exit("%s: no %s" % (formats, marker))
    rows = []
    for line in text.split(marker, 1)[1].lstrip("\n").splitlines():
        if not line.startswith("|"):
            break
        rows.append(line)
    required, optional = set(), set()
    for row in rows[2:]:  # the header and the rule first
        cell = row.rstrip().rstrip("|").split("|", 2)[2]
        while True:  # values and sub-keys, in parentheses, are not top-level keys
            stripped = re.sub(r"\([^()]*\)", "", cell)
            if stripped == cell:
                break
            cell = stripped
        for group in re.findall(r"\[([^\]]*)\]", cell):
            optional.update(re.findall(r"`([^`]+)`", group))
        required.update(re.findall(r"`([^`]+)`", re.sub(r"\[[^\]]*\]", "", cell)))
    if not required:
        sys.exit("%s: the %s table lists no key" % (formats, name))
    return required, optional


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    formats, name, path = sys.argv[1:]
    required, optional = documented(formats, name)
    keys = set(json.load(open(path, encoding="utf-8")))
    missing = sorted(required - keys)
    unlisted = sorted(keys - required - optional)
    if missing or unlisted:
        sys.exit("%s against formats.md's %s keys: missing %s; not listed %s" % (path, name, missing, unlisted))
    print("%s: %d keys, as formats.md lists them (%d listed with a condition, %d of them here)"
          % (path, len(keys), len(optional), len(keys & optional)))


if __name__ == "__main__":
    main()
