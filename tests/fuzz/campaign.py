"""Long fuzz campaign over every reader and the decode pipeline (run by hand, not in CI).

    python -m tests.fuzz.campaign --seconds 600 --seed 1

Three input generators, in turn: byte-level mutations of the real logs (bit
flips, inserted/deleted bytes, truncation, swapped and duplicated lines),
token-level substitution of hostile values into real log lines ('-1', '³',
'nan', '1e400', huge numbers, ...), and random frame batches straight into the
decoder. Each input goes through tests.fuzz.harness (open_log, Decoder, text and
JSONL writers, summary), lenient or strict; any exception other than InputError
is a crash, grouped by where it was raised, and the first input of each group is
saved to --out for a regression test.
"""

from __future__ import annotations

import argparse
import random
import re
import time
import traceback
from collections import Counter
from pathlib import Path

from tests.fuzz.harness import decode_all, run_log

ROOT = Path(__file__).resolve().parents[2]
REAL = ROOT.parent / "shared" / "data" / "real"
_NOT_LOGS = (".eds", ".dcf", ".md", ".yml", ".yaml", ".dbc", ".trc.csv", "EDS_Info.txt")
HOSTILE = [
    "-1",
    "+7",
    "0x10",
    "1_0",
    "\xb3",
    "\xb2\xb9",
    "nan",
    "inf",
    "-inf",
    "1e400",
    "",
    "9" * 30,
    "-0",
    "FFFFFFFFFF",
    "1FFFFFFFx",
    "\xff",
    "\x00",
    "0" * 40,
    "1.5.5",
    "1,5",
    "12:34:61",
    "-5.0",
    "1e-400",
    "R",
    "RTR",
    "FD",
    "##",
    "#",
    "(",
    ")",
    "[99]",
    "[-1]",
    "d",
    "Rx",
    "Tx",
    "Error",
    "9" * 400,
]


def _logs() -> list[Path]:
    """The real logs, the samples, and seeds of the binary formats the real logs lack
    (pcap, pcapng, a cooked capture, MCAP, gzip: `tests.fuzz.seeds`)."""
    import tempfile

    from tests.fuzz.seeds import write_seeds

    found = [p for p in REAL.glob("*/*") if p.is_file() and not p.name.endswith(_NOT_LOGS)]
    seeds = write_seeds(Path(tempfile.mkdtemp(prefix="cananalyze-seeds.")))
    return found + sorted((ROOT / "samples").glob("demo.*")) + seeds


def _suffix(p: Path) -> str:
    return "".join(p.suffixes[-2:]) if p.suffix == ".gz" else p.suffix


def mutate_bytes(rng: random.Random, data: bytes) -> bytes:
    d = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        if not d:
            d += b"\n"
        p = rng.randrange(len(d))
        k = rng.randrange(7)
        if k == 0:
            d[p] ^= 1 << rng.randrange(8)
        elif k == 1:
            d[p:p] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        elif k == 2:
            del d[p : p + rng.randint(1, 16)]
        elif k == 3:
            del d[p:]
        elif k == 4:
            d[p] = rng.choice(b"0123456789abcdefxyz#() .;,\n\r\t\x00\xff\xb3-")
        elif k == 5:
            lines = bytes(d).split(b"\n")
            i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
            lines[i], lines[j] = lines[j], lines[i]
            d = bytearray(b"\n".join(lines))
        else:
            d[p:p] = d[rng.randrange(len(d)) :][: rng.randint(1, 200)]
    return bytes(d)


def mutate_tokens(rng: random.Random, data: bytes) -> bytes:
    lines = data.split(b"\n")
    k = rng.randrange(max(1, len(lines) - 40)) if len(lines) > 60 else 0
    keep = lines[:20] + lines[max(20, k) : max(20, k) + 40]
    for _ in range(rng.randint(1, 3)):
        i = rng.randrange(len(keep))
        toks = re.split(rb"(\s+|[;,#()\[\]])", keep[i])
        idx = [
            j
            for j, t in enumerate(toks)
            if t.strip() and t not in (b";", b",", b"#", b"(", b")", b"[", b"]")
        ]
        if idx:
            toks[rng.choice(idx)] = rng.choice(HOSTILE).encode("latin-1")
            keep[i] = b"".join(toks)
    return b"\n".join(keep)


def random_batch(rng: random.Random):
    from cananalyze.core.frames import from_rows

    rows = []
    for _ in range(rng.randint(0, 200)):
        base = rng.choice(
            [0, 0x80, 0x100, 0x180, 0x200, 0x280, 0x380, 0x580, 0x600, 0x700, 0x7E4, 0x7E5]
        )
        can_id = rng.choice(
            [base + rng.randrange(128), rng.randrange(0x800), rng.randrange(1 << 29)]
        )
        size = rng.choice([0, 1, 2, 4, 5, 8, 8, 8, 12, 64])
        data = bytes(
            [
                rng.choice(
                    [0x20, 0x23, 0x2F, 0x40, 0x43, 0x60, 0x80, 0xA0, 0xC0, 0xC2, rng.randrange(256)]
                )
            ]
        )
        data = (data + bytes(rng.randrange(256) for _ in range(size)))[:size]
        flags = rng.randrange(128) if rng.random() < 0.2 else 0
        rows.append((rng.uniform(-1, 1e4), can_id, data, flags & ~0x01, rng.randrange(3)))
    return from_rows(rows, channels=("can0", "can1", "can2"))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="/tmp/cananalyze-fuzz")
    a = ap.parse_args()
    rng = random.Random(a.seed)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    logs = _logs()
    texts = [p for p in logs if p.suffix not in (".blf", ".gz")]
    cache = {p: p.read_bytes() for p in logs}
    crashes: Counter = Counter()
    tried: Counter = Counter()
    t0 = time.time()
    while time.time() - t0 < a.seconds:
        kind = rng.choice(["bytes", "bytes", "tokens", "frames"])
        tried[kind] += 1
        try:
            if kind == "frames":
                decode_all([random_batch(rng) for _ in range(rng.randint(1, 3))])
                continue
            p = rng.choice(logs if kind == "bytes" else texts)
            data = cache[p]
            if len(data) > 200_000 and p.suffix != ".blf":
                s = rng.randrange(len(data) - 100_000)
                data = data[:2000] + data[s : s + 60_000]
            blob = mutate_bytes(rng, data) if kind == "bytes" else mutate_tokens(rng, data)
            suffix = (
                rng.choice([".log", ".asc", ".blf", ".trc", ".csv", ".txt", ""])
                if rng.random() < 0.2
                else _suffix(p)
            )
            run_log(blob, suffix, strict=rng.random() < 0.3)
        except Exception as exc:  # noqa: BLE001 - the point is to catch everything
            frame = traceback.extract_tb(exc.__traceback__)[-1]
            key = (type(exc).__name__, frame.filename.split("cananalyze/")[-1], frame.lineno)
            if key not in crashes and kind != "frames":
                (out / f"crash_{len(crashes) + 1}{suffix}").write_bytes(blob)
            crashes[key] += 1
    total = sum(tried.values())
    print(f"inputs tried: {total} ({dict(tried)}) in {time.time() - t0:.0f} s, seed {a.seed}")
    print(f"distinct crashes: {len(crashes)}")
    for key, n in crashes.most_common():
        print(f"  {n:6d}  {key[0]} at {key[1]}:{key[2]}")


if __name__ == "__main__":
    main()
