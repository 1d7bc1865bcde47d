"""NMT (CiA 301 7.2.8): module control commands and the states error control reports.

One home for the command specifiers (byte 0 of COB-ID 0x000), the state bytes
of heartbeat, boot-up and node guarding (7 low bits; the guard reply's bit 7
is the toggle), their names (the JSONL `command` / `state` values, a stable
API), what each command does to a node's state, and the text of each frame.
"""

from __future__ import annotations

# Module control command specifiers
START = 0x01
STOP = 0x02
ENTER_PRE_OPERATIONAL = 0x80
RESET_NODE = 0x81
RESET_COMMUNICATION = 0x82

COMMANDS: dict[int, str] = {
    START: "start",
    STOP: "stop",
    ENTER_PRE_OPERATIONAL: "enter pre-operational",
    RESET_NODE: "reset node",
    RESET_COMMUNICATION: "reset communication",
}
ALL_NODES = 0  # the target node-ID that addresses every node

# States as heartbeat and guarding report them; a boot-up frame is the 0x00 byte
BOOTUP = 0x00
STOPPED = 0x04
OPERATIONAL = 0x05
PRE_OPERATIONAL = 0x7F
STATE_MASK = 0x7F  # the state bits of an error-control byte
TOGGLE_BIT = 0x80  # bit 7 of a guard response: alternates from one reply to the next

STATES: dict[int, str] = {
    BOOTUP: "bootup",
    STOPPED: "stopped",
    OPERATIONAL: "operational",
    PRE_OPERATIONAL: "pre-operational",
}

# The state a command puts its targets in (a reset ends in a boot-up)
COMMAND_STATE: dict[int, int] = {
    START: OPERATIONAL,
    STOP: STOPPED,
    ENTER_PRE_OPERATIONAL: PRE_OPERATIONAL,
    RESET_NODE: BOOTUP,
    RESET_COMMUNICATION: BOOTUP,
}

MALFORMED = "malformed: needs 2 bytes"  # a module control frame shorter than CiA 301's 2
BOOTUP_TEXT = "boot-up"  # what a boot-up frame (and the node after it) is called in text
GUARD_REQUEST_TEXT = "node guarding request (RTR)"
ERRCTL_BYTES = 1  # CiA 301: heartbeat, boot-up and guard response carry exactly this many


def errctl_malformed(n_bytes: int) -> str:
    """Why a data frame on an error-control COB-ID of another length is none of them."""
    return f"malformed: {n_bytes} data bytes, CiA 301 says {ERRCTL_BYTES}"


def command_name(cs: int) -> str:
    return COMMANDS.get(cs, f"unknown 0x{cs:02X}")


def state_name(byte: int) -> str:
    """Name of the state in an error-control byte (the toggle bit ignored)."""
    code = byte & STATE_MASK
    return STATES.get(code, f"unknown 0x{code:02X}")


def toggle_of(byte: int) -> int:
    """The toggle bit (0 or 1) of a guard response byte."""
    return int(bool(byte & TOGGLE_BIT))


def command_fields(data: bytes) -> dict:
    """JSONL fields of a module control frame: `command`, `target`; `problem` when short."""
    if len(data) < 2:
        return {"command": None, "target": None, "problem": MALFORMED}
    return {"command": command_name(data[0]), "target": data[1]}


def command_text(fields: dict) -> str:
    target = fields.get("target")
    if target is None:
        return f"NMT ({fields.get('problem', MALFORMED)})"
    command = fields.get("command")
    if target == ALL_NODES:
        return f"NMT {command} all nodes"
    if command == "reset node":  # not "reset node node 32"
        return f"NMT reset node {target}"
    return f"NMT {command} node {target}"


def state_fields(data: bytes, guard: bool = False) -> dict:
    """JSONL fields of a heartbeat, boot-up or (`guard`) guard response: `state`, `toggle`."""
    if not data:
        return {"state": None}
    out: dict = {"state": state_name(data[0])}
    if guard:
        out["toggle"] = toggle_of(data[0])
    return out


def errctl_invalid_fields(data: bytes) -> dict:
    """JSONL fields of such a frame: no `state` (it reports none), the `problem`."""
    return {"problem": errctl_malformed(len(data))}


def errctl_invalid_text(fields: dict) -> str:
    return f"error control ({fields.get('problem')})"


def heartbeat_text(fields: dict) -> str:
    return f"heartbeat {fields.get('state') or '(empty)'}"


def guard_response_text(fields: dict) -> str:
    return f"node guarding response {fields.get('state')} toggle {fields.get('toggle')}"
