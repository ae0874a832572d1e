"""``nematic stability``: the critical strain and the growth rate of the linear-mechanics model.

The command only parses and calls :mod:`nematic_solids.model.stability`; the physics and its
conventions are in ``docs/stability.md``.
"""

from __future__ import annotations

import json as jsonlib
import math
from typing import Any

import typer

from nematic_solids.model.errors import ParameterError
from nematic_solids.model.parameters import Numerics, Parameters, split_settings

from .app import err_console, error, setup_logging

_TRUE = {"true", "yes", "on"}
_FALSE = {"false", "no", "off"}


def parse_value(text: str) -> Any:
    """``"3" -> 3``, ``"1e-4" -> 1e-4``, ``"true" -> True``; anything else stays a string
    (and is then rejected, with its name, by the Parameters/Numerics validation)."""
    low = text.strip().lower()
    if low in _TRUE:
        return True
    if low in _FALSE:
        return False
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


def parse_settings(items: list[str]) -> dict[str, Any]:
    """``["chi=10", "eps=0.1"]`` -> ``{"chi": 10, "eps": 0.1}``; raises ``ValueError`` with a
    message naming the bad item."""
    out: dict[str, Any] = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name or not value.strip():
            raise ValueError(f"--set {item!r}: expected NAME=VALUE, e.g. --set chi=10")
        if name in out:
            raise ValueError(f"--set {item!r}: {name} is set twice")
        out[name] = parse_value(value)
    return out


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _fmt(x: float | None) -> str:
    return "none below eps_max (stable)" if x is None else f"{x:.6g}"


def stability(
    set_: list[str] | None = typer.Option(
        None,
        "--set",
        metavar="NAME=VALUE",
        help="Model parameter or numerics field (repeatable), e.g. --set chi=10 "
        "--set alpha_minus_B=1 --set incompressible=true. Only mechanics=linear is "
        "analysed.",
    ),
    json_: bool = typer.Option(False, "--json", help="Print one JSON object instead of text."),
    nmax: int = typer.Option(
        8,
        "--nmax",
        min=1,
        max=64,
        help="Lattice modes 2 pi (n, m) with |n|, |m| <= NMAX enter the numerical maximum.",
    ),
    verbose: bool = typer.Option(
        False, "--verbose", "-v", help="Also log details (INFO messages, library warnings)."
    ),
    quiet: bool = typer.Option(
        False, "--quiet", "-q", help="Only results and errors: no progress, no warnings."
    ),
) -> None:
    """Critical applied shear eps (closed form and numerical bisection), the critical
    wavevector, and the leading growth rate at the given eps (paper Eq. 6, Fig. A1)."""
    setup_logging(err_console(), verbose, quiet)
    try:
        values = parse_settings(list(set_ or []))
        pvals, nvals = split_settings(values)
        nvals.setdefault("mechanics", "linear")
        numerics = Numerics.from_dict(nvals)
        if numerics.mechanics != "linear":
            raise ParameterError(
                "mechanics",
                numerics.mechanics,
                "'linear' (the stability analysis is of the small-strain model)",
            )
        if numerics.precision != "float64":
            raise ParameterError(
                "precision",
                numerics.precision,
                "float64 (the stability analysis computes its eigenvalues in float64 only; "
                "float32 runs on the accelerated backend only, for now)",
            )
        params = Parameters.from_dict(pvals)
    except (ValueError, TypeError) as exc:
        error(err_console(), exc)
        raise typer.Exit(code=2) from None

    inc = numerics.incompressible
    from nematic_solids.model.stability import (  # scipy: imported only when the command runs
        base_state,
        critical_eps_closed_form,
        critical_eps_numerical,
        max_growth_rate,
        paper_eq6,
    )

    closed = _finite(critical_eps_closed_form(params, incompressible=inc))
    crit = critical_eps_numerical(params, incompressible=inc, nmax=nmax)
    numerical = _finite(crit.eps)
    omega, mode = max_growth_rate(params, incompressible=inc, nmax=nmax)
    base = base_state(params)
    k = [2 * math.pi * mode[0], 2 * math.pi * mode[1]]
    result = {
        "critical_eps_closed_form": closed,
        "critical_eps_numerical": numerical,
        "critical_k": list(crit.k) if crit.k is not None else None,
        "critical_mode": list(crit.mode) if crit.mode is not None else None,
        "growth_rate": omega.real,
        "growth_rate_imag": omega.imag,
        "growth_rate_k": k,
        "growth_rate_mode": list(mode),
        "eps": params.eps,
        "incompressible": inc,
        "base_q1": base.q1,
        "base_A": base.A,
        "paper_eq6": _finite(paper_eq6(params)),
        "nmax": nmax,
    }
    if json_:
        typer.echo(jsonlib.dumps(result, sort_keys=True))
        return
    medium = "incompressible" if inc else f"compressible (kappa = {params.kappa:g})"
    crit_k = (
        "-"
        if crit.k is None
        else f"2 pi ({crit.mode[0]}, {crit.mode[1]}) = ({crit.k[0]:.6g}, {crit.k[1]:.6g})"
        if crit.mode is not None
        else "-"
    )
    lines = [
        f"linear mechanics, {medium}; chi (alpha - B) = {params.chi * params.alpha_minus_B:g}",
        f"critical eps, closed form : {_fmt(closed)}",
        f"critical eps, numerical   : {_fmt(numerical)}  (lattice |n|, |m| <= {nmax})",
        f"critical wavevector       : {crit_k}",
        f"paper Eq. (6) as printed  : {_fmt(_finite(paper_eq6(params)))}",
        f"at eps = {params.eps:g}: base q1 = {base.q1:.6g}, A = {base.A:.6g}; leading growth "
        f"rate {omega.real:.6g}{omega.imag:+.3g}i (1/tau) at 2 pi ({mode[0]}, {mode[1]})",
    ]
    typer.echo("\n".join(lines))
