"""The documentation site loads nothing from outside it (a lab PC offline, this machine).

The site hook (docs/hooks/riprs_site.py) copies MathJax from the pinned package of the docs
extra and fails ``mkdocs build --strict`` on any external script, stylesheet or font in the built
pages (docs/hooks/offline.py). These tests hold the check itself to pages made here, with each
kind of external resource it must find and the links it must leave alone, and mkdocs.yml to
what the check assumes.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import re
import sys
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]


def _offline():
    spec = importlib.util.spec_from_file_location("offline", ROOT / "docs/hooks/offline.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


offline = _offline()

PAGE = """<!doctype html><html><head>
<link rel="stylesheet" href="assets/main.css">
<link rel="icon" href="assets/favicon.png">
<link rel="canonical" href="https://example.org/riprs/">
<script src="javascripts/mathjax.js"></script>
<script src="mathjax/tex-mml-chtml.js"></script>
{extra}
</head><body>
<a href="https://github.com/">a link a reader follows</a>
<img src="generated/arm_angle.svg">
<div style="background: url(data:image/png;base64,AAAA)"></div>
</body></html>
"""

EXTERNAL = [
    ('<script src="https://cdn.jsdelivr.net/npm/mathjax@3/es5/tex-mml-chtml.js"></script>',
     "cdn.jsdelivr.net"),
    ('<link rel="stylesheet" href="https://fonts.googleapis.com/css?family=Roboto">',
     "fonts.googleapis.com"),
    ('<link rel="preconnect" href="https://fonts.gstatic.com">', "fonts.gstatic.com"),
    ('<script src="//unpkg.com/katex/dist/katex.min.js"></script>', "unpkg.com"),
    ("<style>@import url('https://fonts.googleapis.com/css2?family=Inter');</style>",
     "fonts.googleapis.com"),
    ('<span style="font-family: x; src: url(https://example.org/f.woff2)"></span>',
     "example.org"),
    ('<img src="http://example.org/badge.svg">', "example.org"),
]  # fmt: skip


def _site(tmp_path: Path, extra: str = "", css: str = "body { color: red }") -> Path:
    site = tmp_path / "site"
    (site / "assets").mkdir(parents=True)
    (site / "index.html").write_text(PAGE.format(extra=extra))
    (site / "assets" / "main.css").write_text(css)
    return site


def test_a_self_contained_site_passes(tmp_path: Path) -> None:
    assert offline.external_resources(_site(tmp_path)) == []


@pytest.mark.parametrize(("extra", "host"), EXTERNAL, ids=[h for _, h in EXTERNAL])
def test_each_kind_of_external_resource_is_found(tmp_path: Path, extra: str, host: str) -> None:
    found = offline.external_resources(_site(tmp_path, extra))
    assert len(found) == 1 and found[0].startswith("index.html: ") and host in found[0], found


def test_a_stylesheet_that_fetches_a_font_is_found(tmp_path: Path) -> None:
    css = "@font-face { src: url('https://fonts.gstatic.com/s/roboto.woff2') format('woff2') }"
    found = offline.external_resources(_site(tmp_path, css=css))
    assert found == ["assets/main.css: url() https://fonts.gstatic.com/s/roboto.woff2"]


def test_mkdocs_yml_loads_math_and_fonts_from_the_site() -> None:
    text = (ROOT / "mkdocs.yml").read_text()
    scripts = re.search(r"^extra_javascript:\n((?:  - .*\n)+)", text, re.M)
    assert scripts is not None
    entries = [line.strip()[2:] for line in scripts.group(1).splitlines()]
    assert offline.MATHJAX_SCRIPT in entries
    assert not [e for e in entries if offline.is_external(e)], entries
    assert re.search(r"^theme:\n(?:  .*\n)*  font: false\n", text, re.M), "theme.font: false"


def test_mathjax_comes_from_the_pinned_package() -> None:
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    pins = [d for d in pyproject["project"]["optional-dependencies"]["docs"]
            if d.startswith(offline.MATHJAX_DIST)]  # fmt: skip
    assert len(pins) == 1 and "==" in pins[0], pins
    try:
        installed = importlib.metadata.version(offline.MATHJAX_DIST)
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("the docs extra is not installed")
    assert pins[0].split("==")[1] == installed
    files = dict(offline.mathjax_files())
    assert offline.MATHJAX_SCRIPT in files and "mathjax/LICENSE" in files
    # The CHTML output loads its fonts from beside the script ([mathjax]/output/chtml/fonts).
    fonts = [p for p in files if p.startswith("mathjax/output/chtml/fonts/woff-v2/")]
    assert "mathjax/output/chtml/fonts/woff-v2/MathJax_Main-Regular.woff" in fonts
    assert all(path.is_file() for path in files.values())
    # MathJax 3.2.2, whose configuration docs/javascripts/mathjax.js is written for.
    assert b'VERSION="3.2.2"' in files[offline.MATHJAX_SCRIPT].read_bytes()
