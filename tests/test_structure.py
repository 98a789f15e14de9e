"""The structure rules (``structure_rules.py``) hold for the repository, and the checker that
measures them is right on small sources whose answer is known by construction.

Known violations are listed below with their size today. The lists are a ratchet: a listed item
may shrink but not grow, a new violation fails, and a listed item that no longer violates must
be taken off its list (the test says so), so a rule that has been met cannot be lost again.
"""

from __future__ import annotations

import textwrap
import warnings
from pathlib import Path

import pytest
import structure_rules as rules

ROOT = Path(__file__).resolve().parents[1]

# Files over rules.MAX_FILE_LINES non-blank non-test lines, with today's count.
KNOWN_LONG_FILES: dict[str, int] = {}

# Functions over rules.MAX_FUNCTION_LINES non-blank lines, with today's length.
KNOWN_LONG_FUNCTIONS: dict[str, int] = {}

# Module edges that lie on an import cycle today, per crate: (from, to). Both are acyclic: the
# experiment spec assembles the simulation and the swing-up, neither of which reads the spec.
KNOWN_CYCLE_EDGES: dict[str, set[tuple[str, str]]] = {
    "rip-core": set(),
    "rip-rt": set(),
}

CRATES = {"rip-core": ("crate",), "rip-rt": ("crate", "rip_rt")}


def ratchet(measured: dict[str, int], known: dict[str, int], limit: int, what: str) -> list[str]:
    """The ratchet's complaints: new or grown violations, and listed items that are fixed. A
    listed item that shrank but still violates passes, with a warning to lower its entry."""
    problems = []
    for key, size in sorted(measured.items()):
        if size > limit and key not in known:
            problems.append(f"{key}: {size} {what} (limit {limit}); split it")
        elif key in known and size > known[key]:
            problems.append(f"{key}: grew to {size} {what} (listed at {known[key]}); split it")
    for key, size in sorted(known.items()):
        now = measured.get(key, 0)
        if key not in measured:
            problems.append(f"{key}: no longer exists: remove it from the list")
        elif now <= limit:
            problems.append(
                f"{key}: now {now} {what}, within the limit {limit}: remove it from the list"
            )
        elif now < size:
            warnings.warn(
                f"{key}: shrank to {now} {what}: lower its entry from {size}", stacklevel=2
            )
    return problems


def cycle_ratchet(
    found: dict[tuple[str, str], list[str]], known: set[tuple[str, str]]
) -> list[str]:
    """New edges on a cycle (with the lines that make them), and listed edges now off every
    cycle."""
    problems = [
        f"{a} -> {b} closes an import cycle ({', '.join(where[:4])})"
        for (a, b), where in sorted(found.items())
        if (a, b) not in known
    ]
    problems += [
        f"{a} -> {b} is no longer on a cycle: remove it from the list"
        for a, b in sorted(known - set(found))
    ]
    return problems


# --- the repository --------------------------------------------------------------------------


def test_no_new_long_source_file() -> None:
    problems = ratchet(
        rules.file_sizes(ROOT), KNOWN_LONG_FILES, rules.MAX_FILE_LINES, "non-blank lines"
    )
    assert not problems, "\n".join(problems)


def test_no_new_long_function() -> None:
    problems = ratchet(
        rules.function_lengths(ROOT), KNOWN_LONG_FUNCTIONS, rules.MAX_FUNCTION_LINES, "lines"
    )
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("crate", sorted(CRATES))
def test_no_new_import_cycle(crate: str) -> None:
    graph = rules.module_graph(ROOT / "crates" / crate / "src", CRATES[crate])
    assert graph.edges, f"no module edges found in {crate}: the parser has lost its way"
    problems = cycle_ratchet(graph.cycle_edges(), KNOWN_CYCLE_EDGES[crate])
    assert not problems, "\n".join(problems)


#: Definitions that have one home each (the file that holds it), found in the non-test Rust
#: sources after comments and literals are blanked: the plant's lumped constants (J0, Jalpha,
#: m12, G), the arm's stopping model, the stop's braking time and the envelope's margin.
ONE_HOME: dict[str, tuple[str, str]] = {
    "J0 = jr + mr lr^2/4 + mp lr^2": (
        r"\bjr\s*\+\s*\w+\.mr\s*\*\s*\w+\.lr\s*\*\s*\w+\.lr\s*/\s*4",
        "crates/rip-core/src/plant/params.rs",
    ),
    "Jalpha = jp + mp lp^2/4": (
        r"\bjp\s*\+\s*\w+\.mp\s*\*\s*\w+\.lp\s*\*\s*\w+\.lp\s*/\s*4",
        "crates/rip-core/src/plant/params.rs",
    ),
    "m12 = mp lr lp/2": (
        r"\bmp\s*\*\s*\w+\.lr\s*\*\s*\w+\.lp\s*/\s*2",
        "crates/rip-core/src/plant/params.rs",
    ),
    "the stop's braking time": (
        r"\bconst\s+\w*(?:BRAKE|STOP)_S\s*:\s*f64\s*=\s*3\.0",
        "crates/rip-control/src/stop.rs",
    ),
    "the arm's stopping model": (
        r"\bstruct\s+StoppingModel\b",
        "crates/rip-control/src/stop.rs",
    ),
    "the stop's braking law": (r"\bstruct\s+BrakingLaw\b", "crates/rip-control/src/stop.rs"),
    "the stop's hold law": (r"\bstruct\s+HoldLaw\b", "crates/rip-control/src/stop.rs"),
    "the stop simulated from the whole state": (
        r"\bstruct\s+SimulatedStop\b",
        "crates/rip-control/src/stop.rs",
    ),
    "the loop's braking envelope": (r"\bstruct\s+ArmEnvelope\b", "crates/rip-control/src/stop.rs"),
    "the stop's rest test": (r"\bstruct\s+RestTest\b", "crates/rip-control/src/stop.rs"),
    "the stop's command by mode": (r"\bstruct\s+Brake\b", "crates/rip-control/src/stop/brake.rs"),
    "the stop's sequence": (
        r"\bstruct\s+StopSequence\b",
        "crates/rip-control/src/stop/sequence.rs",
    ),
    "the lowering's longest time": (
        r"\bconst\s+MAX_LOWER_S\b",
        "crates/rip-control/src/stop/sequence.rs",
    ),
    "counts to angles": (
        r"\*\s*(?:self\.)?\w*rad_per_count(?:\[\w+\])?\s*-\s*(?:self\.)?\w*offset",
        "crates/rip-control/src/stop.rs",
    ),
    "the angle wrap": (
        r"-\s*tau\s*\*\s*(?:libm::round\(\s*a\s*/\s*tau\s*\)|\(\s*a\s*/\s*tau\s*\)\.round\(\))",
        "crates/rip-control/src/swing/mod.rs",
    ),
    "the position rule": (r"\bfn\s+past_limit\b", "crates/rip-control/src/stop.rs"),
    "the rates from two samples on the device's clock": (
        r"\(1\.\.u32::MAX\s*/\s*2\)",
        "crates/rip-control/src/stop.rs",
    ),
    "the stop envelope's margin": (
        r"\bconst\s+ENVELOPE_MARGIN\b",
        "crates/rip-core/src/preflight/motion.rs",
    ),
    # The run time takes the stop's design from rip-core in one call, which converts the
    # configuration: never a part of it on its own.
    "the stop's design, asked for by the run time": (
        r"rip_core::envelope::(?:braking_law|hold_law\w*|simulated_stop|stopping_model|design_stop)"
        r"\s*\(",
        "crates/rip-rt/src/envelope.rs",
    ),
}


@pytest.mark.parametrize("what", sorted(ONE_HOME))
def test_one_definition_has_one_home(what: str) -> None:
    import re

    pattern, home = ONE_HOME[what]
    found = []
    for path in rules.rust_sources(ROOT):
        code = rules.blank_rust(path.read_text())
        code = rules._without(code, rules.rust_test_spans(code))
        found += [str(path.relative_to(ROOT))] * len(re.findall(pattern, code))
    assert found == [home], f"{what}: defined in {found}, its one home is {home}"


def test_the_sources_are_found() -> None:
    """The rules see the sources they are about (a glob gone wrong would pass everything)."""
    sizes = rules.file_sizes(ROOT)
    for path in (
        "crates/rip-core/src/lib.rs",
        "crates/rip-rt/src/runner.rs",
        "crates/rip-protocol/src/lib.rs",
        "firmware/src/main.rs",
        "python/riprs/__init__.py",
        "python/riprs/campaign/engine.py",
    ):
        assert sizes.get(path, 0) > 0, path
    assert not any(p.endswith("/tests.rs") for p in sizes), "test modules count as sources"


# --- the checker on sources with a known answer ----------------------------------------------


def _lines(n: int, indent: str = "    ") -> str:
    return "".join(f"{indent}let x{i} = {i};\n" for i in range(n))


def test_rust_blanking_keeps_code_and_drops_literals_and_comments() -> None:
    src = textwrap.dedent(
        r"""
        fn a() { let s = "}{ fn fake() {"; let c = '}'; let e = '\''; let q = b'{'; }
        // fn commented() {
        /* fn block() { /* nested } */ } */
        fn b<'a>(x: &'a str) -> &'a str { let r = r#"fn raw() { "# ; x }
        """
    )
    code = rules.blank_rust(src)
    assert len(code) == len(src) and code.count("\n") == src.count("\n")
    assert code.count("{") == code.count("}") == 2
    assert [f.name for f in rules.rust_functions(src)] == ["a", "b"]


def test_rust_function_length_is_its_non_blank_lines() -> None:
    body = _lines(10) + "\n\n" + '    let s = "{";\n' + _lines(5)
    src = f"fn short() {{}}\n\nimpl Foo {{\n    fn long(&self) {{\n{body}    }}\n}}\n"
    fns = {f.name: f.length for f in rules.rust_functions(src)}
    assert fns == {"short": 1, "Foo::long": 10 + 1 + 5 + 2}


def test_rust_functions_are_qualified_by_impl_and_skip_declarations_and_tests() -> None:
    src = textwrap.dedent(
        """
        pub trait T { fn declared(&self) -> [f64; 2]; fn provided(&self) {} }
        impl<const N: usize> T for Wrapper<N> where Self: Sized { fn provided(&self) {} }
        fn outer() { fn inner() {} let f: fn(u8) -> u8 = |x| x; }
        #[cfg(test)]
        mod tests { fn helper() {} #[test] fn case() {} }
        #[test]
        fn loose_test() {}
        """
    )
    names = sorted(f.name for f in rules.rust_functions(src))
    assert names == ["T::provided", "Wrapper::provided", "outer", "outer::inner"]


def test_rust_file_lines_exclude_test_items() -> None:
    src = "//! Docs.\n\nfn a() {}\n\n#[cfg(test)]\nmod tests {\n    fn b() {}\n\n    fn c() {}\n}\n"
    assert rules.rust_nonblank_lines(src) == 2


def test_python_function_length_excludes_docstring_and_blank_lines() -> None:
    src = textwrap.dedent(
        '''
        class C:
            def m(self):
                """Doc
                on three
                lines."""

                x = 1
                return x

        def f():
            def g():
                pass
            return g
        '''
    )
    fns = {f.name: f.length for f in rules.python_functions(src)}
    assert fns == {"C.m": 3, "f": 4, "f.g": 2}


def test_use_trees_expand_to_every_path() -> None:
    paths = rules._use_paths("crate::{a::X, b::{c::Y, Z as W}, d}, super::e")
    assert paths == [
        ["crate", "a", "X"],
        ["crate", "b", "c", "Y"],
        ["crate", "b", "Z"],
        ["crate", "d"],
        ["super", "e"],
    ]


def _crate(tmp_path: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        p = tmp_path / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(textwrap.dedent(text))
    return tmp_path


def test_module_graph_finds_a_cycle_through_use_inline_super_and_reexports(
    tmp_path: Path,
) -> None:
    src = _crate(
        tmp_path,
        {
            "lib.rs": "pub mod a; pub mod b; pub mod c; pub mod d;\npub use c::Thing;\n",
            "a.rs": "use crate::{b::X, d};\n",
            "b/mod.rs": "mod inner;\n",
            "b/inner.rs": "fn f() { super::super::c::g(); }\n",
            "c.rs": '// crate::d::Nope\nfn f() { let s = "crate::d"; crate::a::h(); }\n',
            "d.rs": (
                "use crate::Thing;\n#[cfg(test)]\nmod tests { use crate::a::X; }\n"
                "#[cfg(test)]\nmod more;\n"
            ),
            "d/more.rs": "use crate::a::Y;\n",
        },
    )
    graph = rules.module_graph(src)
    assert set(graph.edges) == {("a", "b"), ("a", "d"), ("b", "c"), ("c", "a"), ("d", "c")}
    assert graph.cycles() == [["a", "b", "c", "d"]]
    assert graph.edges[("b", "c")] == ["b/inner.rs:1"]


def test_module_graph_without_a_cycle(tmp_path: Path) -> None:
    src = _crate(
        tmp_path,
        {
            "lib.rs": "pub mod a; pub mod b;\n",
            "a.rs": "use crate::b::X; use self::y::Z; use std::fmt;\n",
            "b.rs": "extern crate self as me;\nfn f() -> me::c::T { me::b::g() }\n",
        },
    )
    graph = rules.module_graph(src, ("crate", "me"))
    assert set(graph.edges) == {("a", "b")}
    assert graph.cycles() == [] and graph.cycle_edges() == {}


def test_ratchet_fails_on_growth_new_items_and_fixed_entries() -> None:
    known = {"a": 900, "b": 900, "c": 900}
    measured = {"a": 900, "b": 901, "c": 800, "d": 801, "e": 10}
    problems = ratchet(measured, known, 800, "lines")
    assert problems == [
        "b: grew to 901 lines (listed at 900); split it",
        "d: 801 lines (limit 800); split it",
        "c: now 800 lines, within the limit 800: remove it from the list",
    ]
    with pytest.warns(UserWarning, match="a: shrank to 850 lines: lower its entry from 900"):
        assert ratchet({"a": 850}, {"a": 900}, 800, "lines") == []
    assert ratchet({}, {"gone": 900}, 800, "lines") == [
        "gone: no longer exists: remove it from the list"
    ]
    assert ratchet(measured | {"b": 900, "c": 801, "d": 2}, known | {"c": 801}, 800, "x") == []


def test_cycle_ratchet() -> None:
    found = {("a", "b"): ["a.rs:1"], ("b", "a"): ["b.rs:3"]}
    assert cycle_ratchet(found, {("a", "b"), ("b", "a")}) == []
    assert cycle_ratchet(found, {("a", "b"), ("c", "a")}) == [
        "b -> a closes an import cycle (b.rs:3)",
        "c -> a is no longer on a cycle: remove it from the list",
    ]
