"""The ``dancesynth`` command: its libraries load inside the command's own error handling, so
Ctrl-C while they load ends with "interrupted" and exit code 130, as it does later."""

from __future__ import annotations

import sys


def main() -> int:
    try:
        from .cli import main as cli_main
    except KeyboardInterrupt:
        sys.stderr.write("interrupted\n")
        return 130
    return cli_main()
