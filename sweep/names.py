"""The one table of the names of the quantities a campaign sweeps and measures (:data:`NAMES`):
each one's long name, its symbol as text (the report: ``alpha_minus_B`` -> ``α − B``) and as
mathtext (the figures: ``$\\alpha - B$``), and the scale the model's number is in.

The model is dimensionless: lengths in units of the domain size L, times in units of tau,
stresses in units of G; every netCDF variable has the CF units "1" and its long name says the
scale. :func:`unit` gives that scale (``""`` for a pure number)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Name:
    """A quantity's long name, symbol (text, with Unicode) and mathtext, and scale."""

    long_name: str
    symbol: str
    tex: str
    scale: str = ""


#: parameters, observables and derived axes by their code name
NAMES: dict[str, Name] = {
    "alpha_minus_B": Name("contractility alpha - B", "α − B", r"$\alpha - B$"),
    "alpha": Name("active stress magnitude alpha", "α", r"$\alpha$"),
    "B": Name("nemato-elastic coupling B", "B", r"$B$"),
    "K": Name("Frank constant K", "K", r"$K$"),
    "chi": Name("stress-activity coupling chi", "χ", r"$\chi$"),
    "eps": Name("applied pure shear strain eps", "ε", r"$\epsilon$"),
    "S0": Name("initial nematic order S0", "S₀", r"$S_0$"),
    "A0": Name("Landau-de Gennes coefficient A0", "A₀", r"$A_0$"),
    "C": Name("quartic Landau-de Gennes coefficient C", "C", r"$C$"),
    "zeta": Name("activity relaxation rate zeta", "ζ", r"$\zeta$"),
    "s": Name("cubic activity saturation s", "s", r"$s$"),
    "gamma": Name("rotational viscosity gamma", "γ", r"$\gamma$"),
    "tau": Name("activity time scale tau", "τ", r"$\tau$"),
    "kappa": Name("bulk modulus kappa", "κ", r"$\kappa$"),
    "B_prime": Name("volumetric nemato-elastic coupling B'", "B′", r"$B'$"),
    "activity": Name("activity chi (alpha - B)", "χ(α − B)", r"$\chi(\alpha - B)$"),
    "sigma2_S": Name("variance of the nematic order S", "σ²_S", r"$\sigma^2_S$"),
    "mean_S": Name("domain mean of the nematic order S", "⟨S⟩", r"$\langle S\rangle$"),
    "cos2theta": Name("domain mean of cos(2 theta)", "⟨cos 2θ⟩", r"$\langle\cos 2\theta\rangle$"),
    "lambda": Name("pattern size lambda", "λ", r"$\lambda$", "L"),
    "lambda_peak": Name(
        "pattern size lambda at the first peak of sigma2_S", "λ_peak", r"$\lambda_{\rm peak}$", "L"
    ),
    "t_peak": Name("time of the first peak of sigma2_S", "t_peak", r"$t_{\rm peak}$", "τ"),
    "t": Name("time", "t", r"$t$", "τ"),
    "branch": Name("branch of a chain (up: increasing, down: decreasing)", "branch", "branch"),
}


def symbol(name: str) -> str:
    """``name``'s symbol as text (``alpha_minus_B`` -> ``α − B``), else ``name``."""
    return NAMES[name].symbol if name in NAMES else name


def tex(name: str) -> str:
    """``name``'s symbol as mathtext (``$\\alpha - B$``), else ``name``."""
    return NAMES[name].tex if name in NAMES else name


def unit(name: str) -> str:
    """The scale ``name``'s number is in (``L``, ``τ``), ``""`` for a pure number."""
    return NAMES[name].scale if name in NAMES else ""


def label(name: str) -> str:
    """An axis label: the symbol, with its scale in brackets (``λ [L]``)."""
    scale = unit(name)
    return f"{symbol(name)} [{scale}]" if scale else symbol(name)
