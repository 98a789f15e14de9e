"""The repository's structure rules, measured from the sources themselves.

- No import cycle between the top-level modules of ``rip-core`` and ``rip-rt``: an edge ``a -> b``
  is any path ``crate::b…`` (``rip_rt::b…`` in rip-rt, which aliases itself), or a ``super::``
  path that resolves to ``b``, in the non-test code of module ``a``, inside ``use`` trees or
  inline. A name the crate root re-exports (``crate::Mpc``) counts as an edge to the module it
  comes from.
- No non-test source file over :data:`MAX_FILE_LINES` non-blank lines (Rust: ``crates/*/src`` and
  ``firmware/src`` without ``#[cfg(test)]`` items and files; Python: ``python/riprs``).
- No function over :data:`MAX_FUNCTION_LINES` lines. Rust: a ``fn`` item from its signature to
  its closing brace, found by brace matching over the code with comments, strings and character
  literals blanked out; Python: a ``def`` from its first line to its last. Blank lines are not
  counted, and neither is a Python docstring (its Rust counterpart, the doc comment, stands
  above the signature): the rule is about the length of the logic, and must not push against
  documentation.

Everything here is plain text processing, so that the rules hold without building anything.
"""

from __future__ import annotations

import ast
import functools
import re
from dataclasses import dataclass, field
from pathlib import Path

MAX_FILE_LINES = 800
MAX_FUNCTION_LINES = 150

_IDENT = r"[A-Za-z_][A-Za-z0-9_]*"


# --- Rust lexing -----------------------------------------------------------------------------


@functools.cache
def blank_rust(src: str) -> str:
    """``src`` with comments and the contents of string and character literals replaced by
    spaces, newlines kept, so that braces, keywords and paths can be matched by position."""
    out = list(src)
    n = len(src)
    i = 0

    def blank(a: int, b: int) -> None:
        for k in range(a, min(b, n)):
            if out[k] != "\n":
                out[k] = " "

    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            j = n if j < 0 else j
            blank(i, j)
            i = j
        elif src.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if src.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif src.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            blank(i, j)
            i = j
        elif (m := re.match(r'(?:br|cr|r)(#*)"', src[i : i + 300])) and not _ident_char(src, i - 1):
            close = '"' + m.group(1)
            j = src.find(close, i + m.end())
            j = n if j < 0 else j + len(close)
            blank(i + m.end(), j - len(close))
            i = j
        elif c == '"' or (c in "bc" and src.startswith('"', i + 1) and not _ident_char(src, i - 1)):
            j = i + (1 if c == '"' else 2)
            start = j
            while j < n and src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            blank(start, j)
            i = j + 1
        elif c == "'" or (c == "b" and src.startswith("'", i + 1) and not _ident_char(src, i - 1)):
            q = i if c == "'" else i + 1
            if src.startswith("\\", q + 1):
                j = src.find("'", q + 3 if src.startswith("\\'", q + 1) else q + 2)
                blank(q + 1, j)
                i = j + 1
            elif q + 2 < n and src[q + 2] == "'":
                blank(q + 1, q + 2)
                i = q + 3
            else:  # a lifetime or a label
                i = q + 1
        else:
            i += 1
    return "".join(out)


def _ident_char(src: str, i: int) -> bool:
    return i >= 0 and (src[i].isalnum() or src[i] == "_")


def _line_of(code: str, pos: int) -> int:
    return code.count("\n", 0, pos) + 1


def _match_brace(code: str, open_pos: int) -> int:
    """Position of the ``}`` closing the ``{`` at ``open_pos`` (``len(code)`` if unbalanced)."""
    depth = 0
    for k in range(open_pos, len(code)):
        if code[k] == "{":
            depth += 1
        elif code[k] == "}":
            depth -= 1
            if depth == 0:
                return k
    return len(code)


def _item_end(code: str, start: int) -> tuple[int, int | None]:
    """End of the item whose header starts at ``start``: the ``;`` or the closing ``}`` of its
    body, whichever comes first outside parentheses and brackets. Returns (end, body_open)."""
    depth = 0
    for k in range(start, len(code)):
        ch = code[k]
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth -= 1
        elif depth == 0 and ch == ";":
            return k, None
        elif depth == 0 and ch == "{":
            return _match_brace(code, k), k
    return len(code), None


_TEST_ATTR = re.compile(r"#\[\s*(?:cfg\s*\(\s*test\s*\)|test)\s*\]")
_ATTR = re.compile(r"\s*#\[[^\]]*\]")


def rust_test_spans(code: str) -> list[tuple[int, int]]:
    """Character spans of items under ``#[cfg(test)]`` or ``#[test]`` (attribute included)."""
    spans: list[tuple[int, int]] = []
    for m in _TEST_ATTR.finditer(code):
        if spans and m.start() < spans[-1][1]:
            continue
        k = m.end()
        while a := _ATTR.match(code, k):
            k = a.end()
        end, _ = _item_end(code, k)
        spans.append((m.start(), end + 1))
    return spans


def rust_test_mod_files(path: Path, code: str) -> list[Path]:
    """Files that ``path`` declares as test-only modules (``#[cfg(test)] mod name;``)."""
    base = path.parent if path.name in ("mod.rs", "lib.rs", "main.rs") else path.with_suffix("")
    found = []
    for a, b in rust_test_spans(code):
        m = re.search(rf"\bmod\s+({_IDENT})\s*;", code[a:b])
        if m:
            found += [base / f"{m.group(1)}.rs", base / m.group(1) / "mod.rs"]
    return found


def _without(code: str, spans: list[tuple[int, int]]) -> str:
    out = list(code)
    for a, b in spans:
        for k in range(a, min(b, len(out))):
            if out[k] != "\n":
                out[k] = " "
    return "".join(out)


def rust_nonblank_lines(src: str) -> int:
    """Non-blank lines of ``src`` outside its test items (comments count: they are read)."""
    code = blank_rust(src)
    dropped: set[int] = set()
    for a, b in rust_test_spans(code):
        dropped.update(range(_line_of(code, a), _line_of(code, b - 1) + 1))
    return sum(1 for i, line in enumerate(src.splitlines(), 1) if line.strip() and i not in dropped)


@dataclass(frozen=True)
class Function:
    """A function and its length in non-blank lines."""

    name: str
    line: int
    length: int


def _impl_name(header: str) -> str | None:
    """The type an ``impl`` (or ``trait``/``mod``) header is about, for qualifying names."""
    m = re.match(r"\s*(?:unsafe\s+)?(impl|trait|mod)\b(.*)", header, re.S)
    if not m:
        return None
    rest = m.group(2)
    if m.group(1) != "impl":
        n = re.match(rf"\s*({_IDENT})", rest)
        return n.group(1) if n else None
    rest = _strip_generics(rest.split(" where ")[0])
    if re.search(r"\bfor\b", rest):
        rest = re.split(r"\bfor\b", rest)[-1]
    names = re.findall(_IDENT, rest)
    return names[-1] if names else None


def _strip_generics(text: str) -> str:
    out, depth = [], 0
    for ch in text:
        if ch == "<":
            depth += 1
        elif ch == ">" and depth:
            depth -= 1
        elif depth == 0:
            out.append(ch)
    return "".join(out)


_BLOCK_ITEM = re.compile(
    r"^[ \t]*(?:pub(?:\([^)]*\))?\s+)?((?:unsafe\s+)?(?:impl|trait|mod)\b)", re.M
)


def rust_functions(src: str) -> list[Function]:
    """Every ``fn`` item with a body outside test items, named ``Type::name`` inside an
    ``impl``/``trait``/``mod`` block and ``outer::name`` inside another function."""
    code = _without(blank_rust(src), rust_test_spans(blank_rust(src)))
    lines = src.splitlines()
    blocks: list[tuple[int, int, str]] = []  # (open, close, qualifier)
    for m in _BLOCK_ITEM.finditer(code):
        end, body = _item_end(code, m.start(1))
        if body is not None:
            name = _impl_name(code[m.start(1) : body])
            if name:
                blocks.append((body, end, name))
    fns: list[tuple[int, int, int, str]] = []
    for m in re.finditer(rf"\bfn\s+({_IDENT})", code):
        end, body = _item_end(code, m.end())
        if body is not None:
            fns.append((m.start(), body, end, m.group(1)))
    for _start, body, end, _ in fns:
        blocks.append((body, end, ""))
    found = []
    for start, body, end, name in fns:
        outer = [
            q or _fn_at(fns, b)
            for b, e, q in sorted(blocks)
            if b < start and end <= e and not (b == body)
        ]
        first, last = _line_of(code, start), _line_of(code, end)
        length = sum(1 for i in range(first, last + 1) if lines[i - 1].strip())
        found.append(Function("::".join([*outer, name]), first, length))
    return found


def _fn_at(fns: list[tuple[int, int, int, str]], body: int) -> str:
    return next(name for _, b, _, name in fns if b == body)


# --- Python ----------------------------------------------------------------------------------


def python_nonblank_lines(src: str) -> int:
    """Non-blank lines of a Python source."""
    return sum(1 for line in src.splitlines() if line.strip())


def python_functions(src: str) -> list[Function]:
    """Every ``def`` with its qualified name and its non-blank lines, docstring excepted."""
    tree = ast.parse(src)
    lines = src.splitlines()
    found: list[Function] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = prefix + child.name
                first, last = child.lineno, child.end_lineno or child.lineno
                doc: set[int] = set()
                body0 = child.body[0]
                if (
                    isinstance(body0, ast.Expr)
                    and isinstance(body0.value, ast.Constant)
                    and isinstance(body0.value.value, str)
                ):
                    doc = set(range(body0.lineno, (body0.end_lineno or body0.lineno) + 1))
                length = sum(
                    1 for i in range(first, last + 1) if lines[i - 1].strip() and i not in doc
                )
                found.append(Function(name, first, length))
                visit(child, name + ".")
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + ".")
            else:
                visit(child, prefix)

    visit(tree, "")
    return found


# --- the module graph ------------------------------------------------------------------------


@dataclass
class ModuleGraph:
    """Edges between a crate's top-level modules, each with the places that make it."""

    edges: dict[tuple[str, str], list[str]] = field(default_factory=dict)

    def add(self, a: str, b: str, where: str) -> None:
        if a != b:
            self.edges.setdefault((a, b), []).append(where)

    def cycles(self) -> list[list[str]]:
        """The strongly connected components of more than one module (Tarjan), sorted."""
        nodes = sorted({n for e in self.edges for n in e})
        succ: dict[str, list[str]] = {n: [] for n in nodes}
        for a, b in self.edges:
            succ[a].append(b)
        index: dict[str, int] = {}
        low: dict[str, int] = {}
        stack: list[str] = []
        on: set[str] = set()
        out: list[list[str]] = []

        def strong(v: str) -> None:
            index[v] = low[v] = len(index)
            stack.append(v)
            on.add(v)
            for w in succ[v]:
                if w not in index:
                    strong(w)
                    low[v] = min(low[v], low[w])
                elif w in on:
                    low[v] = min(low[v], index[w])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))

        for v in nodes:
            if v not in index:
                strong(v)
        return sorted(out)

    def cycle_edges(self) -> dict[tuple[str, str], list[str]]:
        """The edges that lie on a cycle (both ends in one strongly connected component)."""
        comp = {n: i for i, c in enumerate(self.cycles()) for n in c}
        return {
            e: w
            for e, w in sorted(self.edges.items())
            if e[0] in comp and comp[e[0]] == comp.get(e[1])
        }


def _use_paths(tree: str) -> list[list[str]]:
    """The paths a ``use`` tree (the text between ``use`` and ``;``) names."""
    tokens = re.findall(rf"::|[{{}},*]|\$?{_IDENT}", tree)
    pos = 0

    def parse(prefix: list[str]) -> list[list[str]]:
        nonlocal pos
        paths: list[list[str]] = []
        cur = list(prefix)
        while pos < len(tokens):
            t = tokens[pos]
            pos += 1
            if t == "{":
                paths += parse(cur)
                cur = list(prefix)
            elif t == "}":
                break
            elif t == ",":
                if cur != prefix:
                    paths.append(cur)
                cur = list(prefix)
            elif t == "as":
                pos += 1  # the alias
            elif t not in ("::", "*"):
                cur = [*cur, t.lstrip("$")]
            elif t == "*":
                cur = [*cur, "*"]
        if cur != prefix:
            paths.append(cur)
        return paths

    return parse([])


def _root_reexports(lib_code: str, modules: set[str]) -> dict[str, str]:
    """Names the crate root re-exports from its modules: ``pub use m::…::Name`` → {Name: m}."""
    found = {}
    for m in re.finditer(r"\bpub\s+use\s+([^;]*);", lib_code):
        tree = m.group(1)
        for p in _use_paths(tree):
            if p and p[0] == "crate":
                p = p[1:]
            if len(p) > 1 and p[0] in modules:
                alias = re.search(rf"\b{re.escape(p[-1])}\s+as\s+({_IDENT})", tree)
                found[alias.group(1) if alias else p[-1]] = p[0]
    return found


def module_graph(src_dir: Path, self_names: tuple[str, ...] = ("crate",)) -> ModuleGraph:
    """The graph of ``src_dir``'s top-level modules (``src/bin`` is another crate, left out)."""
    files = {
        p: blank_rust(p.read_text())
        for p in sorted(src_dir.rglob("*.rs"))
        if p.relative_to(src_dir).parts[0] != "bin"
    }
    test_files = {t for p, code in files.items() for t in rust_test_mod_files(p, code)}
    modules = {
        p.relative_to(src_dir).parts[0].removesuffix(".rs")
        for p in files
        if p.name != "lib.rs" or p.parent != src_dir
    }
    lib = src_dir / "lib.rs"
    reexports = _root_reexports(files.get(lib, ""), modules)
    names = "|".join(re.escape(n) for n in self_names)
    graph = ModuleGraph()
    for path, raw in files.items():
        if path == lib or path in test_files:
            continue
        rel = path.relative_to(src_dir)
        mod_path = [*rel.parts[:-1], rel.stem] if rel.stem != "mod" else list(rel.parts[:-1])
        code = _without(raw, rust_test_spans(raw))
        refs: list[tuple[list[str], int]] = []
        for m in re.finditer(r"\buse\s+([^;]*);", code):
            refs += [(p, m.start()) for p in _use_paths(m.group(1))]
        inline = _without(
            code, [(m.start(), m.end()) for m in re.finditer(r"\buse\s+[^;]*;", code)]
        )
        for m in re.finditer(rf"(?<![\w:])(?:{names}|super)(?:\s*::\s*{_IDENT})+", inline):
            refs.append((re.findall(_IDENT, m.group(0)), m.start()))
        for p, pos in refs:
            target = _resolve(p, mod_path, self_names)
            if target is None:
                continue
            top = target[0] if target[0] in modules else reexports.get(target[0])
            if top:
                graph.add(mod_path[0], top, f"{rel}:{_line_of(code, pos)}")
    return graph


def _resolve(path: list[str], mod_path: list[str], self_names: tuple[str, ...]) -> list[str] | None:
    """The crate-absolute form of a path used in module ``mod_path``, or None if external."""
    if not path:
        return None
    if path[0] in self_names:
        return path[1:] or None
    if path[0] == "super":
        base = list(mod_path)
        while path and path[0] == "super":
            base, path = base[:-1], path[1:]
        full = base + path
        return full or None
    if path[0] == "self":
        return (mod_path + path[1:]) or None
    return None


# --- the repository --------------------------------------------------------------------------


def rust_sources(root: Path) -> list[Path]:
    """The non-test Rust sources: ``crates/*/src`` and ``firmware/src``, test modules left out."""
    files = sorted([*root.glob("crates/*/src/**/*.rs"), *root.glob("firmware/src/**/*.rs")])
    tests = {t for p in files for t in rust_test_mod_files(p, blank_rust(p.read_text()))}
    return [p for p in files if p not in tests]


def python_sources(root: Path) -> list[Path]:
    """The Python package's sources."""
    return sorted(root.glob("python/riprs/**/*.py"))


def file_sizes(root: Path) -> dict[str, int]:
    """Non-blank non-test lines of every source file, by path relative to ``root``."""
    sizes = {
        str(p.relative_to(root)): rust_nonblank_lines(p.read_text()) for p in rust_sources(root)
    }
    sizes.update(
        {
            str(p.relative_to(root)): python_nonblank_lines(p.read_text())
            for p in python_sources(root)
        }
    )
    return sizes


def function_lengths(root: Path) -> dict[str, int]:
    """Every function's length, keyed ``path::qualified name`` (the longest of equal keys)."""
    out: dict[str, int] = {}
    for p in rust_sources(root):
        for f in rust_functions(p.read_text()):
            key = f"{p.relative_to(root)}::{f.name}"
            out[key] = max(out.get(key, 0), f.length)
    for p in python_sources(root):
        for f in python_functions(p.read_text()):
            key = f"{p.relative_to(root)}::{f.name}"
            out[key] = max(out.get(key, 0), f.length)
    return out
