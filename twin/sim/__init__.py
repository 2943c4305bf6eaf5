"""Layer 3: assembles a Simulation from a Scenario: the loop, the scheduler, the topic bus, seeded RNG streams."""

from twin.sim.scenario import Scenario, default_scenario_path
from twin.sim.scenario_file import load_scenario

__all__ = ["Scenario", "default_scenario_path", "load_scenario"]
