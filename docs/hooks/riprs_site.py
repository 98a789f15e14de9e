"""MkDocs hook: every figure and printed result on the site is produced by riprs at build time.

Before the pages are rendered, each script in ``examples/`` listed in ``EXAMPLES`` runs in a
subprocess with ``--out`` pointing into a temporary directory. What it prints becomes
``output/NAME.txt`` and the figures it writes become ``generated/NAME/*.svg``: pages include
the former with ``--8<-- "output/NAME.txt"`` (pymdownx.snippets, whose search path gets the
temporary directory) and link the latter as site files. An example that fails, or a page that
names an output no example made, fails the build.

The site works offline (``offline.py``): MathJax is served from the site, copied from the pinned
package of the docs extra, and a built page or stylesheet that would load a script, stylesheet
or font from another host fails the build.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[2]


def _sibling(name: str) -> Any:
    # MkDocs loads a hook from its path, without its directory on sys.path.
    spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(f"{name}.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


offline = _sibling("offline")

# Scripts run for the site, in this order, with extra arguments. The test suite runs every
# script in examples/ (tests/test_examples.py) in its small size; the site runs them full size.
# The rig scripts run the emulator in lockstep, so the pages show the same runs on any machine
# (the real-time loop's timing is tested by crates/rip-rt/tests).
EXAMPLES: dict[str, list[str]] = {
    "getting_started": [],
    "paper_model": [],
    "paper_rig": [],
    "design_controllers": [],
    "matlab_conventions": [],
    "swing_up": [],
    "rig_emulator": ["--lockstep"],
    "rig_swing_up": ["--lockstep"],
    "rig_excite": ["--lockstep"],
    "campaign": [],
    "performance": [],
    "gym_balance": [],
}

_state: dict[str, Any] = {}


def on_config(config: Any) -> Any:
    work = Path(tempfile.mkdtemp(prefix="riprs-site-"))
    _state["work"] = work
    snippets = config.mdx_configs.setdefault("pymdownx.snippets", {})
    snippets["base_path"] = [*snippets.get("base_path", ["."]), str(work)]
    return config


def _run_examples(work: Path) -> None:
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONUNBUFFERED": "1"}
    env.pop("RIPRS_EXAMPLES_SMALL", None)
    (work / "output").mkdir(exist_ok=True)
    for name, extra in EXAMPLES.items():
        script = ROOT / "examples" / f"{name}.py"
        out = work / "generated" / name
        out.mkdir(parents=True)
        start = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, str(script), "--out", str(out), *extra],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        if proc.returncode != 0:
            raise PluginError(
                f"examples/{name}.py failed (exit {proc.returncode}):\n{proc.stdout}\n{proc.stderr}"
            )
        (work / "output" / f"{name}.txt").write_text(proc.stdout)
        print(f"INFO    -  examples/{name}.py ran in {time.perf_counter() - start:.1f} s")


def on_pre_build(config: Any) -> None:
    _run_examples(_state["work"])


def on_files(files: Files, config: Any) -> Files:
    generated = _state["work"] / "generated"
    for path in sorted(generated.rglob("*.svg")):
        uri = "generated/" + path.relative_to(generated).as_posix()
        files.append(File.generated(config, uri, abs_src_path=str(path)))
    try:
        mathjax = offline.mathjax_files()
    except RuntimeError as e:
        raise PluginError(str(e)) from e
    if offline.MATHJAX_SCRIPT not in config.extra_javascript:
        raise PluginError(f"mkdocs.yml: extra_javascript must load {offline.MATHJAX_SCRIPT}")
    for uri, path in mathjax:
        files.append(File.generated(config, uri, abs_src_path=str(path)))
    return files


def on_post_build(config: Any) -> None:
    shutil.rmtree(_state.pop("work"), ignore_errors=True)
    external = offline.external_resources(Path(config.site_dir))
    if external:
        raise PluginError(
            "the site must load nothing from outside it (offline lab PCs); found:\n  "
            + "\n  ".join(external)
        )


def on_build_error(error: Exception) -> None:
    work = _state.pop("work", None)
    if work is not None:
        shutil.rmtree(work, ignore_errors=True)
