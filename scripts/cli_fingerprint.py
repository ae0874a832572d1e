"""The command line's behaviour in one JSON file, to compare before and after a change that
must not alter it (a refactoring):

    python scripts/cli_fingerprint.py --out /tmp/before.json
    ... the change ...
    python scripts/cli_fingerprint.py --out /tmp/after.json
    diff /tmp/before.json /tmp/after.json

It runs ``python -m nematic_solids.sweep`` as a user would: every command's ``--help``; ``validate``
of the shipped campaign files; a small campaign (the quickstart at 32^2 with 8 noise modes, t = 5,
one seed: 4 runs) through ``run --dry-run``, ``run``, ``status`` (text and ``--json``),
``aggregate``, ``export`` and ``report``; then it hashes what the campaign wrote: every run file's
data and attributes, ``phase.nc`` and ``fits.nc``, the campaign copy and the folder's file names.
What differs between two runs of the same code is masked: wall and CPU times, dates, process ids,
ports, load averages, the temporary folder and the provenance of the code itself (commit, code
hash).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = [
    "validate",
    "run",
    "status",
    "aggregate",
    "verify",
    "stop",
    "export",
    "report",
    "simulate",
    "stability",
    "figures",
]
VALIDATED = [
    "quickstart",
    "fig2",
    "fig2_precision",
    "fig3",
    "fig4",
    "figA1",
    "figA1_adaptive",
    "fig2_adaptive",
    "paper",
]
SMALL = [
    "--set",
    "resolution=32",
    "--set",
    "noise_modes=8",
    "--set",
    "t_final=5",
    "--seeds",
    "1",
    "--name",
    "fp",
]
#: attributes and columns that record when, where, how long, or which code
VOLATILE = re.compile(
    r"time|date|created|host|pid|commit|code_hash|code_version|history|"
    r"elapsed|started|finished|duration|stamp|mtime|path|log|worker|"
    r"saved_to|wall|cpu|load",
    re.IGNORECASE,
)
MASKS = [
    (re.compile(r"\d+(\.\d+)?(e[-+]?\d+)? ?(s|ms|min|h|CPU-h)\b"), "<T>"),
    (re.compile(r"\b\d+:\d\d(:\d\d)?\b"), "<T>"),
    (re.compile(r"\d{4}-\d\d-\d\dT[\d:.+]+Z?"), "<DATE>"),
    (re.compile(r"pid \d+"), "pid <N>"),
    (re.compile(r"(127\.0\.0\.1|localhost):\d+"), "<HOST>"),
    (re.compile(r"load average \d+(\.\d+)?"), "load average <L>"),
    (re.compile(r"about \d+ % of a core"), "about <P> % of a core"),
    (re.compile(r"\d+(\.\d+)? ?x\b"), "<X>x"),
    (re.compile(r"[0-9a-f]{7,40}(\+dirty)?"), "<HEX>"),
]


def mask(text: str, tmp: str) -> str:
    """``text`` without what varies between two runs of the same code; the progress lines,
    printed every few seconds, are dropped."""
    text = "\n".join(
        line
        for line in text.replace(tmp, "<TMP>").splitlines()
        if not line.startswith("progress: ")
    )
    for pattern, repl in MASKS:
        text = pattern.sub(repl, text)
    return "\n".join(line.rstrip() for line in text.splitlines())


def nematic(args: list[str], tmp: str) -> dict[str, Any]:
    env = dict(os.environ, COLUMNS="120", NO_COLOR="1", TERM="dumb")
    proc = subprocess.run(
        [sys.executable, "-m", "nematic_solids.sweep", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    stdout: Any = mask(proc.stdout, tmp)
    if "--json" in args:
        stdout = status_json(proc.stdout.replace(tmp, "<TMP>"))
    return {
        "args": " ".join(a.replace(tmp, "<TMP>") for a in args),
        "exit": proc.returncode,
        "stdout": stdout,
        "stderr": mask(proc.stderr, tmp),
    }


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def attrs(a: dict[str, Any]) -> dict[str, str]:
    return {k: repr(v) for k, v in sorted(a.items()) if not VOLATILE.search(k)}


def netcdf(path: Path) -> dict[str, Any]:
    import numpy as np
    import xarray as xr

    with xr.open_dataset(path) as ds:
        out: dict[str, Any] = {"attrs": attrs(dict(ds.attrs)), "vars": {}}
        for name in sorted([*ds.data_vars, *ds.coords]):
            var = ds[name]
            if VOLATILE.search(str(name)):
                out["vars"][name] = {"dims": list(var.dims)}
                continue
            values = np.asarray(var.values)
            data = (
                values.astype(str).tobytes()
                if values.dtype.kind in "OUS"
                else np.ascontiguousarray(values).tobytes()
            )
            out["vars"][name] = {
                "dims": list(var.dims),
                "dtype": str(values.dtype),
                "sha": digest(data),
                "attrs": attrs(dict(var.attrs)),
            }
    return out


def status_json(text: str) -> Any:
    def clean(x: Any) -> Any:
        if isinstance(x, dict):
            return {k: "<V>" if VOLATILE.search(k) else clean(v) for k, v in sorted(x.items())}
        if isinstance(x, list):
            return [clean(v) for v in x]
        return x

    try:
        return clean(json.loads(text))
    except ValueError:
        return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="the JSON file to write")
    args = ap.parse_args()
    out: dict[str, Any] = {"help": {}, "validate": {}, "campaign": [], "files": {}}
    with tempfile.TemporaryDirectory(prefix="clifp-") as tmp:
        out["help"]["nematic"] = nematic(["--help"], tmp)
        for cmd in COMMANDS:
            out["help"][cmd] = nematic([cmd, "--help"], tmp)
        for name in VALIDATED:
            out["validate"][name] = nematic(["validate", f"campaigns/{name}.yaml"], tmp)
        results = Path(tmp) / "results"
        q = ["campaigns/quickstart.yaml", *SMALL, "--results", str(results)]
        steps = [
            ["validate", *q],
            ["run", *q, "--dry-run"],
            ["run", *q, "--no-dashboard"],
            ["status", *q],
            ["status", *q, "--json"],
            ["aggregate", *q],
            ["run", *q, "--no-dashboard"],
            [
                "export",
                "fp",
                "--results",
                str(results),
                "--format",
                "csv",
                "-o",
                str(Path(tmp) / "fp.csv"),
            ],
            ["report", "fp", "--results", str(results)],
            ["status", "campaigns/quickstart.yaml", "--results", str(results)],
            ["aggregate", "campaigns/missing.yaml"],
            ["run", "campaigns/paper.yaml", "--name", "x"],
        ]
        for step in steps:
            out["campaign"].append(nematic(step, tmp))
        folder = results / "fp"
        out["files"]["names"] = sorted(
            str(p.relative_to(folder)) for p in folder.rglob("*") if "report_cache" not in p.parts
        )
        for p in sorted(folder.rglob("*.nc")):
            out["files"][str(p.relative_to(folder))] = netcdf(p)
        out["files"]["campaign.yaml"] = digest((folder / "campaign.yaml").read_bytes())
        import csv

        with open(Path(tmp) / "fp.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        out["files"]["fp.csv"] = digest(
            json.dumps(
                [{k: v for k, v in r.items() if not VOLATILE.search(k)} for r in rows],
                sort_keys=True,
            ).encode()
        )
    args.out.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    print(
        f"wrote {args.out}: {len(out['help'])} help texts, {len(out['validate'])} "
        f"validations, {len(out['campaign'])} campaign steps, "
        f"{len(out['files']) - 1} files hashed"
    )


if __name__ == "__main__":
    main()
