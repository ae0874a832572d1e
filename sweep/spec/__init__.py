"""Campaign YAML -> a validated, immutable :class:`Campaign`.

The schema (documented for users in ``docs/campaigns/file.md``)::

    name: fig2                      # results go to results/<name>/ (default: the file's stem)
    description: free text
    model: nematic                  # the model the runs compute (default: nematic, the paper's)
    parameters: {B: 0.5, K: 5.0e-5}  # base model parameters (Parameters)
    numerics: {resolution: 128, t_final: 300}   # base numerics (Numerics)
    sweep:
      axes:                         # product of all axes by default, in this order
        alpha_minus_B: {linspace: [0.1, 1.0, 10]}
        K: {logspace: [-5, -3, 3]}  # exponents, base 10 (geomspace takes the end points)
        eps: [0.0, 0.1]
      zip:                          # groups of axes that vary together (equal lengths)
        - [K, eps]
    seeds: 50                       # a count (seeds 0..49), a list, or {count: 50, start: 1000}
    store: {snapshot_times: [100, 300], snapshot_fields: [q1, q2, A], snapshot_dtype: float32}
    fits: [transition]              # names (or {name: {options}}) from analysis.registry
    figures: [fig2]                 # names (or {name: {options}}) from figures.registry;
                                    # [] draws none; absent: every figure that applies
    execution:
      workers: 2                    # local dask LocalCluster (default: one per core)
      scheduler: tcp://host:8786    # or an existing dask scheduler
      cluster: {kind: slurm, jobs: 10, cores: 8, memory: 16GB, walltime: "02:00:00"}
    refine: {axis: alpha_minus_B, observable: sigma2_S, rounds: 3}   # adaptive rounds
    precision: {observable: lambda_peak, width: 0.1}   # seeds by precision
    prior: ../docs/results/fig2/phase.nc   # a finished run's seeds: the later rounds' cost

Every mistake is collected as a :class:`~nematic_solids.sweep.errors.Problem` naming the file and
line, the key path, the value and what is allowed (with the closest valid name for unknown keys),
and raised together as one :class:`~nematic_solids.sweep.errors.CampaignError` before anything runs.

Each top-level section has one reader (:data:`SECTIONS`, in the order they are read); a new
section is a reader function, a row of that table, its key in :data:`TOP_KEYS` and a field
of :class:`~nematic_solids.sweep.campaign.Campaign`.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from nematic_solids.model.errors import ParameterError
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.resolution import is_rule, read_rule

from ..campaign import DEFAULT_MODEL, Campaign, InitialSpec
from ..errors import CampaignError, Problem
from ..limits import (
    MAX_GRID_POINTS,
    available_memory,
    fmt_bytes,
    parse_size,
    run_memory_bytes,
)
from ..models.registry import get_model, list_models
from ..settings import setting_names
from .axes import read_sweep
from .chain import read_chain
from .checker import Checker, KeyPath, is_int, suggest
from .execution import read_execution
from .initial import READING, InitialRequest, parent_error, read_initial, resolve_initial
from .model import read_model
from .points import check_points
from .precision import read_precision
from .prior import read_prior
from .protocol import read_protocol
from .refine import read_refine
from .sections import (
    check_product_options,
    read_description,
    read_figures,
    read_fits,
    read_limits,
    read_name,
    read_numerics,
    read_parameters,
    read_seeds,
    read_store,
)
from .verify import read_verify, variant_grid
from .yaml_input import NO_MEMORY, read_document, read_text

#: The top-level keys, in the order error messages list them.
TOP_KEYS = (
    "name",
    "description",
    "model",
    "parameters",
    "protocol",
    "numerics",
    "sweep",
    "seeds",
    "store",
    "fits",
    "figures",
    "execution",
    "limits",
    "refine",
    "precision",
    "verify",
    "initial",
    "chain",
    "prior",
)


class Section(NamedTuple):
    """A top-level key of the campaign YAML, the :class:`Campaign` attribute it fills, and its
    reader: ``read(checker, raw value, sections read so far by key) -> field value``."""

    key: str
    attr: str
    read: Callable[[Checker, Any, Mapping[str, Any]], Any]


#: The sections in the order they are read: ``limits`` bounds the grid sections, ``store``
#: adds to the base ``numerics``, ``sweep`` needs both base sections, ``refine`` takes its
#: seeds from ``precision`` when both are given.
SECTIONS: tuple[Section, ...] = (
    Section("limits", "limits", read_limits),
    Section("name", "name", read_name),
    Section("description", "description", read_description),
    # the model first: the sections after it read its settings and observables
    Section("model", "model", read_model),
    Section("parameters", "parameters", read_parameters),
    # the protocol joins the base parameters (the Campaign keeps the merged mapping)
    Section("protocol", "parameters", read_protocol),
    Section("numerics", "numerics", read_numerics),
    Section("store", "store", read_store),
    Section("sweep", "dims", read_sweep),
    Section("seeds", "seeds", read_seeds),
    Section("fits", "fits", read_fits),
    Section("figures", "figures", read_figures),
    Section("execution", "execution", read_execution),
    Section("precision", "precision", read_precision),
    Section("refine", "refine", read_refine),
    Section("verify", "verify", read_verify),
    Section("initial", "initial", read_initial),
    Section("chain", "chain", read_chain),
    Section("prior", "prior", read_prior),
)


@dataclass(frozen=True)
class Overrides:
    """Command-line changes applied to the YAML before validation (``--set``, ``--seeds``,
    ``--name``, ``--scheduler``, ``--workers``), e.g. to run a campaign at reduced size."""

    settings: Mapping[str, Any] = field(default_factory=dict)
    seeds: int | list[int] | None = None
    name: str | None = None
    scheduler: str | None = None
    workers: int | None = None

    def describe(self) -> tuple[str, ...]:
        out = [f"--set {k}={v!r}" for k, v in self.settings.items()]
        if self.seeds is not None:
            out.append(f"--seeds {self.seeds}")
        if self.name is not None:
            out.append(f"--name {self.name}")
        if self.scheduler is not None:
            out.append(f"--scheduler {self.scheduler}")
        if self.workers is not None:
            out.append(f"--workers {self.workers}")
        return tuple(out)


def _apply_overrides(
    doc: dict[str, Any], ov: Overrides, origins: dict[KeyPath, str], c: Checker
) -> None:
    model = doc.get("model")
    known = isinstance(model, str) and model in list_models()
    names = setting_names(model if known else DEFAULT_MODEL)
    pnames, nnames = set(names.parameters), set(names.numerics)
    for key, value in ov.settings.items():
        label = f"--set {key}={value!r}"
        if key in pnames:
            section = "parameters"
        elif key in nnames:
            section = "numerics"
        else:
            c.problems.append(
                Problem(
                    key,
                    f"unknown name{suggest(key, sorted(pnames | nnames))}"
                    f"; allowed: {', '.join(sorted(pnames | nnames))}",
                    "command line --set",
                )
            )
            continue
        if not isinstance(doc.get(section) or {}, Mapping):
            continue
        doc[section] = dict(doc.get(section) or {})
        doc[section][key] = value
        origins[(section, key)] = label
    if ov.seeds is not None:
        doc["seeds"] = ov.seeds
        origins[("seeds",)] = f"--seeds {ov.seeds}"
    if ov.name is not None:
        doc["name"] = ov.name
        origins[("name",)] = f"--name {ov.name}"
    if ov.scheduler is not None or ov.workers is not None:
        ex = dict(doc.get("execution") or {}) if isinstance(doc.get("execution"), Mapping) else {}
        if ov.scheduler is not None:
            ex.pop("cluster", None)
            ex.pop("workers", None)
            ex["scheduler"] = ov.scheduler
            origins[("execution", "scheduler")] = f"--scheduler {ov.scheduler}"
        if ov.workers is not None:
            ex.pop("cluster", None)
            ex.pop("scheduler", None)
            ex["workers"] = ov.workers
            origins[("execution", "workers")] = f"--workers {ov.workers}"
        doc["execution"] = ex


def parse_campaign(
    text: str,
    source: str = "<string>",
    overrides: Overrides | None = None,
    default_name: str | None = None,
    build_points: bool = True,
) -> Campaign:
    """Validate campaign YAML ``text``; raise
    :class:`~nematic_solids.sweep.errors.CampaignError` listing every problem.

    Every grid point is then checked by the model's own
    :class:`~nematic_solids.model.parameters.Parameters` and
    :class:`~nematic_solids.model.parameters.Numerics` (see ``sweep.spec.points.check_points``), so
    impossible values
    anywhere in the sweep are rejected here too; with ``build_points`` false they are not (a
    campaign copy read back to be shown, whose expansion builds every point again and raises
    the model's :class:`~nematic_solids.model.errors.ParameterError` at one it refuses).
    """
    overrides = overrides or Overrides()
    node, doc, lines, dups = read_document(text, source)
    if node is None:
        raise CampaignError(
            source,
            [
                Problem(
                    "",
                    "the campaign file is empty; allowed: a "
                    "mapping with keys " + ", ".join(TOP_KEYS),
                    source,
                )
            ],
        )
    origins: dict[KeyPath, str] = {}
    c = Checker(source, lines, origins)
    for d in dups:
        c.add(d, "duplicate key (YAML keeps only the last one)")
    if doc is None:
        doc = {}
    if not isinstance(doc, Mapping):
        c.bad((), doc, "a mapping with keys " + ", ".join(TOP_KEYS))
        c.raise_if_any()
    doc = dict(doc)
    for key in doc:
        if key not in TOP_KEYS:
            c.unknown((str(key),), key, TOP_KEYS)
    _apply_overrides(doc, overrides, origins, c)
    doc.setdefault("name", default_name)
    read: dict[str, Any] = {}
    for section in SECTIONS:
        read[section.key] = section.read(c, doc.get(section.key), read)
    if read["initial"] is not None:  # the parent campaign, read and checked against
        read["initial"] = _initial(c, read["initial"], read)
    if read["chain"] is not None:  # the branches are the grid's first dimension
        read["sweep"] = (read["chain"].dim, *read["sweep"])
    campaign = Campaign(
        **{section.attr: read[section.key] for section in SECTIONS},
        source=source,
        text=text,
        overrides=overrides.describe(),
    )
    limits, dims, seeds = campaign.limits, campaign.dims, campaign.seeds
    # Sizes first, by arithmetic: nothing below is built for a grid that is too large.
    before_bounds = len(c.problems)
    if campaign.n_runs > limits.max_runs:
        sizes = " x ".join(f"{len(d)} ({d.name})" for d in dims)
        c.add(
            ("sweep",) if dims else ("seeds",),
            f"{campaign.n_runs} runs ({sizes + ' x ' if dims else ''}{len(seeds)} seeds); "
            f"allowed: at most {limits.max_runs} (limits.max_runs)",
        )
    _check_points(c, campaign)
    _check_memory(c, campaign)
    if len(c.problems) > before_bounds:  # out of bounds: stop before any point is built
        c.raise_if_any()
    check_product_options(c, campaign)
    # The values are checked by the model even when the structure has problems, so that
    # every mistake of the file is reported in one pass (on what could be read of it).
    structural = list(c.problems)
    try:
        if build_points:
            check_points(campaign, c)
    except Exception:  # a structure too broken to build points
        if not structural:
            raise
        c.problems[:] = structural
    c.raise_if_any()
    return campaign


def _initial(c: Checker, request: InitialRequest, read: Mapping[str, Any]) -> InitialSpec | None:
    """``initial.from``'s parent campaign read (a chain of parents that comes back to itself
    is refused), then the section checked against it."""
    token = READING.set((*READING.get(), str(request.file.resolve())))
    try:
        parent = load_campaign(request.file)
    except CampaignError as e:
        parent_error(c, request, e, TOP_KEYS)
        return None
    finally:
        READING.reset(token)
    return resolve_initial(c, request, parent, read)


def _check_points(c: Checker, campaign: Campaign) -> None:
    """Refuse more than :data:`~nematic_solids.sweep.limits.MAX_GRID_POINTS` grid points, the
    parents' (``initial.from``, each already checked) counted with this campaign's: every one
    is built and checked by the model before anything runs."""
    parents, ancestor = 0, campaign.initial
    while ancestor is not None:
        parents += ancestor.parent.n_points
        ancestor = ancestor.parent.initial
    total = campaign.n_points + parents
    if total <= MAX_GRID_POINTS:
        return
    sizes = " x ".join(f"{len(d)} ({d.name})" for d in campaign.dims)
    theirs = f" and {parents} of the campaigns it begins from" if parents else ""
    c.add(
        ("sweep",),
        f"{campaign.n_points} grid points ({sizes}){theirs}; allowed: at most "
        f"{MAX_GRID_POINTS} (each is checked by the model before anything runs): split the "
        "study into several campaigns, or refine where the outcome changes (refine:)",
    )


def run_memory_limit(campaign: Campaign) -> tuple[int | None, str]:
    """The memory one run may use, and whose limit it is: ``limits.run_memory``, else the
    worker's (``execution.memory_limit``; a dask-jobqueue job's ``memory`` over its
    ``processes``; on the local cluster the memory here over the workers). ``None`` when it
    is not known (an external scheduler without ``limits.run_memory``)."""
    if campaign.limits.run_memory is not None:
        return campaign.limits.run_memory, "limits.run_memory"
    ex = campaign.execution
    if ex.memory_limit is not None and parse_size(ex.memory_limit) is not None:
        return parse_size(ex.memory_limit), "execution.memory_limit"
    if ex.cluster is not None:
        memory = parse_size(ex.cluster.options.get("memory"))
        processes = ex.cluster.options.get("processes") or 1
        if memory is not None and is_int(processes) and processes >= 1:
            return memory // int(processes), "execution.cluster memory / processes"
        return None, ""
    if ex.scheduler is not None:
        return None, ""
    total = available_memory()
    if total is None:
        return None, ""
    workers = ex.workers or max(1, (os.cpu_count() or 1) // ex.threads_per_worker)
    workers = min(workers, max(1, (os.cpu_count() or 1)))  # at most one run per core at once
    per = total // (workers * ex.threads_per_worker)
    return per, f"one local worker's share of this machine's memory ({workers} worker(s))"


def _check_memory(c: Checker, campaign: Campaign) -> None:
    """Refuse a grid whose largest run needs more memory than a worker has (estimated from
    the resolution and the mechanics: :func:`nematic_solids.sweep.limits.run_memory_bytes`)."""
    limit, what = run_memory_limit(campaign)
    if limit is None or not get_model(campaign.model).capabilities.memory_per_run:
        return
    axes = {a.name: a.values for a in campaign.axes}
    resolutions = axes.get(
        "resolution", (campaign.numerics.get("resolution", Numerics.resolution),)
    )
    if is_rule(resolutions[0]):
        resolutions = tuple(_rule_grids(campaign, axes))
    mechanics = axes.get("mechanics", (campaign.numerics.get("mechanics", Numerics.mechanics),))
    more = (
        "allowed: a lower resolution, or more memory per run (limits.run_memory, "
        "execution.memory_limit, fewer workers)"
    )
    grid = [(n, str(m)) for n in resolutions for m in mechanics if is_int(n) and n >= 1]
    for n, mech in grid:  # (other values: the model's own check reports them)
        need = run_memory_bytes(int(n), mech)
        if need > limit:
            path: KeyPath = (
                ("sweep", "axes", "resolution")
                if "resolution" in axes
                else ("numerics", "resolution")
            )
            c.add(
                path,
                f"got {n}: one run ({mech} mechanics) needs about {fmt_bytes(need)}, more "
                f"than {what} allows ({fmt_bytes(limit)}); {more}",
            )
            return
    for i, variant in enumerate(campaign.verify.variants if campaign.verify else ()):
        for n, mech in grid:  # a verify variant's runs are bounded as the grid's are
            vn, vmech = variant_grid(variant, int(n), mech)
            need = run_memory_bytes(vn, vmech)
            if need > limit:
                c.add(
                    ("verify", "variants", i),
                    f"the variant {variant.name} runs at resolution {vn} where the grid has "
                    f"{n}: one run ({vmech} mechanics) needs about {fmt_bytes(need)}, more "
                    f"than {what} allows ({fmt_bytes(limit)}); {more}",
                )
                return


def _rule_grids(campaign: Campaign, axes: dict[str, Any]) -> list[Any]:
    """The grids a resolution rule gives at the K and A0 values of the campaign's grid (a
    refined K lies between two of them, so its grid between theirs); [] for a bad rule,
    which the model's own check reports."""
    try:
        rule = read_rule(campaign.numerics["resolution"])
        ks = axes.get("K", (campaign.parameters.get("K", Parameters.K),))
        a0s = axes.get("A0", (campaign.parameters.get("A0", Parameters.A0),))
        return sorted({rule.grid(float(k), float(a)) for k in ks for a in a0s})
    except (ParameterError, TypeError, ValueError):
        return []


def load_campaign(path: str | Path, overrides: Overrides | None = None) -> Campaign:
    """Read and validate a campaign file (see :func:`parse_campaign`): its size is checked
    before it is read (:func:`~nematic_solids.sweep.spec.yaml_input.read_text`)."""
    p = Path(path)
    try:
        text = read_text(p)
        return parse_campaign(text, str(p), overrides, default_name=p.stem)
    except MemoryError:  # refused below, once what the check held is freed
        pass
    raise CampaignError(str(p), [Problem("", NO_MEMORY, str(p))])
