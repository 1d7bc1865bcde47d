"""MCAP export for Foxglove: every PDO as a plottable topic, events as a log panel.

Topics (all JSON-encoded with JSON Schema, so Foxglove needs no configuration):
  /node/<N>/<pdo>     decoded signals of one PDO (numbers as numbers; unit in the
                      schema's description)
  /node/<N>/nmt_state NMT state changes seen in heartbeat, boot-up, guarding
  /canopen/events     foxglove.Log: SDO transactions, EMCY, NMT commands, findings
  /can/frames         every raw frame
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

from .. import __version__
from ..capture import Capture, SignalSeries
from ..frames import FLAG_RTR
from ..protocol.services import SERVICE_NAMES
from .atomic import atomic_path
from .json_text import Texts, hex_text, join, label_text, number_text, object_template
from .mcap_bulk import BulkMcapWriter

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

FRAME_SCHEMA = {
    "title": "cananalyze.Frame",
    "description": "One raw CAN frame with its CANopen service",
    "type": "object",
    "properties": {
        "channel": {"type": "string"},
        "can_id": {"type": "integer", "description": "identifier without flag bits"},
        "dlc": {"type": "integer", "description": "number of data bytes"},
        "data": {"type": "string", "description": "payload, hex"},
        "flags": {"type": "integer", "description": "1 ext, 2 rtr, 4 error, 8 fd, 64 tx"},
        "service": {"type": "string"},
        "node": {"type": "integer", "description": "node-ID, -1 when none"},
    },
}

STATE_SCHEMA = {
    "title": "cananalyze.NmtState",
    "description": "NMT state of a node as reported by heartbeat, boot-up or guarding",
    "type": "object",
    "properties": {"state": {"type": "string"}},
}


def _ns(t: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(t, np.float64) * 1e9).astype(np.int64).clip(min=0)


def _json_type(values: np.ndarray) -> str:
    if values.dtype == bool:
        return "boolean"
    if np.issubdtype(values.dtype, np.integer):
        return "integer"
    return "number"


def signal_schema(s: SignalSeries) -> dict:
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


SLICE = 1 << 20  # rows per join: keeps pyarrow's 32-bit string offsets in range


def signal_payloads(s: SignalSeries) -> Texts:
    """`{"signal": value, ...}` per PDO, built column-wise (NaN/inf become null)."""
    names = list(s.columns)
    return Texts.concat(
        [
            join(object_template(names, [number_text(s.columns[n][a : a + SLICE]) for n in names]))
            for a in range(0, len(s.t), SLICE)
        ]
    )


def frame_payloads(cap: Capture) -> Texts:
    """The /can/frames documents, a slice of rows at a time."""
    fb = cap.batch
    channels = list(fb.channels) or ["can0"]
    parts = []
    for a in range(0, len(fb), SLICE):
        b = min(a + SLICE, len(fb))
        flags = fb.flags[a:b]
        shown = np.where((flags & FLAG_RTR) != 0, 0, np.minimum(fb.dlc[a:b], fb.data.shape[1]))
        data = hex_text(fb.data[a:b], shown)
        long_rows = [i for i in fb.long_data if a <= i < b]
        if long_rows:  # FD payloads beyond the 8-byte column
            import pyarrow as pa
            import pyarrow.compute as pc

            mask = np.zeros(b - a, bool)
            mask[np.array(long_rows) - a] = True
            data = pc.replace_with_mask(
                data, pa.array(mask), pa.array([fb.long_data[i].hex() for i in sorted(long_rows)])
            )
        chan = np.minimum(fb.channel[a:b], len(channels) - 1)
        parts.append(
            join(
                [
                    '{"channel":',
                    label_text(channels, chan),
                    ',"can_id":',
                    number_text(fb.can_id[a:b]),
                    ',"dlc":',
                    number_text(fb.dlc[a:b]),
                    ',"data":"',
                    data,
                    '","flags":',
                    number_text(flags),
                    ',"service":',
                    label_text(list(SERVICE_NAMES), cap.service[a:b]),
                    ',"node":',
                    number_text(cap.node[a:b]),
                    "}",
                ]
            )
        )
    return Texts.concat(parts)


def write_mcap(
    cap: Capture, path: str | Path, compression: str = "zstd", chunk_bytes: int = 4 << 20
) -> dict[str, int]:
    """Write the capture as MCAP; returns message counts per topic."""
    if compression not in ("zstd", "lz4", "none"):
        raise ValueError(f"unknown MCAP compression {compression!r}")
    counts: dict[str, int] = {}
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        w = BulkMcapWriter(
            f, f"cananalyze {__version__}", compression=compression, chunk_bytes=chunk_bytes
        )
        streams: list[tuple[int, np.ndarray, Texts]] = []
        for topic, schema, ns, payload in topic_streams(cap):
            sid = w.schema(schema["title"], "jsonschema", json.dumps(schema).encode())
            streams.append((w.channel(topic, "json", sid), ns, payload))
            counts[topic] = len(ns)
        _write_merged(w, streams)
        _metadata(w, cap)
        w.finish()
    return counts


def topic_streams(cap: Capture) -> list[tuple[str, dict, np.ndarray, Texts]]:
    """(topic, JSON schema, log times in ns, payloads) for every topic, in channel order."""
    out = []
    for s in cap.series:
        out.append((f"/node/{s.node}/{s.pdo}", signal_schema(s), _ns(s.t), signal_payloads(s)))
    by_node: dict[int, list] = {}
    for e in cap.state_changes:
        by_node.setdefault(e.node, []).append(e)
    for node, evs in sorted(by_node.items()):
        t = np.array([e.t for e in evs])
        data = [json.dumps({"state": e.message}).encode() for e in evs]
        out.append((f"/node/{node}/nmt_state", STATE_SCHEMA, _ns(t), Texts.from_list(data)))
    events = cap.sorted_events()
    if events:
        ns = _ns(np.array([e.t for e in events]))
        lines = cap.batch.line
        file = Path(cap.source).name
        data = []
        for e, tn in zip(events, ns.tolist(), strict=True):
            line = int(lines[e.row]) if e.row is not None and e.row < len(lines) else 0
            msg = {
                "timestamp": {"sec": tn // 1_000_000_000, "nsec": tn % 1_000_000_000},
                "level": e.level,
                "message": e.message,
                "name": f"node {e.node}" if e.node is not None else e.kind,
                "file": file,
                "line": line,
            }
            data.append(json.dumps(msg).encode())
        out.append(("/canopen/events", LOG_SCHEMA, ns, Texts.from_list(data)))
    if len(cap.batch):
        out.append(("/can/frames", FRAME_SCHEMA, _ns(cap.batch.t), frame_payloads(cap)))
    return out


def _write_merged(w: BulkMcapWriter, streams: list[tuple[int, np.ndarray, Texts]]) -> None:
    """All streams' messages in log-time order (stable: equal times keep stream order)."""
    if not streams:
        return
    times = np.concatenate([s[1] for s in streams])
    chans = np.concatenate([np.full(len(s[1]), s[0], np.uint16) for s in streams])
    order = np.argsort(times, kind="stable")
    w.messages(chans[order], times[order], [s[2] for s in streams], rows=order)


def _metadata(w: BulkMcapWriter, cap: Capture) -> None:
    w.metadata(
        "cananalyze",
        {
            "version": __version__,
            "source": str(cap.source),
            "network": cap.network or "",
            "frames": str(len(cap.batch)),
            "skipped_input": str(cap.problems.count),
        },
    )
    nodes = [{k: _plain(v) for k, v in row.items()} for row in cap.node_rows()]
    w.attachment("nodes.json", "application/json", json.dumps(nodes, indent=1).encode())
    if cap.network and Path(cap.network).is_file():
        p = Path(cap.network)
        w.attachment(p.name, "text/plain", p.read_bytes())


def _plain(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, np.generic):
        return v.item()
    return v
