#!/usr/bin/env python3
# SPDX-License-Identifier: BSD-3-Clause
"""Checks the include graph of the sources, and the link graph of a build when given, against
the two tables of docs/layers.md. Prints every violation; exits 1 when there is one.

usage: check_layering.py SOURCE_DIR [LINK_GRAPH]   (LINK_GRAPH: <build>/link_graph.txt)
"""
import fnmatch
import os
import re
import sys

INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]')


def cells(line):
    return [c.strip() for c in line.strip().strip("|").split("|")]


def names(cell):
    return [n.strip().split(" ")[0].strip("`") for n in cell.split(",") if n.strip()]


def read_tables(path):
    """The rows of the table under each '## ' heading: {heading: [(first cell, [names])]}."""
    tables, heading = {}, None
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.startswith("## "):
                heading = line[3:].strip()
            elif heading and line.startswith("| `"):
                row = cells(line)
                tables.setdefault(heading, []).append((names(row[0])[0], names(row[1]) if len(row) > 1 else []))
    return tables


def folder_of(path, folders):
    """The most specific folder row (a glob such as drivers/*/fake/) that holds `path`."""
    best = None
    for folder in folders:
        depth = folder.count("/")
        pattern = folder + "*"
        if fnmatch.fnmatch(path, pattern) and (best is None or depth > best.count("/")):
            best = folder
    return best


def check_includes(root, rules):
    folders = [f for f, _ in rules]
    allowed = dict(rules)
    bad = []
    for folder in folders:
        top = folder.split("*")[0]
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            for name in sorted(files):
                if not name.endswith((".hpp", ".cpp")):
                    continue
                rel = os.path.relpath(os.path.join(dirpath, name), root)
                if folder_of(rel, folders) != folder:
                    continue
                with open(os.path.join(root, rel), encoding="utf-8", errors="replace") as f:
                    for number, line in enumerate(f, 1):
                        m = INCLUDE.match(line)
                        if not m:
                            continue
                        header = m.group(1)
                        target = folder_of(header, folders)
                        if target is None or target == folder:
                            continue  # third-party, generated, or its own folder
                        if target in allowed[folder] or header in allowed[folder]:
                            continue
                        bad.append(f"{rel}:{number}: {folder} may not include {header} (docs/layers.md)")
    return bad


def check_links(graph_path, rules):
    allowed = dict(rules)
    bad = []
    seen = set()
    with open(graph_path, encoding="utf-8") as f:
        for line in f:
            if ":" not in line:
                continue
            target, links = line.split(":", 1)
            target = target.strip()
            seen.add(target)
            if target not in allowed:
                bad.append(f"{target}: a target docs/layers.md does not name (add its row to 'Links')")
                continue
            for lib in links.split():
                if lib not in allowed[target]:
                    bad.append(f"{target} links {lib}, which its row in docs/layers.md does not allow")
    for target in allowed:
        if target not in seen:
            bad.append(f"{target}: named in docs/layers.md but not a target of the build")
    return bad


def main():
    if len(sys.argv) not in (2, 3):
        print(__doc__.strip(), file=sys.stderr)
        return 2
    root = sys.argv[1]
    tables = read_tables(os.path.join(root, "docs", "layers.md"))
    includes, links = tables.get("Includes"), tables.get("Links")
    if not includes or not links:
        print("docs/layers.md has no 'Includes' or 'Links' table", file=sys.stderr)
        return 2
    bad = check_includes(root, includes)
    if len(sys.argv) == 3:
        bad += check_links(sys.argv[2], links)
    for b in bad:
        print("layering violation: " + b)
    if not bad:
        print("layering OK" + (" (includes and links)" if len(sys.argv) == 3 else " (includes)"))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
