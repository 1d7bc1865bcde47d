"""Live throughput: saturated 1 Mbit/s buses (>= 32,000 frames/s) through python-can's
virtual bus into LiveSource and `pipeline.run` with the sinks `cananalyze live` runs when
stdout is no terminal (the dashboard's state and end summary; --plain adds the decoded
lines, --check the rules and their report, --record and --rrd the recordings), ~10 s.

A producer thread sends CANopen-like traffic (PDOs of 32 nodes, SYNC, heartbeats, an
SDO read now and then) on a local virtual channel. Reports the frames offered and kept
(decoded and through every sink; their rate up to the last one through), frames dropped
(offered minus kept after a drain of up to 10 s; should be 0), how many were still
queued 0.5 s after the last send (a starved process is late, not lossy: the virtual bus
queues), and the latency from a frame's send time to the end of its batch in the last
sink. The load average is printed: compare CPU seconds, wall time follows the machine.

    python benchmarks/bench_live.py [--rate 32000] [--seconds 10] [--network FILE]
        [--device N=KEY | --no-devices] [--check RULES] [--plain] [--record FILE]
        [--rrd FILE] [--foxglove]

Without --network or --device, nodes 1..16 are the DAT 7014 (as bench_decode's): PDOs
are decoded into signals, as users run live; --no-devices: frames only.

--foxglove serves the decode on 127.0.0.1 (an ephemeral port) to a Foxglove WebSocket
client in another process, subscribed to every topic, which counts what it receives.
CPU seconds (user + system of this process) are printed beside the wall time.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import can  # noqa: E402

from cananalyze.formats.live import LiveSource  # noqa: E402
from cananalyze.pipeline import Options, build_checker, build_decoder, run  # noqa: E402
from cananalyze.pipeline.sink import Sink  # noqa: E402

CHANNEL = "bench-live"
DRAIN = 10.0  # s after the last send a loaded machine gets to finish the queued frames
# the device bench_decode gives its 16 nodes (--device N=dat7014): half the producer's 32
# nodes' PDOs decoded into signals, the others' frames only
DEFAULT_DEVICES = [f"{k}=dat7014" for k in range(1, 17)]


def producer(channel: str, rate: float, seconds: float, sent: list[int]) -> None:
    """Send CANopen-like traffic (PDOs, heartbeats, SYNC) at `rate` frames/s in 5 ms bursts.

    Each frame is a new Message put straight onto the receivers' queues of the virtual
    channel, where `VirtualBus.send` puts its copies: send's deepcopy costs 25 µs a frame,
    0.8 of a core at 32k frames/s, held under this process's GIL beside the system under
    test (a real interface's frames cost the sender nothing here). Built by the
    constructor (2 µs), each with its own time stamp, as a driver's recv builds them.
    """
    bus = can.Bus(interface="virtual", channel=channel)
    receivers = [q for q in bus.channel if q is not bus.queue]  # the live reader's queue
    ids = [0x180 + n for n in range(1, 33)] + [0x280 + n for n in range(1, 33)] + [0x080]
    frames = [(i, bytes(range(8))) for i in ids]
    # an SDO read of 0x1017 on node 5 and its answer now and then: the tracker's stateful path
    frames += [
        (0x605, bytes.fromhex("4017100000000000")),
        (0x585, bytes.fromhex("4B17100064000000")),
    ]
    frames += [(0x700 + n, b"\x05") for n in range(1, 5)]
    per_burst = max(1, int(rate * 0.005))
    message = can.Message
    start = time.perf_counter()
    n = 0
    k = 0
    try:
        while (now := time.perf_counter()) - start < seconds:
            due = int((now - start) * rate)
            while n < due:
                for _ in range(min(per_burst, due - n)):
                    cob, data = frames[k % len(frames)]
                    msg = message(
                        timestamp=time.time(),
                        arbitration_id=cob,
                        data=data,
                        is_extended_id=False,
                        channel=channel,
                        is_rx=True,
                    )
                    for q in receivers:
                        q.put(msg)
                    k += 1
                    n += 1
            time.sleep(0.001)
    finally:
        sent[0] = n
        bus.shutdown()


class Measure(Sink):
    """The last sink: frames kept, signal values, and each frame's latency from its send
    time (the producer stamps Messages with time.time()) to the end of its batch here."""

    def __init__(self, start) -> None:
        self.start = start
        self.frames = self.batches = self.signals = 0
        self.last = 0.0  # perf_counter of the last frame through
        self.latency: list[np.ndarray] = []

    def open(self, run) -> None:
        """Opened last: the traffic starts once every sink is ready (rerun takes a second)."""
        super().open(run)
        self.start()

    def write(self, batch) -> None:
        fb = batch.frames
        if len(fb):
            self.latency.append(time.time() - fb.t)
            self.frames += len(fb)
            self.batches += 1
            self.last = time.perf_counter()
        self.signals += sum(len(b.rows) for b in batch.signals)


# A Foxglove WebSocket client (its own process: it must not share this one's GIL) that
# subscribes to every advertised channel and, at the server's end message (or when the
# server goes away), prints the messages it got per topic.
CLIENT = r"""
import json, struct, sys
from websockets.sync.client import connect
from websockets.exceptions import ConnectionClosed
chan, subs, counts = {}, {}, {}
with connect(sys.argv[1], subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"],
             max_queue=None) as ws:
    print("connected", flush=True)
    try:
        while True:
            m = ws.recv()
            if isinstance(m, str):
                m = json.loads(m)
                if m.get("op") == "advertise":
                    new = []
                    for c in m["channels"]:
                        chan[c["id"]] = c["topic"]
                        subs[len(subs) + 1] = c["id"]
                        new.append({"id": len(subs), "channelId": c["id"]})
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
            elif m[0] == 1:
                topic = chan[subs[struct.unpack_from("<I", m, 1)[0]]]
                counts[topic] = counts.get(topic, 0) + 1
                if topic == sys.argv[2]:  # the server's last message: all is here
                    break
    except ConnectionClosed:
        pass
print(json.dumps(counts), flush=True)
"""


def _devices(items: list[str]) -> dict[int, str]:
    out = {}
    for item in items:
        node, _, key = item.partition("=")
        out[int(node, 0)] = key
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=32_000, help="frames/s to offer (default 32000)")
    ap.add_argument("--seconds", type=float, default=10.0, help="how long to send (default 10)")
    ap.add_argument("--network", help="network file for the decoder (PDO decoding of its nodes)")
    ap.add_argument(
        "--device",
        action="append",
        default=[],
        metavar="N=KEY",
        help="as live's (default, without --network: " + " ".join(DEFAULT_DEVICES[:2]) + " ...)",
    )
    ap.add_argument(
        "--no-devices", action="store_true", help="no default devices: frames only, no PDO decoded"
    )
    ap.add_argument("--check", metavar="RULES", help="also run the rules of this rules file")
    ap.add_argument("--plain", action="store_true", help="also the decoded lines (to /dev/null)")
    ap.add_argument("--record", metavar="FILE", help="also record the raw frames (as live does)")
    ap.add_argument("--rrd", metavar="FILE", help="also stream the timelines into an .rrd")
    ap.add_argument("--bitrate", type=int, default=1_000_000, help="for the bus load figures")
    ap.add_argument(
        "--foxglove", action="store_true", help="also serve the decode to a Foxglove client"
    )
    args = ap.parse_args(argv)
    if not (args.device or args.network or args.no_devices):
        args.device = DEFAULT_DEVICES  # PDOs decoded, as users run live

    from cananalyze.outputs.dashboard import DashboardSink
    from cananalyze.outputs.findings import FindingsSink

    sys.setswitchinterval(0.0005)  # as `live` sets it: the reader thread stamps frames on time
    opts = Options(
        network=args.network,
        devices=_devices(args.device),
        rules=args.check,
        checks=bool(args.check),
        bitrate=args.bitrate,
    )
    checker = build_checker(opts) if args.check else None
    decoder = build_decoder(opts, checker)
    devnull = open(os.devnull, "w")  # noqa: SIM115 - closed at the end of main
    sinks: list[Sink] = []
    if args.record:
        from cananalyze.outputs.recording import RecordSink

        sinks.append(RecordSink(args.record))
    if args.rrd:
        from cananalyze.outputs.rerun.sink import RerunLiveSink

        sinks.append(RerunLiveSink(rrd=args.rrd, bitrate=args.bitrate, name="bench live"))
    if args.plain:
        from cananalyze.outputs.text.writer import TextWriter

        sinks.append(TextWriter(devnull, flush=True))
    client = fox = None
    if args.foxglove:
        from cananalyze.outputs.foxglove.sink import END_TOPIC, FoxgloveSink

        fox = FoxgloveSink(port=0, announce=False)
        sinks.append(fox)
    view = DashboardSink(bitrate=args.bitrate, checking=checker is not None, show=False)
    sinks.append(view)
    report = None
    if checker is not None:
        report = FindingsSink(devnull, quiet=True)
        sinks.append(report)
    source = LiveSource(can.Bus(interface="virtual", channel=CHANNEL), channel_name="vcan0")
    sent = [0]
    th = threading.Thread(target=producer, args=(CHANNEL, args.rate, args.seconds, sent))
    started: list[float] = []
    cpu0: list[float] = []

    def start() -> None:
        nonlocal client
        if fox is not None:  # the client subscribes before the traffic starts
            client = subprocess.Popen(
                [sys.executable, "-c", CLIENT, fox.url, END_TOPIC],
                stdout=subprocess.PIPE,
                text=True,
            )
            assert client.stdout.readline().strip() == "connected"
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline and not all(
                ch.has_sinks() for ch in fox._channels.values()
            ):
                time.sleep(0.01)
        started.append(time.perf_counter())
        cpu0.append(_cpu())
        th.start()

    measure = Measure(start)
    sinks.append(measure)
    done: list[float] = []

    behind: list[int] = []  # frames not yet through every sink 0.5 s after the last send

    def stop() -> bool:
        """Once every frame sent is through the sinks, or DRAIN s after the last send (a
        machine that starves this process makes the run late, not lossy: the virtual bus
        queues; what is still queued at the end is counted as dropped)."""
        if not done and started and not th.is_alive():
            done.append(time.monotonic())
        if not done:
            return False
        late = time.monotonic() - done[0]
        if late >= 0.5 and not behind:
            behind.append(sent[0] - measure.frames)
        return (late >= 0.5 and measure.frames >= sent[0]) or late >= DRAIN

    try:
        run(source, decoder, sinks, opts, stop=stop, tick=0.25)
    finally:
        if started:
            th.join()
        source.close()
        devnull.close()
    elapsed = time.perf_counter() - started[0]
    cpu = _cpu() - cpu0[0]
    received = json.loads(client.communicate(timeout=60)[0]) if client is not None else None
    client_cpu = _cpu(resource.RUSAGE_CHILDREN)
    kept = measure.frames
    latency = np.concatenate(measure.latency) * 1e3 if measure.latency else np.zeros(1)
    offered = sent[0]
    names = ", ".join(type(s).__name__ for s in sinks[:-1])
    print(f"sinks    {names}")
    devices = "1..16=dat7014 (default)" if args.device == DEFAULT_DEVICES else " ".join(args.device)
    print(f"devices  {devices or 'none'}; network {args.network or 'none'}")
    print(
        f"offered  {offered} frames in {args.seconds:.1f} s = {offered / args.seconds:,.0f} frames/s"
    )
    print(
        f"kept     {kept} frames = {kept / max(measure.last - started[0], 1e-9):,.0f} frames/s "
        f"to the last one through (wall {elapsed:.1f} s incl. drain), {measure.batches} batches, "
        f"ring high-water {source.high_water}"
    )
    print(f"dropped  {offered - kept}")
    print(f"behind   {behind[0] if behind else 0} frames 0.5 s after the last send (drained after)")
    print(f"cpu      {cpu:.1f} s user+system beside {elapsed:.1f} s wall")
    print("load     {:.1f} {:.1f} {:.1f} (1, 5, 15 min, at the end)".format(*os.getloadavg()))
    if received is not None:
        frames = received.get("/can/frames", 0)
        print(
            f"foxglove {frames} frames and {sum(received.values())} messages on "
            f"{len(received)} topics received by the client ({fox.sent} sent; "
            f"the client, another process, {client_cpu:.1f} s CPU)"
        )
    print(
        f"latency  send -> last sink: median {np.median(latency):.1f} ms, "
        f"p99 {np.percentile(latency, 99):.1f} ms, max {latency.max():.1f} ms"
    )
    print(f"decoded  {measure.signals} PDO frames into signal values ({kept} frames kept)")
    if report is not None:
        print(f"check    {len(report.findings)} findings")
    return 0 if offered == kept else 1


def _cpu(who: int = resource.RUSAGE_SELF) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


if __name__ == "__main__":
    sys.exit(main())
