"""The media phase of an output folder: renders of the initial state (``views/``), the sweep clips (``clips/``) and
``report.html``.

An output is made in two phases. The first writes what a verdict and a simulator need (``mobility.urdf`` with its
meshes and collision pieces, ``initial_state.json``, ``overlay.json``, ``report.json``, ``evaluation.json``, the MJCF
and USD exports); the second, the media, is for people. A single ``refine`` makes both; ``refine --defer-media`` and a
flow with ``extras: deferred`` stop after the first, and :func:`make_media` (``asset2sim report OUT``) makes the media
later from the folder alone. The media phase never changes a verdict: ``report.json`` keeps its metrics and failure
mode (only its ``media`` field becomes ``done``) and ``evaluation.json`` is not rewritten; the new files join the
completion marker, so the folder stays complete for its input and configuration.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from asset2sim import atomic, output_folder
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.inert import one_line
from asset2sim.output_folder import CLIPS_DIR, MARKER_NAME, RECORD_NAME, REPORT_HTML_NAME, REPORT_NAME, URDF_NAME, VIEWS_DIR, VOLATILE
from asset2sim.output_paths import OutputError, raise_refusal
from asset2sim.tasks.evaluation import evaluate
from asset2sim.tasks.evaluation.clips import CLIPS_JSON
from asset2sim.tasks.geometry import render
from asset2sim.tasks.publish.contract import read_report_json, verify_output, write_report_json

__all__ = ["DEFERRED_NOTE", "media_pending", "make_media", "output_views"]

#: How the note ``report.json`` carries while the media phase is deferred begins.
DEFERRED_NOTE = "media deferred"


def output_views(out_dir: Path | str, state: dict[str, float]) -> dict[str, np.ndarray]:
    """Render the SPEC's five views of the output's ``mobility.urdf`` at ``state`` (joint -> rad or m) into
    ``out_dir/views/<view>.png`` (:data:`asset2sim.tasks.geometry.render.OUTPUT_VIEW_SIZE` pixels). Returns view ->
    (H, W, 3) uint8. Raises what the renderer raises (no renderer, unreadable meshes)."""
    out_dir = Path(out_dir)
    return render.render_views(out_dir / URDF_NAME, state, out_dir / VIEWS_DIR, size=render.OUTPUT_VIEW_SIZE)


def media_pending(out_dir: Path | str) -> bool:
    """True when ``out_dir``'s ``report.json`` says its media phase was deferred (False when it is done, off,
    unrecorded or the report cannot be read)."""
    try:
        report = read_report_json(out_dir)
    except (OSError, ValueError):
        return False
    return report.media == "deferred"


def make_media(out_dir: Path | str, *, reference: Path | str | None = None, clips: bool = True,
               force: bool = False) -> dict[str, str]:
    """Make the media of a complete output folder: ``views/``, ``clips/`` (with ``clips``) and ``report.html``, from the
    folder's own files (its checks run again to draw the report's evidence: :func:`asset2sim.tasks.evaluation.evaluate.recorded_evaluation`;
    the verdict and every measurement shown are the ones ``evaluation.json`` and ``report.json`` record). ``reference``: a PartNet-Mobility folder with the GenSim2 reference, as for refine;
    ``force``: make them again when ``report.json`` says they are done.

    Returns:
        What was written: ``views``, ``html``, ``clips`` -> path; empty when the media were already done. A render or
        clip that cannot be drawn is a note in ``report.json`` (never a lost output).

    Raises:
        OutputError: ``OUTPUT_INCOMPLETE`` before any file is opened when ``out_dir`` does not verify against its
            completion marker (:func:`~asset2sim.tasks.publish.contract.verify_output`: an entry outside the folder,
            missing, not a regular file or changed since) or holds no usable ``report.json`` (a NaN named by its
            field); ``OUTPUT_SYMLINK_ESCAPES`` for a write through a symlink; ``OUTPUT_WRITE_FAILED`` when it cannot
            be written. A failure part way leaves ``report.json`` as it was and the marker matching the files.
    """
    out_dir = Path(out_dir)
    head = verify_output(out_dir)  # before any engine or renderer opens a file of it
    try:
        report_bytes = atomic.read_regular(out_dir / REPORT_NAME, output_folder.MAX_RECORD_BYTES)
        report = read_report_json(out_dir)
    except (OSError, ValueError) as exc:
        raise OutputError(f"{out_dir} holds no usable report.json ({one_line(exc)}); refine it again (--force)",
                          "OUTPUT_INCOMPLETE", out_dir / REPORT_NAME) from exc
    if report.media == "done" and (out_dir / REPORT_HTML_NAME).is_file() and not force:
        return {}
    out: dict[str, str] = {}
    try:
        with output_folder.adopting(out_dir) as owner, quiet_stdout():  # renderers print from C; the library must not
            views = None
            try:
                views = output_views(out_dir, dict(report.initial_joint_positions))
                out["views"] = str(out_dir / VIEWS_DIR)
            except Exception as exc:  # a renderer unavailable: the report without its renders
                raise_refusal(exc)  # but never a write the output guard refused
                report.notes.append(f"renders failed: {one_line(exc)}")
            out["html"] = str(evaluate.write_media(evaluate.recorded_evaluation(out_dir, reference=reference), out_dir,
                                                   views=views, clips=clips))
            if clips and (out_dir / CLIPS_DIR / CLIPS_JSON).is_file():
                out["clips"] = str(out_dir / CLIPS_DIR)
            report.media = "done"
            report.notes = [n for n in report.notes if not n.startswith(DEFERRED_NOTE)]
            added = set(getattr(owner, "files", ()))
            write_report_json(out_dir, report)
        _extend_marker(out_dir, head, added)
    except BaseException:
        with contextlib.suppress(OSError, ValueError):  # the failure itself is what the caller hears of
            _keep_consistent(out_dir, head, report_bytes)
        raise
    return out


def _keep_consistent(out_dir: Path, head: dict, report_bytes: bytes) -> None:
    """After a media phase that failed part way: ``report.json`` as it was, and the completion marker listing the
    files it listed with their bytes now (a render it replaced rehashed; one no longer a regular file dropped), so
    the folder never disagrees with its own marker."""
    try:
        if atomic.read_regular(out_dir / REPORT_NAME, output_folder.MAX_RECORD_BYTES) != report_bytes:
            atomic.write_bytes(out_dir / REPORT_NAME, report_bytes)
    except OSError:
        atomic.write_bytes(out_dir / REPORT_NAME, report_bytes)
    files = {}
    for rel in head["files"]:
        try:
            files[rel] = atomic.sha256_file(out_dir / rel)
        except OSError:
            continue
    atomic.write_json(out_dir / MARKER_NAME, {**{k: v for k, v in head.items() if k != "files"}, "files": files})


def _extend_marker(out_dir: Path, head: dict, added: set[str]) -> None:
    """Rewrite the completion marker ``head`` of ``out_dir`` with the SHA-256 of every file it listed and of
    ``added`` (relative paths written since), then drop the ownership record the writes left."""
    files = sorted(set(head["files"]) | {r for r in added if (out_dir / r).is_file() and r not in VOLATILE})
    atomic.write_json(out_dir / MARKER_NAME, {**{k: v for k, v in head.items() if k != "files"},
                                              "files": {r: atomic.sha256_file(out_dir / r) for r in files}})
    (out_dir / RECORD_NAME).unlink(missing_ok=True)
