"""`python -m twin` runs the command line, as the `twin` script does."""

from twin.cli import run

run()
