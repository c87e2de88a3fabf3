"""What a part is made of and what it is for: the category's lists in
``categories.yaml`` win over the per-label defaults of ``labels.yaml``; unknown
categories use ``Generic``."""

from __future__ import annotations

from collections.abc import Sequence

from asset2sim.tasks.interpret.categories import category_prior
from asset2sim.tasks.interpret.part_labels import BODY_LABELS, canonical_label
from asset2sim.prior_tables import MaterialPrior, PartRole, load_priors
from asset2sim.schemas.asset import AssetDescription


def material_for(
    category: str, semantic_label: str | None, variant: str | None = None
) -> MaterialPrior:
    """The default material of a part: the variant's, then the category's ``part_materials``; body labels
    (and None) the body material; else the label's default in ``labels.yaml``, else the body material."""
    cat = category_prior(category)
    var = cat.variant(variant) if variant else None
    canon = canonical_label(semantic_label)
    body = (var and var.body_material) or cat.body_material
    key: str
    if var is not None and canon in var.part_materials:
        key = var.part_materials[canon]
    elif canon in cat.part_materials:
        key = cat.part_materials[canon]
    elif canon is None or canon in BODY_LABELS:
        key = body
    else:
        lp = load_priors().labels.labels.get(canon)
        key = lp.material if lp is not None else body
    return load_priors().materials[key]  # every key is checked when the tables load



def part_role(category: str, semantic_label: str | None) -> PartRole:
    """Role of a part: ``task`` (what tasks act on), ``body``, ``accessory`` or ``other``."""
    canon = canonical_label(semantic_label)
    if canon is None:
        return "other"
    cat = category_prior(category)
    if canon in cat.task_relevant:
        return "task"
    if canon in BODY_LABELS:
        return "body"
    if canon in cat.accessories:
        return "accessory"
    lp = load_priors().labels.labels.get(canon)
    return "other" if lp is None or (lp.role == "task" and cat.task_relevant) else lp.role  # a 'task' label the list lacks: secondary


def stand_in_joints(category: str, word: str, labelled: Sequence[tuple[str, str | None]]) -> tuple[list[str], str]:
    """Of an object's task-relevant (joint, part label) pairs, the joints a part ``word`` it has no part of
    still names, and how: the unlabelled ones (the word may name them), else all of them when ``word`` is a
    task-relevant part of ``category`` ranked above every one (the object lacks the category's main part,
    which its dataset labels otherwise: a dishwasher's only door labelled "shelf"); ([], "") when none does."""
    free = [j for j, label in labelled if not label]
    if free:
        return free, "its unlabelled task-relevant joints"
    rank = task_relevant_rank(category, word)
    ranks = [task_relevant_rank(category, label) for _, label in labelled]
    if rank is not None and ranks and all(r is not None and r > rank for r in ranks):
        names = ", ".join(dict.fromkeys(str(label) for _, label in labelled))
        return [j for j, _ in labelled], f"its task-relevant parts ({names}), which stand in for a {category}'s {word}:"
    return [], ""


def task_relevant_rank(category: str, semantic_label: str | None) -> int | None:
    """Priority (0 = highest) among the category's task-relevant labels (without a list: the ``task`` role
    ranks 0), or None."""
    canon = canonical_label(semantic_label)
    if canon is None:
        return None
    cat = category_prior(category)
    if canon in cat.task_relevant:
        return cat.task_relevant.index(canon)
    if not cat.task_relevant:
        lp = load_priors().labels.labels.get(canon)
        if lp is not None and lp.role == "task":
            return 0
    return None


#: Canonical part labels nobody operates by hand (a wheel rolls on the floor).
NOT_HANDLED_LABELS = frozenset({"wheel"})


def handled(semantic_label: str | None) -> bool:
    """Whether a part with this label is operated by hand: every part but :data:`NOT_HANDLED_LABELS`; an
    unlabelled part counts as handled."""
    return canonical_label(semantic_label) not in NOT_HANDLED_LABELS


def spring_expected(category: str, semantic_label: str | None) -> bool:
    """True when a joint moving this part naturally has a return spring (a toaster lever, push buttons)."""
    canon = canonical_label(semantic_label)
    if canon is None:
        return False
    lp = load_priors().labels.labels.get(canon)
    return canon in category_prior(category).spring_labels or bool(lp and lp.spring)


def push_buttons(asset: AssetDescription, category: str | None) -> frozenset[str]:
    """Prismatic joints of ``asset`` (a :class:`~asset2sim.schemas.asset.AssetDescription` of a ``category`` object,
    None: none known) whose part a press moves into the body and a return spring brings back (:func:`spring_expected`:
    push buttons and keys in any category, a category's spring-returned slides such as a pump's head or a toaster's
    carriage lever): such a part rests where it stands out of its body, its closed end
    (:func:`~asset2sim.tasks.geometry.closed_state.closed_positions` ``pushed``)."""
    return frozenset(j.name for j in asset.movable_joints()
                     if j.type == "prismatic" and spring_expected(category or "", asset.link(j.child).semantic_label))


def request_label_matches(category: str, request_label: str | None, semantic_label: str | None) -> bool:
    """Whether a request's part word names a link with this label: equal canonical labels, or a category
    ``label_synonyms`` entry (a laptop's "lid" is its ``screen``)."""
    a = canonical_label(request_label)
    b = canonical_label(semantic_label)
    return a is not None and b is not None and (a == b or b in category_prior(category).label_synonyms.get(a, []))



def named_by_word(category: str, word: str | None, labels: Sequence[str | None]) -> tuple[list[int], str]:
    """(indices of ``labels`` a request's part ``word`` names, how): those :func:`request_label_matches` finds (the
    word's own label or the category's ``label_synonyms``; how "" for its own label), else those of the first label of the word's
    ``words`` entry in ``labels.yaml`` that any of ``labels`` carries (how: "'lever' = the 'slider' (synonym
    table ...)"); ([], "") when none."""
    hit = [i for i, lab in enumerate(labels) if request_label_matches(category, word, lab)]
    canon = [canonical_label(lab) for lab in labels]
    w = canonical_label(word)
    if hit or word is None:
        other = list(dict.fromkeys(str(canon[i]) for i in hit if canon[i] != w))
        return hit, (f"'{word}' = the '{', '.join(other)}' (a {category}'s synonym: asset2sim/priors/categories.yaml label_synonyms)"
                     if other else "")
    for target in load_priors().labels.words.get(str(w), []):
        hit = [i for i, c in enumerate(canon) if c == target]
        if hit:
            return hit, f"'{word}' = the '{target}' (no part is labelled '{w}'; synonym table asset2sim/priors/labels.yaml: words)"
    return [], ""


def task_relevant_joints(category: str, joint_labels: Sequence[tuple[str, str | None]]) -> tuple[list[str], str]:
    """(joints whose part tasks manipulate, the rule) from ``joint_labels`` ((joint, part label or None)):
    the task-relevant parts by priority; else every joint of neither body nor accessory; else every joint."""
    ranked = [(99 if rank is None else rank, name) for name, label in joint_labels
              if (rank := task_relevant_rank(category, label)) is not None or part_role(category, label) == "task"]
    if ranked:
        return [n for _, n in sorted(ranked, key=lambda t: t[0])], f"the task-relevant parts of {category} (category prior)"
    out = [name for name, label in joint_labels if part_role(category, label) not in ("accessory", "body")]
    if out:
        return out, "every joint of a part that is neither body nor accessory"
    return [name for name, _ in joint_labels], "every movable joint"
