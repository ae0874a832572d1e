"""The activity's stress in Eq. (5) (Parameters.coupling): tr S of the second Piola stress
S = F^-1 P against tr P. Equal where they must be (F = I; every run in linear mechanics, where
both are tr sigma), the analytic difference under a uniform shear, and apart in a patterned
finite-strain run by the order of its strain."""

from __future__ import annotations

import numpy as np
import pytest

from nematic_solids.model import constitutive as cl
from nematic_solids.model import tensors as T
from nematic_solids.model.errors import ParameterError
from nematic_solids.model.fourier import SpectralGrid
from nematic_solids.model.mechanics import make_mechanics
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run


def _uniform(params: Parameters, n: int = 16):
    grid = SpectralGrid(n, fft_backend="scipy")
    mech = make_mechanics(params, Numerics(resolution=n, backend="numpy"), grid)
    q1, q2 = np.full((n, n), 0.2), np.full((n, n), -0.1)
    return mech.solve(q1, q2), q1, q2


def test_tr_S_is_tr_P_at_F_equal_I_and_the_analytic_value_under_shear():
    state, _, _ = _uniform(Parameters(coupling="trS", eps=0.0, B=0.0))  # F = I exactly
    assert np.allclose(state.F, T.identity((16, 16)), atol=1e-14)
    assert np.allclose(state.trS, state.trP, rtol=0, atol=1e-13)
    p = Parameters(coupling="trS", eps=0.1)
    state, q1, q2 = _uniform(p)
    F = np.array([[1.1, 0.0], [0.0, 0.9]])
    P = cl.first_piola(
        F[:, :, None, None],
        T.nematic(np.array([[0.2]]), np.array([[-0.1]])),
        cl.Moduli.from_params(p),
    )[:, :, 0, 0]
    want = np.trace(np.linalg.inv(F) @ P)
    assert np.allclose(state.trS, want, rtol=1e-12)
    assert not np.allclose(state.trS, state.trP, rtol=1e-3)  # they differ at finite strain


def test_linear_mechanics_runs_are_the_same_with_either_coupling():
    num = Numerics(resolution=32, t_final=6, save_every=1, mechanics="linear")
    a, b = (
        run(Parameters.from_dict({"noise_modes": 8, "alpha_minus_B": 1.0, "coupling": c}), num, 0)
        for c in ("trP", "trS")
    )
    for name in ("sigma2_S", "mean_A", "mean_S"):
        assert np.array_equal(a[name].values, b[name].values)


def test_finite_strain_runs_differ_by_the_order_of_their_strain():
    num = Numerics(resolution=32, t_final=20, save_every=1)
    out = {}
    for c in ("trP", "trS"):
        out[c] = run(
            Parameters.from_dict({"noise_modes": 8, "alpha_minus_B": 1.0, "coupling": c}), num, 0
        )
    a, b = out["trP"].mean_A.values[-1], out["trS"].mean_A.values[-1]
    strain = 1.0 - float(out["trP"].min_J.min())  # about 1 %
    assert 0.1 * strain < abs(b - a) / abs(a) < 10 * strain
    assert out["trS"].attrs["param_coupling"] == "trS"


def test_an_unknown_coupling_is_refused():
    with pytest.raises(ParameterError, match="trP or trS"):
        Parameters(coupling="trF")
