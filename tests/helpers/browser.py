"""Headless Chromium driven over the DevTools protocol (websockets on 127.0.0.1).

Opens a local file, waits until the page says it is ready, and returns what a
person would see: the console errors and exceptions, a screenshot of the first
screen and answers to JavaScript questions. The browser gets no network (the
page must be self-contained) and a fresh profile.
"""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import subprocess
import tempfile
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--remote-debugging-address=127.0.0.1",
    "--remote-debugging-port=0",
    "--proxy-server=127.0.0.1:9",  # any request to the network fails
    "--window-size=1280,900",
]


def chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


@dataclass
class PageView:
    errors: list[str] = field(default_factory=list)  # console errors, exceptions, failed loads
    screenshot: bytes = b""
    answers: dict = field(default_factory=dict)
    ready: bool = False


def view(
    path: str | Path,
    questions: dict[str, str],
    timeout: float = 60.0,
    full_page: bool = False,
    scroll_to: str | None = None,
) -> PageView:
    """Load `path`, wait for document.body.dataset.ready, screenshot the first screen
    (or the whole page; or the screen that starts at the element of id `scroll_to`)."""
    from websockets.sync.client import connect

    exe = chromium()
    assert exe, "no chromium"
    profile = tempfile.mkdtemp(prefix="cananalyze-chromium-")
    proc = subprocess.Popen(
        [exe, *FLAGS, f"--user-data-dir={profile}", "about:blank"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    out = PageView()
    try:
        port = None
        deadline = time.monotonic() + timeout
        while port is None and time.monotonic() < deadline:
            line = proc.stderr.readline()
            m = re.search(r"DevTools listening on ws://127\.0\.0\.1:(\d+)/", line)
            if m:
                port = int(m.group(1))
            elif not line and proc.poll() is not None:
                raise RuntimeError("chromium exited before listening")
        assert port, "chromium did not open its DevTools port"
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
            targets = json.load(r)
        page = next(t for t in targets if t.get("type") == "page")
        with connect(page["webSocketDebuggerUrl"], max_size=64 << 20, open_timeout=10) as ws:
            ids = iter(range(1, 1 << 30))

            def call(method: str, **params):
                mid = next(ids)
                ws.send(json.dumps({"id": mid, "method": method, "params": params}))
                while True:
                    msg = json.loads(ws.recv(timeout=timeout))
                    if msg.get("id") == mid:
                        if "error" in msg:
                            raise RuntimeError(f"{method}: {msg['error']}")
                        return msg.get("result", {})
                    note(msg)

            def note(msg: dict) -> None:
                m, p = msg.get("method"), msg.get("params", {})
                if m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                    out.errors.append(
                        "console: " + " ".join(str(a.get("value", a)) for a in p.get("args", []))
                    )
                elif m == "Runtime.exceptionThrown":
                    d = p.get("exceptionDetails", {})
                    out.errors.append(
                        "exception: " + str(d.get("exception", {}).get("description") or d)
                    )
                elif m == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
                    out.errors.append("log: " + p["entry"].get("text", ""))
                elif m == "Network.loadingFailed":
                    out.errors.append("network: " + str(p.get("errorText")))

            for domain in ("Runtime", "Log", "Page", "Network"):
                call(f"{domain}.enable")
            call(
                "Emulation.setDeviceMetricsOverride",
                width=1280,
                height=900,
                deviceScaleFactor=1,
                mobile=False,
            )
            call("Page.navigate", url=Path(path).resolve().as_uri())
            while time.monotonic() < deadline:
                r = call(
                    "Runtime.evaluate",
                    expression="document.body && document.body.dataset.ready",
                    returnByValue=True,
                )
                if r.get("result", {}).get("value") == "yes":
                    out.ready = True
                    break
                time.sleep(0.2)
            time.sleep(0.5)  # let plotly's last layout pass paint
            for name, expr in questions.items():
                r = call("Runtime.evaluate", expression=expr, returnByValue=True)
                out.answers[name] = r.get("result", {}).get("value")
            if scroll_to:
                call(
                    "Runtime.evaluate",
                    expression=f"document.getElementById({json.dumps(scroll_to)}).scrollIntoView()",
                )
                time.sleep(0.5)
            if full_page:
                r = call(
                    "Runtime.evaluate", expression="document.body.scrollHeight", returnByValue=True
                )
                h = int(r["result"]["value"])
                call(
                    "Emulation.setDeviceMetricsOverride",
                    width=1280,
                    height=h,
                    deviceScaleFactor=1,
                    mobile=False,
                )
                time.sleep(1.0)
            shot = call("Page.captureScreenshot", format="png")
            out.screenshot = base64.b64decode(shot["data"])
            # events that arrived after the last call
            try:
                while True:
                    note(json.loads(ws.recv(timeout=0.2)))
            except TimeoutError:
                pass
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
        shutil.rmtree(profile, ignore_errors=True)
    return out


def save_shot(png: bytes, name: str) -> None:
    """Keep a screenshot where the developer asked (CANANALYZE_SHOTS=folder)."""
    folder = os.environ.get("CANANALYZE_SHOTS")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        (Path(folder) / name).write_bytes(png)
