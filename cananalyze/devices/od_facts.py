"""What decoding asks of a device file, as plain data kept in a cache beside the parse.

Decoding asks a profile only for objects' names, types, flags and values (`variable`,
`object_info`, `effective_value` in `eds.py`). Parsing the file takes canopen, whose import
pulls in python-can (90 ms of a command's start-up, 0.7 s in a notebook, where
python-can also imports asammdf). So the answers for the objects the file defines are
kept in a JSON file under the user's cache folder, keyed by the device file's bytes and
the reader's code; the next run with the same file reads them without canopen. What the
facts cannot answer for certain (an array's sub-index the file does not list, which
canopen makes from the array's template) is asked of the dictionary itself, parsed then.

The cache is only ever an answer canopen gave before for the same bytes: a file that
fails to parse is not cached, a damaged or foreign cache entry is parsed again, and
`CANANALYZE_CACHE=off` turns it off.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.util
import json
import os
import tempfile
from pathlib import Path
from typing import Any, NamedTuple

FORMAT = 1  # the cache entries' layout
UNSURE = object()  # `OdFacts.variable`: ask the parsed dictionary
KINDS = ("var", "record", "array")


class Var(NamedTuple):
    """An ODVariable's attributes that `eds.py` reads (same names)."""

    name: str
    data_type: int
    pdo_mappable: bool
    value_raw: Any
    default_raw: Any
    value: Any
    default: Any


class OdFacts:
    """Each defined object's variables: {index: (kind, {sub: Var})}; kind is "var",
    "record" (a missing sub-index is absent) or "array" (one canopen may make)."""

    def __init__(self, objects: dict, info: dict, node_id: int | None) -> None:
        self.objects = objects
        self.info = info  # [DeviceInfo]: vendor_number, product_number, product_name
        self.node_id = node_id  # a DCF's [DeviceComissioning] NodeID

    def variable(self, index: int, subindex: int):
        """`eds.variable`'s answer: a Var, None (no such object), or UNSURE."""
        if type(index) is not int or type(subindex) is not int:
            return UNSURE
        entry = self.objects.get(index)
        if entry is None:
            return None
        kind, subs = entry
        if kind == "var":
            return subs.get(0) if subindex == 0 else None
        got = subs.get(subindex)
        if got is None and kind == "array":
            return UNSURE
        return got

    @classmethod
    def from_od(cls, od) -> OdFacts:
        objects = {}
        for index, entry in od.items():
            if type(index) is not int:
                continue
            subs = getattr(entry, "subindices", None)
            if subs is None:
                objects[index] = ("var", {0: _var(entry)})
            else:
                kind = "record" if type(entry).__name__ == "ODRecord" else "array"
                objects[index] = (kind, {s: _var(v) for s, v in subs.items() if type(s) is int})
        di = od.device_information
        info = {
            "vendor_number": di.vendor_number,
            "product_number": di.product_number,
            "product_name": di.product_name,
        }
        return cls(objects, info, getattr(od, "node_id", None))

    def to_json(self) -> str:
        objects = [
            [index, kind, [[sub, *map(_out, var)] for sub, var in subs.items()]]
            for index, (kind, subs) in self.objects.items()
        ]
        doc = {"format": FORMAT, "node_id": self.node_id, "info": self.info, "objects": objects}
        return json.dumps(doc, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> OdFacts:
        doc = json.loads(text)
        if doc["format"] != FORMAT:
            raise ValueError("another format")
        objects = {}
        for index, kind, subs in doc["objects"]:
            if kind not in KINDS:
                raise ValueError(f"object kind {kind!r}")
            objects[int(index)] = (kind, {int(s): _var_in(rest) for s, *rest in subs})
        node_id = doc["node_id"]
        if node_id is not None and type(node_id) is not int:
            raise ValueError("node-ID")
        return cls(objects, dict(doc["info"]), node_id)


def _var(v) -> Var:
    return Var(
        v.name,
        int(v.data_type or 0),
        bool(v.pdo_mappable),
        getattr(v, "value_raw", None),
        getattr(v, "default_raw", None),
        getattr(v, "value", None),
        getattr(v, "default", None),
    )


def _var_in(fields: list) -> Var:
    var = Var(*map(_in, fields))
    if type(var.name) is not str or type(var.data_type) is not int:
        raise ValueError("variable")
    return var


def _out(x):
    """JSON keeps str, int, float, bool and None as they are; bytes are tagged."""
    if isinstance(x, bytes | bytearray):
        return {"bytes": bytes(x).hex()}
    return x


def _in(x):
    if isinstance(x, dict):
        return bytes.fromhex(x["bytes"])
    return x


def load_facts(path: Path, node_id: int | None, parse) -> tuple[OdFacts, object | None]:
    """(facts, the parsed dictionary or None when the facts came from the cache);
    `parse(path, node_id)` reads the file (eds.read_od: its errors pass through)."""
    entry = _entry(path, node_id)
    if entry is not None:
        with contextlib.suppress(OSError, ValueError, KeyError, TypeError, RecursionError):
            return OdFacts.from_json(entry.read_text(encoding="utf-8")), None
    od = parse(path, node_id)
    facts = OdFacts.from_od(od)
    if entry is not None:
        _store(entry, facts.to_json())
    return facts, od


def cache_dir() -> Path | None:
    where = os.environ.get("CANANALYZE_CACHE")
    if where == "off":
        return None
    if where:
        return Path(where)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "cananalyze"


def _entry(path: Path, node_id: int | None) -> Path | None:
    """The cache file for these bytes, this node-ID and this reader's code, or None."""
    folder = cache_dir()
    if folder is None:
        return None
    try:
        key = hashlib.sha256(Path(path).read_bytes())
    except OSError:
        return None  # the parse says what is wrong with the file
    key.update(f"{FORMAT} {node_id} {_readers()}".encode())
    return folder / f"od-{key.hexdigest()[:40]}.json"


@functools.cache
def _readers() -> str:
    """The code that makes the facts: canopen's EDS reader and ours, by size and time
    (an upgrade or an edit of either parses the files again); once per process."""
    files = [Path(__file__).with_name("eds.py"), Path(__file__).with_name("xdd.py")]
    spec = importlib.util.find_spec("canopen")  # found, not imported
    if spec is not None and spec.origin:
        files.append(Path(spec.origin).parent / "objectdictionary" / "eds.py")
    marks = []
    for f in files:
        with contextlib.suppress(OSError):
            st = f.stat()
            marks.append(f"{st.st_size}:{st.st_mtime_ns}")
    return ",".join(marks)


def _store(entry: Path, text: str) -> None:
    """Written whole or not at all (a fleet's workers may write the same entry at once);
    a folder that cannot be written only costs the next run a parse."""
    with contextlib.suppress(OSError):
        entry.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=entry.parent, prefix=".od-", suffix=".tmp")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
            os.replace(tmp, entry)
        except OSError:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
