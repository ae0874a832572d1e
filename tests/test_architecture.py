"""The shape of the code, read from the source with ``ast``: the imports inside ``sweep/``
form no cycle and cross its groups (spec, run, outputs, cost, refine, ...) only as
:data:`MAY_IMPORT` allows, ``model/`` never imports ``sweep``, ``sweep/`` loads no module
through ``importlib``, and no file of ``model/`` or ``sweep/`` is longer than
:data:`MAX_LINES` lines."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAX_LINES = 500
#: The import package: the folders model/ and sweep/ are nematic_solids.model and
#: nematic_solids.sweep (pyproject.toml, [tool.setuptools] package-dir).
PARENT = "nematic_solids"


def module_name(path: Path, root: Path = ROOT) -> str:
    """The import name of ``path`` (a file under ``root``'s model/ or sweep/)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join([PARENT, *parts])


def imported_modules(path: Path, root: Path = ROOT) -> set[str]:
    """Every module ``path`` imports (absolute names; ``from X import name`` counts as
    ``X.name`` when that is a module of the project, else as ``X``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = module_name(path, root).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join([*base, *([node.module] if node.module else [])])
            else:
                target = node.module or ""
            out.add(target)
            out.update(f"{target}.{alias.name}" for alias in node.names)
    return out


def project_graph(package: str) -> dict[str, set[str]]:
    """Module -> the modules of ``package`` it imports."""
    files = sorted((ROOT / package).rglob("*.py"))
    names = {module_name(f) for f in files}
    return {
        module_name(f): {m for m in imported_modules(f) if m in names} - {module_name(f)}
        for f in files
    }


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (its modules in order, the first repeated), or None."""
    state: dict[str, int] = {}  # 1 on the current path, 2 done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt) :], nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_sweep_imports_form_no_cycle() -> None:
    cycle = find_cycle(project_graph("sweep"))
    assert cycle is None, "import cycle in sweep/: " + " -> ".join(cycle or [])


#: The groups of sweep/ (docs/architecture.md): a module's group is its subpackage, or "base"
#: for the modules at the top of sweep/. What each group may import of sweep besides itself
#: and the base ("*": anything); the base imports only itself.
MAY_IMPORT: dict[str, set[str]] = {
    # the seam: the model interface and the registry that finds a campaign's model
    "base": {"models.interface", "models.registry"},
    # the names of fits and figures, and the shape of a campaign they need
    # the campaign's model (its settings and observables)
    "spec": {"analysis.registry", "analysis.shape", "figures.registry", "models"},
    "catalogue": set(),
    # the model interface and registry, and the models shipped as plugins (the nematic
    # model's cost is the calibrated cost model)
    "models": {"cost.model"},
    # the cost model sizes the tasks of grouped runs (sweep.run.group)
    "run": {"catalogue", "cost.model", "models"},
    "outputs": {"spec", "refine", "precision", "catalogue", "analysis.fits_file", "models"},
    "cost": {"outputs", "refine", "precision", "catalogue"},
    "analysis": set(),
    # the figures of a model other than the paper's read its theory (sweep/models)
    "figures": {"analysis", "verify", "models"},
    "refine": {"spec", "run", "outputs", "precision", "analysis"},
    "precision": {"spec", "run", "outputs", "refine", "analysis"},
    "verify": {"spec", "run", "outputs", "refine", "precision", "analysis", "models"},
    # the observables a campaign's model declares (what the diagram shows)
    "report": {"spec", "outputs", "refine", "precision", "verify", "analysis", "figures", "models"},
    # the service: the queue, the runner that drives campaigns, the API and dashboard
    "service": {
        "catalogue",
        "models",
        "spec",
        "run",
        "outputs",
        "cost",
        "refine",
        "precision",
        "verify",
        "analysis",
        "figures",
        "report",
    },
    "cli": {"*"},
}
#: Where the base may reach out: ``python -m nematic_solids.sweep`` is the command line, and
#: ``sweep.open_campaign`` is imported on first use from nematic_solids.sweep.outputs.tables.
BASE_EXCEPTIONS = {
    (f"{PARENT}.sweep.__main__", "cli"),
    (f"{PARENT}.sweep", "outputs.tables"),
}


def group_of(module: str) -> str:
    """The group of a module of ``nematic_solids.sweep``: its subpackage, or "base"."""
    parts = module.split(".")
    if len(parts) >= 3 and (ROOT / "sweep" / parts[2]).is_dir():
        return parts[2]
    return "base"


def boundary_violations(graph: dict[str, set[str]]) -> list[str]:
    """Every import of ``graph`` (sweep's) that crosses a group boundary not in
    :data:`MAY_IMPORT`."""
    bad = []
    for module, targets in sorted(graph.items()):
        mine = group_of(module)
        allowed = MAY_IMPORT[mine]
        for target in sorted(targets):
            theirs = group_of(target)
            if theirs in (mine, "base") or "*" in allowed:
                continue
            rest = target.split(".", 2)[2]
            if theirs in allowed or any(rest == a or rest.startswith(a + ".") for a in allowed):
                continue
            if mine == "base" and any(
                module == m and rest.startswith(a) for m, a in BASE_EXCEPTIONS
            ):
                continue
            bad.append(f"{module} ({mine}) imports {target} ({theirs})")
    return bad


def test_sweep_groups_import_only_what_they_may() -> None:
    """spec (reading a campaign file) never imports run, outputs or the command line; run
    (the driver, the worker task, the cluster) imports only the base; nothing but the command
    line (and ``python -m nematic_solids.sweep``) imports the command line."""
    graph = project_graph("sweep")
    assert set(MAY_IMPORT) >= {group_of(m) for m in graph}, "a group without its row"
    bad = boundary_violations(graph)
    assert not bad, "imports across sweep/'s groups (docs/architecture.md):\n" + "\n".join(bad)


def test_the_boundary_check_finds_a_crossing() -> None:
    graph = {
        "nematic_solids.sweep.spec.sections": {
            "nematic_solids.sweep.run.driver",
            "nematic_solids.sweep.campaign",
            "nematic_solids.sweep.analysis.registry",
        },
        "nematic_solids.sweep.run.driver": {"nematic_solids.sweep.outputs.status"},
        "nematic_solids.sweep.cli.app": {"nematic_solids.sweep.run.task"},
    }
    assert boundary_violations(graph) == [
        f"{PARENT}.sweep.run.driver (run) imports {PARENT}.sweep.outputs.status (outputs)",
        f"{PARENT}.sweep.spec.sections (spec) imports {PARENT}.sweep.run.driver (run)",
    ]


def test_model_never_imports_sweep() -> None:
    bad = {
        f"{module_name(f)} imports {m}"
        for f in (ROOT / "model").rglob("*.py")
        for m in imported_modules(f)
        if m == f"{PARENT}.sweep" or m.startswith(f"{PARENT}.sweep.")
    }
    assert not bad, sorted(bad)


@pytest.mark.parametrize("folder", ["model", "sweep", "tests", "scripts", "benchmarks", "docs"])
def test_nothing_imports_the_bare_names(folder: str) -> None:
    """The code is imported as ``nematic_solids.model`` and ``nematic_solids.sweep`` only:
    importing the bare name ``model`` or ``sweep`` (``from sweep.x import y``) would load the
    folder as a top-level package of its own (or a user's ``model.py``) beside the installed
    one."""
    bad = sorted(
        f"{f.relative_to(ROOT)} imports {m}"
        for f in (ROOT / folder).rglob("*.py")
        if "_build" not in f.parts
        for m in imported_modules(f)
        if m.split(".")[0] in {"model", "sweep"}
    )
    assert not bad, bad


#: The one module that loads modules by name: the models' registry, through entry points.
ENTRY_POINT_LOADER = "nematic_solids.sweep.models.registry"


def test_sweep_uses_no_importlib() -> None:
    bad = [
        module_name(f)
        for f in (ROOT / "sweep").rglob("*.py")
        if any(m == "importlib" or m.startswith("importlib.") for m in imported_modules(f))
        and module_name(f) != ENTRY_POINT_LOADER
    ]
    assert not bad, f"importlib in {bad}: import modules by name, in plain sight"


def long_files(package: str, root: Path = ROOT) -> dict[str, int]:
    """The files of ``package`` longer than :data:`MAX_LINES` lines, with their lengths."""
    return {
        str(f.relative_to(root)): n
        for f in sorted((root / package).rglob("*.py"))
        if (n := len(f.read_text(encoding="utf-8").splitlines())) > MAX_LINES
    }


@pytest.mark.parametrize("package", ["model", "sweep"])
def test_files_are_short(package: str) -> None:
    long = long_files(package)
    assert not long, f"files over {MAX_LINES} lines (split them by concept): {long}"


def test_the_length_check_finds_long_files(tmp_path: Path) -> None:
    (tmp_path / "model" / "compiled").mkdir(parents=True)
    (tmp_path / "model" / "short.py").write_text("x = 1\n" * MAX_LINES)
    (tmp_path / "model" / "compiled" / "long.py").write_text("x = 1\n" * (MAX_LINES + 1))
    assert long_files("model", tmp_path) == {"model/compiled/long.py": MAX_LINES + 1}


def test_the_cycle_finder_finds_cycles() -> None:
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("from .spec import AMB\n", {f"{PARENT}.sweep.spec", f"{PARENT}.sweep.spec.AMB"}),
        ("from . import fits\n", {f"{PARENT}.sweep", f"{PARENT}.sweep.fits"}),
        (
            "from nematic_solids.model import errors\n",
            {f"{PARENT}.model", f"{PARENT}.model.errors"},
        ),
        ("import importlib\n", {"importlib"}),
    ],
)
def test_imports_are_resolved(tmp_path: Path, source: str, expected: set[str]) -> None:
    (tmp_path / "sweep").mkdir()
    path = tmp_path / "sweep" / "expand.py"
    path.write_text(source)
    assert imported_modules(path, tmp_path) == expected


# --------------------------------------------------------------------------- the models' seam
#: The campaign manager's core (docs/architecture.md, "The seam"): the base (campaign, store,
#: identity, expand, ...) and these groups. It reaches a model through sweep.models only.
CORE_GROUPS = ("base", "spec", "run", "outputs", "refine", "precision", "verify", "report")
#: The modules that may import the nematic model's code at will: its plugin.
PLUGIN = {"sweep/models/nematic.py", "sweep/models/nematic_identity.py"}
#: Core files that still import nematic_solids.model, and why: a ratchet. The test fails when
#: another core file imports it, and when a file listed here no longer does (remove it then),
#: so the list only shrinks.
CORE_MODEL_IMPORTS: dict[str, str] = {
    "sweep/errors.py": "exceptions extend NematicError; ParameterError, DeviceUnavailable",
    "sweep/protocols.py": "protocol axes read with the model's Protocol",
    "sweep/provenance.py": "the model's version and library versions",
    "sweep/run/continuation.py": "checkpoints and end states are the model's RunState",
    "sweep/spec/__init__.py": "the memory bound before any point is built: the nematic grids",
    "sweep/spec/execution.py": "what the accelerated backend supports",
    "sweep/spec/initial.py": "a parent's points as Parameters/Numerics; the resolution rule",
    "sweep/spec/points.py": "float32 and the accelerated backend's checks of a point",
    "sweep/spec/protocol.py": "the protocol section read by the model's Protocol",
}
#: Files outside the core that import nematic_solids.model: the paper's own commands, fits
#: and cost calibration, and the command line's and service's handling of the model's errors.
OTHER_MODEL_IMPORTS: dict[str, str] = {
    "sweep/analysis/fits_file.py": "the model's errors",
    "sweep/analysis/stability.py": "the stability fit: the model's linear stability analysis",
    "sweep/cli/app.py": "one line for any of the model's errors",
    "sweep/cli/products.py": "the model's errors",
    "sweep/cli/simulate.py": "nematic simulate: one run of the model",
    "sweep/cli/stability.py": "nematic stability: the model's linear stability analysis",
    "sweep/cost/estimate.py": "the resolution rule of a point",
    "sweep/cost/model.py": "the nematic model's calibrated run time",
    "sweep/figures/produce.py": "the model's errors",
    "sweep/service/__init__.py": "the model's errors",
}


def model_importers(root: Path = ROOT) -> dict[str, str]:
    """Each file of sweep/ that imports nematic_solids.model (or a module of it) -> its group."""
    out = {}
    for f in sorted((root / "sweep").rglob("*.py")):
        if any(
            m == f"{PARENT}.model" or m.startswith(f"{PARENT}.model.")
            for m in imported_modules(f, root)
        ):
            rel = f.relative_to(root)
            out[rel.as_posix()] = rel.parts[1] if len(rel.parts) > 2 else "base"
    return out


def test_the_core_reaches_the_model_only_through_the_listed_files() -> None:
    found = model_importers()
    core = {f for f, g in found.items() if g in CORE_GROUPS}
    assert core - set(CORE_MODEL_IMPORTS) == set(), (
        "core files that import nematic_solids.model: reach the model through "
        "sweep.models (get_model(campaign.model)) instead"
    )
    assert set(CORE_MODEL_IMPORTS) - core == set(), (
        "files that no longer import nematic_solids.model: remove them from CORE_MODEL_IMPORTS"
    )


def test_only_the_plugin_and_the_listed_products_import_the_model() -> None:
    found = model_importers()
    other = {f for f, g in found.items() if g not in CORE_GROUPS} - PLUGIN
    assert set(found) >= PLUGIN
    assert other - set(OTHER_MODEL_IMPORTS) == set(), "import the model through sweep.models"
    assert set(OTHER_MODEL_IMPORTS) - other == set(), "no longer imports it: remove from the list"
    assert all(g in MAY_IMPORT for g in CORE_GROUPS if g != "base")


def test_the_seam_check_finds_a_new_importer(tmp_path: Path) -> None:
    (tmp_path / "sweep" / "run").mkdir(parents=True)
    (tmp_path / "sweep" / "run" / "task.py").write_text(
        "def f():\n    from nematic_solids.model.simulate import run\n"
    )
    (tmp_path / "sweep" / "expand.py").write_text("from nematic_solids.sweep import models\n")
    assert model_importers(tmp_path) == {"sweep/run/task.py": "run"}
