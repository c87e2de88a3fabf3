from asset2sim.cli import run

run()
