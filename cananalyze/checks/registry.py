"""Rule names -> classes: the rules file's vocabulary."""

from __future__ import annotations

from cananalyze.checks.rule import Rule
from cananalyze.checks.rules.assert_boot import AssertOperational
from cananalyze.checks.rules.assert_heartbeat import AssertHeartbeat
from cananalyze.checks.rules.assert_pdo_rate import AssertPdoRate
from cananalyze.checks.rules.assert_signal import AssertSignal
from cananalyze.checks.rules.boot import BootRule
from cananalyze.checks.rules.bootup import BootupRule
from cananalyze.checks.rules.consistency import ConsistencyRule
from cananalyze.checks.rules.drive_command import DriveCommandRule
from cananalyze.checks.rules.drive_fault import DriveFaultRule
from cananalyze.checks.rules.drive_transition import DriveTransitionRule
from cananalyze.checks.rules.emcy import EmcyRule
from cananalyze.checks.rules.errctl_length import ErrctlLengthRule
from cananalyze.checks.rules.error_frames import ErrorFrameRule
from cananalyze.checks.rules.guarding import GuardingRule
from cananalyze.checks.rules.heartbeat import HeartbeatRule
from cananalyze.checks.rules.lss import LssRule
from cananalyze.checks.rules.pdo_async import PdoAsyncRule
from cananalyze.checks.rules.pdo_length import PdoLengthRule
from cananalyze.checks.rules.pdo_state import PdoStateRule
from cananalyze.checks.rules.pdo_sync import PdoSyncRule
from cananalyze.checks.rules.pdo_valid import PdoValidRule
from cananalyze.checks.rules.sdo import SdoRule
from cananalyze.checks.rules.srdo import SrdoRule
from cananalyze.checks.rules.sync import SyncRule
from cananalyze.checks.rules.unknown_cobid import UnknownCobIdRule

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
        ConsistencyRule,
        SrdoRule,
        EmcyRule,
        SdoRule,
        ErrorFrameRule,
        LssRule,
        BootRule,
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
