"""Collecting a campaign's problems: :class:`Checker` records each one with its key path and
where it comes from (file and line, or a command-line option); the value tests the section
readers share (:func:`is_int`, :func:`coerce`, ...)."""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..campaign import normalise_float
from ..errors import CampaignError, Problem
from ..limits import DEFAULT_MAX_RUNS

#: A key path inside the YAML document: ``("sweep", "axes", "chi", 2)``.
KeyPath = tuple[str | int, ...]


def format_path(path: KeyPath) -> str:
    """``("sweep", "axes", "chi", 2)`` -> ``"sweep.axes.chi[2]"``."""
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def suggest(name: str, valid: Sequence[str]) -> str:
    """``" (did you mean 'x'?)"`` for the closest valid name, or ``""``."""
    lowered = {v.lower(): v for v in valid}
    close = [lowered[name.lower()]] if name.lower() in lowered else []
    close = close or difflib.get_close_matches(name, list(valid), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


class Checker:
    """Collects problems with their locations."""

    def __init__(self, source: str, lines: dict[KeyPath, int], origins: dict[KeyPath, str]):
        self.source, self.lines, self.origins = source, lines, origins
        self.problems: list[Problem] = []
        self.max_runs = DEFAULT_MAX_RUNS

    def location(self, path: KeyPath) -> str:
        for n in range(len(path), -1, -1):
            if path[:n] in self.origins:
                return f"{self.origins[path[:n]]}"
        for n in range(len(path), -1, -1):
            if path[:n] in self.lines:
                return f"{self.source}:{self.lines[path[:n]]}"
        return self.source

    def add(self, path: KeyPath, message: str) -> None:
        self.problems.append(Problem(format_path(path), message, self.location(path)))

    def bad(self, path: KeyPath, value: Any, allowed: str) -> None:
        self.add(path, f"got {value!r}; allowed: {allowed}")

    def unknown(self, path: KeyPath, key: Any, valid: Sequence[str], hint: str = "") -> None:
        extra = suggest(str(key), valid) if isinstance(key, str) else ""
        self.add(path, f"unknown key {key!r}{extra}{hint}; allowed keys: {', '.join(valid)}")

    def mapping(self, path: KeyPath, value: Any, valid: Sequence[str] | None) -> dict[str, Any]:
        """Check ``value`` is a mapping with string keys from ``valid``; return the known part."""
        if value is None:
            return {}
        if not isinstance(value, Mapping):
            self.bad(path, value, "a mapping of KEY: VALUE")
            return {}
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                self.bad((*path, str(key)), key, "string keys")
            elif valid is not None and key not in valid:
                self.unknown((*path, key), key, valid)
            else:
                out[key] = item
        return out

    def raise_if_any(self) -> None:
        if self.problems:
            raise CampaignError(self.source, sorted(self.problems, key=self._line))

    def _line(self, p: Problem) -> int:
        head, _, tail = p.location.rpartition(":")
        return int(tail) if head == self.source and tail.isdigit() else 0


def is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def is_finite_number(v: Any) -> bool:
    return is_number(v) and math.isfinite(float(v))


def is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


def coerce(kind: str, value: Any) -> Any:
    """Normalise one value for a field of declared type ``kind``; ``ValueError`` if impossible."""
    if kind == "float":
        if not is_number(value) or not math.isfinite(float(value)):
            raise ValueError("a finite real number")
        return normalise_float(value)
    if kind == "int":
        if is_int(value):
            return int(value)
        if is_number(value) and float(value).is_integer():
            return int(value)
        raise ValueError("an integer")
    if kind == "bool":
        if not isinstance(value, bool):
            raise ValueError("true or false")
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise ValueError("a string")
        return value
    return value
