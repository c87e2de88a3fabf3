"""The movable-joint cap (``URDF_TOO_MANY_MOVABLE_JOINTS``, benchmarks/bench_joint_cap.py)."""

from __future__ import annotations

from asset2sim.tasks.ingest import findings
from asset2sim.tasks.ingest import validate_input as vi
from tests import corpus_builder as cb


def _revolute_chain(n: int):
    """Hang ``n`` small links on revolute joints (+-0.5 rad) under the handle."""

    def fn(m: cb.Model) -> None:
        prev = "handle"
        for i in range(n):
            m.links.append(cb.Link(f"chain_{i}", inertial=cb.Inertial(mass="0.01", ixx="1e-6", iyy="1e-6", izz="1e-6")))
            m.joints.append(cb.Joint(f"chain_joint_{i}", "revolute", prev, f"chain_{i}", xyz="0 0 0.001",
                                     axis="1 0 0", lower="-0.5", upper="0.5"))
            prev = f"chain_{i}"

    return fn


def test_default_cap():
    assert vi.DEFAULT_POLICY.max_movable_joints == findings.MAX_MOVABLE_JOINTS == 32
    # a warning: objects with many keys or buttons rarely have touching links and refine far faster
    # than the worst case; the flow's per-asset time limit is the hard bound
    assert findings.CODES["URDF_TOO_MANY_MOVABLE_JOINTS"].severity == "warning"


def test_movable_joint_cap_is_exact(tmp_path):
    base = cb.valid_model()
    n_base = sum(1 for j in base.joints if j.type in ("revolute", "prismatic", "continuous"))
    n_extra = findings.MAX_MOVABLE_JOINTS - n_base
    ok = vi.validate_asset(cb._model_case(_revolute_chain(n_extra))(tmp_path / "ok"))
    assert not vi.has_errors(ok), [f.describe() for f in ok if f.severity == "error"]
    over = vi.validate_asset(cb._model_case(_revolute_chain(n_extra + 1))(tmp_path / "over"))
    assert not vi.has_errors(over)
    hits = [f for f in over if f.code == "URDF_TOO_MANY_MOVABLE_JOINTS"]
    assert len(hits) == 1 and hits[0].values == {"joints": findings.MAX_MOVABLE_JOINTS + 1, "cap": findings.MAX_MOVABLE_JOINTS}
    # fixed joints do not count
    fixed = vi.validate_asset(cb._model_case(cb._chain(n_extra + 20))(tmp_path / "fixed"))
    assert "URDF_TOO_MANY_MOVABLE_JOINTS" not in {f.code for f in fixed}
