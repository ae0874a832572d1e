"""Campaign YAML text -> a document with the line of every key, and command-line values read
as YAML. Every bound is checked before the work it bounds: a file's size with ``fstat`` before
it is read (then a read of at most :data:`MAX_TEXT_BYTES` + 1 bytes), and the number of YAML
values, the expansion of aliases and the depth of nesting while the document is composed, node
by node (:class:`_Bounded`), so that a file is refused after at most :data:`MAX_YAML_NODES`
nodes of work whatever its size or its aliases."""

from __future__ import annotations

import errno
import os
import re
import stat
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.resolver import Resolver

from ..errors import CampaignError, Problem
from .checker import KeyPath

#: Largest campaign file read (bytes), most YAML values (nodes: every key, value and list
#: item, counted again for every alias ``*name`` that repeats one), and deepest nesting of
#: mappings and lists. A campaign file has a few hundred values, nested five or six deep.
MAX_TEXT_BYTES = 4 * 2**20
MAX_YAML_NODES = 100_000
MAX_YAML_DEPTH = 50


class _Resolver(Resolver):
    """YAML 1.1's implicit types, and ``1e-5`` (no dot) read as a float, as YAML 1.2 does."""


_Resolver.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"^(?:[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+|[-+]?\.[0-9_]+[eE][-+]?[0-9]+)$"
    ),
    list("-+0123456789."),
)


class _Refused(yaml.YAMLError):
    """A bound reached while composing: the problem and the line where it was reached."""

    def __init__(self, message: str, line: int) -> None:
        super().__init__(message)
        self.message, self.line = message, line


class _Bounded(Composer):
    """PyYAML's composer that counts while it composes: every node, every node an alias
    repeats (an anchored node's expanded size is known once it is composed, so an alias
    costs one addition), and the depth; it stops at the first bound reached."""

    def _start_counts(self) -> None:
        self.nodes = 0  # nodes written in the file
        self.expanded = 0  # nodes once every alias is expanded
        self.depth = 0
        self.sizes: dict[int, int] = {}  # anchored node -> its expanded size

    def compose_node(self, parent: Any, index: Any) -> Any:
        event = self.peek_event()
        line = event.start_mark.line + 1
        if isinstance(event, yaml.AliasEvent):
            target = self.anchors.get(event.anchor)
            if target is not None:  # else PyYAML reports the undefined alias
                size = self.sizes.get(id(target))
                if size is None:
                    raise _Refused(
                        f"the alias *{event.anchor} is inside its own anchor: it expands to "
                        f"more than {MAX_YAML_NODES} values (without end); allowed: an alias "
                        "to a value written before it",
                        line,
                    )
                self.expanded += size
                if self.expanded > MAX_YAML_NODES:
                    raise _Refused(
                        f"the YAML expands to more than {MAX_YAML_NODES} values through its "
                        "aliases (*name); allowed: a campaign without such nesting",
                        line,
                    )
            return super().compose_node(parent, index)
        self.nodes += 1
        self.expanded += 1
        if self.nodes > MAX_YAML_NODES:
            raise _Refused(
                f"the file has more than {MAX_YAML_NODES} YAML values (keys, values and list "
                f"items; refused at line {line}); allowed: at most {MAX_YAML_NODES} (a long "
                "list of values is written as a range: {linspace: [start, stop, num]})",
                line,
            )
        if self.expanded > MAX_YAML_NODES:
            raise _Refused(
                f"the YAML expands to more than {MAX_YAML_NODES} values through its aliases "
                "(*name); allowed: a campaign without such nesting",
                line,
            )
        self.depth += 1
        if self.depth > MAX_YAML_DEPTH:
            raise _Refused(
                f"the YAML is nested more than {MAX_YAML_DEPTH} levels deep; allowed: at most "
                f"{MAX_YAML_DEPTH}",
                line,
            )
        before = self.expanded
        node = super().compose_node(parent, index)
        self.depth -= 1
        if getattr(event, "anchor", None) is not None:
            self.sizes[id(node)] = self.expanded - before + 1
        return node


if yaml.__with_libyaml__:  # libyaml scans and parses; the counting composer is Python
    from yaml._yaml import CParser as _CParser

    class _Loader(_Bounded, _CParser, SafeConstructor, _Resolver):  # type: ignore[misc]
        def __init__(self, stream: str) -> None:
            _CParser.__init__(self, stream)
            SafeConstructor.__init__(self)
            _Resolver.__init__(self)
            Composer.__init__(self)
            self._start_counts()

        # the composer's, not libyaml's (which would compose without counting)
        check_node = Composer.check_node
        get_node = Composer.get_node
        get_single_node = Composer.get_single_node

else:  # pragma: no cover - PyYAML without libyaml

    class _Loader(  # type: ignore[no-redef]
        yaml.reader.Reader,
        yaml.scanner.Scanner,
        yaml.parser.Parser,
        _Bounded,
        SafeConstructor,
        _Resolver,
    ):
        def __init__(self, stream: str) -> None:
            yaml.reader.Reader.__init__(self, stream)
            yaml.scanner.Scanner.__init__(self)
            yaml.parser.Parser.__init__(self)
            Composer.__init__(self)
            SafeConstructor.__init__(self)
            _Resolver.__init__(self)
            self._start_counts()


def _load(text: str) -> Any:
    loader = _Loader(text)
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def parse_value(text: str) -> Any:
    """A command-line value read as YAML (``0.3`` -> float, ``[1, 2]`` -> list, ``abc`` -> str)."""
    try:
        return _load(text)
    except (yaml.YAMLError, RecursionError):
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


#: What a campaign file that the process has not the memory to read or check is refused with.
NO_MEMORY = (
    "not enough memory to read and check this campaign file (give the process more memory, or "
    "make the campaign smaller)"
)


def _too_large(size: str) -> str:
    return (
        f"the file has {size} bytes; allowed: at most {MAX_TEXT_BYTES} (a campaign file is a "
        "few kilobytes of text)"
    )


def read_text(path: str | Path) -> str:
    """The UTF-8 text of the campaign file at ``path``. Its size is checked (``fstat`` of the
    opened file) before anything is read, and at most :data:`MAX_TEXT_BYTES` + 1 bytes are
    read; a folder, a device or a pipe is refused without reading it. Raises
    :class:`CampaignError` naming the file."""
    where = str(path)

    def refused(message: str) -> CampaignError:
        return CampaignError(where, [Problem("", message, where)])

    exhausted = False
    try:
        # O_NONBLOCK: opening a named pipe does not wait for a writer (it is refused below)
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as e:
        raise refused(f"cannot read the file: {e.strerror}") from None
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise refused(f"cannot read the file: {os.strerror(errno.EISDIR)}")
        if not stat.S_ISREG(st.st_mode):
            raise refused("cannot read the file: not a regular file (a device, pipe or socket)")
        if st.st_size > MAX_TEXT_BYTES:
            raise refused(_too_large(str(st.st_size)))
        data = os.read(fd, MAX_TEXT_BYTES + 1)
        while data and len(data) <= MAX_TEXT_BYTES:  # os.read may return less than asked
            more = os.read(fd, MAX_TEXT_BYTES + 1 - len(data))
            if not more:
                break
            data += more
    except OSError as e:
        raise refused(f"cannot read the file: {e.strerror}") from None
    except MemoryError:  # refused below (not while handling it: what it held is freed)
        exhausted = True
    finally:
        os.close(fd)
    if not exhausted and len(data) > MAX_TEXT_BYTES:  # it grew after fstat
        raise refused(_too_large(f"more than {MAX_TEXT_BYTES}"))
    try:
        if not exhausted:
            return data.decode("utf-8")
    except UnicodeDecodeError:
        raise refused("not a UTF-8 text file") from None
    except MemoryError:
        pass
    data = b""  # what was read is freed before the refusal is made
    raise refused(NO_MEMORY)


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
    :class:`CampaignError` for text that is too long or not YAML, and, as soon as the bound is
    reached while it is composed, for a document of more than :data:`MAX_YAML_NODES` values
    (aliases expanded) or nested more than :data:`MAX_YAML_DEPTH` deep."""
    if len(text) > MAX_TEXT_BYTES:
        raise CampaignError(
            source,
            [
                Problem(
                    "",
                    f"the text has {len(text)} characters; allowed: at most {MAX_TEXT_BYTES}",
                    source,
                )
            ],
        )
    refusal: Problem | None = None
    exhausted = False
    try:
        loader = _Loader(text)
        try:
            node = loader.get_single_node()
            doc = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except _Refused as e:
        refusal = Problem("", e.message, f"{source}:{e.line}")
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"{source}:{mark.line + 1}" if mark is not None else source
        msg = " ".join(str(getattr(e, "problem", None) or e).split())
        refusal = Problem("", f"not valid YAML: {msg}", where)
    except RecursionError:  # pragma: no cover - MAX_YAML_DEPTH stops it first
        refusal = Problem("", "the YAML is nested too deeply", source)
    except MemoryError:  # nothing allocated while the parse's frames hold its nodes
        exhausted = True
    if exhausted:
        refusal = Problem("", NO_MEMORY, source)
    if refusal is not None:  # raised here, not while handling: the parse's frames are freed
        raise CampaignError(source, [refusal])
    lines: dict[KeyPath, int] = {}
    dups: list[KeyPath] = []
    if node is None:
        return None, None, lines, dups
    _walk(node, (), lines, dups)
    return node, doc, lines, dups
