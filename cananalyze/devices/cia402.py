"""CiA 402 (drives and motion control) as tables: objects, default PDOs, the state machine.

The statusword's state is a lookup of its low seven bits (`STATE_OF`), a controlword's
command a lookup of bits 0-3 and 7 (`COMMAND_OF`): numpy indexes these tables with whole
columns, so naming a million statuswords is one fancy-indexing step. The masks and the
transition table follow CiA 402-2 (figure "state machine", transitions 0-16), as
python-canopen's `canopen.profiles.p402.State402` writes them (the tests compare).
"""

from __future__ import annotations

import numpy as np

from cananalyze.protocol.pdo import fields_text

STATUSWORD, CONTROLWORD = 0x6041, 0x6040
MODES, MODES_DISPLAY = 0x6060, 0x6061
U8, U16, U32, I8, I16, I32 = 0x05, 0x06, 0x07, 0x02, 0x03, 0x04

# --- objects: (index, subindex) -> (name, data type, unit) -------------------------------
# Names in the EDS ParameterName style, as an EDS of a drive gives them (SDO texts name the
# object by it); the signal of a mapped object is `profile.signal_name` of it, as for an
# EDS ("Modes of operation display" -> modes_of_operation_display).
# Units are CiA 402's defaults: positions in increments, velocities in increments per
# second, torques and currents in per mille of the motor's rated value (0x6076 / 0x6075).
OBJECTS: dict[tuple[int, int], tuple[str, int, str | None]] = {
    (0x603F, 0): ("Error code", U16, None),
    (0x6040, 0): ("Controlword", U16, None),
    (0x6041, 0): ("Statusword", U16, None),
    (0x6042, 0): ("vl target velocity", I16, "rpm"),
    (0x6043, 0): ("vl velocity demand", I16, "rpm"),
    (0x6044, 0): ("vl velocity actual value", I16, "rpm"),
    (0x605A, 0): ("Quick stop option code", I16, None),
    (0x605B, 0): ("Shutdown option code", I16, None),
    (0x605C, 0): ("Disable operation option code", I16, None),
    (0x605D, 0): ("Halt option code", I16, None),
    (0x605E, 0): ("Fault reaction option code", I16, None),
    (0x6060, 0): ("Modes of operation", I8, None),
    (0x6061, 0): ("Modes of operation display", I8, None),
    (0x6062, 0): ("Position demand value", I32, "inc"),
    (0x6063, 0): ("Position actual internal value", I32, "inc"),
    (0x6064, 0): ("Position actual value", I32, "inc"),
    (0x6065, 0): ("Following error window", U32, "inc"),
    (0x6066, 0): ("Following error time out", U16, "ms"),
    (0x6067, 0): ("Position window", U32, "inc"),
    (0x6068, 0): ("Position window time", U16, "ms"),
    (0x606B, 0): ("Velocity demand value", I32, "inc/s"),
    (0x606C, 0): ("Velocity actual value", I32, "inc/s"),
    (0x606D, 0): ("Velocity window", U16, "inc/s"),
    (0x606E, 0): ("Velocity window time", U16, "ms"),
    (0x6071, 0): ("Target torque", I16, "‰ rated torque"),
    (0x6072, 0): ("Max torque", U16, "‰ rated torque"),
    (0x6073, 0): ("Max current", U16, "‰ rated current"),
    (0x6074, 0): ("Torque demand", I16, "‰ rated torque"),
    (0x6075, 0): ("Motor rated current", U32, "mA"),
    (0x6076, 0): ("Motor rated torque", U32, "mNm"),
    (0x6077, 0): ("Torque actual value", I16, "‰ rated torque"),
    (0x6078, 0): ("Current actual value", I16, "‰ rated current"),
    (0x6079, 0): ("DC link circuit voltage", U32, "mV"),
    (0x607A, 0): ("Target position", I32, "inc"),
    (0x607C, 0): ("Home offset", I32, "inc"),
    (0x607D, 1): ("Min position limit", I32, "inc"),
    (0x607D, 2): ("Max position limit", I32, "inc"),
    (0x607E, 0): ("Polarity", U8, None),
    (0x607F, 0): ("Max profile velocity", U32, "inc/s"),
    (0x6080, 0): ("Max motor speed", U32, "rpm"),
    (0x6081, 0): ("Profile velocity", U32, "inc/s"),
    (0x6082, 0): ("End velocity", U32, "inc/s"),
    (0x6083, 0): ("Profile acceleration", U32, "inc/s²"),
    (0x6084, 0): ("Profile deceleration", U32, "inc/s²"),
    (0x6085, 0): ("Quick stop deceleration", U32, "inc/s²"),
    (0x6086, 0): ("Motion profile type", I16, None),
    (0x6098, 0): ("Homing method", I8, None),
    (0x6099, 1): ("Homing speed switch", U32, "inc/s"),
    (0x6099, 2): ("Homing speed zero", U32, "inc/s"),
    (0x609A, 0): ("Homing acceleration", U32, "inc/s²"),
    (0x60B0, 0): ("Position offset", I32, "inc"),
    (0x60B1, 0): ("Velocity offset", I32, "inc/s"),
    (0x60B2, 0): ("Torque offset", I16, "‰ rated torque"),
    (0x60C1, 1): ("Interpolation data record", I32, "inc"),
    (0x60C2, 1): ("Interpolation time period value", U8, None),
    (0x60C2, 2): ("Interpolation time index", I8, None),
    (0x60F4, 0): ("Following error actual value", I32, "inc"),
    (0x60FD, 0): ("Digital inputs", U32, None),
    (0x60FE, 1): ("Digital outputs", U32, None),
    (0x60FF, 0): ("Target velocity", I32, "inc/s"),
    (0x6502, 0): ("Supported drive modes", U32, None),
}

# --- default PDOs (CiA 402-3, "predefined PDO mapping") ---------------------------------
# (direction, number) -> mapped objects; COB-IDs are CiA 301's predefined connection set.
DEFAULT_PDOS: dict[tuple[str, int], tuple[tuple[int, int], ...]] = {
    ("rx", 1): ((0x6040, 0),),
    ("rx", 2): ((0x6040, 0), (0x6060, 0)),
    ("rx", 3): ((0x6040, 0), (0x607A, 0)),
    ("rx", 4): ((0x6040, 0), (0x60FF, 0)),
    ("tx", 1): ((0x6041, 0),),
    ("tx", 2): ((0x6041, 0), (0x6061, 0)),
    ("tx", 3): ((0x6041, 0), (0x6064, 0)),
    ("tx", 4): ((0x6041, 0), (0x606C, 0)),
}

# --- the state machine ---------------------------------------------------------------------
STATES = (
    "not ready to switch on",
    "switch on disabled",
    "ready to switch on",
    "switched on",
    "operation enabled",
    "quick stop active",
    "fault reaction active",
    "fault",
)
(
    NOT_READY,
    SWITCH_ON_DISABLED,
    READY,
    SWITCHED_ON,
    OPERATION_ENABLED,
    QUICK_STOP,
    FAULT_REACTION,
    FAULT,
) = range(8)
UNKNOWN_STATE = 8  # a statusword no state's mask matches
STATE_NAMES = (*STATES, "unknown state")

# statusword & mask == value, CiA 402-2 table "state coding"
STATE_MASKS: tuple[tuple[int, int, int], ...] = (
    (NOT_READY, 0x4F, 0x00),
    (SWITCH_ON_DISABLED, 0x4F, 0x40),
    (READY, 0x6F, 0x21),
    (SWITCHED_ON, 0x6F, 0x23),
    (OPERATION_ENABLED, 0x6F, 0x27),
    (QUICK_STOP, 0x6F, 0x07),
    (FAULT_REACTION, 0x4F, 0x0F),
    (FAULT, 0x4F, 0x08),
)

# statusword flag bits (bit, name); bits 12 and 13 are mode specific (their profile
# position / cyclic position names, the ones a log reader meets most)
STATUS_FLAGS: tuple[tuple[int, str], ...] = (
    (4, "voltage enabled"),
    (7, "warning"),
    (9, "remote"),
    (10, "target reached"),
    (11, "internal limit active"),
    (12, "set-point acknowledge"),
    (13, "following error"),
)

# controlword commands: (command, mask, value) over bits 0-3 and 7; CiA 402-2 table
# "command coding". Bit 7's rising edge is the fault reset; 0x07 is "switch on" in
# switched on / ready to switch on and "disable operation" from operation enabled.
COMMANDS = (
    "shutdown",
    "switch on",
    "disable voltage",
    "quick stop",
    "disable operation",
    "enable operation",
    "fault reset",
)
(
    SHUTDOWN,
    SWITCH_ON,
    DISABLE_VOLTAGE,
    QUICK_STOP_CMD,
    DISABLE_OPERATION,
    ENABLE_OPERATION,
    FAULT_RESET,
) = range(7)
NO_COMMAND = 7
COMMAND_NAMES = (*COMMANDS, "no command")
COMMAND_MASKS: tuple[tuple[int, int, int], ...] = (
    (FAULT_RESET, 0x80, 0x80),
    (SHUTDOWN, 0x87, 0x06),
    (SWITCH_ON, 0x8F, 0x07),
    (ENABLE_OPERATION, 0x8F, 0x0F),
    (DISABLE_VOLTAGE, 0x82, 0x00),
    (QUICK_STOP_CMD, 0x86, 0x02),
)
CONTROL_FLAGS: tuple[tuple[int, str], ...] = (
    (0, "switch on"),
    (1, "enable voltage"),
    (2, "quick stop off"),
    (3, "enable operation"),
    (4, "new set-point"),
    (5, "change set immediately"),
    (6, "relative"),
    (7, "fault reset"),
    (8, "halt"),
    (9, "change on set-point"),
)

# Transitions CiA 402-2 allows: (from, to) -> transition number. 13 (fault detected) goes
# from every state to fault reaction active; 0 is power-on.
TRANSITIONS: dict[tuple[int, int], int] = {
    (NOT_READY, SWITCH_ON_DISABLED): 1,
    (SWITCH_ON_DISABLED, READY): 2,
    (READY, SWITCHED_ON): 3,
    (SWITCHED_ON, OPERATION_ENABLED): 4,
    (OPERATION_ENABLED, SWITCHED_ON): 5,
    (SWITCHED_ON, READY): 6,
    (READY, SWITCH_ON_DISABLED): 7,
    (OPERATION_ENABLED, READY): 8,
    (OPERATION_ENABLED, SWITCH_ON_DISABLED): 9,
    (SWITCHED_ON, SWITCH_ON_DISABLED): 10,
    (OPERATION_ENABLED, QUICK_STOP): 11,
    (QUICK_STOP, SWITCH_ON_DISABLED): 12,
    (FAULT_REACTION, FAULT): 14,
    (FAULT, SWITCH_ON_DISABLED): 15,
    (QUICK_STOP, OPERATION_ENABLED): 16,
}
for _s in range(8):
    if _s != FAULT_REACTION:
        TRANSITIONS[(_s, FAULT_REACTION)] = 13

# Which state a command leads to from a state (the transition it asks for); a command
# not listed for a state is not one the drive has to follow there.
COMMAND_TARGET: dict[tuple[int, int], int] = {
    (SHUTDOWN, SWITCH_ON_DISABLED): READY,  # 2
    (SHUTDOWN, SWITCHED_ON): READY,  # 6
    (SHUTDOWN, OPERATION_ENABLED): READY,  # 8
    (SWITCH_ON, READY): SWITCHED_ON,  # 3
    (DISABLE_OPERATION, OPERATION_ENABLED): SWITCHED_ON,  # 5
    (ENABLE_OPERATION, SWITCHED_ON): OPERATION_ENABLED,  # 4
    (ENABLE_OPERATION, QUICK_STOP): OPERATION_ENABLED,  # 16
    (DISABLE_VOLTAGE, READY): SWITCH_ON_DISABLED,  # 7
    (DISABLE_VOLTAGE, SWITCHED_ON): SWITCH_ON_DISABLED,  # 10
    (DISABLE_VOLTAGE, OPERATION_ENABLED): SWITCH_ON_DISABLED,  # 9
    (DISABLE_VOLTAGE, QUICK_STOP): SWITCH_ON_DISABLED,  # 12
    (QUICK_STOP_CMD, OPERATION_ENABLED): QUICK_STOP,  # 11
    (QUICK_STOP_CMD, READY): SWITCH_ON_DISABLED,  # 7
    (QUICK_STOP_CMD, SWITCHED_ON): SWITCH_ON_DISABLED,  # 10
    (FAULT_RESET, FAULT): SWITCH_ON_DISABLED,  # 15
}

# modes of operation (0x6060 / 0x6061), CiA 402-2; negative values are the manufacturer's
MODES_OF_OPERATION: dict[int, str] = {
    0: "no mode",
    1: "profile position",
    2: "velocity",
    3: "profile velocity",
    4: "profile torque",
    6: "homing",
    7: "interpolated position",
    8: "cyclic synchronous position",
    9: "cyclic synchronous velocity",
    10: "cyclic synchronous torque",
}


def _table(masks: tuple[tuple[int, int, int], ...], size: int, none: int) -> np.ndarray:
    """Code per value of the masked bits; the first matching row wins."""
    out = np.full(size, none, np.uint8)
    for v in range(size):
        for code, mask, value in masks:
            if v & mask == value:
                out[v] = code
                break
    return out


STATE_OF = _table(STATE_MASKS, 0x80, UNKNOWN_STATE)  # index: statusword & 0x7F
COMMAND_OF = _table(COMMAND_MASKS, 0x100, NO_COMMAND)  # index: controlword & 0xFF


def state_codes(statusword: np.ndarray) -> np.ndarray:
    """State code (index into STATE_NAMES) of each statusword: one table lookup."""
    return STATE_OF[np.asarray(statusword).astype(np.int64) & 0x7F]


def command_codes(controlword: np.ndarray) -> np.ndarray:
    """Command code (index into COMMAND_NAMES) of each controlword: one table lookup."""
    return COMMAND_OF[np.asarray(controlword).astype(np.int64) & 0xFF]


def _flags(word: int, table: tuple[tuple[int, str], ...]) -> list[str]:
    return [name for bit, name in table if word >> bit & 1]


def statusword_fields(word: int) -> dict:
    """{"state": "operation enabled", "flags": ["voltage enabled", "remote", ...]}."""
    word = int(word)
    return {"state": STATE_NAMES[int(STATE_OF[word & 0x7F])], "flags": _flags(word, STATUS_FLAGS)}


def statusword_text(word: int) -> str:
    """ "operation enabled; voltage enabled, remote, target reached" for 0x0637."""
    return fields_text(statusword_fields(word))


def command_name(word: int, state: int | None = None) -> str:
    """The command of a controlword; 0x07 from operation enabled is "disable operation"."""
    code = int(COMMAND_OF[int(word) & 0xFF])
    if code == SWITCH_ON and state == OPERATION_ENABLED:
        code = DISABLE_OPERATION
    return COMMAND_NAMES[code]


def controlword_fields(word: int) -> dict:
    """{"command": "enable operation", "flags": ["switch on", "enable voltage", ...]}."""
    word = int(word)
    name = command_name(word)
    if name == "switch on":
        name = "switch on / disable operation"
    return {"command": name, "flags": _flags(word, CONTROL_FLAGS)}


def controlword_text(word: int) -> str:
    """ "enable operation; switch on, enable voltage, quick stop off, enable operation"."""
    return fields_text(controlword_fields(word))


def mode_fields(value: int) -> dict:
    """{"mode": "profile position"} (0x6060, 0x6061)."""
    value = int(value)
    if value < 0:
        return {"mode": f"manufacturer-specific mode {value}"}
    return {"mode": MODES_OF_OPERATION.get(value, f"reserved mode {value}")}


def mode_text(value: int) -> str:
    return fields_text(mode_fields(value))


def value_tables() -> dict[int, dict[int, str]]:
    """Value tables a DBC can carry (`export --dbc`, `devices --dbc`): the modes by name,
    and each controlword command at the word it is sent as (its mask's value: a DBC
    table names exact values). The statusword has none: its states are bit patterns
    with free flag bits beside them, which an exact-value table cannot express."""
    commands = {value: command_name(value) for _, _, value in COMMAND_MASKS}
    commands[0x07] = "switch on / disable operation"  # which one depends on the state
    return {MODES: dict(MODES_OF_OPERATION), MODES_DISPLAY: dict(MODES_OF_OPERATION),
            CONTROLWORD: dict(sorted(commands.items()))}  # fmt: skip


# a value as data (JSONL's "drive" field) and in words (SDO reads and writes, signal text)
FIELDS = {
    STATUSWORD: statusword_fields,
    CONTROLWORD: controlword_fields,
    MODES: mode_fields,
    MODES_DISPLAY: mode_fields,
}
WORDS = {
    STATUSWORD: statusword_text,
    CONTROLWORD: controlword_text,
    MODES: mode_text,
    MODES_DISPLAY: mode_text,
}
