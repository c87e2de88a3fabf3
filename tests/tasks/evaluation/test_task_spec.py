"""Task text -> joints, direction and target opening fraction (tasks.evaluation.task_spec)."""

from __future__ import annotations

import csv

import pytest

from asset2sim.tasks.check.probes import CLOSE_TARGET, OPEN_TARGET
from asset2sim.tasks.evaluation.asset_files import parse_urdf, read_semantics
from asset2sim.tasks.evaluation.task_spec import parse_task, task_actions
from tests.conftest import SHARED, needs_shared


def _asset(aid: str):
    _, joints = parse_urdf(SHARED / aid / "mobility.urdf")
    return joints, read_semantics(SHARED / aid)


def _movable(joints):
    return [n for n, j in joints.items() if j.type in ("revolute", "prismatic", "continuous")]


@needs_shared
def test_manifest_tasks_name_their_part_and_direction():
    rows = {r["id"]: r for r in csv.DictReader(open(SHARED / "manifest.csv"))}
    joints, sem = _asset("7236")  # microwave: "close the microwave door"
    t = parse_task(rows["7236"]["task"], joints, sem, "Microwave", ["fallback"])
    assert t.actions == ("close",) and t.targets == {"close": CLOSE_TARGET}
    assert t.part == "door" and t.joints and all(sem[joints[j].child][1] == "door" for j in t.joints)
    joints, sem = _asset("20279")  # cabinet: "open the top drawer"
    t = parse_task(rows["20279"]["task"], joints, sem, "StorageFurniture", ["fallback"])
    assert t.actions == ("open",) and t.targets == {"open": OPEN_TARGET}
    assert t.joints and all(sem[joints[j].child][1] == "drawer" for j in t.joints)
    assert any("ordinal" in n for n in t.notes)


@needs_shared
def test_whole_object_and_unknown_tasks_fall_back_to_the_task_joints():
    joints, sem = _asset("103275")  # stapler: "press the stapler" is a whole-object phrase
    t = parse_task("press the stapler", joints, sem, "Stapler", ["joint_1"])
    assert t.actions == ("close",) and t.joints == ["joint_1"] and "whole object" in t.rule
    joints, sem = _asset("148")  # faucet: "turn" has no direction
    t = parse_task("turn the faucet handle", joints, sem, "Faucet", ["j"])
    assert t.actions == ("close", "open")
    t = parse_task("wiggle the flux capacitor", joints, sem, "Faucet", ["j"])
    assert t.actions == ("close", "open") and t.joints == ["j"] and t.rule.startswith("fallback")


@needs_shared
@pytest.mark.parametrize("verb,action", [("shut", "close"), ("lift", "open"), ("pull out", "open"), ("lower", "close")])
def test_verbs(verb, action):
    joints, sem = _asset("102703")
    t = parse_task(f"{verb} the toilet lid", joints, sem, "Toilet", [])
    assert t.actions == (action,)


def test_task_actions_follow_the_verb():
    from_verb = {"close the microwave door": ("close",), "press the stapler": ("close",), "open the top drawer": ("open",),
                 "Lift the lid": ("open",), "turn the faucet handle": ("close", "open"), "": ("close", "open")}
    for text, want in from_verb.items():
        assert task_actions(text) == want, text
    assert task_actions(None) == ("close", "open")
