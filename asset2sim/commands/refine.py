"""``asset2sim refine ASSET --prompt P --out OUT``: refine one asset."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

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


def run(args: argparse.Namespace) -> int:
    from asset2sim.schemas.config import RefineConfig
    from asset2sim.tasks.refine import RefineError, refine_asset

    t0 = time.perf_counter()

    def progress(stage: str, message: str) -> None:
        if not args.quiet:
            print(f"[{time.perf_counter() - t0:6.2f}s] {stage:<12} {message}", flush=True)

    engines = ["pybullet"] + [e.strip() for e in getattr(args, "engines", "pybullet").split(",") if e.strip() and e.strip() != "pybullet"]
    config = RefineConfig(estimator=args.estimator, model=args.model, base_url=args.base_url, engines=engines)
    try:
        result = refine_asset(
            args.asset,
            args.prompt,
            args.out,
            config,
            category=args.category,
            progress=progress,
            skip_if_complete=not args.force,
            extras=not args.no_extras,
        )
    except RefineError as exc:
        print(f"asset2sim refine: {exc.failure_mode}: {exc}", file=sys.stderr)
        return 2
    for line in summary_lines(result):
        print(line)
    return 0
