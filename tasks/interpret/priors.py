"""The public names of the prior modules (:mod:`asset2sim.prior_tables`, :mod:`.part_labels`, :mod:`.categories`,
:mod:`.part_priors`, :mod:`.size_priors`) in one place. The priors are data (``asset2sim/priors/*.yaml``, SI, each entry
with its source); unknown categories and labels fall back to ``Generic`` and ``labels.yaml`` (``docs/design/priors.md``).
"""

from __future__ import annotations

from asset2sim.prior_tables import GENERIC, GRASPABLE_WIDTH_M, SIZE_CLASSES, PriorsError, load_priors, load_priors_from
from asset2sim.tasks.interpret.categories import category_prior, find_variant, recognize_category, request_category, resolve_category
from asset2sim.tasks.interpret.part_labels import canonical_label
from asset2sim.tasks.interpret.part_priors import (material, material_for, part_role, request_label_matches,
                                                   spring_expected, task_relevant_joints, task_relevant_rank)
from asset2sim.tasks.interpret.size_priors import (MASS_FLOOR_KG, fits_gripper, gripper_limit_factor, mass_range,
                                                   plausible_largest_dimension, scale_mass_range, size_factor, target_size)

__all__ = [
    "GENERIC", "GRASPABLE_WIDTH_M", "MASS_FLOOR_KG", "SIZE_CLASSES", "PriorsError", "canonical_label", "category_prior", "find_variant",
    "fits_gripper", "gripper_limit_factor", "load_priors", "load_priors_from", "mass_range", "material", "material_for", "part_role",
    "plausible_largest_dimension",
    "recognize_category", "request_category", "request_label_matches", "resolve_category", "scale_mass_range", "size_factor",
    "spring_expected", "target_size", "task_relevant_joints", "task_relevant_rank",
]
