"""Rule names -> classes: the rules file's vocabulary."""

from __future__ import annotations

from .assert_boot import AssertOperational
from .assert_heartbeat import AssertHeartbeat
from .assert_pdo_rate import AssertPdoRate
from .assert_signal import AssertSignal
from .bootup import BootupRule
from .emcy import EmcyRule
from .error_frames import ErrorFrameRule
from .guarding import GuardingRule
from .heartbeat import HeartbeatRule
from .pdo_async import PdoAsyncRule
from .pdo_length import PdoLengthRule
from .pdo_state import PdoStateRule
from .pdo_sync import PdoSyncRule
from .pdo_valid import PdoValidRule
from .rule import Rule
from .sdo import SdoRule
from .sync import SyncRule
from .unknown_cobid import UnknownCobIdRule

# Enabled unless the rules file disables them.
RULES: dict[str, type[Rule]] = {
    r.name: r
    for r in (
        HeartbeatRule,
        BootupRule,
        GuardingRule,
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
