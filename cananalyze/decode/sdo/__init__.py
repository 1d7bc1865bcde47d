"""Stateful SDO reassembly: frames in, one record per finished transaction out.

Per-frame Python is fine here: SDO traffic is rare next to PDOs and heartbeats,
and every CiA 301 transfer protocol (expedited, segmented, block) needs state.
"""

from cananalyze.decode.sdo.channels import SdoChannel
from cananalyze.decode.sdo.tracker import SdoTracker
from cananalyze.decode.sdo.transaction import FrameRole, SdoTransaction

__all__ = ["FrameRole", "SdoChannel", "SdoTracker", "SdoTransaction"]
