"""Timeline export cost on a generated log: MCAP (bulk writer vs `mcap`'s Writer), .rrd, Parquet.

The log is decoded once (16 DAT 7014 nodes, so every TPDO is decoded into signals);
each exporter then runs on the same Capture, reporting wall and CPU seconds (CPU is
the fairer figure on a shared machine). The reference MCAP is the same topics and
payloads written one `Writer.add_message` per message, as the exporter did before
the bulk writer. The bulk writer runs first (cold: imports pyarrow, fresh memory)
and again after the reference (warm).

    python benchmarks/bench_export.py [N_FRAMES]     # default 1e6
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from generate import generate  # noqa: E402

from cananalyze.capture import load  # noqa: E402
from cananalyze.io.logfile import write_log  # noqa: E402


def timed(label: str, fn) -> None:
    wall, cpu = time.perf_counter(), time.process_time()
    fn()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(f"{label:<28} wall {wall:6.2f} s   cpu {cpu:6.2f} s", flush=True)


def reference_mcap(cap, path: Path) -> None:
    """Same topics through mcap.writer.Writer, one add_message per message."""
    import json

    import numpy as np
    from mcap.writer import Writer

    from cananalyze.outputs.mcap.topics import topic_streams

    with open(path, "wb") as f:
        w = Writer(f, chunk_size=4 << 20)
        w.start(profile="", library="reference")
        times, chans, datas = [], [], []
        for topic, schema, ns, payload in topic_streams(cap):
            sid = w.register_schema(schema["title"], "jsonschema", json.dumps(schema).encode())
            ch = w.register_channel(topic, "json", sid)
            times.append(ns)
            chans.append(np.full(len(ns), ch))
            datas += [payload[i] for i in range(len(payload))]
        t = np.concatenate(times)
        c = np.concatenate(chans)
        for i in np.argsort(t, kind="stable").tolist():
            w.add_message(
                channel_id=int(c[i]), log_time=int(t[i]), data=datas[i], publish_time=int(t[i])
            )
        w.finish()


def main(argv: list[str]) -> int:
    n = int(float(argv[0])) if argv else 1_000_000
    from cananalyze.outputs.mcap.topics import write_mcap
    from cananalyze.outputs.rerun.send import write_rrd
    from cananalyze.outputs.tables.whole import write_parquet

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        write_log(generate(n), d / "b.log")
        caps = []
        timed(
            f"decode {n:,} frames",
            lambda: caps.append(load(d / "b.log", device=[f"{k}=dat7014" for k in range(1, 17)])),
        )
        cap = caps[0]
        timed("mcap (bulk writer)", lambda: write_mcap(cap, d / "a.mcap"))
        timed("mcap (Writer.add_message)", lambda: reference_mcap(cap, d / "r.mcap"))
        timed("mcap (bulk writer, again)", lambda: write_mcap(cap, d / "a.mcap"))
        timed("rrd", lambda: write_rrd(cap, d / "a.rrd"))
        timed("parquet", lambda: write_parquet(cap, d / "pq"))
        print(
            f"mcap sizes: bulk {(d / 'a.mcap').stat().st_size / 1e6:.1f} MB, "
            f"reference {(d / 'r.mcap').stat().st_size / 1e6:.1f} MB"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
