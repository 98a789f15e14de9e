"""Running test bodies on several threads at once, for the thread-safety tests."""

from __future__ import annotations

import threading
from collections.abc import Callable


def run_threads(*targets: Callable[[], None]) -> list[BaseException]:
    """Run each of ``targets`` on its own thread, all released together by a barrier so that
    they overlap; return what they raised (empty when none did)."""
    errors: list[BaseException] = []
    start = threading.Barrier(len(targets))

    def guard(f: Callable[[], None]) -> Callable[[], None]:
        def run() -> None:
            start.wait()
            try:
                f()
            except BaseException as exc:
                errors.append(exc)

        return run

    threads = [threading.Thread(target=guard(t)) for t in targets]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return errors
