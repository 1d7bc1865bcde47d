"""The live dashboard: what a commissioning engineer wants to see on a running bus.

`LiveView` keeps the state (nodes, latest PDO signal values, an event log with
levels, check findings, frame rate and bus load) and is fed DecodedBatches as they
land; device names come from the decoder's network model (--network, --eds,
--device, SDO identification) when it is given one; `render()` builds a rich
renderable from it, so the same view runs under `rich.live.Live` or prints into a
recording Console in tests. Updates are columnar per batch; only the rare rows
(heartbeats' last state per node, EMCY, NMT, records) are looked at one by one.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from typing import TextIO

import numpy as np

from cananalyze.core.frames import MAX_BUSES, OTHER_CHANNELS
from cananalyze.core.records import DecodedBatch
from cananalyze.outputs.fields import row_fields
from cananalyze.outputs.summary import Summary
from cananalyze.outputs.text.records import format_record
from cananalyze.pipeline.sink import Sink
from cananalyze.protocol import nmt
from cananalyze.protocol.emcy import error_text
from cananalyze.protocol.fields import annotation
from cananalyze.protocol.services import Service

_ERRCTL = np.array([Service.HEARTBEAT, Service.BOOTUP, Service.GUARD_RESPONSE], np.uint8)
_RARE = np.array([Service.NMT, Service.EMCY], np.uint8)
_SDO = np.array([Service.SDO_REQUEST, Service.SDO_RESPONSE], np.uint8)
RATE_WINDOW = 1.0  # seconds of wall time over which frame rate and bus load are measured
FINDINGS_SHOWN = 5  # rows of the findings panel (live --check): the latest ones
INFO, WARNING, ERROR = "info", "warning", "error"
_LEVEL_STYLE = {INFO: "", WARNING: "yellow", ERROR: "bold red"}
_SEVERITY_LEVEL = {"error": ERROR, "warning": WARNING, "info": INFO}
_STATE_STYLE = {
    nmt.STATES[nmt.OPERATIONAL]: "green",
    nmt.STATES[nmt.PRE_OPERATIONAL]: "yellow",
    nmt.STATES[nmt.STOPPED]: "red",
    nmt.BOOTUP_TEXT: "cyan",
}


@dataclass
class NodeState:
    node: int
    device: str | None = None
    state: str | None = None
    last_seen: float | None = None  # frame time of the last heartbeat / boot-up / guard reply
    last_hb: float | None = None
    periods: deque = field(default_factory=lambda: deque(maxlen=16))
    emcy: dict[int, str] = field(default_factory=dict)  # active error code -> text
    last_sdo: str | None = None
    identity: dict[str, object] = field(default_factory=dict)

    @property
    def period_ms(self) -> float | None:
        return float(np.median(self.periods)) * 1e3 if self.periods else None


@dataclass
class SignalValue:
    node: int
    pdo: str
    name: str
    value: object
    unit: str | None
    t: float


def _value_text(value) -> str:
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


class LiveView:
    """State behind the dashboard. `add(batch)` after every decode; `render()` to show it."""

    def __init__(
        self,
        bitrate: int | None = None,
        devices: dict[int, str] | None = None,
        events: int = 200,
        model=None,
        checking: bool = False,
    ) -> None:
        self.bitrate = bitrate
        self.model = model  # NetworkModel: profiles declared or identified, per node
        self.checking = checking
        self.violations = 0
        self.notes = 0
        self.summary = Summary()
        self.declared = dict(devices or {})  # node -> device name, on every bus
        # node states per bus (channel name; None until the first frame names it): node
        # 5 on can0 and on can1 are two devices. `nodes` is the first bus's
        self.buses: dict[str | None, dict[int, NodeState]] = {None: {}}
        self.nodes: dict[int, NodeState] = self.buses[None]
        self.networks = None  # () -> {bus: NetworkModel} (Decoder.networks), several buses
        self.signals: dict[tuple[int, str, str], SignalValue] = {}
        self.events: deque[tuple[float, str, str]] = deque(maxlen=events)  # (t, level, text)
        # the latest findings, newest last: a panel of their own, so the event log's
        # traffic cannot scroll a silent node's finding away
        self.findings: deque[tuple[float, str, str]] = deque(maxlen=FINDINGS_SHOWN)
        self.t0: float | None = None
        self.t_last: float | None = None  # newest frame time
        self.clock_offset = 0.0  # frame time minus wall time at the newest frame
        self._window: deque[tuple[float, int, int]] = deque()  # (wall, frames, bits) per batch
        self.status = ""  # e.g. "recording to x.blf"
        for node in self.declared:
            self._node(node)

    def _node(self, n: int, bus: str | None = None) -> NodeState:
        """Node n of `bus` (a channel name; None: the first bus)."""
        nodes = self.nodes if bus is None else self._bus(bus)
        st = nodes.get(n)
        if st is None:
            st = nodes[n] = NodeState(n, device=self.declared.get(n))
        return st

    def _bus(self, bus: str) -> dict[int, NodeState]:
        """The node states of `bus`: the first bus named takes those kept so far; past
        MAX_BUSES the channels share one (as the decoder's)."""
        nodes = self.buses.get(bus)
        if nodes is not None:
            return nodes
        if None in self.buses:
            self.buses = {bus: self.buses.pop(None)}
            return self.nodes
        if len(self.buses) >= MAX_BUSES:
            return self._bus(OTHER_CHANNELS)
        nodes = self.buses[bus] = {}
        return nodes

    @property
    def several(self) -> bool:
        """More than one bus seen: the nodes panel has a bus column."""
        return len(self.buses) > 1

    def _who(self, node: int, bus: str | None) -> str:
        return f"{bus} node {node}" if self.several and bus else f"node {node}"

    def _row_bus(self, batch: DecodedBatch, row: int) -> str | None:
        """The bus of the batch's row: its channel's decoder's name (past 64 channels the
        shared one's); a record past the frames: the batch's bus, if the decoder said."""
        fb = batch.frames
        if 0 <= row < len(fb):
            c = int(fb.channel[row])
            if batch.channel_bus is not None:
                return batch.channel_bus[c]
            return batch.bus or fb.channel_label(c)
        return batch.bus

    def _event(self, t: float, text: str, level: str = INFO) -> None:
        self.events.append((t, level, text))

    def device(self, n: int, bus: str | None = None) -> str | None:
        """The node's device: the network model's profile (that bus's, several buses),
        else what SDO identity told."""
        model = self.model
        if bus is not None and self.several and self.networks is not None:
            model = self.networks().get(bus, model)
        cfg = model.nodes.get(n) if model is not None else None
        if cfg is not None and cfg.profile is not None:
            return cfg.profile.name
        nodes = self.nodes if bus is None else self.buses.get(bus, {})
        return nodes[n].device if n in nodes else None

    # --- feeding --------------------------------------------------------------
    def add(self, batch: DecodedBatch, wall: float | None = None) -> None:
        wall = time.time() if wall is None else wall
        bits_before = self.summary.bits
        self.summary.add(batch)
        n = len(batch)
        self._window.append((wall, n, self.summary.bits - bits_before))
        while self._window and self._window[0][0] < wall - RATE_WINDOW:
            self._window.popleft()
        fb = batch.frames
        if n:
            if self.t0 is None:
                self.t0 = float(fb.t[0])
            self.t_last = float(fb.t[-1])
            self.clock_offset = self.t_last - wall
            self._error_control(batch)
            self._rare(batch)
            self._sdo_frames(batch)
        for row, rec in batch.records_and_findings():
            self._record(batch, row, rec)
        for block in batch.signals:
            if not len(block.rows):
                continue
            t = float(fb.t[block.rows[-1]])
            for name, col in block.columns.items():
                value = col[-1]
                value = value.item() if hasattr(value, "item") else value
                key = (block.node, block.pdo, name)
                self.signals[key] = SignalValue(
                    block.node, block.pdo, name, value, block.units.get(name), t
                )

    def _error_control(self, batch: DecodedBatch) -> None:
        fb = batch.frames
        rows = np.flatnonzero(np.isin(batch.service, _ERRCTL) & (batch.node >= 0))
        if not rows.size:
            return
        keys = batch.node[rows].astype(np.int64) | (fb.channel[rows].astype(np.int64) << 8)
        for key in np.unique(keys).tolist():
            mine = rows[keys == key]
            node, bus = key & 0xFF, fb.channel_label(key >> 8)
            st = self._node(node, bus)
            t = fb.t[mine]
            hb = mine[batch.service[mine] == Service.HEARTBEAT]
            if hb.size:
                th = fb.t[hb]
                if st.last_hb is not None:
                    th = np.concatenate([[st.last_hb], th])
                st.periods.extend(np.diff(th).tolist())
                st.last_hb = float(th[-1])
            last = int(mine[-1])
            if batch.service[last] == Service.BOOTUP:
                st.state = nmt.BOOTUP_TEXT
            elif fb.dlc[last]:
                st.state = nmt.state_name(int(fb.data[last, 0]))
            st.last_seen = float(t[-1])
            boots = mine[batch.service[mine] == Service.BOOTUP]
            for r in boots.tolist():
                self._event(float(fb.t[r]), f"{self._who(node, bus)} {nmt.BOOTUP_TEXT}")
                st.emcy.clear()

    def _rare(self, batch: DecodedBatch) -> None:
        fb = batch.frames
        for r in np.flatnonzero(np.isin(batch.service, _RARE)).tolist():
            svc = int(batch.service[r])
            node = int(batch.node[r])
            f = row_fields(batch, r)
            text = annotation(svc, node, 0, f)
            if svc == Service.EMCY and node >= 0:
                bus = self._row_bus(batch, r)
                st = self._node(node, bus)
                if f.get("reset"):
                    st.emcy.clear()
                elif f.get("error_code") is not None:
                    st.emcy[f["error_code"]] = error_text(f["error_code"])
                text = f"{self._who(node, bus)} {text}"
                level = INFO if f.get("reset") else ERROR
            else:
                level = INFO
            self._event(float(fb.t[r]), text, level)

    def _sdo_frames(self, batch: DecodedBatch) -> None:
        """Last SDO frame per node, stateless: shown until an SDO transaction record replaces it."""
        rows = np.flatnonzero(np.isin(batch.service, _SDO) & (batch.node >= 0))
        if not rows.size:
            return
        fb = batch.frames
        keys = batch.node[rows].astype(np.int64) | (fb.channel[rows].astype(np.int64) << 8)
        for key in np.unique(keys).tolist():
            r = int(rows[keys == key][-1])
            node = key & 0xFF
            st = self._node(node, fb.channel_label(key >> 8))
            if st.last_sdo is None or st.last_sdo.startswith("frame: "):
                text = annotation(int(batch.service[r]), node, 0, row_fields(batch, r))
                st.last_sdo = f"frame: {text}"

    def _record(self, batch: DecodedBatch, row: int, rec: dict) -> None:
        fb = batch.frames
        t = float(rec.get("t") or (fb.t[row] if 0 <= row < len(fb) else (self.t_last or 0.0)))
        kind = rec.get("kind")
        text = format_record(rec)
        level = INFO
        if kind == "sdo":
            level = INFO if rec.get("result") == "ok" else WARNING
            node = rec.get("node")
            if isinstance(node, int) and node >= 0:
                st = self._node(node, self._row_bus(batch, row))
                st.last_sdo = text.removeprefix(f"node {node} ")
                if rec.get("result") == "ok" and rec.get("index") in (0x1000, 0x1008, 0x1018):
                    self._identity(st, rec)
        elif kind == "finding":
            severity = str(rec.get("severity") or "warning")
            level = _SEVERITY_LEVEL.get(severity, WARNING)
            if severity == "info":
                self.notes += 1
            else:
                self.violations += 1
            node = rec.get("node")
            where = f"node {node} " if isinstance(node, int) else ""
            text = f"{rec.get('rule')}: {where}{rec.get('message')}"
            self.findings.append((t, level, text))
        self._event(t, text, level)

    def _identity(self, st: NodeState, rec: dict) -> None:
        key = {
            (0x1000, 0): "device_type",
            (0x1008, 0): "device_name",
            (0x1018, 1): "vendor_id",
            (0x1018, 2): "product_code",
        }.get((rec.get("index"), rec.get("subindex")))
        if key is None:
            return
        value = rec.get("value")
        raw = bytes.fromhex(rec.get("data") or "")
        # without an object dictionary the tracker leaves the value as hex: CiA 301 types apply
        if key == "device_name":
            if raw:
                value = raw.rstrip(b"\0").decode("latin-1")
        elif not isinstance(value, int) and raw:
            value = int.from_bytes(raw[:4], "little")
        st.identity[key] = value
        if st.device is None or st.device.startswith("?"):
            from cananalyze.devices.builtin import identify

            ident = {k: v for k, v in st.identity.items()}
            name = ident.get("device_name")
            try:
                prof = identify(
                    vendor_id=ident.get("vendor_id")
                    if isinstance(ident.get("vendor_id"), int)
                    else None,
                    product_code=ident.get("product_code")
                    if isinstance(ident.get("product_code"), int)
                    else None,
                    device_type=ident.get("device_type")
                    if isinstance(ident.get("device_type"), int)
                    else None,
                    device_name=name if isinstance(name, str) else None,
                )
            except Exception:  # noqa: BLE001 - identification is a nicety, never fatal
                prof = None
            if prof is not None:
                st.device = prof.name
            elif isinstance(name, str):
                st.device = f"? {name}"

    # --- measures -------------------------------------------------------------
    def frame_rate(self) -> float:
        if len(self._window) < 2:
            return 0.0
        span = self._window[-1][0] - self._window[0][0]
        frames = sum(n for _, n, _ in list(self._window)[1:])
        return frames / span if span > 0 else 0.0

    def bus_load(self) -> float | None:
        """Percent of the bitrate used over the last second (nominal bits, no stuffing)."""
        if not self.bitrate or len(self._window) < 2:
            return None
        span = self._window[-1][0] - self._window[0][0]
        bits = sum(b for _, _, b in list(self._window)[1:])
        return bits / (self.bitrate * span) * 100 if span > 0 else None

    def now(self, wall: float | None = None) -> float:
        """The current time on the frames' clock (frame times are not always wall time)."""
        wall = time.time() if wall is None else wall
        return wall + self.clock_offset

    # --- rendering ------------------------------------------------------------
    def render(self, wall: float | None = None, height: int = 40):
        """A rich renderable of the whole dashboard.

        Every column has a fixed width or a ratio of the terminal width, never one
        measured from its content, so columns stay put between refreshes.
        """
        from rich.console import Group
        from rich.panel import Panel
        from rich.table import Table
        from rich.text import Text

        now = self.now(wall)
        load = self.bus_load()
        head = Text()
        head.append("cananalyze live  ", style="bold")
        head.append(f"frames {self.summary.frames:>9}  ")
        head.append(f"rate {self.frame_rate():>6.0f}/s  ")
        head.append(f"bus load {load:5.1f} %" if load is not None else "bus load - (give -b)")
        if self.checking:
            style = "bold red" if self.violations else "green"
            head.append(f"  check: {self.violations} violation(s)", style=style)
            if self.notes:
                head.append(f", {self.notes} note(s)")
        if self.status:
            head.append(f"  {self.status}", style="dim")
        if len(self.summary.by_channel) > 1:  # several buses: each one's frames and load
            for name, (frames, _) in self.summary.by_channel.items():
                load = self.summary.channel_load(name, self.bitrate)
                head.append(f"\n  {name}: {frames} frames")
                head.append(f", {load:.1f} % load" if load is not None else "")

        nodes = Table(title="Nodes", title_justify="left", expand=True, pad_edge=False)
        several = self.several  # node 5 of each bus a row of its own
        if several:
            nodes.add_column("bus", width=8, overflow="ellipsis", no_wrap=True)
        for col, kw in (
            ("node", {"width": 4, "justify": "right"}),
            ("device", {"ratio": 2}),
            ("NMT state", {"width": 15}),
            ("hb age", {"width": 8, "justify": "right"}),
            ("hb period", {"width": 9, "justify": "right"}),
            ("active EMCY", {"ratio": 2}),
            ("last SDO", {"ratio": 3}),
        ):
            nodes.add_column(col, overflow="ellipsis", no_wrap=True, **kw)
        shown = [(bus, n, states[n]) for bus, states in self.buses.items() for n in sorted(states)]
        for bus, n, st in shown:
            age_s = now - st.last_seen if st.last_seen is not None else None
            age = Text(f"{age_s * 1e3:.0f} ms" if age_s is not None else "-")
            period = st.period_ms
            if age_s is not None and period and age_s * 1e3 > 2 * period:
                age.stylize("bold red")  # its heartbeat is overdue: the node may be gone
            state_style = _STATE_STYLE.get(st.state or "", "")
            emcy = ", ".join(st.emcy.values()) or "-"
            # names from the log and files as Text: a str cell is rich markup, and a
            # "[link=...]" in a channel's or device's name would become a terminal escape
            nodes.add_row(
                *((Text(bus or "-"),) if several else ()),
                str(n),
                Text(self.device(n, bus if several else None) or "-"),
                Text(st.state or "-", style=state_style),
                age,
                f"{period:.0f} ms" if period is not None else "-",
                Text(emcy, style="bold red" if st.emcy else ""),
                Text(st.last_sdo or "-"),
            )

        # one row per PDO, its signals side by side: a node with 8 inputs takes one line,
        # not eight, so the event log (where findings appear) keeps its room
        by_pdo: dict[tuple[int, str], list[SignalValue]] = {}
        for key in sorted(self.signals):
            s = self.signals[key]
            by_pdo.setdefault((s.node, s.pdo), []).append(s)
        # lines: header 1, each table title + borders + heading 5 + rows, the log panel 2 + room,
        # one spare so the cursor line never scrolls the screen
        nodes_h = 5 + max(1, len(shown))
        room_sigs = max(2, height - 1 - nodes_h - 5 - (2 + 8) - 1)  # 8 lines kept for the log
        rows = list(by_pdo.items())
        shown = rows if len(rows) <= room_sigs else rows[: room_sigs - 1]
        sigs = Table(
            title="PDO signals (latest)", title_justify="left", expand=True, pad_edge=False
        )
        for col, kw in (
            ("node", {"width": 4, "justify": "right"}),
            ("PDO", {"width": 6}),
            ("values", {"ratio": 1}),
            ("age", {"width": 9, "justify": "right"}),
        ):
            sigs.add_column(col, no_wrap=True, overflow="ellipsis", **kw)
        for (node, pdo), values in shown:
            cells = Text()
            for k, s in enumerate(values):
                if k:
                    cells.append("   ")
                cells.append(f"{s.name} ", style="dim")
                cells.append(_value_text(s.value))
                if s.unit:
                    cells.append(f" {s.unit}")
            age = (now - max(s.t for s in values)) * 1e3
            sigs.add_row(str(node), Text(pdo), cells, f"{age:.0f} ms")
        if len(shown) < len(rows):
            sigs.add_row("", "", Text(f"... {len(rows) - len(shown)} more PDOs", style="dim"), "")
        if not rows:
            sigs.add_row(
                "-", "-", "(no decoded PDO yet: --device, --eds or --network name them)", ""
            )

        sigs_h = 5 + max(1, len(shown) + (len(shown) < len(rows)))
        t0 = self.t0 or 0.0
        parts = [head, nodes, sigs]
        room = max(4, height - 1 - nodes_h - sigs_h - 2 - 1)
        if self.checking:
            found = list(self.findings) or [(None, INFO, "none so far")]
            parts.append(
                Panel(
                    _log(found, t0),
                    title="Findings (latest)",
                    title_align="left",
                    height=2 + FINDINGS_SHOWN,
                )
            )
            room = max(4, room - 2 - FINDINGS_SHOWN)
        parts.append(Panel(_log(list(self.events)[-room:], t0), title="Events", title_align="left"))
        return Group(*parts)


def _log(rows: list[tuple[float | None, str, str]], t0: float):
    """Lines of (time, level, text), styled by level, for a log panel."""
    from rich.text import Text

    log = Text(no_wrap=True, overflow="ellipsis")
    for k, (t, level, text) in enumerate(rows):
        log.append(f"{t - t0:10.3f}  " if t is not None else " " * 12, style="dim")
        log.append(text + ("\n" if k < len(rows) - 1 else ""), style=_LEVEL_STYLE.get(level, ""))
    return log


class DashboardSink(Sink):
    """The live dashboard as a sink: its state from every batch, redrawn on a terminal
    four times a second (`show`); without a terminal only the state (the end summary)."""

    def __init__(
        self,
        bitrate: int | None = None,
        checking: bool = False,
        status: str = "",
        show: bool = True,
        every: float = 0.25,
        summary: TextIO | None = None,
    ) -> None:
        """`summary`: where to print the frame summary when the session ends."""
        self.summary_out = summary
        self.bitrate = bitrate
        self.checking = checking
        self.status = status
        self.show = show
        self.every = every
        self.view: LiveView | None = None
        self._live = None
        self._shown = 0.0

    def open(self, run) -> None:
        super().open(run)
        self.view = LiveView(bitrate=self.bitrate, model=run.network, checking=self.checking)
        self.view.networks = run.decoder.networks
        self.view.status = self.status
        if self.show:
            from rich.console import Console
            from rich.live import Live

            self._console = Console()
            self._live = Live(
                self.view.render(height=self._console.height),
                console=self._console,
                auto_refresh=False,
                screen=False,
                transient=False,
                redirect_stderr=False,
            )
            self._live.start()

    def write(self, batch) -> None:
        self.view.add(batch)
        self.tick(time.monotonic())

    def tick(self, now: float) -> None:
        if self._live is not None and (now - self._shown >= self.every):
            self._live.update(self.view.render(height=self._console.height), refresh=True)
            self._shown = now

    def close(self) -> None:
        if self._live is not None:
            self._live.update(self.view.render(height=self._console.height), refresh=True)
            self._live.stop()
            self._live = None
        if self.summary_out is not None:
            self.summary_out.flush()
            print("\n".join(self.view.summary.lines(self.bitrate)), file=self.summary_out)
            self.summary_out.flush()

    def abort(self) -> None:
        if self._live is not None:
            self._live.stop()
            self._live = None
