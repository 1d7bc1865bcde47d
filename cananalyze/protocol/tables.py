"""CiA 301 value tables in one place (as Wireshark's packet-canopen.c keeps them).

Plain dicts, no logic: abort codes, EMCY error classes, error-register bits,
NMT commands and states, LSS command specifiers.
"""

from __future__ import annotations

# CiA 301 table 22: SDO abort codes.
SDO_ABORT: dict[int, str] = {
    0x05030000: "Toggle bit not alternated",
    0x05040000: "SDO protocol timed out",
    0x05040001: "Client/server command specifier not valid or unknown",
    0x05040002: "Invalid block size (block mode only)",
    0x05040003: "Invalid sequence number (block mode only)",
    0x05040004: "CRC error (block mode only)",
    0x05040005: "Out of memory",
    0x06010000: "Unsupported access to an object",
    0x06010001: "Attempt to read a write only object",
    0x06010002: "Attempt to write a read only object",
    0x06020000: "Object does not exist in the object dictionary",
    0x06040041: "Object cannot be mapped to the PDO",
    0x06040042: "The number and length of the objects to be mapped would exceed PDO length",
    0x06040043: "General parameter incompatibility reason",
    0x06040047: "General internal incompatibility in the device",
    0x06060000: "Access failed due to a hardware error",
    0x06070010: "Data type does not match, length of service parameter does not match",
    0x06070012: "Data type does not match, length of service parameter too high",
    0x06070013: "Data type does not match, length of service parameter too low",
    0x06090011: "Sub-index does not exist",
    0x06090030: "Invalid value for parameter (download only)",
    0x06090031: "Value of parameter written too high (download only)",
    0x06090032: "Value of parameter written too low (download only)",
    0x06090036: "Maximum value is less than minimum value",
    0x060A0023: "Resource not available: SDO connection",
    0x08000000: "General error",
    0x08000020: "Data cannot be transferred or stored to the application",
    0x08000021: "Data cannot be transferred or stored to the application because of local control",
    0x08000022: "Data cannot be transferred or stored to the application because of the present device state",
    0x08000023: "Object dictionary dynamic generation fails or no object dictionary is present",
    0x08000024: "No data available",
}


def abort_text(code: int) -> str:
    return SDO_ABORT.get(code, f"Unknown abort code 0x{code:08X}")


# CiA 301 table 21: emergency error code classes, matched on the high byte
# (or high nibble where only the nibble is defined). Longest match wins.
EMCY_CODES: dict[int, str] = {
    0x0000: "Error reset or no error",
    0x1000: "Generic error",
    0x2000: "Current",
    0x2100: "Current, CANopen device input side",
    0x2200: "Current inside the CANopen device",
    0x2300: "Current, CANopen device output side",
    0x3000: "Voltage",
    0x3100: "Mains voltage",
    0x3200: "Voltage inside the CANopen device",
    0x3300: "Output voltage",
    0x4000: "Temperature",
    0x4100: "Ambient temperature",
    0x4200: "Device temperature",
    0x5000: "CANopen device hardware",
    0x6000: "CANopen device software",
    0x6100: "Internal software",
    0x6200: "User software",
    0x6300: "Data set",
    0x7000: "Additional modules",
    0x8000: "Monitoring",
    0x8100: "Communication",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "Life guard error or heartbeat error",
    0x8140: "Recovered from bus off",
    0x8150: "CAN-ID collision",
    0x8200: "Protocol error",
    0x8210: "PDO not processed due to length error",
    0x8220: "PDO length exceeded",
    0x8230: "DAM MPDO not processed, destination object not available",
    0x8240: "Unexpected SYNC data length",
    0x8250: "RPDO timeout",
    0x9000: "External error",
    0xF000: "Additional functions",
    0xFF00: "Device specific",
}


def emcy_class(code: int) -> str:
    """Most specific CiA 301 name for an emergency error code."""
    if code in EMCY_CODES:
        return EMCY_CODES[code]
    for mask in (0xFFF0, 0xFF00, 0xF000):
        name = EMCY_CODES.get(code & mask)
        if name is not None:
            return name
    return "Unknown"


# CiA 301 object 0x1001 error register bits.
ERROR_REGISTER_BITS: dict[int, str] = {
    0: "generic",
    1: "current",
    2: "voltage",
    3: "temperature",
    4: "communication",
    5: "device profile specific",
    6: "reserved",
    7: "manufacturer specific",
}


def error_register_names(reg: int) -> list[str]:
    return [name for bit, name in ERROR_REGISTER_BITS.items() if reg >> bit & 1]


# NMT module control command specifiers.
NMT_COMMANDS: dict[int, str] = {
    0x01: "start",
    0x02: "stop",
    0x80: "enter pre-operational",
    0x81: "reset node",
    0x82: "reset communication",
}

# NMT states as reported in heartbeat / guarding (7 low bits).
NMT_STATES: dict[int, str] = {
    0x00: "bootup",
    0x04: "stopped",
    0x05: "operational",
    0x7F: "pre-operational",
}

# CiA 305 LSS command specifiers.
LSS_COMMANDS: dict[int, str] = {
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
