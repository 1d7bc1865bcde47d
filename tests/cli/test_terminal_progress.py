"""The progress bar on a real pseudo-terminal: drawn only after its delay, and erased
before the first line of results, whichever stream the results go to (issue 44 item 5).

The delay is set through CANANALYZE_PROGRESS_DELAY (0: the bar is drawn at once; a day:
never), so no test depends on how fast the machine is.
"""

from __future__ import annotations

import fcntl
import os
import re
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest
from conftest import SAMPLES

from cananalyze.outputs.progress import DEFAULT_DELAY, DELAY_ENV, DelayedBar, progress_delay

ROOT = Path(__file__).resolve().parents[2]
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
BAR_TEXT = ("decoding", "━", "frames -:--", "%")  # what a drawn bar line holds
FINDING = re.compile(r"[+-]\d+\.\d{3} s node .* \[(warning|error|info)\] ")
NEVER = "86400"


def _on_pty(args: list[str], delay: str, stdout_pty: bool = True) -> tuple[str, str]:
    """Run the CLI with stderr (and stdout unless told) on one pseudo-terminal of 120
    columns; returns what the terminal received and what a piped stdout received."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), **{DELAY_ENV: delay})
    env.pop("NO_COLOR", None)
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    proc = subprocess.Popen(
        [sys.executable, "-m", "cananalyze", *args],
        stdin=subprocess.DEVNULL,
        stdout=slave if stdout_pty else subprocess.PIPE,
        stderr=slave,
        env=env,
        cwd=ROOT,
    )
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:  # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    piped = proc.stdout.read().decode() if proc.stdout is not None else ""
    proc.wait(timeout=60)
    os.close(master)
    return b"".join(chunks).decode("utf-8", "replace"), piped


def _segments(terminal: str) -> list[str]:
    """What each line of the terminal shows piece by piece: split where the cursor goes
    back to the line's start (\\r) or down (\\n), escape sequences removed."""
    return [ANSI.sub("", s) for s in re.split(r"[\r\n]", terminal)]


def _bar_drawn(terminal: str) -> bool:
    return any("decoding" in s and "frames" in s for s in _segments(terminal))


def _assert_no_shared_line(terminal: str, is_result) -> int:
    """No results line has bar text before it on its line; returns the results lines."""
    results = 0
    for seg in _segments(terminal):
        if is_result(seg):
            results += 1
            assert not any(b in seg for b in BAR_TEXT[:2]), f"bar text on a results line: {seg!r}"
    return results


def test_check_bar_is_drawn_then_cleared_before_the_first_finding():
    terminal, _ = _on_pty(["check", str(SAMPLES / "faults.log")], delay="0")
    assert _bar_drawn(terminal)
    n = _assert_no_shared_line(terminal, FINDING.search)
    assert n >= 3
    # every bar drawing comes before the first finding, and the erase (cursor to the
    # line start, line cleared) comes between them
    first = FINDING.search(ANSI.sub("", terminal)).start()
    plain = ANSI.sub("", terminal)
    assert plain.rfind("decoding") < first
    raw_first = terminal.index("[warning]")
    assert "\x1b[2K" in terminal[terminal.rfind("decoding") : raw_first]
    assert "violation(s)" in plain[first:]  # the verdict, after the bar too


def test_check_small_log_draws_no_bar_before_its_delay():
    terminal, _ = _on_pty(["check", str(SAMPLES / "faults.log")], delay=NEVER)
    assert not _bar_drawn(terminal)
    assert "━" not in terminal and "decoding" not in terminal
    assert _assert_no_shared_line(terminal, FINDING.search) >= 3


def test_check_findings_piped_bar_on_the_terminal_still_cleared():
    terminal, piped = _on_pty(["check", str(SAMPLES / "faults.log")], "0", stdout_pty=False)
    assert _bar_drawn(terminal)
    assert FINDING.search(piped) and "━" not in piped and "decoding" not in piped
    # the terminal is left with no bar on it: its last state is an erased line
    assert terminal.rstrip("\r\n").endswith(("\x1b[2K", "\x1b[?25h", "\x1b[2K\x1b[?25h"))


def test_decode_summary_bar_cleared_before_the_summary():
    terminal, _ = _on_pty(["decode", str(SAMPLES / "faults.log"), "--summary"], delay="0")
    assert _bar_drawn(terminal)
    summary = ("frames: 933", "frames per service", "duration: ")
    lines = _assert_no_shared_line(terminal, lambda s: any(w in s for w in summary))
    assert lines == 3
    plain = ANSI.sub("", terminal)
    assert plain.rfind("decoding") < plain.index("frames: 933")


def test_decode_to_the_terminal_never_draws_a_bar():
    """Its lines reach the terminal from the first frame: no bar even with no delay."""
    terminal, _ = _on_pty(["decode", str(SAMPLES / "faults.log")], delay="0")
    assert not _bar_drawn(terminal) and "━" not in terminal
    assert "bootup" in terminal


def test_quiet_and_pipe_draw_no_bar():
    terminal, _ = _on_pty(["check", str(SAMPLES / "faults.log"), "-q"], delay="0")
    assert not _bar_drawn(terminal)
    proc = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", str(SAMPLES / "faults.log")],
        capture_output=True,
        text=True,
        env=dict(os.environ, PYTHONPATH=str(ROOT), **{DELAY_ENV: "0"}),
        cwd=ROOT,
        timeout=60,
    )
    assert "━" not in proc.stderr + proc.stdout and "\x1b" not in proc.stdout


def test_no_color_still_plain_findings_with_the_bar():
    env_terminal, _ = _on_pty(["check", str(SAMPLES / "faults.log"), "--no-color"], delay="0")
    assert _bar_drawn(env_terminal)
    assert _assert_no_shared_line(env_terminal, FINDING.search) >= 3
    after = env_terminal[env_terminal.index("[warning]") :]
    assert "\x1b[33m" not in after  # findings uncoloured


@pytest.mark.parametrize(
    ("value", "expected"),
    [(None, DEFAULT_DELAY), ("0", 0.0), ("2.5", 2.5), ("-1", DEFAULT_DELAY), ("x", DEFAULT_DELAY)],
)
def test_progress_delay_from_the_environment(value, expected):
    env = {} if value is None else {DELAY_ENV: value}
    assert progress_delay(env) == expected
    assert DEFAULT_DELAY == 1.0


def test_delayed_bar_never_starts_after_clear():
    made = []
    bar = DelayedBar(lambda: made.append(1), lambda progress: None, delay=3600)
    bar.update(advance=1, frames=5)
    bar.clear()
    bar._start()  # the timer firing late changes nothing
    assert made == [] and not bar.drawn
