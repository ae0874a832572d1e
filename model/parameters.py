"""Model parameters and numerics: two frozen, keyword-only, validated objects.

The physical constants carry the paper's symbols (Eqs. 1-5). The Fig. 2 caption fixes
``S0, A0, gamma/tau, B, K, chi``; every other constant is our choice, documented with its
reason in ``docs/model/constants.md`` (table "Constants").

``alpha_minus_B`` is accepted as an input everywhere a dict of parameters is read
(``alpha = B + alpha_minus_B``), because the paper sweeps the contractility ``alpha - B``.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

from .errors import ParameterError
from .protocol import Protocol, protocol_from

if TYPE_CHECKING:
    import numpy as np

MECHANICS = ("finite", "linear")
#: the initial director texture (Parameters.initial; docs/model/texture.md)
INITIAL = ("band", "per_node")
#: the stress that drives the activity in Eq. (5) (Parameters.coupling)
COUPLINGS = ("trP", "trS")
#: the choices of the parameters that are words
CHOICES = {"initial": INITIAL, "coupling": COUPLINGS}
#: Most saved times (rows of the time series) and snapshots of one run.
MAX_SAVES = 1_000_000
#: Most time steps one run may need at its largest step (t_final / dt_max).
MAX_STEPS = 10**8
SCHEMES = ("etdrk4", "etdrk2")
ERROR_NORMS = ("max", "rms")
#: how the finite-strain displacement is found at the stages of a step (Numerics.displacement)
DISPLACEMENT = ("integrated", "equilibrium")
#: how the numerics are executed: "compiled" (numba + native FFTW, where FFTW loads; the numpy
#: path otherwise) or "numpy" (the readable reference). Results agree to rounding (tested), so
#: the backend is not part of a run's identity.
BACKENDS = ("compiled", "numpy")
#: the precision of a run's fields and passes (Numerics.precision; docs/guide/precision.md)
PRECISIONS = ("float64", "float32")
#: what the compiled and numpy backends allow (model.simulate.run)
FLOAT64_ONLY = "float64 (float32 runs on the accelerated backend only, for now)"


def _suggest(name: str, valid: list[str]) -> str:
    close = difflib.get_close_matches(name, valid, n=1)
    return f"did you mean '{close[0]}'? " if close else ""


@dataclass(frozen=True, kw_only=True)
class Parameters:
    """Dimensionless constants of paper Eqs. (1)-(5). Lengths in units of L, stresses in
    units of the shear modulus G, time in units of tau (so ``tau = 1`` by default).

    Attributes:
        S0: initial (homogeneous) nematic order parameter S.
        A0: A_0, the Landau-de Gennes quadratic coefficient without activity.
        B: nemato-elastic deviatoric coupling.
        B_prime: B', nemato-elastic volumetric coupling.
        C: quartic Landau-de Gennes coefficient (bounds S).
        K: Frank constant.
        kappa: bulk modulus of the neo-Hookean matrix (2-D, in units of G).
        alpha: active stress magnitude.
        chi: stress-activity coupling, Eq. (5) f = chi tr P (or tr S: ``coupling``).
        zeta: linear relaxation of the activity A, Eq. (5).
        s: cubic saturation of the activity A, Eq. (5).
        gamma: rotational viscosity of Q, Eq. (4).
        tau: time scale of A, Eq. (5).
        eps: applied macroscopic pure shear, F_bar = diag(1 + eps, 1 - eps).
        initial: the initial director texture: "band" (a band-limited random field with the
            Fourier modes 2 pi (n, m), n^2 + m^2 <= noise_modes^2: the same physical field at
            every resolution) or "per_node" (an independent random orientation at every grid
            node, the paper's "initial random orientation": resolution dependent by nature).
        noise_modes: the band of the "band" texture (unused by "per_node"); resolution > 2x it.
        texture_resolution: "per_node" only: the grid the per-node texture is drawn on (0,
            the default: the run's own grid). A run on a finer grid gets that texture by
            spectral interpolation, so that it starts from the same physical field (the
            resolution variant of a verification, sweep/verify).
        noise_amplitude: RMS of an extra Gaussian (q1, q2) perturbation drawn from the same
            random field (needed when S0 = 0, as in Fig. A1).
        coupling: the stress of Eq. (5)'s f = chi tr(.): "trP" (the first Piola stress, the
            paper's Eq. 5) or "trS" (the second Piola stress S = F^-1 P, which the paper's text
            says it also tried); equal at small strain (linear mechanics uses tr sigma).
        protocol: alpha - B, chi and eps as functions of time (:mod:`nematic_solids.model.protocol`;
        empty:
            constant). Where it makes one time dependent, the plain field holds its value at
            t = 0 and :meth:`at` gives the constants at a time.
    """

    S0: float = 0.1
    A0: float = 0.1
    B: float = 0.5
    B_prime: float = 0.0
    C: float = 3.0
    K: float = 5e-5
    kappa: float = 20.0
    alpha: float = 1.5
    chi: float = 10.0
    zeta: float = 0.5
    s: float = 10.0
    gamma: float = 1.0
    tau: float = 1.0
    eps: float = 0.0
    initial: str = "band"
    noise_modes: int = 32
    texture_resolution: int = 0
    noise_amplitude: float = 0.0
    coupling: str = "trP"
    protocol: Protocol = Protocol()

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "protocol":
                if not isinstance(value, Protocol):
                    raise ParameterError(
                        "protocol", value, "a nematic_solids.model.protocol.Protocol"
                    )
            elif f.type in ("str", str):
                if value not in CHOICES[f.name]:
                    raise ParameterError(f.name, value, " or ".join(CHOICES[f.name]))
            elif f.type in ("int", int):
                if isinstance(value, bool) or not isinstance(value, int):
                    if isinstance(value, float) and value.is_integer():
                        object.__setattr__(self, f.name, int(value))
                        continue
                    raise ParameterError(f.name, value, "an integer")
            else:
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise ParameterError(f.name, value, "a real number")
                if not math.isfinite(value):
                    raise ParameterError(f.name, value, "a finite real number")
                object.__setattr__(self, f.name, float(value))
        positive = ("gamma", "tau", "kappa")
        non_negative = ("S0", "K", "C", "zeta", "s", "chi", "B", "noise_amplitude")
        for name in positive:
            if getattr(self, name) <= 0:
                raise ParameterError(name, getattr(self, name), "a number > 0")
        for name in non_negative:
            if getattr(self, name) < 0:
                raise ParameterError(name, getattr(self, name), "a number >= 0")
        if self.S0 >= 1:
            raise ParameterError("S0", self.S0, "0 <= S0 < 1")
        if not -0.5 < self.eps < 0.5:
            raise ParameterError("eps", self.eps, "-0.5 < eps < 0.5 (J_bar = 1 - eps^2 > 0)")
        if not 1 <= self.noise_modes <= 256:
            raise ParameterError("noise_modes", self.noise_modes, "an integer in [1, 256]")
        if self.texture_resolution != 0 and not (
            self.texture_resolution >= 16 and self.texture_resolution % 2 == 0
        ):
            raise ParameterError(
                "texture_resolution",
                self.texture_resolution,
                "0 (the run's grid) or an even integer >= 16",
            )
        if self.texture_resolution and self.initial != "per_node":
            raise ParameterError(
                "texture_resolution",
                self.texture_resolution,
                "0 unless initial = 'per_node' (the band texture is the same "
                "physical field at every resolution already)",
            )
        if self.protocol:
            self._check_protocol()

    def _check_protocol(self) -> None:
        """Every value the protocol takes is a valid value of its parameter; the plain
        fields hold the values at t = 0."""
        bounds = {"chi": (0.0, math.inf, "a number >= 0"), "eps": (-0.5, 0.5, "-0.5 < eps < 0.5")}
        for name in self.protocol.names:
            if name not in bounds:
                continue
            lo, hi, usage = bounds[name]
            for v in self.protocol.extremes(name):
                if v < lo or v > hi or (name == "eps" and abs(v) == 0.5):
                    raise ParameterError(f"protocol.{name}", v, f"values with {usage}")
        at0 = self.protocol.values(0.0)
        if "alpha_minus_B" in at0:
            object.__setattr__(self, "alpha", self.B + at0["alpha_minus_B"])
        for name in ("chi", "eps"):
            if name in at0:
                object.__setattr__(self, name, at0[name])

    @property
    def alpha_minus_B(self) -> float:
        """The contractility alpha - B that the paper's figures are plotted against."""
        return self.alpha - self.B

    def at(self, t: float, after: float | None = None) -> Parameters:
        """The constants at time ``t`` (on the protocol's pieces that hold ``after``:
        :meth:`nematic_solids.model.protocol.Protocol.values`), without the protocol; ``self``
        without one."""
        if not self.protocol:
            return self
        base = self.to_dict()
        base.pop("protocol")
        values = self.protocol.values(t, after)
        if "alpha_minus_B" in values:
            base["alpha"] = self.B + values.pop("alpha_minus_B")
        return Parameters(**{**base, **values})

    def to_dict(self) -> dict[str, Any]:
        """Every field; ``protocol`` only where there is one, in its canonical form
        (:meth:`nematic_solids.model.protocol.Protocol.to_dict`)."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "protocol"}
        if self.protocol:
            out["protocol"] = self.protocol.to_dict()
        return out

    @classmethod
    def names(cls) -> list[str]:
        return [f.name for f in fields(cls)]

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> Parameters:
        """Build from a mapping; ``alpha_minus_B`` sets ``alpha = B + alpha_minus_B``."""
        values = dict(values)
        valid = cls.names()
        protocol, constants = protocol_from(values.pop("protocol", None))
        for name, value in constants.items():  # a constant function is the plain parameter
            values[name] = value
            if name == "alpha_minus_B":
                values.pop("alpha", None)
        if protocol:
            values["protocol"] = protocol
        amb = values.pop("alpha_minus_B", None)
        for key in values:
            if key not in valid:
                raise ParameterError(
                    key,
                    values[key],
                    f"{_suggest(key, valid + ['alpha_minus_B'])}known parameters: "
                    + ", ".join(valid + ["alpha_minus_B"]),
                )
        if amb is not None:
            if "alpha" in values:
                raise ParameterError(
                    "alpha_minus_B", amb, "either 'alpha' or 'alpha_minus_B', not both"
                )
            if isinstance(amb, bool) or not isinstance(amb, (int, float)):
                raise ParameterError("alpha_minus_B", amb, "a real number")
            values["alpha"] = float(values.get("B", cls.B)) + float(amb)
        return cls(**values)

    def replace(self, **changes: Any) -> Parameters:
        """A copy with ``changes``; ``alpha_minus_B`` keeps B (or the new B) and sets alpha."""
        base = self.to_dict()
        if "alpha_minus_B" in changes:
            base.pop("alpha")
        return Parameters.from_dict({**base, **changes})


@dataclass(frozen=True, kw_only=True)
class Numerics:
    """How the equations are solved (not what they are).

    Attributes:
        resolution: N, grid points per side of the periodic unit square (even, >= 16; band
            texture: N > 2 ``noise_modes``, so that its modes fit the grid).
        t_final: end time (units of tau).
        dt: initial (and, with ``adaptive = False``, fixed) time step.
        scheme: time integrator, "etdrk4" (Krogstad's fourth-order exponential Runge-Kutta,
            embedded third-order error estimate) or "etdrk2" (second order, embedded ETD1).
        adaptive: adapt dt from the scheme's embedded error estimate.
        tolerance: absolute local error tolerance per step (per field, in ``error_norm``).
        error_norm: "max" (the largest pointwise error: no grid point may leave the accurate
            trajectory) or "rms" (the RMS over the grid).
        dt_max: largest step the adaptive controller may take.
        save_every: interval between saved time-series points.
        snapshot_times: times at which full fields are stored (final time always is).
        mechanics: "finite" (neo-Hookean, Newton-Krylov) or "linear" (small strain).
        incompressible: linear mechanics only: enforce div u = 0 by spectral projection.
        displacement: finite mechanics only: "integrated" (the displacement is part of the
            integrated state, advanced with the displacement rate the spin solve computes, and
            projected back onto force balance once per accepted step) or "equilibrium"
            (force balance solved by Newton at every stage: the cross-check).
        newton_tol: force-balance residual tolerance (see docs/model/numerics.md, "Residual").
        max_newton: Newton iterations allowed per solve before failing.
        spin_tol: relative GMRES tolerance of the Jaumann spin solve.
        backend: "compiled" (the Krylov solves and the linear right-hand side as compiled
            functions with native FFTW, where FFTW loads) or "numpy" (their readable
            reference); results agree to rounding.
        steady_tol: early stop (0, the default: off): at a save time t, the run ends when
            sigma2_S and mean_S each changed by at most this fraction of the larger of their
            two values between t - ``steady_window`` and t (the saved values; a relaxing run,
            whose sigma2_S decays geometrically, never counts as steady, until it reaches
            round-off level and stops changing).
        steady_window: the time span of that comparison (units of tau; with steady_tol > 0
            at least save_every and below t_final).
        precision: "float64" (default) or "float32": fields, transforms and passes in float32,
            sums, time and step in float64 (docs/guide/precision.md); accelerated only. In the id.
    """

    resolution: int = 128
    t_final: float = 300.0
    dt: float = 0.05
    scheme: str = "etdrk4"
    adaptive: bool = True
    tolerance: float = 1e-3
    error_norm: str = "max"
    dt_max: float = 1.0
    save_every: float = 5.0
    snapshot_times: tuple[float, ...] = ()
    mechanics: str = "finite"
    incompressible: bool = False
    displacement: str = "integrated"
    newton_tol: float = 1e-6
    max_newton: int = 30
    spin_tol: float = 1e-2
    backend: str = "compiled"
    steady_tol: float = 0.0
    steady_window: float = 50.0
    precision: str = "float64"

    def _snapshot_times(self) -> tuple[float, ...]:
        """``snapshot_times`` as a sorted tuple of times in [0, t_final], at most MAX_SAVES."""
        snaps = self.snapshot_times
        snaps = (snaps,) if isinstance(snaps, (int, float)) else snaps
        try:
            snaps = tuple(sorted(float(t) for t in snaps))
        except (TypeError, ValueError):
            raise ParameterError("snapshot_times", self.snapshot_times, "a list of times") from None
        if any(not 0 <= t <= self.t_final for t in snaps):
            raise ParameterError(
                "snapshot_times", list(snaps), f"times between 0 and t_final = {self.t_final}"
            )
        if len(snaps) > MAX_SAVES:
            raise ParameterError(
                "snapshot_times", f"{len(snaps)} times", f"at most {MAX_SAVES} snapshot times"
            )
        return snaps

    def __post_init__(self) -> None:
        def number(name: str, *, integer: bool = False) -> float:
            value = getattr(self, name)
            ok = isinstance(value, int) if integer else isinstance(value, (int, float))
            if isinstance(value, bool) or not ok or not math.isfinite(value):
                if integer and isinstance(value, float) and value.is_integer():
                    object.__setattr__(self, name, int(value))
                    return int(value)
                raise ParameterError(name, value, "an integer" if integer else "a real number")
            if not integer:
                object.__setattr__(self, name, float(value))
            return value

        n = number("resolution", integer=True)
        if n < 16 or n % 2:
            raise ParameterError("resolution", n, "an even integer >= 16")
        for name in (
            "t_final",
            "dt",
            "tolerance",
            "dt_max",
            "save_every",
            "newton_tol",
            "spin_tol",
        ):
            if number(name) <= 0:
                raise ParameterError(name, getattr(self, name), "a number > 0")
        if number("steady_tol") < 0:
            raise ParameterError("steady_tol", self.steady_tol, "a number >= 0 (0: no early stop)")
        if number("steady_window") <= 0:
            raise ParameterError("steady_window", self.steady_window, "a number > 0")
        if self.steady_tol > 0 and not self.save_every <= self.steady_window < self.t_final:
            raise ParameterError(
                "steady_window",
                self.steady_window,
                f"at least save_every "
                f"({self.save_every}) and below t_final ({self.t_final}) when steady_tol > 0",
            )
        if number("max_newton", integer=True) < 1:
            raise ParameterError("max_newton", self.max_newton, "an integer >= 1")
        for name, words in (
            ("error_norm", ERROR_NORMS),
            ("scheme", SCHEMES),
            ("mechanics", MECHANICS),
            ("displacement", DISPLACEMENT),
            ("backend", BACKENDS),
            ("precision", PRECISIONS),
        ):
            if getattr(self, name) not in words:
                raise ParameterError(name, getattr(self, name), " or ".join(words))
        for name in ("adaptive", "incompressible"):
            if not isinstance(getattr(self, name), bool):
                raise ParameterError(name, getattr(self, name), "true or false")
        if self.incompressible and self.mechanics != "linear":
            raise ParameterError(
                "incompressible",
                True,
                "true only with mechanics = 'linear' (finite strain "
                "is compressible with bulk modulus kappa)",
            )
        object.__setattr__(self, "snapshot_times", self._snapshot_times())
        # Bounds on the work and the memory of one run, checked before anything is allocated.
        if self.t_final / self.save_every > MAX_SAVES:
            raise ParameterError(
                "t_final",
                self.t_final,
                f"at most {MAX_SAVES} saved times: t_final / "
                f"save_every <= {MAX_SAVES} (save_every = {self.save_every}; raise it)",
            )
        step = self.dt_max if self.adaptive else self.dt
        if self.t_final / step > MAX_STEPS:
            raise ParameterError(
                "t_final",
                self.t_final,
                f"at most {MAX_STEPS:.0e} time steps of the largest "
                f"step allowed: t_final / {'dt_max' if self.adaptive else 'dt'} <= "
                f"{MAX_STEPS:.0e} ({'dt_max' if self.adaptive else 'dt'} = {step})",
            )

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["snapshot_times"] = list(self.snapshot_times)
        return d

    @classmethod
    def names(cls) -> list[str]:
        return [f.name for f in fields(cls)]

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> Numerics:
        valid = cls.names()
        for key in values:
            if key not in valid:
                raise ParameterError(
                    key,
                    values[key],
                    f"{_suggest(key, valid)}known numerics: " + ", ".join(valid),
                )
        return cls(**dict(values))

    def replace(self, **changes: Any) -> Numerics:
        return Numerics.from_dict({**self.to_dict(), **changes})


def check_compatible(params: Parameters, numerics: Numerics) -> None:
    """Constraints that involve both objects: the grid must resolve a band-limited initial
    texture (resolution > 2 noise_modes, so the same physical field exists at this
    resolution), a per-node texture drawn on a grid no finer than the run's, and a protocol's
    time scales resolved (:func:`nematic_solids.model.time_scales.check_time_scales`)."""
    if params.protocol:
        from .time_scales import check_time_scales

        check_time_scales(params, numerics)
    if params.texture_resolution > numerics.resolution:
        raise ParameterError(
            "texture_resolution",
            params.texture_resolution,
            f"at most the resolution ({numerics.resolution}): a texture is carried to a finer "
            "grid, not a coarser one",
        )
    if params.initial == "band" and numerics.resolution <= 2 * params.noise_modes:
        raise ParameterError(
            "resolution",
            numerics.resolution,
            f"an even integer > 2 * noise_modes = {2 * params.noise_modes} (the initial field "
            f"has Fourier modes up to {params.noise_modes}; raise the resolution or lower "
            "noise_modes)",
        )


def split_settings(values: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Split a flat mapping of NAME -> value into (parameters, numerics) dicts.

    Unknown names raise :class:`ParameterError` with the closest valid name suggested.
    """
    pnames = set(Parameters.names()) | {"alpha_minus_B"}
    nnames = set(Numerics.names())
    params: dict[str, Any] = {}
    numerics: dict[str, Any] = {}
    for key, value in values.items():
        if key in pnames:
            params[key] = value
        elif key in nnames:
            numerics[key] = value
        else:
            valid = sorted(pnames | nnames)
            raise ParameterError(
                key, value, f"{_suggest(key, valid)}known names: " + ", ".join(valid)
            )
    return params, numerics


__all__ = ["MECHANICS", "Numerics", "Parameters", "check_compatible", "split_settings"]


def save_times(numerics: Numerics) -> np.ndarray:
    """The save times of a run: regular saves every ``save_every`` plus ``t_final`` and the
    snapshot times (the time stepper lands on each, so they shape the steps)."""
    import numpy as np  # here: the command line's help reads this module without numpy

    regular = np.arange(0.0, numerics.t_final, numerics.save_every)
    times = np.concatenate([regular, [numerics.t_final], numerics.snapshot_times])
    return np.unique(np.round(times, 12))
