"""A rerun with nothing to do over N small logs already in an object-storage dataset (moto's
S3 server on 127.0.0.1): wall, CPU and requests with the `logs` table as N loose parts,
then `fleet compact`, then the same rerun over the compacted table.

One generated log (benchmarks/generate.py's healthy bus) is decoded by a real `cananalyze
fleet` run; its `logs` row is the template of N rows, one per uploaded copy of the log
under its own name (size and modification time as the store lists them), written as the
N one-row `logs` parts a fleet run leaves. Requests are counted by method from the
server's request log (LIST apart from the other GETs).

    python benchmarks/bench_rerun_s3.py [N] (default 10000)
"""

from __future__ import annotations

import hashlib
import io
import logging
import os
import socket
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

from bench_fleet import Requests  # noqa: E402 - the S3 server's requests, counted by method


def run(args: list[str], requests: Requests, errors: Path) -> tuple[float, float, dict, str]:
    """(wall, CPU of the process tree, requests, stderr) of one `cananalyze` process;
    its stderr goes to a file (a pipe read after the end would fill and block it)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
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
    return wall, usage.ru_utime + usage.ru_stime, dict(requests.counts), text


def main(argv: list[str]) -> None:
    n = int(argv[0]) if argv else 10_000
    import pyarrow as pa
    import pyarrow.parquet as pq
    import s3fs
    from generate import generate
    from moto.server import ThreadedMotoServer

    from cananalyze.core import storage
    from cananalyze.formats.logfile import write_log

    requests = Requests()
    log = logging.getLogger("werkzeug")
    log.setLevel(logging.INFO)
    log.addHandler(requests)
    log.propagate = False
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)
    server.start()
    os.environ.update(
        AWS_ACCESS_KEY_ID="testing",
        AWS_SECRET_ACCESS_KEY="testing",
        AWS_DEFAULT_REGION="us-east-1",
        AWS_ENDPOINT_URL=f"http://127.0.0.1:{port}",
    )
    work = Path(tempfile.mkdtemp(prefix="bench-rerun-"))
    errors = work / "stderr.txt"
    try:
        fs = s3fs.S3FileSystem(endpoint_url=os.environ["AWS_ENDPOINT_URL"])
        fs.mkdir(BUCKET)
        write_log(generate(300, seed=3), work / "one.log")
        data = (work / "one.log").read_bytes()
        fs.pipe_file(f"{BUCKET}/one/x.log", data)
        ds = f"s3://{BUCKET}/ds"
        run(["fleet", f"s3://{BUCKET}/one", "--out", ds, "--workers", "1", "-q"], requests, errors)
        (part,) = [k for k in fs.find(f"{BUCKET}/ds/logs") if k.endswith(".parquet")]
        date = part.split("date=")[1].split("/")[0]
        with fs.open(part) as f:
            template = pq.read_table(f)
        fs.rm(part)  # its input goes: the N copies are the dataset's logs
        t = time.perf_counter()
        names = [f"{BUCKET}/logs/logger{i % 100:03d}/run{i:05d}.log" for i in range(n)]
        for i in range(0, n, 1000):
            fs.pipe({name: data for name in names[i : i + 1000]})
        fs.invalidate_cache()
        infos = fs.find(f"{BUCKET}/logs", detail=True)
        parts = {}
        for name in names:
            st = storage.stat_of(f"s3://{name}", None, infos[name])
            digest = hashlib.sha256(name.encode()).hexdigest()  # a distinct content each
            cols = {}
            for c in template.column_names:
                col = template[c]
                value = {"source": f"s3://{name}", "hash": digest, "size": st.size}
                value["mtime_ns"] = st.mtime_ns
                if c in value:
                    col = pa.array([value[c]]).cast(col.type)
                cols[c] = col
            buf = io.BytesIO()
            pq.write_table(pa.table(cols, schema=template.schema), buf)
            parts[f"{BUCKET}/ds/logs/date={date}/part-{digest}.parquet"] = buf.getvalue()
        keys = list(parts)
        for i in range(0, n, 1000):
            fs.pipe({k: parts[k] for k in keys[i : i + 1000]})
        print(
            f"rerun: {n} logs of {len(data):,} bytes and their {n} logs parts in the bucket, "
            f"made in {time.perf_counter() - t:.1f} s",
            flush=True,
        )
        rerun = ["fleet", f"s3://{BUCKET}/logs", "--out", ds, "--workers", "1"]
        for label in ("loose", "compacted"):
            if label == "compacted":
                wall, cpu, counts, text = run(["fleet", "compact", ds], requests, errors)
                print(
                    f"compact: wall {wall:.2f} s, CPU {cpu:.2f} s, requests {_requests(counts)}; "
                    f"{text.strip().splitlines()[-1]}",
                    flush=True,
                )
            wall, cpu, counts, text = run(rerun, requests, errors)
            summary = text.strip().splitlines()[0]
            if f"(0 decoded, {n} already in the dataset)" not in summary:
                raise SystemExit(f"the rerun decoded something: {summary}")
            print(
                f"rerun {label}: wall {wall:.2f} s, CPU {cpu:.2f} s, requests "
                f"{_requests(counts)}; {summary}",
                flush=True,
            )
    finally:
        server.stop()
        import shutil

        shutil.rmtree(work, ignore_errors=True)
    print(f"load average {os.getloadavg()[0]:.1f}")


def _requests(counts: dict) -> str:
    return " ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "none"


if __name__ == "__main__":
    main(sys.argv[1:])
