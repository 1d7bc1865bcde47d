"""Every command-line flag, declared once: its spelling, default and help.

A sub-command names the flags it takes (`add(parser, "log", "rules", ...)`); it never
declares one itself, so a flag's help and default are the same in every command that
has it (tests/cli/test_cli_options.py checks this by building every parser). Defaults
that are library facts come from the library (`core.defaults`), and the built-in
devices a help text lists are the ones found in `decoders/`.

A few spellings mean something else in one command (`query --json` is an output
format, `devices --node` a node-ID for $NODEID): those are their own entries, named
for their command.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

from cananalyze.core.defaults import COMPACT_TARGET_SIZE, SDO_TIMEOUT, TASK_TIMEOUT

_UNITS = {"": 1, "B": 1, "K": 1 << 10, "KB": 1 << 10, "M": 1 << 20, "MB": 1 << 20}
_UNITS |= {"G": 1 << 30, "GB": 1 << 30}


def byte_size(text: str) -> int:
    """`128MB`, `64M`, `1GB`, `500000`: a size in bytes (binary units, as `du -h`)."""
    t = text.strip().upper().replace("IB", "B")
    number = t.rstrip("KMGB")
    try:
        n = float(number) * _UNITS[t[len(number) :].strip()]
    except (KeyError, ValueError):
        raise argparse.ArgumentTypeError(f"not a size: {text!r} (e.g. 128MB)") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"not a size: {text!r} (must be positive)")
    return int(n)


@dataclass(frozen=True)
class Flag:
    names: tuple[str, ...]  # ("-q", "--quiet"), or ("log",) for a positional
    kwargs: dict = field(default_factory=dict)  # argparse's add_argument keywords


def _devices_help() -> str:
    """--device's help: the devices found in decoders/ (read when the parser is built)."""
    from cananalyze.devices.catalog import PROFILE_KEYS, builtin_keys

    return (
        f"node NODE is this built-in device ({', '.join(builtin_keys())}) or a CiA "
        f"profile's defaults ({', '.join(PROFILE_KEYS)}); repeatable"
    )


def _scenarios_help() -> str:
    """--scenario's help: the simulator's scenarios, by name (sim/scenario_names)."""
    from cananalyze.sim.scenario_names import SCENARIO_NAMES

    return f"what the master does: {', '.join(SCENARIO_NAMES)} (default steady)"


_COMPRESSIONS = ["snappy", "zstd", "lz4", "none"]


def _version() -> str:
    from cananalyze.core.version import __version__
    from cananalyze.runtime import speedups

    return f"cananalyze {__version__} ({speedups.status()})"


FLAGS: dict[str, Flag] = {
    "version": Flag(("--version",), dict(action="version", version=_version)),
    # --- what is read -----------------------------------------------------------
    "log": Flag(
        ("log",),
        dict(help="log file (candump, ASC, BLF, TRC, CSV, pcap/pcapng; .gz too), or - for stdin"),
    ),
    "inputs": Flag(("inputs",), dict(nargs="+", metavar="INPUT", help="log file, folder or glob")),
    "strict": Flag(
        ("--strict",),
        dict(
            action="store_true",
            help="stop at the first unreadable line or record (exit 2) instead of skipping it; "
            "fleet: the log fails",
        ),
    ),
    "input_format": Flag(
        ("--input-format",),
        dict(metavar="NAME", help="force the log format instead of detecting it"),
    ),
    "sdo_timeout": Flag(
        ("--sdo-timeout",),
        dict(
            type=float,
            default=SDO_TIMEOUT,
            metavar="S",
            help=f"an SDO request unanswered this long is a timeout (default {SDO_TIMEOUT:g} s)",
        ),
    ),
    "fd": Flag(
        ("--fd",),
        dict(
            action="store_true",
            help="the network is CANopen FD (CiA 1301): every frame on the SDO COB-IDs is a "
            "USDO one, FD flag or not (FD frames there always are; one node: the network "
            "file's canopen_fd)",
        ),
    ),
    # --- what the user knows about the nodes and the bus -------------------------
    "device": Flag(
        ("--device",),
        dict(action="append", default=[], metavar="NODE=NAME", help=_devices_help),
    ),
    "eds": Flag(
        ("--eds",),
        dict(
            action="append",
            default=[],
            metavar="NODE=FILE",
            help="node NODE is described by this EDS/DCF or XDD/XDC (CiA 311) file; repeatable",
        ),
    ),
    "network": Flag(
        ("--network",),
        dict(
            metavar="FILE",
            help="network file (TOML/YAML, docs/network-file.md): nodes, profiles, PDO/heartbeat "
            "overrides, SDO channels (simulate: default one of each built-in device)",
        ),
    ),
    "dbc_in": Flag(
        ("--dbc-in",),
        dict(
            dest="dbc_in",
            action="append",
            default=[],
            metavar="FILE",
            help="DBC file (read with cantools): its messages decoded as signals, its layouts, "
            "scaling, units and value tables winning over the profile's PDOs; repeatable "
            "(--dbc in every command but export, which writes one)",
        ),
    ),
    "bitrate": Flag(
        ("-b", "--bitrate"),
        dict(
            type=int,
            metavar="BIT/S",
            help="bus bitrate: the bus load in percent (live: also the bus's; simulate: frame "
            "timing, default the network file's or 500000)",
        ),
    ),
    # --- what the outputs show (decoding and the rules see everything) ----------
    "node": Flag(
        ("--node",), dict(metavar="N[,N]", help="only frames and records of these node-IDs")
    ),
    "service": Flag(
        ("--service",),
        dict(
            metavar="S[,S]",
            help="only these services (nmt, sync, time, emcy, tpdo, rpdo, pdo, sdo, heartbeat, ...)",
        ),
    ),
    "from": Flag(
        ("--from",),
        dict(dest="t_from", type=float, metavar="S", help="start, seconds after the first frame"),
    ),
    "to": Flag(
        ("--to",),
        dict(dest="t_to", type=float, metavar="S", help="end, seconds after the first frame"),
    ),
    "time": Flag(
        ("--time",),
        dict(
            choices=["rel", "abs"],
            default="rel",
            help="times in text output: seconds from the first frame (rel, default) or as "
            "logged (abs, like candump -ta)",
        ),
    ),
    # --- checks and their reports ------------------------------------------------
    "rules": Flag(
        ("--rules",),
        dict(
            metavar="FILE",
            help="rules file (YAML, docs/rules-file.md): its assertions join the findings "
            "(decode: implies --check)",
        ),
    ),
    "check": Flag(
        ("--check",),
        dict(
            action="store_true",
            help="run the CANopen rules too: findings appear in the output at their frames",
        ),
    ),
    "no_check": Flag(
        ("--no-check",),
        dict(action="store_true", help="skip the CANopen rules (no findings; a little faster)"),
    ),
    "junit": Flag(
        ("--junit",),
        dict(
            metavar="FILE",
            help="write a JUnit XML report (fleet: one testsuite per log; live: at exit)",
        ),
    ),
    "json": Flag(
        ("--json",),
        dict(metavar="FILE", help="write the findings as a JSON list (live: at exit)"),
    ),
    "timing": Flag(("--timing",), dict(action="store_true", help="also print the timing analysis")),
    "html": Flag(
        ("--html",), dict(metavar="FILE", help="also write the HTML report (as `report`)")
    ),
    "title": Flag(("--title",), dict(help="the report's title (default: the log's name)")),
    # --- terminal ----------------------------------------------------------------
    "no_color": Flag(
        ("--no-color",), dict(action="store_true", help="no ANSI colours even on a terminal")
    ),
    "quiet": Flag(
        ("-q", "--quiet"),
        dict(action="store_true", help="no progress bar (export, fleet: nor the summary line)"),
    ),
    # --- decode ------------------------------------------------------------------
    "format": Flag(
        ("--format",), dict(choices=["text", "jsonl"], default="text", help="output format")
    ),
    "summary": Flag(("--summary",), dict(action="store_true", help="print only the summary")),
    "sdo": Flag(("--sdo",), dict(action="store_true", help="print only the SDO transaction table")),
    "signals": Flag(
        ("--signals",),
        dict(
            action="store_true",
            help="print only decoded PDO values, one signal record per value (t, node, pdo, "
            "signal, value, unit)",
        ),
    ),
    "output": Flag(
        ("-o", "--output"),
        dict(metavar="FILE", help="write to FILE instead of stdout (report: the HTML file)"),
    ),
    "dcf": Flag(
        ("--dcf",),
        dict(
            metavar="DIR",
            help="also write each node's configuration as a CiA 306 DCF in DIR (node<N>.dcf)",
        ),
    ),
    # --- diff ---------------------------------------------------------------------
    "reference": Flag(
        ("reference",),
        dict(
            metavar="B",
            help="the run to compare with: another log (same formats), or a DCF (an XDC) whose "
            "ParameterValues (actualValues) are the expected configuration",
        ),
    ),
    "against": Flag(
        ("--against",),
        dict(
            metavar="B",
            help="also compare the log with B as `diff LOG B` does (a log, or a DCF/XDC): a "
            "Differences section",
        ),
    ),
    "tolerance": Flag(
        ("--tolerance",),
        dict(
            type=float,
            default=0.1,
            metavar="FRACTION",
            help="timings and PDO rates differ beyond this part of the larger (default 0.1)",
        ),
    ),
    "tolerance_ms": Flag(
        ("--tolerance-ms",),
        dict(
            type=float,
            default=2.0,
            metavar="MS",
            help="and beyond this many ms (default 2: thread and bus jitter)",
        ),
    ),
    "diff_json": Flag(
        ("--json",),
        dict(
            dest="diff_json",
            metavar="FILE",
            help="also write the differences as JSON (- for stdout)",
        ),
    ),
    "reference_node": Flag(
        ("--ref-node",),
        dict(
            type=int,
            metavar="N",
            help="a DCF/XDC reference: the node it describes (default its NodeID)",
        ),
    ),
    # --- timelines and tables ----------------------------------------------------
    "mcap": Flag(
        ("--mcap",),
        dict(metavar="FILE", help="write an MCAP file for Foxglove (PDO signal topics, events)"),
    ),
    "mcap_compression": Flag(
        ("--mcap-compression",),
        dict(
            choices=["zstd", "lz4", "none"],
            default="zstd",
            help="MCAP chunk compression (default zstd)",
        ),
    ),
    "rrd": Flag(("--rrd",), dict(metavar="FILE", help="write the timelines to a Rerun .rrd file")),
    "rerun": Flag(
        ("--rerun",),
        dict(action="store_true", help="show the timelines in a spawned Rerun viewer"),
    ),
    "connect": Flag(
        ("--connect",),
        dict(
            metavar="ADDR",
            help="also stream to a running Rerun viewer (host:port or rerun+http:// URL)",
        ),
    ),
    "parquet": Flag(
        ("--parquet",),
        dict(metavar="DIR", help="directory for frames/signals/sdo/events/... .parquet"),
    ),
    "csv": Flag(("--csv",), dict(metavar="DIR", help="directory for the same tables as CSV")),
    "parquet_compression": Flag(
        ("--parquet-compression",),
        dict(
            choices=_COMPRESSIONS,
            default="snappy",
            help="Parquet page compression (default snappy, as pandas writes; zstd files are "
            "40 %% smaller but cost 1/3 more time at 10M frames)",
        ),
    ),
    "dbc_out": Flag(
        ("--dbc",),
        dict(
            metavar="FILE",
            help="DBC file (written with cantools) of the network's PDOs as configured at the "
            "end of the log, SDO remaps included (to read a DBC, use --dbc-in)",
        ),
    ),
    # --- live --------------------------------------------------------------------
    "interface": Flag(
        ("-i", "--interface"),
        dict(
            action="append",
            help="python-can interface (socketcan, pcan, slcan, virtual, ...); repeat with -c "
            "for several buses",
        ),
    ),
    "channel": Flag(
        ("-c", "--channel"),
        dict(
            action="append",
            help="channel (can0, PCAN_USBBUS1, /dev/ttyACM0, ...); several buses: can0,can1 or "
            "repeated -i/-c pairs",
        ),
    ),
    "filter": Flag(
        ("--filter",),
        dict(
            action="append",
            default=[],
            metavar="ID:MASK",
            help="hardware acceptance filter, hex (e.g. 580:780 = SDO responses); repeatable",
        ),
    ),
    "bus_option": Flag(
        ("--bus-option",),
        dict(
            action="append",
            default=[],
            metavar="KEY=VALUE",
            help="extra python-can interface argument (e.g. tty_baudrate=921600, or port=43114 "
            "for udp_multicast); repeatable",
        ),
    ),
    "live_check": Flag(
        ("--check",),
        dict(
            metavar="RULES",
            help="check the rules of this rules file live; exit 1 on violations, as `check` does",
        ),
    ),
    "foxglove": Flag(
        ("--foxglove",),
        dict(
            nargs="?",
            const="127.0.0.1:8765",
            metavar="HOST:PORT",
            help="serve the decode to Foxglove over WebSocket (default 127.0.0.1:8765; the "
            "topics of export --mcap)",
        ),
    ),
    "plain": Flag(
        ("--plain",), dict(action="store_true", help="decode-style lines instead of the dashboard")
    ),
    "record": Flag(
        ("--record",),
        dict(metavar="FILE", help="record the raw frames (.log candump, .asc, .blf, .mcap)"),
    ),
    "duration": Flag(
        ("--duration",),
        dict(type=float, metavar="S", help="stop after S seconds (simulate: default 10)"),
    ),
    # --- fleet and query ---------------------------------------------------------
    "out": Flag(
        ("--out",),
        dict(required=True, metavar="DATASET", help="the dataset folder, or a URL (s3://...)"),
    ),
    "workers": Flag(
        ("--workers",),
        dict(type=int, metavar="N", help="local worker processes (default: the number of cores)"),
    ),
    "scheduler": Flag(
        ("--scheduler",),
        dict(
            metavar="tcp://HOST:PORT",
            help="use this running Dask scheduler instead of a local cluster "
            "(its workers must see the same paths)",
        ),
    ),
    "batch": Flag(
        ("--batch",),
        dict(
            type=int,
            default=1,
            metavar="N",
            help="decode small logs (under 16 MB) N to a task, their parts merged into "
            "shared files (default 1: a task and seven parts a log)",
        ),
    ),
    "compact": Flag(
        ("--compact",),
        dict(
            action="store_true",
            help="at the end, compact the days this run wrote (as `fleet compact`, --target-size)",
        ),
    ),
    "force": Flag(
        ("--force",), dict(action="store_true", help="decode logs already in the dataset again")
    ),
    "task_timeout": Flag(
        ("--task-timeout",),
        dict(
            type=float,
            default=TASK_TIMEOUT,
            metavar="S",
            help=f"give a log up after S seconds: a failed row saying so (default {TASK_TIMEOUT:g})",
        ),
    ),
    "dataset": Flag(("dataset",), dict(help="the dataset folder or URL (fleet --out)")),
    "target_size": Flag(
        ("--target-size",),
        dict(
            type=byte_size,
            default=COMPACT_TARGET_SIZE,
            metavar="SIZE",
            help="the compacted files' size, e.g. 64MB (default "
            f"{COMPACT_TARGET_SIZE >> 20}MB; parts already this big stay as they are)",
        ),
    ),
    "storage_options": Flag(
        ("--storage-options",),
        dict(
            metavar="JSON",
            help="fsspec options for s3:// and other URLs, e.g. "
            '\'{"endpoint_url": "http://127.0.0.1:9000"}\' (credentials: also AWS_* variables)',
        ),
    ),
    "sql": Flag(
        ("sql",),
        dict(help='the statement, e.g. "SELECT status, count(*) FROM logs GROUP BY 1"'),
    ),
    "query_csv": Flag(("--csv",), dict(action="store_true", help="CSV with a header line")),
    "query_json": Flag(("--json",), dict(action="store_true", help="one JSON object per row")),
    # --- devices -----------------------------------------------------------------
    "profile_key": Flag(
        ("key",), dict(nargs="?", help="profile key (e.g. dat7130) or an EDS/DCF/XDD/XDC file")
    ),
    "profile_node": Flag(
        ("--node",), dict(type=int, default=1, help="node ID for $NODEID defaults (1)")
    ),
    "profile_dbc": Flag(
        ("--dbc",), dict(metavar="OUT.dbc", help="write the device's PDOs at --node as a DBC file")
    ),
    # --- simulate ----------------------------------------------------------------
    "sim_to": Flag(
        ("--to",),
        dict(
            metavar="FILE",
            help="write the traffic to a log (.log candump, .asc, .blf) on a simulated clock",
        ),
    ),
    "sim_interface": Flag(
        ("-i", "--interface"),
        dict(
            help="python-can interface for real-time mode (e.g. socketcan; udp_multicast to "
            "reach another process: virtual is in-process only)"
        ),
    ),
    "sim_channel": Flag(
        ("-c", "--channel"), dict(help="python-can channel for real-time mode (e.g. can0)")
    ),
    "seed": Flag(
        ("--seed",), dict(type=int, default=0, help="random seed: same seed, same log (default 0)")
    ),
    "scenario": Flag(
        ("--scenario",),
        dict(
            default="steady",
            help=_scenarios_help,
        ),
    ),
    "no_master": Flag(
        ("--no-master",),
        dict(
            action="store_true",
            help="real-time mode: emulate only the devices, another tool is the master",
        ),
    ),
}

# Groups several commands take together
INPUT = (
    "log", "strict", "input_format", "sdo_timeout", "fd", "device", "eds", "network", "dbc_in"
)  # fmt: skip
FILTERS = ("node", "service", "from", "to")


def add(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    *keys: str,
    extra_names: dict[str, tuple[str, ...]] | None = None,
    required: tuple[str, ...] = (),
    **defaults,
) -> None:
    """Add the registry's flags `keys` to a parser (or a group), in that order.

    `extra_names` gives a flag another spelling in this command only (`--dbc` for
    `--dbc-in` where no `--dbc` is written); `required` names the flags this command
    cannot do without (`report`'s `-o`); `defaults` override a flag's default here
    (`duration=10.0`), the help saying so."""
    unknown = (set(defaults) | set(extra_names or ()) | set(required)) - set(keys)
    if unknown:
        raise ValueError(f"defaults, names or required for flags not added here: {sorted(unknown)}")
    for key in keys:
        flag = FLAGS[key]
        kwargs = dict(flag.kwargs)
        for text in ("help", "version"):  # read when the parser is built
            if callable(kwargs.get(text)):
                kwargs[text] = kwargs[text]()
        if key in defaults:
            kwargs["default"] = defaults[key]
        if key in required:
            kwargs["required"] = True
        names = (extra_names or {}).get(key, ()) + flag.names
        parser.add_argument(*names, **kwargs)
