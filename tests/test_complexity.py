"""The complexity ratchet: no function of model/ or sweep/ is rated E or F by cyclomatic
complexity (radon), except those listed here with their complexity today, which may only fall.
A new E or F function fails, a listed one that grew fails, and a listed one that is now D or
better fails until it is removed from the list, so the list only shrinks."""

from __future__ import annotations

from pathlib import Path

import pytest

radon = pytest.importorskip("radon.complexity")

ROOT = Path(__file__).resolve().parents[1]
#: rank E starts at this complexity (radon: A 1-5, B 6-10, C 11-20, D 21-30, E 31-40, F 41+)
RANK_E = 31
#: "file::function" -> its complexity today: the functions still rated E or F
ALLOWED: dict[str, int] = {
    "sweep/cli/run.py::run": 66,
    "sweep/cost/estimate.py::estimate": 45,
    "sweep/figures/fig2.py::fig2": 45,
    "sweep/figures/fig4.py::fig4": 57,
    "sweep/outputs/aggregate.py::build_phase": 51,
    "sweep/spec/axes.py::read_sweep": 47,
    "sweep/spec/verify.py::check_verify": 52,
}


def complex_functions(root: Path = ROOT) -> dict[str, int]:
    """Every function or method of model/ and sweep/ rated E or F -> its complexity."""
    out = {}
    for folder in ("model", "sweep"):
        for path in sorted((root / folder).rglob("*.py")):
            for block in radon.cc_visit(path.read_text(encoding="utf-8")):
                for b in [block, *getattr(block, "closures", [])]:
                    if b.complexity >= RANK_E:
                        name = (
                            f"{b.classname}.{b.name}" if getattr(b, "classname", None) else b.name
                        )
                        out[f"{path.relative_to(root).as_posix()}::{name}"] = b.complexity
    return out


def test_no_function_is_rated_e_or_f_but_the_listed_ones() -> None:
    found = complex_functions()
    new = {k: v for k, v in found.items() if k not in ALLOWED}
    assert not new, f"functions rated E or F (complexity >= {RANK_E}): split them: {new}"
    grown = {k: (ALLOWED[k], v) for k, v in found.items() if v > ALLOWED[k]}
    assert not grown, f"listed functions grew (was, now): {grown}"
    better = sorted(set(ALLOWED) - set(found))
    assert not better, f"now D or better: remove them from ALLOWED: {better}"


def test_the_ratchet_finds_a_complex_function(tmp_path: Path) -> None:
    branches = "\n".join(f"    if x == {i}:\n        return {i}" for i in range(RANK_E))
    (tmp_path / "model").mkdir()
    (tmp_path / "sweep").mkdir()
    (tmp_path / "sweep" / "m.py").write_text(f"def f(x):\n{branches}\n    return -1\n")
    assert complex_functions(tmp_path) == {"sweep/m.py::f": RANK_E + 1}
