"""What keeps the short commands fast (sweep/startup.py; the times are measured in
benchmarks/report_time.py, not here): ``nematic --help`` imports none of the numerical
libraries, xarray recognises dask arrays made after :func:`defer_dask_array` without
importing ``dask.array`` before, the FFTW version is read without numba, and the garbage
collector is paused and restored. Each check runs in a fresh interpreter, where nothing is
imported yet. What ``nematic report`` and ``status`` import: tests/sweep/test_report.py."""

from __future__ import annotations

import gc
import os
import subprocess
import sys
from pathlib import Path

from sweep_helpers import cli_modules

from nematic_solids.sweep.startup import FRESH_PROCESS, paused_gc

ROOT = Path(__file__).resolve().parents[2]


def python(code: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_the_help_imports_no_numerical_library():
    modules, out = cli_modules("--help")
    assert "Usage" in out
    for heavy in (
        "numpy",
        "yaml",
        "xarray",
        "pandas",
        "dask",
        "distributed",
        "numba",
        "matplotlib",
        "bokeh",
    ):
        assert heavy not in modules, heavy


def test_xarray_recognises_dask_arrays_made_after_the_deferral():
    out = python(
        "import sys\n"
        "import numpy as np, xarray as xr\n"
        "from nematic_solids.sweep.startup import defer_dask_array\n"
        "assert defer_dask_array()\n"
        "ds = xr.Dataset({'a': ('x', np.arange(3.0))})\n"
        "assert float(ds['a'].sum()) == 3.0\n"
        "print('dask.array' in sys.modules)\n"
        "import dask.array as da\n"
        "v = xr.Variable(('x',), da.ones(4, chunks=2))\n"
        "print(type(v.data).__name__, v.chunks)\n"
        "m = xr.Variable(('x',), np.ma.masked_array([1.0, 2.0], mask=[True, False]))\n"
        "print(np.isnan(m.values[0]))\n"
        "print(defer_dask_array())\n"
    )
    assert out.split() == ["False", "Array", "((2,", "2),)", "True", "False"]


def test_the_fftw_version_is_read_without_numba():
    out = python(
        "import sys\n"
        "from nematic_solids.model.provenance import _fftw_version, fftw_candidates\n"
        "light = _fftw_version()\n"
        "print('numba' in sys.modules)\n"
        "import nematic_solids.model.compiled.fftw as fftw\n"
        "_fftw_version.cache_clear()\n"
        "print(light == _fftw_version())\n"
        "print(list(fftw_candidates()) == fftw._candidates())\n"
        "print(bool(light) == fftw.AVAILABLE)\n"
    )
    assert out.split() == ["False", "True", "True", "True"]


def test_the_collector_is_paused_and_restored():
    assert gc.isenabled()
    with paused_gc():
        assert not gc.isenabled()
        with paused_gc():
            assert not gc.isenabled()
        assert not gc.isenabled()
    assert gc.isenabled()
    assert not FRESH_PROCESS["on"]  # a test process is not the command line's own: no freeze

    @paused_gc()
    def command() -> bool:
        return gc.isenabled()

    assert command() is False
    assert gc.isenabled()
