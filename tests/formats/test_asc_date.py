"""The ASC header date (formats/logs/asc._date) is python-can's reading of it, restated so
that an ASC read does not import python-can: every `date` line of the real and sample
ASC files, and every month name, clock and precision python-can takes, give python-can's
own timestamp (or, where python-can refuses the text, None)."""

from __future__ import annotations

import itertools
import subprocess
import sys

import pytest
from can.io.asc import ASCReader
from conftest import REAL, ROOT, SAMPLES

from cananalyze.formats.logs.asc import _date


def _pycan(text: str) -> float | None:
    try:
        return ASCReader._datetime_to_timestamp(text.strip())
    except ValueError:
        return None


def _header_dates() -> list[str]:
    files = [*SAMPLES.glob("*.asc"), *(REAL.rglob("*.asc") if REAL.exists() else [])]
    out = []
    for path in files:
        with open(path, encoding="latin-1") as f:
            for line in itertools.islice(f, 20):
                tok = line.split(None, 2)
                if tok and tok[0].lower() == "date" and len(tok) > 2:
                    out.append(tok[2])  # as the reader passes it: after the weekday
    return out


MONTHS = "Jan Feb Mar Apr May Jun Jul Aug Sep Oct Nov Dec Mär Mai Okt Dez".split()
SYNTHETIC = [
    f"{m} {d} {clock} {y}"
    for m in MONTHS
    for d, y in (("1", "2017"), ("30", "1999"))
    for clock in (
        "15:06:13.191",
        "15:06:13",
        "03:06:13.191 pm",
        "10:44:52.480 am",
        "10:44:52 AM",
        "12:00:00 PM",
        "00:00:00.0",
    )
] + ["", "garbage", "Sep 31 10:00:00 2017", "Foo 30 15:06:13 2017", "Sep 30 25:00:00 2017"]


def test_every_header_date_we_have_is_read_as_python_can_reads_it():
    dates = _header_dates()
    assert len(dates) >= 6  # the samples' and python-can's own test files
    for text in dates:
        assert _date(text) == _pycan(text), text
    assert any(_date(t) is not None for t in dates)


@pytest.mark.parametrize("text", SYNTHETIC)
def test_month_names_clocks_and_precisions(text):
    assert _date(text) == _pycan(text)


def test_reading_an_asc_imports_no_python_can():
    code = (
        "import sys\nfrom cananalyze.formats.source import open_log\n"
        "n = sum(len(b) for b in open_log(sys.argv[1]).batches())\n"
        "print(n, 'can' in sys.modules)"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(SAMPLES / "faults.asc")],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    frames, imported = done.stdout.split()
    assert int(frames) > 100 and imported == "False", done.stderr
