"""asset2sim: articulated-object assets in, interaction-ready simulation assets out.

The package imports nothing heavy at import time: simulators other than the
default, renderers and model clients are imported inside the code that needs
them.
"""

__version__ = "0.1.0"
