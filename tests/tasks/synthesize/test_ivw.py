"""Inverse-variance weighting (asset2sim.tasks.synthesize.ivw)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from asset2sim.tasks.synthesize import ivw


def test_equal_uncertainties_give_the_mean_and_shrink_the_std():
    f = ivw.fuse([(1.0, 0.5), (2.0, 0.5), (6.0, 0.5), (3.0, 0.5)])
    assert f.value == pytest.approx(3.0)
    assert f.std == pytest.approx(0.5 / math.sqrt(4))


def test_weights_are_inverse_variances():
    # w = 1/0.1^2 = 100 and 1/0.2^2 = 25 -> (100*1 + 25*2) / 125 = 1.2
    f = ivw.fuse([(1.0, 0.1), (2.0, 0.2)])
    assert f.value == pytest.approx(1.2)
    assert f.std == pytest.approx(1.0 / math.sqrt(125.0))


def test_a_confident_estimate_dominates():
    est = [(10.0, 1e-6), (0.0, 1.0), (0.0, 1.0)]
    assert ivw.fuse(est).value == pytest.approx(10.0, rel=1e-6)


@pytest.mark.parametrize(
    "est, match",
    [
        ([], "at least one"),
        ([(1.0, 0.0)], "must be > 0"),
        ([(1.0, -1.0)], "must be > 0"),
        ([(float("nan"), 1.0)], "finite"),
        ([(1.0, float("inf"))], "finite"),
    ],
)
def test_bad_estimates_raise(est, match):
    with pytest.raises(ValueError, match=match):
        ivw.fuse(est)


def test_fuse_all_names_the_parameter_and_skips_empty():
    out = ivw.fuse_all({"scale": [(0.2, 0.02), (0.3, 0.02)], "mass": []})
    assert set(out) == {"scale"}
    assert out["scale"].value == pytest.approx(0.25)
    with pytest.raises(ValueError, match="damping"):
        ivw.fuse_all({"damping": [(1.0, 0.0)]})


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(min_value=-1e3, max_value=1e3, allow_nan=False),
            st.floats(min_value=1e-3, max_value=1e3, allow_nan=False),
        ),
        min_size=1,
        max_size=25,
    )
)
def test_fused_value_lies_between_the_estimates_and_std_below_the_best(est):
    f = ivw.fuse(est)
    lo = min(v for v, _ in est)
    hi = max(v for v, _ in est)
    tol = 1e-9 * max(1.0, abs(lo), abs(hi))
    assert lo - tol <= f.value <= hi + tol
    assert f.std <= min(s for _, s in est) * (1 + 1e-12)
