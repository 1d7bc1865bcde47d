"""Seeds in the binary formats the real logs lack, each written by an independent writer:
pcap and pcapng of SocketCAN and a Linux cooked capture (scapy), a BLF and an MF4
(python-can's writers, MF4 through asammdf), an MCAP (the mcap library, through
`cananalyze export --mcap`) and a gzip'd candump (gzip).
The CI's short fuzz run and the long campaigns mutate them with the real logs."""

from __future__ import annotations

import gzip
import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "samples" / "demo.log"


def _frames(n: int = 60):
    """(t, identifier, data) of the first `n` frames of samples/demo.log."""
    out = []
    for line in DEMO.read_text().splitlines():
        parts = line.split()
        if len(parts) != 3 or "#" not in parts[2] or "R" in parts[2].split("#")[1]:
            continue  # a comment, a remote request
        ident, data = parts[2].split("#")
        out.append((float(parts[0].strip("()")), int(ident, 16), bytes.fromhex(data)))
        if len(out) == n:
            break
    return out


def write_seeds(folder: Path) -> list[Path]:
    """The seed files, written into `folder` (skipped: a writer that is not installed)."""
    folder.mkdir(parents=True, exist_ok=True)
    frames = _frames()
    made: list[Path] = []
    try:
        from scapy.all import wrpcap, wrpcapng
        from scapy.layers.can import CAN
        from scapy.layers.l2 import CookedLinuxV2
    except ImportError:
        pass
    else:
        pkts = []
        for t, ident, data in frames:
            p = CAN(identifier=ident, length=len(data), data=data)
            p.time = t
            pkts.append(p)
        for name, write in (("seed.pcap", wrpcap), ("seed.pcapng", wrpcapng)):
            write(str(folder / name), pkts)
            made.append(folder / name)
        cooked = []
        for t, ident, data in frames:
            raw = ident.to_bytes(4, "little") + bytes([len(data), 0, 0, 0]) + data.ljust(8, b"\0")
            for pkttype, dt in ((4, 0.0), (0, 0.0001)) if ident >= 0x600 else ((0, 0.0),):
                p = CookedLinuxV2(proto=0x000C, lladdrtype=280, pkttype=pkttype) / raw
                p.time = t + dt
                cooked.append(p)
        wrpcapng(str(folder / "sll2.pcapng"), cooked)
        made.append(folder / "sll2.pcapng")
    try:
        import can
    except ImportError:
        pass
    else:
        with can.BLFWriter(str(folder / "seed.blf")) as w:
            for t, ident, data in frames:
                w.on_message_received(can.Message(timestamp=t, arbitration_id=ident, data=data))
        made.append(folder / "seed.blf")
        if importlib.util.find_spec("asammdf") is not None:
            try:  # python-can's MF4 writer: without asammdf (or with asammdf imported
                # before python-can, a circular import) NotImplementedError
                w = can.MF4Writer(str(folder / "seed.mf4"))
            except NotImplementedError:
                w = None
            if w is not None:
                for k, (t, ident, data) in enumerate(frames):
                    m = can.Message(t, arbitration_id=ident, data=data, channel=k % 2)
                    m.is_extended_id = False
                    w.on_message_received(m)
                w.stop()
                made.append(folder / "seed.mf4")
    head = "\n".join(DEMO.read_text().splitlines()[:60]) + "\n"
    (folder / "seed.log.gz").write_bytes(gzip.compress(head.encode()))
    made.append(folder / "seed.log.gz")
    small = folder / "seed.log"
    small.write_text(head)
    mcap = folder / "seed.mcap"
    done = subprocess.run(
        [sys.executable, "-m", "cananalyze", "export", str(small), "--mcap", str(mcap), "-q"],
        capture_output=True,
    )
    if done.returncode == 0:
        made.append(mcap)
    small.unlink()
    return made
