"""Chains (``chain:``): a sweep axis walked in order, each point's runs starting from the end
state of the previous point's run with the same seed and the same other values: the
quasi-static sweep that finds hysteresis.

The grid gains a first dimension :data:`~nematic_solids.sweep.campaign.BRANCH` with the branches
("up": the axis' values in increasing order, "down": decreasing). On each branch the first value's
runs begin from the seeded texture (they are the plain runs of that point); every later run begins
from its predecessor's end state at t = 0 under its own parameters, and its run id includes the
predecessor's id (:func:`nematic_solids.sweep.identity.hash_canonical`'s ``start``), so a chain's
ids follow its whole history. The runs of a chain run one after the other (the driver submits a run
with its predecessor's task as a dependency, or after its record), the chains in parallel; a chain
stopped half-way resumes at its first run not done.

With ``up: fresh`` every run of the up branch begins from the seeded texture, as Fig. 2's runs (the
plain runs of its points), so that one campaign gives the jump from a texture and the down branch's
from the pattern: the loop's width. The up branch's top run is then the down branch's first run too
(the same run id: the driver runs it once), and the down branch's second run starts from it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from .campaign import BRANCH, Campaign


def chain_parents(campaign: Campaign) -> list[int | None]:
    """For every run position of the campaign (grid points in C order, then seeds) the
    position of the run it starts from, None for the first value of its branch."""
    chain = campaign.chain
    if chain is None:
        return [None] * campaign.n_runs
    dims = campaign.dims
    names = [d.name for d in dims]
    bi, ci = names.index(BRANCH), names.index(chain.axis)
    values = dims[ci].axes[0].values
    order = sorted(range(len(values)), key=lambda k: values[k])
    rank = {k: r for r, k in enumerate(order)}
    shape, n_seeds = campaign.shape, len(campaign.seeds)
    strides = [math.prod(shape[j + 1 :]) for j in range(len(shape))]
    branches = list(dims[bi].axes[0].values)
    fresh = chain.up == "fresh" and "up" in branches
    out: list[int | None] = []
    for pos in range(campaign.n_runs):
        point, seed = divmod(pos, n_seeds)
        index = [(point // strides[j]) % shape[j] for j in range(len(shape))]
        up = branches[index[bi]] == "up"
        previous = rank[index[ci]] + (-1 if up else 1)
        if (up and fresh) or not 0 <= previous < len(values):
            out.append(None)
            continue
        index[ci] = order[previous]
        if fresh and previous == len(values) - 1:
            # the down branch's first run is the up branch's fresh run at the top: its twin
            # (the same run id), which the driver runs once, at the up branch's position
            index[bi] = branches.index("up")
        out.append(sum(i * s for i, s in zip(index, strides, strict=True)) * n_seeds + seed)
    return out


def depths(parents: Sequence[int | None]) -> list[int]:
    """How many runs come before each run in its chain (0: the first)."""
    out: list[int] = [-1] * len(parents)

    def depth(i: int) -> int:
        while out[i] < 0:
            p = parents[i]
            if p is None:
                out[i] = 0
            elif out[p] >= 0:
                out[i] = out[p] + 1
            else:  # the predecessor first (chains are short: no deep recursion)
                out[i] = depth(p) + 1
        return out[i]

    for i in range(len(parents)):
        depth(i)
    return out


def in_chain_order(todo: Sequence[int], parents: Sequence[int | None]) -> list[int]:
    """The runs to do with every run after its predecessor: by depth in its chain, then by
    position (so the first runs of all chains go first, and the chains advance together)."""
    d = depths(parents)
    return sorted(todo, key=lambda i: (d[i], i))
