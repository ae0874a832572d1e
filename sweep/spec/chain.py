"""The ``chain:`` section (nematic_solids.sweep.chains): the axis walked in order and the branches,
checked against the sweep with file:line."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from ..campaign import BRANCH, BRANCHES, CHAIN_STARTS, DEFAULT_MODEL, ChainSpec, Dim, StoreSpec
from ..models.interface import resolution_rule
from ..models.registry import get_model
from .checker import Checker, is_number, suggest

CHAIN_KEYS = ("axis", "branches", "up")
#: the axes that set the grid of the fields: a run could not begin from its predecessor's
GRID_AXES = ("resolution",)


def read_chain(c: Checker, raw: Any, read: Mapping[str, Any]) -> ChainSpec | None:
    """``chain: {axis, branches, up}`` (branches: ``up``, ``down`` or both; default both; up:
    ``predecessor``, default, or ``fresh``: each run of the up branch from the seeded texture). The
    axis is a swept dimension of its own (not zipped) with two or more numbers; a chain
    begins from the seeded texture, so it has no ``initial``, ``refine``, ``precision`` or
    ``verify`` section. A run begins from its predecessor's fields on the same grid and from its
    exact end state: the axis is not one that sets the grid (:data:`GRID_AXES`), and the store
    keeps end states (``store.end_state``). None without it."""
    if raw is None:
        return None
    spec = c.mapping(("chain",), raw, CHAIN_KEYS)
    if not isinstance(raw, Mapping):
        return None
    dims = {d.name: d for d in read.get("sweep") or ()}
    axis = spec.get("axis")
    ok = _axis_ok(c, axis, dims, read)
    ok = _store_ok(c, read.get("store")) and ok
    if BRANCH in dims:
        c.add(("sweep", "axes", BRANCH), f"'{BRANCH}' names the chain's branches; rename it")
        ok = False
    branches = _branches(c, spec)
    up = spec.get("up", CHAIN_STARTS[0])
    if up not in CHAIN_STARTS:
        c.bad(("chain", "up"), up, " or ".join(CHAIN_STARTS))
        ok = False
    others = [k for k in ("initial", "refine", "precision", "verify") if read.get(k) is not None]
    if others:
        c.add(("chain",), f"a chain has no {' or '.join(others)} section (it starts from t = 0)")
        ok = False
    return ChainSpec(str(axis), branches, str(up)) if ok and branches is not None else None


def _axis_ok(c: Checker, axis: Any, dims: Mapping[str, Dim], read: Mapping[str, Any]) -> bool:
    """Whether ``axis`` can be walked in order: a swept axis of its own with two or more
    numbers that keeps the grid of the fields (not a :data:`GRID_AXES` one, nor one that
    ``resolution: auto`` sets the grid by); else ``False``, its problem added to ``c``."""
    ok = True
    if not isinstance(axis, str):
        c.bad(("chain", "axis"), axis, "the name of one swept axis")
        ok = False
    elif axis in GRID_AXES:
        c.add(
            ("chain", "axis"),
            f"a chain along {axis} would change the grid between a run and the next, which "
            "starts from its fields; sweep it as a plain axis (each chain keeps its grid)",
        )
        ok = False
    elif axis not in dims:
        names = [a.name for d in dims.values() for a in d.axes]
        hint = f"; the swept axes: {', '.join(names)}" if names else " (nothing is swept)"
        c.bad(("chain", "axis"), axis, f"a swept axis{suggest(str(axis), names)}{hint}")
        ok = False
    elif len(dims[axis].axes) > 1:
        c.bad(("chain", "axis"), axis, "an axis of its own (not in a zip group)")
        ok = False
    elif len(dims[axis]) < 2 or not all(is_number(v) for v in dims[axis].axes[0].values):
        c.bad(("chain", "axis"), axis, "an axis of two or more numbers")
        ok = False
    model = get_model(read.get("model") or DEFAULT_MODEL)
    setting = (read.get("numerics") or {}).get("resolution")
    if ok and axis in ("K", "A0") and resolution_rule(model, setting) is not None:
        c.add(
            ("chain", "axis"),
            f"a chain along {axis} with resolution: auto would change the grid between a run "
            "and the next, which starts from its fields; set a resolution (a number)",
        )
        ok = False
    return ok


def _store_ok(c: Checker, store: StoreSpec | None) -> bool:
    """Whether the store keeps the end states a chain's runs begin from (``end_state``);
    else ``False``, its problem added to ``c``."""
    if store is not None and not store.end_state:
        c.add(
            ("store", "end_state"),
            "a chain's runs begin from their predecessor's exact end state, which only a store "
            "with end_state: true keeps (a snapshot is not it: another precision, fields left "
            "out); keep end_state: true",
        )
        return False
    return True


def _branches(c: Checker, spec: Mapping[str, Any]) -> tuple[str, ...] | None:
    """``branches:`` (``up``, ``down`` or both; default both) as a tuple; ``None``, its
    problem added to ``c``, when it is not."""
    branches: Any = spec.get("branches", list(BRANCHES))
    if isinstance(branches, str):
        branches = [branches]
    if (
        not isinstance(branches, Sequence)
        or not branches
        or any(b not in BRANCHES for b in branches)
        or len(set(branches)) != len(branches)
    ):
        c.bad(("chain", "branches"), spec.get("branches"), "up, down or [up, down]")
        return None
    return tuple(branches)
