"""The fast readers and decode give the same tables as decoding through python-can.

Issue 10's equality check: every log is decoded twice, once by the bulk readers
(candump, ASC, BLF, TRC) and once frame by frame through python-can's `LogReader`
(`input_format="pycan"`), and the frames, signals, SDO, events and findings tables
must agree. What legitimately differs is normalised first, each for a stated reason:

- times: compared relative to the first frame, to 1 µs (python-can's TRC reader and
  ours may anchor a file differently);
- channel names: python-can numbers BLF/ASC channels from 0, Vector's files from 1;
  compared as codes;
- error frames: python-can reports a BLF error frame with 8 bytes of driver data and
  an ASC error frame as extended, and its candump reader takes only bus errors
  (CAN_ERR_BUSERROR) for error frames, where SocketCAN flags every error frame with
  CAN_ERR_FLAG. So error-frame rows are compared by time and ID only, and the
  `error_frames` rule's findings are left out (the fast path finds at least as many);
- a classic (not FD) frame whose DLC code is 9-15 carries 8 bytes (ISO 11898-1);
  python-can's TRC reader keeps every byte the line lists (pcan3.trc has two lines
  of 14). Compared as CAN defines them, at most 8 bytes.

python-can cannot read candump's screen format (no times), so the screen-format
real logs are not in this comparison; their own tests cover them.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import cananalyze
from cananalyze.core.frames import FLAG_FD
from cananalyze.formats.logfile import write_log
from tests.conftest import real_file

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "samples"
TABLES = ("frames", "signals", "sdo", "events", "findings")
DEVICES = [f"{k}=dat7014" for k in range(1, 17)]


def _normalised(cap, name: str, err: np.ndarray) -> pd.DataFrame:
    df = getattr(cap, name).reset_index(drop=True).copy()
    t0 = float(cap.frames["t"].iloc[0]) if len(cap.frames) else 0.0
    for col in ("t", "t_start"):
        if col in df:
            df[col] = (df[col].astype(float) - t0).round(6)
    if "channel" in df:
        df["channel"] = df["channel"].cat.codes
    if "bus" in df:  # several buses (findings, nodes): the channel's code, as above
        codes = {c: k for k, c in enumerate(cap.frames["channel"].cat.categories)}
        df["bus"] = df["bus"].map(codes)
    if name == "frames":
        df.loc[err, ["dlc", "flags"]] = 0
        df["data"] = df["data"].astype(object)
        df.loc[err, "data"] = b""
        df["service"] = df["service"].astype(object)
        df.loc[err, "service"] = "error_frame"
        classic = (df["flags"].to_numpy() & FLAG_FD) == 0
        df.loc[classic, "dlc"] = np.minimum(df.loc[classic, "dlc"], 8)
        df.loc[classic, "data"] = df.loc[classic, "data"].map(lambda d: d[:8])
    # what each side concludes about the error frames: the fast path's error_frames
    # finding, or python-can's "unknown 29-bit identifier" for the same frames
    err_ids = {f"0x{i:08X}" for i in cap.frames["can_id"].to_numpy()[err].tolist()}

    def about_error_frames(text: str) -> bool:
        return text.startswith("[error_frames]") or (
            text.startswith("[unknown_cob_id]") and text.split()[-2] in err_ids
        )

    if name == "findings":
        text = "[" + df["rule"].astype(str) + "] " + df["message"].astype(str)
        df = df[~text.map(about_error_frames)].reset_index(drop=True)
    if name == "events":
        df = df[~df["message"].astype(str).map(about_error_frames)].reset_index(drop=True)
    return df


def _assert_same(path: Path, **kw) -> None:
    fast = cananalyze.load(path, **kw)
    slow = cananalyze.load(path, input_format="pycan", **kw)
    assert len(fast.frames) == len(slow.frames) > 0
    err = (fast.frames["service"] == "error_frame").to_numpy()
    assert (slow.frames["service"] == "error_frame").sum() <= err.sum()
    for name in TABLES:
        a, b = _normalised(fast, name, err), _normalised(slow, name, err)
        pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=0, atol=2e-6, obj=name)


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
@pytest.mark.parametrize("stem", ["demo", "commissioning", "faults"])
def test_samples(stem: str, suffix: str) -> None:
    _assert_same(SAMPLES / f"{stem}{suffix}", network=SAMPLES / "network.toml")


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> dict[str, Path]:
    """The benchmark's traffic mix (SDO, EMCY, PDOs of 16 DAT 7014) in three formats."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from generate import generate
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    batch = generate(30_000, seed=7)
    d = tmp_path_factory.mktemp("gen")
    out = {}
    for suffix in (".log", ".asc", ".blf"):
        write_log(batch, d / f"bench{suffix}")
        out[suffix] = d / f"bench{suffix}"
    return out


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_generated_mix_with_devices(generated: dict[str, Path], suffix: str) -> None:
    path = generated[suffix]
    _assert_same(path, device=DEVICES)
    cap = cananalyze.load(path, device=DEVICES)
    assert len(cap.signals) > 10_000 and len(cap.sdo) > 500  # the comparison had content


REAL = [
    ("hilch__canopen-message-interpreter/pcan1.trc", {}),
    ("hilch__canopen-message-interpreter/pcan2.trc", {}),
    ("hilch__canopen-message-interpreter/pcan3.trc", {}),
    ("collin80__SavvyCAN/candump.log", {}),
    ("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log", {}),
    ("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log", {}),
    ("hardbyte__python-can/logfile.asc", {}),
    ("hardbyte__python-can/test_CanMessage.blf", {}),
    ("hardbyte__python-can/test_CanMessage2.blf", {}),
]


@pytest.mark.parametrize("rel,kw", REAL, ids=[r for r, _ in REAL])
@pytest.mark.slow
def test_real_logs(rel: str, kw: dict) -> None:
    _assert_same(real_file(rel), **kw)


def test_a_difference_is_seen(generated: dict[str, Path]) -> None:
    """The comparison is not blind: one changed byte in one frame fails it."""
    fast = cananalyze.load(generated[".log"], device=DEVICES)
    frames = _normalised(fast, "frames", np.zeros(len(fast.frames), bool))
    changed = frames.copy()
    changed.loc[100, "data"] = b"\xff" + changed.loc[100, "data"][1:]
    assert not np.array_equal(frames["data"].to_numpy(), changed["data"].to_numpy())
    with pytest.raises(AssertionError):
        pd.testing.assert_frame_equal(frames, changed, obj="frames")
