"""Putting a simulation together: nodes from profiles, a master running a scenario."""

from __future__ import annotations

import random

from cananalyze.core.frames import FrameBatch
from cananalyze.devices.profile import DeviceProfile
from cananalyze.sim.engine import Simulation
from cananalyze.sim.master import Master
from cananalyze.sim.network import default_network
from cananalyze.sim.node import SimNode
from cananalyze.sim.scenarios import SCENARIOS, script


def build(
    profiles: dict[int, DeviceProfile] | None = None,
    scenario: str = "steady",
    duration: float = 10.0,
    seed: int = 0,
    bitrate: int = 500_000,
    master: bool = True,
    config: dict[int, list[tuple[int, int, int]]] | None = None,
) -> tuple[Simulation, dict[int, SimNode], Master | None]:
    """A Simulation with one SimNode per profile and (optionally) the scenario's master.

    config: per node, stored parameters (index, subindex, value) from a network file.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}")
    profiles = profiles if profiles is not None else default_network()
    sim = Simulation(bitrate=bitrate)
    nodes = {
        nid: sim.add(
            SimNode(nid, prof, random.Random(seed * 1000 + nid), config=(config or {}).get(nid, ()))
        )
        for nid, prof in sorted(profiles.items())
    }
    # the master's rng (SYNC jitter) apart from the nodes' (seed * 1000 + node-ID, 1-127)
    rng = random.Random(seed * 1000)
    m = sim.add(Master(script(scenario, nodes, duration), rng=rng)) if master else None
    return sim, nodes, m


def simulate(
    profiles: dict[int, DeviceProfile] | None = None,
    scenario: str = "steady",
    duration: float = 10.0,
    seed: int = 0,
    bitrate: int = 500_000,
) -> FrameBatch:
    """Frames of a scenario on the simulated clock: deterministic for a seed."""
    sim, _, _ = build(profiles, scenario, duration, seed, bitrate)
    sim.run(duration)
    return sim.batch()
