"""Objects as robosuite, Meta-World and gymnasium-robotics (Franka Kitchen) ship them, refined from the installed package's own files (skipped where the
package is not installed: neither is a dependency of asset2sim). Nothing of the package is imported; its files are
found where Python would import it from."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
from pathlib import Path

import pytest

mujoco = pytest.importorskip("mujoco")

from asset2sim.schemas.config import RefineConfig  # noqa: E402
from asset2sim.formats.mjcf.conventions import package_tree  # noqa: E402
from asset2sim.tasks.refine import refine_asset  # noqa: E402
from asset2sim.urdf import read_urdf  # noqa: E402

CONFIG = RefineConfig(engines=["pybullet"])


def _package_file(package: str, rel: str) -> Path:
    spec = importlib.util.find_spec(package)
    if spec is None or not spec.submodule_search_locations:
        pytest.skip(f"{package} is not installed (pip install {package}; not a dependency of asset2sim)")
    path = Path(list(spec.submodule_search_locations)[0]) / rel
    if not path.is_file():
        pytest.skip(f"this {package} has no {rel}")
    return path


KITCHEN = "envs/assets/kitchen_franka/kitchen_assets/kitchen_env_model.xml"


@pytest.mark.parametrize("package, rel, prompt, body", [
    ("robosuite", "models/assets/objects/door.xml", "A door, slightly open.", None),
    ("metaworld", "assets/objects/drawer.xml", "A drawer, slightly open.", None),
    ("metaworld", "assets/objects/faucet.xml", "A faucet.", None),
    ("metaworld", "assets/objects/lever.xml", "A lever.", None),
    ("metaworld", "assets/objects/coffeemachine.xml", "A coffee machine.", None),
    ("metaworld", "assets/objects/doorlockA.xml", "A door lock.", None),
    ("gymnasium_robotics", KITCHEN, "A microwave, door slightly open.", "microwave"),
], ids=lambda v: Path(v).stem if "/" in str(v) else None)
def test_a_package_object_is_refined_interaction_ready_at_its_size_in_its_unit(tmp_path, package, rel, prompt, body):
    xml = _package_file(package, rel)
    res = refine_asset(xml, prompt, tmp_path / "out", CONFIG.model_copy(update={"body": body}), extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    assert json.loads((res.out_dir / "overlay.json").read_text())["scale"] == 1.0
    spec = mujoco.MjSpec.from_file(str(xml))
    spec.compiler.degree = False  # both packages compile these files with radians
    compiled = spec.compile()
    model = read_urdf(res.out_dir / "mobility.urdf")
    for j in model.movable_joints:
        jid = mujoco.mj_name2id(compiled, mujoco.mjtObj.mjOBJ_JOINT, j.name)
        if jid >= 0 and compiled.jnt_limited[jid]:
            lo, hi = compiled.jnt_range[jid]
            assert lo - 1e-9 <= j.limit.lower <= j.limit.upper <= hi + 1e-9, (j.name, (j.limit.lower, j.limit.upper), (lo, hi))
            assert j.limit.upper - j.limit.lower > 0.5 * (hi - lo), j.name  # clipped by the geometry at most
    assert (res.out_dir / "mjcf" / "host" / xml.name).is_file()
    # the package's files holding the object written again, as the package wrote them (robosuite's door.xml, or the
    # objects/assets/<name>.xml a Meta-World scene includes): the package's tree (linked) with them in place
    # compiles the input scene with the refined masses, as the package's environments would
    files = res.out_dir / "mjcf" / "host" / "files"
    written = sorted(files.rglob("*.xml"))
    assert written, res.report.notes
    tree = package_tree(xml)
    copy = tmp_path / "swapped" / tree.name
    shutil.copytree(tree, copy, copy_function=os.symlink)
    for f in written:
        (copy / f.relative_to(files)).unlink()
        shutil.copyfile(f, copy / f.relative_to(files))
    spec = mujoco.MjSpec.from_file(str(copy / xml.relative_to(tree)))
    spec.compiler.degree = False
    swapped = spec.compile()
    for name, link in model.links.items():
        b = mujoco.mj_name2id(swapped, mujoco.mjtObj.mjOBJ_BODY, name)
        if b > 0 and link.inertial is not None and compiled.body_geomnum[b] > 0:
            assert swapped.body_mass[b] == pytest.approx(link.inertial.mass, rel=1e-5), name
