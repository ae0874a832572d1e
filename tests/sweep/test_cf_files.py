"""The netCDF files (run files, phase.nc, fits.nc) follow the CF conventions: checked
attribute by attribute, by compliance-checker's cf:1.11 suite and by cfchecks (test
dependencies: the `test` extra; cfchecks' UDUNITS-2 C library is the one the cf-units wheel
carries, so no system package is needed) on small real files."""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path
from types import SimpleNamespace

import netCDF4
import pytest
from sweep_helpers import write_campaign

from nematic_solids.model.fourier import HAVE_FFTW
from nematic_solids.sweep.analysis.fits_file import load_fits, write_fits
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.outputs.aggregate import write_phase
from nematic_solids.sweep.run.task import RunTask, execute_run
from nematic_solids.sweep.spec import load_campaign, parse_campaign
from nematic_solids.sweep.store import CampaignStore
from nematic_solids.sweep.verify.measure import verify_dataset, write_verify
from nematic_solids.sweep.verify.sample import plan_sample

LIBRARIES = ("numpy", "py-pde", "numba", "xarray", "dask") + (("fftw",) if HAVE_FFTW else ())


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Four real runs (32^2, to t = 1), their phase.nc and fits.nc."""
    folder = tmp_path_factory.mktemp("cf")
    path = write_campaign(folder, name="cf", values="[0.1, 0.7]", seeds=2, t_final=1.0)
    campaign = load_campaign(path)
    expansion = expand(campaign)
    store = CampaignStore(folder / "results", campaign.name)
    store.ensure()
    for i in range(len(expansion)):
        record = execute_run(
            RunTask.from_spec(expansion.run(i), store, campaign.name, campaign.store)
        )
        assert record["status"] == "ok", record
    write_phase(expansion, store)
    fits_path, failures = write_fits(store.root, [("transition", {})])
    assert not failures
    run_file = next(iter(sorted(store.runs_dir.glob("*.nc"))))
    # verify.nc of a verification whose variant reproduces the base runs (records reused)
    checked = parse_campaign(
        path.read_text() + "fits: [transition]\nverify: {seeds: 2, variants: [{tolerance: /10}]}\n",
        str(path),
    )
    sample = plan_sample(checked, expansion, load_fits(store.root))
    records = store.scan()
    by_point = {(r.point.index, r.seed): records[r.run_id] for r in sample.base_list()}
    variant = {r.run_id: by_point[(r.point.index, r.seed)] for r in sample.variant_list()}
    verify = write_verify(store.root, verify_dataset(sample, records, variant))
    return SimpleNamespace(run=run_file, phase=store.phase_path, fits=fits_path, verify=verify)


@pytest.fixture(scope="module")
def chained(tmp_path_factory):
    """A chain's phase.nc and fits.nc (a branch dimension, the loop width; 32^2, to t = 1)
    and a protocol campaign's phase.nc (its numbers as coordinates)."""
    from nematic_solids.sweep.chains import in_chain_order

    folder = tmp_path_factory.mktemp("cf_chain")
    out = {}
    for name, extra in (
        ("chain", "chain: {axis: alpha_minus_B}\n"),
        (
            "timed",
            "protocol: {chi: {pulse: {base: 10, level: 0, start: 0.5}}}\n",
        ),
    ):
        path = write_campaign(folder, name=name, values="[0.1, 0.7]", seeds=1, t_final=1.0)
        text = path.read_text() + extra
        if name == "timed":
            text = text.replace("alpha_minus_B: [0.1, 0.7]", "chi_duration: [0.25, 0.5]")
        path.write_text(text)
        campaign = load_campaign(path)
        expansion = expand(campaign)
        store = CampaignStore(folder / "results", campaign.name)
        store.ensure()
        for i in in_chain_order(range(len(expansion)), expansion.chain_parents):
            record = execute_run(
                RunTask.from_spec(expansion.run(i), store, campaign.name, campaign.store)
            )
            assert record["status"] == "ok", record
        write_phase(expansion, store)
        out[f"{name}_phase"] = store.phase_path
        if name == "chain":
            out["chain_fits"], failures = write_fits(store.root, [("transition", {})])
            assert not failures
    return SimpleNamespace(**out)


@pytest.mark.parametrize("which", ["chain_phase", "chain_fits", "timed_phase"])
def test_chain_and_protocol_files_are_cf_clean(chained, which, tmp_path):
    path = getattr(chained, which)
    assert _checker_messages(path, tmp_path) == []
    for name, attrs in _variables(path).items():
        assert attrs.get("long_name", "").strip(), f"{name} has no long_name"


def _variables(path: Path) -> dict[str, dict]:
    with netCDF4.Dataset(path) as nc:
        return {
            name: {k: v.getncattr(k) for k in v.ncattrs()} | {"_dims": v.dimensions}
            for name, v in nc.variables.items()
        }


def _globals(path: Path) -> dict:
    with netCDF4.Dataset(path) as nc:
        return {k: nc.getncattr(k) for k in nc.ncattrs()}


@pytest.mark.parametrize("which", ["run", "phase", "fits", "verify"])
def test_global_attributes(files, which):
    attrs = _globals(getattr(files, which))
    assert attrs["Conventions"] == "CF-1.11"
    assert attrs["history"].strip()
    assert attrs["title"].strip()
    versions = dict(item.split(" ", 1) for item in attrs["library_versions"].split(", "))
    for lib in LIBRARIES:
        assert versions.get(lib, "").strip(), (lib, versions)


@pytest.mark.parametrize("which", ["run", "phase", "fits", "verify"])
def test_variable_attributes(files, which):
    variables = _variables(getattr(files, which))
    for name, attrs in variables.items():
        dims = attrs["_dims"]
        if dims == (name,):  # a coordinate variable
            assert "_FillValue" not in attrs, name
        assert attrs.get("long_name", "").strip(), f"{name} has no long_name"
        if "units" in attrs:
            # UDUNITS: the model is dimensionless ("1"); only wall times are in seconds
            assert attrs["units"] in ("1", "s"), (name, attrs["units"])
        elif "flag_values" not in attrs:  # only text (run_id, reason) has no units
            with netCDF4.Dataset(getattr(files, which)) as nc:
                assert nc.variables[name].dtype in (str, "S1"), f"{name}: no units"


def test_run_file_scales_and_time(files):
    variables = _variables(files.run)
    assert "time" not in variables  # CF reads a coordinate named time as calendar time
    assert variables["t"]["units"] == "1"
    assert "units of tau" in variables["t"]["long_name"]
    assert variables["sigma2_S"]["_dims"] == ("t",)
    assert "units of L" in variables["x"]["long_name"]
    assert "units of L" in variables["lambda"]["long_name"]
    assert "G L^2" in variables["free_energy"]["long_name"]
    assert variables["wall_time"]["units"] == "s"


def test_phase_file_seed_statistics(files):
    variables = _variables(files.phase)
    assert variables["seed"]["standard_name"] == "realization"
    assert variables["sigma2_S_mean"]["cell_methods"] == "realization: mean"
    assert variables["sigma2_S_std"]["cell_methods"] == "realization: standard_deviation"
    assert "seed" not in variables["sigma2_S_mean"]["_dims"]
    # the name in cell_methods is a scalar coordinate variable of the statistics (CF 7.3)
    assert variables["realization"]["_dims"] == ()
    assert "realization" in variables["sigma2_S_mean"]["coordinates"].split()
    assert "realization" not in variables["sigma2_S"].get("coordinates", "")  # per seed


def test_phase_file_text_is_char_arrays_read_back_as_strings(files):
    import xarray as xr

    with netCDF4.Dataset(files.phase) as nc:
        assert nc.variables["run_id"].dtype == "S1"  # classic char arrays, not vlen strings
        assert nc.variables["reason"].dtype == "S1"
    with xr.open_dataset(files.phase) as ds:
        run_ids = ds["run_id"].values.ravel().tolist()
        assert all(isinstance(r, str) and len(r) == 16 for r in run_ids)
        assert set(ds["reason"].values.ravel().tolist()) == {""}


def _checker_messages(path: Path, tmp_path: Path) -> list[str]:
    try:
        from compliance_checker.runner import CheckSuite, ComplianceChecker
    except ImportError:  # a test dependency: never skip silently
        pytest.fail("compliance-checker is not installed: pip install -e '.[test]'")
    CheckSuite.load_all_available_checkers()
    out = tmp_path / f"{path.stem}.json"
    ComplianceChecker.run_checker(
        str(path), ["cf:1.11"], 0, "normal", output_filename=str(out), output_format="json"
    )
    report = json.loads(out.read_text())["cf:1.11"]
    return [
        m
        for key in ("high_priorities", "medium_priorities", "low_priorities")
        for item in report[key]
        for m in item["msgs"]
    ]


@pytest.mark.parametrize("which", ["run", "phase", "fits", "verify"])
def test_compliance_checker_cf_1_11_reports_nothing(files, which, tmp_path):
    """No error and no warning of any priority."""
    assert _checker_messages(getattr(files, which), tmp_path) == []


#: cfchecks 4.1 knows CF up to 1.8: on a file that says CF-1.11 its one error is this (§2.6.1).
CFCHECKS_UNKNOWN_VERSION = "does not appear to contain CF Convention data"
#: The files use no area types and no region names, so empty tables stand in for the ones
#: cfchecks would download (the standard-name table is the one compliance-checker ships).
EMPTY_TABLE = '<?xml version="1.0"?>\n<{0}><version_number>0</version_number><date/></{0}>\n'


def _bundled_udunits() -> tuple[str, str] | None:
    """The UDUNITS-2 C library and its XML database that the cf-units wheel (a dependency of
    compliance-checker, so of the test extra) carries: ``(library, udunits2.xml)``, or None
    where this installation of cf-units has none (built against a system library)."""
    try:
        import cf_units
    except ImportError:
        return None
    here = Path(cf_units.__file__).parent
    libraries = sorted((here.parent / "cf_units.libs").glob("libudunits2*.so*"))
    database = here / "etc" / "share" / "udunits2.xml"
    if not libraries or not database.is_file():
        return None
    return str(libraries[0]), str(database)


def _import_cfchecker():
    """cfchecks' classes. Its units module (cfunits) loads UDUNITS-2 by
    ``ctypes.util.find_library("udunits2")``, which finds only a system installation; the
    library the cf-units wheel carries is given to it instead (with its XML database, read
    through ``UDUNITS2_XML_PATH``), so the test extra needs no system package. Without either,
    the test fails with the one line that says how to install one."""
    import ctypes.util

    bundled = _bundled_udunits()
    if bundled is None and ctypes.util.find_library("udunits2") is None:
        pytest.fail(
            "cfchecks needs the UDUNITS-2 library: pip install -e '.[test]' (cf-units' wheel "
            "carries it) or, on Debian, apt-get install libudunits2-0",
            pytrace=False,
        )
    find_library = ctypes.util.find_library
    if bundled is not None:
        library, database = bundled
        os.environ.setdefault("UDUNITS2_XML_PATH", database)
        ctypes.util.find_library = lambda name: (  # type: ignore[assignment]
            library if name == "udunits2" else find_library(name)
        )
    try:
        from cfchecker.cfchecks import CFChecker, CFVersion
    except (ImportError, OSError) as e:  # a test dependency: never skip silently
        pytest.fail(
            f"cfchecks cannot be loaded ({e}): pip install -e '.[test]' or, on Debian, "
            "apt-get install libudunits2-0",
            pytrace=False,
        )
    finally:
        ctypes.util.find_library = find_library
    return CFChecker, CFVersion


def _cfchecks(path: Path, tmp_path: Path, version: tuple[int, int]) -> dict[str, list[str]]:
    import compliance_checker

    CFChecker, CFVersion = _import_cfchecker()
    names = Path(compliance_checker.__file__).parent / "data" / "cf-standard-name-table.xml"
    tables = {}
    for kind, root in (("area", "area_type_table"), ("region", "standardized_region_list")):
        tables[kind] = tmp_path / f"{kind}.xml"
        tables[kind].write_text(EMPTY_TABLE.format(root))
    checker = CFChecker(
        cfStandardNamesXML=str(names),
        cfAreaTypesXML=str(tables["area"]),
        cfRegionNamesXML=str(tables["region"]),
        version=CFVersion(version),
        silent=True,
    )
    results = checker.checker(str(path))
    out: dict[str, list[str]] = {"FATAL": [], "ERROR": [], "WARN": []}
    for scope in [results["global"], *results["variables"].values()]:
        for level in out:
            out[level] += scope[level]
    return out


@pytest.mark.parametrize("which", ["run", "phase", "fits", "verify"])
def test_cfchecks_finds_only_the_newer_cf_version(files, which, tmp_path):
    """cfchecks (CF up to 1.8): on the file as written, the one error is that it does not
    know CF-1.11; on a copy that says CF-1.8, no error and no warning."""
    path = getattr(files, which)
    as_written = _cfchecks(path, tmp_path, (1, 8))
    assert len(as_written["ERROR"]) == 1, as_written
    assert CFCHECKS_UNKNOWN_VERSION in as_written["ERROR"][0]
    assert as_written == {"FATAL": [], "ERROR": as_written["ERROR"], "WARN": []}
    relabelled = tmp_path / path.name
    shutil.copy(path, relabelled)
    with netCDF4.Dataset(relabelled, "a") as nc:
        nc.Conventions = "CF-1.8"
    assert _cfchecks(relabelled, tmp_path, (1, 8)) == {"FATAL": [], "ERROR": [], "WARN": []}


def test_a_missing_udunits_library_is_one_line_that_says_how_to_install_it(monkeypatch):
    """Where neither the cf-units wheel nor the system has UDUNITS-2, the cfchecks tests fail
    with one line naming the install commands, never a traceback."""
    import ctypes.util

    monkeypatch.setattr(sys.modules[__name__], "_bundled_udunits", lambda: None)
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None)
    with pytest.raises(pytest.fail.Exception) as failed:
        _import_cfchecker()
    assert failed.value.pytrace is False
    message = str(failed.value)
    assert "\n" not in message
    assert "pip install -e '.[test]'" in message
    assert "apt-get install libudunits2-0" in message
