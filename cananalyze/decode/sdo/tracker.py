"""SDO tracker: reassembles every CiA 301 SDO protocol, frame by frame.

Hand-written because no library does this from a passive observer's seat: the
`canopen` package implements client and server ends (and has no block server),
Wireshark's dissector is stateless (block transfers are a TODO there). An
observer must follow both directions, survive logs that start or end
mid-transfer, and report protocol faults instead of swallowing them.

Expedited, segmented (toggle bit), block upload/download (sub-blocks, seqno /
ackseq, blksize changes, retransmission, `n` of the last segment, CRC-16 when
both sides agreed, the server's switch from block to segmented/expedited
upload), and aborts from either side at any point.
"""

from __future__ import annotations

import binascii
from collections.abc import Callable

from cananalyze.core.defaults import SDO_TIMEOUT
from cananalyze.decode.sdo.channels import ChannelTable, SdoChannel
from cananalyze.decode.sdo.transaction import FrameRole, SdoTransaction
from cananalyze.decode.sdo.transfer import PHASE_TEXT, Transfer
from cananalyze.decode.sdo.words import sdo_words
from cananalyze.protocol.datatypes import decode_value
from cananalyze.protocol.sdo import (
    ABORT,
    CCS_BLOCK_DOWNLOAD,
    CCS_BLOCK_UPLOAD,
    CCS_DOWNLOAD_SEGMENT,
    CCS_INITIATE_DOWNLOAD,
    CCS_INITIATE_UPLOAD,
    CCS_UPLOAD_SEGMENT,
    MAX_BLKSIZE,
    NO_MORE_SEGMENTS,
    SCS_BLOCK_DOWNLOAD,
    SCS_BLOCK_UPLOAD,
    SCS_DOWNLOAD_SEGMENT,
    SCS_INITIATE_DOWNLOAD,
    SCS_INITIATE_UPLOAD,
    SCS_UPLOAD_SEGMENT,
    SEQNO_MASK,
    abort_text,
    describe_sdo,
    object_text,
)

ObjectInfo = Callable[[int, int, int], "tuple[str, int] | None"]


def block_crc(data: bytes) -> int:
    """CiA 301 block CRC: CRC-16 CCITT (x^16+x^12+x^5+1), initial value 0 (= XMODEM)."""
    return binascii.crc_hqx(data, 0)


def _mux(index: int | None, subindex: int | None) -> str:
    """' 0x1018:01' after a text, or nothing when the frame named no object."""
    return "" if index is None else " " + object_text(index, subindex)


class SdoTracker:
    """Feed SDO frames in time order; collect finished transactions with `pop_completed()`."""

    def __init__(self, timeout: float = SDO_TIMEOUT, object_info: ObjectInfo | None = None) -> None:
        self.timeout = timeout
        self.object_info = object_info
        self._channels = ChannelTable()
        self._pending: dict[int, Transfer] = {}  # request COB-ID -> transfer in progress
        self._completed: list[SdoTransaction] = []
        # Request COB-ID -> how the last transfer there ended, while no new one started:
        # lets a late abort (a client giving up after our timeout) join it, not stand alone.
        self._ended: dict[int, str] = {}

    # -- channels ---------------------------------------------------------------

    def add_channel(self, node: int, request_cob: int, response_cob: int) -> None:
        """Declare an extra SDO channel (server `node` listens on request_cob)."""
        self._channels.add(node, request_cob, response_cob)

    def extra_cob_ids(self) -> list[int]:
        """COB-IDs of explicit channels, which the predefined set does not classify as SDO."""
        return self._channels.explicit()

    def channel_of(self, cob_id: int) -> tuple[int, bool] | None:
        """(server node, is_request) if `cob_id` carries SDO, else None."""
        found = self._channels.lookup(cob_id)
        if found is None:
            return None
        return found[0].node, found[1]

    # -- feeding ----------------------------------------------------------------

    def feed(self, t: float, cob_id: int, data: bytes, ref: int) -> FrameRole:
        """Take one frame; return its role in its transfer."""
        self.advance(t)
        found = self._channels.lookup(cob_id)
        if found is None:
            return FrameRole("not_sdo", f"COB-ID 0x{cob_id:03X} is not an SDO channel")
        channel, is_request = found
        data = bytes(data)
        xfer = self._pending.get(channel.request_cob)
        if xfer is not None:
            xfer.frames += 1
            xfer.prev_t, xfer.prev_ref = xfer.t_last, xfer.ref
            xfer.t_last = t
            xfer.ref = ref
            if not is_request and xfer.t_first_response is None:
                xfer.t_first_response = t
            if xfer.phase == "segments" and is_request == xfer.sender_is_client:
                if data and data[0] != ABORT:  # seqno 0 with c: never a segment; an abort
                    return self._block_segment(xfer, data)
        if len(data) < 8:
            role = FrameRole("invalid", f"SDO frame with {len(data)} data bytes (8 required)")
            role.problem = role.text
            if xfer is not None:
                self._fail(xfer, role.text)
            return role
        info = describe_sdo(data, is_request)
        if info["command"] == "abort":
            return self._abort(t, channel, is_request, info, ref)
        handler = (self._REQUESTS if is_request else self._RESPONSES).get(info["cs"])
        if handler is None:
            return self._unexpected(xfer, info, is_request)
        return handler(self, t, channel, xfer, data, info, ref)

    def advance(self, t: float) -> None:
        """End transfers idle for longer than `timeout` at time `t`."""
        for xfer in list(self._pending.values()):
            if t - xfer.t_last > self.timeout:
                if xfer.failed:
                    self._finish(xfer, xfer.t_last, "protocol_error")
                else:
                    waited = PHASE_TEXT.get(xfer.phase, xfer.phase)
                    xfer.note(f"no frame within {self.timeout:g} s while waiting for {waited}")
                    self._finish(xfer, xfer.t_last + self.timeout, "timeout")

    def finish(self) -> None:
        """End of log: close every transfer still open."""
        for xfer in list(self._pending.values()):
            if xfer.failed:
                self._finish(xfer, xfer.t_last, "protocol_error")
            elif xfer.t_first_response is None:
                xfer.note("no response before the log ended")
                self._finish(xfer, xfer.t_last, "timeout")
            else:
                xfer.note("log ended mid-transfer")
                self._finish(xfer, xfer.t_last, "protocol_error")

    def pop_completed(self) -> list[SdoTransaction]:
        done, self._completed = self._completed, []
        return done

    # -- endings ----------------------------------------------------------------

    def _finish(
        self,
        xfer: Transfer,
        t: float,
        result: str,
        abort_code: int | None = None,
    ) -> SdoTransaction:
        self._pending.pop(xfer.channel.request_cob, None)
        self._ended[xfer.channel.request_cob] = result
        if result == "ok" and xfer.size is not None and xfer.size != len(xfer.data):
            result = "protocol_error"
            xfer.note(f"size announced {xfer.size}, assembled {len(xfer.data)}")
        ch = xfer.channel
        tx = SdoTransaction(
            t_start=xfer.t_start,
            t=t,
            node=ch.node,
            channel=(ch.request_cob, ch.response_cob),
            direction=xfer.direction,
            protocol=xfer.protocol,
            index=xfer.index,
            subindex=xfer.subindex,
            result=result,
            frames=xfer.frames,
            ref=xfer.ref,
        )
        if xfer.t_first_response is not None:
            tx.latency_ms = round((xfer.t_first_response - xfer.t_start) * 1000.0, 6)
        if xfer.data or result == "ok":
            tx.size = len(xfer.data)
            tx.data = xfer.data.hex()
        elif xfer.size is not None:
            tx.size = xfer.size
        if abort_code is not None:
            tx.abort_code = abort_code
            tx.abort_text = abort_text(abort_code)
        if xfer.failed:
            xfer.notes.insert(0, xfer.failed)
        tx.problems = list(xfer.notes)
        tx.detail = "; ".join(xfer.notes) or None
        self._describe_object(tx, bytes(xfer.data) if result == "ok" else None)
        if result == "ok" and xfer.direction == "download" and xfer.index is not None:
            value = int.from_bytes(xfer.data[:4], "little") if len(xfer.data) >= 4 else None
            if value is not None:
                self._channels.learn(ch.node, xfer.index, xfer.subindex or 0, value)
        self._completed.append(tx)
        return tx

    def _describe_object(self, tx: SdoTransaction, data: bytes | None) -> None:
        if tx.index is None:
            return
        known = self.object_info(tx.node, tx.index, tx.subindex or 0) if self.object_info else None
        if known is not None:
            tx.name, datatype = known
            if data is not None:
                tx.value = decode_value(data, datatype)
        if data is not None:
            tx.words = sdo_words(tx.node, tx.index, tx.subindex, tx.value, data, tx.name,
                                 self.object_info)  # fmt: skip

    def _fail(self, xfer: Transfer, problem: str) -> None:
        """Protocol error: wait for the abort the peer should send, else end as protocol_error."""
        if xfer.failed is None:
            xfer.failed = problem
        else:
            xfer.note(problem)
        xfer.phase = "failed"

    def _abort(
        self, t: float, channel: SdoChannel, is_request: bool, info: dict, ref: int
    ) -> FrameRole:
        side = "client" if is_request else "server"
        code = info.get("abort_code")
        index, subindex = info.get("index"), info.get("subindex")
        text = f"abort by {side}{_mux(index, subindex)}: 0x{code:08X} {info['abort_text']}"
        role = FrameRole("abort", text, index, subindex)
        xfer = self._pending.get(channel.request_cob)
        if xfer is None and self._ended.get(channel.request_cob) in ("timeout", "protocol_error"):
            role.text += (
                f" (the transfer had already ended: {self._ended.pop(channel.request_cob)})"
            )
            return role
        if xfer is None:
            xfer = Transfer(channel, None, None, index, subindex, t, t, ref)  # type: ignore[arg-type]
            if not is_request:
                xfer.t_first_response = t
            cob = channel.request_cob if is_request else channel.response_cob
            xfer.note(
                f"abort by {side} on 0x{cob:03X} (node {channel.node}), "
                "the transfer's start is not in the log"
            )
        else:
            xfer.note(f"aborted by {side}")
            if (index, subindex) != (xfer.index, xfer.subindex) and xfer.index is not None:
                xfer.note(
                    f"abort names{_mux(index, subindex)}, transfer is{_mux(xfer.index, xfer.subindex)}"
                )
        self._finish(xfer, t, "abort", code)
        return role

    def _unexpected(self, xfer: Transfer | None, info: dict, is_request: bool) -> FrameRole:
        command = info["command"]
        index, subindex = info.get("index"), info.get("subindex")
        if xfer is None:
            problem = f"{command} with no transfer in progress"
        elif xfer.phase == "failed":
            return FrameRole(command, f"{command} after a protocol error", index, subindex)
        else:
            problem = f"unexpected {command} while waiting for {PHASE_TEXT[xfer.phase]}"
            self._fail(xfer, problem)
        return FrameRole(command, command.replace("_", " "), index, subindex, problem)

    def _start(
        self,
        t: float,
        channel: SdoChannel,
        xfer: Transfer | None,
        direction: str,
        protocol: str | None,
        info: dict,
        ref: int,
    ) -> Transfer:
        if xfer is not None:
            # This frame belongs to the new transfer, not to the one it cuts short.
            xfer.frames -= 1
            xfer.t_last, xfer.ref = xfer.prev_t, xfer.prev_ref
            self._cut_short(xfer, t)
        self._ended.pop(channel.request_cob, None)
        new = Transfer(
            channel, direction, protocol, info.get("index"), info.get("subindex"), t, t, ref
        )
        self._pending[channel.request_cob] = new
        return new

    def _cut_short(self, xfer: Transfer, t: float) -> None:
        """End the transfer a new initiate request at `t` cuts short (that frame not counted)."""
        if xfer.failed:
            self._finish(xfer, xfer.t_last, "protocol_error")
        elif xfer.t_first_response is None:
            # Unanswered, and the client moved on (its own timeout or a retry).
            waited = (t - xfer.t_start) * 1000.0
            xfer.note(f"no response; the client sent a new request after {waited:.1f} ms")
            self._finish(xfer, t, "timeout")
        else:
            xfer.note("new request on the channel before this transfer ended")
            self._finish(xfer, xfer.t_last, "protocol_error")

    def cut_short(self, request_cob: int, t: float) -> bool:
        """A new expedited initiate request on `request_cob` at `t`, taken elsewhere (the fast
        path): end the transfer in progress there as `feed` would. False when that frame
        would not start a new transfer (a block download's client segments), so `feed` must
        take it."""
        xfer = self._pending.get(request_cob)
        if xfer is None:
            return True
        if xfer.phase == "segments" and xfer.sender_is_client:
            return False
        self._cut_short(xfer, t)
        return True

    def _check_echo(self, xfer: Transfer, info: dict) -> str | None:
        echo = (info.get("index"), info.get("subindex"))
        if echo != (xfer.index, xfer.subindex):
            problem = f"response names{_mux(*echo)}, request was{_mux(xfer.index, xfer.subindex)}"
            self._fail(xfer, problem)
            return problem
        return None

    def _expect(
        self, xfer: Transfer | None, info: dict, direction: str, phase: str, protocol: str | None
    ) -> FrameRole | None:
        """None if `xfer` is in `phase` of a `direction` transfer; else the frame's role."""
        if (
            xfer is not None
            and xfer.direction == direction
            and xfer.phase == phase
            and (protocol is None or xfer.protocol == protocol)
        ):
            return None
        return self._unexpected(xfer, info, True)

    # -- client -> server -------------------------------------------------------

    def _initiate_download(self, t, channel, xfer, data, info, ref) -> FrameRole:
        protocol = "expedited" if info["expedited"] else "segmented"
        new = self._start(t, channel, xfer, "download", protocol, info, ref)
        if info["expedited"]:
            new.data += bytes.fromhex(info["data"])
        elif info["size_indicated"]:
            new.size = info["size"]
        size = f", {info['size']} bytes" if "size" in info else ""
        return FrameRole(
            "initiate_download_request",
            f"{protocol} download request{_mux(new.index, new.subindex)}{size}",
            new.index,
            new.subindex,
        )

    def _initiate_upload(self, t, channel, xfer, data, info, ref) -> FrameRole:
        new = self._start(t, channel, xfer, "upload", None, info, ref)
        return FrameRole(
            "initiate_upload_request",
            f"upload request{_mux(new.index, new.subindex)}",
            new.index,
            new.subindex,
        )

    def _download_segment(self, t, channel, xfer, data, info, ref) -> FrameRole:
        role = self._expect(xfer, info, "download", "seg_req", "segmented")
        if role is not None:
            return role
        xfer.segments += 1
        text = f"segmented download segment {xfer.segments}, toggle {info['toggle']}"
        role = FrameRole("download_segment_request", text, xfer.index, xfer.subindex)
        if info["toggle"] != xfer.toggle:
            role.problem = f"toggle bit not alternated (expected {xfer.toggle})"
            self._fail(xfer, role.problem)
            return role
        xfer.data += bytes.fromhex(info["data"])
        xfer.last = bool(info["c"])
        xfer.phase = "seg_resp"
        if xfer.last:
            role.text += ", last"
        return role

    def _upload_segment(self, t, channel, xfer, data, info, ref) -> FrameRole:
        role = self._expect(xfer, info, "upload", "seg_req", "segmented")
        if role is not None:
            return role
        text = f"segmented upload request {xfer.segments + 1}, toggle {info['toggle']}"
        role = FrameRole("upload_segment_request", text, xfer.index, xfer.subindex)
        if info["toggle"] != xfer.toggle:
            role.problem = f"toggle bit not alternated (expected {xfer.toggle})"
            self._fail(xfer, role.problem)
            return role
        xfer.phase = "seg_resp"
        return role

    def _block_upload_request(self, t, channel, xfer, data, info, ref) -> FrameRole:
        command = info["command"]
        if command == "block_upload_initiate":
            new = self._start(t, channel, xfer, "upload", "block", info, ref)
            new.crc_client = info["crc_supported"]
            new.blksize = info.get("blksize", 0)
            text = f"block upload request{_mux(new.index, new.subindex)}, blksize {new.blksize}"
            if info.get("pst"):
                text += f", protocol switch threshold {info['pst']}"
            return FrameRole(command, text, new.index, new.subindex)
        if command == "block_upload_start":
            role = self._expect(xfer, info, "upload", "start", "block")
            if role is not None:
                return role
            self._new_sub_block(xfer, xfer.blksize)
            return FrameRole(command, "block upload start", xfer.index, xfer.subindex)
        if command == "block_upload_ack":
            role = self._expect(xfer, info, "upload", "ack", "block")
            if role is not None:
                return role
            return self._block_ack(xfer, info, command, "block upload")
        # block_upload_end_response: the client confirms the server's end frame.
        role = self._expect(xfer, info, "upload", "end_resp", "block")
        if role is not None:
            return role
        self._finish(xfer, t, "ok")
        return FrameRole(command, "block upload end confirmed", xfer.index, xfer.subindex)

    def _block_download_request(self, t, channel, xfer, data, info, ref) -> FrameRole:
        command = info["command"]
        if command == "block_download_initiate":
            new = self._start(t, channel, xfer, "download", "block", info, ref)
            new.crc_client = info["crc_supported"]
            new.size = info.get("size")
            size = f", {new.size} bytes" if new.size is not None else ""
            text = f"block download request{_mux(new.index, new.subindex)}{size}"
            return FrameRole(command, text, new.index, new.subindex)
        role = self._expect(xfer, info, "download", "end", "block")
        if role is not None:
            return role
        return self._block_end(xfer, info, command, "block download")

    # -- server -> client -------------------------------------------------------

    def _initiate_upload_response(self, t, channel, xfer, data, info, ref) -> FrameRole:
        command = info["command"]
        if xfer is None or xfer.direction != "upload" or xfer.phase != "init_resp":
            return self._unexpected(xfer, info, False)
        problem = self._check_echo(xfer, info)
        if problem:
            return FrameRole(
                command, "upload response", info.get("index"), info.get("subindex"), problem
            )
        if xfer.protocol == "block":
            xfer.note("server switched from block to normal upload")
        if info["expedited"]:
            xfer.protocol = "expedited"
            # Only the 4-n valid bytes: padding (I-7231D leaves stale bytes there) is dropped.
            xfer.data += bytes.fromhex(info["data"])
            self._finish(xfer, t, "ok")
            text = f"expedited upload response{_mux(xfer.index, xfer.subindex)} = {info['data']}"
            return FrameRole(command, text, xfer.index, xfer.subindex)
        xfer.protocol = "segmented"
        xfer.size = info.get("size")
        xfer.phase = "seg_req"
        size = f", {xfer.size} bytes" if xfer.size is not None else ""
        text = f"segmented upload response{_mux(xfer.index, xfer.subindex)}{size}"
        return FrameRole(command, text, xfer.index, xfer.subindex)

    def _upload_segment_response(self, t, channel, xfer, data, info, ref) -> FrameRole:
        if xfer is None or xfer.phase != "seg_resp" or xfer.direction != "upload":
            return self._unexpected(xfer, info, False)
        xfer.segments += 1
        text = f"segmented upload segment {xfer.segments}, toggle {info['toggle']}"
        role = FrameRole(info["command"], text, xfer.index, xfer.subindex)
        if info["toggle"] != xfer.toggle:
            role.problem = f"toggle bit not echoed (expected {xfer.toggle})"
            self._fail(xfer, role.problem)
            return role
        xfer.data += bytes.fromhex(info["data"])
        xfer.toggle ^= 1
        if info["c"]:
            role.text += ", last"
            self._finish(xfer, t, "ok")
        else:
            xfer.phase = "seg_req"
        return role

    def _initiate_download_response(self, t, channel, xfer, data, info, ref) -> FrameRole:
        command = info["command"]
        if xfer is None or xfer.direction != "download" or xfer.phase != "init_resp":
            return self._unexpected(xfer, info, False)
        if xfer.protocol == "block":
            return self._unexpected(xfer, info, False)
        problem = self._check_echo(xfer, info)
        text = f"download response{_mux(info.get('index'), info.get('subindex'))}"
        if problem:
            return FrameRole(command, text, info.get("index"), info.get("subindex"), problem)
        if xfer.protocol == "expedited":
            self._finish(xfer, t, "ok")
        else:
            xfer.phase = "seg_req"
        return FrameRole(command, text, xfer.index, xfer.subindex)

    def _download_segment_response(self, t, channel, xfer, data, info, ref) -> FrameRole:
        if xfer is None or xfer.phase != "seg_resp" or xfer.direction != "download":
            return self._unexpected(xfer, info, False)
        text = f"segmented download response {xfer.segments}, toggle {info['toggle']}"
        role = FrameRole(info["command"], text, xfer.index, xfer.subindex)
        if info["toggle"] != xfer.toggle:
            role.problem = f"toggle bit not echoed (expected {xfer.toggle})"
            self._fail(xfer, role.problem)
            return role
        xfer.toggle ^= 1
        if xfer.last:
            self._finish(xfer, t, "ok")
        else:
            xfer.phase = "seg_req"
        return role

    def _block_download_response(self, t, channel, xfer, data, info, ref) -> FrameRole:
        command = info["command"]
        if command == "block_download_initiate_response":
            if xfer is None or xfer.protocol != "block" or xfer.phase != "init_resp":
                return self._unexpected(xfer, info, False)
            if xfer.direction != "download":
                return self._unexpected(xfer, info, False)
            problem = self._check_echo(xfer, info)
            if problem:
                return FrameRole(command, "block download response", None, None, problem)
            xfer.crc_server = info["crc_supported"]
            self._new_sub_block(xfer, info.get("blksize", 0))
            text = f"block download response, blksize {xfer.blksize}"
            return FrameRole(command, text, xfer.index, xfer.subindex)
        if command == "block_download_ack":
            if xfer is None or xfer.direction != "download" or xfer.phase != "ack":
                return self._unexpected(xfer, info, False)
            return self._block_ack(xfer, info, command, "block download")
        if command == "block_download_end_response":
            if xfer is None or xfer.direction != "download" or xfer.phase != "end_resp":
                return self._unexpected(xfer, info, False)
            self._finish(xfer, t, "ok")
            return FrameRole(command, "block download end confirmed", xfer.index, xfer.subindex)
        return self._unexpected(xfer, info, False)

    def _block_upload_response(self, t, channel, xfer, data, info, ref) -> FrameRole:
        command = info["command"]
        if command == "block_upload_initiate_response":
            if xfer is None or xfer.protocol != "block" or xfer.phase != "init_resp":
                return self._unexpected(xfer, info, False)
            if xfer.direction != "upload":
                return self._unexpected(xfer, info, False)
            problem = self._check_echo(xfer, info)
            if problem:
                return FrameRole(command, "block upload response", None, None, problem)
            xfer.crc_server = info["crc_supported"]
            xfer.size = info.get("size")
            xfer.phase = "start"
            size = f", {xfer.size} bytes" if xfer.size is not None else ""
            return FrameRole(command, f"block upload response{size}", xfer.index, xfer.subindex)
        if xfer is None or xfer.direction != "upload" or xfer.phase != "end":
            return self._unexpected(xfer, info, False)
        return self._block_end(xfer, info, command, "block upload")

    # -- block helpers ----------------------------------------------------------

    def _new_sub_block(self, xfer: Transfer, blksize: int) -> None:
        xfer.blksize = blksize
        xfer.block = []
        xfer.block_last = False
        xfer.block_gap = False
        xfer.block_seen = 0
        xfer.phase = "segments"

    def _block_segment(self, xfer: Transfer, data: bytes) -> FrameRole:
        seqno, last = data[0] & SEQNO_MASK, bool(data[0] & NO_MORE_SEGMENTS)
        what = "block download" if xfer.direction == "download" else "block upload"
        text = f"{what} segment {seqno}/{xfer.blksize}" + (", last" if last else "")
        role = FrameRole("block_segment", text, xfer.index, xfer.subindex)
        expected = len(xfer.block) + 1
        if seqno == expected and not xfer.block_gap:
            xfer.block.append(data[1:8])
            xfer.block_last = last
        elif seqno < expected:
            role.problem = f"seqno {seqno} repeated (expected {expected})"
        elif not xfer.block_gap:
            role.problem = f"seqno gap: expected {expected}, got {seqno}"
            xfer.block_gap = True
        if role.problem:
            xfer.note(role.problem)
        xfer.block_seen = max(xfer.block_seen, seqno)
        if last or seqno >= xfer.blksize:
            xfer.phase = "ack"
        return role

    def _block_ack(self, xfer: Transfer, info: dict, command: str, what: str) -> FrameRole:
        ackseq, blksize = info.get("ackseq", 0), info.get("blksize", 0)
        text = f"{what} ack {ackseq}, next blksize {blksize}"
        role = FrameRole(command, text, xfer.index, xfer.subindex)
        if ackseq > len(xfer.block):
            role.problem = (
                f"ackseq {ackseq} acknowledges segments not seen in order ({len(xfer.block)})"
            )
            self._fail(xfer, role.problem)
            return role
        for segment in xfer.block[:ackseq]:
            xfer.data += segment
        done = xfer.block_last and ackseq == len(xfer.block)
        if ackseq < xfer.block_seen:
            xfer.note(f"segments {ackseq + 1}..{xfer.block_seen} to be repeated")
        if done:
            xfer.phase = "end"
            return role
        if not 1 <= blksize <= MAX_BLKSIZE:
            role.problem = f"invalid blksize {blksize}"
            self._fail(xfer, role.problem)
            return role
        self._new_sub_block(xfer, blksize)
        return role

    def _block_end(self, xfer: Transfer, info: dict, command: str, what: str) -> FrameRole:
        n, crc = info.get("n", 0), info.get("crc", 0)
        role = FrameRole(command, f"{what} end, n {n}, crc 0x{crc:04X}", xfer.index, xfer.subindex)
        if n:
            if n > 6 or n > len(xfer.data):
                role.problem = f"invalid n {n} in end of block"
                self._fail(xfer, role.problem)
                return role
            del xfer.data[-n:]
        if xfer.crc_client and xfer.crc_server:
            computed = block_crc(bytes(xfer.data))
            if computed != crc:
                role.problem = f"CRC mismatch: frame says 0x{crc:04X}, data gives 0x{computed:04X}"
                self._fail(xfer, role.problem)
                return role
        xfer.phase = "end_resp"
        return role

    _REQUESTS = {
        CCS_DOWNLOAD_SEGMENT: _download_segment,
        CCS_INITIATE_DOWNLOAD: _initiate_download,
        CCS_INITIATE_UPLOAD: _initiate_upload,
        CCS_UPLOAD_SEGMENT: _upload_segment,
        CCS_BLOCK_UPLOAD: _block_upload_request,
        CCS_BLOCK_DOWNLOAD: _block_download_request,
    }
    _RESPONSES = {
        SCS_UPLOAD_SEGMENT: _upload_segment_response,
        SCS_DOWNLOAD_SEGMENT: _download_segment_response,
        SCS_INITIATE_UPLOAD: _initiate_upload_response,
        SCS_INITIATE_DOWNLOAD: _initiate_download_response,
        SCS_BLOCK_DOWNLOAD: _block_download_response,
        SCS_BLOCK_UPLOAD: _block_upload_response,
    }
