"""float32 on the accelerated backend (``Numerics.precision``): what the compiled step computes in
which precision (from its traced program, no compile: every field-sized float64 value of a float32
step is a widening inside a float64 reduction, the fields come back in float32, the time and step
size stay float64), and whole float32 runs against float64 (the observables within 1e-4
relative; measured: a few 1e-6, docs/guide/precision.md). Skipped where JAX is not installed."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

pytest.importorskip("jax", reason="the accelerated backend needs JAX: pip install -e '.[accel]'")

import jax
import jax.numpy as jnp

from nematic_solids.model.accelerated import finite, run_batch
from nematic_solids.model.accelerated.dtypes import narrow, wide_mean, wide_sum
from nematic_solids.model.accelerated.etdrk4 import Control
from nematic_solids.model.accelerated.linear_rhs import setup, symbols_on
from nematic_solids.model.accelerated.observables import shell_data
from nematic_solids.model.accelerated.run import _jitted
from nematic_solids.model.parameters import Numerics, Parameters

N = 16
PARAMS = Parameters.from_dict({"alpha_minus_B": 0.6, "noise_modes": 4})
WIDE = (jnp.float64, jnp.complex128)


def equations(jaxpr) -> Iterator:
    """Every equation of a traced program, the nested ones (loops, branches) included."""
    for eqn in jaxpr.eqns:
        yield eqn
        for value in eqn.params.values():
            for sub in value if isinstance(value, (tuple, list)) else (value,):
                inner = getattr(sub, "jaxpr", None)
                if inner is not None:
                    yield from equations(getattr(inner, "jaxpr", inner))


def traced_step(mechanics: str, precision: str):
    """The batched advance of a run (2 seeds) traced, and the state it takes."""
    num = Numerics(resolution=N, t_final=1.0, mechanics=mechanics, precision=precision)
    dev = jax.devices("cpu")[0]
    sym: Any
    c: Any
    if mechanics == "linear":
        linear_symbols, c = setup(PARAMS, num)
        sym = symbols_on(linear_symbols, dev, precision)
    else:
        finite_symbols, c = finite.setup(PARAMS, num)
        sym = finite.symbols_on(finite_symbols, dev, precision)
    ctl = Control(num.tolerance, num.dt_max, num.adaptive, num.error_norm)
    begin, step, _ = _jitted(c, ctl, shell_data(N)[1], num.dt)
    real = jnp.float32 if precision == "float32" else jnp.float64
    q = jax.ShapeDtypeStruct((2, 2, N, N), real)
    A = jax.ShapeDtypeStruct((2, N, N), real)
    state = jax.eval_shape(begin, q, A, sym)
    t = jax.ShapeDtypeStruct((), jnp.float64)
    return jax.make_jaxpr(step)(state, t, sym), jax.eval_shape(step, state, t, sym)


@pytest.mark.parametrize("mechanics", ["linear", "finite"])
def test_a_float32_step_keeps_its_fields_in_float32_and_sums_in_float64(mechanics):
    program, state = traced_step(mechanics, "float32")
    assert (state.q.dtype, state.q_hat.dtype, state.A.dtype) == (
        jnp.float32,
        jnp.complex64,
        jnp.float32,
    )
    assert state.t.dtype == state.h.dtype == jnp.float64
    grids = {(N, N), (N, N // 2 + 1)}  # a field's or a spectrum's last two axes
    wide_fields, widened = [], 0
    for eqn in equations(program.jaxpr):
        for v in eqn.outvars:
            aval = v.aval
            if getattr(aval, "dtype", None) in WIDE and tuple(aval.shape[-2:]) in grids:
                where = str(eqn.source_info.traceback)
                if eqn.primitive.name == "convert_element_type" and "dtypes.py" in where:
                    widened += 1  # a float32 field widened inside a float64 sum
                else:
                    wide_fields.append(f"{eqn.primitive} -> {aval}")
    assert wide_fields == []
    assert widened > 0  # the sums are there, and they are float64


def test_a_float64_step_is_float64_throughout():
    program, state = traced_step("linear", "float64")
    assert (state.q.dtype, state.q_hat.dtype) == (jnp.float64, jnp.complex128)
    narrow_values = [
        str(v.aval)
        for eqn in equations(program.jaxpr)
        for v in eqn.outvars
        if getattr(v.aval, "dtype", None) in (jnp.float32, jnp.complex64)
    ]
    assert narrow_values == []


def test_the_wide_sums_are_float64_and_narrow_follows_the_field():
    x = jnp.full((512, 512), 0.1, jnp.float32)
    assert wide_sum(x).dtype == jnp.float64
    # 512^2 float32 values of 0.1 summed in float64: the float32 0.1 times 512^2, exactly
    assert float(wide_sum(x)) == float(np.float32(0.1)) * 512**2
    assert float(wide_mean(x)) == pytest.approx(float(np.float32(0.1)), rel=1e-15)
    assert narrow(jnp.float64(2.0), jnp.zeros(3, jnp.complex64)).dtype == jnp.float32


@pytest.mark.slow  # (about a minute: two compiles of the small-strain batch)
def test_a_float32_linear_run_agrees_with_float64():
    results = {}
    for precision in ("float64", "float32"):
        num = Numerics(
            resolution=32, t_final=20.0, save_every=5.0, mechanics="linear", precision=precision
        )
        results[precision] = run_batch(
            Parameters.from_dict({"alpha_minus_B": 0.6, "noise_modes": 8}), num, [0, 1]
        )
    a, b = results["float64"], results["float32"]
    assert a.status == b.status == ["ok", "ok"]
    assert b.fields.dtype == np.float64  # handed to the host widened (exactly)
    assert not np.array_equal(a.fields, b.fields)  # it did compute in float32
    for name in ("sigma2_S", "lambda", "cos2theta", "mean_S"):
        # relative to each value, and to the series' scale where a value is rounding noise
        # (sigma2_S at t = 0 of the uniform band: 2e-30 in float64, 4e-18 in float32)
        scale = float(np.nanmax(np.abs(a.series[name])))
        np.testing.assert_allclose(
            b.series[name], a.series[name], rtol=1e-4, atol=1e-6 * scale, err_msg=name
        )
    steps64, steps32 = a.work["steps"], b.work["steps"]
    assert np.all(np.abs(steps32 - steps64) <= 0.1 * steps64)
