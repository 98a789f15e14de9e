"""The ``rip-rt`` console script: the real-time loop, ``excite``, ``emulate`` and ``config``.

``pip install`` cannot put a second, cargo-built binary next to the extension module (one wheel
holds one or the other), so this script runs the same program in-process: the native module's
``rip_rt_main`` is ``rip_rt::cli::run``, the function the ``rip-rt`` binary's ``main`` calls.
Exit codes and signal behaviour are the binary's: see ``rip-rt run --help`` and docs/rip-rt.md.
"""

from __future__ import annotations

import signal
import sys
from typing import NoReturn

from riprs._riprs import rip_rt_main


def main() -> NoReturn:
    """Run ``rip-rt`` with ``sys.argv`` and exit with its exit code.

    Python's own SIGINT handler (``KeyboardInterrupt``) is removed first, so that rip-rt's
    handlers see Ctrl-C as the binary's do: the loop sends 0 V and exits with 130. rip-rt
    installs its handlers before it opens the device, as the binary does; until then a
    signal ends the process by its default action, with the motor never enabled.
    """
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, signal.SIG_DFL)
    sys.stdout.flush()
    sys.stderr.flush()
    raise SystemExit(rip_rt_main(sys.argv))


if __name__ == "__main__":
    main()
