"""Rule names -> classes: the rules file's vocabulary."""

from __future__ import annotations

from .rule import Rule
from .rules.assert_boot import AssertOperational
from .rules.assert_heartbeat import AssertHeartbeat
from .rules.assert_pdo_rate import AssertPdoRate
from .rules.assert_signal import AssertSignal
from .rules.bootup import BootupRule
from .rules.drive_command import DriveCommandRule
from .rules.drive_fault import DriveFaultRule
from .rules.drive_transition import DriveTransitionRule
from .rules.emcy import EmcyRule
from .rules.errctl_length import ErrctlLengthRule
from .rules.error_frames import ErrorFrameRule
from .rules.guarding import GuardingRule
from .rules.heartbeat import HeartbeatRule
from .rules.pdo_async import PdoAsyncRule
from .rules.pdo_length import PdoLengthRule
from .rules.pdo_state import PdoStateRule
from .rules.pdo_sync import PdoSyncRule
from .rules.pdo_valid import PdoValidRule
from .rules.sdo import SdoRule
from .rules.sync import SyncRule
from .rules.unknown_cobid import UnknownCobIdRule

# Enabled unless the rules file disables them.
RULES: dict[str, type[Rule]] = {
    r.name: r
    for r in (
        HeartbeatRule,
        BootupRule,
        GuardingRule,
        ErrctlLengthRule,
        SyncRule,
        PdoSyncRule,
        PdoAsyncRule,
        PdoStateRule,
        PdoLengthRule,
        PdoValidRule,
        UnknownCobIdRule,
        EmcyRule,
        SdoRule,
        ErrorFrameRule,
        DriveTransitionRule,
        DriveFaultRule,
        DriveCommandRule,
    )
}

# Assertions: stated in the rules file's `assert:` list, each with its own parameters.
ASSERTIONS: dict[str, type[Rule]] = {
    "heartbeat": AssertHeartbeat,
    "pdo_rate": AssertPdoRate,
    "signal": AssertSignal,
    "operational_after_boot": AssertOperational,
}


def default_rules() -> list[Rule]:
    return [cls() for cls in RULES.values()]
