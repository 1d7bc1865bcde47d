"""USDO (CiA 1301, CANopen FD): the command specifiers and frame layouts as data, in one place.

The universal SDO replaces the SDO on a CANopen FD network: the same COB-IDs
(0x600 + node for what a client sends, 0x580 + node for what a server sends) in
CAN FD frames of up to 64 bytes. Unlike the SDO, the COB-ID's node-ID is the
*sender* (source address) and byte 0 names the receiver (destination address:
a node-ID, or 0 for every server: broadcast), so one client can talk to every
server on its own COB-ID; byte 2 (session ID) tells a client's transfers apart.

References (third-party, cited; read, not copied; go-canopen and CANopenNode
implement only the classic SDO):
  * Embedded Systems Academy's USDO codec, github.com/em-sa/SOFA-CANopenFD
    (Apache-2.0), `variants/canopen_fd/common/fbsec_co_fd_usdo.{h,c}` V3.1 of
    2026-07-20 and `shared/fbsec_abort.h`, which cite CiA 1301 v1.1 Tables 22,
    31 and 32: the byte layouts of the expedited, segmented and abort frames
    (sub-index in byte 3, the index in bytes 4-5, byte-aligned as CiA's USDO page
    says; segments with their counter in byte 3 and 60 data bytes from byte 4;
    the last segment with its byte count in byte 3), the abort frame (7Fh, its
    one-byte code in byte 6) and the codes 15h and 21h. tests/data/usdo_emsa.log
    holds frames that codec encoded;
  * emtas/emotas' CANopen FD stack header `ico_usdo.h` ($Id: ico_usdo.h 16986
    2017-02-27; public code index file ids 44359093029 and 35776154010): every
    command specifier value, the remote (routed) variants, and the other one-byte
    abort codes.

Neither spells out the bulk frames (emotas lists their command specifiers only):
their layouts follow the segmented ones and are marked `assumed`, so a reader
knows which rows a copy of CiA 1301 should confirm, and a correction is an edit
of this table only (the decoder and the simulator both read it).
"""

from __future__ import annotations

from dataclasses import dataclass

# The COB-ID bases (CiA 1301 keeps CiA 301's predefined connection set for the USDO).
CLIENT_BASE = 0x600  # + the client's node-ID: what a client sends
SERVER_BASE = 0x580  # + the server's node-ID: what a server sends
BROADCAST = 0  # destination address: every server
HEAD = 3  # destination address, command specifier, session ID
MAX_FRAME = 64
EXPEDITED_MAX = MAX_FRAME - 8  # 56 data bytes in one expedited frame (data from byte 8)
SEGMENT_MAX = MAX_FRAME - 4  # 60 data bytes in one segment (data from byte 4)
REMOTE = 0x80  # bit 7 of the command specifier: the remote (routed) variant


@dataclass(frozen=True)
class Command:
    """What one command specifier means.

    `sender`: "client" or "server"; `direction`: the transfer it belongs to
    (download = write, upload = read); `protocol`: expedited / segmented / bulk;
    `step`: init, segment (more follow), last, or abort; `layout`: the key of the
    frame's fields in LAYOUTS.
    """

    name: str
    sender: str
    direction: str | None
    protocol: str | None
    step: str
    layout: str
    assumed: bool = False  # the byte layout is inferred (see the module text)


# Command specifier (byte 1) -> its meaning. The local values; a remote (routed)
# frame sets bit 7 (REMOTE) and is named, not reassembled (its routing head is
# not in the references).
COMMANDS: dict[int, Command] = {
    0x01: Command("download expedited request", "client", "download", "expedited", "init", "expedited"),
    0x21: Command("download expedited response", "server", "download", "expedited", "last", "mux"),
    0x11: Command("upload request", "client", "upload", None, "init", "mux"),
    0x31: Command("upload expedited response", "server", "upload", "expedited", "last", "expedited"),
    0x02: Command("download segmented initiate", "client", "download", "segmented", "init", "initiate"),
    0x03: Command("download segment", "client", "download", "segmented", "segment", "segment"),
    0x04: Command("download last segment", "client", "download", "segmented", "last", "last"),
    0x22: Command("download segmented initiate response", "server", "download", "segmented", "ack", "mux"),
    0x23: Command("download segment response", "server", "download", "segmented", "ack", "counter"),
    0x24: Command("download last segment response", "server", "download", "segmented", "end", "head"),
    0x32: Command("upload segmented initiate response", "server", "upload", "segmented", "init", "initiate"),
    0x13: Command("upload segment request", "client", "upload", "segmented", "ack", "counter"),
    0x33: Command("upload segment", "server", "upload", "segmented", "segment", "segment"),
    0x34: Command("upload last segment", "server", "upload", "segmented", "last", "last"),
    0x06: Command("download bulk initiate", "client", "download", "bulk", "init", "initiate", True),
    0x07: Command("download bulk segment", "client", "download", "bulk", "segment", "segment", True),
    0x08: Command("download bulk last segment", "client", "download", "bulk", "last", "last", True),
    0x26: Command("download bulk initiate response", "server", "download", "bulk", "ack", "mux", True),
    0x28: Command("download bulk last response", "server", "download", "bulk", "end", "head", True),
    0x7F: Command("abort", "either", None, None, "abort", "abort"),
}  # fmt: skip
ABORT = 0x7F
ABORT_REMOTE = 0xFF

# Frame layouts: field -> (offset, size in bytes), little-endian unsigned. Every
# layout starts with HEAD. The multiplexer is the sub-index then the index, so the
# index sits on an even offset (CiA 1301 "considered the byte-alignment").
_HEAD = {"destination": (0, 1), "command": (1, 1), "session": (2, 1)}
_MUX = {"subindex": (3, 1), "index": (4, 2)}
LAYOUTS: dict[str, dict[str, tuple[int, int]]] = {
    "head": _HEAD,  # the last segment's answer: 3 bytes
    "mux": _HEAD | _MUX,  # names the object, carries nothing else (6 bytes)
    "expedited": _HEAD | _MUX | {"datatype": (6, 1), "size": (7, 1)},  # + data
    "initiate": _HEAD | _MUX | {"datatype": (6, 1), "total": (8, 4)},  # byte 7 reserved
    "segment": _HEAD | {"counter": (3, 1)},  # + data: the rest of the frame
    "last": _HEAD | {"size": (3, 1)},  # + data: `size` bytes
    "counter": _HEAD | {"counter": (3, 1)},  # a segment's answer, or an upload's ask
    "abort": _HEAD | _MUX | {"abort_code": (6, 1)},  # 7 bytes
}
# Where a data-carrying layout's data starts, and the field that gives its size
# (None: the data runs to the end of the frame, a full segment).
DATA: dict[str, tuple[int, str | None]] = {
    "expedited": (8, "size"),
    "segment": (4, None),
    "last": (4, "size"),
}

# One-byte USDO abort codes and their text (the values of `ico_usdo.h`'s USDO_ABORT_T;
# the texts CiA 1301's meaning of each, in this project's words).
ABORT_CODES: dict[int, str] = {
    0x10: "Unknown error",
    0x11: "USDO protocol error",
    0x12: "USDO time-out",
    0x13: "Unknown command specifier",
    0x14: "Invalid value in the counter byte (segmented protocol)",
    0x15: "Incorrect data size (segmented transfer)",  # CiA 1301 v1.1 (emotas' 2017 draft: CRC error)
    0x16: "Out of memory",
    0x17: "General parameter incompatibility",
    0x18: "General internal incompatibility in the device",
    0x19: "USDO routing error",
    0x1A: "Destination network unknown",
    0x1B: "Destination node unknown",
    0x1C: "Source network unknown",
    0x1D: "Source node unknown",
    0x1E: "Unexpected CAN DLC",
    0x1F: "Unexpected multiplexer",
    0x21: "USDO session ID wrong or unknown",  # CiA 1301 v1.1 (EmSA's fbsec_abort.h)
    0x30: "Unsupported access to an object",
    0x31: "Attempt to read a write-only object",
    0x32: "Attempt to write a read-only object",
    0x33: "Object does not exist in the object dictionary",
    0x34: "Sub-index does not exist",
    0x35: "Access failed due to a hardware error",
    0x36: "Data type does not match, length of service parameter does not match",
    0x37: "Data type does not match, length of service parameter too high",
    0x38: "Data type does not match, length of service parameter too low",
    0x40: "Invalid value for parameter (download only)",
    0x41: "Value of parameter written too high (download only)",
    0x42: "Value of parameter written too low (download only)",
    0x43: "Maximum value is less than minimum value",
    0x44: "Minimum value is higher than maximum value",
    0x45: "CAN-ID and CAN frame format are read-only",
    0x50: "Object cannot be mapped to the PDO",
    0x51: "The number and length of the objects to be mapped would exceed the PDO length",
    0x52: "Attempt to map a non-mappable parameter to a PDO",
    0x53: "Attempt to map a parameter of access type RPDO to a TPDO",
    0x54: "Attempt to map a parameter of access type TPDO to an RPDO",
    0x55: "Attempt to write PDO parameters while the PDO is valid",
    0x56: "Attempt to write PDO mapping parameters while the mapping is valid",
    0x60: "Data cannot be transferred or stored to the application",
    0x61: "Data cannot be transferred or stored to the application because of local control",
    0x62: "Data cannot be transferred or stored to the application because of the device state",
    0x63: "Object dictionary dynamic generation fails or no object dictionary is present",
    0x64: "No data available",
    0x70: "USDO server busy",
}


def abort_text(code: int) -> str:
    return ABORT_CODES.get(code, f"Unknown USDO abort code 0x{code:02X}")


def command_of(cs: int) -> Command | None:
    """The meaning of command specifier `cs`, remote (bit 7) variants by their local one."""
    return COMMANDS.get(cs & ~REMOTE & 0xFF)


def parse(data: bytes) -> dict | None:
    """The fields of one USDO frame (LAYOUTS by its command specifier), `data` as bytes
    when it carries some; None when the frame is too short for its layout or its
    command specifier is unknown. `remote` when bit 7 is set (routed: only the head)."""
    if len(data) < HEAD:
        return None
    cs = data[1]
    cmd = command_of(cs)
    if cmd is None:
        return None
    remote = bool(cs & REMOTE)
    out: dict = {"cmd": cmd, "remote": remote}
    layout = _HEAD if remote else LAYOUTS[cmd.layout]
    if len(data) < _end(layout):
        return None
    for name, (o, s) in layout.items():
        out[name] = int.from_bytes(data[o : o + s], "little")
    if not remote and cmd.layout in DATA:
        at, size_field = DATA[cmd.layout]
        end = len(data) if size_field is None else at + out[size_field]
        if end > len(data):
            return None
        out["data"] = bytes(data[at:end])
    return out


def _end(layout: dict[str, tuple[int, int]]) -> int:
    return max(o + s for o, s in layout.values())


def fd_length(n: int) -> int:
    """The CAN FD frame length that holds `n` bytes: `n` itself up to 8, else 12, 16,
    20, 24, 32, 48 or 64 (a sender pads the rest with zeros)."""
    for size in (8, 12, 16, 20, 24, 32, 48, 64):
        if n <= size:
            return n if size == 8 else size
    raise ValueError(f"{n} bytes do not fit a CAN FD frame")


def encode(cs: int, destination: int, session: int, **fields) -> bytes:
    """One USDO frame: the layout of `cs` filled from `fields` (`data`: the data bytes,
    its size field taken from it), padded with zeros to the CAN FD length that holds it."""
    cmd = command_of(cs)
    if cmd is None:
        raise ValueError(f"unknown USDO command specifier 0x{cs:02X}")
    layout = LAYOUTS[cmd.layout]
    data = bytes(fields.pop("data", b""))
    end = _end(layout)
    if cmd.layout in DATA:
        at, size_field = DATA[cmd.layout]
        if size_field is not None:
            fields[size_field] = len(data)
        end = at + len(data)
    values = {"destination": destination, "command": cs, "session": session} | fields
    buf = bytearray(fd_length(end))
    for name, (o, s) in layout.items():
        buf[o : o + s] = int(values.get(name, 0)).to_bytes(s, "little")
    if cmd.layout in DATA:
        buf[DATA[cmd.layout][0] : end] = data
    return bytes(buf)


def object_text(index: int, subindex: int) -> str:
    return f"0x{index:04X}:{subindex:02X}"


def fields(data: bytes) -> dict:
    """The JSONL fields of one USDO frame (stable names, docs/outputs.md): `usdo_cs`,
    `command`, `destination`, `session`, and what its layout holds (`index`,
    `subindex`, `datatype`, `size`, `total`, `counter`, `abort_code`, `usdo_data`)."""
    f = parse(data)
    if f is None:
        cs = data[1] if len(data) > 1 else None
        return {"usdo_cs": cs, "command": "invalid", "usdo_problem": _invalid(data)}
    cmd = f.pop("cmd")
    out: dict = {"usdo_cs": f.pop("command"), "command": cmd.name.replace(" ", "_")}
    if f.pop("remote"):
        out["remote"] = True
    payload = f.pop("data", None)
    out |= f
    if "abort_code" in out:
        out["abort_text"] = abort_text(out["abort_code"])
    if payload is not None:
        out["usdo_data"] = payload.hex()
    return out


def _invalid(data: bytes) -> str:
    if len(data) < HEAD:
        return f"frame with {len(data)} data bytes (at least {HEAD})"
    if command_of(data[1]) is None:
        return f"unknown command specifier 0x{data[1]:02X}"
    return f"{COMMANDS[data[1] & 0x7F].name} frame too short ({len(data)} bytes)"


def annotation(f: dict) -> str:
    """The text after a USDO frame in `decode` output (the tracker's role, when it gave one)."""
    if f.get("role"):
        return "USDO " + f["role"]
    if f.get("command") == "invalid":
        return "USDO " + f.get("usdo_problem", "invalid frame")
    text = "USDO " + f["command"].replace("_", " ")
    if "index" in f:
        text += " " + object_text(f["index"], f["subindex"])
    if "abort_code" in f:
        text += f": 0x{f['abort_code']:02X} {f['abort_text']}"
    elif "usdo_data" in f:
        text += " = " + f["usdo_data"][:32] + ("…" if len(f["usdo_data"]) > 32 else "")
    return text
