"""Task text -> joints, direction and target opening fraction (tasks.check.task_spec)."""

from __future__ import annotations

import csv

import pytest

from asset2sim.tasks.check.probes import CLOSE_TARGET, OPEN_TARGET
from asset2sim.tasks.check.task_spec import parse_task, with_work_to_do
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.interpret.task_words import task_actions
from tests.conftest import SHARED, needs_shared


def _asset(aid: str):
    return extract_asset(SHARED / aid)


def _movable(asset):
    return [j.name for j in asset.movable_joints()]


def _label(asset, joint: str):
    return asset.link(asset.joint(joint).child).semantic_label


@needs_shared
def test_manifest_tasks_name_their_part_and_direction():
    rows = {r["id"]: r for r in csv.DictReader(open(SHARED / "manifest.csv"))}
    asset = _asset("7236")  # microwave: "close the microwave door"
    t = parse_task(rows["7236"]["task"], asset, "Microwave", ["fallback"])
    assert t.actions == ("close",) and t.targets == {"close": CLOSE_TARGET}
    assert t.part == "door" and t.joints and all(_label(asset, j) == "door" for j in t.joints)
    asset = _asset("20279")  # cabinet: "open the top drawer"
    t = parse_task(rows["20279"]["task"], asset, "StorageFurniture", ["fallback"])
    assert t.actions == ("open",) and t.targets == {"open": OPEN_TARGET}
    assert t.joints and all(_label(asset, j) == "drawer" for j in t.joints)
    assert any("ordinal" in n for n in t.notes)


@needs_shared
def test_whole_object_and_unknown_tasks_fall_back_to_the_task_joints():
    asset = _asset("103275")  # stapler: "press the stapler" is a whole-object phrase
    t = parse_task("press the stapler", asset, "Stapler", ["joint_1"])
    assert t.actions == ("close",) and t.joints == ["joint_1"] and "whole object" in t.rule
    asset = _asset("148")  # faucet: "turn" has no direction
    t = parse_task("turn the faucet handle", asset, "Faucet", ["j"])
    assert t.actions == ("close", "open")
    t = parse_task("wiggle the flux capacitor", asset, "Faucet", ["j"])
    assert t.actions == ("close", "open") and t.joints == ["j"] and t.rule.startswith("fallback")


@needs_shared
@pytest.mark.parametrize("verb,action", [("shut", "close"), ("lift", "open"), ("pull out", "open"), ("lower", "close")])
def test_verbs(verb, action):
    asset = _asset("102703")
    t = parse_task(f"{verb} the toilet lid", asset, "Toilet", [])
    assert t.actions == (action,)


def test_task_actions_follow_the_verb():
    from_verb = {"close the microwave door": ("close",), "press the stapler": ("close",), "open the top drawer": ("open",),
                 "Lift the lid": ("open",), "turn the faucet handle": ("close", "open"), "": ("close", "open")}
    for text, want in from_verb.items():
        assert task_actions(text) == want, text
    assert task_actions(None) == ("close", "open")


@needs_shared
def test_a_task_on_one_of_several_drawers_acts_on_the_one_with_work_to_do():
    """Cabinet 19179 (two drawers), "close the cabinet drawer" with one drawer
    open: the task acts on the open one; "close the drawers", "close every
    drawer", an open task (both have work) and both drawers closed (neither
    has: an asset delivered closed is still asked to close) keep both."""
    asset = _asset("19179")
    drawers = sorted(j for j in _movable(asset) if _label(asset, j) == "drawer")
    assert len(drawers) == 2
    one_open = {drawers[0]: 0.12, drawers[1]: 0.0}
    t = with_work_to_do(parse_task("close the cabinet drawer", asset, "StorageFurniture", []), one_open)
    assert t.joints == [drawers[0]] and any(f"{drawers[1]} already closed" in n for n in t.notes)
    for text in ("close the drawers", "close every drawer", "close both drawers"):
        assert sorted(with_work_to_do(parse_task(text, asset, "StorageFurniture", []), one_open).joints) == drawers
    assert sorted(with_work_to_do(parse_task("open the drawer", asset, "StorageFurniture", []), one_open).joints) == drawers
    shut = {drawers[0]: 0.0, drawers[1]: 0.0}
    assert sorted(with_work_to_do(parse_task("close the drawer", asset, "StorageFurniture", []), shut).joints) == drawers
    wide = {drawers[0]: 0.9, drawers[1]: 0.1}  # open the drawer: only the second is below the open target
    assert with_work_to_do(parse_task("open the drawer", asset, "StorageFurniture", []), wide).joints == [drawers[1]]
