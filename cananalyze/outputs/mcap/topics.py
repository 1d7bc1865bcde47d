"""MCAP export for Foxglove: every PDO as a plottable topic, events as a log panel.

Topics (all JSON-encoded with JSON Schema, so Foxglove needs no configuration):
  /node/<N>/<pdo>     decoded signals of one PDO (/dbc/<message>: a DBC's, on no node) (numbers as numbers; unit in the
                      schema's description)
  /node/<N>/nmt_state NMT state changes seen in heartbeat, boot-up, guarding
  /node/<N>/drive_state CiA 402 state changes of a drive (statusword by PDO or SDO)
  /canopen/events     foxglove.Log: SDO transactions, EMCY, NMT commands, findings
  /can/frames         every raw frame (schema and builder: `formats/mcap_frames.py`)
With several buses (a log of several channels, `live -c can0,can1`), the decoded topics
of each bus carry its name in front (`records.on_bus`): /can1/node/5/tpdo1, /can1/node/5/nmt_state;
events name it ("can1 node 5"). /can/frames stays one topic of every frame, its channel
in each message (Foxglove: `/can/frames{channel=="can1"}`): it is what the MCAP reader
and `live --record` read back, and frames are the bulk a second copy would double.
Log time = frame time in ns. Messages are written in time order across topics.
JSON text is built column-wise (`json_text`) and the records in bulk (`mcap_bulk`):
one json.dumps and one `mcap` Writer.add_message per frame cost ~12 s on a million
frames.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from cananalyze.core.columns import arrow_build as ab
from cananalyze.core.columns.json_text import Texts, join, number_text, object_template
from cananalyze.core.records import SignalBlock, signal_path
from cananalyze.core.version import __version__
from cananalyze.formats.mcap_bulk import BulkMcapWriter
from cananalyze.outputs.capture import SignalSeries

LOG_SCHEMA = {
    "title": "foxglove.Log",
    "description": "A log message",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object",
            "title": "time",
            "properties": {
                "sec": {"type": "integer", "minimum": 0},
                "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
            },
            "description": "Timestamp of log message",
        },
        "level": {
            "title": "foxglove.LogLevel",
            "description": "Log level",
            "oneOf": [
                {"title": "UNKNOWN", "const": 0},
                {"title": "DEBUG", "const": 1},
                {"title": "INFO", "const": 2},
                {"title": "WARNING", "const": 3},
                {"title": "ERROR", "const": 4},
                {"title": "FATAL", "const": 5},
            ],
        },
        "message": {"type": "string", "description": "Log message"},
        "name": {"type": "string", "description": "Process or node name"},
        "file": {"type": "string", "description": "Filename"},
        "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
    },
}

STATE_SCHEMA = {
    "title": "cananalyze.NmtState",
    "description": "NMT state of a node as reported by heartbeat, boot-up or guarding",
    "type": "object",
    "properties": {"state": {"type": "string"}},
}

DRIVE_SCHEMA = {
    "title": "cananalyze.DriveState",
    "description": "CiA 402 state of a drive, from its statusword (PDO or SDO)",
    "type": "object",
    "properties": {"state": {"type": "string"}, "statusword": {"type": "integer"}},
}


def _json_type(values: np.ndarray) -> str:
    if values.dtype == bool:
        return "boolean"
    if np.issubdtype(values.dtype, np.integer):
        return "integer"
    return "number"


def signal_schema(s: SignalSeries | SignalBlock) -> dict:
    """JSON schema of one PDO's signal documents (from a whole series or its first block)."""
    props = {}
    for name, values in s.columns.items():
        unit = s.units.get(name)
        props[name] = {"type": _json_type(values)}
        if unit:
            props[name]["description"] = f"unit: {unit}"
    return {
        "title": f"cananalyze.node{s.node}.{s.pdo}",
        "description": f"node {s.node} {s.pdo.upper()} (COB-ID 0x{s.cob_id:03X}) decoded signals",
        "type": "object",
        "properties": props,
    }


# json.dumps's own escaping of a str (ensure_ascii, as the documents are dumped)
_json_string = json.encoder.encode_basestring_ascii
EVENTS_TOPIC = "/canopen/events"
SLICE = 1 << 20  # rows per join: keeps pyarrow's 32-bit string offsets in range


def signal_payloads(columns: dict[str, np.ndarray]) -> Texts:
    """`{"signal": value, ...}` per PDO, built column-wise (NaN/inf become null)."""
    names = list(columns)
    n = len(columns[names[0]]) if names else 0
    return Texts.concat(
        [
            join(object_template(names, [number_text(columns[k][a : a + SLICE]) for k in names]))
            for a in range(0, n, SLICE)
        ]
    )


def state_payloads(states: list) -> Texts:
    """`{"state": ...}` of NMT state changes (rare: one json.dumps each)."""
    return Texts.from_list([json.dumps({"state": e.message}).encode() for e in states])


def drive_payloads(changes: list) -> Texts:
    """`{"state": ..., "statusword": ...}` of CiA 402 state changes (rare)."""
    return Texts.from_list(
        [json.dumps({"state": c.name, "statusword": c.word}).encode() for c in changes]
    )


def event_payloads(
    ns: np.ndarray,
    level: list[int],
    message: list[str],
    name: list[str],
    file: str,
    line: list[int],
) -> Texts:
    """foxglove.Log documents of events, byte for byte `json.dumps` of the dict
    {"timestamp": {"sec", "nsec"}, "level", "message", "name", "file", "line"}.

    A polled bus has an event per SDO transfer: each string is escaped by the json
    module's own C escaper, numbers and the fixed text come as columns, and the
    documents are joined in pyarrow (a dict and a json.dumps each took 3x longer).
    Columns from buffers (`arrow_build`): pa.array imports pandas.
    """
    ns = np.asarray(ns, np.int64)
    quote = _json_string
    names = {nm: quote(nm) for nm in set(name)}
    head = f', "file": {quote(file)}, "line": '
    parts = []
    for a in range(0, len(ns), SLICE):  # a slice at a time: pyarrow's 32-bit string offsets
        b = a + SLICE
        t = ns[a:b]
        parts.append(
            join(
                [
                    '{"timestamp": {"sec": ',
                    number_text(t // 1_000_000_000),
                    ', "nsec": ',
                    number_text(t % 1_000_000_000),
                    '}, "level": ',
                    number_text(np.asarray(level[a:b], np.int64)),
                    ', "message": ',
                    ab.strings(list(map(quote, message[a:b])), nulls=False),
                    ', "name": ',
                    ab.strings([names[nm] for nm in name[a:b]], nulls=False),
                    head,
                    number_text(np.asarray(line[a:b], np.int64)),
                    "}",
                ]
            )
        )
    return Texts.concat(parts)


def signal_topic(s: SignalSeries | SignalBlock) -> str:
    return signal_path(s.node, s.pdo)


def state_topic(node: int) -> str:
    return f"/node/{node}/nmt_state"


def drive_topic(node: int) -> str:
    return f"/node/{node}/drive_state"


def write_merged(w: BulkMcapWriter, streams: list[tuple[int, np.ndarray, Texts]]) -> None:
    """All streams' messages in log-time order (stable: equal times keep stream order)."""
    if not streams:
        return
    times = np.concatenate([s[1] for s in streams])
    chans = np.concatenate([np.full(len(s[1]), s[0], np.uint16) for s in streams])
    order = np.argsort(times, kind="stable")
    w.messages(chans[order], times[order], [s[2] for s in streams], rows=order)


def write_metadata(
    w: BulkMcapWriter, source: str, network: str, frames: int, skipped: int, nodes: list[dict]
) -> None:
    """The `cananalyze` metadata record, nodes.json and the network file as attachments."""
    w.metadata(
        "cananalyze",
        {
            "version": __version__,
            "source": str(source),
            "network": network or "",
            "frames": str(frames),
            "skipped_input": str(skipped),
        },
    )
    plain = [{k: _plain(v) for k, v in row.items()} for row in nodes]
    w.attachment("nodes.json", "application/json", json.dumps(plain, indent=1).encode())
    if network and Path(network).is_file():
        p = Path(network)
        w.attachment(p.name, "text/plain", p.read_bytes())


def _plain(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, np.generic):
        return v.item()
    return v
