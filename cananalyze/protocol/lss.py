"""LSS (CiA 305): command specifiers (byte 0 on COB-IDs 0x7E5 / 0x7E4) and their names."""

from __future__ import annotations

COMMANDS: dict[int, str] = {
    0x04: "switch state global",
    0x11: "configure node-ID",
    0x13: "configure bit timing",
    0x15: "activate bit timing",
    0x17: "store configuration",
    0x40: "switch state selective: vendor-ID",
    0x41: "switch state selective: product-code",
    0x42: "switch state selective: revision-number",
    0x43: "switch state selective: serial-number",
    0x44: "switch state selective: response",
    0x46: "identify remote slave: vendor-ID",
    0x47: "identify remote slave: product-code",
    0x48: "identify remote slave: revision-number low",
    0x49: "identify remote slave: revision-number high",
    0x4A: "identify remote slave: serial-number low",
    0x4B: "identify remote slave: serial-number high",
    0x4C: "identify non-configured remote slave",
    0x4F: "identify slave",
    0x50: "identify non-configured slave",
    0x51: "fastscan",
    0x5A: "inquire vendor-ID",
    0x5B: "inquire product-code",
    0x5C: "inquire revision-number",
    0x5D: "inquire serial-number",
    0x5E: "inquire node-ID",
}


MASTER_COB, SLAVE_COB = 0x7E5, 0x7E4  # CiA 305: the LSS master's and the slaves' COB-IDs
CODES: dict[str, int] = {name: cs for cs, name in COMMANDS.items()}
# switch state global modes (byte 1)
WAITING, CONFIGURATION = 0, 1
# the four switch state selective commands, vendor-ID to serial-number, in order
SELECTIVE = tuple(
    CODES[f"switch state selective: {p}"]
    for p in ("vendor-ID", "product-code", "revision-number", "serial-number")
)


def command_name(cs: int) -> str:
    return COMMANDS.get(cs, f"unknown 0x{cs:02X}")


# CiA 305 frames carry 8 bytes, the command specifier first: one with none cannot be read
MALFORMED = "malformed: no command specifier"


def fields(data: bytes) -> dict:
    """JSONL fields of an LSS frame: `command` (null, and `problem`, when empty)."""
    if not data:
        return {"command": None, "problem": MALFORMED}
    return {"command": command_name(data[0])}


def text(fields: dict, master: bool) -> str:
    """The line of an LSS frame; an empty one says what is wrong, not "None"."""
    command = fields.get("command")
    return f"LSS {'master' if master else 'slave'} {command or '(' + MALFORMED + ')'}"
