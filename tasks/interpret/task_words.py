"""A manipulation task's words ("close the microwave door", the manifest's ``task`` column or ``--task``): the
leading verb and the direction it asks for (:data:`VERBS`); the joints it names are matched by
:mod:`asset2sim.tasks.check.task_spec` (the rules are in ``docs/design/metrics.md``, "Behaviour: passive probes").
"""

from __future__ import annotations

import re

#: Leading verbs -> action ("close" / "open"); any other verb: both directions.
VERBS: dict[str, str] = {
    "close": "close", "shut": "close", "press": "close", "push down": "close", "lower": "close", "fold": "close",
    "open": "open", "pull": "open", "pull out": "open", "lift": "open", "raise": "open", "unfold": "open",
}

#: Words that make a task act on every joint of its part.
EVERY = re.compile(r"\b(?:all|every|each|both)\b")


def task_verb(low: str) -> tuple[str | None, str]:
    """(action of the leading verb of ``low`` (lower-case task text) or None when it has no direction, the words
    after the verb)."""
    for verb in sorted(VERBS, key=len, reverse=True):
        m = re.match(rf"\s*{re.escape(verb)}\b(.*)$", low)
        if m:
            return VERBS[verb], m.group(1).strip()
    m = re.match(r"\s*(\w+)\b(.*)$", low)
    return None, (m.group(2).strip() if m else low)


def task_actions(text: str | None) -> tuple[str, ...]:
    """The actions of a task's leading verb (:data:`VERBS`); both without a direction or a task."""
    action, _ = task_verb(" ".join(str(text or "").lower().split()))
    return (action,) if action else ("close", "open")
