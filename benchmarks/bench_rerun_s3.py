"""A rerun with nothing to do over N small logs already in a dataset, on a local disk and on
object storage (moto's S3 server on 127.0.0.1): wall, CPU, peak memory and (S3) requests,
with the `logs` table as N loose parts, then `fleet compact`, then the same rerun over the
compacted table.

One generated log (benchmarks/generate.py's healthy bus) is decoded by a real `cananalyze
fleet` run; its parts are the template of N logs, one per copy of the log under its own
name (size and modification time as the file system or the store gives them), each with
its own parts written as a fleet run leaves them: locally all seven tables' (a no-op
rerun must not read them), on S3 the `logs` table's (the other tables are never listed
there by a rerun that decodes nothing). Requests are counted by method from the server's
request log (LIST apart from the other GETs); the inputs' listing is also timed in this
process, page by page (what the store itself costs a rerun).

Each rerun is a fresh `cananalyze fleet` process; with `--against TREE` the same command
runs from that source tree too, interleaved run by run (the machine is shared); figures
are medians over `--repeats` runs. A local dataset is kept in `--out` between runs.

    python benchmarks/bench_rerun_s3.py [N] (default 10000) [--storage s3,local]
        [--repeats 3] [--against /path/to/other/checkout] [--out DIR]
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

BUCKET = "rerun"
INDEX = "_index/logs.parquet"  # the dataset's index of its `logs` rows (fleet/logsindex)
STATES = ("no-index", "loose", "compacted")
FORMAT = 2  # of the local logs and dataset kept in --out: made again when it changes

from bench_fleet import CREDENTIALS, Requests, start_s3  # noqa: E402 - moto's S3, its requests counted


def run(
    args: list[str], requests: Requests | None, errors: Path, tree: Path = ROOT
) -> tuple[float, float, float, dict, str]:
    """(wall, CPU of the process tree, peak RSS in MB (a local run's only: next to the S3
    server, a child starts with this process's size, which its peak keeps), requests,
    stderr) of one
    `cananalyze` process run from `tree`; its stderr goes to a file (a pipe read after
    the end would fill and block it)."""
    env = {**os.environ, "PYTHONPATH": str(tree) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    if requests is not None:
        requests.counts.clear()
    t = time.perf_counter()
    with open(errors, "w+") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "cananalyze", *args], env=env, stderr=err, cwd=errors.parent
        )
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        err.seek(0)
        text = err.read()
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise SystemExit(f"cananalyze {' '.join(args)} exited {code}:\n{text[-2000:]}")
    counts = dict(requests.counts) if requests is not None else {}
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, counts, text


def _lineage(template, values: dict):
    """A copy of a one-log table with its lineage columns (and, for `logs`, its skip key)
    set to `values`."""
    import pyarrow as pa

    from cananalyze.fleet.schema import constant

    cols = {}
    for c in template.column_names:
        col = template[c]
        if c in values:
            if pa.types.is_dictionary(col.type):
                col = constant(values[c], template.num_rows)
            else:
                col = pa.array([values[c]] * template.num_rows).cast(col.type)
        cols[c] = col
    return pa.table(cols, schema=template.schema)


def _parquet(table) -> bytes:
    import pyarrow.parquet as pq

    buf = io.BytesIO()
    pq.write_table(table, buf)
    return buf.getvalue()


def _one_log(work: Path, requests: Requests | None, errors: Path) -> tuple[bytes, Path]:
    """The generated log's bytes and a local dataset a real fleet run made of it."""
    from generate import generate

    from cananalyze.formats.logfile import write_log

    one = work / "one" / "x.log"
    one.parent.mkdir(parents=True, exist_ok=True)
    write_log(generate(300, seed=3), one)
    ds = work / "one-ds"
    shutil.rmtree(ds, ignore_errors=True)
    run(["fleet", str(one.parent), "--out", str(ds), "--workers", "1", "-q"], requests, errors)
    return one.read_bytes(), ds


def compacted(ds: Path, errors: Path) -> Path:
    """A copy of the local dataset `fleet compact`ed, made once beside it and kept."""
    dest = ds.with_name(ds.name + "-compacted")
    stamp = ds.parent / f".compacted-v{FORMAT}"
    if not stamp.exists():
        shutil.rmtree(dest, ignore_errors=True)
        shutil.copytree(ds, dest)
        wall, cpu, _, _, text = run(["fleet", "compact", str(dest)], None, errors)
        print(
            f"compact local: wall {wall:.2f} s, CPU {cpu:.2f} s; {text.strip().splitlines()[-1]}",
            flush=True,
        )
        stamp.touch()
    return dest


def _names(n: int) -> list[str]:
    return [f"logs/logger{i % 100:03d}/run{i:05d}.log" for i in range(n)]


def make_local(out: Path, n: int, errors: Path) -> tuple[Path, Path]:
    """(logs folder, dataset): N copies of the log and every table's N parts, made once
    and kept in `out` (a stamp names N); `compacted` makes the compacted copy."""
    import pyarrow.parquet as pq

    stamp = out / f".made-v{FORMAT}-{n}"
    logs, ds = out / "logs", out / "ds"
    if stamp.exists():
        return logs, ds
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    t = time.perf_counter()
    data, one = _one_log(out, None, errors)
    templates = {
        p.parts[-3]: (p.parent.name, pq.read_table(p)) for p in one.rglob("part-*.parquet")
    }
    for name in _names(n):
        path = out / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
        st = path.stat()
        digest = hashlib.sha256(name.encode()).hexdigest()  # a distinct content each
        values = {"source": str(path), "hash": digest, "size": st.st_size}
        values["mtime_ns"] = st.st_mtime_ns
        for table, (date, template) in templates.items():
            dest = ds / table / date / f"part-{digest}.parquet"
            dest.parent.mkdir(parents=True, exist_ok=True)
            dest.write_bytes(_parquet(_lineage(template, values)))
    shutil.rmtree(one)
    shutil.rmtree(out / "one")
    print(
        f"local: {n} logs of {len(data):,} bytes and their {n * len(templates)} parts "
        f"({len(templates)} tables) in {out}, made in {time.perf_counter() - t:.1f} s",
        flush=True,
    )
    stamp.touch()
    return logs, ds


class S3:
    """moto's S3 server on 127.0.0.1 holding N logs and their N `logs` parts."""

    def __init__(self, n: int, work: Path, errors: Path) -> None:
        import pyarrow.parquet as pq
        import s3fs

        from cananalyze.core import storage

        self.server, self.requests, url = start_s3()
        os.environ.update(CREDENTIALS, AWS_ENDPOINT_URL=url)
        self.fs = fs = s3fs.S3FileSystem(endpoint_url=os.environ["AWS_ENDPOINT_URL"])
        fs.mkdir(BUCKET)
        data, one = _one_log(work, self.requests, errors)
        (part,) = one.glob("logs/date=*/part-*.parquet")
        date, template = part.parent.name, pq.read_table(part)
        t = time.perf_counter()
        names = [f"{BUCKET}/{name}" for name in _names(n)]
        for i in range(0, n, 1000):
            fs.pipe({name: data for name in names[i : i + 1000]})
        fs.invalidate_cache()
        infos = fs.find(f"{BUCKET}/logs", detail=True)
        parts = {}
        for name in names:
            st = storage.stat_of(f"s3://{name}", None, infos[name])
            digest = hashlib.sha256(name.encode()).hexdigest()  # a distinct content each
            values = {"source": f"s3://{name}", "hash": digest, "size": st.size}
            values["mtime_ns"] = st.mtime_ns
            parts[f"{BUCKET}/ds/logs/{date}/part-{digest}.parquet"] = _parquet(
                _lineage(template, values)
            )
        keys = list(parts)
        for i in range(0, n, 1000):
            fs.pipe({k: parts[k] for k in keys[i : i + 1000]})
        self.logs, self.ds = f"s3://{BUCKET}/logs", f"s3://{BUCKET}/ds"
        print(
            f"s3: {n} logs of {len(data):,} bytes and their {n} logs parts in the bucket, "
            f"made in {time.perf_counter() - t:.1f} s",
            flush=True,
        )

    def listing(self) -> str:
        """The inputs listed in this process, each page of 1,000 keys timed (what moto
        takes to answer, with this process's client)."""
        import boto3

        client = boto3.client("s3", endpoint_url=os.environ["AWS_ENDPOINT_URL"])
        pages, keys, t0 = [], 0, time.perf_counter()
        kwargs = {"Bucket": BUCKET, "Prefix": "logs/"}
        while True:
            t = time.perf_counter()
            page = client.list_objects_v2(**kwargs)
            pages.append(time.perf_counter() - t)
            keys += page.get("KeyCount", 0)
            if not page.get("IsTruncated"):
                break
            kwargs["ContinuationToken"] = page["NextContinuationToken"]
        return (
            f"{keys} keys in {len(pages)} LIST pages: {time.perf_counter() - t0:.2f} s, a page "
            f"median {statistics.median(pages) * 1e3:.0f} ms (max {max(pages) * 1e3:.0f} ms)"
        )

    def drop_index(self, ds: str) -> None:
        self.fs.invalidate_cache()
        with contextlib.suppress(FileNotFoundError):
            self.fs.rm(f"{ds}/{INDEX}")

    def stop(self) -> None:
        self.server.stop()


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="?", type=int, default=10_000, help="logs (default 10000)")
    ap.add_argument("--storage", default="s3", help="s3, local or both: s3,local (default s3)")
    ap.add_argument("--repeats", type=int, default=1, help="runs of each rerun; medians (1)")
    ap.add_argument("--against", type=Path, help="another source tree, run interleaved")
    ap.add_argument("--out", type=Path, help="where the local logs and dataset are kept")
    ap.add_argument("--states", default=",".join(STATES), help=f"of {', '.join(STATES)} (all)")
    ap.add_argument(
        "--against-states", help="the states --against runs in (default: all of --states)"
    )
    args = ap.parse_args(argv)
    n = args.logs
    trees = {"this": ROOT} | ({"against": args.against.resolve()} if args.against else {})
    states = args.states.split(",")
    against = (args.against_states or args.states).split(",")
    work = Path(tempfile.mkdtemp(prefix="bench-rerun-"))
    errors = work / "stderr.txt"
    try:
        for storage in args.storage.split(","):
            if storage == "local":
                logs, ds = make_local(args.out or work / "local", n, errors)
                _measure(
                    *(n, "local", str(logs), str(ds), None, trees, args.repeats, errors),
                    states,
                    against,
                    lambda ds: (Path(ds) / INDEX).unlink(missing_ok=True),
                )
            else:
                s3 = S3(n, work, errors)
                try:
                    print(f"s3 listing: {s3.listing()}", flush=True)
                    _measure(
                        *(n, "s3", s3.logs, s3.ds, s3.requests, trees, args.repeats, errors),
                        states,
                        against,
                        s3.drop_index,
                    )
                    print(f"s3 listing: {s3.listing()}", flush=True)
                finally:
                    s3.stop()
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"load average {os.getloadavg()[0]:.1f}")


def _measure(
    n: int,
    storage: str,
    logs: str,
    ds: str,
    requests: Requests | None,
    trees: dict[str, Path],
    repeats: int,
    errors: Path,
    states: list[str],
    against: list[str],
    drop_index,
) -> None:
    """The reruns over the loose `logs` parts without the dataset's index of them (each
    part read: a dataset written before the index, or its first rerun), with it (made by
    an unmeasured first run: the steady state of hourly reruns), then `fleet compact` and
    the reruns again (the index made again first: the compaction rewrote the parts)."""
    label = storage if len(trees) == 1 else None
    everyone = trees
    for state in (s for s in STATES if s in states):
        trees = everyone if state in against else {"this": everyone["this"]}
        if state == "compacted" and requests is None:
            ds = str(compacted(Path(ds), errors))
        elif state == "compacted":
            wall, cpu, _, counts, text = run(["fleet", "compact", ds], requests, errors)
            req = f", requests {_requests(counts)}" if requests is not None else ""
            print(
                f"compact {storage}: wall {wall:.2f} s, CPU {cpu:.2f} s{req}; "
                f"{text.strip().splitlines()[-1]}",
                flush=True,
            )
        rerun = ["fleet", logs, "--out", ds, "--workers", "1"]
        if state != "no-index":
            wall, cpu, rss, counts, _ = run(rerun, requests, errors)
            req = f", requests {_requests(counts)}" if requests is not None else ""
            print(
                f"rerun {storage} {state} 0 (writes the index, not counted): wall {wall:.2f} s, "
                f"CPU {cpu:.2f} s{_rss(rss, requests)}{req}",
                flush=True,
            )
        figs: dict[str, list] = {name: [] for name in trees}
        for r in range(repeats):
            for name, tree in trees.items():
                if state == "no-index":
                    drop_index(ds)
                load = os.getloadavg()[0]
                wall, cpu, rss, counts, text = run(rerun, requests, errors, tree)
                summary = text.strip().splitlines()[0]
                if f"(0 decoded, {n} already in the dataset)" not in summary:
                    raise SystemExit(f"the rerun decoded something: {summary}")
                figs[name].append((wall, cpu, rss))
                req = f", requests {_requests(counts)}" if requests is not None else ""
                who = f"rerun {label or storage + ' ' + name}"
                print(
                    f"{who} {state} {r + 1}: wall {wall:.2f} s, CPU {cpu:.2f} s"
                    f"{_rss(rss, requests)}{req}; load average {load:.1f}; {summary}",
                    flush=True,
                )
        for name, runs in figs.items():
            wall, cpu, rss = (statistics.median(f[i] for f in runs) for i in range(3))
            who = storage if label else f"{storage} {name}"
            print(
                f"median rerun {who} {state} ({len(runs)} runs): wall {wall:.2f} s, CPU "
                f"{cpu:.2f} s{_rss(rss, requests)}",
                flush=True,
            )
        if len(trees) == 2:
            (a, b) = ([statistics.median(f[i] for f in figs[k]) for i in range(2)] for k in trees)
            print(
                f"ratio {storage} {state} this/against: wall {a[0] / b[0]:.2f}, CPU "
                f"{a[1] / b[1]:.2f}",
                flush=True,
            )


def _rss(mb: float, requests: Requests | None) -> str:
    return f", peak RSS {mb:.0f} MB" if requests is None else ""


def _requests(counts: dict) -> str:
    return " ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "none"


if __name__ == "__main__":
    main(sys.argv[1:])
