"""What a part is made of and what it is for.

:func:`material_for` gives a part's default material (density, shell or
solid, wall thickness, contact friction); :func:`part_role`,
:func:`task_relevant_rank` and :func:`spring_expected` say whether a part is
what tasks act on, the body, an accessory, or spring-returned;
:func:`request_label_matches` says whether a request's part word names a link.
The category's lists in ``categories.yaml`` win over the per-label defaults of
``labels.yaml``; unknown categories use ``Generic``.
"""

from __future__ import annotations

from collections.abc import Sequence

from asset2sim.tasks.interpret.categories import category_prior
from asset2sim.tasks.interpret.part_labels import BODY_LABELS, canonical_label
from asset2sim.prior_tables import MaterialPrior, PartRole, load_priors


def material(key: str) -> MaterialPrior:
    """The material ``key`` of materials.yaml. Raises ``KeyError`` if unknown."""
    mats = load_priors().materials
    if key not in mats:
        raise KeyError(f"unknown material {key!r} (not in materials.yaml)")
    return mats[key]


def material_for(
    category: str, semantic_label: str | None, variant: str | None = None
) -> MaterialPrior:
    """The default material of a part (density kg/m^3, shell, wall m, friction).

    Lookup order: the variant's and then the category's ``part_materials`` for
    the canonical label; body/base/frame (and a missing label) -> the
    variant's or category's ``body_material``; else the label's default in
    ``labels.yaml``; unknown labels -> the category's body material. Unknown
    categories use ``Generic``. Sources: materials.yaml, categories.yaml.
    """
    cat = category_prior(category)
    var = cat.variant(variant) if variant else None
    canon = canonical_label(semantic_label)
    body = (var.body_material if var and var.body_material else None) or cat.body_material
    key: str
    if canon is not None and var is not None and canon in var.part_materials:
        key = var.part_materials[canon]
    elif canon is not None and canon in cat.part_materials:
        key = cat.part_materials[canon]
    elif canon is None or canon in BODY_LABELS:
        key = body
    else:
        lp = load_priors().labels.labels.get(canon)
        key = lp.material if lp is not None else body
    return material(key)



def part_role(category: str, semantic_label: str | None) -> PartRole:
    """Role of a part: ``task`` (its joint state is what a task/request acts on),
    ``body``, ``accessory`` or ``other``.

    The category's ``task_relevant`` and ``accessories`` lists win over the
    per-label defaults of labels.yaml; body/base/frame labels are ``body``.
    """
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
    if lp is None:
        return "other"
    if lp.role == "task" and cat.task_relevant:
        # the category names its task parts; a generic 'task' label not in the
        # list (e.g. a toilet's pump lid) is secondary
        return "other"
    return lp.role


def task_relevant_rank(category: str, semantic_label: str | None) -> int | None:
    """Priority (0 = highest) of a part among the category's task-relevant
    labels, or None if it is not task-relevant. For ``Generic`` (no list) the
    labels.yaml ``task`` role gives rank 0."""
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


def spring_expected(category: str, semantic_label: str | None) -> bool:
    """True when a joint moving this part naturally has a return spring (stapler
    top arm, toaster lever, push buttons). Sources: ``spring_source`` of
    categories.yaml and the header of labels.yaml."""
    canon = canonical_label(semantic_label)
    if canon is None:
        return False
    cat = category_prior(category)
    if canon in cat.spring_labels:
        return True
    lp = load_priors().labels.labels.get(canon)
    return bool(lp and lp.spring)


def request_label_matches(category: str, request_label: str | None, semantic_label: str | None) -> bool:
    """Whether a part word of a request (``JointStateRequest.label``) names a link
    with this semantic label: equal canonical labels, or a category
    ``label_synonyms`` entry (a faucet's "handle" is labelled ``switch``, a
    laptop's "lid" is its ``screen``). When no joint matches, callers should fall
    back to the category's task-relevant joints."""
    a = canonical_label(request_label)
    b = canonical_label(semantic_label)
    if a is None or b is None:
        return False
    if a == b:
        return True
    return b in category_prior(category).label_synonyms.get(a, [])



def task_relevant_joints(category: str, joint_labels: Sequence[tuple[str, str | None]]) -> tuple[list[str], str]:
    """The joints whose moving part tasks manipulate, and the rule that chose
    them, from ``joint_labels`` ((movable joint, its child link's part label
    or None), in the asset's order): the joints of the category's
    task-relevant parts (:func:`task_relevant_rank`, or labels.yaml's
    ``task`` role) ordered by the category's priority; else every joint
    whose part is neither ``body`` nor ``accessory``; else every joint. One
    rule for refine (which states it sets and tasks it checks) and for the
    evaluation of any output that carries its part labels."""
    ranked = []
    for name, label in joint_labels:
        rank = task_relevant_rank(category, label)
        if rank is not None or part_role(category, label) == "task":
            ranked.append((rank if rank is not None else 99, name))
    if ranked:
        return [n for _, n in sorted(ranked, key=lambda t: t[0])], f"the task-relevant parts of {category} (category prior)"
    out = [name for name, label in joint_labels if part_role(category, label) not in ("accessory", "body")]
    if out:
        return out, "every joint of a part that is neither body nor accessory"
    return [name for name, _ in joint_labels], "every movable joint"
