"""``asset2sim refine ASSET --prompt P --out OUT``: refine one asset.

Exit status (:mod:`asset2sim.commands._status`): 0 written and
interaction-ready, 1 invalid input, 2 invalid request (too long), estimator
failure or invalid overlay, 3 written but not interaction-ready, 4 output
location problem (inside or containing the input, not a folder, holding files
asset2sim did not write without ``--overwrite``, not writable, disk full).
"""

from __future__ import annotations

import argparse
import errno
import os
import time
from pathlib import Path

from asset2sim.commands._status import (
    INVALID_INPUT,
    INVALID_REQUEST,
    NOT_READY,
    OUTPUT_LOCATION,
    CommandError,
)
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks import refine as refine_stage
from asset2sim.tasks.interpret.request import RequestTooLong
from asset2sim.tasks.publish.output_folder import OutputError
from asset2sim.tasks.refine import RefineError

NAME = "refine"
HELP = "Refine one asset for a natural-language request into an interaction-ready asset (output folder of the SPEC's contract)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("asset", type=Path, help="asset folder (mobility.urdf + meshes) or a URDF file")
    parser.add_argument("--prompt", "-p", default="", help='the request, e.g. "I want a slightly open stapler."')
    parser.add_argument("--out", "-o", type=Path, required=True, help="output folder (must not be inside the input)")
    parser.add_argument("--category", default=None, help="override the asset's category (meta.json model_cat)")
    parser.add_argument(
        "--estimator",
        default="offline",
        help="overlay estimator: offline (default, no network); llm (any litellm model, e.g. --model gemini/gemini-2.5-flash, "
        "key from the provider's environment variable); openai (an OpenAI-compatible server: --base-url URL --model M). "
        "See docs/model_backends.md",
    )
    parser.add_argument("--model", default=None, help="model for llm/openai: a litellm model string (provider/name) or the server's model name")
    parser.add_argument("--base-url", default=None, help="base URL of an OpenAI-compatible or local server (vLLM, Ollama, llama.cpp); needs no key")
    parser.add_argument(
        "--engines",
        default="pybullet",
        help="comma-separated engines the asset must pass in (pybullet,physx,mujoco); missing ones are skipped and reported",
    )
    parser.add_argument("--force", action="store_true", help="redo even when the output is complete for this input and configuration")
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="write into an output folder that holds files asset2sim did not write (they are kept unless a written file has the same path)",
    )
    parser.add_argument("--no-extras", action="store_true", help="skip MJCF export, renders and the HTML report")
    parser.add_argument("--quiet", "-q", action="store_true", help="print only the summary")


def summary_lines(result) -> list[str]:
    """Human-readable summary of a RefineResult."""
    r = result.report
    pen = r.metric("penetration")
    stab = r.metric("rest_stability")
    osc = r.metric("oscillation")
    state = ", ".join(f"{k}={v:.4g}" for k, v in r.initial_joint_positions.items()) or "(no movable joints)"
    lines = [
        f"asset        {r.asset_id} ({r.category})",
        f"output       {result.out_dir}",
        f"scale        {r.scale:.4g}",
        f"total mass   {r.total_mass:.4g} kg",
        f"initial state {state}  (rad / m)",
        f"penetration  {pen.value:.3f} mm" if pen and pen.value is not None else "penetration  n/a",
        (
            f"stability    {'PASS' if stab.passed else 'FAIL'} (D_pos {stab.details.get('D_pos_m', float('nan')):.2e} m, D_ori {stab.details.get('D_ori_rad', float('nan')):.2e} rad)"
            if stab
            else "stability    n/a"
        ),
        f"oscillation  {'PASS' if osc and osc.passed else 'FAIL'}",
        f"verdict      {'interaction-ready' if r.failure_mode == 'none' else 'FAILED: ' + r.failure_mode}",
    ] + [
        f"engine {row['engine']:<8} {row['status']}: rest {row['rest_stability']}, oscillation {row['oscillation']}, Phi {row['penetration_mm']} mm"
        + (f" ({row['reason']})" if row['reason'] else "")
        for row in r.parity
    ] + [
        "wall time    " + ", ".join(f"{k} {v:.2f}s" for k, v in r.stage_seconds.items()),
    ]
    return lines


def _inside(path: str | os.PathLike | None, folder: Path) -> bool:
    if path is None:
        return False
    p = os.path.abspath(os.fsdecode(path))
    root = os.path.abspath(folder)
    return p == root or p.startswith(root.rstrip(os.sep) + os.sep)


def _refine_failure(exc: Exception, args: argparse.Namespace) -> CommandError:
    """The one-line failure of a refine run: status, code and path."""
    cause = exc.__cause__
    codes = list(getattr(exc, "codes", []) or [])
    mode = getattr(exc, "failure_mode", "invalid_input")
    code = f"{mode}" + (f" [{', '.join(codes)}]" if codes else "")  # e.g. "invalid_input [OUTPUT_INSIDE_INPUT]"
    if isinstance(cause, OutputError):
        return CommandError(OUTPUT_LOCATION, code, cause.path or args.out, str(cause))
    if isinstance(cause, RequestTooLong):
        return CommandError(INVALID_REQUEST, code, args.asset, str(cause))
    status = INVALID_INPUT if mode == "invalid_input" else INVALID_REQUEST
    return CommandError(status, code, args.asset, str(exc))


def _os_failure(exc: OSError, args: argparse.Namespace) -> CommandError:
    """An OSError of a refine run: under the output folder (read-only, full
    disk, permissions) -> status 4, else the input could not be read -> 1."""
    name = errno.errorcode.get(exc.errno or 0, "OSERROR")
    paths = [exc.filename, exc.filename2]
    out = Path(args.out)
    if any(_inside(p, out) for p in paths) or exc.errno in (errno.ENOSPC, errno.EROFS, getattr(errno, "EDQUOT", -1)):
        return CommandError(OUTPUT_LOCATION, f"OUTPUT_WRITE_FAILED [{name}]", exc.filename or args.out, exc.strerror or str(exc))
    return CommandError(INVALID_INPUT, f"INPUT_READ_FAILED [{name}]", exc.filename or args.asset, exc.strerror or str(exc))


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()

    def progress(stage: str, message: str) -> None:
        if not args.quiet:
            print(f"[{time.perf_counter() - t0:6.2f}s] {stage:<12} {message}", flush=True)

    engines = ["pybullet"] + [e.strip() for e in getattr(args, "engines", "pybullet").split(",") if e.strip() and e.strip() != "pybullet"]
    config = RefineConfig(estimator=args.estimator, model=args.model, base_url=args.base_url, engines=engines)
    try:
        result = refine_stage.refine_asset(
            args.asset,
            args.prompt,
            args.out,
            config,
            category=args.category,
            progress=progress,
            skip_if_complete=not args.force,
            extras=not args.no_extras,
            overwrite=getattr(args, "overwrite", False),
        )
    except RefineError as exc:
        raise _refine_failure(exc, args) from exc
    except OutputError as exc:  # e.g. an output file missing at the end: no completion marker
        raise CommandError(OUTPUT_LOCATION, exc.code, exc.path or args.out, str(exc)) from exc
    except OSError as exc:
        raise _os_failure(exc, args) from exc
    for line in summary_lines(result):
        print(line)
    return 0 if result.report.failure_mode == "none" else NOT_READY
