"""Bounded configuration: a ``--config`` file is read as a regular file under a cap without blocking, its YAML
built with aliases, depth and expanded size capped, every numeric field in a range and every engine known; a
refusal is a named code, quickly. The files are generated here (FIFOs, a symlink to ``/dev/zero``, anchor
bombs); calls that could block run under an alarm or in a child process with a time-out."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from asset2sim import cli
from asset2sim.api import load_config
from asset2sim.input_files import InputFileError, load_yaml
from asset2sim.schemas.config import MAX_MEASUREMENT_STEPS, RefineConfig, SimConventions
from tests.helpers import no_hang

HANG_LIMIT_S = 20


def _no_hang(seconds: int = HANG_LIMIT_S):
    """:func:`tests.helpers.no_hang` with this module's limit."""
    return no_hang(seconds)


def _bomb(levels: int, width: int = 9) -> str:
    """An anchor bomb under overrides.state: ``width ** levels`` leaves from ``levels * width`` aliases."""
    lines = ["a0: &a0 [" + ", ".join(["lol"] * width) + "]"]
    for i in range(1, levels + 1):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * width) + "]")
    lines.append(f"overrides: {{state: {{lid: *a{levels}}}}}")
    return "\n".join(lines) + "\n"


def _refused(path: Path, code: str) -> InputFileError:
    with _no_hang():  # the bomb refused, not expanded (an expansion would hang past the guard)
        with pytest.raises(InputFileError) as info:
            load_config(path)
    assert info.value.code == code, str(info.value)
    assert str(path) in str(info.value)
    return info.value


def test_a_config_fifo_is_refused_without_blocking(tmp_path):
    os.mkfifo(tmp_path / "config.yaml")
    _refused(tmp_path / "config.yaml", "INPUT_NOT_REGULAR_FILE")


def test_a_config_symlink_to_dev_zero_is_refused_unread(tmp_path):
    os.symlink("/dev/zero", tmp_path / "config.yaml")
    _refused(tmp_path / "config.yaml", "INPUT_NOT_REGULAR_FILE")


def test_a_config_above_the_cap_is_refused_unread(tmp_path):
    with open(tmp_path / "config.yaml", "wb") as fh:
        fh.truncate(2 * 1024 * 1024)
    _refused(tmp_path / "config.yaml", "INPUT_TOO_LARGE")


def test_an_anchor_bomb_under_overrides_state_is_refused_quickly(tmp_path):
    (tmp_path / "many.yaml").write_text(_bomb(10))  # 90 aliases
    _refused(tmp_path / "many.yaml", "YAML_ALIAS_LIMIT")
    (tmp_path / "few.yaml").write_text(_bomb(6))  # 54 aliases, 9^6 = 531,441 leaves
    err = _refused(tmp_path / "few.yaml", "YAML_ALIAS_LIMIT")
    assert "expand" in str(err)
    (tmp_path / "loop.yaml").write_text("overrides: &o {state: {lid: *o}}\n")
    _refused(tmp_path / "loop.yaml", "YAML_ALIAS_LIMIT")


def test_yaml_nested_too_deep_is_refused(tmp_path):
    (tmp_path / "deep.yaml").write_text("x: " + "[" * 200 + "]" * 200 + "\n")
    _refused(tmp_path / "deep.yaml", "YAML_TOO_DEEP")


def test_a_few_aliases_still_load(tmp_path):
    (tmp_path / "ok.yaml").write_text("base: &b {timestep: 0.005}\nsim: *b\nseed: 3\n")
    data = load_yaml(tmp_path / "ok.yaml")
    assert data["sim"] == {"timestep": 0.005}
    (tmp_path / "cfg.yaml").write_text("sim: {timestep: 0.005, settle_time: 0.5}\nengines: [pybullet]\n")
    cfg = load_config(tmp_path / "cfg.yaml")
    assert cfg.sim.timestep == 0.005 and cfg.engines == ["pybullet"]


@pytest.mark.parametrize("sim, field", [
    ({"timestep": 0}, "sim.timestep"),
    ({"timestep": -0.01}, "sim.timestep"),
    ({"timestep": float("nan")}, "sim.timestep"),
    ({"settle_time": 1e7}, "sim.settle_time"),
    ({"test_time": float("inf")}, "sim.test_time"),
    ({"gravity": float("nan")}, "sim.gravity"),
    ({"timestep": 1e-5, "settle_time": 30}, "sim"),
    ({"oscillation_sign_changes": 0}, "sim.oscillation_sign_changes"),
])
def test_simulation_values_out_of_range_are_refused(sim, field):
    with pytest.raises(ValueError) as info:
        load_config({"sim": sim})
    assert field in str(info.value)


@pytest.mark.parametrize("values, field", [
    ({"max_state_evaluations": 10**9}, "max_state_evaluations"),
    ({"max_escalation_rounds": -1}, "max_escalation_rounds"),
    ({"escalation_factor": 0.5}, "escalation_factor"),
    ({"penetration_tolerance": float("inf")}, "penetration_tolerance"),
    ({"max_decompositions": 10**6}, "max_decompositions"),
    ({"engines": []}, "engines"),
])
def test_counts_and_tolerances_out_of_range_are_refused(values, field):
    with pytest.raises(ValueError) as info:
        load_config(values)
    assert field in str(info.value)


def test_the_step_cap_bounds_a_measurement():
    with pytest.raises(ValueError):
        SimConventions(timestep=1e-4, settle_time=10.0, test_time=20.0)
    ok = SimConventions()
    assert (ok.settle_time + ok.test_time) / ok.timestep <= MAX_MEASUREMENT_STEPS


def test_an_unknown_engine_is_named_with_the_known_ones(tmp_path):
    (tmp_path / "cfg.yaml").write_text("engines: [nosuch, pybullet]\n")
    with pytest.raises(ValueError) as info:
        load_config(tmp_path / "cfg.yaml")
    assert "nosuch" in str(info.value) and "pybullet" in str(info.value) and "known" in str(info.value)
    with pytest.raises(ValueError, match="nosuch"):
        load_config(RefineConfig(engines=["nosuch"]))


def test_the_hash_of_the_default_configuration_is_unchanged():
    """The ranges change no valid configuration's hash (catalog rows and completed outputs stay valid)."""
    assert RefineConfig(engines=["pybullet"]).config_hash() == "4d3323857260543d"  # as before the ranges
    assert RefineConfig(engines=["pybullet", "mujoco"], seed=3).config_hash() == "aa86e340cefe7bcd"


def test_refine_refuses_hostile_configs_with_named_codes(tmp_path, capsys):
    asset = tmp_path / "asset"
    asset.mkdir()
    cases = {}
    os.symlink("/dev/zero", tmp_path / "zero.yaml")
    cases["zero.yaml"] = "INPUT_NOT_REGULAR_FILE"
    (tmp_path / "bomb.yaml").write_text(_bomb(12))
    cases["bomb.yaml"] = "YAML_ALIAS_LIMIT"
    (tmp_path / "engines.yaml").write_text("engines: [nosuch, pybullet]\n")
    cases["engines.yaml"] = "CONFIG_INVALID"
    (tmp_path / "settle.yaml").write_text("sim: {settle_time: 1e7}\n")
    cases["settle.yaml"] = "CONFIG_INVALID"
    (tmp_path / "step.yaml").write_text("sim: {timestep: 0}\n")
    cases["step.yaml"] = "CONFIG_INVALID"
    for name, code in cases.items():
        with _no_hang():
            status = cli.main(["refine", str(asset), "--out", str(tmp_path / "out"), "--config", str(tmp_path / name)])
        err = capsys.readouterr().err
        assert status == 2, (name, err)
        assert code in err, (name, err)
        assert not (tmp_path / "out").exists()


def test_refine_with_a_fifo_config_ends_in_a_child_process(tmp_path):
    """The command itself, killed after 60 s (a hang fails the test): a FIFO ``--config`` is refused at once."""
    os.mkfifo(tmp_path / "config.yaml")
    (tmp_path / "asset").mkdir()
    proc = subprocess.run([sys.executable, "-m", "asset2sim", "refine", str(tmp_path / "asset"), "--out", str(tmp_path / "out"),
                           "--config", str(tmp_path / "config.yaml")], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "INPUT_NOT_REGULAR_FILE" in proc.stderr


@pytest.mark.parametrize("overrides, field", [
    ({"mass": float("inf")}, "overrides.mass"),
    ({"mass": "1e400 kg"}, "overrides.mass"),
    ({"size": 1e300}, "overrides.size"),
    ({"scale": float("inf")}, "overrides.scale"),
    ({"scale": 1e-9}, "overrides.scale"),
    ({"material": "x" * 1000}, "overrides.material"),
])
def test_override_values_out_of_range_are_refused(overrides, field):
    with pytest.raises(ValueError) as info:
        load_config({"overrides": overrides})
    assert field in str(info.value)
    assert load_config({"overrides": {"mass": "12 kg", "size": "30 cm", "scale": 2, "material": "oak"}}).overrides.mass == 12.0


def test_a_file_swapped_after_its_check_is_not_read(tmp_path, monkeypatch):
    """read_file opens the file it checked: one replaced in between (here by a symlink to a file outside the tree,
    swapped in right after the check) is refused, not read."""
    from asset2sim import input_files

    tree = tmp_path / "tree"
    tree.mkdir()
    (tree / "config.yaml").write_text("seed: 1\n")
    (tmp_path / "secret.yaml").write_text("seed: 4711\n")
    real_check = input_files.check_file

    def check_then_swap(path, **kw):
        st = real_check(path, **kw)
        os.replace(tmp_path / "swap", path)
        return st

    os.symlink(tmp_path / "secret.yaml", tmp_path / "swap")
    monkeypatch.setattr(input_files, "check_file", check_then_swap)
    with pytest.raises(InputFileError) as info:
        input_files.read_file(tree / "config.yaml", tree=tree)
    assert info.value.code == "INPUT_UNREADABLE"
