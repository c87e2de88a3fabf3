"""Extras said aloud: a missing optional dependency is one line naming the extra that installs it, never a bare
"No module named ..."; refine's summary names the exports it skipped for one; the README's table lists every extra
of ``pyproject.toml``. A missing module is simulated by ``sys.modules[name] = None`` (Python then refuses the import
as it does for an uninstalled package, with the module's ``name``)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from asset2sim import demo_assets
from asset2sim.cli import main
from asset2sim.extras import EXTRA_OF_MODULE, MissingExtra, import_extra, install_hint

ROOT = Path(__file__).resolve().parents[2]


def pyproject_extras() -> set[str]:
    """The extras of ``pyproject.toml``'s ``[project.optional-dependencies]`` (read as text: Python 3.10 has no tomllib)."""
    text = (ROOT / "pyproject.toml").read_text()
    section = text.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
    return set(re.findall(r"^([A-Za-z][\w-]*)\s*=\s*\[", section, flags=re.M))


def test_every_extra_is_in_the_readme_table_and_every_hint_names_a_real_extra():
    extras = pyproject_extras()
    assert {"mujoco", "usd", "physx", "pipeline", "realism", "newton", "llm", "coacd"} <= extras
    readme = (ROOT / "README.md").read_text()
    rows = [ln.split("|")[1] for ln in readme.splitlines() if ln.startswith("| `[")]  # the extras table's first column
    assert {e for e in extras if not any(f"`[{e}]`" in r for r in rows)} == set()
    assert {extra for _, extra in EXTRA_OF_MODULE.values()} <= extras


def test_a_missing_module_is_one_line_naming_its_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)
    with pytest.raises(MissingExtra) as err:
        import_extra("mujoco", "the MJCF export")
    assert str(err.value) == "the MJCF export: MuJoCo is not installed: pip install 'asset2sim[mujoco]'"
    assert isinstance(err.value, ImportError) and err.value.name == "mujoco"
    assert install_hint(ModuleNotFoundError("No module named 'pxr'", name="pxr")) == \
        "OpenUSD (usd-core) is not installed: pip install 'asset2sim[usd]'"
    assert install_hint(ModuleNotFoundError("No module named 'foo'", name="foo")) == "No module named 'foo'"  # no extra's


def test_auditing_an_mjcf_without_mujoco_names_the_extra(tmp_path, monkeypatch, capsys):
    from tests.formats.test_mjcf_reader import _cabinet_xml

    _cabinet_xml(tmp_path / "in")
    monkeypatch.chdir(tmp_path)  # a short path: the table's cell holds the whole reason
    xml = Path("in") / "cabinet.xml"
    monkeypatch.setitem(sys.modules, "mujoco", None)
    assert main(["audit", str(xml)]) == 1
    cap = capsys.readouterr()
    lines = cap.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"asset2sim audit: AUDIT_FAILED: {xml}: "), cap.err
    assert lines[0].endswith("MuJoCo is not installed: pip install 'asset2sim[mujoco]'"), lines[0]
    for text in (cap.out, cap.err):
        assert "No module named" not in text and "halted" not in text
    assert "pip install 'asset2sim[mujoco]'" in cap.out  # the table's cell: "[mujoco]" is text, not rich markup


def test_refine_names_the_extra_of_each_export_it_skipped(tmp_path, monkeypatch, capsys):
    box = demo_assets.build_box_with_lid(tmp_path / "in" / "box_lid")
    monkeypatch.setitem(sys.modules, "mujoco", None)
    monkeypatch.setitem(sys.modules, "pxr", None)
    assert main(["refine", str(box), "--out", str(tmp_path / "o"), "--no-clips", "-q", "--engines", "pybullet,mujoco"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert "skipped      MJCF export: MuJoCo is not installed: pip install 'asset2sim[mujoco]'" in out, out
    assert "skipped      USD export: OpenUSD (usd-core) is not installed: pip install 'asset2sim[usd]'" in out, out
    engine = [ln for ln in out if ln.startswith("engine mujoco")]
    assert len(engine) == 1 and "skipped" in engine[0] and "pip install 'asset2sim[mujoco]'" in engine[0], out
    assert not any("No module named" in ln or "halted" in ln for ln in out), out


def test_a_command_whose_extra_is_missing_exits_2_with_one_line(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "prefect", None)
    assert main(["flow", "--catalog", str(ROOT / "catalog.yaml"), "--limit", "1"]) == 2
    cap = capsys.readouterr()
    assert cap.err == "asset2sim flow: EXTRA_MISSING: Prefect is not installed: pip install 'asset2sim[pipeline]'\n", cap.err


def test_the_maniskill_module_without_maniskill_names_its_extra(monkeypatch):
    """Without ManiSkill (or without torch, which it needs and is imported first) the module names its extra."""
    for name in ["mani_skill", *(m for m in list(sys.modules) if m.startswith("mani_skill."))]:
        monkeypatch.setitem(sys.modules, name, None)  # as if not installed, also where another test imported it
    monkeypatch.delitem(sys.modules, "asset2sim.apps.learn.maniskill", raising=False)
    with pytest.raises(MissingExtra, match=r"asset2sim\.apps\.learn\.maniskill: (ManiSkill 3|torch) is not installed: "
                                           r"pip install 'asset2sim\[maniskill\]'"):
        import asset2sim.apps.learn.maniskill  # noqa: F401
