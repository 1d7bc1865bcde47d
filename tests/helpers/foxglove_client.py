"""A Foxglove WebSocket protocol client on 127.0.0.1.

It offers both subprotocol names: foxglove-sdk 0.30's server accepts only
"foxglove.sdk.v1" (the protocol's current name), older servers "foxglove.websocket.v1";
the messages are the same (JSON control messages, binary message data: opcode 1,
subscription id u32, log time u64 ns, payload).

Written from the protocol's spec with the `websockets` package, not with foxglove-sdk:
it subscribes to every channel the server advertises and keeps every message it
receives, by topic, as (log time ns, decoded JSON).
"""

from __future__ import annotations

import json
import struct
import threading
import time

# cananalyze's server sends this topic's message last, then waits for its clients to go
from cananalyze.outputs.foxglove.sink import END_TOPIC

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01


class FoxgloveClient:
    def __init__(self, url: str) -> None:
        self.url = url
        self.channels: dict[int, dict] = {}  # channel id -> advertisement
        self.subscribed: dict[int, int] = {}  # subscription id -> channel id
        self.messages: dict[str, list[tuple[int, dict]]] = {}
        self.server_info: dict | None = None
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self, timeout: float = 10.0) -> FoxgloveClient:
        self._thread.start()
        if not self._ready.wait(timeout):
            raise TimeoutError(f"no serverInfo from {self.url}: {self.error}")
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(10)

    def topics_subscribed(self) -> set[str]:
        return {self.channels[c]["topic"] for c in self.subscribed.values()}

    def wait_for(self, topic: str, count: int, timeout: float = 20.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if len(self.messages.get(topic, [])) >= count:
                return True
            time.sleep(0.02)
        return False

    def _run(self) -> None:
        from websockets.exceptions import ConnectionClosed
        from websockets.sync.client import connect

        try:
            with connect(self.url, subprotocols=SUBPROTOCOLS, open_timeout=10) as ws:
                assert ws.subprotocol in SUBPROTOCOLS
                while not self._stop.is_set():
                    try:
                        msg = ws.recv(timeout=0.1)
                    except TimeoutError:
                        continue
                    except ConnectionClosed:
                        break
                    if isinstance(msg, str):
                        self._control(ws, json.loads(msg))
                    elif msg and msg[0] == MESSAGE_DATA:
                        sub, t = struct.unpack_from("<IQ", msg, 1)
                        topic = self.channels[self.subscribed[sub]]["topic"]
                        self.messages.setdefault(topic, []).append((t, json.loads(msg[13:])))
                        if topic == END_TOPIC:  # the server's last: every message is here
                            break
        except BaseException as exc:  # noqa: BLE001 - kept for the test to report
            self.error = exc
            self._ready.set()

    def _control(self, ws, msg: dict) -> None:
        op = msg.get("op")
        if op == "serverInfo":
            self.server_info = msg
            self._ready.set()
        elif op == "advertise":
            subs = []
            for ch in msg["channels"]:
                self.channels[ch["id"]] = ch
                sub = len(self.subscribed) + len(subs) + 1
                subs.append({"id": sub, "channelId": ch["id"]})
            for s in subs:
                self.subscribed[s["id"]] = s["channelId"]
            if subs:
                ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
