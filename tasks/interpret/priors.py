"""Physical priors as data: categories, materials, part labels, size classes.

The numbers live in ``asset2sim/priors/*.yaml`` (package data), each with its
source. The answers the estimator asks for live in one module per concern;
this module gathers their public names in one place:

- the tables, their models, loading and checks
  (:mod:`~asset2sim.prior_tables`: :func:`load_priors`,
  :func:`load_priors_from`, :class:`PriorsError`);
- canonical part labels (:mod:`~asset2sim.tasks.interpret.part_labels`:
  :func:`canonical_label`);
- which category is this asset (:mod:`~asset2sim.tasks.interpret.categories`:
  :func:`recognize_category`, from the request words, ``meta.json``'s
  ``model_cat`` and the semantic labels; :func:`category_prior`,
  :func:`find_category_mentions`, :func:`find_variant`);
- what a part is made of and what it is for
  (:mod:`~asset2sim.tasks.interpret.part_priors`: :func:`material_for`,
  :func:`part_role`, :func:`spring_expected`, :func:`request_label_matches`);
- how big and how heavy a regular / small / large one is
  (:mod:`~asset2sim.tasks.interpret.size_priors`: :func:`target_size`,
  :func:`mass_range`, :func:`scale_mass_range`).

Units: SI throughout: lengths m, masses kg, densities kg/m^3. Nothing here is
object-specific; unknown categories and labels fall back to the ``Generic``
category and to the per-label defaults of ``labels.yaml``.

Sources of the tables: see each yaml entry and ``docs/design/priors.md``.
"""

from __future__ import annotations

from asset2sim.tasks.interpret.categories import (
    CategoryMatch,
    CategoryMention,
    category_prior,
    find_category_mentions,
    find_variant,
    phrase_regex,
    recognize_category,
    request_category,
    resolve_category,
)
from asset2sim.tasks.interpret.part_labels import BODY_LABELS, canonical_label
from asset2sim.tasks.interpret.part_priors import (
    material,
    material_for,
    part_role,
    request_label_matches,
    spring_expected,
    task_relevant_joints,
    task_relevant_rank,
)
from asset2sim.prior_tables import (
    GENERIC,
    GRASPABLE_WIDTH_M,
    SIZE_CLASSES,
    CategoryPrior,
    CheckedDims,
    Dims,
    LabelPrior,
    LabelTable,
    MassRange,
    MaterialPrior,
    PartRole,
    PriorModel,
    Priors,
    PriorsError,
    SizeClassPrior,
    VariantPrior,
    load_priors,
    load_priors_from,
)
from asset2sim.tasks.interpret.size_priors import (
    MASS_FLOOR_KG,
    SizeTarget,
    fits_gripper,
    gripper_limit_factor,
    mass_range,
    scale_mass_range,
    size_factor,
    target_size,
)

__all__ = [
    "BODY_LABELS",
    "GENERIC",
    "GRASPABLE_WIDTH_M",
    "MASS_FLOOR_KG",
    "SIZE_CLASSES",
    "CategoryMatch",
    "CategoryMention",
    "CategoryPrior",
    "CheckedDims",
    "Dims",
    "LabelPrior",
    "LabelTable",
    "MassRange",
    "MaterialPrior",
    "PartRole",
    "PriorModel",
    "Priors",
    "PriorsError",
    "SizeClassPrior",
    "SizeTarget",
    "VariantPrior",
    "canonical_label",
    "category_prior",
    "find_category_mentions",
    "find_variant",
    "fits_gripper",
    "gripper_limit_factor",
    "load_priors",
    "load_priors_from",
    "mass_range",
    "material",
    "material_for",
    "part_role",
    "phrase_regex",
    "recognize_category",
    "request_category",
    "request_label_matches",
    "resolve_category",
    "scale_mass_range",
    "size_factor",
    "spring_expected",
    "target_size",
    "task_relevant_joints",
    "task_relevant_rank",
]
