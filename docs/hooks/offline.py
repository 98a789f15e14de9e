"""The site works offline: its math renderer is served from the site, and nothing it loads
comes from elsewhere.

``mathjax_files`` lists the MathJax files the site serves, taken from the pinned
``django-static-mathjax`` package of the docs extra (MathJax's own ``es5`` build, no Django
needed). ``external_resources`` finds what a built page or stylesheet would fetch from another
host: scripts, stylesheets, fonts, preloads, CSS ``@import`` and ``url(...)``. Links a reader
follows (``<a href>``) are not resources. The site hook fails the build on any.
"""

from __future__ import annotations

import importlib.metadata
import re
from html.parser import HTMLParser
from pathlib import Path

MATHJAX_DIST = "django-static-mathjax"
_MATHJAX_ES5 = "mathjax/static/mathjax/es5/"
# The combined component the site loads and what it loads on demand (TeX extensions, the
# CHTML fonts, the menu, accessibility and speech); the other combined builds are not needed.
_MATHJAX_KEEP = ("tex-mml-chtml.js", "input/", "output/chtml", "ui/", "a11y/", "sre/", "adaptors/")
MATHJAX_SCRIPT = "mathjax/tex-mml-chtml.js"

# A URL that leaves the site: a scheme with a host, or protocol-relative.
_EXTERNAL = re.compile(r"^\s*(?:[a-zA-Z][a-zA-Z0-9+.-]*:)?//")
_CSS_URL = re.compile(r"""(?:@import\s+(?:url\()?|url\()\s*['"]?([^'")\s;]+)""")
# <link rel=...> values that make the browser fetch the target.
_FETCHING_RELS = {"stylesheet", "preload", "modulepreload", "prefetch", "preconnect", "icon",
                  "dns-prefetch", "manifest", "apple-touch-icon"}  # fmt: skip


def mathjax_files() -> list[tuple[str, Path]]:
    """The MathJax files to serve: (site path under ``mathjax/``, installed file).

    Raises
    ------
    RuntimeError
        The package is not installed.
    """
    try:
        dist = importlib.metadata.distribution(MATHJAX_DIST)
    except importlib.metadata.PackageNotFoundError as e:
        raise RuntimeError(
            f"the documentation serves MathJax from the {MATHJAX_DIST} package, which is not "
            "installed: pip install '.[docs]'"
        ) from e
    out = []
    for f in dist.files or []:
        name = f.as_posix()
        if name == "mathjax/static/mathjax/LICENSE":
            out.append(("mathjax/LICENSE", Path(str(dist.locate_file(f)))))
        if not name.startswith(_MATHJAX_ES5):
            continue
        rel = name[len(_MATHJAX_ES5) :]
        if rel.startswith(_MATHJAX_KEEP):
            out.append(("mathjax/" + rel, Path(str(dist.locate_file(f)))))
    if not any(site == MATHJAX_SCRIPT for site, _ in out):
        raise RuntimeError(f"{MATHJAX_DIST} has no es5/tex-mml-chtml.js")
    return out


def is_external(url: str) -> bool:
    """Whether ``url`` points to another host (``https://…``, ``//…``)."""
    return bool(_EXTERNAL.match(url))


class _Resources(HTMLParser):
    """Collects (what, url) for everything a page makes the browser fetch."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.found: list[tuple[str, str]] = []
        self._in_style = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = {k: v or "" for k, v in attrs}
        if tag == "script" and a.get("src"):
            self.found.append(("<script src>", a["src"]))
        elif tag == "link" and a.get("href"):
            if set(a.get("rel", "").lower().split()) & _FETCHING_RELS:
                self.found.append((f"<link rel={a.get('rel')}>", a["href"]))
        elif tag in ("img", "iframe", "source", "audio", "video", "embed") and a.get("src"):
            self.found.append((f"<{tag} src>", a["src"]))
        elif tag == "object" and a.get("data"):
            self.found.append(("<object data>", a["data"]))
        if a.get("style"):
            self.found += [("style url()", u) for u in _CSS_URL.findall(a["style"])]
        self._in_style = tag == "style"

    def handle_endtag(self, tag: str) -> None:
        if tag == "style":
            self._in_style = False

    def handle_data(self, data: str) -> None:
        if self._in_style:
            self.found += [("<style> url()", u) for u in _CSS_URL.findall(data)]


def external_resources(site: Path) -> list[str]:
    """What the built site at ``site`` would load from another host, as ``"file: what"``.

    Parameters
    ----------
    site : pathlib.Path
        The built site directory.

    Returns
    -------
    list of str
        Empty when the site is self-contained.
    """
    problems = []
    for path in sorted(site.rglob("*")):
        if path.suffix == ".html":
            parser = _Resources()
            parser.feed(path.read_text(encoding="utf-8", errors="replace"))
            hits = [f"{what} {url}" for what, url in parser.found if is_external(url)]
        elif path.suffix == ".css":
            text = path.read_text(encoding="utf-8", errors="replace")
            hits = [f"url() {u}" for u in _CSS_URL.findall(text) if is_external(u)]
        else:
            continue
        problems += [f"{path.relative_to(site).as_posix()}: {h}" for h in hits]
    return problems
