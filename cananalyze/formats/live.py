"""LiveSource: frames from a python-can bus, as small FrameBatches for the same Decoder.

python-can hands over one Message per frame; that is unavoidable on a live bus, so
a reader thread copies each into preallocated numpy columns (a ring) and drops the
Message at once. The consumer takes what has arrived every `interval` seconds (or as
soon as `batch_max` frames wait) as one FrameBatch, so the decoder, outputs and
checks see exactly what they see offline. When the ring is full the reader waits for
the consumer instead of overwriting: frames then queue in the interface's own buffer
(which is where a real adapter would report an overrun), never vanish silently here.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from cananalyze.core.errors import CananalyzeError, ProblemLog
from cananalyze.core.frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
)


class LiveError(CananalyzeError):
    """The interface could not be opened or failed while sniffing (one line, exit 2)."""


class LiveOpenError(LiveError):
    """The interface could not be opened: nothing was read, so no output is kept."""


@dataclass(frozen=True)
class HwFilter:
    """An acceptance filter handed to the interface: frames with (id & mask) == can_id & mask."""

    can_id: int
    mask: int
    extended: bool = False

    @classmethod
    def parse(cls, text: str) -> HwFilter:
        """'ID:MASK' in hex (0x optional) or decimal with 0x; ':ext' forces 29-bit."""
        parts = text.split(":")
        if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2].lower() != "ext"):
            raise ValueError(f"filter {text!r}: expected ID:MASK, e.g. 580:780 (hex)")
        try:
            can_id, mask = (int(p, 16) for p in parts[:2])
        except ValueError:
            raise ValueError(f"filter {text!r}: ID and MASK must be hexadecimal") from None
        extended = len(parts) == 3 or can_id > 0x7FF
        if can_id > 0x1FFFFFFF or mask > 0x1FFFFFFF:
            raise ValueError(f"filter {text!r}: identifiers have at most 29 bits")
        return cls(can_id, mask, extended)

    def as_python_can(self) -> dict:
        return {"can_id": self.can_id, "can_mask": self.mask, "extended": self.extended}


def open_bus(
    interface: str | None = None,
    channel: str | None = None,
    bitrate: int | None = None,
    filters: list[HwFilter] | None = None,
    **options,
):
    """can.Bus with only the given settings; python-can's config file/environment fill the rest."""
    import can

    kwargs = dict(options)
    if interface:
        kwargs["interface"] = interface
    if channel is not None:
        kwargs["channel"] = channel
    if bitrate:
        kwargs["bitrate"] = bitrate
    if filters:
        kwargs["can_filters"] = [f.as_python_can() for f in filters]
    where = " ".join(x for x in (interface or "", str(channel) if channel is not None else "") if x)
    where = where or "python-can default interface"
    try:
        return can.Bus(**kwargs)
    except can.CanInterfaceNotImplementedError as exc:
        if not interface and "None" in str(exc):  # nothing given, nothing configured
            raise LiveError(
                "no CAN interface given: name one with -i/--interface and -c/--channel "
                "(e.g. -i socketcan -c can0, -i virtual -c test), or set a default in "
                "python-can's configuration file (~/.canrc) or CAN_INTERFACE/CAN_CHANNEL"
            ) from None
        raise LiveError(f"{where}: interface not available: {exc}") from None
    except (can.CanError, OSError, ValueError, TypeError, ImportError) as exc:
        raise LiveError(f"{where}: cannot open: {exc}") from None


class LiveSource:
    """Drains `bus.recv()` on a thread into a ring; `batches()` yields FrameBatches.

    `channel_name` labels frames whose Message has no channel (slcan, serial).
    `batches()` also yields empty batches when the bus is quiet, once per interval,
    so a dashboard can tick (heartbeat ages) without traffic.
    """

    def __init__(
        self,
        bus,
        channel_name: str = "can0",
        interval: float = 0.05,
        batch_max: int = 4096,
        ring_size: int = 1 << 20,
        owns_bus: bool = True,
        name_of: Callable[[object], str] | None = None,
    ) -> None:
        """`bus`: a python-can bus, or a callable that opens one when reading starts (so
        that the outputs are open first: frames the adapter buffers while a viewer starts
        would get their receive times late, bunched together). `name_of(bus)`: the
        channel name, asked once the bus is open."""
        self._open_bus = bus if callable(bus) and not hasattr(bus, "recv") else None
        self._name_of = name_of
        bus = None if self._open_bus is not None else bus
        if bus is not None and name_of is not None:
            channel_name = name_of(bus)
        self.bus = bus
        self.interval = interval
        self.batch_max = batch_max
        self.owns_bus = owns_bus
        self._size = ring_size
        self._ring = FrameBatch.allocate(ring_size)
        self._default_channel = channel_name
        self._channels: list[str] = [channel_name]
        self._channel_index: dict[object, int] = {None: 0, channel_name: 0}
        self.received = 0  # frames written into the ring (monotonic)
        self.consumed = 0  # frames handed out as batches (monotonic)
        self.high_water = 0  # most frames ever waiting in the ring
        self.stalls = 0  # times the reader found the ring full and waited
        self.error: str | None = None
        # what pipeline.Source asks of every source (a live bus has no unreadable lines)
        self.path = "live"
        self.problems = ProblemLog()
        self._stop = threading.Event()
        self._wake = threading.Event()  # batch_max frames waiting
        self._space = threading.Condition()
        self._thread = threading.Thread(
            target=self._read, name="cananalyze-live-reader", daemon=True
        )
        self._started = False

    # --- reader thread ----------------------------------------------------
    def _read(self) -> None:
        import can

        r = self._ring
        size = self._size
        # memoryviews: item assignment on them is several times cheaper than on ndarrays
        t_mv = memoryview(r.t)
        id_mv = memoryview(r.can_id)
        fl_mv = memoryview(r.flags)
        dlc_mv = memoryview(r.dlc)
        ch_mv = memoryview(r.channel)
        data_mv = memoryview(r.data).cast("B")
        chan_index = self._channel_index
        recv = self.bus.recv
        stop = self._stop
        batch_max = self.batch_max
        try:
            while not stop.is_set():
                msg = recv(0.05)
                if msg is None:
                    continue
                n = self.received
                if n - self.consumed >= size:
                    self._wait_for_space()
                    if stop.is_set() and n - self.consumed >= size:
                        break
                i = n % size
                t_mv[i] = msg.timestamp
                id_mv[i] = msg.arbitration_id
                fl = 0
                if msg.is_extended_id:
                    fl |= FLAG_EXT
                if msg.is_remote_frame:
                    fl |= FLAG_RTR
                if msg.is_error_frame:
                    fl |= FLAG_ERR
                if msg.is_fd:
                    fl |= (
                        FLAG_FD
                        | (FLAG_BRS if msg.bitrate_switch else 0)
                        | (FLAG_ESI if msg.error_state_indicator else 0)
                    )
                if not msg.is_rx:
                    fl |= FLAG_TX
                fl_mv[i] = fl
                if msg.is_remote_frame:
                    dlc_mv[i] = min(msg.dlc, 255)
                else:
                    data = msg.data
                    k = len(data)
                    dlc_mv[i] = k
                    if k > 8:
                        self._long[n] = bytes(data)
                        data_mv[i * 8 : i * 8 + 8] = data[:8]
                    elif k:
                        data_mv[i * 8 : i * 8 + k] = data
                ch = chan_index.get(msg.channel)
                if ch is None:
                    ch = self._add_channel(msg.channel)
                ch_mv[i] = ch
                self.received = n + 1
                waiting = n + 1 - self.consumed
                if waiting > self.high_water:
                    self.high_water = waiting
                if waiting >= batch_max:
                    self._wake.set()
        except (can.CanError, OSError, ValueError) as exc:
            self.error = f"{exc}" or exc.__class__.__name__
        finally:
            self._stop.set()
            self._wake.set()

    _long: dict[int, bytes]

    def _add_channel(self, channel) -> int:
        name = str(channel)
        idx = self._channel_index.get(name)
        if idx is None:
            if self._channels == [self._default_channel] and self.received == 0:
                # the interface names its channels itself: use its names from the start
                self._channels[0] = name
                idx = 0
            else:
                idx = len(self._channels)
                self._channels.append(name)
            self._channel_index[name] = idx
        self._channel_index[channel] = idx
        return idx

    def _wait_for_space(self) -> None:
        self.stalls += 1
        self._wake.set()
        with self._space:
            while self.received - self.consumed >= self._size and not self._stop.is_set():
                self._space.wait(0.05)

    # --- consumer ---------------------------------------------------------
    def start(self) -> LiveSource:
        if not self._started:
            if self.bus is None and self._open_bus is not None:
                try:
                    self.bus = self._open_bus()
                except LiveError as exc:
                    raise LiveOpenError(str(exc)) from None
                if self._name_of is not None:
                    name = self._name_of(self.bus)
                    self._default_channel = name
                    self._channels = [name]
                    self._channel_index = {None: 0, name: 0}
            self._long = {}
            self._started = True
            self._thread.start()
        return self

    def stop(self) -> None:
        """Ask the reader to stop; `batches()` then yields what is left and ends."""
        self._stop.set()
        self._wake.set()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    def take(self) -> FrameBatch:
        """Everything received since the last take, as one new FrameBatch (copied out of the ring)."""
        start, end = self.consumed, self.received
        n = end - start
        out = FrameBatch.allocate(n, tuple(self._channels))
        if n:
            r = self._ring
            idx = np.arange(start, end) % self._size
            np.take(r.t, idx, out=out.t)
            np.take(r.can_id, idx, out=out.can_id)
            np.take(r.flags, idx, out=out.flags)
            np.take(r.dlc, idx, out=out.dlc)
            np.take(r.data, idx, axis=0, out=out.data)
            np.take(r.channel, idx, out=out.channel)
            out.line[:] = np.arange(start + 1, end + 1)
            # ring slots are reused: clear bytes beyond each frame's length
            out.data[np.arange(8) >= out.dlc[:, None].astype(np.int64)] = 0
            out.data[(out.flags & FLAG_RTR) != 0] = 0
            if self._long:
                for k in [k for k in self._long if start <= k < end]:
                    out.long_data[k - start] = self._long.pop(k)
        self.consumed = end
        with self._space:
            self._space.notify()
        return out

    def batches(self) -> Iterator[FrameBatch]:
        """FrameBatches as they arrive until stop() or an interface error (then LiveError)."""
        self.start()
        try:
            while True:
                stopped = self._stop.is_set()
                self._wake.wait(self.interval)
                self._wake.clear()
                yield self.take()
                if stopped:
                    break
            self._thread.join(timeout=2.0)
            rest = self.take()
            if len(rest):
                yield rest
        finally:
            self.close()
        if self.error:
            raise LiveError(f"interface error: {self.error}")

    def close(self) -> None:
        self.stop()
        if (
            self._started
            and self._thread.is_alive()
            and threading.current_thread() is not self._thread
        ):
            self._thread.join(timeout=2.0)
        if self.owns_bus and self.bus is not None:
            try:
                self.bus.shutdown()
            except Exception:  # noqa: BLE001 - an adapter gone away cannot be shut down cleanly
                pass
            self.bus = None

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self._channels)
