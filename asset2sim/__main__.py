"""`python -m asset2sim`: the `asset2sim` command line (:mod:`asset2sim.cli`)."""

from asset2sim.cli import run

run()
