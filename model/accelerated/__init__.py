r"""The model in JAX: B seeds of one point advance together, on a CPU or a GPU, through one code
path (``jax.jit``; XLA compiles it for the device the arrays live on).

The same equations as the numpy reference (paper Eqs. (3)-(5); small-strain mechanics as
:meth:`nematic_solids.model.split.SpectralSplit.reference`, finite strain as
:class:`nematic_solids.model.mechanics.FiniteMechanics` with the integrated displacement), the same
parameters (:class:`nematic_solids.model.parameters.Parameters`,
:class:`nematic_solids.model.parameters.Numerics`), Krogstad's ETDRK4 with the same embedded error
estimate and step controller as :mod:`nematic_solids.model.solver`, in float64 or, with
``Numerics.precision = "float32"``, in float32 with the sums kept in float64
(:mod:`nematic_solids.model.accelerated.dtypes`). Every array carries
a leading batch axis (one seed per row); each seed has its own step size and its own accept / reject
/ retry decisions (per-seed control: ``jax.vmap`` of one seed's adaptive loop, whose
``lax.while_loop`` runs while any seed is still short of the save time, the seeds that are done
masked), so a seed's trajectory is the one it has when run alone. Modules:

* :mod:`nematic_solids.model.accelerated.dtypes`: which arrays a float32 run keeps in float32 and
  which sums stay float64;
* :mod:`nematic_solids.model.accelerated.device`: the device a run asks for (``"cpu"``, ``"gpu"``,
  ``"auto"``), or :class:`nematic_solids.model.errors.DeviceUnavailable`;
* :mod:`nematic_solids.model.accelerated.krylov`: restarted GMRES with an auxiliary output (the
  algorithm of :func:`nematic_solids.model.krylov.gmres_aux`) and preconditioned CG;
* :mod:`nematic_solids.model.accelerated.linear_rhs`: the small-strain split right-hand side with
  its spin solve, and its constant symbols (made by the numpy reference's own code);
* :mod:`nematic_solids.model.accelerated.finite`: finite strain's force balance (Newton-Krylov)
  and a stage's split right-hand side at a given displacement, on the reference's constitutive
  formulas (:mod:`nematic_solids.model.constitutive` takes JAX arrays);
* :mod:`nematic_solids.model.accelerated.etdrk4`: the phi functions, one Krogstad step with its
  error estimate, and the adaptive loop to a save time;
* :mod:`nematic_solids.model.accelerated.finite_step`: finite strain's Krogstad step, the
  displacement carried through the stages and projected per accepted step;
* :mod:`nematic_solids.model.accelerated.observables`: the per-save observables on the device;
* :mod:`nematic_solids.model.accelerated.run`:
  :func:`~nematic_solids.model.accelerated.run.run_batch`, the seeds of one point from t = 0
  to ``t_final``.

ETDRK2, finite strain with the displacement solved at every stage (``displacement:
equilibrium``), time protocols and the early stop are not here:
:func:`~nematic_solids.model.accelerated.run.run_batch` refuses them with
a :class:`nematic_solids.model.errors.ParameterError`. Importing this package enables JAX's float64
(``jax_enable_x64``) for the process (a float32 run casts its arrays explicitly); without JAX
installed it raises :class:`nematic_solids.model.errors.DeviceUnavailable` with the install line.
"""

from __future__ import annotations

from ..errors import DeviceUnavailable

try:
    import jax
except ImportError as exc:  # pragma: no cover - exercised where jax is absent
    raise DeviceUnavailable(
        "the accelerated backend needs JAX, which is not installed: pip install -e '.[accel]' "
        "(CPU), or pip install -e '.[accel]' 'jax[cuda12]' for an NVIDIA GPU"
    ) from exc

jax.config.update("jax_enable_x64", True)

from .device import select_device  # noqa: E402  (after float64 is on)
from .run import BatchResult, run_batch  # noqa: E402

__all__ = ["BatchResult", "run_batch", "select_device"]
