"""Every table's columns, declared once: name, Arrow type, pandas type, nullability, the
fleet dataset's type and what the column means.

`export --parquet/--csv` (outputs/tables), `load()`'s DataFrames (outputs/capture), a
fleet's dataset parts (fleet/schema) and the schema section of docs/outputs.md
(`markdown()`, checked by a test) all read these tables. The SDO and findings columns are
the record model's (`SDO_TABLE_COLUMNS`, `TABLE_COLUMNS`: the JSON outputs' keys too);
their types are declared here by name, and a column without one fails at import.

Two kinds of column are typed per log by the single-log export, as pandas would type
that log's values (an SDO `value` is a number in one log, text in another): `DECIDED`.
A dataset needs one type for every log, so each column also has its `dataset` type.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import pyarrow as pa

from cananalyze.core.finding import TABLE_COLUMNS
from cananalyze.core.sdo_records import SDO_TABLE_COLUMNS
from cananalyze.decode.events.build import LEVEL_NAMES
from cananalyze.decode.node_tally import IDENTITY_KEYS
from cananalyze.decode.od_tally import OD_COLUMNS
from cananalyze.protocol.services import SERVICE_NAMES

LABEL = pa.dictionary(pa.int32(), pa.string())  # a dataset's categories: one type for every part
TEXT = pa.large_string()  # what pandas writes a text column as (a `bus` column)
DECIDED = None  # typed per log, as pandas types that log's values (SDO, findings)
CODED = "coded"  # a dictionary of strings whose index width comes from its categories


def code_type(n: int) -> pa.DataType:
    """The index type pandas gives a categorical of n categories."""
    return pa.int8() if n < 128 else pa.int16() if n < 32768 else pa.int32()


@dataclass(frozen=True)
class Column:
    name: str
    doc: str
    arrow: pa.DataType | str | None  # the export's type; CODED; DECIDED
    pandas: tuple[str, str] | None = None  # (pandas_type, numpy_type) of pandas' metadata
    categories: int = 0  # CODED: a fixed number of categories (0: counted per file)
    nullable: bool = True  # False: never null, written REQUIRED by the export
    dataset: pa.DataType | None = None  # the fleet's type (None: the export's; CODED: LABEL)

    @property
    def fleet_type(self) -> pa.DataType:
        if self.dataset is not None:
            return self.dataset
        if self.arrow == CODED and not self.categories:
            return LABEL
        return self.export_type()  # type: ignore[return-value]

    def arrow_type(self) -> pa.DataType | None:
        """The export's Arrow type (None: a Coded column, typed when the file opens)."""
        if self.arrow == CODED:
            return code_type(self.categories) if self.categories else None
        return self.arrow  # type: ignore[return-value]

    def export_type(self) -> pa.DataType | None:
        """As `arrow_type`, with a fixed-count category column as a dictionary of strings."""
        t = self.arrow_type()
        return pa.dictionary(t, pa.string()) if self.arrow == CODED and t is not None else t


@dataclass(frozen=True)
class Table:
    name: str
    doc: str
    columns: tuple[Column, ...]
    in_dataset: bool = True  # a fleet's dataset has it (`od`: the single-log export only)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.columns)

    def column(self, name: str) -> Column:
        return next(c for c in self.columns if c.name == name)

    def without(self, *names: str) -> Table:
        return replace(self, columns=tuple(c for c in self.columns if c.name not in names))

    def export_fields(self) -> list[tuple[str, pa.DataType | None]]:
        """(name, Arrow type) as the export's writer takes them (None: Coded)."""
        return [(c.name, c.export_type()) for c in self.columns]

    def required(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.columns if not c.nullable)

    def dataset_columns(self) -> list[tuple[str, pa.DataType]]:
        return [(c.name, c.fleet_type) for c in self.columns]


def _bus(what: str, dataset: pa.DataType | None = None) -> Column:
    return Column(
        "bus",
        f"a log of several buses: the {what}'s channel name (absent, or null in a dataset, on "
        "a log of one bus)",
        TEXT,
        ("object", "str"),
        dataset=dataset or pa.string(),
    )


FRAMES = Table(
    "frames",
    "one row per frame, in log order",
    (
        Column(
            "t",
            "time as logged: Unix seconds when the log has absolute time, else seconds from its start",
            pa.float64(),
            ("float64", "float64"),
            nullable=False,
        ),
        Column("channel", "the bus the frame was on", CODED, ("categorical", ""), nullable=False),
        Column(
            "can_id",
            "the identifier (11 or 29 bits)",
            pa.uint32(),
            ("uint32", "uint32"),
            nullable=False,
        ),
        Column("dlc", "data length code", pa.uint8(), ("uint8", "uint8"), nullable=False),
        Column(
            "data",
            "the payload's bytes (CSV: lowercase hex)",
            pa.binary(),
            ("bytes", "binary[pyarrow]"),
            nullable=False,
        ),
        Column(
            "flags",
            "bits: 1 29-bit, 2 remote, 4 error frame, 8 FD, 16 BRS, 32 ESI, 64 sent by the logger, "
            "128 bytes reconstructed from the log's text",
            pa.uint8(),
            ("uint8", "uint8"),
            nullable=False,
        ),
        Column(
            "service",
            "the CiA 301 service the COB-ID has",
            CODED,
            ("categorical", ""),
            categories=len(SERVICE_NAMES),
            nullable=False,
        ),
        Column("node", "the node-ID (null: none)", pa.int16(), ("int16", "Int16")),
        Column(
            "pdo",
            "the PDO number, or the SRDO number of an srdo/srdo_inverted frame (null: neither)",
            pa.int8(),
            ("int8", "Int8"),
        ),
        Column(
            "sync_latency_ms",
            "a synchronous PDO's (transmission type 0-240 in force) time after the SYNC before "
            "it, in ms, as `check --timing` sums it up per COB-ID (null: not a synchronous PDO, "
            "no SYNC before it, a log without times, or the checks off)",
            pa.float64(),
            ("float64", "float64"),
        ),
    ),
)

SIGNALS = Table(
    "signals",
    "one row per PDO signal value (Parquet: one row per PDO frame, a column per signal)",
    (
        Column("t", "the frame's time", pa.float64(), ("float64", "float64")),
        Column("node", "the node-ID", pa.int16(), ("int16", "int16")),
        Column(
            "pdo",
            "tpdoN / rpdoN / srdoN (an SRDO pair's normal frame), or the DBC message's name",
            CODED,
            ("categorical", ""),
        ),
        Column("cob_id", "the frame's COB-ID", pa.uint32(), ("uint32", "uint32")),
        Column("signal", "the signal's name", CODED, ("categorical", "")),
        Column(
            "value",
            "the value, scaled (float64 for every signal)",
            pa.float64(),
            ("float64", "float64"),
        ),
        Column("unit", 'the unit ("" for none)', CODED, ("categorical", "")),
        _bus("PDO", TEXT),
    ),
)

EVENTS = Table(
    "events",
    "NMT commands and states, boot-ups, EMCY, SDO transfers, drive states, LSS steps, boot "
    "stories and findings, by time. An `nmt_state` event is a change of a node's NMT state as "
    "the checks follow it: reported by its heartbeat, guard response or boot-up "
    "(pre-operational), or commanded by NMT, at the frame that made it, once the node has sent "
    "a frame of its own. An `lss` event is a CiA 305 step with its result, at the frame that "
    "ended it; a `boot` event a node's boot story (CiA 302-2) at its boot-up, judged at the "
    "end of the log (no row); a `burst` event the bus's longest run of frames back to back, "
    "at its first frame (with a bitrate and times; no row)",
    (
        Column("t", "the event's time", pa.float64(), ("float64", "float64")),
        Column(
            "kind", "what happened (nmt_state, emcy, sdo, finding, ...)", CODED, ("categorical", "")
        ),
        Column("node", "the node-ID (null: the whole bus)", pa.int16(), ("int16", "Int16")),
        Column(
            "level",
            "debug, info, warning, error or fatal",
            CODED,
            ("categorical", ""),
            categories=len(LEVEL_NAMES),
        ),
        Column("message", "the event in words", pa.large_string(), ("object", "string")),
        Column(
            "row",
            "the frame's row in the frames table (null: none)",
            pa.int64(),
            ("int64", "Int64"),
        ),
        _bus("event", TEXT),
    ),
)

_SDO = {
    "t_start": ("the request's time", pa.float64()),
    "t": ("the time the transfer ended (its last frame, or the timeout)", pa.float64()),
    "latency_ms": ("request to response, ms", pa.float64()),
    "node": ("the server's node-ID", pa.int16()),
    "direction": ("upload (read) or download (write)", pa.string()),
    "protocol": ("expedited, segmented or block", pa.string()),
    "index": ("the object's index", pa.int32()),
    "subindex": ("the object's sub-index", pa.int16()),
    "size": ("bytes transferred", pa.int64()),
    "data": ("the bytes, hex", pa.string()),
    "value": ("the value decoded by the object's data type (dataset: text)", pa.string()),
    "name": ("the object's name in the node's profile", pa.string()),
    "result": ("ok, abort, timeout or a protocol error", pa.string()),
    "abort_code": ("the SDO abort code", pa.int64()),
    "abort_text": ("its CiA 301 text", pa.string()),
    "detail": ("what went wrong, in words", pa.string()),
    "words": ("the value in words (a CiA 402 state, a COB-ID's parts, ...)", pa.string()),
}
_FINDINGS = {
    "t": ("the time of the fault (Unix seconds when the log has them)", pa.float64()),
    "t_rel": ("seconds from the log's first frame", pa.float64()),
    "rule": ("the rule that found it", pa.string()),
    "severity": ("error, warning or info", pa.string()),
    "node": ("the node-ID (null: none)", pa.int16()),
    "cob_id": ("the COB-ID (null: none)", pa.int64()),
    "message": ("the finding in words", pa.string()),
    "measured": ("what the log shows (dataset: text)", pa.string()),
    "expected": ("what the configuration in force says (dataset: text)", pa.string()),
    "why": ("why it matters and how to check it", pa.string()),
    "basis": ("where the expected value came from", pa.string()),
    "line": ("the log's line, in a log without times", pa.int64()),
}


def _declared(names: tuple[str, ...], declared: dict, what: str) -> tuple[Column, ...]:
    """The record model's columns in its order, each with its type and doc from here."""
    if set(names) != set(declared):
        raise RuntimeError(
            f"{what}: columns without a declaration here: {set(names) ^ set(declared)}"
        )
    return tuple(Column(n, declared[n][0], DECIDED, dataset=declared[n][1]) for n in names)


SDO = Table(
    "sdo",
    "one row per SDO transfer, in completion order",
    (*_declared(SDO_TABLE_COLUMNS, _SDO, "sdo"), _bus("transfer")),
)

FINDINGS = Table(
    "findings",
    "one row per finding of the checks, by time (as `check --json`)",
    (*_declared(TABLE_COLUMNS, _FINDINGS, "findings"), _bus("finding")),
)

_NODE_NUMBERS = ("device_type", "vendor_id", "product_code", "revision", "serial")
NODES = Table(
    "nodes",
    "one row per node (per bus and node on a log of several buses)",
    (
        Column("node", "the node-ID", DECIDED, dataset=pa.int16()),
        Column("frames", "frames the node sent", DECIDED, dataset=pa.int64()),
        *(
            Column(f"frames_{s}", f"its {s} frames (0 when none)", DECIDED, dataset=pa.int64())
            for s in SERVICE_NAMES
        ),
        Column(
            "last_state",
            "its last NMT state: reported (heartbeat, guarding, boot-up) or commanded (NMT), "
            "as the checks follow it",
            DECIDED,
            dataset=pa.string(),
        ),
        Column("last_state_t", "when it entered that state", DECIDED, dataset=pa.float64()),
        *(
            Column(
                k,
                f"{k} read by SDO",
                DECIDED,
                dataset=pa.int64() if k in _NODE_NUMBERS else pa.string(),
            )
            for k in IDENTITY_KEYS
        ),
        Column("profile", "the device profile it was decoded with", DECIDED, dataset=pa.string()),
        Column("identified_by", "how that profile was chosen", DECIDED, dataset=pa.string()),
        Column(
            "bits",
            "nominal bits of the frames it sent itself (heartbeat, TPDO, EMCY, SDO response, "
            "guard response, boot-up), stuff bits left out",
            DECIDED,
            dataset=pa.int64(),
        ),
        Column(
            "bus_load_percent",
            "those bits over the log's duration, in percent of the bitrate (--bitrate or the "
            "network file's; null without one or without times): its mean share of the bus",
            DECIDED,
            dataset=pa.float64(),
        ),
        _bus("node"),
    ),
)

OD = Table(
    "od",
    "one row per object a node's successful SDO transfers showed, or a PDO it had mapped "
    "carried, per life of the node (`cananalyze od`)",
    tuple(
        Column(n, doc, DECIDED, dataset=t)
        for n, t, doc in (
            ("node", pa.int16(), "the node-ID"),
            ("index", pa.int32(), "the object's index"),
            ("subindex", pa.int16(), "its sub-index"),
            ("life", pa.int32(), "the node's boot-ups seen before the value (0: none yet)"),
            ("name", pa.string(), "the object's name (profile, EDS or CiA 301)"),
            ("value", pa.string(), "its last value, as the text outputs print it"),
            ("data", pa.string(), "the bytes of that value, hex (none for pdo)"),
            ("size", pa.int64(), "their count"),
            ("words", pa.string(), "the value in words, where known"),
            ("t", pa.float64(), "when the last transfer (or PDO frame) ended"),
            (
                "set_by",
                pa.string(),
                "write (an SDO download), read (an upload) or pdo (a PDO mapping it)",
            ),
            ("t_first", pa.float64(), "when the first transfer (or PDO frame) of it ended"),
            ("transfers", pa.int64(), "successful transfers of it (pdo: frames carrying it)"),
            ("changes", pa.int64(), "times its value changed"),
            ("history", pa.string(), "the values it went through, oldest first"),
        )
    )
    + (_bus("object"),),
    in_dataset=False,
)
if OD.without("bus").names != OD_COLUMNS:  # the tally's rows, in its order
    raise RuntimeError(f"od: the tally's columns are {OD_COLUMNS}")

LOGS = Table(
    "logs",
    "a fleet dataset's one row per input log, with its status",
    tuple(
        Column(n, doc, DECIDED, dataset=t)
        for n, t, doc in (
            ("format", pa.string(), "the log's format"),
            ("size", pa.int64(), "bytes"),
            ("frames", pa.int64(), "frames read"),
            ("t_first", pa.float64(), "first frame's time"),
            ("t_last", pa.float64(), "last frame's time"),
            ("date_from", pa.string(), "log: the log's own times date it; mtime: the file's"),
            ("status", pa.string(), "ok or failed"),
            ("error", pa.string(), "a failed log's one-line error"),
            ("seconds", pa.float64(), "wall time of its task"),
            ("cpu_seconds", pa.float64(), "the worker process's CPU, threads included"),
            ("peak_rss_mb", pa.float64(), "the worker's peak resident memory so far"),
            ("skipped_lines", pa.int64(), "unreadable lines or records skipped"),
            ("findings", pa.int64(), "findings of the checks"),
            ("violations", pa.int64(), "of which errors"),
            ("config", pa.string(), "SHA-256 of the options and the files they name"),
            (
                "mtime_ns",
                pa.int64(),
                "the file's modification time (ns) as read: a rerun's skip key",
            ),
            ("run", pa.string(), "the fleet run that wrote the row (its id): the run's counts"),
        )
    ),
)

TABLES: dict[str, Table] = {
    t.name: t for t in (FRAMES, SIGNALS, SDO, EVENTS, FINDINGS, NODES, OD, LOGS)
}


def _type_text(t: pa.DataType) -> str:
    return "string (dictionary)" if pa.types.is_dictionary(t) else str(t)


def markdown() -> str:
    """The tables as docs/outputs.md lists them (a test keeps the page equal to this)."""
    out = []
    for table in TABLES.values():
        out.append(f"### `{table.name}`\n\n{table.doc[0].upper()}{table.doc[1:]}.\n")
        out.append("| column | dataset type | |\n|---|---|---|")
        out += [f"| `{c.name}` | {_type_text(c.fleet_type)} | {c.doc} |" for c in table.columns]
        out.append("")
    return "\n".join(out)
