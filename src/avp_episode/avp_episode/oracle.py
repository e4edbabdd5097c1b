"""Ground truth for the ``oracle`` reference method (docs/experiment.md, "Reference bounds") — in-process only.

The ``oracle`` row of Table I is an upper bound, not a method of the paper: its spot selection is given every
other vehicle's **true target spot** and **true future trajectory**, read from the simulator's state
(:class:`avp_sim.core.world.World`). This module is the one place where ground truth reaches an ego
(DEVELOPERS: "ground truth reaches the ego only in a method labelled as an oracle bound"); a profile asks for
it with ``perception.ground_truth: true``, and only ``avp experiment --transport inproc`` can serve it (the live
graph refuses such a profile: :func:`avp_episode.profiles.method_node_params`).

What the oracle knows at step t, for every dynamic vehicle (observed or not):

* its target spot: the spot's belief is set to 1 ("taken") until the vehicle is parked, after eq. (7);
* its future: the states its predefined plan (§III-B) gives from its current state and plan index over
  ``horizon`` seconds, unobstructed — the plan a reactive agent follows unless the ego makes it brake;
* whether it reacts (§III-B: n_pass > 0), for every vehicle and pedestrian: the profile's planner takes it with
  ``collision.reactive_evidence: told`` (:meth:`avp_planner.core.decision.EgoPlanner.tell_reacting`), so the
  bound checks its plans with the braking rule of every agent that reacts and of no other (docs/research/unfreezing.md).
  Its own n_pass stays unknown: the check's look-ahead is ``collision.reactive_steps``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from avp_episode.ego import MethodEgo
from avp_world.kinematics import rollout_vehicle
from avp_world.types import Observation, PredictedTrajectory


@dataclass(frozen=True)
class GroundTruth:
    """What the oracle is told at one step."""

    target_spots: tuple[int, ...]  # spots some dynamic vehicle is heading for
    trajectories: tuple[PredictedTrajectory, ...]  # each dynamic vehicle's planned future
    reacting: frozenset = frozenset()  # (is a pedestrian, id) of every agent that brakes for the ego (n_pass > 0)


def ground_truth(world, horizon: float) -> GroundTruth:
    """The :class:`GroundTruth` of ``world`` (an :class:`avp_sim.core.world.World`) at its current step."""
    dt = world.dt
    n = max(1, int(round(horizon / dt)))
    targets: list[int] = []
    trajs: list[PredictedTrajectory] = []
    for i in np.nonzero(world.is_dynamic)[0]:
        start = int(min(world.plan_index[i], world.plans.shape[1] - 1))
        controls = world.plans[i, start:start + n]
        if len(controls) < n:
            controls = np.concatenate([controls, np.zeros((n - len(controls), 2))])
        states = rollout_vehicle(world.states[i], controls, dt)[1:]
        if int(world.target_spot[i]) >= 0 and np.any(world.plans[i, start:, 0] != 0.0):  # not parked yet
            targets.append(int(world.target_spot[i]))
        trajs.append(PredictedTrajectory(agent_id=int(world.vehicle_ids[i]), poses=states, dt=dt,
                                         length=float(world.vehicle_dims[i, 0]), width=float(world.vehicle_dims[i, 1]),
                                         spot_id=int(world.target_spot[i])))
    reacting = {(False, int(world.vehicle_ids[i])) for i in np.nonzero(world.is_dynamic & (world.passiveness > 0))[0]}
    reacting |= {(True, int(world.ped_ids[j])) for j in np.nonzero(world.ped_pass > 0)[0]}
    return GroundTruth(tuple(targets), tuple(trajs), frozenset(reacting))


def apply_targets(beliefs: np.ndarray, lot, truth: GroundTruth) -> np.ndarray:
    """b_t with every true target spot set to 1 (taken)."""
    b = np.array(beliefs, dtype=float, copy=True)
    for sid in truth.target_spots:
        b[lot.spot_index(sid)] = 1.0
    return b


class OracleEgo(MethodEgo):
    """:class:`~.ego.MethodEgo` of a ``ground_truth`` profile: before each :meth:`step` the runner hands it the
    simulator's :class:`GroundTruth` (:meth:`tell`); the true targets and futures replace §V-B's eq. (8) and
    §V-C."""

    truth: GroundTruth | None = None

    def tell(self, truth: GroundTruth) -> None:
        self.truth = truth

    def predict(self, obs: Observation, b: np.ndarray, intentions: list) -> tuple[np.ndarray, list]:
        if self.truth is None:
            raise ValueError(f"method {self.profile.name!r} is an oracle bound: tell() it the ground truth first")
        truth, self.truth = self.truth, None  # one step's truth is used once
        self.planner.tell_reacting(truth.reacting)  # read only with collision.reactive_evidence: told
        return apply_targets(b, self.lot, truth), list(truth.trajectories)
