"""Where the libraries asset2sim drives keep their configuration and caches: never a folder a run creates outside its
output as a side effect.

matplotlib (the report's figures) creates ``~/.config/matplotlib`` and ``~/.cache/matplotlib`` (its font list) the
first time it is imported on a fresh machine; MLflow (the flow's tracking, ``rate --tracking-uri``) writes
``~/.config/mlflow/telemetry.json`` and reports usage over the network; Prefect's home is set by the flow
(:func:`asset2sim.flows.stages.prepare_prefect_environment`: ``<project>/.prefect``). :func:`configure` sets, where
the user has not:

- ``MPLCONFIGDIR`` to ``matplotlib/`` in asset2sim's own cache (:func:`asset2sim.array_cache.cache_dir`,
  ``~/.cache/asset2sim`` or ``$ASSET2SIM_CACHE``), or to a temporary folder of the process (removed when it exits)
  when that cache is off; left alone when the user has a matplotlib configuration folder of their own (their
  ``matplotlibrc`` keeps working);
- ``MLFLOW_DISABLE_TELEMETRY=true``.

It is called by the command line before anything runs, and before matplotlib or MLflow is imported by the code
that needs them (:mod:`asset2sim.tasks.evaluation.plots`, :mod:`asset2sim.flows.tracking`); calling it again
changes nothing.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

from asset2sim import array_cache, atomic

__all__ = ["configure", "matplotlib_dir"]

_LOCK = threading.Lock()
_TEMP: list[Path] = []


def matplotlib_dir() -> Path:
    """The folder ``MPLCONFIGDIR`` gets: ``<asset2sim cache>/matplotlib``, or a temporary folder of this process
    (``asset2sim-matplotlib-*`` in the temporary directory, removed at exit) when the cache is off."""
    cache = array_cache.cache_dir()
    if cache is not None:
        return Path(cache) / "matplotlib"
    with _LOCK:
        if not _TEMP:
            _TEMP.append(atomic.process_folder("asset2sim-matplotlib-"))
        return _TEMP[0]


def configure() -> dict[str, str]:
    """Set the libraries' folders and switches in ``os.environ`` where they are unset (module docstring); returns
    what it set (name -> value). Raises nothing (a cache folder that cannot be made is matplotlib's to report)."""
    done: dict[str, str] = {}
    # the user's own matplotlib configuration folder: $XDG_CONFIG_HOME/matplotlib, ~/.config/matplotlib or ~/.matplotlib
    home, xdg = Path(os.path.expanduser("~")), os.environ.get("XDG_CONFIG_HOME")
    own = [*([Path(xdg) / "matplotlib"] if xdg else []), home / ".config" / "matplotlib", home / ".matplotlib"]
    if "MPLCONFIGDIR" not in os.environ and not any(p.is_dir() for p in own):
        done["MPLCONFIGDIR"] = os.environ["MPLCONFIGDIR"] = str(matplotlib_dir())
    if "MLFLOW_DISABLE_TELEMETRY" not in os.environ:
        done["MLFLOW_DISABLE_TELEMETRY"] = os.environ["MLFLOW_DISABLE_TELEMETRY"] = "true"
    return done
