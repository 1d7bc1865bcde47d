"""What legal but large input costs (issue 38, item 5): a rules file of many assertions,
and blank lines in every text log format.

Each command runs in a fresh process; for each the best CPU time (user + system, from
wait4) and the largest peak RSS are kept over the repeats.

- rules: `cananalyze check samples/demo.log --rules FILE` with FILE N heartbeat assertions
  (nodes 1..127, six periods, four tolerances, repeated to N; 50,000 make 2.7 MB, under
  the 4 MiB limit), beside the same with no rules file.
- blank lines: per text format, FRAMES frames read (every batch of `open_log`) with and
  without BLANK MiB of empty lines spread between them; the difference per MiB of blank
  lines. The frames read must be the same both ways.

    python benchmarks/bench_bounded.py [--assertions 50000] [--frames 100000] [--blank 10]
        [--repeat 3] [--formats candump,trc,...] [--against DIR] [--out DIR]

`--against DIR`: the same commands on another checkout too (its own package), beside.
"""

from __future__ import annotations

import argparse
import base64
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
FORMATS = ("candump", "asc", "trc", "pycan_csv", "gvret", "ixxat", "canbusanalyzer", "sevcon")


def rules_file(path: Path, n: int) -> Path:
    """N heartbeat assertions for nodes 1..127, periods and tolerances cycling."""
    periods, tols = (100, 50, 200, 1000, 10, 500), (None, 0.1, 0.2, 0.05)
    with open(path, "w") as f:
        f.write("tolerance: 0.1\nassert:\n")
        for i in range(n):
            period = periods[(i // 127) % len(periods)]
            tol = tols[(i // (127 * len(periods))) % len(tols)]
            extra = "" if tol is None else f", tolerance: {tol}"
            f.write(f"  - heartbeat: {{node: {i % 127 + 1}, period_ms: {period}{extra}}}\n")
    return path


def _frames(n: int):
    """(time s, identifier, data) of n frames: SYNC, PDOs, heartbeats of 16 nodes."""
    for i in range(n):
        node = i % 16 + 1
        kind = i % 5
        can_id = (0x80, 0x180 + node, 0x280 + node, 0x700 + node, 0x380 + node)[kind]
        size = (0, 8, 4, 1, 2)[kind]
        data = bytes((i + k) & 0xFF for k in range(size)) if kind != 3 else b"\x05"
        yield 10.0 + i * 0.001, can_id, data


def log_lines(fmt: str, n: int) -> tuple[list[str], list[str], str]:
    """(header lines, one line per frame, line end) of n frames in format `fmt`."""
    head: list[str] = []
    rows: list[str] = []
    end = "\n"
    for i, (t, can_id, data) in enumerate(_frames(n)):
        hx = data.hex().upper()
        spaced = " ".join(hx[k : k + 2] for k in range(0, len(hx), 2))
        if fmt == "candump":
            rows.append(f"({1767225600 + t:.6f}) can0 {can_id:03X}#{hx}")
        elif fmt == "asc":
            rows.append(f"{t:11.6f} 1  {can_id:X}             Rx   d {len(data)} {spaced}".rstrip())
        elif fmt == "trc":
            rows.append(
                f"{i + 1:>7} {t * 1000:13.3f} DT 1      {can_id:04X} Rx -  {len(data)}    {spaced}"
            )
        elif fmt == "pycan_csv":
            b64 = base64.b64encode(data).decode()
            rows.append(f"{1767225600 + t},0x{can_id:08X},0,0,0,{len(data)},{b64}")
        elif fmt == "gvret":
            cells = ",".join(f"{b:02X}" for b in data) + "," * (8 - len(data))
            rows.append(f"{int(t * 1e6)},{can_id:08X},false,0,{len(data)},{cells}")
        elif fmt == "ixxat":
            cs = int(round(t * 100))
            clock = f"00:{cs // 6000:02d}:{cs % 6000 // 100:02d}.{cs % 100:02d}"
            rows.append(f'"{clock}";"{can_id:X}";"Std";"";"{spaced} "')
        elif fmt == "canbusanalyzer":
            when = f"{t:.3f}".replace(".", ",")
            rows.append(f"{when}\t1\t0004\t{can_id:X}\t{len(data)}\t{spaced}\t00000000\t.")
        elif fmt == "sevcon":
            brace = " { " + " ".join(f"0x{b:02X}" for b in data) + " }" if data else ""
            rows.append(f"0x{can_id:04X}   {int(t * 1e4)} - d1.0 0 Unknown{brace}")
        else:
            raise SystemExit(f"unknown format {fmt}")
    if fmt == "asc":
        head = [
            "date Thu Jan 1 10:00:00.000 am 2026",
            "base hex  timestamps absolute",
            "internal events logged",
            "// version 9.0.0",
            "Begin Triggerblock Thu Jan 1 10:00:00.000 am 2026",
            "   0.000000 Start of measurement",
        ]
        rows.append("End TriggerBlock")
    elif fmt == "trc":
        head = [";$FILEVERSION=2.1", ";$STARTTIME=46023.5", ";$COLUMNS=N,O,T,B,I,d,R,L,D", ";"]
    elif fmt == "pycan_csv":
        head = ["timestamp,arbitration_id,extended,remote,error,dlc,data"]
    elif fmt == "gvret":
        head = ["Time Stamp,ID,Extended,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8"]
    elif fmt == "ixxat":
        head = [
            "ASCII Trace IXXAT MiniMon V3  Version: 1.0.0.1271",
            "Date: 01.01.2026",
            "Start time: 10:00:00",
            '"Time";"Identifier (hex)";"Format";"Flags";"Data (hex)"',
        ]
    elif fmt == "canbusanalyzer":
        head = [f"@ TEXT @ 2 @ 64 @ 0 @ {n} @ 10 @ 00:00:00.000 @"]
        end = "\r"
    return head, rows, end


def write_log(path: Path, fmt: str, n: int, blank_mib: float) -> None:
    """The log, with `blank_mib` MiB of empty lines spread evenly between its frames."""
    head, rows, end = log_lines(fmt, n)
    blanks = int(blank_mib * (1 << 20)) // len(end)
    with open(path, "w", encoding="latin-1", newline="") as f:
        f.write("".join(h + end for h in head))
        done = 0
        for i, row in enumerate(rows):
            f.write(row + end)
            want = blanks * (i + 1) // len(rows)
            f.write(end * (want - done))
            done = want


def run(cmd: list[str], cwd: Path) -> tuple[float, float, str]:
    """(CPU seconds, peak RSS MB, stdout) of one child process."""
    env = dict(os.environ, PYTHONPATH=str(cwd))
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, cwd=cwd, env=env, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.stdout.close()
    if os.waitstatus_to_exitcode(status) not in (0, 1):
        raise SystemExit(f"failed ({os.waitstatus_to_exitcode(status)}): {' '.join(cmd)}")
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, out


# reads every batch; prints frames, format, problems and a digest of what was read (the
# line numbers aside: blank lines move them)
READ = (
    "import sys, hashlib; from cananalyze.formats.source import open_log\n"
    "src = open_log(sys.argv[1]); h = hashlib.sha1(); n = 0\n"
    "for b in src.batches():\n"
    "    n += len(b)\n"
    "    for c in (b.t, b.can_id, b.flags, b.dlc, b.data, b.channel): h.update(c.tobytes())\n"
    "print(n, src.ctx.format, src.ctx.problems.count, h.hexdigest())"
)


def best(cmd: list[str], cwd: Path, repeat: int) -> tuple[float, float, str]:
    runs = [run(cmd, cwd) for _ in range(repeat)]
    return min(r[0] for r in runs), max(r[1] for r in runs), runs[0][2]


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--assertions", type=int, default=50_000, help="0: no rules case")
    ap.add_argument("--frames", type=int, default=100_000)
    ap.add_argument("--blank", type=float, default=10.0, help="MiB of blank lines (0: none)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--formats", default=",".join(FORMATS))
    ap.add_argument("--against", type=Path, help="another checkout, measured beside")
    ap.add_argument("--out", type=Path, help="where the inputs are written (default: a temp dir)")
    args = ap.parse_args(argv)
    trees = [("this", ROOT)] + ([("other", args.against.resolve())] if args.against else [])
    if args.against and not (args.against / "cananalyze" / "__init__.py").exists():
        raise SystemExit(f"--against {args.against}: no cananalyze package there")
    py = sys.executable
    with tempfile.TemporaryDirectory(dir=args.out) as tmp:
        out = Path(tmp)
        print(f"CPU seconds (user+system), best of {args.repeat}; peak RSS, largest")
        if args.assertions:
            rules = rules_file(out / "rules.yaml", args.assertions)
            size = rules.stat().st_size / 1e6
            print(f"rules: check samples/demo.log --rules FILE ({args.assertions:,} assertions,"
                  f" {size:.1f} MB)")  # fmt: skip
            for name, tree in trees:
                base = [py, "-m", "cananalyze", "check", str(ROOT / "samples" / "demo.log")]
                cpu0, rss0, _ = best(base, tree, args.repeat)
                cpu, rss, _ = best([*base, "--rules", str(rules)], tree, args.repeat)
                print(f"  {name:5} no rules  CPU {cpu0:7.2f} s  peak RSS {rss0:6.0f} MB")
                print(f"  {name:5} rules     CPU {cpu:7.2f} s  peak RSS {rss:6.0f} MB")
        if args.blank:
            print(f"blank lines: {args.frames:,} frames, with and without {args.blank:g} MiB "
                  "of empty lines")  # fmt: skip
            for fmt in args.formats.split(","):
                plain, blank = out / f"plain.{fmt}", out / f"blank.{fmt}"
                write_log(plain, fmt, args.frames, 0)
                write_log(blank, fmt, args.frames, args.blank)
                for name, tree in trees:
                    cpu0, _, got0 = best([py, "-c", READ, str(plain)], tree, args.repeat)
                    cpu, _, got = best([py, "-c", READ, str(blank)], tree, args.repeat)
                    frames, fmt_read, problems, digest = got.split()
                    same = "same frames" if got == got0 else "FRAMES DIFFER"
                    per = (cpu - cpu0) / args.blank
                    print(
                        f"  {name:5} {fmt:15} {int(frames):>8,} frames  CPU {cpu0:6.2f} s, with "
                        f"blank lines {cpu:6.2f} s: {per:+.3f} s/MiB  ({same}, {fmt_read}, "
                        f"{problems} problems)"
                    )


if __name__ == "__main__":
    main(sys.argv[1:])
