"""A manipulation task ("close the microwave door", the manifest's ``task`` column or ``--task``) as
joints, a direction (:func:`~asset2sim.tasks.interpret.task_words.task_verb`) and a target opening fraction; the rules are in
``docs/design/metrics.md``, "Behaviour: passive probes".
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace

from asset2sim.tasks.check.probes import CLOSE_TARGET, OPEN_TARGET
from asset2sim.schemas.asset import AssetDescription
from asset2sim.tasks.interpret.named_parts import labelled_joints
from asset2sim.tasks.interpret.request import parse_prompt
from asset2sim.tasks.interpret.task_words import EVERY, task_verb

@dataclass
class TaskSpec:
    """A parsed task: ``actions`` (``close``, ``open`` or both), ``targets`` action
    -> target opening fraction, the movable ``joints`` it acts on and the ``rule`` that found them."""

    text: str
    actions: tuple[str, ...]
    targets: dict[str, float]
    joints: list[str]
    part: str | None = None
    rule: str = ""
    notes: list[str] = field(default_factory=list)


def parse_task(text: str, asset: AssetDescription, category: str | None, task_joints: list[str]) -> TaskSpec:
    """The :class:`TaskSpec` of ``text`` for ``asset``'s movable joints and part labels; ``task_joints`` the fallback.
    Never raises on unknown words.
    """
    low = " ".join(str(text or "").lower().split())
    action, rest = task_verb(low)
    actions = (action,) if action else ("close", "open")
    targets = {a: (CLOSE_TARGET if a == "close" else OPEN_TARGET) for a in actions}
    spec, err = parse_prompt(f"{rest} closed") if rest else (None, None)
    notes = [f"task words not parsed: {err}"] if err else []
    if action is None:
        notes.append(f"verb of {text!r} has no direction: both directions")
    part = None
    found: list[str] = []
    if spec is not None:
        labels = [js.label for js in spec.joint_states if js.selector == "label" and js.label]
        part = labels[0] if labels else None
        found = list(dict.fromkeys(labelled_joints(spec, asset, category)))
        if any(js.ordinal is not None for js in spec.joint_states):
            notes.append("ordinal read but not used: every joint with the label is tried")
        if spec.ignored:
            notes.append("task words not understood: " + "; ".join(spec.ignored))
        if not labels and not spec.ignored and any(js.selector == "all" for js in spec.joint_states):
            return TaskSpec(text, actions, targets, list(task_joints), None, "whole object: every task-relevant joint", notes)
    if found:
        return TaskSpec(text, actions, targets, found, part, f"part label {part!r} in semantics.txt", notes)
    rule = "fallback: every task-relevant joint" + ("" if action else ", both directions")
    if part:
        notes.append(f"no movable joint's link is labelled {part!r}")
    return TaskSpec(text, actions, targets, list(task_joints), part, rule, notes)


def with_work_to_do(spec: TaskSpec, fractions: dict[str, float]) -> TaskSpec:
    """``spec`` narrowed to the joints it has work on (``docs/design/metrics.md``, probes);
    ``fractions``: joint -> opening fraction at the initial state (missing: has work)."""
    low = " ".join(spec.text.lower().split())
    if len(spec.actions) != 1 or len(spec.joints) < 2 or spec.rule.startswith("fallback") or EVERY.search(low):
        return spec
    if spec.part and re.search(rf"\b{re.escape(spec.part.lower())}(?:s|es)\b", low):
        return spec  # "close the drawers"
    action = spec.actions[0]
    target = spec.targets[action]

    def todo(j: str) -> bool:
        f = fractions.get(j)
        return f is None or (f > target if action == "close" else f < target)

    keep = [j for j in spec.joints if todo(j)]
    if not keep or len(keep) == len(spec.joints):
        return spec
    left = [j for j in spec.joints if j not in keep]
    note = (f"{', '.join(left)} already {'closed' if action == 'close' else 'open'} at the initial state: "
            f"the task acts on {', '.join(keep)}")
    return replace(spec, joints=keep, rule=spec.rule + "; the joints with work to do", notes=[*spec.notes, note])
