"""Print the model's fingerprint: six short, deterministic runs of
:func:`nematic_solids.model.simulate.run` that cover its main paths, each reduced to exact hashes of
its arrays and the full-precision values of its scalars and counters, as JSON. A change meant to
keep the behaviour (a refactoring) leaves the output byte-identical; compare the output before and
after it.

    .venv/bin/python scripts/fingerprint.py                       # JSON on stdout
    .venv/bin/python scripts/fingerprint.py --output before.json  # also written to a file

The runs (32^2 or 64^2, t = 4 to 8; about ten seconds with the compiled kernels in
numba's cache, two minutes without):

====================  =========================================================================
name                  path
====================  =========================================================================
finite_compiled       finite strain, integrated displacement, compiled kernels, band texture
finite_numpy          the same with the numpy kernels
finite_equilibrium    finite strain, force balance at every stage, eps > 0, B' > 0, chi, ETDRK2
linear_compiled       small strain, compiled, per-node texture, eps > 0
linear_numpy          small strain, numpy kernels, incompressible, B' > 0
linear_texture        small strain, compiled, a per-node texture drawn on 32^2 run on 64^2, ETDRK2
====================  =========================================================================

Each run's record: ``status``, ``reason``, the solver's counters (steps, rejections, spin and
CG iterations, transforms by part), the sha256 of every array of the Dataset (its dtype, shape
and bytes: the series, the snapshots and the coordinates) and ``repr`` of every scalar but the
wall time. The wall time, the creation time and the git commit are left out (they differ
between identical runs).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run

#: the workload's constants (the tests' small workload: resolved at 32^2, quick to pattern)
BASE = Parameters(noise_modes=6, K=1e-3, S0=0.2, zeta=1.0, kappa=10.0)

#: name -> (parameters, numerics, seed)
RUNS: dict[str, tuple[Parameters, Numerics, int]] = {
    "finite_compiled": (
        BASE.replace(alpha_minus_B=1.0),
        Numerics(resolution=32, t_final=8.0, save_every=2.0, mechanics="finite"),
        1,
    ),
    "finite_numpy": (
        BASE.replace(alpha_minus_B=1.0),
        Numerics(resolution=32, t_final=8.0, save_every=2.0, mechanics="finite", backend="numpy"),
        1,
    ),
    "finite_equilibrium": (
        BASE.replace(alpha_minus_B=1.2, eps=0.03, B_prime=0.1, chi=5.0),
        Numerics(
            resolution=32,
            t_final=4.0,
            save_every=1.0,
            mechanics="finite",
            displacement="equilibrium",
            scheme="etdrk2",
            snapshot_times=(2.0,),
        ),
        2,
    ),
    "linear_compiled": (
        BASE.replace(alpha_minus_B=1.5, eps=0.02, initial="per_node"),
        Numerics(resolution=64, t_final=8.0, save_every=2.0, mechanics="linear"),
        3,
    ),
    "linear_numpy": (
        BASE.replace(alpha_minus_B=1.5, B_prime=0.1),
        Numerics(
            resolution=32,
            t_final=8.0,
            save_every=2.0,
            mechanics="linear",
            incompressible=True,
            backend="numpy",
        ),
        4,
    ),
    "linear_texture": (
        BASE.replace(alpha_minus_B=1.3, eps=0.01, initial="per_node", texture_resolution=32),
        Numerics(resolution=64, t_final=6.0, save_every=1.5, mechanics="linear", scheme="etdrk2"),
        5,
    ),
}

#: attributes that differ between identical runs
VOLATILE_ATTRS = {"history", "git_commit", "library_versions"}
#: scalars that differ between identical runs
VOLATILE_VARS = {"wall_time"}


def array_hash(values: np.ndarray) -> str:
    """sha256 of an array's dtype, shape and bytes (C order)."""
    a = np.ascontiguousarray(values)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def fingerprint(ds: xr.Dataset) -> dict[str, Any]:
    """The record of one run (module docstring)."""
    arrays: dict[str, str] = {}
    scalars: dict[str, str] = {}
    for name in sorted(map(str, ds.variables)):
        if name in VOLATILE_VARS:
            continue
        values = ds[name].values
        if values.ndim == 0:
            scalars[name] = repr(values.item())
        else:
            arrays[name] = array_hash(values)
    attrs = {
        k: repr(v)
        for k, v in sorted(ds.attrs.items())
        if k not in VOLATILE_ATTRS
        and (k.startswith(("solver_", "fft_", "status", "reason", "detail", "t_failed")))
    }
    return {"attrs": attrs, "scalars": scalars, "arrays": arrays}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output", type=Path, help="also write the JSON here")
    args = parser.parse_args(argv)
    out = {name: fingerprint(run(p, n, seed)) for name, (p, n, seed) in RUNS.items()}
    text = json.dumps(out, indent=1, sort_keys=True) + "\n"
    sys.stdout.write(text)
    if args.output is not None:
        args.output.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
