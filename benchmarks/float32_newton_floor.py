"""Whether finite strain's Newton solve reaches a force-balance tolerance in float32 (the
accelerated backend, JAX on the CPU): Newton from the homogeneous state at a seeded texture whose
order is raised to S ~ 0.5 (a patterned state's size), for newton_tol 1e-5, 1e-6 (the default) and
1e-7 in float32 and 1e-6 in float64; the residual it ends at, its iterations and its outcome
(docs/guide/precision.md).

    .venv/bin/python benchmarks/float32_newton_floor.py   # -> float32_newton_floor.json here
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from nematic_solids.model.accelerated import finite  # (enables float64)
from nematic_solids.model.initial import initial_fields
from nematic_solids.model.parameters import Numerics, Parameters


def floor(n: int, precision: str, amb: float, tol: float) -> dict:
    params = Parameters.from_dict({"alpha_minus_B": amb, "noise_modes": 8})
    num = Numerics(resolution=n, mechanics="finite", precision=precision)
    symbols, c = finite.setup(params, num)
    c = dataclasses.replace(c, tol=tol)
    dev = jax.devices("cpu")[0]
    sym = finite.symbols_on(symbols, dev, precision)
    dtype = jnp.float32 if precision == "float32" else jnp.float64
    q1, q2, _ = initial_fields(params, n, 0)
    q = np.stack([q1, q2])
    q = 0.5 * q / np.max(np.hypot(q[0], q[1]))  # |S| up to 0.5
    order = jnp.asarray(q, dtype)
    cdtype = jnp.complex64 if precision == "float32" else jnp.complex128

    @jax.jit
    def solve(q):
        zero = jnp.zeros((2, n, n // 2 + 1), cdtype)
        return finite.force_balance(q, zero, finite.deformation(zero, sym, c), sym, c)

    bal = solve(order)
    return {
        "resolution": n,
        "precision": precision,
        "alpha_minus_B": amb,
        "newton_tol": tol,
        "residual_reached": float(bal.residual),
        "newton_iterations": int(bal.iterations),
        "outcome": finite.BALANCE_REASONS[int(bal.status)] or "converged",
    }


def main() -> None:
    cases = [("float64", 1e-6)] + [("float32", tol) for tol in (1e-5, 1e-6, 1e-7)]
    rows = []
    for n in (32, 64):
        for precision, tol in cases:
            rows.append(floor(n, precision, 0.6, tol))
            print(rows[-1], flush=True)
    out = Path(__file__).with_name("float32_newton_floor.json")
    out.write_text(json.dumps({"what": __doc__.split("\n\n")[0], "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
