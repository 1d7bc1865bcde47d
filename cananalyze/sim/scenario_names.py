"""The simulator's scenario names, in the order `--scenario`'s help lists them.

Apart from scenarios.py (which builds SCENARIOS from these names) so the CLI's parser
can list them without importing the simulator and numpy.
"""

from __future__ import annotations

SCENARIO_NAMES = (
    "steady",
    "commissioning",
    "faults",
    "commissioning-faults",
    "safety",
    "safety-faults",
    "fd",
)
