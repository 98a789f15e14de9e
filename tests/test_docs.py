"""The documentation site covers the public API and its pages point at files that exist."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import riprs

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
DIRECTIVE = re.compile(r"^::: (riprs(?:\.[A-Za-z_]\w*)*)\s*$", re.MULTILINE)


def _directives() -> list[str]:
    pages = sorted((DOCS / "api").glob("*.md"))
    return [path for page in pages for path in DIRECTIVE.findall(page.read_text())]


def _resolve(path: str) -> object:
    parts = path.split(".")
    for split in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:split]))
        except ModuleNotFoundError:
            continue
        for name in parts[split:]:
            obj = getattr(obj, name)
        return obj
    raise ModuleNotFoundError(path)


def test_every_public_name_has_an_api_entry() -> None:
    documented = {path.removeprefix("riprs.") for path in _directives()}
    missing = sorted(set(riprs.__all__) - documented)
    assert not missing, f"names in riprs.__all__ without '::: riprs.NAME' in docs/api: {missing}"


def test_every_api_entry_names_an_existing_object() -> None:
    paths = _directives()
    assert paths
    for path in paths:
        _resolve(path)  # raises for a name that does not exist


def test_configuration_page_is_the_generated_reference() -> None:
    # The site's page is docs/configuration.md itself, which test_config.py checks against
    # `riprs config --reference`; no other page may hold a copy of the keys.
    assert "Configuration reference: configuration.md" in (ROOT / "mkdocs.yml").read_text()
    copies = [p.name for p in DOCS.rglob("*.md") if "[monte_carlo]\nruns =" in p.read_text()]
    assert copies == ["configuration.md"], copies


def test_snippet_includes_point_at_files_and_sections_that_exist() -> None:
    include = re.compile(r'^--8<-- "([^"]+)"', re.MULTILINE)
    for page in DOCS.rglob("*.md"):
        for target in include.findall(page.read_text()):
            path, _, section = target.partition(":")
            if path.startswith("output/"):
                continue  # written by the build hook
            file = ROOT / path
            assert file.is_file(), f"{page.name}: {path} does not exist"
            if section:
                text = file.read_text()
                assert f"[start:{section}]" in text and f"[end:{section}]" in text, (
                    f"{page.name}: no section {section!r} in {path}"
                )


def test_example_sections_are_unique() -> None:
    # pymdownx.snippets includes only the first section of a name: a repeated name would hide
    # code from the page.
    marker = re.compile(r"\[start:(\w+)\]")
    for script in (ROOT / "examples").glob("*.py"):
        names = marker.findall(script.read_text())
        assert len(names) == len(set(names)), f"{script.name}: repeated sections {names}"


def test_readme_links_point_at_files_that_exist() -> None:
    link = re.compile(r"\]\(([^)#]+)(?:#[^)]*)?\)")
    targets = [t for t in link.findall((ROOT / "README.md").read_text()) if "://" not in t]
    assert targets
    missing = [t for t in targets if not (ROOT / t).exists()]
    assert not missing, missing
