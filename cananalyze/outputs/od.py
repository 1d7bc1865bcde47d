"""`cananalyze od`: each node's object dictionary as the log showed it, as text, JSON lines
and one CiA 306 DCF per node.

The rows are `OdTally`'s (the export's `od` table and `load().od` are the same rows).
A DCF is the node's device description (its profile's object dictionary: EDS, DCF or
built-in device; CiA 301's objects where none is known) with a `ParameterValue` for
every object the node's last life's SDO transfers showed (PDO-mapped values are process
data, not configuration: the text and JSON lines only), written by canopen's `export_od` so
that canopen and `--eds` read it back. Objects the log never showed keep what the given
description says: a DCF's (an XDC's) ParameterValue, else no ParameterValue, so that their
DefaultValue applies; the file's comments name those kept as given (not seen).
"""

from __future__ import annotations

import copy
import json
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import TextIO

from cananalyze.core.errors import UsageError
from cananalyze.core.records import DecodedBatch
from cananalyze.core.text import printable
from cananalyze.decode.od_tally import OdTally
from cananalyze.pipeline.sink import Sink

DATA_TYPES = {1: 0x0005, 2: 0x0006, 3: 0x0016, 4: 0x0007, 8: 0x001B}  # by size: UNSIGNEDn


class OdSink(Sink):
    """Tallies every batch; at the end prints the rows and writes the DCFs."""

    def __init__(self, out: TextIO = sys.stdout, fmt: str = "text", dcf: str | None = None):
        self.out, self.fmt, self.dcf = out, fmt, dcf
        self.tally = OdTally()
        self.t0: float | None = None
        self.dest = dcf

    def open(self, run) -> None:
        self.run = run
        if self.dcf is not None:
            d = Path(self.dcf)
            if d.exists() and not d.is_dir():
                raise UsageError(f"{self.dcf}: --dcf needs a folder, this is a file")

    def write(self, batch: DecodedBatch) -> None:
        if self.t0 is None and len(batch.frames):
            self.t0 = float(batch.frames.t[0])
        self.tally.add(batch)

    def close(self) -> None:
        rows = self.tally.rows()
        if self.fmt == "jsonl":
            for r in rows:
                self.out.write(json.dumps(r, ensure_ascii=False) + "\n")
        else:
            self.out.write(text(rows, self.tally, self.t0 or 0.0, self._profiles()))
        if self.dcf is not None:
            for path in write_dcfs(Path(self.dcf), rows, self._ods(), self._source()):
                print(f"wrote {path}", file=sys.stderr)

    def _source(self) -> str:
        return str(self.run.source.path)

    def _networks(self) -> dict:
        return self.run.decoder.networks()

    def _profiles(self) -> dict:
        """(bus, node) -> the node's profile, or None."""
        out = {}
        for bus, model in self._networks().items():
            for node, cfg in getattr(model, "nodes", {}).items():
                out[(bus, node)] = cfg.profile
        return out

    def _ods(self) -> dict:
        return {k: p.od for k, p in self._profiles().items() if p is not None}


def _life(node_boots: list[float], life: int, t0: float) -> str:
    if life == 0:
        return "before any boot-up in the log" if node_boots else "no boot-up in the log"
    return f"since boot-up {life} at {node_boots[life - 1] - t0:.3f} s"


def text(rows: list[dict], tally: OdTally, t0: float, profiles: dict) -> str:
    """Per node and life, one line per object: where, name, value in words, when and how
    set, and the values it went through when it changed. Every text from the log or an
    EDS is printable (a terminal shows it, never obeys it)."""
    if not rows:
        return "no successful SDO transfer nor mapped PDO in the log: no object values to show\n"
    out: list[str] = []
    last = None
    width = max(len(printable(r["name"] or "")) for r in rows)
    for r in rows:
        bus = r.get("bus")
        key = (bus, r["node"], r["life"])
        if key != last:
            prof = profiles.get((bus, r["node"]))
            what = f" ({printable(prof.key)})" if prof is not None else ""
            on = f" on {printable(str(bus))}" if bus is not None else ""
            boots = tally.boot_times(bus, r["node"])
            out += [""] if out else []
            out.append(f"node {r['node']}{on}{what}, {_life(boots, r['life'], t0)}:")
            last = key
        shown = r["value"] if r["value"] is not None else (f"0x{r['data']}" if r["data"] else "-")
        value = printable(shown)
        words = f" ({printable(r['words'])})" if r["words"] else ""
        how = {"write": "written", "pdo": "by PDO"}.get(r["set_by"], "read")
        line = (
            f"  0x{r['index']:04X}:{r['subindex']:02X}  {printable(r['name'] or ''):<{width}}"
            f"  = {value}{words}  {how} at {r['t'] - t0:.3f} s"
        )
        if r["transfers"] > 1:
            line += f", {r['transfers']} {'frames' if r['set_by'] == 'pdo' else 'transfers'}"
        if r["changes"]:
            line += f", changed {r['changes']}x: {printable(r['history'])}"
        out.append(line)
    return "\n".join(out) + "\n"


def write_dcfs(folder: Path, rows: list[dict], ods: dict, source: str) -> list[Path]:
    """One DCF per node (per bus and node on a log of several buses) with the values of
    its last life; the paths written."""
    from canopen.objectdictionary import ObjectDictionary, export_od

    rows = [r for r in rows if r["set_by"] != "pdo"]  # process data: no configuration
    last: dict[tuple, int] = {}
    for r in rows:
        k = (r.get("bus"), r["node"])
        last[k] = max(last.get(k, 0), r["life"])
    by_node: dict[tuple, list[dict]] = {}
    for r in rows:
        k = (r.get("bus"), r["node"])
        if r["life"] == last[k]:
            by_node.setdefault(k, []).append(r)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for (bus, node), objs in by_node.items():
        base = ods.get((bus, node)) or ods.get((None, node))
        od = copy.deepcopy(base) if base is not None else ObjectDictionary()
        od.node_id = node
        shown = {(r["index"], r["subindex"]) for r in objs}
        given = [v for v in _variables(od) if v.value is not None and _key(v) not in shown]
        records = {r["index"] for r in objs if r["subindex"] > 0}
        seen = [_set(od, r, r["index"] in records) for r in objs]
        od.comments = _comments(node, source, sum(seen), given)
        name = f"node{node}.dcf" if bus is None else f"{_safe(str(bus))}-node{node}.dcf"
        path = folder / name
        tmp = path.with_suffix(".dcf.tmp")
        with open(tmp, "w", encoding="utf-8") as f:
            export_od(od, f, doc_type="dcf")
        tmp.replace(path)
        written.append(path)
    return written


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name) or "bus"


def _variables(od) -> Iterable:
    for obj in od.values():
        if hasattr(obj, "subindices"):
            yield from obj.subindices.values()
        else:
            yield obj


def _key(var) -> tuple[int, int]:
    return var.index, var.subindex


def _section(var) -> str:
    """The variable's DCF section name, as export_od writes it ("1017", "1800sub5")."""
    from canopen.objectdictionary import ODArray, ODRecord

    if isinstance(getattr(var, "parent", None), ODArray | ODRecord):
        return f"{var.index:04X}sub{var.subindex:X}"
    return f"{var.index:04X}"


def _comments(node: int, source: str, seen: int, given: list) -> str:
    """The DCF's [Comments]: which ParameterValues are the log's and which the given
    description's (objects the log did not show), by their DCF section names."""
    lines = [
        f"Configuration of node {node} as the log {Path(source).name} showed it (cananalyze od).",
        f"ParameterValue: {seen} objects seen in the log.",
    ]
    if given:
        lines.append(f"Not seen in the log, ParameterValue as the given DCF says ({len(given)}):")
        names = [_section(v) for v in given]
        lines += [" ".join(names[k : k + 10]) for k in range(0, len(names), 10)]
    lines.append("Objects without a ParameterValue were not seen (DefaultValue applies).")
    return "\n".join(lines)


def _set(od, r: dict, record: bool) -> bool:
    """The object's ParameterValue from the bytes the log showed; an object the
    dictionary lacks is added with a type of its size (DOMAIN when none fits), in a
    record when the log shows sub-indices of its index (`record`)."""
    from canopen import objectdictionary as cod

    raw = bytes.fromhex(r["data"] or "")
    var = _variable(od, r["index"], r["subindex"])
    if var is None:
        name = r["name"] or f"Object 0x{r['index']:04X}sub{r['subindex']}"
        var = cod.ODVariable(name, r["index"], r["subindex"])
        var.data_type = DATA_TYPES.get(len(raw), 0x000F)
        var.access_type = "rw"
        if not record and r["index"] not in od:
            od.add_object(var)
        else:
            rec = od.get(r["index"])
            if rec is None or not hasattr(rec, "subindices"):
                rec = cod.ODRecord(f"Object 0x{r['index']:04X}", r["index"])
                od.add_object(rec)
            rec.add_member(var)
    if getattr(var, "value_raw", None) is not None:
        var.value_raw = None  # a given DCF's text, which export_od would write instead
    try:
        var.value = var.decode_raw(raw)
    except Exception:  # noqa: BLE001 - bytes that do not fit the declared type: kept raw
        var.data_type = 0x000F
        var.value = raw
    return True


def _variable(od, index: int, sub: int):
    obj = od.get(index)
    if obj is None:
        return None
    if hasattr(obj, "subindices"):
        return obj.subindices.get(sub)
    return obj if sub == 0 else None
