"""Run episodes in-process (no ROS): the same cores the nodes wrap, for tests and the experiment runner."""

from __future__ import annotations

from collections.abc import Callable

from avp_sim.core.world import World
from avp_world.types import Observation

Controller = Callable[[Observation], tuple[float, float]]


def run_episode(world: World, controller: Controller, max_steps: int | None = None) -> World:
    """Lock-step loop: observe, decide, step — until the episode ends (or ``max_steps``)."""
    n = 0
    while not world.done and (max_steps is None or n < max_steps):
        obs = world.observe()
        v, om = controller(obs)
        world.step(v, om)
        n += 1
    return world
