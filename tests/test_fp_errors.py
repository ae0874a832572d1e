"""The test suite's floating-point policy (tests/conftest.py): errors raise unless a test
opts out, with a reason."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.parametrize(
    "operation",
    [
        lambda: np.array([1.0]) / np.array([0.0]),  # divide
        lambda: np.array([0.0]) / np.array([0.0]),  # invalid
        lambda: np.exp(np.array([1000.0])),  # overflow
        lambda: np.sqrt(np.array([-1.0])),  # invalid
    ],
)
def test_floating_point_errors_raise_in_every_test(operation):
    with pytest.raises(FloatingPointError):
        operation()


def test_underflow_to_zero_is_not_an_error():
    assert np.exp(np.array([-1000.0]))[0] == 0.0


@pytest.mark.allow_fp_errors("checks the opt-out itself")
def test_a_test_can_opt_out_with_a_reason():
    with pytest.warns(RuntimeWarning, match="divide by zero"):  # numpy's default: a warning
        assert np.isinf(np.array([1.0]) / np.array([0.0]))[0]
