"""Griffe extensions for the API pages.

``NativeConstructors``: native classes documented with their constructor signature.

PyO3 classes are constructed by ``__new__``. At run time it takes ``(*args, **kwargs)``;
``riprs/_riprs.pyi`` declares the real parameters. Griffe merges the stubs' annotations into
the inspected module but keeps the run-time parameter names, and it takes a class's signature,
and checks the ``Parameters`` section of its docstring, against ``__init__``. For each class of
``riprs._riprs`` this sets ``__init__`` to the stubs' ``__new__`` (``self`` for ``cls``), so the
API pages show ``Mpc(A, B, C, Ts, *, prediction_horizon=..., ...)`` from the stubs with the
docstring from the compiled module.

``SphinxMarkup``: the docstrings use Sphinx roles and directives (numpydoc style, for Python's
``help`` and Sphinx alike); the site renders Markdown, so they are rewritten for it.
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path
from typing import Any

import griffe


class NativeConstructors(griffe.Extension):
    def _add_inits(self, pkg: Any) -> None:
        native = pkg.members.get("_riprs")
        if native is None:
            return
        stub_path = Path(pkg.filepath).parent / "_riprs.pyi"
        stubs = griffe.visit("_riprs", filepath=stub_path, code=stub_path.read_text())
        for name, cls in native.classes.items():
            stub = stubs.members.get(name)
            new = stub.members.get("__new__") if stub is not None and stub.is_class else None
            if not isinstance(new, griffe.Function):
                continue
            params = [
                griffe.Parameter(
                    "self" if p.name == "cls" else p.name,
                    annotation=None if p.name == "cls" else p.annotation,
                    kind=p.kind,
                    default=p.default,
                )
                for p in new.parameters
            ]
            init = griffe.Function(
                "__init__",
                parameters=griffe.Parameters(*params),
                returns="None",
                lineno=new.lineno,
                endlineno=new.endlineno,
            )
            cls.set_member("__init__", init)

    # griffe >= 2
    def on_package(self, *, pkg: Any, **kwargs: Any) -> None:
        self._add_inits(pkg)

    # griffe 1.x
    def on_package_loaded(self, *, pkg: Any, **kwargs: Any) -> None:
        self._add_inits(pkg)


_ROLE = re.compile(r":(?:class|func|meth|attr|mod|data|exc|obj):`~?([^`]+)`")
_MATH_ROLE = re.compile(r":math:`([^`]+)`")


def _math_block(lines: list[str]) -> list[str]:
    """A ``.. math::`` body as display blocks, one per paragraph (as Sphinx numbers them)."""
    out: list[str] = []
    for para in "\n".join(lines).split("\n\n"):
        body = para.strip("\n")
        if not body.strip():
            continue
        if "&" in body or "\\\\" in body:
            body = "\\begin{aligned}\n" + body + "\n\\end{aligned}"
        out += ["\\[", *body.split("\n"), "\\]", ""]
    return out


def markdown_docstring(text: str) -> str:
    """Sphinx/numpydoc markup in a docstring as the site's Markdown: roles as code or inline
    math, ``.. math::`` directives as display math."""
    text = _MATH_ROLE.sub(lambda m: "\\(" + m[1] + "\\)", text)
    text = _ROLE.sub(lambda m: "`" + m[1] + "`", text)
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.strip() == ".. math::":
            indent = len(line) - len(line.lstrip())
            i += 1
            body: list[str] = []
            while i < len(lines) and (
                not lines[i].strip() or len(lines[i]) - len(lines[i].lstrip()) > indent
            ):
                body.append(lines[i])
                i += 1
            block = _math_block(textwrap.dedent("\n".join(body)).split("\n"))
            out += [" " * indent + b for b in block]
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


class SphinxMarkup(griffe.Extension):
    """Rewrites the docstrings of the riprs package (Python and native) with
    :func:`markdown_docstring`, so ``:math:`` and ``:class:`` render on the site."""

    def _rewrite(self, obj: Any, seen: set[int]) -> None:
        if id(obj) in seen:
            return
        seen.add(id(obj))
        if obj.docstring is not None:
            obj.docstring.value = markdown_docstring(obj.docstring.value)
        for member in obj.members.values():
            if not member.is_alias:
                self._rewrite(member, seen)

    def on_package(self, *, pkg: Any, **kwargs: Any) -> None:
        self._rewrite(pkg, set())

    def on_package_loaded(self, *, pkg: Any, **kwargs: Any) -> None:
        self._rewrite(pkg, set())
