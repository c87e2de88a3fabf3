"""The Python API: what ``import asset2sim`` offers.

Refine an asset, evaluate or validate one, export an output folder to MJCF or
USD, and load an output into PyBullet, SAPIEN (PhysX) or MuJoCo exactly as
asset2sim verified it::

    import asset2sim

    result = asset2sim.refine("path/to/103275", "a slightly open stapler", "out/stapler")
    print(result.ready, result.report.failure_mode)
    robot = asset2sim.load_pybullet("out/stapler", client)   # client = pybullet.connect(...)

The command line calls the same stages (``asset2sim.tasks``). Units: SI,
radians (revolute) and metres (prismatic) for joint positions.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from asset2sim.engines.base import SimSession
from asset2sim.engines.passive_joints import DeclaredPhysics
from asset2sim.engines.registry import known_engines, open_session
from asset2sim.inert import field_errors
from asset2sim.input_files import load_yaml
from asset2sim.output_folder import URDF_NAME
from asset2sim.schemas.config import RefineConfig, SimConventions
from asset2sim.schemas.evaluation import Evaluation
from asset2sim.schemas.request import RequestOverrides
from asset2sim.formats import FORMATS
from asset2sim.refined_asset import RefinedAsset
from asset2sim.apps.audit.audit import AuditError, AuditResult, audit_asset
from asset2sim.tasks.evaluation.evaluate import evaluate_asset
from asset2sim.tasks.ingest.validate_input import Finding, ValidationPolicy, validate_asset
from asset2sim.tasks.refine import RefineError, RefineResult, refine_asset

__all__ = [
    "AuditError", "AuditResult", "Evaluation", "Finding", "RefineConfig", "RefineError", "RefineResult", "RequestOverrides",
    "SimConventions", "audit", "declare_physics", "evaluate", "export", "load_config", "load_mujoco", "load_pybullet", "load_sapien", "make_media", "refine",
    "validate",
]


def load_config(config: RefineConfig | Mapping[str, Any] | str | Path | None) -> RefineConfig:
    """A :class:`RefineConfig` from itself, a mapping of its fields, or a YAML
    file of them; None gives the defaults.

    Raises:
        FileNotFoundError: the YAML file does not exist.
        ValueError: the file is not YAML or not a mapping, or a field is
            unknown, invalid or out of its range, or an engine is unknown (the
            message names the file and the field); an
            :class:`~asset2sim.input_files.InputFileError` (``code``) when the
            file is refused unread or while parsing: a FIFO or device, above
            1 MiB, more than 64 YAML aliases (an anchor bomb), nested deeper
            than 64 levels (:func:`asset2sim.input_files.load_yaml`).
    """
    if config is None:
        return RefineConfig()
    source = "the configuration"
    if isinstance(config, RefineConfig):
        return _known_engines(config, source)
    if isinstance(config, (str, Path)):
        path = Path(config)
        source = str(path)
        if not os.path.lexists(path):
            raise FileNotFoundError(f"{path}: no such configuration file")
        config = load_yaml(path)  # InputFileError (a ValueError with a code): FIFO, too large, aliases ...
        if config is None:
            config = {}
    if not isinstance(config, Mapping):
        raise ValueError(f"{source}: expected a mapping of RefineConfig fields, got {type(config).__name__}")
    try:
        return _known_engines(RefineConfig.model_validate(dict(config)), source)
    except ValidationError as exc:
        raise ValueError(f"{source}: {field_errors(exc)}") from exc


def _known_engines(config: RefineConfig, source: str) -> RefineConfig:
    """``config`` when every engine it lists is known to the registry (installed or not); ValueError naming the
    unknown ones and the known ones otherwise."""
    known = known_engines()
    unknown = [e for e in config.engines if e not in known]
    if unknown:
        raise ValueError(f"{source}: engines: unknown engine(s) {', '.join(unknown)}; known: {', '.join(known)}")
    return config


def merge_overrides(base: RequestOverrides, more: RequestOverrides | Mapping[str, Any]) -> RequestOverrides:
    """``base`` with the fields ``more`` sets replacing its own (``state`` entries added). Raises ValueError
    naming the field when a value of ``more`` is invalid."""
    given = more.model_dump(exclude_none=True, exclude_defaults=True) if isinstance(more, RequestOverrides) else dict(more)
    merged = base.model_dump(exclude_none=True)
    state = {**merged.get("state", {}), **dict(given.pop("state", None) or {})}
    merged.update(given)
    if state:
        merged["state"] = state
    try:
        return RequestOverrides.model_validate(merged)
    except ValidationError as exc:
        raise ValueError(f"overrides: {field_errors(exc)}") from exc


def refine(asset: str | Path, prompt: str = "", out_dir: str | Path = "out", *,
           config: RefineConfig | Mapping[str, Any] | str | Path | None = None,
           overrides: RequestOverrides | Mapping[str, Any] | None = None, task: str | None = None,
           category: str | None = None, force: bool = False, overwrite: bool = False, extras: bool = True,
           media: bool = True, progress: Callable[[str, str], None] | None = None) -> RefineResult:
    """Refine one articulated asset for a natural-language request.

    Writes ``out_dir`` (``mobility.urdf``, meshes, ``initial_state.json``,
    ``overlay.json``, ``report.json`` and, with ``extras``, ``report.html``,
    the MJCF export and renders); the same as ``asset2sim refine``.

    Args:
        asset: a PartNet-Mobility-style folder (``mobility.urdf`` + meshes) or a
            URDF file. Never modified.
        prompt: the request, e.g. "a slightly open stapler" ("" = the
            category's defaults: typical size, closed).
        out_dir: the output folder (created; must not be inside the input).
        config: :class:`RefineConfig`, a mapping of its fields or a YAML file
            (:func:`load_config`).
        overrides: values that win over the prompt's words, as
            :class:`RequestOverrides` or a mapping of its fields: ``mass``
            ("12kg" or kg), ``size`` ("0.5m" or m: the closed object's largest
            extent), ``scale``, ``state`` ({joint name or part label: "30deg",
            "2cm", 0.4 (opening fraction) or "halfway"}), ``mount`` ("fixed" or
            "free"), ``material`` (a ``materials.yaml`` key). They replace the
            configuration's own ``overrides`` field by field (``state`` adds).
        task: a manipulation task ("close the microwave door") the check
            executes with a force-limited gripper.
        category: overrides the asset's own category.
        force: redo even when ``out_dir`` is complete for this input and
            configuration (otherwise the recorded result is returned).
        overwrite: write into a folder that holds files asset2sim did not write.
        extras: also write report.html, the MJCF export and renders.
        media: with ``extras``, also make the renders, clips and report.html (False: the verdict's files and the
            exports only, ``report.media == "deferred"``; :func:`make_media` or ``asset2sim report OUT`` makes them
            later, and a refine with ``media`` over the complete output makes them there).
        progress: called with (stage, message) as the run goes.

    Returns:
        :class:`RefineResult`: ``out_dir``, ``report`` (a pydantic
        :class:`~asset2sim.schemas.report.RefineReport`; ``report.failure_mode``
        is "none" when every check passed), ``overlay``, ``ready`` and
        :meth:`RefineResult.to_json`.

    Raises:
        RefineError: the input, the request, an override (codes
            ``OVERRIDE_*``: unknown joint or part, wrong kind, beyond the
            joint's range, unknown material) or the output folder was refused,
            or the estimator failed (``failure_mode`` and ``codes`` say which);
            ``failure_mode`` ``timeout`` with code ``SIM_STEPS_EXCEEDED`` when its
            simulations passed the cap of one refine
            (:data:`asset2sim.schemas.config.MAX_REFINE_STEPS` steps, every phase
            and engine together).
        ValueError: ``config`` or ``overrides`` is invalid (a unit missing or
            unknown, a negative value, an unknown field, a time step below
            :data:`asset2sim.schemas.config.MIN_TIMESTEP`).
    """
    cfg = load_config(config)
    if overrides:
        cfg = cfg.model_copy(update={"overrides": merge_overrides(cfg.overrides, overrides)})
    return refine_asset(asset, prompt, out_dir, cfg, task=task, category=category, progress=progress,
                        skip_if_complete=not force, overwrite=overwrite, extras=extras, media=media)


def evaluate(asset: str | Path, *, prompt: str | None = None, task: str | None = None,
             reference: str | Path | None = None, engines: tuple[str, ...] | list[str] | None = None,
             category: str | None = None, probes: bool = True, write_to: str | Path | None = None,
             clips: bool = True) -> Evaluation:
    """Evaluate any articulated URDF asset (a refine output or not) with the checks a refine runs: rest stability,
    penetration (mm), oscillation, state hold, the joint sweep, operability, robust rest, the task and the request as
    asked (the verdict: ``failure_mode``), the semantic measures and the probes (reported, never deciding). A refine's
    output folder is checked with the closed ends, request and task its ``report.json`` records, so its verdict is
    the refine's. Nothing is written unless ``write_to`` names a folder.

    Args:
        asset: a folder holding one URDF (``initial_state.json``,
            ``overlay.json``, ``report.json`` beside it are used) or a URDF file.
        prompt: the request graded as asked (None: the one ``report.json`` records, else none).
        task: the manipulation task the task tier performs and the probes try (None: ``report.json``'s, else none).
        reference: a PartNet-Mobility folder with ``reference_gensim2.json``.
        engines: simulators to measure in (``pybullet``, ``physx``, ``mujoco``), the manipulation tiers in each;
            unavailable ones are recorded as skipped. None: as refine checks (the tiers in PyBullet, the rest
            metrics in the engines a refined folder's ``report.json`` names).
        category: overrides the category found beside the asset.
        probes: run the passive probes.
        write_to: folder for ``evaluation.json`` and ``report.html``.
        clips: with ``write_to``, also write the clips of each task-relevant joint's sweep
            (``clips/clips.json``, WebM and PNG; ``docs/guide/outputs.md``) and play them in the report.

    Returns:
        :class:`~asset2sim.schemas.evaluation.Evaluation` (pydantic;
        ``failure_mode``, ``passed``, ``metrics``, ``model_dump_json()``).

    Raises:
        EvaluationError: the asset cannot be evaluated (no URDF, unreadable).
        OutputError: ``write_to`` cannot be written.
    """
    return evaluate_asset(asset, reference=reference, prompt=prompt, engines=None if engines is None else tuple(engines), category=category,
                          out_dir=write_to, write_report=write_to is not None, probes=probes, task=task, clips=clips)


def audit(asset: str | Path, out_dir: str | Path | None = None, *, category: str | None = None,
          simulate: bool = True) -> AuditResult:
    """Audit the physics an asset declares (``asset2sim audit``, ``docs/guide/audit.md``): every mass, density,
    inertia tensor, center of mass, joint damping, friction, spring and limit against asset2sim's estimate and
    the band a real object's value lies in; the rest, robust-rest and sweep checks on the declared and the
    patched physics; with ``out_dir``, ``audit.json``, ``audit.md`` and a patch in the input's format.

    Args:
        asset: a URDF folder or file, an MJCF file, an OpenUSD file, or a folder holding one. Never modified.
        out_dir: where to write (None: nothing written); not inside the input's folder.
        category: the object category (default: from the asset's files and names).
        simulate: run the simulation checks (PyBullet).

    Returns:
        :class:`AuditResult`: ``report`` (``values``: ``where``, ``quantity``, ``declared``, ``estimate``, ``low``,
        ``high``, ``factor``, ``verdict``, ``reason``, ``patched``, SI units; ``checks``; ``patch``;
        ``failure_mode``) and ``out_dir``.

    Raises:
        AuditError: the asset cannot be read, or ``out_dir`` lies inside the input.
    """
    return audit_asset(asset, out_dir, category=category, simulate=simulate)


def validate(asset: str | Path, policy: ValidationPolicy | None = None) -> list[Finding]:
    """The validation findings of an input asset (safe XML, kinematic tree,
    numbers, inertials, mesh paths and contents), as ``asset2sim validate``.

    Args:
        asset: an asset folder, a URDF file, or an MJCF or USD file (every
            file it names checked first: ``MJCF_PATH_ESCAPES``,
            ``USD_LAYER_OUTSIDE_ASSET``, ``INPUT_NOT_REGULAR_FILE`` ...;
            ``docs/guide/validation.md``). Never modified.
        policy: severities and caps (default: the product's).

    Returns:
        :class:`~asset2sim.schemas.report.Finding` list (``code``,
        ``severity``, ``file``, ``where``, ``message``); the asset is refused
        iff one has severity ``error``. Never raises for bad input.
    """
    return validate_asset(asset, policy)


def export(out_dir: str | Path, format: str = "mjcf", *, visuals: bool = True) -> Path:
    """Export a refine output folder to MJCF (``OUT/mjcf/mobility.xml``:
    springs, friction loss, the initial state as keyframe ``initial``) or USD
    with UsdPhysics (``OUT/usd/mobility.usd``), and check the file reads back
    with the same masses, inertias and state.

    Args:
        out_dir: a folder written by :func:`refine`.
        format: ``"mjcf"`` (needs ``mujoco``) or ``"usd"`` (needs ``usd-core``).
        visuals: include the visual meshes.

    Returns:
        The path of the written file.

    Raises:
        ValueError: unknown format, or ``out_dir`` is not an output folder.
        ImportError: the format's package is not installed.
        ExportError / UsdExportError: the export did not read back the same.
    """
    out = _output_folder(out_dir)
    if format not in FORMATS:
        raise ValueError(f"unknown export format {format!r} (mjcf or usd)")
    return FORMATS[format].export(out, visuals=visuals)


def make_media(out_dir: str | Path, *, reference: str | Path | None = None, clips: bool = True,
               force: bool = False) -> dict[str, str]:
    """Make the renders (``views/``), sweep clips (``clips/``) and ``report.html`` of a refine output folder whose
    refine deferred them (``refine(..., media=False)``, ``--defer-media``, a flow with ``extras: deferred``); the
    same as ``asset2sim report OUT``. The verdict in ``report.json`` is kept; the new files join the completion
    marker.

    Args:
        out_dir: a complete folder written by :func:`refine`.
        reference: a PartNet-Mobility folder with GenSim2's reference, shown in the report.
        clips: also write the clips of each task-relevant joint's sweep.
        force: make them again when they are already made.

    Returns:
        What was written (``views``, ``html``, ``clips`` -> path); empty when the media were already made.

    Raises:
        OutputError: ``out_dir`` holds no complete refine output, or cannot be written.
    """
    from asset2sim.tasks.publish.media import make_media as _make_media

    return _make_media(out_dir, reference=reference, clips=clips, force=force)


def _output_folder(out_dir: str | Path) -> RefinedAsset:
    """The output folder ``out_dir``. Raises ValueError: it has no ``mobility.urdf``."""
    asset = RefinedAsset(Path(out_dir))
    if not asset.urdf_path.is_file():
        raise ValueError(f"{asset.folder}: has no {URDF_NAME} (not an asset2sim output folder)")
    return asset


def _load(engine: str, out_dir: str | Path, **attach) -> SimSession:
    asset = _output_folder(out_dir)
    return open_session(engine, asset.urdf_path, asset.session_options(), **attach)


def load_pybullet(out_dir: str | Path, client: int | None = None, *, ground: bool = True) -> SimSession:
    """Load a refine output into PyBullet as asset2sim verified it.

    Joint friction (N or N*m) becomes a zero-target velocity motor, the root
    is welded when mounted, else put on z = 0. Springs act through
    ``session.step()``; when stepping yourself, call
    ``session.apply_passive_forces()`` before each ``pybullet.stepSimulation``.

    Args:
        out_dir: a folder written by :func:`refine`.
        client: a PyBullet physics client id (``pybullet.connect``) to load
            into; its gravity and time step stay yours (the checks used
            -9.81 m/s^2 and 1/240 s). None: a new DIRECT client with those.
        ground: add a plane at z = 0 (the checks' floor); False when your
            world has its own floor there.

    Returns:
        The session (:class:`asset2sim.engines.base.SimSession`): ``cid`` the
        client, ``body`` the body id, ``joint_positions()``, ``step(n)``,
        ``close()`` (removes the body; disconnects only a client it made).

    Raises:
        ValueError: not an output folder.
        RuntimeError: PyBullet cannot load the URDF.
    """
    return _load("pybullet", out_dir, **({} if client is None else {"client": client, "ground": ground}))


def load_sapien(out_dir: str | Path, scene: Any = None, *, ground: bool = True) -> SimSession:
    """Load a refine output into SAPIEN 3 (PhysX) as asset2sim verified it.
    Friction, damping and springs act through ``session.step()``; when
    stepping yourself, call ``session.apply_passive_forces()`` before each
    ``scene.step()``.

    Args:
        out_dir: a folder written by :func:`refine`.
        scene: a ``sapien.Scene`` with a PhysX system to load into; its
            gravity and time step stay yours (the checks used -9.81 m/s^2 and
            1/240 s). None: a new CPU scene with those.
        ground: add a plane at z = 0 (the checks' floor, friction 0.25);
            False when your scene has its own floor there.

    Returns:
        The session: ``scene``, ``art`` (the ``PhysxArticulation``),
        ``step(n)``, ``joint_positions()``, ``close()`` (removes what it
        added to a scene you gave).

    Raises:
        ValueError: not an output folder.
        EngineUnavailable: SAPIEN is not installed (``pip install 'asset2sim[physx]'``).
    """
    return _load("physx", out_dir, **({} if scene is None else {"scene": scene, "ground": ground}))


def declare_physics(articulation: Any, out_dir: str | Path) -> DeclaredPhysics:
    """Give a SAPIEN articulation you built yourself (SAPIEN's ``URDFLoader``, ManiSkill's loader, your own builder) from
    a refine output's ``mobility.urdf`` the physics the output declares, as asset2sim verified it: each movable joint's
    Coulomb friction (N*m or N) and damping through a zero-velocity drive whose force limit is friction + damping *
    |qdot|, springs from ``overlay.json`` as joint forces, PhysX's own joint friction coefficient set to 0. SAPIEN's
    loader reads ``<dynamics friction>`` as that unitless coefficient (a part then moves at about 5 % of its
    friction) and damping as a drive; after this call it breaks away at its friction.

    Call ``declared.before_step()`` before every ``scene.step()``.

    Args:
        articulation: a ``sapien.physx.PhysxArticulation`` whose active joints are the output's movable joints.
        out_dir: a folder written by :func:`refine`.

    Returns:
        The :class:`~asset2sim.engines.passive_joints.DeclaredPhysics` (``before_step()``, ``passive`` the values).

    Raises:
        ValueError: not an output folder, or the articulation's joints are not the file's.
    """
    asset = _output_folder(out_dir)
    return DeclaredPhysics(articulation, asset.model, asset.session_options().springs)


def load_mujoco(out_dir: str | Path) -> SimSession:
    """Load a refine output into MuJoCo as asset2sim verified it (the initial
    state as keyframe ``initial``, a ground plane at z = 0 when not mounted).

    Returns:
        The session: ``m`` (``mujoco.MjModel``), ``d`` (``mujoco.MjData``,
        at the keyframe), ``build.xml`` (the MJCF text); ``mujoco.mj_step(m,
        d)`` steps it as ``session.step()`` does.

    Raises:
        ValueError: not an output folder.
        EngineUnavailable: MuJoCo is not installed (``pip install 'asset2sim[mujoco]'``).
    """
    return _load("mujoco", out_dir)
