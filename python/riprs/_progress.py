"""Progress bars: on standard error, and only when it is a terminal.

A bar redraws its line with carriage returns; written to a file or a pipe (``riprs compare >
out.txt 2>&1``, a CI log) it leaves those fragments in front of the next printed line, such as
the Tab. 1 header. Standard output stays for results.
"""

from __future__ import annotations

import sys
from typing import Any


def wanted(enabled: bool = True) -> bool:
    """Whether to show a bar: asked for, and standard error is a terminal."""
    if not enabled:
        return False
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):  # replaced or closed stream
        return False


def bar(enabled: bool = True, **kwargs: Any) -> Any:
    """A tqdm bar on standard error (``kwargs`` are tqdm's), or None when not :func:`wanted`."""
    if not wanted(enabled):
        return None
    from tqdm.auto import tqdm

    return tqdm(file=sys.stderr, **kwargs)
