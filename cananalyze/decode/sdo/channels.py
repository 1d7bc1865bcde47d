"""Which COB-IDs carry SDO, for which node, and in which direction.

The default server channel of node n (0x600+n / 0x580+n) always exists. Extra
channels come from the SDO parameter objects (CiA 301 0x1200-0x127F server,
0x1280-0x12FF client), either declared by the user or learnt from writes seen
in the log, so that traffic on them is reassembled too.
"""

from __future__ import annotations

from dataclasses import dataclass

COB_MASK = 0x7FF
COB_INVALID = 1 << 31


@dataclass(frozen=True)
class SdoChannel:
    node: int  # the SDO server's node-ID (whose object dictionary is accessed)
    request_cob: int  # client -> server
    response_cob: int  # server -> client


class ChannelTable:
    """COB-ID -> channel lookup; explicit channels take precedence over defaults."""

    def __init__(self) -> None:
        self._by_cob: dict[int, tuple[SdoChannel, bool]] = {}
        # Partly seen SDO parameter records: (node, index) -> {subindex: value}.
        self._params: dict[tuple[int, int], dict[int, int]] = {}

    def add(self, node: int, request_cob: int, response_cob: int) -> SdoChannel:
        channel = SdoChannel(node, request_cob, response_cob)
        self._by_cob[request_cob] = (channel, True)
        self._by_cob[response_cob] = (channel, False)
        return channel

    def remove(self, request_cob: int, response_cob: int) -> None:
        for cob in (request_cob, response_cob):
            self._by_cob.pop(cob, None)

    def explicit(self) -> list[int]:
        """COB-IDs of channels declared or learnt (not the predefined 0x600+n/0x580+n)."""
        return list(self._by_cob)

    def lookup(self, cob_id: int) -> tuple[SdoChannel, bool] | None:
        found = self._by_cob.get(cob_id)
        if found is not None:
            return found
        if 0x601 <= cob_id <= 0x67F:
            node = cob_id - 0x600
            return SdoChannel(node, cob_id, 0x580 + node), True
        if 0x581 <= cob_id <= 0x5FF:
            node = cob_id - 0x580
            return SdoChannel(node, 0x600 + node, cob_id), False
        return None

    def learn(self, node: int, index: int, subindex: int, value: int) -> SdoChannel | None:
        """Follow a completed write to an SDO parameter object; return a channel it created.

        Server parameter (0x1201-0x127F) on node n: sub1 = COB-ID client->server,
        sub2 = server->client, the server being n. Client parameter (0x1280-0x12FF):
        sub1, sub2 likewise, sub3 = the server's node-ID (needed before we add it).
        Bit 31 set means "not valid": the channel is removed.
        """
        if not (0x1201 <= index <= 0x12FF) or subindex not in (1, 2, 3):
            return None
        params = self._params.setdefault((node, index), {})
        old = self._channel_of(node, index, params)
        params[subindex] = value
        new = self._channel_of(node, index, params)
        if old is not None and old != new:
            self.remove(old.request_cob, old.response_cob)
        if new is None or new == old:
            return None
        return self.add(new.node, new.request_cob, new.response_cob)

    @staticmethod
    def _channel_of(node: int, index: int, params: dict[int, int]) -> SdoChannel | None:
        req, resp = params.get(1), params.get(2)
        if req is None or resp is None or (req | resp) & COB_INVALID:
            return None
        if index >= 0x1280:
            server = params.get(3)
            if server is None:
                return None
            node = server & 0x7F
        return SdoChannel(node, req & COB_MASK, resp & COB_MASK)
