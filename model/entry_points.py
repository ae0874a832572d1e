"""The kernels' entry points: the signatures with which Python calls compiled code, as the
lines of ``model/compiled/entry_points.txt`` and back.

An entry point (:class:`EntryPoint`) is a kernel's module and name, its numba argument types
as text (:func:`type_text`, read back by :func:`read_types`: numba's cache keys a compiled
signature by these types) and what compiling it took when the list was made.
``scripts/kernel_entry_points.py`` makes the list from a tiny finite and two tiny linear runs
(one under a protocol; :func:`nematic_solids.model.warmup.warm_up`);
``python -m nematic_solids.model.warmup`` reads it (:func:`read_entry_points`) and compiles it
in parallel processes (:func:`nematic_solids.model.warmup.compile_in_parallel`, each entry by
:func:`compile_entry_point`).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: The kernels' entry points, compiled in parallel by ``python -m nematic_solids.model.warmup``.
ENTRY_POINTS_FILE = Path(__file__).with_name("compiled") / "entry_points.txt"


@dataclass(frozen=True)
class EntryPoint:
    """One signature with which Python calls a compiled kernel: ``function`` (its module and
    name), ``args`` (its numba argument types as :func:`type_text` writes them; numba's cache
    keys a compiled signature by these types) and ``seconds``, what compiling it took when the
    list was made (the longest of a module go first)."""

    function: str
    args: str
    seconds: float = 0.0

    def arg_types(self) -> tuple[Any, ...]:
        """The numba types of ``args`` (:func:`read_types`)."""
        return read_types(self.args)

    def dispatcher(self) -> Any:
        """The numba dispatcher of ``function``."""
        module, _, name = self.function.rpartition(".")
        return getattr(importlib.import_module(module), name)

    def label(self) -> str:
        """``module.function(types)``, with numba's short type names."""
        try:
            return f"{self.function}({', '.join(str(t) for t in self.arg_types())})"
        except Exception:  # noqa: BLE001 - a label never fails
            return f"{self.function}{self.args}"

    def line(self) -> str:
        """Its line in :data:`ENTRY_POINTS_FILE`."""
        return f"{self.seconds:.2f}\t{self.function}\t{self.args}"


def _type_namespace() -> dict[str, Any]:
    from numba.core import types

    def tup(*items: Any) -> Any:
        return types.BaseTuple.from_types(list(items))

    def named(cls: str, *items: Any) -> Any:
        module, _, name = cls.rpartition(".")
        return types.BaseTuple.from_types(
            list(items), getattr(importlib.import_module(module), name)
        )

    return {**vars(types), "tup": tup, "named": named}


def type_text(t: Any) -> str:
    """numba type ``t`` as text that :func:`read_types` reads back: its ``repr``
    (``Array(float64, 2, 'C', False, aligned=True)``), tuples as ``tup(...)`` and named tuples
    as ``named('module.Class', ...)`` (the argument types of a ``typing.NamedTuple`` defined
    at a module's top level). Raises ``ValueError`` for a type that does not read back."""
    from numba.core import types

    if isinstance(t, types.BaseTuple):
        members: Any = t  # a tuple type iterates over its members' types
        items = ", ".join(type_text(i) for i in members)
        cls = getattr(t, "instance_class", None)
        if cls is not None and cls is not tuple:
            text = f"named({cls.__module__ + '.' + cls.__qualname__!r}, {items})"
        else:
            text = f"tup({items})"
    else:
        text = repr(t)
    try:
        same = read_types(f"tup({text})") == (t,)
    except Exception:  # noqa: BLE001 - said below
        same = False
    if not same:
        raise ValueError(f"numba type {t} does not read back from {text}")
    return text


def read_types(text: str) -> tuple[Any, ...]:
    """The tuple of numba types that ``text`` (``tup(...)`` of :func:`type_text`) spells."""
    from numba.core import types

    # the text comes from our own file (ENTRY_POINTS_FILE); no builtins
    value: Any = eval(text, {"__builtins__": {}}, _type_namespace())
    if not isinstance(value, types.BaseTuple):
        raise ValueError(f"not a tuple of numba types: {text}")
    members: Any = value
    return tuple(members)


def read_entry_points(path: Path = ENTRY_POINTS_FILE) -> list[EntryPoint]:
    """The entry points of ``path`` (lines ``seconds<TAB>module.function<TAB>types``; ``#``
    starts a comment)."""
    out = []
    for number, raw in enumerate(path.read_text().splitlines(), 1):
        text = raw.strip()
        if not text or text.startswith("#"):
            continue
        fields = text.split("\t")
        if len(fields) != 3:
            raise ValueError(
                f"{path}:{number}: expected seconds, function and types separated by tabs"
            )
        out.append(EntryPoint(fields[1], fields[2], float(fields[0])))
    return out


def compile_entry_point(entry: EntryPoint) -> None:
    """Compile ``entry`` in this process (or load it from the disk cache)."""
    entry.dispatcher().compile(entry.arg_types())
