"""`cananalyze devices [KEY|FILE]`: list built-in device profiles, or show one's PDOs and notes.

`cia402` and `cia401` are the CiA profiles' defaults (cananalyze/devices/cia402.py, cia401.py); a drive's own
EDS/DCF that names CiA 402 is shown with the same state machine summary."""

from __future__ import annotations

import argparse
from pathlib import Path

from cananalyze.cli import options as options_
from cananalyze.core.errors import UsageError


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "devices",
        help="list built-in device profiles, or show one (PDOs, notes)",
        description="Without KEY: list the built-in device profiles and the CiA profiles "
        "(cia402 drives, cia401 I/O). With KEY (or an EDS/DCF/XDD/XDC path): show its default PDOs "
        "for --node and the notes on manual quirks; for a CiA 402 drive also its states, "
        "commands and modes as cananalyze names them. --dbc OUT.dbc writes those PDOs as a "
        "DBC file (cantools) with their scaling, units and signedness. A user's EDS picks up "
        "a TOML sidecar of the same name beside it (units and scales per object: docs/decoding.md, "
        "Your own units).",
    )
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EPILOG
    options_.add(parser, "profile_key", "profile_node", "profile_dbc")
    parser.set_defaults(func=run)
    return parser


EPILOG = """\
your own devices and layouts:
  drive.eds + drive.toml     a TOML sidecar beside your EDS/DCF (format of decoders/*.toml:
                             [[signal]] index, subindex, name, unit, scale, offset, split)
                             is loaded with it: --eds 5=drive.eds, the network file, here
  network file signals       [nodes.5.signals] "6401:01" = {unit = "degC", scale = 0.1}
  devices KEY --dbc OUT.dbc  this device's PDOs at --node as a DBC (cantools)
  export LOG --dbc OUT.dbc   the network's PDOs as configured at the end of a log
  decode LOG --dbc MINE.dbc  frames a DBC names decoded by it (export: --dbc-in), over the
                             profile's PDO layout; non-CANopen identifiers on a mixed bus
  decode CAPTURE.pcapng      Wireshark/tcpdump captures of SocketCAN (link type 227,
                             Linux cooked SLL/SLL2) read like any log
"""


def _hex(value: int | None, width: int = 8) -> str:
    return "-" if value is None else f"0x{value:0{width}X}"


def run(args: argparse.Namespace) -> int:
    from cananalyze.devices.builtin import builtin_profiles, load_builtin
    from cananalyze.devices.catalog import PROFILE_KEYS, device_keys
    from cananalyze.devices.eds import DEVICE_SUFFIXES
    from cananalyze.devices.profile import load_eds

    if not args.key:
        print(f"{'key':<9} {'vendor ID':<11} {'product':<11} {'device type':<11} name")
        for p in builtin_profiles():
            print(
                f"{p.key:<9} {_hex(p.vendor_id):<11} {_hex(p.product_code):<11} "
                f"{_hex(p.device_type):<11} {p.name}"
            )
        for key in PROFILE_KEYS:
            p = load_builtin(key)
            print(f"{p.key:<9} {'-':<11} {'-':<11} {_hex(p.device_type):<11} {p.name}")
        print(
            "A node whose device type (0x1000: read in the log, or in its EDS) names CiA 402 "
            "or 401 gets that profile's defaults when no device of ours matches."
        )
        return 0
    if not 1 <= args.node <= 127:
        raise UsageError(f"--node {args.node}: node ID must be 1..127")
    if args.key in device_keys():
        prof = load_builtin(args.key)
    elif Path(args.key).suffix.lower() in DEVICE_SUFFIXES:
        prof = load_eds(args.key)
    else:
        raise UsageError(f"unknown device {args.key!r}: use one of {', '.join(device_keys())}")
    # the DBC first: printing may end early (`| head` closes the pipe), the file must not
    wrote = _write_dbc(args, prof) if args.dbc else None
    print(f"{prof.key}: {prof.name}")
    print(
        f"  vendor ID {_hex(prof.vendor_id)}  product {_hex(prof.product_code)}  "
        f"device type {_hex(prof.device_type)}  device name {prof.device_name or '-'}"
    )
    print(f"  source {prof.source}")
    print(f"PDOs for node {args.node}:")
    for pdo in prof.pdos(args.node):
        state = "" if pdo.valid else "  (not valid)"
        print(
            f"  {pdo.direction[0].upper()}PDO{pdo.number} COB-ID 0x{pdo.cob_id:03X} "
            f"type {pdo.transmission_type} inhibit {pdo.inhibit_time / 10:g} ms "
            f"event {pdo.event_timer} ms{state}"
        )
        bit = 0
        for e in pdo.mapping:
            unit = f" [{e.unit}]" if e.unit else ""
            scale = f" x{e.scale:g}" if e.scale is not None else ""
            print(
                f"    bit {bit:2d}+{e.bits:<2d} {e.index:04X}:{e.subindex:02X} {e.name}{unit}{scale}"
            )
            bit += e.bits
    if prof.family == 402:
        _cia402_summary()
    if prof.notes:
        print("Notes:")
        for note in prof.notes:
            print(f"  - {note}")
    if wrote is not None:
        print(wrote)
    return 0


def _write_dbc(args, prof) -> str:
    """Write the device's PDOs at --node as a DBC; the line that says so."""
    from cananalyze.core.atomic import check_writable
    from cananalyze.outputs.dbc import pdo_database, write_dbc

    check_writable(args.dbc)
    drives = {args.node} if prof.family == 402 else set()
    db = pdo_database(((args.node, pdo) for pdo in prof.pdos(args.node)), drives)
    write_dbc(args.dbc, db)
    return f"wrote {len(db.messages)} PDOs of node {args.node} to {args.dbc}"


def _cia402_summary() -> None:
    """The CiA 402 words cananalyze uses, from the profile's tables."""
    from cananalyze.devices import cia402

    print("CiA 402 (statusword 0x6041, controlword 0x6040, modes 0x6060/0x6061):")
    print("  states (statusword & mask == value):")
    for code, mask, value in cia402.STATE_MASKS:
        print(f"    {cia402.STATE_NAMES[code]:<24} mask 0x{mask:02X} value 0x{value:02X}")
    flags = ", ".join(f"{name} (bit {bit})" for bit, name in cia402.STATUS_FLAGS)
    print(f"  statusword flags: {flags}")
    print("  commands (controlword & mask == value):")
    for code, mask, value in cia402.COMMAND_MASKS:
        print(f"    {cia402.COMMAND_NAMES[code]:<24} mask 0x{mask:02X} value 0x{value:02X}")
    print("    (0x07 from operation enabled is disable operation)")
    modes = ", ".join(f"{k} {v}" for k, v in cia402.MODES_OF_OPERATION.items())
    print(f"  modes of operation: {modes}")
    print(
        "  checks: drive_transition, drive_fault, drive_command (timeout_ms); "
        "timeline: cap.drive_states, events kind drive_state, /node/N/drive_state"
    )
