"""The files a package ships beside its modules (package data: word tables, messages, templates), read once each.

YAML is parsed by libyaml (PyYAML's ``CSafeLoader``) where PyYAML is built with it: the same result as ``SafeLoader``,
about six times faster (``tasks/interpret/words.yaml``: 25 ms against 150 ms).
"""

from __future__ import annotations

import functools
from importlib import resources
from typing import Any

import yaml


@functools.cache
def package_text(package: str, name: str) -> str:
    """The text (UTF-8) of the file ``name`` that ``package`` (a dotted name, e.g. ``asset2sim.priors``) ships.

    Raises:
        FileNotFoundError: the package ships no such file.
    """
    return resources.files(package).joinpath(name).read_text(encoding="utf-8")


@functools.cache
def package_yaml(package: str, name: str) -> Any:
    """The YAML file ``name`` that ``package`` ships, parsed once (safe loading: plain data only). The value is
    shared by every caller: read it, never change it.

    Raises:
        FileNotFoundError: the package ships no such file.
        yaml.YAMLError: the file is not valid YAML.
    """
    return yaml.load(package_text(package, name), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
