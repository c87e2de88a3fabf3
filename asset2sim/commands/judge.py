"""``asset2sim judge``: a vision-language model judges the realism of a pair set's clips (both orders,
verdicts kept only when they agree), calibrated on the planted-defect pairs; with two models of two
families, their agreement (Cohen's kappa). Protocol: docs/guide/realism.md.

Exit status: 0 judged; 1 no pair set or an invalid one; 2 a bad option, a model that cannot be used, or
``MODEL_CALLS_FAILED``: every call to a model failed (its verdicts are still written, each without an answer); 4 the
folder cannot be written."""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

from asset2sim.commands._status import CommandError, check_jobs
from asset2sim.apps.realism.calibration import CALIBRATION_FILE, judge_calibration, write_calibration
from asset2sim.apps.realism.judge import JUDGEMENTS_FILE, find_pair_set, judge_pairs
from asset2sim.apps.realism.scores import SCORES_FILE, judge_scores
from asset2sim.models.config import ClientConfig

NAME = "judge"
HELP = ("Ask vision-language models which clip of each pair looks more realistic (both orders; a verdict kept only "
        "when they agree), calibrate them on the planted-defect pairs and report the agreement between families; "
        "writes judgements.parquet and judge_calibration.json beside pairs.json (docs/guide/realism.md).")

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {0: "judged", 1: "no pair set or an invalid one", 2: "a model that cannot be used, or every call to a model failed",
         4: "the folder cannot be written"}


class _JudgeOption(argparse.Action):
    """``--model`` starts a judge; ``--base-url`` and ``--family`` set the latest one's."""

    def __call__(self, parser, namespace, value, option_string=None):
        # the parser's default [] is set before any option is read
        judges = list(namespace.judges)
        if self.dest == "model":
            judges.append({"model": value})
        elif not judges:
            parser.error(f"{option_string} must follow the --model it belongs to")
        elif self.dest in judges[-1]:
            parser.error(f"{option_string} given twice for --model {judges[-1]['model']}")
        else:
            judges[-1][self.dest] = value
        namespace.judges = judges


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, help="a pair-set folder (with pairs.json), or a folder with realism/pairs.json")
    parser.add_argument("--model", dest="model", action=_JudgeOption, metavar="MODEL", help=(
        "a judge: a litellm model string, provider/name (openai/NAME with --base-url for vLLM or any "
        "OpenAI-compatible server, ollama/NAME, gemini/NAME, ...); repeat for a second judge"))
    parser.add_argument("--base-url", dest="base_url", action=_JudgeOption, metavar="URL",
                        help="server of the --model before it (a local server needs no API key)")
    parser.add_argument("--family", dest="family", action=_JudgeOption, metavar="NAME",
                        help="model family of the --model before it (default: the leading letters of its name)")
    parser.add_argument("--timeout", type=float, metavar="S",
                        help="deadline of one HTTP attempt in seconds: connecting, sending and the whole reply "
                             "(default: ASSET2SIM_LLM_TIMEOUT_S or 120)")
    parser.add_argument("--jobs", type=int, default=4, metavar="N", help="pairs asked at once per model (default 4)")
    parser.set_defaults(judges=[])


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100 * x:.0f} %"


def run(args: argparse.Namespace) -> int:
    judges = args.judges
    if not judges:
        raise CommandError.invalid("MODEL_REQUIRED", "give at least one judge: --model PROVIDER/NAME")
    if args.timeout is not None and not args.timeout > 0:
        raise CommandError.invalid("TIMEOUT_INVALID", f"--timeout must be > 0, got {args.timeout}")
    check_jobs(args.jobs)
    over = {} if args.timeout is None else {"timeout_s": args.timeout}
    try:
        configs = [ClientConfig.from_env(j["model"], j.get("base_url"), **over) for j in judges]
    except ValueError as exc:
        raise CommandError.invalid("MODEL_CONFIG_INVALID", str(exc)) from None
    folder = find_pair_set(args.folder)
    verdicts = judge_pairs(folder, configs, families=[j.get("family") for j in judges], workers=args.jobs)
    cal = judge_calibration(verdicts)
    write_calibration(folder, cal)
    scored = judge_scores(folder, verdicts, cal)
    for m in cal.models:
        print(f"{m.model} (family {m.family}): {m.pairs} pairs, {m.kept} kept ({_pct(m.kept_rate)}), "
              f"{m.orders_without_answer} questions without an answer")
        print(f"  planted defects: caught {m.defect_caught} of {m.defect_pairs} (sensitivity {_pct(m.sensitivity)}; "
              f"{_pct(m.sensitivity_of_kept)} of kept); calibrated: {'yes' if m.calibrated else 'no'} ({m.why})")
        if m.method_wins:
            print("  win rate on plain pairs: " + ", ".join(f"{k} {w.wins}/{w.comparisons}" for k, w in m.method_wins.items()))
        print(f"  {m.calls} model calls, {m.prompt_tokens + m.completion_tokens} tokens ({m.prompt_tokens} prompt + "
              f"{m.completion_tokens} completion), cost ${m.cost_usd:.4f}")
    for k in cal.kappa:
        kappa = "undefined" if k.kappa is None else f"{k.kappa:.2f}"
        print(f"agreement {k.family_1} ({k.model_1}) vs {k.family_2} ({k.model_2}): kappa {kappa} over "
              f"{k.pairs_both_kept} pairs both kept (agreement {_pct(k.agreement)})"
              + (" [same family]" if k.same_family else ""))
    for sc in scored:
        print(f"realism ({sc.source}): {sc.method} {sc.elo:.0f} Elo, strength {sc.strength:+.2f} [{sc.ci_low:+.2f}, {sc.ci_high:+.2f}]")
    print(f"wrote {folder / JUDGEMENTS_FILE} and {folder / CALIBRATION_FILE}"
          + (f"; calibrated models' Bradley-Terry scores in {folder / SCORES_FILE}" if scored else ""))
    silent = _models_without_a_reply(verdicts)
    if silent:
        raise CommandError.invalid("MODEL_CALLS_FAILED", "; ".join(silent) + (
            ": check --model, --base-url and the server (its verdicts are recorded as without an answer)"))
    return 0


def _models_without_a_reply(verdicts) -> list[str]:
    """One line per model every one of whose questions failed (no reply from the server nor the cache)."""
    asked: Counter[str] = Counter()
    failed: Counter[str] = Counter()
    why: dict[str, str] = {}
    for v in verdicts:
        asked[v.model] += 2  # both orders
        failed[v.model] += v.failed_calls
        if v.failed_calls:
            first = v.reason.split(" | B/A: ")[0].removeprefix("A/B: ")  # what the first order's call got
            why.setdefault(v.model, first if len(first) <= 240 else first[:237] + "...")
    return [f"model {m}: all {n} calls failed (e.g. {why.get(m, '')})" for m, n in asked.items() if failed[m] == n]
