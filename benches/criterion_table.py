"""Print the medians of the last ``cargo bench`` run as a Markdown table.

Criterion keeps each benchmark's statistics in ``target/criterion/<id>/new/estimates.json``;
this reads the median point estimate of every one.

Usage: ``cargo bench && python benches/criterion_table.py [target/criterion]``
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def medians(root: Path) -> dict[str, float]:
    """Benchmark id -> median time per iteration (s)."""
    out = {}
    for path in sorted(root.glob("**/new/estimates.json")):
        bench_id = str(path.parent.parent.relative_to(root))
        with path.open() as fh:
            out[bench_id] = json.load(fh)["median"]["point_estimate"] * 1e-9
    return out


def _fmt(seconds: float) -> str:
    if seconds < 1e-6:
        return f"{seconds * 1e9:.0f} ns"
    if seconds < 1e-3:
        return f"{seconds * 1e6:.2f} µs"
    return f"{seconds * 1e3:.2f} ms"


def main() -> None:
    root = Path(sys.argv[1] if len(sys.argv) > 1 else "target/criterion")
    table = medians(root)
    if not table:
        sys.exit(f"no criterion results under {root}; run `cargo bench` first")
    print("| benchmark | median |\n| --- | ---: |")
    for bench_id, seconds in table.items():
        print(f"| `{bench_id}` | {_fmt(seconds)} |")


if __name__ == "__main__":
    main()
