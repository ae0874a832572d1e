"""Campaign YAML text -> a document with the line of every key, and command-line values read
as YAML. A file too large, or whose aliases expand too far, is refused before it is built."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

import yaml

from ..errors import CampaignError, Problem
from .checker import KeyPath

#: Largest campaign file read (bytes), and most YAML nodes after aliases are expanded: a
#: file of anchors that refer to anchors (a "billion laughs") is refused before it is built.
MAX_TEXT_BYTES = 4 * 2**20
MAX_YAML_NODES = 100_000


class _Loader(yaml.SafeLoader):
    """Safe loader that also reads ``1e-5`` (no dot) as a float, as YAML 1.2 does."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"^(?:[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+|[-+]?\.[0-9_]+[eE][-+]?[0-9]+)$"
    ),
    list("-+0123456789."),
)


def parse_value(text: str) -> Any:
    """A command-line value read as YAML (``0.3`` -> float, ``[1, 2]`` -> list, ``abc`` -> str)."""
    try:
        return yaml.load(text, Loader=_Loader)  # _Loader is a SafeLoader
    except yaml.YAMLError:
        return text


def parse_assignments(items: Sequence[str]) -> dict[str, Any]:
    """``["K=1e-4", "resolution=64"]`` -> ``{"K": 1e-4, "resolution": 64}``.

    Raises :class:`CampaignError` for an item without ``=``.
    """
    out: dict[str, Any] = {}
    problems = []
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            problems.append(Problem(f"--set {item}", "expected NAME=VALUE", "command line"))
            continue
        out[name.strip()] = parse_value(value.strip())
    if problems:
        raise CampaignError("command line", problems)
    return out


def _expanded_size(root: yaml.Node) -> int:
    """How many nodes the document has once every alias is expanded (each distinct node is
    visited once: linear in the file, whatever the expansion)."""
    sizes: dict[int, int] = {}
    open_: set[int] = set()  # being sized: meeting one again is a recursive alias
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        if id(node) in sizes:
            continue
        if isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        elif isinstance(node, yaml.SequenceNode):
            children = list(node.value)
        else:
            sizes[id(node)] = 1
            continue
        if done:
            sizes[id(node)] = min(1 + sum(sizes[id(n)] for n in children), 2**62)
            open_.discard(id(node))
            continue
        if id(node) in open_:
            return 2**62  # a value that contains itself: infinitely large
        open_.add(id(node))
        stack.append((node, True))
        for n in children:
            if id(n) in open_:
                return 2**62
            if id(n) not in sizes:
                stack.append((n, False))
    return sizes[id(root)]


def _walk(node: yaml.Node, path: KeyPath, lines: dict[KeyPath, int], dups: list[KeyPath]) -> None:
    lines[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        seen: set[Any] = set()
        for key_node, value_node in node.value:
            key = key_node.value
            if key in seen:
                dups.append((*path, key))
            seen.add(key)
            lines[(*path, key)] = key_node.start_mark.line + 1
            _walk(value_node, (*path, key), lines, dups)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _walk(item, (*path, i), lines, dups)


def read_document(
    text: str, source: str
) -> tuple[yaml.Node | None, Any, dict[KeyPath, int], list[KeyPath]]:
    """``text`` parsed: its root node (``None`` for an empty document), the document, the line
    of every key path and the key paths written twice in one mapping. Raises
    :class:`CampaignError` for text that is too long, not YAML, nested too deeply, or that
    expands through its aliases to more than :data:`MAX_YAML_NODES` values."""
    if len(text) > MAX_TEXT_BYTES:
        raise CampaignError(
            source,
            [
                Problem(
                    "",
                    f"the file has {len(text)} characters; allowed: at most {MAX_TEXT_BYTES}",
                    source,
                )
            ],
        )
    try:
        loader = _Loader(text)
        try:
            node = loader.get_single_node()
            if node is not None:
                size = _expanded_size(node)
                if size > MAX_YAML_NODES:
                    raise CampaignError(
                        source,
                        [
                            Problem(
                                "",
                                f"the YAML expands to more than {MAX_YAML_NODES} values through "
                                "its aliases (*name); allowed: a campaign without such nesting",
                                f"{source}:{node.start_mark.line + 1}",
                            )
                        ],
                    )
            doc = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"{source}:{mark.line + 1}" if mark is not None else source
        msg = " ".join(str(getattr(e, "problem", None) or e).split())
        raise CampaignError(source, [Problem("", f"not valid YAML: {msg}", where)]) from None
    except RecursionError:
        raise CampaignError(
            source, [Problem("", "the YAML is nested too deeply", source)]
        ) from None
    lines: dict[KeyPath, int] = {}
    dups: list[KeyPath] = []
    if node is None:
        return None, None, lines, dups
    try:
        _walk(node, (), lines, dups)
    except RecursionError:
        raise CampaignError(
            source, [Problem("", "the YAML is nested too deeply", source)]
        ) from None
    return node, doc, lines, dups
