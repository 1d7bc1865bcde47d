"""A plain install does what the project is for; the fleet, the live Foxglove server, MF4
input and the development tools are extras, and a command that needs a missing one says so in one line.

The CLI runs in a subprocess whose `sitecustomize` blocks the named packages' imports (a
meta-path finder raising ModuleNotFoundError, as if they were not installed), so the
packages this environment does have cannot mask an eager import.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import tomllib

import pyarrow.parquet as pq
import pytest
from conftest import ROOT

from cananalyze.core.errors import UsageError
from cananalyze.core.extras import MissingExtra, need

SAMPLES = ROOT / "samples"
# the import names each extra's packages give (pyproject.toml's optional-dependencies)
FLEET = ("dask", "distributed", "bokeh", "duckdb")
FOXGLOVE = ("foxglove",)
MF4 = ("asammdf",)
# [dev]'s own tools and test-only readers and writers: no plain command may need them
DEV_TOOLS = (
    "pytest",
    "hypothesis",
    "pytest_benchmark",
    "importlinter",
    "serial",
    "junitparser",
    "nbclient",
    "nbformat",
    "ipykernel",
    "matplotlib",
    "websockets",
    "scapy",
)

SITECUSTOMIZE = textwrap.dedent(
    """
    import os, sys

    BLOCKED = set(os.environ["CANANALYZE_TEST_BLOCK"].split(","))

    class Blocker:
        def find_spec(self, name, path=None, target=None):
            if name.partition(".")[0] in BLOCKED:
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
            return None

    sys.meta_path.insert(0, Blocker())
    """
)


def blocked_cli(tmp_path, blocked, *args: str) -> subprocess.CompletedProcess:
    """`python -m cananalyze ARGS` with the `blocked` top-level packages not importable."""
    site = tmp_path / "site"
    site.mkdir(exist_ok=True)
    (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(ROOT)])
    env["CANANALYZE_TEST_BLOCK"] = ",".join(blocked)
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=120,
    )


def one_line(out: subprocess.CompletedProcess) -> str:
    lines = out.stderr.splitlines()
    assert len(lines) == 1, out.stderr
    assert "Traceback" not in out.stderr
    return lines[0]


def test_blocker_hides_an_installed_package(tmp_path):
    """The harness itself: a blocked package that is installed here does not import."""
    pytest.importorskip("duckdb")
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
    env = dict(os.environ, PYTHONPATH=str(site), CANANALYZE_TEST_BLOCK="duckdb")
    code = "import duckdb"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.returncode == 1
    assert "ModuleNotFoundError: No module named 'duckdb'" in out.stderr


def test_fleet_without_the_fleet_extra(tmp_path):
    dataset = tmp_path / "dataset"
    out = blocked_cli(tmp_path, FLEET, "fleet", str(SAMPLES / "demo.log"), "--out", str(dataset))
    assert out.returncode == 2
    assert one_line(out) == (
        "cananalyze: error: fleet needs the fleet extra (distributed is not installed): "
        'pip install "cananalyze[fleet]"'
    )
    assert not dataset.exists()  # said before anything is written


def test_query_without_the_fleet_extra(tmp_path):
    out = blocked_cli(tmp_path, FLEET, "query", str(tmp_path), "SELECT 1")
    assert out.returncode == 2
    assert one_line(out) == (
        "cananalyze: error: query needs the fleet extra (duckdb is not installed): "
        'pip install "cananalyze[fleet]"'
    )


def test_live_foxglove_without_the_foxglove_extra(tmp_path):
    # python-can's in-process virtual bus: nothing leaves the process; the sink is refused
    # before the bus is opened
    out = blocked_cli(
        tmp_path,
        FOXGLOVE,
        *("live", "-i", "virtual", "-c", "extras-test", "--plain", "--duration", "0.5"),
        *("--foxglove", "127.0.0.1:0"),
    )
    assert out.returncode == 2
    assert one_line(out) == (
        "cananalyze: error: live --foxglove needs the foxglove extra (foxglove is not "
        'installed): pip install "cananalyze[foxglove]"'
    )


def test_mf4_without_the_mf4_extra(tmp_path):
    """The format is still told from the content; reading it names the extra."""
    path = tmp_path / "x.mf4"
    path.write_bytes(b"MDF     4.10    " + bytes(200))
    out = blocked_cli(tmp_path, MF4, "decode", str(path))
    assert out.returncode == 2
    assert one_line(out) == (
        "cananalyze: error: reading MF4 logs needs the mf4 extra (asammdf is not installed): "
        'pip install "cananalyze[mf4]"'
    )


PLAIN_BLOCKED = FLEET + FOXGLOVE + MF4 + DEV_TOOLS


def test_decode_and_check_without_any_extra(tmp_path):
    out = blocked_cli(tmp_path, PLAIN_BLOCKED, "decode", str(SAMPLES / "demo.log"), "--summary")
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
    assert "frames" in out.stdout and "node 5" in out.stdout

    out = blocked_cli(
        tmp_path,
        PLAIN_BLOCKED,
        *("check", str(SAMPLES / "faults.log"), "--rules", str(SAMPLES / "rules.yaml")),
        *("--network", str(SAMPLES / "network.toml")),
    )
    assert out.returncode == 1, out.stderr  # the faulty sample's violations
    assert "16 violation(s)" in out.stdout


def test_export_and_report_without_any_extra(tmp_path):
    parquet, csv = tmp_path / "parquet", tmp_path / "csv"
    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    out = blocked_cli(
        tmp_path,
        PLAIN_BLOCKED,
        *("export", str(SAMPLES / "demo.log"), "-q"),
        *("--parquet", str(parquet), "--csv", str(csv), "--mcap", str(mcap), "--rrd", str(rrd)),
    )
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
    frames = pq.read_table(parquet / "frames.parquet")
    assert frames.num_rows > 100
    assert (csv / "frames.csv").read_text().count("\n") == frames.num_rows + 1
    assert mcap.read_bytes()[:8] == b"\x89MCAP0\r\n"
    assert rrd.stat().st_size > 1000 and rrd.read_bytes()[:4] == b"RRF2"

    html = tmp_path / "report.html"
    out = blocked_cli(
        tmp_path,
        PLAIN_BLOCKED,
        *("report", str(SAMPLES / "faults.log"), "-o", str(html)),
        *("--rules", str(SAMPLES / "rules.yaml"), "--network", str(SAMPLES / "network.toml")),
    )
    assert out.returncode == 1, out.stderr  # violations, the page written all the same
    assert html.read_text().lstrip().lower().startswith("<!doctype html>")


def test_need_names_the_extra(monkeypatch):
    """In the library too: a MissingExtra (a UsageError) whose text is the CLI's line."""
    monkeypatch.setitem(sys.modules, "duckdb", None)  # `import duckdb` now fails as missing
    with pytest.raises(MissingExtra) as info:
        need("duckdb", "query", "fleet")
    assert isinstance(info.value, UsageError)
    assert (info.value.feature, info.value.extra, info.value.module) == ("query", "fleet", "duckdb")
    assert str(info.value) == (
        'query needs the fleet extra (duckdb is not installed): pip install "cananalyze[fleet]"'
    )
    assert need("json", "x", "fleet") is sys.modules["json"]


def test_need_keeps_a_broken_install_loud(tmp_path, monkeypatch):
    """An installed package that fails to import is not 'missing': its error stays."""
    (tmp_path / "broken_extra_pkg.py").write_text("raise ImportError('bad build')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ImportError, match="bad build") as info:
        need("broken_extra_pkg", "fleet", "fleet")
    assert not isinstance(info.value, MissingExtra)


def test_pyproject_extras():
    """A plain install leaves the extras' packages out; [all] is every extra and [dev] is
    [all] plus the test tools (so `.ci/run`'s `pip install -e ".[dev]"` runs every test)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]

    def names(reqs: list[str]) -> set[str]:
        return {r.split(";")[0].split("[")[0].split(">")[0].split("=")[0].strip() for r in reqs}

    assert names(extras["fleet"]) == {"dask", "bokeh", "duckdb"}
    assert "dask[distributed]>=2024.1" in extras["fleet"]
    assert names(extras["foxglove"]) == {"foxglove-sdk"}
    assert names(extras["mf4"]) == {"asammdf"}
    assert names(extras["s3"]) == {"s3fs"}  # fleet and query over s3:// (core/storage.py)
    assert extras["all"] == ["cananalyze[fleet,foxglove,mf4,s3]"]
    assert "cananalyze[all]" in extras["dev"]
    plain = names(project["dependencies"])
    for extra in ("fleet", "foxglove", "mf4", "s3", "dev"):
        assert not plain & names(extras[extra]), extra
    assert {"pyarrow", "mcap", "rerun-sdk", "plotly", "jinja2", "rich"} <= plain
