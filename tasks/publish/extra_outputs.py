"""A refine's optional outputs beside the refined asset: the MJCF and USD exports, the host files an MJCF or USD
input is written back into, the evaluation and (unless deferred) the media. A failure is a note in the report, never
the loss of the refined asset, except an output folder that cannot be written (``OUTPUT_WRITE_FAILED``)."""

from __future__ import annotations

import errno
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from asset2sim import output_folder
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.extras import install_hint
from asset2sim.inert import one_line
from asset2sim.output_paths import exception_chain, raise_refusal
from asset2sim.output_folder import CLIPS_DIR, VIEWS_DIR
from asset2sim.refined_asset import RefinedAsset
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.report import RefineReport
from asset2sim.stage_log import StageLog
from asset2sim.tasks.tune.attempt import Attempt
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.request_apply import StateResolution
from asset2sim.tasks.evaluation import evaluate
from asset2sim.tasks.evaluation.clips import CLIPS_JSON
from asset2sim.formats import FORMATS, ReadOptions, staging
from asset2sim.formats.mjcf.files import staged_sources
from asset2sim.formats.mjcf.physics import write_host_mjcf
from asset2sim.formats.usd.physics import write_host_usd
from asset2sim.tasks.publish import media as media_phase


#: errno values of an OSError that says nothing more can be written to the
#: output folder: a full disk, an exhausted quota, a read-only file system.
UNWRITABLE = frozenset(e for e in (errno.ENOSPC, getattr(errno, "EDQUOT", None), errno.EROFS) if e is not None)


def raise_if_unwritable(exc: BaseException, out_dir: Path) -> None:
    """Raise ``OUTPUT_WRITE_FAILED`` (an :class:`~asset2sim.output_folder.OutputError`) when ``exc`` or an
    exception in its chain is an OSError whose errno is in :data:`UNWRITABLE`, and the output guard's own
    refusal (``OUTPUT_SYMLINK_ESCAPES``, ``OUTPUT_PATH_ESCAPES``) as it is; return otherwise."""
    raise_refusal(exc)
    for cur in exception_chain(exc):
        if isinstance(cur, OSError) and cur.errno in UNWRITABLE:
            where = cur.filename or out_dir
            raise output_folder.OutputError(f"output folder {out_dir} cannot be written: {where}: {cur.strerror or cur}",
                                            "OUTPUT_WRITE_FAILED", where) from cur


@contextmanager
def _noted(report: RefineReport, out_dir: Path, what: str, named: bool = False) -> Iterator[None]:
    """A failure inside is the note ``what: why`` (``named``: the exception's type first) in ``report``, never the loss
    of the refined asset, except what :func:`raise_if_unwritable` raises."""
    try:
        yield
    except Exception as exc:
        raise_if_unwritable(exc, out_dir)
        report.notes.append(f"{what}: {type(exc).__name__ + ': ' if named else ''}{one_line(exc)}")


def host_files(out_dir: Path, asset: AssetDescription, config: RefineConfig, report: RefineReport) -> dict[str, str]:
    """An MJCF or USD input's refined object written back into its own files (``mjcf/host/``,
    :func:`asset2sim.formats.mjcf.physics.write_host_mjcf`; ``usd/host/``,
    :func:`asset2sim.formats.usd.physics.write_host_usd`), noted in the report; {} for other inputs. A file
    that cannot be written (a rescaled object, MuJoCo or usd-core missing) is a note, never the loss of the refined
    asset."""
    source = asset.staged_from
    write = _HOST_FILES.get(staging.input_format(source)) if source is not None else None
    return write(out_dir, source, asset.urdf_path, config, report) if write is not None else {}


def _host_mjcf(out_dir: Path, source: Path, staged_urdf: Path, config: RefineConfig, report: RefineReport) -> dict[str, str]:
    read = staged_sources(staged_urdf)  # the bytes the reader policy read when the refine began
    if read is None:
        report.notes.append(f"host MJCF not written: the files of {source.name} as read when the refine began are no "
                            "longer at hand (its staged folder is gone); the input is not read a second time")
        return {}
    done = None
    with _noted(report, out_dir, "host MJCF not written"), quiet_stdout():
        done = write_host_mjcf(out_dir, source, ReadOptions(body=config.body, mjcf_angle=config.mjcf.angle),
                               sources=read[0], angle=read[1].get("angle"))
    if done is None:
        return {}
    rel = done.path.relative_to(out_dir).as_posix()
    report.notes.append(f"host MJCF: {rel} is {source.name} with the refined physics (bodies {list(done.bodies)}, joints "
                        f"{list(done.joints)}, keyframe 'initial'), names and geometry as they were; the diff: "
                        f"{done.diff.relative_to(out_dir).as_posix()}"
                        + "".join(f"; {f.relative_to(out_dir).as_posix()}, the package's file with the same physics"
                                  for f in done.files))
    report.notes.extend(f"host MJCF: {note}" for note in done.overrides)
    return {"host_mjcf": str(done.path)}


def _host_usd(out_dir: Path, source: Path, staged_urdf: Path, config: RefineConfig, report: RefineReport) -> dict[str, str]:
    done = None
    with _noted(report, out_dir, "host USD not written"):
        done = write_host_usd(out_dir, source)
    if done is None:
        return {}

    def rel(p: Path) -> str:
        return p.relative_to(out_dir).as_posix()

    report.notes.append(f"host USD: {rel(done.path)} is {source.name} with the refined physics and initial state "
                        f"({done.changes} attributes on {list(done.prims)}), prim paths as they were; the changes alone as a "
                        f"layer: {rel(done.layer)}; prim path -> attribute old -> new: {rel(done.diff)}")
    return {"host_usd": str(done.path), "host_usd_layer": str(done.layer)}


#: Input format -> the writer of its input's own files with the refined physics, noted in the report.
_HOST_FILES = {"mjcf": _host_mjcf, "usd": _host_usd}


def write_extras(out_dir: Path, report: RefineReport, att: Attempt, ctx: EstimationContext, resolution: StateResolution | None,
                 log: StageLog, reference: Path | str | None, shown: Path, clips: bool = True, media: bool = True) -> dict[str, str]:
    """Optional outputs: the MJCF and USD exports, ``evaluation.json`` (the refine's record presented with the semantic
    measures: :func:`asset2sim.tasks.evaluation.evaluate.refined_evaluation`, nothing simulated again) and, with
    ``media``, the renders, the sweep clips (``clips``) and ``report.html`` (without: ``report`` says the media phase is
    deferred, :mod:`asset2sim.tasks.publish.media`). Each failure (an engine or renderer unavailable included) is a note
    in ``report``, never the loss of the refined asset, except a full disk, a quota or a read-only file system
    (``OUTPUT_WRITE_FAILED``); the caller writes ``report.json`` once, after. ``ctx`` and ``resolution``: the refine's
    context and reading of the request; ``shown``: the output folder as the user named it (``out_dir`` may be a
    staging folder). Returns name -> path."""
    out: dict[str, str] = {}
    held = RefinedAsset.held(out_dir, report)  # the exports read the verdict record from memory, not a stale file
    with quiet_stdout():  # engines and renderers print from C; the library must not
        for key, fmt in FORMATS.items():
            with _noted(report, out_dir, f"{fmt.label} export failed"):  # export must not lose the refined asset
                try:
                    out[key] = str(fmt.export(held))
                    report.solver_aids += fmt.aids(Path(out[key]))  # read back from the file as written
                except ImportError as exc:  # MuJoCo / usd-core (pxr) not installed: the extra that would do it named
                    report.notes.append(f"{fmt.label} export skipped: {install_hint(exc)}")
            log.lap(f"extras_{key}")
        ev = views = None
        with _noted(report, out_dir, "evaluation.json failed", named=True):
            made = evaluate.refined_evaluation(ctx, att, report, resolution, out_dir, reference=reference, shown=shown)
            evaluate.write_evaluation(made, out_dir, report=False)
            ev = made
        log.lap("extras_evaluation")
        if media and ev is not None:
            with _noted(report, out_dir, "renders failed"):
                views = media_phase.output_views(out_dir, report.initial_joint_positions)
                out["views"] = str(out_dir / VIEWS_DIR)
            log.lap("extras_render")
            with _noted(report, out_dir, "HTML report failed", named=True):
                out["html"] = str(evaluate.write_media(ev, out_dir, views=views, clips=clips))
                if clips and (out_dir / CLIPS_DIR / CLIPS_JSON).is_file():
                    out["clips"] = str(out_dir / CLIPS_DIR)
            log.lap("extras_report")
    report.media = "done" if media else "deferred"
    if not media:
        report.notes.append(f"{media_phase.DEFERRED_NOTE} (views/, clips/, report.html): `asset2sim report {shown}` makes them")
    return out
