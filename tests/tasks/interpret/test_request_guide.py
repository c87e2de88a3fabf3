"""Every example request of ``docs/guide/requests.md`` is run: the table under "Examples" on the object each row
names (a dev object by id, or a generated one of the kind described), checking the joint it names and the amount
(from the closed end), the phrases applied to nothing, and sizes; and every full request quoted anywhere in the
guide is a row of that table."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from asset2sim.tasks.synthesize import estimate, request_apply
from asset2sim.tasks.synthesize.context import build_context
from tests.conftest import SHARED, needs_shared
from tests.tasks.interpret.request_assets import build_three_drawer_cabinet
from tests.tasks.interpret.request_corpus import _num
from tests.unseen_assets import build_bottle, build_toaster

GUIDE = Path(__file__).resolve().parents[3] / "docs" / "guide" / "requests.md"
#: The generated objects the table describes in words.
GENERATED = {"a toaster whose lever is labelled `slider`": build_toaster, "a bottle whose cap is labelled `lid`": build_bottle,
             "a chest of three drawers": build_three_drawer_cabinet}


def example_rows() -> list[tuple[str, str, str]]:
    """(request, object, what it sets) of each row of the guide's example table."""
    text = GUIDE.read_text()
    section = text.split("### Examples", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        m = re.fullmatch(r'\| "(?P<req>[^"]+)" \| (?P<obj>[^|]+) \| (?P<want>[^|]+) \|', line.strip())
        if m:
            rows.append((m["req"], m["obj"].strip(), m["want"].strip()))
    return rows


ROWS = example_rows()


def test_the_guide_has_examples_and_every_full_request_it_quotes_is_one():
    assert len(ROWS) >= 20
    quoted = set(re.findall(r'"((?:A|I) [^"]{10,}?[.])"', " ".join(GUIDE.read_text().split())))
    assert quoted and quoted <= {r for r, _, _ in ROWS}, quoted - {r for r, _, _ in ROWS}


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("guide")
    return {name: build(root / f"g{i}") for i, (name, build) in enumerate(GENERATED.items())}


@needs_shared
@pytest.mark.parametrize("request_text,obj,want", ROWS, ids=[r[0][:40] for r in ROWS])
def test_each_example_sets_the_joint_it_names_by_the_amount_it_says(request_text, obj, want, generated):
    folder = generated[obj] if obj in GENERATED else SHARED / obj.split()[0]
    joints = dict(re.findall(r"`(joint_\d+)=([^`]+)`", want))
    unapplied = re.findall(r"`not applied: '([^']+)'`", want)
    sizes = re.findall(r"`size=(\w+):([^`]+)`", want)
    assert joints or unapplied or sizes, want
    with build_context(folder, request_text) as (ctx, kin):
        scale, _ = estimate.choose_scale(ctx)
        res = request_apply.resolve_states(ctx, kin, scale)
        got_sizes = {sz.dimension: got for sz, (_, _, got) in zip(ctx.request.sizes, request_apply.size_residuals(ctx, scale))}
    for j, exp in joints.items():
        t = res.targets.get(j)
        if ":" not in exp:
            assert res.bands[j] == exp and t is None, (j, res.bands.get(j), t)
            continue
        kind, x = exp.split(":", 1)
        assert t is not None and t.kind == kind, (j, t)
        if kind == "end":
            assert res.requests[j].target.end == x
        elif kind == "fraction":
            assert t.fraction == pytest.approx(_num(x), abs=1e-3)
        else:  # an angle (rad) or a distance (m) from the closed end, as asked
            assert t.asked == pytest.approx(_num(x), rel=1e-3)
            prismatic = ctx.asset.joint(j).type == "prismatic"
            if kind == "angle" or prismatic:  # the opening set from the closed end is the number asked (a hinge's gap: angle = d / r)
                assert t.fraction * ctx.closed[j].open_range * (scale if prismatic else 1.0) == pytest.approx(_num(x), rel=1e-3)
    assert [p for p, _ in res.unapplied] == unapplied
    for dim, v in sizes:
        assert got_sizes[dim] == pytest.approx(float(v), rel=0.05)
