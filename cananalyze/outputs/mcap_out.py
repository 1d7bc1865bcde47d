"""MCAP export for Foxglove: every PDO as a plottable topic, events as a log panel.

Topics (all JSON-encoded with JSON Schema, so Foxglove needs no configuration):
  /node/<N>/<pdo>     decoded signals of one PDO (numbers as numbers; unit in the
                      schema's description)
  /node/<N>/nmt_state NMT state changes seen in heartbeat, boot-up, guarding
  /canopen/events     foxglove.Log: SDO transactions, EMCY, NMT commands, findings
  /can/frames         every raw frame
Log time = frame time in ns. Messages are written in time order across topics.
JSON text is formatted with templates over column lists: one json.dumps per frame
would cost several seconds on a million frames.
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


def _json_values(values: np.ndarray) -> list[str]:
    """JSON text of each value; NaN/inf become null (JSON has no such numbers)."""
    if values.dtype == bool:
        return ["true" if v else "false" for v in values.tolist()]
    if np.issubdtype(values.dtype, np.integer):
        return [str(v) for v in values.tolist()]
    v = np.asarray(values, np.float64)
    out = [repr(x) for x in v.tolist()]
    if not np.isfinite(v).all():
        for i in np.flatnonzero(~np.isfinite(v)).tolist():
            out[i] = "null"
    return out


def signal_payloads(s: SignalSeries) -> list[bytes]:
    names = list(s.columns)
    tmpl = "{" + ",".join(f"{json.dumps(n)}:%s" for n in names) + "}"
    cols = [_json_values(s.columns[n]) for n in names]
    return [(tmpl % vals).encode() for vals in zip(*cols, strict=True)]


def frame_payloads(cap: Capture) -> list[bytes]:
    fb = cap.batch
    channels = list(fb.channels) or ["can0"]
    chan = [json.dumps(c) for c in channels]
    svc = [json.dumps(n) for n in SERVICE_NAMES]
    hexes = bytes(fb.data.reshape(-1)).hex()
    dlc = np.where((fb.flags & FLAG_RTR) != 0, 0, np.minimum(fb.dlc, 8)).tolist()
    out = []
    for i, (c, cid, d, f, s, n) in enumerate(
        zip(
            fb.channel.tolist(),
            fb.can_id.tolist(),
            fb.dlc.tolist(),
            fb.flags.tolist(),
            cap.service.tolist(),
            cap.node.tolist(),
            strict=True,
        )
    ):
        data = fb.long_data[i].hex() if i in fb.long_data else hexes[16 * i : 16 * i + 2 * dlc[i]]
        out.append(
            f'{{"channel":{chan[min(c, len(chan) - 1)]},"can_id":{cid},"dlc":{d},'
            f'"data":"{data}","flags":{f},"service":{svc[s]},"node":{n}}}'.encode()
        )
    return out


def write_mcap(cap: Capture, path: str | Path, compression: str = "zstd") -> dict[str, int]:
    """Write the capture as MCAP; returns message counts per topic."""
    from mcap.writer import CompressionType, Writer

    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[
        compression
    ]
    counts: dict[str, int] = {}
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        w = Writer(f, chunk_size=4 * 1024 * 1024, compression=comp)
        w.start(profile="", library=f"cananalyze {__version__}")
        streams: list[tuple[int, np.ndarray, list[bytes]]] = []

        def channel(topic: str, schema: dict, title: str | None = None) -> int:
            sid = w.register_schema(
                name=title or schema["title"],
                encoding="jsonschema",
                data=json.dumps(schema).encode(),
            )
            return w.register_channel(topic=topic, message_encoding="json", schema_id=sid)

        for s in cap.series:
            topic = f"/node/{s.node}/{s.pdo}"
            streams.append((channel(topic, signal_schema(s)), _ns(s.t), signal_payloads(s)))
            counts[topic] = len(s.t)
        by_node: dict[int, list] = {}
        for e in cap.state_changes:
            by_node.setdefault(e.node, []).append(e)
        for node, evs in sorted(by_node.items()):
            topic = f"/node/{node}/nmt_state"
            t = np.array([e.t for e in evs])
            data = [json.dumps({"state": e.message}).encode() for e in evs]
            streams.append((channel(topic, STATE_SCHEMA), _ns(t), data))
            counts[topic] = len(evs)
        events = cap.sorted_events()
        if events:
            t = np.array([e.t for e in events])
            ns = _ns(t)
            lines = cap.batch.line
            data = []
            for e, tn in zip(events, ns.tolist(), strict=True):
                line = int(lines[e.row]) if e.row is not None and e.row < len(lines) else 0
                msg = {
                    "timestamp": {"sec": tn // 1_000_000_000, "nsec": tn % 1_000_000_000},
                    "level": e.level,
                    "message": e.message,
                    "name": f"node {e.node}" if e.node is not None else e.kind,
                    "file": Path(cap.source).name,
                    "line": line,
                }
                data.append(json.dumps(msg).encode())
            streams.append((channel("/canopen/events", LOG_SCHEMA), ns, data))
            counts["/canopen/events"] = len(events)
        if len(cap.batch):
            streams.append(
                (channel("/can/frames", FRAME_SCHEMA), _ns(cap.batch.t), frame_payloads(cap))
            )
            counts["/can/frames"] = len(cap.batch)
        _write_merged(w, streams)
        _metadata(w, cap)
        w.finish()
    return counts


def _write_merged(w, streams: list[tuple[int, np.ndarray, list[bytes]]]) -> None:
    """All streams' messages in log-time order (stable: equal times keep stream order)."""
    if not streams:
        return
    times = np.concatenate([s[1] for s in streams])
    which = np.concatenate([np.full(len(s[1]), k, np.int32) for k, s in enumerate(streams)])
    pos = np.concatenate([np.arange(len(s[1])) for s in streams])
    order = np.argsort(times, kind="stable")
    add = w.add_message
    chans = [s[0] for s in streams]
    datas = [s[2] for s in streams]
    for tn, k, j in zip(
        times[order].tolist(), which[order].tolist(), pos[order].tolist(), strict=True
    ):
        add(channel_id=chans[k], log_time=tn, data=datas[k][j], publish_time=tn)


def _metadata(w, cap: Capture) -> None:
    w.add_metadata(
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
    w.add_attachment(0, 0, "nodes.json", "application/json", json.dumps(nodes, indent=1).encode())
    if cap.network and Path(cap.network).is_file():
        p = Path(cap.network)
        w.add_attachment(0, 0, p.name, "text/plain", p.read_bytes())


def _plain(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, np.generic):
        return v.item()
    return v
