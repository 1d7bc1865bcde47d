"""The `/can/frames` MCAP topic: its one schema, its payload builder and its clock.

`export --mcap` (StreamMcap, write_mcap), `live --record x.mcap` (FrameRecorder) and
the MCAP reader (`formats/logs/mcap.py`) all take the topic from here, so a file written by
either opens in the other. One JSON message per frame, schema `cananalyze.Frame`:

  {"channel":"can0","can_id":385,"dlc":8,"data":"0102030405060708","flags":0,
   "service":"tpdo","node":1}

channel, can_id, flags, dlc and data rebuild the frame exactly; service and node
are the decoder's annotations (for Foxglove's filters; the reader ignores them).
The frame's time is the message's log_time (= publish_time): ns since the Unix
epoch, or since the log's start when the log has relative times.

Older live recordings used `cananalyze.CanFrame` (a `timestamp` and one boolean per
flag); the reader still opens them (LEGACY_FRAME_SCHEMA_NAME).
"""

from __future__ import annotations

import json

import numpy as np

from cananalyze.core.columns import bytecols
from cananalyze.core.columns.json_text import Texts
from cananalyze.core.frames import FLAG_RTR, FrameBatch
from cananalyze.protocol.services import SERVICE_NAMES
from cananalyze.runtime import speedups

FRAMES_TOPIC = "/can/frames"
FRAME_SCHEMA_NAME = "cananalyze.Frame"
LEGACY_FRAME_SCHEMA_NAME = "cananalyze.CanFrame"  # live recordings before the shared schema

FLAGS_TEXT = (
    "FrameBatch FLAG_* bits: 1 ext (29-bit identifier), 2 rtr (remote request), "
    "4 err (error frame), 8 fd (CAN FD), 16 brs (FD bit-rate switch), "
    "32 esi (FD error state indicator), 64 tx (sent by the logging node; else received), "
    "128 reconstructed (data bytes rebuilt from the log's text, not captured)"
)
# (name, JSON type, description), in the order the fields appear in every message
FRAME_FIELDS: tuple[tuple[str, str, str], ...] = (
    ("channel", "string", "interface name as the log gives it (can0, CAN1, ...)"),
    ("can_id", "integer", "identifier without flag bits (29-bit when flags has ext)"),
    ("dlc", "integer", "number of data bytes (0-64, not the DLC code); requested for rtr"),
    ("data", "string", "payload as lowercase hex, dlc bytes (CAN FD up to 64); empty for rtr"),
    ("flags", "integer", FLAGS_TEXT),
    ("service", "string", "CiA 301 service the decoder gave the frame (annotation)"),
    ("node", "integer", "node-ID the decoder gave the frame, -1 when none (annotation)"),
)
FRAME_SCHEMA = {
    "title": FRAME_SCHEMA_NAME,
    "description": "One raw CAN frame with its CANopen service; its time is the message log time",
    "type": "object",
    "properties": {name: {"type": kind, "description": text} for name, kind, text in FRAME_FIELDS},
}
SLICE = 1 << 20  # rows per compaction: keeps each part's offsets and scratch memory bounded


def log_time_ns(t: np.ndarray) -> np.ndarray:
    """Seconds as int64 ns, the nearest ns of each float exactly (negative times become 0).

    `round(t * 1e9)` rounds the product to float64 first, off by up to 128 ns at epoch
    times; whole seconds and the fraction are converted apart (the fraction is exact).
    """
    t = np.asarray(t, np.float64)
    whole = np.floor(t)
    ns = whole.astype(np.int64) * 1_000_000_000 + np.round((t - whole) * 1e9).astype(np.int64)
    return ns.clip(min=0)


def seconds(ns: np.ndarray) -> np.ndarray:
    """float64 seconds of int ns, the float nearest to each: what parsing the log's own
    decimal gave, so times survive an MCAP round trip unchanged."""
    ns = np.asarray(ns, np.int64)
    exact = np.abs(ns) < 2**53  # the int is exact as a float: one correctly rounded division
    out = ns.astype(np.float64) / 1e9
    big = ~exact
    if big.any():
        whole, frac = np.divmod(ns[big], 1_000_000_000)
        out[big] = whole.astype(np.float64) + frac.astype(np.float64) / 1e9
    return out


def frame_payloads(fb: FrameBatch, service: np.ndarray, node: np.ndarray) -> Texts:
    """The /can/frames documents (FRAME_FIELDS order), built as byte columns and joined
    in one compaction (`bytecols`), a slice of rows at a time: no json.dumps per frame,
    and pyarrow's number casts and row join took twice as long."""
    if len(fb) == 0:
        return Texts.concat([])
    top = int(fb.channel.max()) + 1
    labels = [json.dumps(fb.channel_label(c)).encode() for c in range(max(top, len(fb.channels)))]
    services = [json.dumps(s).encode() for s in SERVICE_NAMES]
    compiled = getattr(speedups.C, "frame_json", None)
    if compiled is not None:  # the same bytes in one pass, without the GIL
        return _compiled(compiled, fb, service, node, labels, services)
    chan_text = bytecols.padded_table(labels)
    service_text = bytecols.padded_table(services)
    parts = []
    for a in range(0, len(fb), SLICE):
        b = min(a + SLICE, len(fb))
        n = b - a
        flags = fb.flags[a:b]
        raw, shown = _payload_bytes(fb, a, b)
        values = {
            "channel": [chan_text[fb.channel[a:b]]],
            "can_id": [bytecols.decimal(fb.can_id[a:b])],
            "dlc": [bytecols.decimal(fb.dlc[a:b])],
            "data": [
                '"',
                bytecols.hex_bytes(raw, shown),
                '"',
            ],
            "flags": [bytecols.decimal(flags)],
            "service": [service_text[service[a:b]]],
            "node": [bytecols.decimal(node[a:b])],
        }
        pieces: list = []
        for k, (name, _, _) in enumerate(FRAME_FIELDS):
            pieces.append(("{" if k == 0 else ",") + json.dumps(name) + ":")
            pieces.extend(values[name])
        pieces.append("}")
        blob, ends = bytecols.compact(_columns(pieces, n), n, with_ends=True)
        offsets = np.zeros(n + 1, np.int64)
        offsets[1:] = ends
        parts.append(Texts(np.frombuffer(blob, np.uint8), offsets))
    return Texts.concat(parts)


def _compiled(frame_json, fb: FrameBatch, service, node, labels, services) -> Texts:
    """frame_payloads by the compiled helper, a slice of rows at a time."""
    parts = []
    for a in range(0, len(fb), SLICE):
        b = min(a + SLICE, len(fb))
        raw, shown = _payload_bytes(fb, a, b)
        offsets = np.zeros(b - a + 1, np.int64)
        blob = frame_json(
            labels,
            services,
            np.ascontiguousarray(fb.channel[a:b], np.uint16),
            np.ascontiguousarray(fb.can_id[a:b], np.uint32),
            np.ascontiguousarray(fb.dlc[a:b], np.uint8),
            np.ascontiguousarray(raw, np.uint8),
            np.ascontiguousarray(shown, np.int64),
            np.ascontiguousarray(fb.flags[a:b], np.uint8),
            np.ascontiguousarray(service[a:b], np.uint8),
            np.ascontiguousarray(node[a:b], np.int16),
            offsets[1:],
        )
        parts.append(Texts(np.frombuffer(blob, np.uint8), offsets))
    return Texts.concat(parts)


def _columns(pieces: list, n: int) -> list[np.ndarray]:
    """Byte columns of the pieces, neighbouring fixed texts merged into one column."""
    out: list[np.ndarray] = []
    text = ""
    for p in pieces:
        if isinstance(p, str):
            text += p
            continue
        if text:
            out.append(bytecols.repeat(text, n))
            text = ""
        out.append(p)
    if text:
        out.append(bytecols.repeat(text, n))
    return out


def _payload_bytes(fb: FrameBatch, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows a..b's payload bytes as a matrix and how many of each to show (none for a
    remote request): the 8-byte column, widened to 64 when CAN FD frames carry more
    (`long_data`, rare)."""
    data = fb.data[a:b]
    rtr = (fb.flags[a:b] & FLAG_RTR) != 0
    shown = np.where(rtr, 0, np.minimum(fb.dlc[a:b], data.shape[1])).astype(np.int64)
    long_rows = [i for i in fb.long_data if a <= i < b and not rtr[i - a]]
    if not long_rows:
        return data, shown
    wide = np.zeros((b - a, 64), np.uint8)
    wide[:, : data.shape[1]] = data
    for i in long_rows:
        raw = fb.long_data[i][:64]
        wide[i - a, : len(raw)] = np.frombuffer(raw, np.uint8)
        shown[i - a] = len(raw)
    return wide, shown
