"""Replay a log, with its timing, as an slcan adapter on a pseudo-terminal.

For live tests and demos without hardware: `cananalyze live -i slcan -c <pty>` reads
from the slave side while this speaks the slcan ASCII protocol on the master side:
it answers the adapter set-up commands (`S6`, `O`, `C`, `V`, ...) with CR and, once
the channel is opened (`O`/`L`), sends each frame as `t<id><len><data>\\r`. The log is
read with cananalyze's own readers (python-can's candump reader takes error
frames for 29-bit data frames) and paced with python-can's `can.MessageSync`.

    python -m cananalyze.sim.slcan_replay samples/demo.log   # prints the pty path
"""

from __future__ import annotations

import os
import pty
import select
import sys
import time
import tty


def slcan_frame(msg) -> bytes:
    """One frame in the slcan (Lawicel) ASCII protocol, as python-can's slcan reads it."""
    if msg.is_extended_id:
        head = f"{'R' if msg.is_remote_frame else 'T'}{msg.arbitration_id:08X}{msg.dlc:d}"
    else:
        head = f"{'r' if msg.is_remote_frame else 't'}{msg.arbitration_id:03X}{msg.dlc:d}"
    body = "" if msg.is_remote_frame else bytes(msg.data).hex().upper()
    return (head + body + "\r").encode("ascii")


class SlcanAdapter:
    """The adapter side of an slcan link on a pty master fd."""

    def __init__(self, master_fd: int) -> None:
        self.fd = master_fd
        self.opened = False
        self.closed = False
        self.commands: list[str] = []
        self._buf = b""

    def poll(self, timeout: float = 0.0) -> None:
        """Read and answer whatever commands the host sent."""
        while True:
            ready, _, _ = select.select([self.fd], [], [], timeout)
            if not ready:
                return
            try:
                chunk = os.read(self.fd, 4096)
            except OSError:  # host closed its side
                self.closed = True
                return
            if not chunk:
                return
            self._buf += chunk
            while b"\r" in self._buf:
                line, self._buf = self._buf.split(b"\r", 1)
                cmd = line.decode("ascii", "replace")
                self.commands.append(cmd)
                reply = b"\r"
                if cmd.startswith("V"):
                    reply = b"V1013\r"
                elif cmd.startswith("N"):
                    reply = b"NA123\r"
                elif cmd in ("O", "L"):
                    self.opened = True
                elif cmd == "C":
                    self.opened = False
                os.write(self.fd, reply)
            timeout = 0.0

    def wait_open(self, timeout: float = 10.0) -> bool:
        end = time.monotonic() + timeout
        while not self.opened and time.monotonic() < end:
            self.poll(0.05)
        # python-can may close and reopen while setting the bitrate: let it settle
        settle = time.monotonic() + 0.2
        while time.monotonic() < settle:
            self.poll(0.02)
        return self.opened

    def send(self, msg) -> None:
        os.write(self.fd, slcan_frame(msg))


def replay(adapter: SlcanAdapter, log_path: str, timed: bool = True) -> int:
    """Send the log's frames (paced like the original unless timed=False); returns the count.

    Error frames are left out: the slcan protocol has no way to carry them (an adapter
    would report bus errors through its status flags, which python-can does not read).
    """
    import can

    from cananalyze.formats.logs._pycan_writer import to_messages
    from cananalyze.formats.source import read_all

    reader = to_messages(read_all(log_path))
    messages = can.MessageSync(reader, timestamps=True, skip=3600) if timed else reader
    n = 0
    for msg in messages:
        adapter.poll()
        if msg.is_error_frame:
            continue
        adapter.send(msg)
        n += 1
    return n


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if not args:
        print("usage: python -m cananalyze.sim.slcan_replay LOG [--loop]", file=sys.stderr)
        return 2
    master, slave = pty.openpty()
    tty.setraw(slave)
    print(os.ttyname(slave), flush=True)
    adapter = SlcanAdapter(master)
    adapter.wait_open(timeout=3600)
    while True:
        replay(adapter, args[0])
        if "--loop" not in args:
            break
    time.sleep(0.5)
    return 0


if __name__ == "__main__":
    sys.exit(main())
