"""The `kodama-dag` command line from the wheel: the script `kodama-dag` and `python -m kodama_dag`
run the same commands, flags and exit codes as the binary (README, "Commands"), in this process.
"""

import signal
import sys

from . import _core


def main() -> int:
    """Runs `kodama-dag` with this process's arguments; returns its exit code."""
    # Ctrl-C stops the command as it stops the binary: Python's own handler would run only once
    # the call returned, which for `watch` and `serve` is never.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    return _core.cli(["kodama-dag", *sys.argv[1:]])


if __name__ == "__main__":
    sys.exit(main())
