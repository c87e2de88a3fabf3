import sys

from asset2sim.cli import main

sys.exit(main())
