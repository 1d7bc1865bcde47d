"""The one-line text of a record (SDO transfer, finding, other), as the text output and
the live dashboard show it under the frame that completed it."""

from __future__ import annotations

from cananalyze.decode.events.sdo_text import shown_data, shown_text
from cananalyze.protocol.sdo import object_text

_VERB = {"upload": "read", "download": "write"}


def format_record(rec: dict) -> str:
    """One line for a record of kind sdo / finding / event."""
    kind = rec.get("kind")
    if kind == "sdo":
        what = _VERB.get(rec.get("direction"), "transfer")  # an abort alone: no direction
        obj = object_text(rec["index"], rec["subindex"]) if rec.get("index") is not None else "?"
        name = f" {rec['name']}" if rec.get("name") else ""
        protocol = rec.get("protocol") or ""
        usdo = protocol.startswith("usdo")  # CiA 1301 (CANopen FD): usdo_expedited ...
        if usdo:
            protocol = protocol[5:]
        proto = f" {protocol}" if protocol else ""  # unknown when aborted at once
        svc = "USDO" if usdo else "SDO"
        line = f"node {rec.get('node')} {svc} {what} {obj}{name}{proto} -> {rec.get('result')}"
        if rec.get("result") == "ok":
            value = rec.get("value")
            if value is None:
                line += f": data {shown_data(rec.get('data') or '-', size=False)}"
            elif isinstance(value, str):
                line += f": {shown_text(value)!r}"
            elif isinstance(value, int) and not isinstance(value, bool) and abs(value) > 9:
                line += f": {value} (0x{value & 0xFFFFFFFFFFFFFFFF:X})"
            else:
                line += f": {value}"
            if rec.get("words"):
                line += f" ({rec['words']})"
            line += f" ({rec.get('size')} bytes)"
        elif rec.get("abort_code") is not None:
            width = 2 if usdo else 8  # a USDO abort code is one byte
            line += f": 0x{rec['abort_code']:0{width}X} {rec.get('abort_text')}"
        if rec.get("detail"):
            line += f" [{rec['detail']}]"
        if rec.get("latency_ms") is not None:
            line += f", latency {rec['latency_ms']:.1f} ms"
        if usdo and rec.get("client") is not None:
            line += f" (client {rec['client']}, session {rec.get('session')})"
        return line
    if kind == "finding":
        return f"{rec.get('severity', 'warning').upper()} {rec.get('rule')}: {rec.get('message')}"
    return " ".join(f"{k}={v}" for k, v in rec.items())


def format_alone(rec: dict, t0: float) -> str:
    """A record on a line of its own (no frame line above it: a live tick's finding, the
    end of the log): a finding then carries its time and node, as a frame line would."""
    if rec.get("kind") != "finding" or not isinstance(rec.get("t"), (int, float)):
        return format_record(rec)
    node = rec.get("node")
    where = f"node {node} " if isinstance(node, int) else ""
    if rec.get("bus") is not None:  # several buses: which one ("can1 node 5")
        where = f"{rec['bus']} {where}"
    severity = str(rec.get("severity", "warning")).upper()
    return f"{rec['t'] - t0:12.6f}  {severity} {rec.get('rule')}: {where}{rec.get('message')}"
