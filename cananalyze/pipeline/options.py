"""What a run is asked to do: the Options every door builds (CLI, load(), fleet)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from cananalyze.core.defaults import SDO_TIMEOUT
from cananalyze.core.errors import UsageError

TIME_MODES = ("rel", "abs")


@dataclass
class Options:
    """What a run is asked to do, whichever door it came through (CLI, `load()`, fleet).

    Devices: `devices` maps node-IDs to built-in profile keys, `eds` to EDS/DCF/XDD/XDC files,
    on top of the `network` file. `rules` adds the rules file's assertions to the
    CANopen rules, which run when `checks` is set (or a rules file is given).
    Filters (`nodes`, `services`, `t_from`/`t_to` in seconds after the log's first
    frame) choose what the sinks see; the decoder and the rules always see everything.
    `time`: text outputs show seconds from the first frame ("rel") or as logged ("abs").
    """

    network: str | Path | None = None
    devices: Mapping[int, str] = field(default_factory=dict)
    eds: Mapping[int, str | Path] = field(default_factory=dict)
    rules: str | Path | None = None
    checks: bool = False
    timing: bool = False
    sdo_timeout: float = SDO_TIMEOUT
    # CiA 1301 (--fd): the network (True) or these nodes are CANopen FD: their SDO COB-IDs
    # carry USDO frames (docs/decoding.md); the network file's `canopen_fd` keys add to it
    fd: frozenset[int] | bool = frozenset()
    strict: bool = False
    input_format: str | None = None
    bitrate: int | None = None
    nodes: frozenset[int] | None = None
    services: frozenset[int] | None = None
    t_from: float | None = None
    t_to: float | None = None
    time: str = "rel"
    dbc: tuple[str | Path, ...] = ()  # DBC files: their messages decoded as signals (--dbc)
    # how to reach logs given as URLs (s3://...): fsspec's options (fleet --storage-options)
    storage_options: dict | None = None

    def __post_init__(self) -> None:
        if isinstance(self.dbc, (str, Path)):
            self.dbc = (self.dbc,)
        self.dbc = tuple(self.dbc or ())
        for what, table in (("--device", self.devices), ("--eds", self.eds)):
            for node in table:
                if not isinstance(node, int) or isinstance(node, bool) or not 1 <= node <= 127:
                    raise UsageError(f"{what} takes NODE=VALUE with NODE 1..127 (got {node!r})")
        if self.time not in TIME_MODES:
            raise UsageError(f"--time is rel or abs (got {self.time!r})")
        if self.sdo_timeout is not None and not self.sdo_timeout > 0:
            raise UsageError(f"--sdo-timeout must be positive (got {self.sdo_timeout})")
        if self.bitrate is not None and not 0 < self.bitrate <= 8_000_000:
            raise UsageError(f"--bitrate must be 1..8000000 bit/s (got {self.bitrate})")

    @property
    def checking(self) -> bool:
        return self.checks or self.rules is not None

    @property
    def filtered(self) -> bool:
        return (
            self.nodes is not None
            or self.services is not None
            or self.t_from is not None
            or self.t_to is not None
        )
