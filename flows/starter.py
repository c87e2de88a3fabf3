"""A starter ``catalog.yaml`` for a project outside a clone of asset2sim (``asset2sim init``): the built-in demo
objects as a dataset generated on first use and, when a folder of the user's own objects is given, that folder as
the default dataset with a manifest listing its objects (written beside the catalog: the folder itself is only
read). The text keeps the comments of the clone's ``catalog.yaml`` that say what each setting does; every setting
it leaves out takes :class:`~asset2sim.flows.catalog_config.CatalogConfig`'s default.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path

from asset2sim import atomic
from asset2sim.inert import csv_cell
from asset2sim.flows.catalog_config import load_catalog
from asset2sim.package_data import package_yaml

__all__ = ["CATALOG_NAME", "StarterCatalog", "object_folders", "starter_catalog_text", "write_starter_catalog"]

#: The catalog's file name, the one the pipeline's commands read by default.
CATALOG_NAME = "catalog.yaml"
#: Suffixes of the files an object folder is recognised by (URDF, MJCF, OpenUSD).
OBJECT_SUFFIXES = (".urdf", ".xml", ".mjcf", ".usd", ".usda", ".usdc", ".usdz")

#: The starter catalog's text in three templates (``starter_catalog.yaml`` beside this module): ``head`` and ``tail``
#: take ``{default}``, ``own`` the user's dataset.
_TEXT: dict[str, str] = package_yaml(__package__, "starter_catalog.yaml")


@dataclass(frozen=True)
class StarterCatalog:
    """What :func:`write_starter_catalog` wrote: ``catalog`` the file; ``manifest`` the manifest it listed the
    objects of a folder in (None: the folder's own ``manifest.csv`` is used, or no folder was given);
    ``objects`` how many objects that manifest lists; ``dataset`` the default dataset's name."""

    catalog: Path
    dataset: str
    manifest: Path | None = None
    objects: int = 0


def object_folders(root: Path) -> list[Path]:
    """The sub-folders of ``root`` that hold an object (a file ending in one of :data:`OBJECT_SUFFIXES`), sorted by
    name; hidden folders are left out."""
    return [d for d in sorted(p for p in Path(root).iterdir() if p.is_dir() and not p.name.startswith("."))
            if any(f.is_file() and f.suffix.lower() in OBJECT_SUFFIXES for f in d.iterdir())]


def _relative(path: Path, base: Path) -> str:
    """``path`` relative to ``base`` when it lies on the same drive, else absolute; POSIX separators."""
    try:
        return Path(os.path.relpath(path.resolve(), base.resolve())).as_posix()
    except ValueError:
        return path.resolve().as_posix()


def starter_catalog_text(default: str = "demo", own: dict[str, str] | None = None) -> str:
    """The text of a starter ``catalog.yaml``: the demo dataset and, with ``own`` (``name``, ``description``,
    ``root``, ``manifest``: paths relative to the catalog's folder), the user's dataset; ``default`` the default
    dataset's name. Values are written as JSON strings (valid YAML whatever characters a path holds)."""
    quoted = {k: (v if k == "name" else json.dumps(v)) for k, v in (own or {}).items()}
    return (_TEXT["head"].format(default=default) + (_TEXT["own"].format(**quoted) if own else "")
            + _TEXT["tail"].replace("{default}", default))


def write_starter_catalog(folder: Path | str, objects: Path | str | None = None, *, force: bool = False) -> StarterCatalog:
    """Write a starter ``catalog.yaml`` into ``folder`` (created when missing). With ``objects`` (a folder of object
    folders, one object each: a URDF with its meshes, an MJCF or a USD file), that folder becomes the default
    dataset, named after it; its ``manifest.csv`` is used when it has one, else a manifest listing each object
    folder with an empty request is written beside the catalog (``<name>_manifest.csv``; ``objects`` is only read).

    Raises:
        FileExistsError: ``catalog.yaml`` (or the manifest to write) exists and ``force`` is False.
        NotADirectoryError: ``objects`` is not a folder.
        ValueError: ``objects`` holds no object folder.
        CatalogError: the written catalog does not load (a bug: the text is fixed).
        OSError: the files cannot be written.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    target = folder / CATALOG_NAME
    if target.exists() and not force:
        raise FileExistsError(f"{target} exists; --force replaces it")
    own, manifest, count, default = None, None, 0, "demo"
    if objects is not None:
        root = Path(objects)
        if not root.is_dir():
            raise NotADirectoryError(f"{root}: not a folder of objects")
        found = object_folders(root)
        if not found and not (root / "manifest.csv").is_file():
            raise ValueError(f"{root}: no object folder in it (a sub-folder holding a URDF, MJCF or USD file)")
        default = re.sub(r"[^A-Za-z0-9_.-]+", "_", root.resolve().name).strip("_.-") or "objects"  # a catalog partition name
        if default == "demo":
            default = "objects"
        if (root / "manifest.csv").is_file():
            listed = root / "manifest.csv"
        else:
            manifest = folder / f"{default}_manifest.csv"
            if manifest.exists() and not force:
                raise FileExistsError(f"{manifest} exists; --force replaces it")
            text = io.StringIO()
            writer = csv.writer(text, lineterminator="\n")
            writer.writerow(["id", "category", "prompt", "task"])
            writer.writerows([csv_cell(d.name), "", "", ""] for d in found)  # a folder named =cmd stays text
            atomic.write_text(manifest, text.getvalue())
            listed, count = manifest, len(found)
        own = {"name": default, "description": f"The objects of {root.name}/, one per sub-folder.",
               "root": _relative(root, folder), "manifest": _relative(listed, folder)}
    atomic.write_text(target, starter_catalog_text(default, own))
    load_catalog(target)  # the text is this module's: a catalog that does not load is a bug, not the user's
    return StarterCatalog(catalog=target, dataset=default, manifest=manifest, objects=count)
