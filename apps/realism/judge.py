"""The model judge of realism: stills of both clips of a pair shown to a
vision-language model with a fixed rubric, each pair asked in both orders, a
verdict kept only when both orders pick the same method.

Position bias (a judge preferring the first or the second answer whatever it
shows) is the best-documented failure of model judges: Zheng et al. 2023,
"Judging LLM-as-a-Judge with MT-Bench and Chatbot Arena" (NeurIPS Datasets and
Benchmarks), Sec. 3.3, who also propose the remedy used here: ask in both
orders and count only a consistent verdict. Calls go through the one model
client (``LLMClient``: retries, time-outs, the reply cache keyed by the model
and the messages, frames included, and usage); a usable reply is cached, so a
rerun of the same frames, rubric and model makes no call. The protocol and how
to point it at a real model: ``docs/guide/realism.md``; the calibration
on planted defects: :mod:`asset2sim.apps.realism.calibration`.
"""

from __future__ import annotations

import base64
import re
import threading
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path
from typing import Any, Sequence

from asset2sim import atomic, output_folder
from asset2sim.file_names import UnsafePath, join_inside
from asset2sim.models.client import LLMClient
from asset2sim.models.config import ClientConfig
from asset2sim.models.errors import ModelCallError
from asset2sim.models.usage import Usage
from asset2sim.schemas.catalog import model_arrow_schema, parquet_bytes, parquet_models
from asset2sim.schemas.realism import ClipPair, JudgeVerdict, PairSet, PairSide
from asset2sim.apps.realism import pair_set
from asset2sim.apps.realism.judge_reply import Reading, read_reply
from asset2sim.apps.realism.pair_set import PairSetError, find_pair_set  # noqa: F401  (the judge command's)
from asset2sim.inert import one_line
from asset2sim.package_data import package_yaml

#: Version of :data:`RUBRIC` and of the message layout (a new version is a new cache key anyway).
RUBRIC_VERSION = "1"

#: The judge's words, ``judge_prompts.yaml`` beside this module.
_PROMPTS = package_yaml(__package__, "judge_prompts.yaml")
#: The fixed instructions every judge gets (the system message).
RUBRIC: str = _PROMPTS["rubric"]

#: The reply format sent as a strict JSON schema (servers that cannot enforce it get the rubric's words only).
REPLY_SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {"more_realistic": {"type": "string", "enum": ["A", "B"]},
                   "reason": {"type": "string", "description": "one sentence"}},
    "required": ["more_realistic", "reason"],
    "additionalProperties": False,
}

#: What each scripted motion shows, in the words the judge reads (``schemas/realism.py`` ``Motion``).
MOTION_TEXT: dict[str, str] = _PROMPTS["motion_text"]

#: File names beside ``pairs.json``.
PAIRS_FILE = pair_set.PAIRS_JSON
JUDGEMENTS_FILE = "judgements.parquet"
#: Largest frame read, bytes.
MAX_FRAME_BYTES = 16 << 20
_PNG = b"\x89PNG\r\n\x1a\n"

Frames = list[tuple[str, str, bytes]]
"""(view, path, PNG bytes) of the stills of one side (:func:`side_frames`)."""


#: A pair set or frame the judge cannot use (``path`` the file at fault): the pair-set reader's error.
JudgeInputError = PairSetError


def read_pair_set(folder: Path | str) -> PairSet:
    """``folder/pairs.json`` (:func:`asset2sim.apps.realism.pair_set.read_pair_set`), a missing file reported as a
    :class:`JudgeInputError` too.

    Raises:
        JudgeInputError: missing, unreadable, invalid file or a repeated pair id (naming the file).
    """
    try:
        return pair_set.read_pair_set(folder)
    except FileNotFoundError as exc:
        raise JudgeInputError(exc.filename, "cannot be read (no such file)") from None


def side_frames(folder: Path | str, pair: ClipPair, side: str) -> Frames:
    """(view, path, PNG bytes) of every still of one side's clips (``side`` ``a`` or ``b``), in the order
    ``pairs.json`` lists clips and frames; paths are relative to ``folder``.

    Raises:
        JudgeInputError: a side without stills, a path leaving the folder, a missing, unreadable or
            non-PNG frame (naming the frame and the pair).
    """
    folder = Path(folder)
    ps: PairSide = getattr(pair, side)
    out = []
    for clip in ps.clips:
        for rel in clip.frames:
            where = f"pair {pair.pair_id} side {side} ({ps.method}) view {clip.view}"
            try:
                path = join_inside(folder, rel)
                data = atomic.read_regular(path, MAX_FRAME_BYTES)
            except UnsafePath as exc:
                raise JudgeInputError(folder / PAIRS_FILE, f"{where}: frame {rel!r} {exc}") from None
            except OSError as exc:
                raise JudgeInputError(folder / rel, f"{where}: frame cannot be read ({exc.strerror or exc})") from None
            if not data.startswith(_PNG):
                raise JudgeInputError(folder / rel, f"{where}: frame is not a PNG image")
            out.append((clip.view, rel, data))
    if not out:
        raise JudgeInputError(folder / PAIRS_FILE, f"pair {pair.pair_id} side {side} ({ps.method}): no frames to judge")
    return out


# ----------------------------------------------------------------------------- messages
def build_messages(pair: ClipPair, first: Frames, second: Frames) -> list[dict[str, Any]]:
    """The chat messages of one question (OpenAI format): the :data:`RUBRIC` as the system message, then
    one user message: what is shown, ``Video A:`` and the stills of ``first`` (``image_url`` data URIs),
    ``Video B:`` and the stills of ``second``, the question. Neither methods nor file names are shown."""
    parts: list[dict[str, Any]] = [{"type": "text", "text": (
        f"Object: {pair.category or 'unknown category'}. Moving part: joint {pair.joint!r}; "
        f"{MOTION_TEXT.get(pair.motion, pair.motion)}.")}]
    for label, frames in (("Video A", first), ("Video B", second)):
        views = list(dict.fromkeys(v for v, _, _ in frames))
        parts.append({"type": "text", "text": f"{label}: {len(frames)} stills in time order (camera: {', '.join(views)})."})
        parts += [{"type": "image_url", "image_url": {"url": "data:image/png;base64," + base64.b64encode(data).decode("ascii")}}
                  for _, _, data in frames]
    parts.append({"type": "text", "text": 'Which video is more physically realistic? Answer with the JSON object only: '
                                          '{"more_realistic": "A" or "B", "reason": "..."}'})
    return [{"role": "system", "content": RUBRIC}, {"role": "user", "content": parts}]


# ----------------------------------------------------------------------------- asking
def ask_once(client: LLMClient, messages: list[dict[str, Any]]) -> tuple[Reading, Usage]:
    """One question: the reply's :class:`Reading` and what it cost. A usable reply is stored in the client's
    cache; a refusal, unusable prose or a failed call (time-out, HTTP error after the client's retries) is
    no answer and is not cached (a rerun asks again). Raises only what the client raises besides
    :class:`ModelCallError` (e.g. ``LLMUnavailable``) and OSError when the cache cannot be written."""
    try:
        comp = client.complete(messages, schema=REPLY_SCHEMA, schema_name="realism_verdict")
    except ModelCallError as exc:
        return Reading(None, f"call failed: {one_line(exc)}"), Usage(attempts=exc.attempts)
    reading = read_reply(comp.content, finish_reason=comp.finish_reason, refusal=comp.refusal)
    if reading.choice is not None and not comp.cached:
        client.cache_put(comp.key, comp)
    return reading, comp.usage


def judge_pair(client: LLMClient, folder: Path | str, pair: ClipPair, *, family: str | None = None) -> JudgeVerdict:
    """Ask ``client``'s model about one pair in both orders (``a`` as Video A, then ``b`` as Video A) and
    keep the verdict only when both orders pick the same method (side). ``first`` / ``second``: the method
    each order picked (None: no usable answer); ``reason``: the model's reason when kept, else what each
    order said; calls, tokens and cost of both questions (cache hits cost nothing). ``family``: default
    :func:`family_of` the model.

    Raises:
        JudgeInputError: the pair's frames (see :func:`side_frames`).
    """
    fa, fb = side_frames(folder, pair, "a"), side_frames(folder, pair, "b")
    method = {"a": pair.a.method, "b": pair.b.method, None: None}
    picks: list[str | None] = []
    readings: list[Reading] = []
    usage = Usage()
    failed = 0
    for first, second, sides in ((fa, fb, ("a", "b")), (fb, fa, ("b", "a"))):
        reading, u = ask_once(client, build_messages(pair, first, second))
        usage.add(u)
        failed += u.calls == 0 and u.cached == 0  # no reply from the network nor the cache: the call failed
        readings.append(reading)
        picks.append(None if reading.choice is None else sides[0 if reading.choice == "A" else 1])
    kept = picks[0] is not None and picks[0] == picks[1]
    if kept:
        reason = readings[0].reason
    else:
        said = [r.reason[:300] if s is None else f"picked {method[s]}" + (f": {r.reason[:200]}" if r.reason else "")
                for r, s in zip(readings, picks)]
        reason = f"A/B: {said[0]} | B/A: {said[1]}"
    return JudgeVerdict(
        model=client.config.model, family=family or family_of(client.config.model), pair_id=pair.pair_id,
        object_id=pair.object_id, method_a=pair.a.method, method_b=pair.b.method, defect=pair.defect,
        first=method[picks[0]], second=method[picks[1]], kept=kept, winner=method[picks[0]] if kept else None, reason=reason, calls=usage.calls,
        prompt_tokens=usage.prompt_tokens, completion_tokens=usage.completion_tokens, cost_usd=usage.cost_usd or 0.0,
        failed_calls=failed)


def family_of(model: str) -> str:
    """The model family a litellm model string names: the leading letters of its last ``/`` part, lower
    case (``openai/gpt-4o`` -> ``gpt``, ``hosted_vllm/Qwen/Qwen2.5-VL-7B-Instruct`` -> ``qwen``,
    ``ollama/llava:13b`` -> ``llava``, ``gemini/gemini-2.5-flash`` -> ``gemini``); the provider when the
    name starts with no letter."""
    name = model.rsplit("/", 1)[-1].lower()
    m = re.match(r"[a-z]+", name)
    return m.group(0) if m else model.split("/", 1)[0].lower()


def judge_pairs(folder: Path | str, configs: Sequence[ClientConfig], *, families: Sequence[str | None] | None = None,
                workers: int = 1, write: bool = True) -> list[JudgeVerdict]:
    """Every pair of ``folder/pairs.json`` judged by every configured model (rows in config order, then
    pair order); ``families[i]`` names config i's family (None or missing: :func:`family_of`); ``workers``
    pairs asked at once per model. With ``write`` the rows go to ``folder/judgements.parquet`` (atomic),
    rewritten after every verdict, so a run that fails or is stopped keeps the verdicts it reached.
    Every frame is read before the first call.

    Raises:
        JudgeInputError: the pair set or a frame (see :func:`read_pair_set`, :func:`side_frames`).
        OSError: the reply cache or ``judgements.parquet`` cannot be written (raised once every other pair
            of that model is judged and written).
        ValueError: no config, two configs with the same model string (the reply cache keys on it), or
            ``workers`` < 1.
        MissingCredentials, LLMUnavailable: a provider key missing, litellm missing (before any call).
    """
    folder = Path(folder)
    if not configs:
        raise ValueError("judge_pairs needs at least one model configuration")
    models = [c.model for c in configs]
    dupes = sorted({m for m in models if models.count(m) > 1})
    if dupes:
        raise ValueError(f"model {dupes[0]!r} is configured twice: the reply cache keys on the model string, "
                         "so each judge needs its own (give the second another name)")
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    fams = list(families or [])
    ps = read_pair_set(folder)
    for pair in ps.pairs:
        side_frames(folder, pair, "a"), side_frames(folder, pair, "b")
    clients = [LLMClient(c) for c in configs]
    for c in clients:
        c.check_credentials()
    done: dict[tuple[int, int], JudgeVerdict] = {}
    lock = threading.Lock()

    def keep(key: tuple[int, int], verdict: JudgeVerdict) -> None:
        with lock:
            done[key] = verdict
            if write:
                write_judgements(folder, [done[k] for k in sorted(done)])

    for i, client in enumerate(clients):
        family = (fams[i] if i < len(fams) else None) or family_of(client.config.model)
        failure: BaseException | None = None
        with ThreadPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(judge_pair, client, folder, p, family=family): (i, j) for j, p in enumerate(ps.pairs)}
            for future in as_completed(futures):
                try:
                    keep(futures[future], future.result())
                except Exception as exc:  # the others are still judged and written first
                    failure = failure or exc
        if failure is not None:
            raise failure
    verdicts = [done[k] for k in sorted(done)]
    if write and not verdicts:
        write_judgements(folder, verdicts)
    return verdicts


# ----------------------------------------------------------------------------- judgements.parquet
def judgement_schema():
    """The Arrow schema of ``judgements.parquet``: one column per :class:`JudgeVerdict` field, in order."""
    return model_arrow_schema(JudgeVerdict)


def write_judgements(folder: Path | str, verdicts: Sequence[JudgeVerdict]) -> Path:
    """``folder/judgements.parquet`` (rows of :class:`JudgeVerdict`), written atomically. Raises OSError."""
    import pyarrow as pa

    table = pa.Table.from_pylist([v.model_dump() for v in verdicts], schema=judgement_schema())
    with output_folder.guarding(folder):
        return atomic.write_bytes(Path(folder) / JUDGEMENTS_FILE, parquet_bytes(table))


def read_judgements(folder: Path | str) -> list[JudgeVerdict]:
    """The rows of ``folder/judgements.parquet``.

    Raises:
        JudgeInputError: missing or not a judgements file (naming it).
    """
    path = Path(folder) / JUDGEMENTS_FILE
    try:
        return parquet_models(path, JudgeVerdict)
    except (OSError, ValueError) as exc:
        raise JudgeInputError(path, f"not a readable judgements file ({str(exc)[:300]})") from None
