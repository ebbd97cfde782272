"""The `gearte` command's entry point.

This module installs the interrupt handlers first, so that Ctrl-C or SIGTERM ends the command
cleanly (exit status 128 + signal: 130 for Ctrl-C, 143 for SIGTERM; no traceback, nothing
written) from its first instant. (The command line itself is light; it imports JAX and the
drives, which take a second or more, in the commands that need them, with interrupts deferred.)
It lives outside the `gearte` package because importing anything inside it imports gearte.
"""

from __future__ import annotations

import os
import signal
import sys


def main() -> int:
    received: list[int] = []
    armed: list[bool] = []

    def handler(signum, frame):
        del frame
        received.append(signum)
        # While gearte, JAX and their compiled extensions are imported the interrupt is only remembered: an
        # exception raised inside an extension's initialisation comes out as an ImportError, or worse.
        if armed:
            raise KeyboardInterrupt

    def unraisable(u, previous=sys.unraisablehook):
        # An interrupt raised inside a garbage-collector callback cannot propagate; it is remembered above.
        if u.exc_type is None or not issubclass(u.exc_type, KeyboardInterrupt):
            previous(u)

    sys.unraisablehook = unraisable
    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    try:
        if not received:
            from gearte.cli.main import main as gearte_main  # installs its own handlers when it starts

            armed.append(True)
            if not received:
                status = gearte_main()
                if status < 128:
                    if sys.argv[1:2] == ["check"]:
                        # `gearte check` computed nothing and wrote nothing: its answer is printed, and the
                        # interpreter's orderly teardown of JAX and the drives (about 0.2 s) would only delay it.
                        _exit_now(status)
                    return status
                _exit_now(status)
    except KeyboardInterrupt:
        pass
    print("gearte: interrupted; no results were written", file=sys.stderr)
    _exit_now(128 + (received[0] if received else signal.SIGINT))
    return 130  # not reached


def _exit_now(status: int) -> None:
    """Exit at once (streams flushed, no interpreter teardown): after an interrupt, computations JAX still runs in
    its own threads must not meet the interpreter's shutdown (which can crash it), and the results folder is
    already settled; after `gearte check`, there is nothing left to settle."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


if __name__ == "__main__":
    sys.exit(main())
