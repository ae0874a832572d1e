"""The accelerated backend (model/accelerated/, JAX) against the numpy reference and the
compiled path, on the CPU (the code path a GPU runs): its right-hand side, phi functions,
step ladder and observables against their numpy twins; whole small-strain runs against
nematic_solids.model.simulate.run (the same accepted and rejected steps, the observables at every
save); a batch of seeds against the same seeds run alone; a failing seed that does not stop its
batch-mates; the device selection's error. Skipped where JAX is not installed (CI installs the accel
extra before the suite: .ci/run)."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr

pytest.importorskip("jax", reason="the accelerated backend needs JAX: pip install -e '.[accel]'")

import jax

from nematic_solids.model.accelerated import run_batch, select_device
from nematic_solids.model.accelerated.datasets import batch_datasets
from nematic_solids.model.accelerated.etdrk4 import phi_functions, quantize
from nematic_solids.model.accelerated.linear_rhs import linear_split, setup, symbols_on
from nematic_solids.model.accelerated.observables import NAMES, observe, shell_data
from nematic_solids.model.errors import DeviceUnavailable, ParameterError
from nematic_solids.model.fourier import SpectralGrid
from nematic_solids.model.initial import initial_fields
from nematic_solids.model.observables import anisotropy, pattern_size, pattern_size_mean
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.pde import ActiveNematicPDE
from nematic_solids.model.reference_kernels import phi_functions as phi_reference
from nematic_solids.model.run_dataset import SERIES
from nematic_solids.model.simulate import run
from nematic_solids.model.solver_base import ETDSolver
from nematic_solids.model.split import make_split

N = 32
#: a 32^2 small-strain point that patterns by t = 20 (band texture of 8 modes at 32^2)
PARAMS = Parameters.from_dict({"alpha_minus_B": 1.0, "noise_modes": 8})
NUMERICS = Numerics(resolution=N, mechanics="linear", t_final=20.0, save_every=5.0)
SEEDS = (0, 1)


def random_state(params: Parameters, rng: np.random.Generator) -> np.ndarray:
    """q1, q2, A: a seeded texture with white noise on top (|S| < 0.5, well posed at
    alpha - B = 1) and a random activity."""
    u = np.stack(initial_fields(params, N, 3))
    u[:2] = 2.0 * u[:2] + 0.1 * rng.normal(size=(2, N, N))
    u[2] = 0.3 * rng.normal(size=(N, N))
    return u


@pytest.mark.parametrize(
    "extra",
    [
        {},  # the defaults: B' = 0, eps = 0, the default spin_tol 1e-2
        {"B_prime": 0.3, "eps": 0.05, "incompressible": True, "spin_tol": 1e-10},
    ],
    ids=["defaults", "Bprime-eps-incompressible-tight"],
)
def test_rhs_equals_the_numpy_reference(extra, rng):
    """N_q hat and Adot of the JAX split equal SpectralSplit.reference to 1e-12 of their
    maximum, with the same number of spin GMRES iterations (the same algorithm)."""
    settings = {"alpha_minus_B": 1.0, "noise_modes": 8, **extra}
    num_keys = {"incompressible", "spin_tol"}
    params = Parameters.from_dict({k: v for k, v in settings.items() if k not in num_keys})
    numerics = Numerics(
        resolution=N,
        mechanics="linear",
        backend="numpy",
        **{k: v for k, v in settings.items() if k in num_keys},
    )
    eq = ActiveNematicPDE(params, numerics)
    g = eq.spectral
    split = make_split(eq.mechanics, eq, -(params.A0 + params.K * g.k2) / params.gamma)
    u = random_state(params, rng)
    q_hat = g.forward(u[:2])
    before = eq.mechanics.spin_iterations
    Nq, Adot = split.reference(u, q_hat, 0.0)  # type: ignore[union-attr]
    iterations = eq.mechanics.spin_iterations - before

    symbols, consts = setup(params, numerics)
    sym = symbols_on(symbols, select_device("cpu"))
    rate = jax.jit(lambda q, A, qh, s: linear_split(q, A, qh, s, consts))(u[:2], u[2], q_hat, sym)
    assert bool(rate.converged)
    assert int(rate.iterations) == iterations > 0
    assert np.abs(np.asarray(rate.Nq) - Nq).max() <= 1e-12 * np.abs(Nq).max()
    assert np.abs(np.asarray(rate.Adot) - Adot).max() <= 1e-12 * np.abs(Adot).max()


def test_phi_functions_and_the_step_ladder_match_the_reference():
    """The phi functions (both branches, across |z| = 1) and the rounding onto the ladder
    dt_max 2^(-j/8) are the solver's."""
    z = np.concatenate([np.linspace(-40.0, 3.0, 401), [-1.0, -0.999999, 0.0, 1e-9]])
    z = z.reshape(5, -1)
    phis = jax.jit(phi_functions, static_argnums=1)(z, 3)
    for got, want in zip(phis, phi_reference(z, 3), strict=True):
        np.testing.assert_allclose(np.asarray(got), want, rtol=1e-13, atol=1e-16)
    solver = SimpleNamespace(dt_max=1.0)
    for h in (1.0, 0.9, 0.5, 2.0**-0.125, 0.05, 1e-3, 3.3e-7):
        assert float(quantize(h, 1.0)) == pytest.approx(ETDSolver._quantize(solver, h), rel=1e-15)  # type: ignore[arg-type]


def test_observables_match_the_reference(rng):
    """mean_S, sigma2_S, cos2theta, lambda, lambda_mean, mean_A and the small-strain margin
    on the device equal nematic_solids.model.observables' on the same fields."""
    u = random_state(PARAMS, rng)
    grid = SpectralGrid(N, fft_backend="scipy")
    shells, nshell = shell_data(N)
    look = jax.jit(lambda q, A, sh: observe(q, A, sh, nshell=nshell, alpha_minus_B=1.0))
    got = np.asarray(look(u[:2], u[2], shells))
    S = np.hypot(u[0], u[1])
    want = {
        "mean_S": S.mean(),
        "sigma2_S": np.mean((S - S.mean()) ** 2),
        "cos2theta": anisotropy(u[0], u[1]),
        "lambda": pattern_size(S, grid),
        "lambda_mean": pattern_size_mean(S, grid),
        "mean_A": u[2].mean(),
        "rate_margin": 1.0 - S.max(),
    }
    for i, name in enumerate(NAMES):
        assert got[i] == pytest.approx(want[name], rel=1e-12, abs=1e-15), name


@pytest.fixture(scope="module")
def runs():
    """The batch of SEEDS, seed 1 alone, and the compiled path's runs of SEEDS."""
    return SimpleNamespace(
        batch=run_batch(PARAMS, NUMERICS, SEEDS),
        alone=run_batch(PARAMS, NUMERICS, (SEEDS[1],)),
        reference=[run(PARAMS, NUMERICS, seed) for seed in SEEDS],
    )


def test_a_run_agrees_with_the_compiled_path(runs):
    """Every seed of the batch takes the steps nematic_solids.model.simulate.run takes (accepted and
    rejected), and its sigma2_S, mean_S, lambda at every save agree to 1e-10 relative
    (measured: 1e-14)."""
    batch = runs.batch
    assert batch.status == ["ok", "ok"]
    for i, ds in enumerate(runs.reference):
        assert ds.attrs["status"] == "ok"
        assert int(batch.work["steps"][i]) == ds.attrs["solver_steps"]
        assert int(batch.work["rejected"][i]) == ds.attrs["solver_rejected"]
        np.testing.assert_allclose(batch.times, ds["t"].values)
        for name in ("sigma2_S", "mean_S", "lambda"):
            want = ds[name].values
            got = batch.series[name][i]
            finite = np.isfinite(want)
            assert np.array_equal(finite, np.isfinite(got)), name
            scale = np.abs(want[finite]).max()
            assert np.abs(got[finite] - want[finite]).max() <= 1e-10 * scale, name
        assert batch.series["sigma2_S"][i][-1] > 2 * batch.series["sigma2_S"][i][1]  # grows


def test_a_batch_equals_its_seeds_run_alone(runs):
    """Per-seed step control: seed 1 in the batch takes the same steps and reaches the same
    fields (to 1e-13; bitwise here) as seed 1 run alone, and differs from seed 0."""
    batch, alone = runs.batch, runs.alone
    for name, counts in alone.work.items():
        assert counts[0] == batch.work[name][1], name
    np.testing.assert_allclose(alone.fields[0], batch.fields[1], rtol=0, atol=1e-13)
    for name in NAMES:
        np.testing.assert_allclose(alone.series[name][0], batch.series[name][1], rtol=1e-13)
    assert np.abs(batch.fields[0] - batch.fields[1]).max() > 1e-2


def test_a_failing_seed_does_not_stop_its_batch(runs):
    """A seed whose start is ill posed ((alpha - B) S = 1.5 > 1) fails at t = 0 with
    rate_problem_ill_posed; its batch-mate runs on exactly as in the other batch."""
    fields = np.stack([np.stack(initial_fields(PARAMS, N, SEEDS[0]))] * 2)
    fields[1, 0] = 1.5
    fields[1, 1] = 0.0
    result = run_batch(PARAMS, NUMERICS, SEEDS, initial=fields)
    assert result.status == ["ok", "failed"]
    assert result.reason == ["", "rate_problem_ill_posed"]
    assert result.t_failed[1] == 0.0
    sigma2 = result.series["sigma2_S"][1]
    assert sigma2[0] == 0.0  # saved at t = 0, then nothing
    assert np.isnan(sigma2[1:]).all()
    np.testing.assert_allclose(result.fields[0], runs.batch.fields[0], rtol=0, atol=1e-13)
    assert int(result.work["steps"][0]) == int(runs.batch.work["steps"][0])


def test_a_batch_writes_each_seed_a_run_file_like_a_compiled_run(runs, tmp_path):
    """batch_datasets gives each seed the Dataset nematic_solids.model.simulate.run gives it:
    the same variables, dims, coordinates and attributes (plus the batch's own), every series,
    snapshot and scalar within 1e-10 of its scale (+ 1e-14: the force-balance residual is
    rounding), the same steps; it says how it ran; it
    round-trips through netCDF."""
    got = batch_datasets(PARAMS, NUMERICS, SEEDS)
    assert len(got) == len(SEEDS)
    for seed, ds, ref in zip(SEEDS, got, runs.reference, strict=True):
        assert set(ds.data_vars) == set(ref.data_vars)
        assert set(ref.attrs) <= set(ds.attrs)
        assert ds.attrs["seed"] == seed
        assert ds.attrs["status"] == "ok"
        assert ds.attrs["run_backend"] == "accelerated"
        assert ref.attrs["run_backend"] == "compiled"
        assert ds.attrs["batch_size"] == len(SEEDS)
        assert "batch_datasets" in ds.attrs["history"]
        assert ds.attrs["solver_steps"] == ref.attrs["solver_steps"]
        assert ds.attrs["solver_rejected"] == ref.attrs["solver_rejected"]
        assert ds.attrs["fft_saves"] > 0
        assert ds.attrs["fft_count"] > ds.attrs["fft_saves"]
        for name, var in ref.data_vars.items():
            assert ds[name].dims == var.dims, name
            want, have = var.values, ds[name].values
            finite = np.isfinite(want)
            assert np.array_equal(finite, np.isfinite(have)), name
            if name == "wall_time" or not finite.any():
                continue
            scale = np.abs(want[finite]).max()  # (the residual is rounding: 1e-16, hence abs)
            assert np.abs(have[finite] - want[finite]).max() <= 1e-10 * scale + 1e-14, name
        np.testing.assert_array_equal(ds["t"].values, ref["t"].values)
        np.testing.assert_array_equal(ds["snapshot_time"].values, ref["snapshot_time"].values)
    assert all(np.isfinite(got[0][name].values[-1]) for name in ("sigma2_S", "lambda"))
    assert set(SERIES) <= set(got[0].data_vars)
    got[1].to_netcdf(tmp_path / "seed1.nc")
    with xr.open_dataset(tmp_path / "seed1.nc") as back:
        np.testing.assert_array_equal(back["sigma2_S"].values, got[1]["sigma2_S"].values)
        assert back.attrs["batch_seeds"] == "[0, 1]"


def test_a_failed_seed_has_its_own_failed_run_file(runs):
    """The ill-posed seed of a batch gets a failed Dataset (its reason, t_failed = 0, the one
    save at t = 0); its batch-mate's Dataset is that of the batch without it."""
    fields = np.stack([np.stack(initial_fields(PARAMS, N, SEEDS[0]))] * 2)
    fields[1, 0] = 1.5
    fields[1, 1] = 0.0
    good, bad = batch_datasets(PARAMS, NUMERICS, SEEDS, initial=fields)
    assert bad.attrs["status"] == "failed"
    assert bad.attrs["reason"] == "rate_problem_ill_posed"
    assert bad.attrs["t_failed"] == 0.0
    assert "rate_problem_ill_posed at t = 0" in bad.attrs["detail"]
    assert bad["t"].values.tolist() == [0.0]
    assert np.isnan(bad["sigma2_S_final"].values)
    assert good.attrs["status"] == "ok"
    np.testing.assert_allclose(  # (at t = 0 sigma2_S is rounding: 1e-30)
        good["sigma2_S"].values, runs.batch.series["sigma2_S"][0], rtol=1e-12, atol=1e-20
    )


def test_device_selection_fails_clearly():
    """The CPU is always there; a GPU where JAX sees none is one DeviceUnavailable naming
    what there is and the install line; so is an unknown device name."""
    assert select_device("cpu").platform == "cpu"
    try:
        gpus = jax.devices("gpu")
    except RuntimeError:
        gpus = []
    if gpus:
        pytest.skip("this machine has a GPU: the error cannot be provoked here")
    assert select_device("auto").platform == "cpu"
    with pytest.raises(DeviceUnavailable, match=r"a GPU was asked for.*jax\[cuda12\]"):
        select_device("gpu")
    with pytest.raises(DeviceUnavailable, match="unknown device 'tpu9'"):
        select_device("tpu9")


def test_what_is_not_accelerated_yet_is_refused():
    """Finite strain with its displacement solved at every stage, ETDRK2 and the early stop
    are refused with a ParameterError naming the setting, before anything is compiled."""
    for numerics, name in (
        (Numerics(resolution=N, displacement="equilibrium"), "displacement"),
        (NUMERICS.replace(scheme="etdrk2"), "scheme"),
        (NUMERICS.replace(steady_tol=1e-3, steady_window=10.0), "steady_tol"),
    ):
        with pytest.raises(ParameterError, match=name):
            run_batch(PARAMS, numerics, SEEDS)


def _same_files(a: xr.Dataset, b: xr.Dataset, *, transforms: bool = True) -> None:
    """Every variable of two run Datasets bitwise equal (the wall times aside), and the work
    counted (``transforms=False``: but the transforms, which count a shorter run's snapshot
    at its end)."""
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.data_vars:
        if name != "wall_time":
            np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=str(name))
    keys = ["solver_steps", "solver_rejected", "solver_spin_iterations", "status"]
    for key in [*keys, "fft_count"] if transforms else keys:
        assert a.attrs[key] == b.attrs[key], key


def test_a_batch_continued_from_its_checkpoints_equals_the_batch_that_never_stopped(tmp_path):
    """States handed out at t = 10 (written to netCDF and read back, as a campaign's rolling
    checkpoints are) continue the same batch to t = 20 bitwise: every series, snapshot,
    scalar and counter of each seed's file; the end states too. A longer run continues a
    finished shorter one's end state the same way."""
    from nematic_solids.model.checkpoint import RunState, Schedule, load

    states: dict[int, RunState] = {}

    def keep(b, state):
        path = tmp_path / f"seed{b}.nc"
        state.to_dataset().to_netcdf(path)
        states[b] = load(path)

    whole = batch_datasets(
        PARAMS, NUMERICS, SEEDS, checkpoint=keep, schedule=Schedule(tau=10.0), keep_state=True
    )
    assert sorted(states) == [0, 1]
    assert all(s.t == 10.0 for s in states.values())
    again = batch_datasets(PARAMS, NUMERICS, SEEDS, start=[states[0], states[1]], keep_state=True)
    for (ds, end), (ref, ref_end) in zip(again, whole, strict=True):
        _same_files(ds, ref)
        assert end is not None
        assert ref_end is not None
        np.testing.assert_array_equal(end.fields, ref_end.fields)
        np.testing.assert_array_equal(end.solver.q_hat, ref_end.solver.q_hat)
        assert end.solver.h == ref_end.solver.h
    # t_final 10 -> 20: the shorter batch's end states continue to the longer one's end
    short = dataclasses.replace(NUMERICS, t_final=10.0)
    ends = [end for _, end in batch_datasets(PARAMS, short, SEEDS, keep_state=True) if end]
    assert len(ends) == len(SEEDS)
    longer = batch_datasets(PARAMS, NUMERICS, SEEDS, start=ends)
    for ds, (ref, _) in zip(longer, whole, strict=True):
        _same_files(ds, ref, transforms=False)
        assert ds.attrs["fft_count"] > ref.attrs["fft_count"]  # the short run's end snapshot


def test_a_batch_continues_a_compiled_runs_state_within_the_tolerance(runs):
    """A state of the compiled path (simulate.run's checkpoint at t = 10) continued by the
    accelerated path ends within the backends' tolerance of the compiled run to t = 20."""
    from nematic_solids.model.checkpoint import RunState, Schedule

    states: list[RunState] = []
    run(PARAMS, NUMERICS, SEEDS[0], checkpoint=states.append, schedule=Schedule(tau=10.0))
    assert [s.t for s in states] == [10.0]
    (ds,) = batch_datasets(PARAMS, NUMERICS, SEEDS[:1], start=states)
    ref = runs.reference[0]
    assert ds.attrs["solver_steps"] == ref.attrs["solver_steps"]
    for name in ("sigma2_S", "mean_S", "lambda"):
        want, have = ref[name].values, ds[name].values
        finite = np.isfinite(want)
        assert np.array_equal(finite, np.isfinite(have)), name
        scale = np.abs(want[finite]).max()
        assert np.abs(have[finite] - want[finite]).max() <= 1e-10 * scale, name


def test_a_state_that_does_not_continue_the_run_is_refused(runs):
    from nematic_solids.model.checkpoint import CheckpointError, RunState, Schedule

    states: list[RunState] = []
    run(PARAMS, NUMERICS, SEEDS[0], checkpoint=states.append, schedule=Schedule(tau=10.0))
    with pytest.raises(CheckpointError, match="seed 0's state, not seed 1's"):
        run_batch(PARAMS, NUMERICS, (1,), start=states)
    with pytest.raises(ParameterError, match="one state per seed"):
        run_batch(PARAMS, NUMERICS, SEEDS, start=states)


def test_the_finite_strain_constitutive_law_is_one_code_for_numpy_and_jax():
    """The reference's stress, its Q increment, the tangent and the energy (paper Eqs. 1-3,
    nematic_solids.model.constitutive) evaluated on JAX arrays under jit, batched over seeds,
    give the numpy values to rounding: the accelerated backend's finite strain reuses the
    formulas instead of restating them."""
    import jax.numpy as jnp

    from nematic_solids.model import constitutive as C
    from nematic_solids.model import tensors as T

    rng = np.random.default_rng(7)
    shape = (3, 8, 8)  # (seed, x, y): the batch axis rides along the grid axes
    F = np.eye(2)[:, :, None, None, None] + 0.2 * rng.standard_normal((2, 2, *shape))
    Q = T.nematic(*(0.3 * rng.standard_normal((2, *shape))))
    dQ = T.nematic(*(0.1 * rng.standard_normal((2, *shape))))
    m = C.Moduli(kappa=20.0, B=0.5, B_prime=0.1, alpha=1.5)

    def all_of(F, Q, dQ):
        return (
            C.first_piola(F, Q, m),
            C.first_piola_q_increment(F, Q, dQ, m),
            C.tangent(F, Q, m),
            C.energy_density(F, Q, m),
            C.small_strain_stress(F - T.identity(F.shape[2:], like=F), Q, m),
        )

    ref = all_of(F, Q, dQ)
    got = jax.jit(all_of)(jnp.asarray(F), jnp.asarray(Q), jnp.asarray(dQ))
    assert T.namespace(got[0]) is jnp
    for r, g in zip(ref, got, strict=True):
        assert isinstance(g, jax.Array)
        np.testing.assert_allclose(np.asarray(g), r, rtol=0, atol=1e-13 * np.abs(r).max())


#: a 32^2 finite-strain point with every coupling on: B' > 0, an applied shear
FINITE = Parameters(noise_modes=6, K=1e-3, S0=0.2, zeta=1.0, kappa=10.0).replace(
    B_prime=0.1, eps=0.03, alpha_minus_B=1.0
)


def finite_reference(params: Parameters, numerics: Numerics, seed: int):
    """The numpy reference's PDE (numpy backend) and a seeded state with a banded activity."""
    pde = ActiveNematicPDE(params, numerics.replace(backend="numpy"))
    u = np.ascontiguousarray(np.stack(initial_fields(params, N, seed)))
    u[2] = 0.3 * np.cos(2 * np.pi * (np.arange(N) + 0.5) / N)[:, None]
    return pde, u


def test_finite_force_balance_agrees_with_the_reference():
    """Newton-Krylov for Div P = 0 (paper Eq. 3) in JAX, from the homogeneous state, takes
    the reference's Newton steps to its displacement (to rounding), and a batch of two
    seeds under jax.vmap gives each seed's solve alone."""
    import jax.numpy as jnp

    from nematic_solids.model.accelerated import finite as AF

    num = Numerics(resolution=N, mechanics="finite", newton_tol=1e-10)
    sym, c = AF.setup(FINITE, num)
    solve = jax.jit(AF.force_balance, static_argnums=4)
    zero = jnp.zeros((2, N, N // 2 + 1), complex)
    F0 = AF.deformation(zero, sym, c)
    alone = []
    for seed in (3, 4):
        pde, u = finite_reference(FINITE, num, seed)
        ref = pde.mechanics.solve(u[0], u[1])
        got = solve(jnp.asarray(u[:2]), zero, F0, sym, c)
        assert int(got.status) == 0
        assert int(got.iterations) == ref.iterations >= 3
        assert float(got.residual) <= 1e-10
        scale = np.abs(ref.u_hat).max()
        np.testing.assert_allclose(np.asarray(got.u_hat), ref.u_hat, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(np.asarray(got.P), ref.P, rtol=0, atol=1e-12)
        alone.append((u[:2], got))
    q = jnp.asarray(np.stack([a[0] for a in alone]))
    both = jax.jit(jax.vmap(AF.force_balance, (0, None, None, None, None)), static_argnums=4)(
        q, zero, F0, sym, c
    )
    for i, (_, got) in enumerate(alone):
        assert int(both.iterations[i]) == int(got.iterations)
        np.testing.assert_allclose(np.asarray(both.u_hat[i]), np.asarray(got.u_hat), atol=1e-14)


@pytest.mark.parametrize("coupling", ["trP", "trS"])
def test_finite_stage_rates_agree_with_the_reference(coupling):
    """A stage's split right-hand side at a displacement off force balance (the integrated
    scheme's), in JAX: N_q, A-dot, the displacement rate and its gradient agree with the
    numpy reference's (nematic_solids.model.split.ForceBalanceSplit) to rounding, with the
    same GMRES iterations, from a zero start and warm-started from the last rate."""
    import jax.numpy as jnp

    from nematic_solids.model.accelerated import finite as AF
    from nematic_solids.model.split import ForceBalanceSplit

    params = FINITE.replace(coupling=coupling)
    num = Numerics(resolution=N, mechanics="finite", spin_tol=1e-10)
    pde, u = finite_reference(params, num, 3)
    mech, g = pde.mechanics, pde.spectral
    mech.solve(u[0], u[1])
    sym, c = AF.setup(params, num)
    split = ForceBalanceSplit(pde, np.asarray(sym.Lq))
    rates = jax.jit(AF.finite_split, static_argnums=7)
    q_hat = g.forward(u[:2])
    udot, grad = jnp.zeros((2, N, N // 2 + 1), complex), jnp.zeros((2, 2, N, N))
    for factor in (1.05, 1.06):  # two stages: the second warm-started
        d = mech.u_hat * factor
        F = mech.deformation(d)
        before = mech.spin_iterations
        Nq, Adot, _ = split(u, q_hat, 0.0, d, F)
        got = rates(*map(jnp.asarray, (u[:2], u[2], q_hat, F)), udot, grad, sym, c)
        assert bool(got.converged)
        assert not bool(got.folded)
        assert int(got.iterations) == mech.spin_iterations - before >= 5
        for a, b in ((got.Nq, Nq), (got.Adot, Adot), (got.udot_hat, mech.udot_hat)):
            np.testing.assert_allclose(np.asarray(a), b, rtol=0, atol=1e-12 * np.abs(b).max())
        np.testing.assert_allclose(
            np.asarray(got.udot_grad), mech.udot_grad, atol=1e-12 * np.abs(mech.udot_grad).max()
        )
        udot, grad = got.udot_hat, got.udot_grad


#: a 32^2 finite-strain point that patterns by t = 20, with B' and an applied shear
FINITE_RUN = PARAMS.replace(B_prime=0.1, eps=0.03)
FINITE_NUMERICS = NUMERICS.replace(mechanics="finite")


@pytest.fixture(scope="module")
def finite_runs():
    """A finite-strain batch of SEEDS as run files (with its states at t = 10 written and
    read back, and its end states), seed 1 alone, and the compiled path's runs."""
    import tempfile

    from nematic_solids.model.checkpoint import RunState, Schedule, load

    states: dict[int, RunState] = {}
    with tempfile.TemporaryDirectory() as tmp:

        def keep(b, state):
            path = f"{tmp}/seed{b}.nc"
            state.to_dataset().to_netcdf(path)
            states[b] = load(path)

        whole = batch_datasets(
            FINITE_RUN,
            FINITE_NUMERICS,
            SEEDS,
            checkpoint=keep,
            schedule=Schedule(tau=10.0),
            keep_state=True,
        )
    return SimpleNamespace(
        files=[ds for ds, _ in whole],
        ends=[end for _, end in whole],
        states=states,
        alone=run_batch(FINITE_RUN, FINITE_NUMERICS, (SEEDS[1],)),
        reference=[run(FINITE_RUN, FINITE_NUMERICS, seed) for seed in SEEDS],
    )


@pytest.mark.slow  # (about a minute: finite strain's batch compiles for two batch sizes)
def test_a_finite_strain_batch_agrees_with_the_compiled_path(finite_runs):
    """Finite strain in JAX (the displacement integrated through Krogstad's stages and
    projected onto force balance per accepted step): every seed takes the compiled run's
    accepted and rejected steps and Newton iterations, and every series, snapshot and scalar
    of its run file agrees within 1e-10 of its scale (+ 1e-14: the residual is rounding)."""
    for ds, ref in zip(finite_runs.files, finite_runs.reference, strict=True):
        assert ds.attrs["status"] == ref.attrs["status"] == "ok"
        for key in ("solver_steps", "solver_rejected", "solver_newton", "solver_projections"):
            assert ds.attrs[key] == ref.attrs[key], key
        assert ds.attrs["solver_steps"] > 50
        assert set(ds.data_vars) == set(ref.data_vars)
        for name, var in ref.data_vars.items():
            want, have = var.values, ds[name].values
            finite = np.isfinite(want)
            assert np.array_equal(finite, np.isfinite(have)), name
            if name == "wall_time" or not finite.any():
                continue
            scale = np.abs(want[finite]).max()
            assert np.abs(have[finite] - want[finite]).max() <= 1e-10 * scale + 1e-14, name
        assert ds["sigma2_S"].values[-1] > 2 * ds["sigma2_S"].values[1]  # it patterns
        assert ds["min_J"].values[-1] != 1.0  # and strains


@pytest.mark.slow  # (about a minute: finite strain's batch compiles for two batch sizes)
def test_a_finite_strain_batch_equals_its_seeds_run_alone(finite_runs):
    """Per-seed step control with finite strain: seed 1 in the batch takes the same steps,
    Newton and GMRES iterations and reaches the same fields as run alone (to 1e-12: XLA
    rounds a batch's reductions in another order; measured 2e-13)."""
    alone, ds = finite_runs.alone, finite_runs.files[1]
    assert alone.status == ["ok"]
    assert int(alone.work["steps"][0]) == ds.attrs["solver_steps"]
    assert int(alone.work["newton"][0]) == ds.attrs["solver_newton"]
    assert int(alone.work["spin_iterations"][0]) == ds.attrs["solver_spin_iterations"]
    end = finite_runs.ends[1]
    np.testing.assert_allclose(alone.fields[0], end.fields, rtol=0, atol=1e-12)


@pytest.mark.slow  # (about a minute: finite strain's batch compiles for two batch sizes)
def test_a_finite_strain_batch_continues_from_its_checkpoints_bitwise(finite_runs):
    """A finite-strain batch's states at t = 10 (through netCDF, with the displacement, its
    rate and the rate's gradient) continue it to t = 20 bitwise: every variable and the
    work of each seed's file, and the end states."""
    states = finite_runs.states
    assert sorted(states) == [0, 1]
    assert set(states[0].mechanics) == {"u_hat", "udot_hat", "udot_grad"}
    again = batch_datasets(
        FINITE_RUN, FINITE_NUMERICS, SEEDS, start=[states[0], states[1]], keep_state=True
    )
    for (ds, end), ref, ref_end in zip(again, finite_runs.files, finite_runs.ends, strict=True):
        _same_files(ds, ref)
        for key in ("solver_newton", "solver_cg_iterations"):
            assert ds.attrs[key] == ref.attrs[key], key
        assert end is not None
        assert ref_end is not None
        np.testing.assert_array_equal(end.fields, ref_end.fields)
        for key in ("u_hat", "udot_hat", "udot_grad"):
            np.testing.assert_array_equal(end.mechanics[key], ref_end.mechanics[key])


@pytest.mark.slow  # (about a minute: finite strain's batch compiles for two batch sizes)
def test_a_finite_strain_seed_that_fails_does_not_stop_its_batch(finite_runs):
    """A seed whose start is ill posed in finite strain ((alpha - B) S = 0.75 > 1/2) fails at
    t = 0 with rate_problem_ill_posed; its batch-mate's run is the batch's without it."""
    fields = np.stack([np.stack(initial_fields(FINITE_RUN, N, SEEDS[0]))] * 2)
    fields[1, 0], fields[1, 1] = 0.75, 0.0
    good, bad = batch_datasets(FINITE_RUN, FINITE_NUMERICS, SEEDS, initial=fields)
    assert bad.attrs["status"] == "failed"
    assert bad.attrs["reason"] == "rate_problem_ill_posed"
    assert bad.attrs["t_failed"] == 0.0
    assert good.attrs["status"] == "ok"
    assert good.attrs["solver_steps"] == finite_runs.files[0].attrs["solver_steps"]
    np.testing.assert_allclose(
        good["sigma2_S"].values, finite_runs.files[0]["sigma2_S"].values, rtol=1e-12, atol=1e-20
    )
