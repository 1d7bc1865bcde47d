"""Regenerate the scenario samples: python -m cananalyze.sim.samples samples/

Writes commissioning.{log,asc,blf}, faults.{log,asc,blf} and fd.{log,asc,blf} (CANopen FD:
USDO) from the simulator
(seed 0, the four seed devices at nodes 3, 5, 6, 7) and the demo sample. The
output is byte-for-byte reproducible; a test compares it with the committed files.
"""

from __future__ import annotations

import sys
from pathlib import Path

SAMPLES = {"commissioning": 12.0, "faults": 10.0, "fd": 3.0}  # scenario -> seconds
SEED = 0


def pin_utc() -> None:
    """python-can writes ASC header times in local time: pin it so files are reproducible."""
    import os
    import time

    os.environ["TZ"] = "UTC"
    time.tzset()


def write_samples(out: Path) -> list[Path]:
    from cananalyze.formats.logfile import write_log
    from cananalyze.sim.demo import demo_batch
    from cananalyze.sim.session import simulate

    pin_utc()
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name in ("demo", *SAMPLES):
        if name == "demo":
            batch = demo_batch()
        else:
            batch = simulate(scenario=name, duration=SAMPLES[name], seed=SEED)
        for suffix in (".log", ".asc", ".blf"):
            path = out / f"{name}{suffix}"
            write_log(batch, path)
            written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    out = Path(args[0] if args else "samples")
    for path in write_samples(out):
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
