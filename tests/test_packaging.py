"""The code installs as one import package, ``nematic_solids`` (``nematic_solids.model`` is the
folder model/, ``nematic_solids.sweep`` the folder sweep/: pyproject.toml's package-dir), so a
user's own ``model.py`` or ``sweep`` package beside a notebook breaks nothing.

The default suite checks the package list and the imports from a folder that holds such a
``model.py`` and ``sweep/`` (with this environment's install). ``pytest -m package`` (CI runs it;
a few minutes: it installs the dependencies and compiles the kernels) builds the wheel, installs
it, not editable, into a fresh virtual environment, makes that environment's site-packages
read-only and runs a small campaign with ``nematic run`` from such a folder: it must finish,
write phase.nc and compile the numba kernels into a writable cache outside the package (the
user's ``~/.cache/nematic``: :func:`nematic_solids.model.compiled.cache_dir`). As root (CI),
the campaign runs as the user ``nobody`` (``runuser``), for whom the read-only folder is
read-only indeed: root writes anywhere.
"""

from __future__ import annotations

import os
import pwd
import shutil
import stat
import subprocess
import sys
import tempfile
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PARENT = "nematic_solids"

#: A user's own files, which shadowed the code when it installed as the top-level packages
#: model and sweep (importing sweep failed beside a model.py: "'model' is not a package").
USER_MODEL_PY = "raise ImportError('the user model.py was imported')\n"
USER_SWEEP_INIT = "raise ImportError('the user sweep package was imported')\n"


def user_folder(folder: Path) -> Path:
    """``folder`` with a notebook user's own ``model.py`` and ``sweep/`` package in it."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "model.py").write_text(USER_MODEL_PY)
    (folder / "sweep").mkdir(exist_ok=True)
    (folder / "sweep" / "__init__.py").write_text(USER_SWEEP_INIT)
    return folder


def test_every_package_folder_is_listed() -> None:
    """pyproject.toml lists every folder of model/ and sweep/ with an ``__init__.py`` as a
    package of ``nematic_solids`` (a folder left out would be missing from the wheel)."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert config["package-dir"] == {f"{PARENT}.model": "model", f"{PARENT}.sweep": "sweep"}
    folders = {
        ".".join([PARENT, *init.parent.relative_to(ROOT).parts])
        for top in ("model", "sweep")
        for init in (ROOT / top).rglob("__init__.py")
        if "__pycache__" not in init.parts
    }
    # a folder of data only (no __init__.py) is listed as the package of its package-data
    folders |= {
        name
        for name in config.get("package-data", {})
        if not ROOT.joinpath(*name.split(".")[1:], "__init__.py").is_file()
    }
    listed = set(config["packages"])
    assert listed == folders, (
        f"add to pyproject.toml's [tool.setuptools] packages: {sorted(folders - listed)}; "
        f"remove: {sorted(listed - folders)}"
    )


def test_imports_beside_a_user_model_py(tmp_path: Path) -> None:
    """From a folder with its own ``model.py`` and ``sweep/`` (first on ``sys.path``), the
    command line, the campaign manager and the model import, from this environment."""
    folder = user_folder(tmp_path / "notebooks")
    code = (
        "import nematic_solids.sweep.cli, nematic_solids.model.simulate, sys; "
        "from nematic_solids import sweep; "
        "print(sweep.open_campaign.__module__); "
        "print('model' in sys.modules, 'sweep' in sys.modules)"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=folder, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [f"{PARENT}.sweep.outputs.tables", "False", "False"]


# --- the wheel in a fresh environment (pytest -m package) ---

CAMPAIGN = """\
name: wheel
description: two runs at 32^2, from the installed wheel
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 2, save_every: 1}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.5]
seeds: 1
execution:
  workers: 1
"""


def _run(
    cmd: list[str],
    cwd: Path | None = None,
    env: dict[str, str] | None = None,
    timeout: float = 600,
) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(cmd, cwd=cwd, env=env, timeout=timeout, capture_output=True, text=True)
    assert done.returncode == 0, f"{cmd} failed ({done.returncode}):\n{done.stdout}\n{done.stderr}"
    return done


def _source_copy(dest: Path) -> Path:
    """The repository's source (what a clone holds, without environments, caches, results or
    the documentation's build) in ``dest``: the wheel is built from it, not from the working
    folder, whose compiled kernels' caches and build folders it must not see."""
    shutil.copytree(
        ROOT,
        dest,
        ignore=shutil.ignore_patterns(
            ".git",
            ".venv",
            "__pycache__",
            "results",
            "build",
            "_build",
            "_generated",
            "*.egg-info",
            ".*_cache",
            ".typecheck",
            "docs",
        ),
    )
    return dest


def _as_user() -> tuple[list[str], int | None]:
    """The command prefix that runs a command as an unprivileged user, and that user's uid:
    nothing and None for a user who is not root; ``runuser -u nobody --`` for root."""
    if os.geteuid() != 0:
        return [], None
    runuser = shutil.which("runuser")
    try:
        nobody = pwd.getpwnam("nobody")
    except KeyError:
        nobody = None
    if runuser is None or nobody is None:
        pytest.skip("running as root without runuser or the user nobody: read-only untestable")
    return [runuser, "-u", "nobody", "--"], nobody.pw_uid


def _interpreter(prefix: list[str]) -> str:
    """A Python (>= 3.11, with venv) for the fresh environment that the user of ``prefix`` may
    run: this environment's base interpreter, else ``python3`` on PATH (a base interpreter under
    root's home, e.g. pyenv's, is out of the user nobody's reach)."""
    candidates = [os.path.realpath(getattr(sys, "_base_executable", sys.executable))]
    candidates += [p for p in (shutil.which("python3"), "/usr/bin/python3") if p]
    check = "import sys, venv, ensurepip; assert sys.version_info >= (3, 11)"
    for python in dict.fromkeys(candidates):
        done = subprocess.run([*prefix, python, "-c", check], capture_output=True, timeout=120)
        if done.returncode == 0:
            return python
    pytest.skip(f"no Python >= 3.11 with venv that the test's user can run: {candidates}")


def _chown_tree(path: Path, uid: int) -> None:
    for dirpath, _dirs, files in os.walk(path):
        os.chown(dirpath, uid, -1)
        for f in files:
            os.chown(os.path.join(dirpath, f), uid, -1, follow_symlinks=False)


def _read_only(path: Path, on: bool) -> None:
    """Take away (``on``) or give back the write permission of every file and folder."""
    write = stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH
    for dirpath, dirs, files in os.walk(path):
        for name in [*dirs, *files]:
            p = os.path.join(dirpath, name)
            if not os.path.islink(p):
                mode = os.stat(p).st_mode
                os.chmod(p, (mode & ~write) if on else (mode | stat.S_IWUSR))
        mode = os.stat(dirpath).st_mode
        os.chmod(dirpath, (mode & ~write) if on else (mode | stat.S_IWUSR))


@pytest.fixture
def scratch() -> Iterator[Path]:
    """A folder that every user can enter (pytest's own tmp_path is private to its user)."""
    path = Path(tempfile.mkdtemp(prefix="nematic-wheel-"))
    path.chmod(0o755)
    yield path
    _read_only(path, on=False)
    shutil.rmtree(path, ignore_errors=True)


@pytest.mark.package
def test_wheel_in_a_fresh_venv_runs_a_campaign(scratch: Path) -> None:
    prefix, uid = _as_user()
    # the wheel, from a copy of the source
    wheels = scratch / "wheels"
    source = _source_copy(scratch / "src")
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(wheels), str(source)])
    (wheel,) = wheels.glob("active_nematic_solids-*.whl")
    # a fresh environment with the wheel (not editable) and its dependencies from the index
    venv = scratch / "venv"
    _run([_interpreter(prefix), "-m", "venv", str(venv)], timeout=300)
    python = venv / "bin" / "python"
    _run([str(python), "-m", "pip", "install", "-q", str(wheel)], timeout=1800)
    site = Path(
        _run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]
        ).stdout.strip()
    )
    installed = site / PARENT
    assert {p.name for p in installed.iterdir()} == {"model", "sweep"}  # nothing else
    assert not (site / "model").exists()
    assert not (site / "sweep").exists()
    assert (installed / "model" / "compiled" / "fftw_wisdom.txt").is_file()
    assert (installed / "model" / "compiled" / "entry_points.txt").is_file()
    _read_only(site, on=True)

    # the user's folder, with their own model.py and sweep/, and their home
    work = user_folder(scratch / "notebooks")
    (work / "wheel.yaml").write_text(CAMPAIGN)
    home = scratch / "home"
    home.mkdir()
    if uid is not None:
        _chown_tree(work, uid)
        _chown_tree(home, uid)
    env = {
        "PATH": f"{venv / 'bin'}:/usr/bin:/bin",
        "HOME": str(home),
        "MPLBACKEND": "Agg",
        "LANG": "C.UTF-8",
    }

    def as_user(*cmd: str) -> list[str]:
        """``cmd`` as the test's user, in ``env`` (runuser would set HOME to nobody's own,
        /nonexistent: a user without a writable home sets NUMBA_CACHE_DIR, docs/guide)."""
        if not prefix:
            return list(cmd)
        return [*prefix, "env", "-i", *(f"{k}={v}" for k, v in env.items()), *cmd]

    probe = (
        "import os, nematic_solids.sweep as s, nematic_solids.model.compiled as c; "
        "print(s.__file__); print(c.cache_dir()); "
        "print(os.access(os.path.dirname(c.__file__), os.W_OK))"
    )
    where = _run(as_user(str(python), "-c", probe), cwd=work, env=env).stdout.split()
    assert Path(where[0]).is_relative_to(installed)  # the wheel's code, not the source tree
    cache = Path(where[1])
    assert cache.is_relative_to(home / ".cache" / "nematic"), where  # read-only: home instead
    assert where[2] == "False"  # the package folder is read-only for this user

    nematic = str(venv / "bin" / "nematic")
    _run(as_user(nematic, "run", "wheel.yaml", "--no-dashboard"), cwd=work, env=env, timeout=3600)
    assert (work / "results" / "wheel" / "phase.nc").is_file()
    assert len(list((work / "results" / "wheel" / "runs").glob("*.nc"))) == 2
    # the kernels were compiled into the user's cache, and nothing was written into the package
    assert list(cache.rglob("*.nbi"))
    assert list(cache.rglob("*.nbc"))
    assert not [p for p in installed.rglob("numba-*") if p.parent.name == "__pycache__"]
    # python -m works from the same folder
    version = _run(as_user(str(python), "-m", f"{PARENT}.sweep", "--version"), cwd=work, env=env)
    assert version.stdout.strip()
