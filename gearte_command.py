"""The `gearte` command's entry point.

gearte and JAX take a second or more to import; this module installs the interrupt handlers
first, so that Ctrl-C or SIGTERM ends the command cleanly (exit status 128 + signal: 130
for Ctrl-C, 143 for SIGTERM; no traceback, nothing written) from its first instant.
It lives outside the `gearte` package because importing anything inside it imports gearte.
"""

from __future__ import annotations

import signal
import sys


def main() -> int:
    received: list[int] = []

    def handler(signum, frame):
        del frame
        received.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    try:
        if not received:
            from gearte.cli.main import main as gearte_main  # installs its own handlers when it starts

            if not received:
                return gearte_main()
    except KeyboardInterrupt:
        pass
    print("gearte: interrupted; no results were written", file=sys.stderr)
    return 128 + (received[0] if received else signal.SIGINT)


if __name__ == "__main__":
    sys.exit(main())
