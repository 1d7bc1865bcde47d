"""Reading a user's YAML or TOML file so that every message can name the file and the line.

Shared by the network file and the rules file: one reader (YAML only through the
safe loader: user text is data, never code), one key-path -> line lookup, one way to
say "FILE:LINE: ..." for errors and deprecation warnings.
"""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

from cananalyze.core.errors import InputError, read_bounded

# (file, old key) pairs already warned about: one warning per key per file and process
_warned: set[tuple[str, str]] = set()


class Lines:
    """Key path (tuple of keys) -> 1-based line of one file, below an optional root path.

    YAML: from the composed node marks (each key also under its integer value, so
    `0x285` is found as 645). TOML: the key's own line inside a table header naming
    its parents, else its first use. `alias` points a path made up by a translation
    (a deprecated key's new name) at the line of the key it came from.
    """

    def __init__(self, path: Path, text: str = "", yaml_node=None, root: tuple = ()) -> None:
        self.path = path
        self.text = text.splitlines()
        self.map: dict[tuple, int] = {}
        self.aliases: dict[tuple, tuple] = {}
        self.root = root
        if yaml_node is not None:
            self._walk(yaml_node, ())

    def under(self, *keys) -> Lines:
        """The same file seen from a sub-table (the rules file's `network:`). It keeps the
        lines of that table and of the keys above it only: the settings read through it
        keep it (a PDO's `_at`), not the lines of a rules file's 50,000 assertions."""
        view = Lines.__new__(Lines)
        view.__dict__.update(self.__dict__)
        view.root = root = self.root + tuple(str(k) for k in keys)
        n = len(root)
        view.map = {k: v for k, v in self.map.items() if k[:n] == root or root[: len(k)] == k}
        return view

    def _walk(self, root, where: tuple) -> None:
        """Every path's line, depth first in document order (a loop, not a recursion: a
        rules file of 50,000 assertions has a few hundred thousand nodes)."""
        from yaml import MappingNode, SequenceNode

        lines = self.map
        todo = [(root, where)]
        while todo:
            node, where = todo.pop()
            lines.setdefault(where, node.start_mark.line + 1)  # a key: its own line
            kind = type(node)
            if kind is MappingNode:
                below = []
                for k, v in node.value:
                    for key in _spellings(k.value):
                        lines[(*where, key)] = k.start_mark.line + 1
                        below.append((v, (*where, key)))
                todo.extend(reversed(below))
            elif kind is SequenceNode:
                todo.extend((v, (*where, str(i))) for i, v in reversed(list(enumerate(node.value))))

    def alias(self, new: tuple, old: tuple) -> None:
        self.aliases[self.root + tuple(map(str, new))] = self.root + tuple(map(str, old))

    def line(self, where: tuple) -> int | None:
        full = self.root + tuple(str(k) for k in where)
        for _ in range(4):  # a renamed key inside a moved table: two aliases
            hit = next((n for n in range(len(full), 0, -1) if full[:n] in self.aliases), 0)
            if not hit:
                break
            full = self.aliases[full[:hit]] + full[hit:]
        for n in range(len(full), -1, -1):
            if full[:n] in self.map:
                return self.map[full[:n]]
        return self._toml_line(full) if self.text else None

    def _toml_line(self, where: tuple) -> int | None:
        if not where:
            return None
        last, parents = re.escape(str(where[-1])), [str(k) for k in where[:-1]]
        header, first = "", None
        for i, text in enumerate(self.text, 1):
            h = re.match(r"^\s*\[+\s*([^\]]+?)\s*\]+", text)
            if h:
                header = h.group(1).replace('"', "")
                parts = header.split(".")
                if parts[-1] == str(where[-1]) and all(p in parts for p in parents):
                    return i
                continue
            if re.match(rf'^\s*"?{last}"?\s*=', text):
                if all(p in header.split(".") for p in parents[-1:]):
                    return i
                first = first or i
        if first is None and len(where) > 1:  # a key of an inline table: its parent's line
            return self._toml_line(where[:-1])
        return first

    def at(self, where: tuple) -> str:
        line = self.line(where)
        return f"{self.path}:{line}" if line else str(self.path)

    def error(self, where: tuple, message: str) -> InputError:
        key = ".".join(str(k) for k in self.root + tuple(where))
        return InputError(f"{self.at(where)}: {key + ': ' if key else ''}{message}")

    def deprecated(self, where: tuple, old: str, new: str) -> None:
        """One line on stderr, once per old key and file: the old spelling still works."""
        if (str(self.path), old) in _warned:
            return
        _warned.add((str(self.path), old))
        print(f"{self.at(where)}: '{old}' is deprecated, use {new}", file=sys.stderr)


def integer(value, lines: Lines, where: tuple, low: int = 0, high: int = 0xFFFFFFFF) -> int:
    """An integer setting (or an integer string such as "0x285"), range-checked: bools,
    fractions and other strings are errors that name the file and the line."""
    if isinstance(value, str):
        try:
            value = int(value, 0)
        except ValueError:
            raise lines.error(where, f"expected an integer, got {value!r}") from None
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise lines.error(where, f"expected an integer, got {_shown(value)}")
    if not low <= value <= high:
        raise lines.error(where, f"{value} is out of range {low}..{high}")
    return value


def _shown(value) -> str:
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "a list"
    return repr(value)


def _spellings(key) -> list[str]:
    """A YAML key as written, and as the integer it stands for (0x285 -> 645)."""
    out = [str(key)]
    try:
        value = int(str(key), 0)
    except ValueError:
        return out
    if str(value) != out[0]:
        out.append(str(value))
    return out


# Limits on a configuration file (the network file, the rules file): the largest real one
# is a few KB, so these only stop a hostile or mistaken file before it costs memory or the
# stack. Readers of binary logs follow the same rule for every length they read.
MAX_BYTES = 4 << 20  # --network /dev/zero: stop at 4 MiB, not at MemoryError
MAX_DEPTH = 64  # nesting of tables and lists (deeper overflows the parsers' recursion)
MAX_NODES = 1_000_000  # values after alias expansion ("billion laughs": 10^9)


def read_tree(path: str | Path, what: str) -> tuple[object, Lines]:
    """A TOML (`.toml`) or YAML file's data and its lines; InputError with the line if it
    does not parse, is not UTF-8, or passes a limit above. `what` names the file in
    messages ("network file", "rules file")."""
    path = Path(path)
    raw = read_bounded(path, MAX_BYTES, what)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise InputError(
            f"{path}:{line}: {what} is not UTF-8 text (byte 0x{raw[exc.start]:02X})"
        ) from None
    if path.suffix.lower() == ".toml":
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"{path}: not valid TOML: {exc}") from None
        except RecursionError:
            raise InputError(f"{path}: {what} nests deeper than {MAX_DEPTH} levels") from None
        except ValueError as exc:  # an integer of over 4300 digits (Python's own limit)
            raise InputError(f"{path}: {what}: {_first_line(exc)}") from None
        if _depth(data) > MAX_DEPTH:
            raise InputError(f"{path}: {what} nests deeper than {MAX_DEPTH} levels")
        return data, Lines(path, text)
    import yaml

    loader = yaml_loader()
    try:
        _check_yaml_shape(text, path, what, loader)
        data, lines = _load_yaml(text, loader, path)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f"{path}:{mark.line + 1}" if mark else str(path)
        why = (getattr(exc, "problem", None) or str(exc)).splitlines()[0]  # one line
        raise InputError(f"{at}: not valid YAML: {why}") from None
    except ValueError as exc:  # an integer of over 4300 digits (Python's own limit)
        raise InputError(f"{path}: {what}: {_first_line(exc)}") from None
    return data, lines


def yaml_loader() -> type:
    """PyYAML's safe loader, on its C parser (libyaml) where PyYAML was built with it: the
    same safe constructor and resolver (Python), so the same data, parsed 20 times faster
    (a 2 MB rules file: 40 s in the pure-Python parser). Never the full loader."""
    import yaml

    return getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def _load_yaml(text: str, loader: type, path: Path) -> tuple[object, Lines]:
    """The document's data and lines from one parse: the lines from the composed nodes
    (before the constructor flattens their merge keys `<<` in place), then the data
    constructed from those nodes (what `yaml.safe_load` does after composing)."""
    one = loader(text)
    try:
        node = one.get_single_node()
        lines = Lines(path, "", node)
        return (one.construct_document(node) if node is not None else None), lines
    finally:
        one.dispose()


def _first_line(exc: Exception) -> str:
    return (str(exc).splitlines() or [type(exc).__name__])[0].partition("; use sys.")[0]


def _depth(data) -> int:
    """Nesting depth of parsed data, without recursion."""
    deepest, todo = 0, [(data, 1)]
    while todo:
        value, depth = todo.pop()
        if isinstance(value, dict):
            value = list(value.values())
        if isinstance(value, list):
            deepest = max(deepest, depth)
            if depth <= MAX_DEPTH:
                todo.extend((v, depth + 1) for v in value)
    return deepest


def _check_yaml_shape(text: str, path: Path, what: str, loader: type) -> None:
    """Depth, self-reference and alias expansion from YAML's event stream (the parser keeps
    its own stack, so this cannot overflow), before anything builds nested objects: PyYAML
    expands aliases into shared objects, but every reader after it walks them in full."""
    import yaml

    scalar, alias = yaml.ScalarEvent, yaml.AliasEvent
    start, end = yaml.CollectionStartEvent, yaml.CollectionEndEvent
    depth = 0
    open_: list[tuple[str | None, int]] = []  # (anchor, nodes before it) per open collection
    sizes: dict[str, int] = {}  # anchor -> nodes it stands for, expanded
    nodes = 0
    for ev in yaml.parse(text, Loader=loader):
        if isinstance(ev, scalar):  # most events: tested first
            nodes += 1
            if ev.anchor:
                sizes[ev.anchor] = 1
        elif isinstance(ev, alias):
            if any(a == ev.anchor for a, _ in open_):
                raise InputError(f"{_at(path, ev)}: {what}: alias *{ev.anchor} refers to itself")
            nodes += sizes.get(ev.anchor, 1)
        elif isinstance(ev, start):
            depth += 1
            if depth > MAX_DEPTH:
                raise InputError(f"{_at(path, ev)}: {what} nests deeper than {MAX_DEPTH} levels")
            open_.append((ev.anchor, nodes))
            nodes += 1
        elif isinstance(ev, end):
            depth -= 1
            anchor, before = open_.pop()
            if anchor:
                sizes[anchor] = nodes - before
        if nodes > MAX_NODES:
            raise InputError(
                f"{_at(path, ev)}: {what} expands to more than {MAX_NODES:,} values (aliases)"
            )


def _at(path: Path, event) -> str:
    return f"{path}:{event.start_mark.line + 1}"
