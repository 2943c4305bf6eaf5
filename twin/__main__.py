"""`python -m twin` runs the command line, as the `twin` script does."""

import os
import signal


def _interrupted_at_start(signum: int, frame: object) -> None:
    # Ctrl-C while Python is still importing twin: one line, no traceback (twin.cli.main takes over).
    os.write(2, b"twin: interrupted\n")
    os._exit(130)


signal.signal(signal.SIGINT, _interrupted_at_start)

from twin.cli import run  # noqa: E402 -- after the start-up SIGINT handler

run()
