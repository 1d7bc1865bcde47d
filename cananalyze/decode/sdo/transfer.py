"""The state of one SDO transfer in progress on one channel.

Phases name what the transfer waits for next:
  init_resp  the server's answer to an initiate request
  seg_req    the client's next segment request (segmented)
  seg_resp   the server's answer to a segment request (segmented)
  start      the client's "start upload" (block upload)
  segments   the sender's block segments (block)
  ack        the receiver's block acknowledgement (block)
  end        the sender's "end block" frame with n and CRC (block)
  end_resp   the receiver's answer to "end block" (block)
  failed     a protocol error was seen; an abort may follow
"""

from __future__ import annotations

from dataclasses import dataclass, field

from cananalyze.decode.sdo.channels import SdoChannel

PHASE_TEXT = {
    "init_resp": "the initiate response",
    "seg_req": "the next segment request",
    "seg_resp": "the segment response",
    "start": "the client's start of block upload",
    "segments": "block segments",
    "ack": "the block acknowledgement",
    "end": "the end of block transfer",
    "end_resp": "the end-of-block response",
    "failed": "an abort after a protocol error",
}


@dataclass
class Transfer:
    channel: SdoChannel
    direction: str  # "upload" / "download"
    protocol: str | None  # None until an upload's response says which
    index: int | None
    subindex: int | None
    t_start: float
    t_last: float
    ref: int
    phase: str = "init_resp"
    frames: int = 1
    t_first_response: float | None = None
    size: int | None = None  # announced by the side that sends the data
    data: bytearray = field(default_factory=bytearray)
    toggle: int = 0
    segments: int = 0
    last: bool = False  # the final segment has been sent (segmented download)
    # Block transfer state.
    crc_client: bool = False
    crc_server: bool = False
    crc: int | None = None
    blksize: int = 0
    block: list[bytes] = field(default_factory=list)  # in-order segments of this sub-block
    block_last: bool = False  # the in-order segments include the one with c=1
    block_gap: bool = False  # a seqno gap was seen: ignore until the ack
    block_seen: int = 0  # highest seqno seen in this sub-block
    failed: str | None = None
    prev_t: float = 0.0  # t_last / ref before the frame being handled (see SdoTracker._start)
    prev_ref: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def sender_is_client(self) -> bool:
        """Whether the client sends the data (download) or the server (upload)."""
        return self.direction == "download"

    def note(self, text: str) -> None:
        self.notes.append(text)
