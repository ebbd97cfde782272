import sys

try:  # the command's entry point: interrupt handlers first, then gearte (gearte_command, beside the package)
    from gearte_command import main
except ImportError:  # pragma: no cover - a copy of the package without its entry module
    from .cli.main import main

sys.exit(main())
