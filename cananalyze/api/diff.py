"""Two runs of a network compared per node, as an engineer compares them: configuration,
identity, PDOs, timing, NMT and drive states, EMCY codes and findings.

`facts(capture)` reduces a decoded log to what a run is judged by, per node (and per bus
on a log of several): each section a dict of item -> value. `compare(a, b)` lists what
differs, numbers beyond a tolerance (relative, with an absolute floor in ms for times),
everything else exactly. A frame-by-frame diff says nothing when two runs are seconds
apart; this says "node 5's heartbeat went from 100 to 250 ms" and "EMCY 0xFF00 only in B".

A DCF as the reference (`reference(path, node)`) holds only configuration: each object
it gives a ParameterValue for is compared with the value the log's last life showed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cananalyze.core.errors import UsageError
from cananalyze.protocol.services import Service

SECTIONS = ("identity", "configuration", "pdo", "timing", "nmt", "drive", "emcy", "findings")
TIMED = ("pdo", "timing")  # numbers compared within the tolerance
NETWORK = "network"  # the key of facts that belong to no node (SYNC, error frames)
IDENTITY = ("device_type", "vendor_id", "product_code", "revision", "serial", "device_name")


@dataclass(frozen=True)
class Difference:
    node: str  # "5", "can1/5", or "network"
    section: str
    item: str
    a: Any  # None: not in A
    b: Any

    @property
    def text(self) -> str:
        if self.section == "nodes":
            return "seen in A only" if self.a else "seen in B only"
        return f"{self.section}: {self.item}: {shown(self.a)} -> {shown(self.b)}"

    @property
    def cells(self) -> tuple[str, str, str, str, str]:
        """(who, section, item, A, B) as text: a table's row (the report's Differences)."""
        bus, _, node = self.node.rpartition("/")
        who = self.node if self.node == NETWORK else f"{bus} node {node}".lstrip()
        if self.section == "nodes":
            return who, "nodes", self.text, "seen" if self.a else "-", "seen" if self.b else "-"
        return who, self.section, self.item, shown(self.a), shown(self.b)

    def as_dict(self) -> dict:
        return asdict(self)


def shown(v) -> str:
    """A compared value as the differences print it."""
    if v is None:
        return "(none)"
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, list | tuple):
        return ", ".join(map(str, v)) or "(none)"
    return str(v)


def _node_key(bus, node) -> str:
    if node is None or (isinstance(node, float) and np.isnan(node)):
        return NETWORK
    return f"{bus}/{int(node)}" if isinstance(bus, str) else str(int(node))


def _put(out: dict, key: str, section: str, item: str, value) -> None:
    out.setdefault(key, {}).setdefault(section, {})[item] = value


def _median_max(gaps_s: np.ndarray) -> tuple[float, float] | None:
    if gaps_s.size == 0:
        return None
    ms = gaps_s * 1000.0
    return round(float(np.median(ms)), 3), round(float(ms.max()), 3)


def facts(cap) -> dict[str, dict[str, dict]]:
    """node key -> section -> item -> value (JSON-able), of one decoded log."""
    out: dict[str, dict[str, dict]] = {}
    several = "bus" in cap.nodes.columns
    for node, row in cap.nodes.iterrows():
        key = _node_key(row.get("bus") if several else None, node)
        out.setdefault(key, {})
        for field in (*IDENTITY, "profile"):
            v = row.get(field)
            v = v.item() if hasattr(v, "item") else v
            if isinstance(v, float) and v.is_integer():
                v = int(v)  # a number column with gaps is float in pandas
            if v is not None and not (isinstance(v, float) and np.isnan(v)):
                _put(out, key, "identity", field, v)
    od = _configuration(cap)
    if len(od):
        last = od.groupby(["bus", "node"] if "bus" in od else "node")["life"].transform("max")
        for r in od[od["life"] == last].to_dict("records"):
            key = _node_key(r.get("bus"), r["node"])
            shown = r["value"] if isinstance(r["value"], str) else f"0x{r['data']}"
            words = r.get("words")
            if isinstance(words, str) and words:
                shown += f" ({words})"
            _put(out, key, "configuration", _item(r), shown)
    _pdo_facts(cap, out)
    _timing_facts(cap, out)
    _sequences(cap, out)
    _emcy_facts(cap, out)
    f = cap.findings
    for (node, rule, severity), n in (
        f.groupby([f["node"].fillna(-1), "rule", "severity"], dropna=False).size().items()
    ):
        key = NETWORK if node == -1 else str(int(node))
        _put(out, key, "findings", f"{rule} {severity}", int(n))
    return out


def _configuration(cap):
    """The od rows SDO transfers showed: PDO-mapped values are process data, which two
    runs differ in by nature."""
    od = cap.od
    return od[od["set_by"] != "pdo"] if len(od) else od


def _item(r: dict) -> str:
    """An object as the differences name it: "0x1017:00 Producer heartbeat time"."""
    name = r["name"] if isinstance(r["name"], str) else ""
    return f"0x{r['index']:04X}:{r['subindex']:02X} {name}".rstrip()


def _span(cap) -> float:
    t = cap.batch.t
    return float(t[-1] - t[0]) if t.size > 1 else 0.0


def _pdo_facts(cap, out: dict) -> None:
    fb = cap.batch
    span = _span(cap)
    pdo = cap.pdo > 0
    ids = fb.can_id[pdo]
    for cob in np.unique(ids).tolist():
        rows = np.flatnonzero(pdo)[ids == cob]
        node = int(cap.node[rows[0]])
        key = _node_key(None, node if node >= 0 else None)
        lengths = sorted(set(fb.dlc[rows].tolist()))
        _put(out, key, "pdo", f"0x{cob:03X} length", lengths)
        if span > 0:
            _put(out, key, "pdo", f"0x{cob:03X} frames/s", round(rows.size / span, 3))


def _timing_facts(cap, out: dict) -> None:
    fb = cap.batch
    if _span(cap) <= 0:
        return  # a log without times: no timing to compare
    beats = cap.service == Service.HEARTBEAT
    for node in np.unique(cap.node[beats]).tolist():
        mm = _median_max(np.diff(fb.t[beats & (cap.node == node)]))
        if mm is not None:
            _put(out, str(node), "timing", "heartbeat median ms", mm[0])
            _put(out, str(node), "timing", "heartbeat max ms", mm[1])
    mm = _median_max(np.diff(fb.t[cap.service == Service.SYNC]))
    if mm is not None:
        _put(out, NETWORK, "timing", "SYNC median ms", mm[0])
        _put(out, NETWORK, "timing", "SYNC max ms", mm[1])
    errors = int((cap.service == Service.ERROR_FRAME).sum())
    if errors:
        _put(out, NETWORK, "findings", "error frames", errors)


def _dedup(seq: list[str]) -> list[str]:
    return [s for k, s in enumerate(seq) if k == 0 or s != seq[k - 1]]


def _sequences(cap, out: dict) -> None:
    ev = cap.events
    states = ev[ev["kind"] == "nmt_state"]
    for node, g in states.groupby("node"):
        seq = [m.split("NMT state ", 1)[-1] for m in g["message"]]
        _put(out, str(int(node)), "nmt", "states", _dedup(seq))
    ds = cap.drive_states
    for node, g in ds.groupby("node"):
        _put(out, str(int(node)), "drive", "states", _dedup(g["state"].tolist()))


def _emcy_facts(cap, out: dict) -> None:
    fb = cap.batch
    rows = np.flatnonzero((cap.service == Service.EMCY) & (fb.dlc >= 2))
    codes: dict[int, set] = {}
    for r in rows.tolist():
        code = int(fb.data[r, 0]) | int(fb.data[r, 1]) << 8
        if code:  # 0x0000: error reset, not an error
            codes.setdefault(int(cap.node[r]), set()).add(code)
    for node, cs in codes.items():
        _put(out, str(node), "emcy", "codes", [f"0x{c:04X}" for c in sorted(cs)])


def compare(
    a: dict, b: dict, tolerance: float = 0.1, floor_ms: float = 2.0, sections=SECTIONS
) -> list[Difference]:
    """What differs between two `facts`: a node in one only, then per section and item.
    Numbers of `TIMED` sections differ when apart by more than `tolerance` of the larger
    and by more than `floor_ms` (times) or 1 % (rates); the rest must be equal. An item
    in one run only is a difference (an object written, a PDO, an EMCY code), but an
    identity object read in one run only (unknown in the other)."""
    out: list[Difference] = []
    for key in sorted(set(a) | set(b), key=_order):
        if key != NETWORK and (key not in a or key not in b):
            out.append(Difference(key, "nodes", "node seen", key in a, key in b))
            continue
        fa, fb_ = a.get(key, {}), b.get(key, {})
        for section in sections:
            sa, sb = fa.get(section, {}), fb_.get(section, {})
            if section == "configuration":
                sa, sb = _by_object(sa, sb), _by_object(sb, sa)
            for item in sorted(set(sa) | set(sb)):
                va, vb = sa.get(item), sb.get(item)
                if section == "identity" and (va is None or vb is None):
                    continue  # read in one run only: unknown in the other, not different
                if not _same(section, item, va, vb, tolerance, floor_ms):
                    out.append(Difference(key, section, item, va, vb))
    return out


def _by_object(mine: dict, theirs: dict) -> dict:
    """Configuration items keyed by object as both runs name it: one run may name
    0x1800:03 by the node's profile, the other (device unknown there) generically; the
    object is the same, so its name is taken from whichever run has the longer one."""
    names: dict[str, str] = {}
    for item in (*mine, *theirs):
        obj = item.split(" ", 1)[0]
        if len(item) > len(names.get(obj, "")):
            names[obj] = item
    return {names[item.split(" ", 1)[0]]: v for item, v in mine.items()}


def _order(key: str):
    if key == NETWORK:
        return (0, "", 0)
    bus, _, node = key.rpartition("/")
    return (1, bus, int(node))


def _same(section: str, item: str, a, b, tolerance: float, floor_ms: float) -> bool:
    if a is None or b is None:
        return a is None and b is None
    if section in TIMED and isinstance(a, int | float) and isinstance(b, int | float):
        floor = floor_ms if item.endswith(" ms") else 0.01 * max(abs(a), abs(b))
        return abs(a - b) <= max(tolerance * max(abs(a), abs(b)), floor)
    if section == "configuration" and isinstance(a, str) and isinstance(b, str):
        # the value, not its words: a run that knows the device words it more fully
        return a.split(" (", 1)[0] == b.split(" (", 1)[0]
    return a == b


def reference(path: str | Path, node: int | None) -> tuple[int, dict[str, str]]:
    """(node, {item: value}) of a DCF's ParameterValues, the items named as `facts`
    names the configuration (the log's words are not in a DCF: values only)."""
    from cananalyze.devices.eds import read_od

    od = read_od(path, node)
    node = node if node is not None else getattr(od, "node_id", None)
    if node is None:
        raise UsageError(f"{path}: no NodeID in [DeviceComissioning]: give --node N")
    items = {}
    for obj in od.values():
        for var in obj.subindices.values() if hasattr(obj, "subindices") else [obj]:
            if getattr(var, "value", None) is None:
                continue
            try:
                raw = var.encode_raw(var.value)
            except Exception:  # noqa: BLE001 - a value its type cannot hold: as text
                raw = str(var.value).encode()
            items[(var.index, var.subindex)] = (raw.hex(), var.value)
    return int(node), items


def compare_reference(cap, path: str | Path, node: int | None) -> list[Difference]:
    """The log's last-life values against a DCF's ParameterValues, for the objects both
    give (a DCF lists far more objects than a log shows: those the log did not show are
    counted by `unseen`, not differences)."""
    node, ref = reference(path, node)
    od = _configuration(cap)
    mine = od[od["node"] == node]
    if len(mine):
        mine = mine[mine["life"] == mine["life"].max()]
    out = []
    for r in mine.to_dict("records"):
        got = ref.get((r["index"], r["subindex"]))
        if got is None or got[0] == r["data"]:
            continue
        item = _item(r)
        value = r["value"] if isinstance(r["value"], str) else f"0x{r['data']}"
        out.append(Difference(str(node), "configuration", item, value, str(got[1])))
    return out


def unseen(cap, path: str | Path, node: int | None) -> int:
    """How many of the DCF's ParameterValues the log never showed."""
    node, ref = reference(path, node)
    od = _configuration(cap)
    seen = set(
        zip(od[od["node"] == node]["index"], od[od["node"] == node]["subindex"], strict=True)
    )
    return sum(1 for k in ref if k not in seen)


@dataclass(frozen=True)
class Comparison:
    """What `diff A B` and `report A --against B` show: the differences, a note (how
    many objects of a DCF the log never showed) and B's unreadable lines (a log)."""

    differences: list[Difference]
    note: str = ""
    problems: Any = None  # B's Problems when B is a log
    reference: str = ""
    kind: str = "log"  # "log" or "dcf": what B was


def against(
    a,
    reference: str | Path,
    opts,
    tolerance: float = 0.1,
    floor_ms: float = 2.0,
    ref_node: int | None = None,
) -> Comparison:
    """A decoded log compared with B: a DCF/XDD/XDC (by its suffix, configuration only)
    or another log decoded with the same `opts`."""
    from cananalyze.api.capture import load_with
    from cananalyze.devices.eds import DEVICE_SUFFIXES

    if str(reference).lower().endswith(DEVICE_SUFFIXES):
        found = compare_reference(a, reference, ref_node)
        note = f"{unseen(a, reference, ref_node)} objects of B not shown by A"
        return Comparison(found, note, None, str(reference), "dcf")
    b = load_with(reference, opts)
    found = compare(facts(a), facts(b), tolerance, floor_ms)
    return Comparison(found, "", b.problems, str(reference), "log")
