"""USDO tracker: reassembles CiA 1301 USDO transfers (CANopen FD) into SDO table records.

Frame by frame, like the SDO tracker, from a passive observer's seat: a client's
frames come on 0x600 + its node-ID and name the server in byte 0, a server's on
0x580 + its node-ID and name the client; the session ID tells a client's
transfers to one server apart. Expedited, segmented and bulk transfers in both
directions (the layouts in protocol/usdo.py), aborts from either side with
their text, time-outs, broadcast requests (each server's answer its own
transfer). A finished transfer is the same record as an SDO transfer (the one
record every output reads: `core/sdo_records.py`), its `protocol` prefixed
`usdo_` and with the USDO's `client` and `session`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from cananalyze.core.defaults import SDO_TIMEOUT
from cananalyze.decode.sdo.words import sdo_words
from cananalyze.protocol import usdo
from cananalyze.protocol.datatypes import decode_value

ObjectInfo = Callable[[int, int, int], "tuple[str, int] | None"]
Key = tuple[int, int, int]  # (client, server, session); server 0: a broadcast request


@dataclass
class UsdoTransfer:
    client: int
    server: int
    session: int
    direction: str
    protocol: str | None
    index: int | None
    subindex: int | None
    t_start: float
    t_last: float
    ref: int
    datatype: int | None = None
    total: int | None = None
    data: bytearray = field(default_factory=bytearray)
    counter: int | None = None  # the last segment counter seen
    frames: int = 1
    t_first_response: float | None = None
    answered: bool = False  # a broadcast request some server answered
    notes: list[str] = field(default_factory=list)


def _mux(index: int | None, subindex: int | None) -> str:
    return "" if index is None else " " + usdo.object_text(index, subindex or 0)


class UsdoTracker:
    """Feed USDO frames in time order; collect finished transfers (record dicts) with
    `pop_completed()`, each with the ref of the frame that ended it."""

    def __init__(self, timeout: float = SDO_TIMEOUT, object_info: ObjectInfo | None = None) -> None:
        self.timeout = timeout
        self.object_info = object_info
        self._pending: dict[Key, UsdoTransfer] = {}
        self._completed: list[tuple[int | None, dict]] = []

    # -- feeding ----------------------------------------------------------------

    def feed(self, t: float, cob_id: int, data: bytes, ref: int) -> dict:
        """Take one frame; return its note (`role`, `command`, `index`, `subindex`,
        `usdo_problem` when it breaks the protocol)."""
        self.advance(t)
        by_client = usdo.CLIENT_BASE < cob_id <= usdo.CLIENT_BASE + 0x7F
        sender = cob_id - (usdo.CLIENT_BASE if by_client else usdo.SERVER_BASE)
        f = usdo.parse(data)
        if f is None:
            problem = usdo.fields(data).get("usdo_problem", "invalid USDO frame")
            return {"role": problem, "command": "invalid", "usdo_problem": problem}
        cmd = f["cmd"]
        index, subindex = f.get("index"), f.get("subindex")
        note = {"command": cmd.name.replace(" ", "_"), "index": index, "subindex": subindex}
        dest, session = f["destination"], f["session"]
        client, server = (sender, dest) if by_client else (dest, sender)
        side = "client" if by_client else "server"
        if f["remote"]:
            note["role"] = f"remote (routed) {cmd.name}, session {session}: not reassembled"
            return note
        if cmd.sender != "either" and cmd.sender != side:
            problem = f"{cmd.name} sent by a {side} (on 0x{cob_id:03X})"
            return note | {"role": problem, "usdo_problem": problem}
        key = (client, server, session)
        xfer = self._pending.get(key)
        if xfer is None and not by_client:
            xfer = self._from_broadcast(key)
        if xfer is not None:
            xfer.frames += 1
            xfer.t_last, xfer.ref = t, ref
            if not by_client and xfer.t_first_response is None:
                xfer.t_first_response = t
        what = f"{cmd.name}{_mux(index, subindex)}, session {session}"
        if cmd.step == "abort":
            return note | {"role": self._abort(t, f, key, xfer, side, ref)}
        if cmd.step == "init" and by_client:
            if xfer is not None:
                self._cut_short(xfer, t)
            new = UsdoTransfer(client, server, session, cmd.direction, cmd.protocol,
                               index, subindex, t, t, ref)  # fmt: skip
            new.datatype, new.total = f.get("datatype"), f.get("total")
            if "data" in f:
                new.data += f["data"]
            self._pending[key] = new
            return note | {"role": what + self._size_text(f)}
        if xfer is None:
            problem = f"{cmd.name} with no USDO transfer in progress (session {session})"
            return note | {"role": problem, "usdo_problem": problem}
        if cmd.direction != xfer.direction or (
            cmd.protocol and xfer.protocol and cmd.protocol != xfer.protocol
        ):
            problem = f"unexpected {cmd.name} in a {xfer.protocol or ''} {xfer.direction}".replace(
                "  ", " "
            )
            xfer.notes.append(problem)
            return note | {"role": problem, "usdo_problem": problem}
        if (
            index is not None
            and xfer.index is not None
            and (index, subindex)
            != (
                xfer.index,
                xfer.subindex,
            )
        ):
            xfer.notes.append(f"answer names{_mux(index, subindex)}")
        if cmd.protocol and xfer.protocol is None:
            xfer.protocol = cmd.protocol  # an upload's answer tells
        if "datatype" in f and xfer.datatype is None:
            xfer.datatype = f["datatype"]
        if f.get("total") is not None:
            xfer.total = f["total"]
        problem = None
        if "counter" in f and cmd.layout == "segment":
            problem = self._count(xfer, f["counter"])
        if "data" in f:
            xfer.data += f["data"]
        # the server's last frame ends a transfer; a client's (a download's last
        # segment) waits for the server's answer
        if cmd.step == "end" or (cmd.step == "last" and cmd.sender == "server"):
            self._finish(xfer, t, "ok")
        out = note | {"role": what + self._size_text(f)}
        if problem:
            out["usdo_problem"] = problem
        return out

    @staticmethod
    def _size_text(f: dict) -> str:
        if "data" in f:
            return f" ({len(f['data'])} bytes)"
        if f.get("total") is not None:
            return f" ({f['total']} bytes to come)"
        return ""

    def _count(self, xfer: UsdoTransfer, counter: int) -> str | None:
        prev, xfer.counter = xfer.counter, counter
        if prev is not None and counter != (prev + 1) & 0xFF:
            problem = f"segment counter {counter} after {prev}"
            xfer.notes.append(problem)
            return problem
        return None

    def _from_broadcast(self, key: Key) -> UsdoTransfer | None:
        """A server's answer to a broadcast request: that server's own copy of it."""
        client, server, session = key
        b = self._pending.get((client, usdo.BROADCAST, session))
        if b is None:
            return None
        b.answered = True
        copy = UsdoTransfer(client, server, session, b.direction, b.protocol, b.index,
                            b.subindex, b.t_start, b.t_last, b.ref, b.datatype, b.total,
                            bytearray(b.data), b.counter, b.frames)  # fmt: skip
        copy.notes.append("broadcast request")
        self._pending[key] = copy
        return copy

    def _abort(self, t, f, key, xfer, side, ref) -> str:
        code = f["abort_code"]
        text = (f"abort by {side}{_mux(f.get('index'), f.get('subindex'))}, session "
                f"{f['session']}: 0x{code:02X} {usdo.abort_text(code)}")  # fmt: skip
        if xfer is None:
            client, server, session = key
            xfer = UsdoTransfer(client, server, session, None, None, f.get("index"),  # type: ignore[arg-type]
                                f.get("subindex"), t, t, ref)  # fmt: skip
            xfer.notes.append("the transfer's start is not in the log")
            if side == "server":
                xfer.t_first_response = t
        else:
            xfer.notes.append(f"aborted by {side}")
        self._finish(xfer, t, "abort", code)
        return text

    def _cut_short(self, xfer: UsdoTransfer, t: float) -> None:
        if xfer.t_first_response is None and not xfer.answered:
            xfer.notes.append("no response; the client started a new transfer in the session")
            self._finish(xfer, t, "timeout")
        elif xfer.server == usdo.BROADCAST:
            self._pending.pop((xfer.client, xfer.server, xfer.session), None)
        else:
            xfer.notes.append("new request in the session before this transfer ended")
            self._finish(xfer, xfer.t_last, "protocol_error")

    def advance(self, t: float) -> None:
        """End as time-outs the transfers quiet for longer than the timeout at `t`."""
        if not self._pending:
            return
        for xfer in [x for x in self._pending.values() if t - x.t_last > self.timeout]:
            if xfer.server == usdo.BROADCAST and xfer.answered:
                self._pending.pop((xfer.client, xfer.server, xfer.session), None)
                continue
            xfer.notes.append(f"no frame within {self.timeout:g} s")
            self._finish(xfer, xfer.t_last + self.timeout, "timeout", ref=None)

    def finish(self) -> None:
        for xfer in list(self._pending.values()):
            if xfer.server == usdo.BROADCAST and xfer.answered:
                continue
            if xfer.t_first_response is None and not xfer.answered:
                xfer.notes.append("no response before the log ended")
                self._finish(xfer, xfer.t_last, "timeout", ref=None)
            else:
                xfer.notes.append("log ended mid-transfer")
                self._finish(xfer, xfer.t_last, "protocol_error", ref=None)
        self._pending.clear()

    def pop_completed(self) -> list[tuple[int | None, dict]]:
        out, self._completed = self._completed, []
        return out

    # -- records ----------------------------------------------------------------

    def _finish(
        self,
        xfer: UsdoTransfer,
        t: float,
        result: str,
        code: int | None = None,
        ref: int | None = -1,
    ) -> None:
        self._pending.pop((xfer.client, xfer.server, xfer.session), None)
        if result == "ok" and xfer.total is not None and xfer.total != len(xfer.data):
            result = "protocol_error"
            xfer.notes.append(f"size announced {xfer.total}, assembled {len(xfer.data)}")
        ok = result == "ok"
        data = bytes(xfer.data)
        rec = {
            "kind": "sdo",
            "t_start": xfer.t_start,
            "t": t,
            "latency_ms": None
            if xfer.t_first_response is None
            else round((xfer.t_first_response - xfer.t_start) * 1000.0, 3),
            "node": xfer.server,
            "direction": xfer.direction,
            "protocol": "usdo" if xfer.protocol is None else f"usdo_{xfer.protocol}",
            "index": xfer.index,
            "subindex": xfer.subindex,
            "size": len(data) if (data or ok) else xfer.total,
            "data": data.hex() if (data or ok) else None,
            "value": None,
            "name": None,
            "result": result,
            "abort_code": code,
            "abort_text": None if code is None else usdo.abort_text(code),
            "detail": "; ".join(xfer.notes) or None,
            "words": None,
            "frames": xfer.frames,
            "cob_ids": [usdo.CLIENT_BASE + xfer.client, usdo.SERVER_BASE + xfer.server],
            "client": xfer.client,
            "session": xfer.session,
        }
        if xfer.index is not None:
            known = (
                self.object_info(xfer.server, xfer.index, xfer.subindex or 0)
                if self.object_info
                else None
            )
            datatype = xfer.datatype
            if known is not None:
                rec["name"], datatype = known
            if ok and datatype:
                rec["value"] = decode_value(data, datatype)
            if ok:
                rec["words"] = sdo_words(xfer.server, xfer.index, xfer.subindex, rec["value"],
                                         data, rec["name"], self.object_info)  # fmt: skip
        self._completed.append((xfer.ref if ref == -1 else ref, rec))
