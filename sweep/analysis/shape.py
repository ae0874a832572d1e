"""The shape of a campaign as the fits and figures see it (:class:`Shape`): its sweep dims with
the axes each carries, its chain's axis, its time protocol. Built from a validated campaign
(:meth:`Shape.of_campaign`, so that the validator refuses a fit or figure the campaign cannot
have, at its file:line) or from its phase.nc (:meth:`Shape.of_phase`, what the figures' registry
decides from after a run): the same answers from either."""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..campaign import AMB, BRANCH, DEFAULT_MODEL

if TYPE_CHECKING:
    import xarray as xr

    from ..campaign import Campaign


@dataclass(frozen=True)
class Shape:
    """``dims``: one tuple per sweep dim (the dim's name first, then the axes zipped onto it);
    ``chain_axis``: the chain's axis or ``""``; ``protocol``: the time protocol
    (``{parameter: {kind: {...}}}``, empty without one); ``mechanics``: the campaign's."""

    dims: tuple[tuple[str, ...], ...]
    chain_axis: str = ""
    protocol: Mapping[str, Any] = field(default_factory=dict)
    mechanics: str = "finite"
    #: the campaign's model (``model:``): a fit or figure reads one model's observables
    model: str = DEFAULT_MODEL

    @classmethod
    def of_campaign(cls, campaign: Campaign) -> Shape:
        dims = [tuple(a.name for a in d.axes) for d in campaign.dims]
        if campaign.chain is not None and (BRANCH,) not in dims:
            dims.insert(0, (BRANCH,))
        protocol = campaign.parameters.get("protocol") or {}
        return cls(
            tuple(dims),
            campaign.chain.axis if campaign.chain is not None else "",
            dict(protocol) if isinstance(protocol, Mapping) else {},
            str(campaign.numerics.get("mechanics", "finite")),
            campaign.model,
        )

    @classmethod
    def of_phase(cls, phase: xr.Dataset) -> Shape:
        from .phase import sweep_dims

        dims = []
        for d in sweep_dims(phase):
            zipped = [str(n) for n, c in phase.coords.items() if c.dims == (d,) and str(n) != d]
            dims.append((d, *sorted(zipped)))
        raw = phase.attrs.get("param_protocol")
        try:
            protocol = json.loads(str(raw)) if raw else {}
        except ValueError:
            protocol = {}
        return cls(
            tuple(dims),
            str(phase.attrs.get("chain_axis", "")) if BRANCH in phase.dims else "",
            protocol if isinstance(protocol, Mapping) else {},
            str(phase.attrs.get("num_mechanics", "finite")),
            str(phase.attrs.get("model", DEFAULT_MODEL)),
        )

    @property
    def chained(self) -> bool:
        return bool(self.chain_axis)

    def swept(self, name: str) -> bool:
        """Whether ``name`` varies (a sweep axis, zipped or not; ``alpha_minus_B`` also when
        ``alpha`` or ``B`` is swept)."""
        names = {n for d in self.dims for n in d}
        return name in names or (name == AMB and bool({"alpha", "B"} & names))

    def others(self, used: Iterable[str], options: Mapping[str, Any] | None = None) -> list[str]:
        """The sweep dims that carry none of ``used`` and that the option ``select`` (in
        ``options``) does not fix: those a fit along ``used`` would have to pick a value of."""
        chosen = set(used) | set(((options or {}).get("select") or {}).keys())
        if AMB in chosen:
            chosen |= {"alpha", "B"}
        return [d[0] for d in self.dims if not chosen & set(d)]

    def sine_of_eps(self) -> bool:
        """An oscillatory shear: a sine of eps in the protocol."""
        spec = self.protocol.get("eps")
        return isinstance(spec, Mapping) and "sine" in spec

    def pulse_of_activity(self) -> bool:
        """A switch-off of activity: a pulse of alpha - B in the protocol."""
        spec = self.protocol.get(AMB)
        return isinstance(spec, Mapping) and "pulse" in spec


def pick_one(what: str, extra: list[str]) -> str:
    """The refusal of a fit or figure over more sweep dims than it reads."""
    return (
        f"{what} reads no more than its axes, but the campaign also varies "
        f"{', '.join(extra)}: pick one value with the option select: {{{extra[0]}: VALUE}}"
    )
