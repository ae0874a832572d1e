"""The resolution rule (nematic_solids.model.resolution): the coarsest grid of the ladder with c
cells per Frank length sqrt(K / A0), floored and capped; every mistake a ParameterError."""

from __future__ import annotations

import math

import pytest

from nematic_solids.model.errors import ParameterError
from nematic_solids.model.resolution import ResolutionRule, is_rule, read_rule, resolve


def test_the_grid_has_c_cells_per_frank_length_on_the_ladder():
    rule = ResolutionRule(cells_per_frank=1.0, floor=128, cap=1024)
    for K in (1e-7, 1e-6, 3e-6, 1e-5, 5e-5, 1e-3):
        n = rule.grid(K, 0.1)
        frank = math.sqrt(K / 0.1)
        assert n in (128, 256, 512, 1024)
        if not rule.capped(K, 0.1):
            assert n * frank >= 1.0  # c cells per Frank length at least
        if n > 128:
            assert (n // 2) * frank < 1.0  # and the next coarser grid has fewer
    assert rule.grid(1e-6, 0.1) == 512  # l_F = 3.2e-3: 1 cell needs 317 points per side
    assert rule.grid(1e-5, 0.1) == 128  # l_F = 1e-2: the floor has 1.28 cells


def test_floor_and_cap_hold_and_the_cap_is_reported():
    rule = ResolutionRule(cells_per_frank=2.0, floor=96, cap=384)
    assert rule.grid(1.0, 0.1) == 96
    assert rule.grid(1e-8, 0.1) == 384
    assert rule.capped(1e-8, 0.1)
    assert not rule.capped(1.0, 0.1)
    assert rule.grid(0.0, 0.1) == 384  # no Frank elasticity: as fine as allowed
    assert rule.grid(1e-6, 0.0) == 96  # no Landau stiffness: no finite Frank length


def test_auto_and_mappings_are_rules_and_numbers_pass_through():
    assert is_rule("auto")
    assert is_rule({"floor": 64})
    assert not is_rule(128)
    assert read_rule("auto") == ResolutionRule()
    assert read_rule({"cap": 512}) == ResolutionRule(cap=512)
    assert resolve(96, 1e-9, 0.1) == 96
    assert resolve("auto", 1e-6, 0.1) == ResolutionRule().grid(1e-6, 0.1)


@pytest.mark.parametrize(
    "value",
    [
        "fine",
        {},
        {"cells": 1.0},
        {"cells_per_frank": 0},
        {"cells_per_frank": "many"},
        {"floor": 100, "cap": 90},
        {"floor": 33},
        {"cap": True},
    ],
)
def test_a_bad_rule_is_a_parameter_error_naming_resolution(value):
    with pytest.raises(ParameterError) as err:
        read_rule(value)
    assert err.value.name == "resolution"
    assert "auto" in err.value.allowed
