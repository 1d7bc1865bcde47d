"""`decode` text output: one aligned, candump-like line per frame plus its annotation.

Records (SDO transactions, findings) print as indented lines right after the
frame that completed them.
"""

from __future__ import annotations

from typing import TextIO

import numpy as np

from ..decoded import DecodedBatch
from ..frames import FLAG_ERR, FLAG_EXT, FLAG_RTR
from ..protocol.fields import annotation
from ..protocol.services import SERVICE_NAMES

_HEX3 = [f"{i:02X} " for i in range(256)]

# ANSI colours per service group, only on a terminal.
_COLOURS = {
    "nmt": "\033[1;35m",
    "sync": "\033[2m",
    "time": "\033[2m",
    "emcy": "\033[1;31m",
    "tpdo": "\033[36m",
    "rpdo": "\033[34m",
    "sdo_request": "\033[33m",
    "sdo_response": "\033[33m",
    "heartbeat": "\033[32m",
    "bootup": "\033[1;32m",
    "guard_request": "\033[32m",
    "guard_response": "\033[32m",
    "lss_master": "\033[35m",
    "lss_slave": "\033[35m",
    "error_frame": "\033[1;31m",
    "other": "\033[2m",
}
_RESET = "\033[0m"


def format_record(rec: dict) -> str:
    """One line for a record of kind sdo / finding / event."""
    kind = rec.get("kind")
    if kind == "sdo":
        what = "read" if rec.get("direction") == "upload" else "write"
        obj = f"0x{rec['index']:04X}:{rec['subindex']:02X}" if rec.get("index") is not None else "?"
        name = f" {rec['name']}" if rec.get("name") else ""
        proto = f" {rec['protocol']}" if rec.get("protocol") else ""  # unknown when aborted at once
        line = f"node {rec.get('node')} SDO {what} {obj}{name}{proto} -> {rec.get('result')}"
        if rec.get("result") == "ok":
            value = rec.get("value")
            if value is None:
                line += f": data {rec.get('data') or '-'}"
            elif isinstance(value, str):
                line += f": {value!r}"
            elif isinstance(value, int) and not isinstance(value, bool) and abs(value) > 9:
                line += f": {value} (0x{value & 0xFFFFFFFFFFFFFFFF:X})"
            else:
                line += f": {value}"
            line += f" ({rec.get('size')} bytes)"
        elif rec.get("abort_code") is not None:
            line += f": 0x{rec['abort_code']:08X} {rec.get('abort_text')}"
        if rec.get("detail"):
            line += f" [{rec['detail']}]"
        if rec.get("latency_ms") is not None:
            line += f", latency {rec['latency_ms']:.1f} ms"
        return line
    if kind == "finding":
        return f"{rec.get('severity', 'warning').upper()} {rec.get('rule')}: {rec.get('message')}"
    return " ".join(f"{k}={v}" for k, v in rec.items())


class TextWriter:
    def __init__(
        self, out: TextIO, color: bool = False, t0: float | None = None, only_records: bool = False
    ) -> None:
        self.out = out
        self.color = color
        self.t0 = t0
        self.only_records = only_records

    def write(self, batch: DecodedBatch, mask: np.ndarray | None = None) -> None:
        fb = batch.frames
        if self.t0 is None and len(fb):
            self.t0 = float(fb.t[0])
        t0 = self.t0 or 0.0
        by_row: dict[int, list[dict]] = {}
        for row, rec in batch.records:
            by_row.setdefault(row, []).append(rec)
        rows = range(len(fb)) if mask is None else np.flatnonzero(mask).tolist()
        lines: list[str] = []
        if not self.only_records:
            rel = (fb.t - t0).tolist()
            ids = fb.can_id.tolist()
            flags = fb.flags.tolist()
            dlcs = fb.dlc.tolist()
            nodes = batch.node.tolist()
            pdos = batch.pdo.tolist()
            services = batch.service.tolist()
            for i in rows:
                fl = flags[i]
                ident = f"{ids[i]:08X}" if fl & (FLAG_EXT | FLAG_ERR) else f"{ids[i]:03X}"
                if fl & FLAG_RTR:
                    data = "remote request"
                else:
                    data = "".join(_HEX3[b] for b in fb.payload(i)).rstrip()
                svc = SERVICE_NAMES[services[i]]
                node = nodes[i]
                text = annotation(services[i], node, pdos[i], batch.fields(i), bool(fl & FLAG_RTR))
                ch = fb.channel_name(i)
                line = (
                    f"{rel[i]:12.6f}  {ch:<5} {ident:>8}  [{dlcs[i]}]  {data:<23}  "
                    f"{svc:<14} {'' if node < 0 else node:>3}  {text}"
                )
                if self.color:
                    line = f"{_COLOURS.get(svc, '')}{line}{_RESET}"
                lines.append(line)
                for rec in by_row.get(i, ()):
                    lines.append("    └─ " + format_record(rec))
        # records of rows not printed (filtered out, records-only view, end of log) still print
        shown = (
            set() if self.only_records else (set(rows) if mask is not None else set(range(len(fb))))
        )
        for row, rec in batch.records:
            if row not in shown:
                lines.append(format_record(rec))
        if lines:
            self.out.write("\n".join(lines) + "\n")
