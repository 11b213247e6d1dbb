#!/usr/bin/env python3
"""The structure rules of `docs/architecture.md` that the compiler does not hold.

- No function outside tests is longer than `--max-lines` lines (80).
- No import circle between files: file A imports file B when it names an item of B through a
  path (`use super::b::X`, `crate::x::b::f(...)`, `use super::{b, c}`) or `use`s its own
  child module B (`use b::X`); re-exporting a child (`pub use b::X`) is not an import.

Usage: python3 scripts/structure.py [--check] [--max-lines N] [SRC]
Prints every long function and every circle; with --check, exits 1 if there is any.
"""

import argparse
import os
import re
import sys

TEST_BLOCK = re.compile(r"#\[cfg\(test\)\]\s*mod \w+ \{[\s\S]*")
LINE_COMMENT = re.compile(r"//[^\n]*")
PATH = re.compile(r"\b((?:crate|super|self)(?:::[A-Za-z_]\w*)+)")
CHILD_MODULE = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;", re.M)
CHILD_USE = re.compile(r"^\s*use\s+(\w+)::", re.M)
GROUP = re.compile(r"\b((?:crate|super|self)(?:::[A-Za-z_]\w*)*)::\{([^}]*)\}")
FUNCTION = re.compile(r"\s*(pub(\([^)]*\))?\s+)?(const\s+)?(async\s+)?(unsafe\s+)?fn\s+(\w+)")


def is_test_file(path):
    """Test modules and fixtures: excluded from every rule."""
    name = os.path.basename(path)
    parts = path.split(os.sep)
    return name.startswith("tests") or "tests" in parts[:-1] or name == "fixtures.rs"


def source_files(root):
    """Every non-test `.rs` file under `root`, with its text."""
    files = {}
    for folder, _, names in os.walk(root):
        for name in names:
            path = os.path.join(folder, name)
            if name.endswith(".rs") and not is_test_file(path):
                with open(path, encoding="utf-8") as handle:
                    files[path] = handle.read()
    return files


def without_tests(text):
    """The text before its inline test module."""
    return TEST_BLOCK.sub("", text)


def code_only(text):
    """The text without line comments (doc comments name paths that are not imports)."""
    return LINE_COMMENT.sub("", without_tests(text))


def strip_literals(line):
    """A line with its string and char literals emptied (their braces are not code)."""
    line = re.sub(r'"(\\.|[^"\\])*"', '""', line)
    return re.sub(r"'(\\.|[^'\\])'", "''", line).split("//")[0]


def function_end(lines, first, end):
    """The line where the function starting at `first` closes, or None for a declaration."""
    depth, opened = 0, False
    for index in range(first, end):
        code = strip_literals(lines[index])
        for char in code:
            if char == "{":
                depth, opened = depth + 1, True
            elif char == "}":
                depth -= 1
        if opened and depth == 0:
            return index
        if not opened and code.rstrip().endswith(";"):
            return None
    return None


def long_functions(files, limit):
    """(lines, path, first line, name) of every function over `limit` lines."""
    found = []
    for path, text in files.items():
        lines = without_tests(text).split("\n")
        for index, line in enumerate(lines):
            match = FUNCTION.match(line)
            if not match:
                continue
            last = function_end(lines, index, len(lines))
            if last is not None and last - index + 1 > limit:
                found.append((last - index + 1, path, index + 1, match.group(6)))
    return sorted(found, reverse=True)


def module_path(root, path):
    """`src/a/b.rs` and `src/a/b/mod.rs` are module `a::b`."""
    parts = os.path.relpath(path, root)[:-3].split(os.sep)
    return tuple(parts[:-1] if parts[-1] in ("mod", "lib") else parts)


def references(text):
    """The `crate::`/`super::`/`self::` paths a file's code names, groups expanded, and its
    private `use` of its own child modules (a `pub use` re-export is not counted)."""
    code = code_only(text)
    found = [m.group(1) for m in PATH.finditer(code)]
    children = set(CHILD_MODULE.findall(code))
    found += [f"self::{m.group(1)}" for m in CHILD_USE.finditer(code) if m.group(1) in children]
    for match in GROUP.finditer(code):
        for item in match.group(2).split(","):
            item = item.strip().split(" as ")[0].strip()
            found.append(match.group(1) if item == "self" else f"{match.group(1)}::{item}")
    return found


def resolve(module, reference):
    """The absolute module path a reference starts from, then its segments."""
    segments = reference.split("::")
    if segments[0] == "crate":
        return list(segments[1:])
    base = list(module)
    if segments[0] == "self":
        return base + segments[1:]
    while segments and segments[0] == "super":
        base, segments = base[:-1], segments[1:]
    return base + segments


def import_graph(root, files):
    """File -> the files it imports from."""
    modules = {module_path(root, path): path for path in files}
    graph = {}
    for path, text in files.items():
        targets = set()
        for reference in references(text):
            full = resolve(module_path(root, path), reference)
            for length in range(len(full), 0, -1):
                target = modules.get(tuple(full[:length]))
                if target:
                    if target != path:
                        targets.add(target)
                    break
        graph[path] = targets
    return graph


def circles(graph):
    """The strongly connected sets of more than one file (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in graph.get(node, ()):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    sys.setrecursionlimit(100000)
    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(found)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("src", nargs="?", default="src")
    parser.add_argument("--max-lines", type=int, default=80)
    parser.add_argument("--check", action="store_true", help="exit 1 on any finding")
    args = parser.parse_args()
    files = source_files(args.src)
    long = long_functions(files, args.max_lines)
    loops = circles(import_graph(args.src, files))
    for lines, path, line, name in long:
        print(f"long function: {path}:{line} {name} ({lines} lines)")
    for loop in loops:
        print(f"import circle: {' -> '.join(loop)}")
    print(f"{len(long)} functions over {args.max_lines} lines, {len(loops)} import circles")
    return 1 if args.check and (long or loops) else 0


if __name__ == "__main__":
    sys.exit(main())
