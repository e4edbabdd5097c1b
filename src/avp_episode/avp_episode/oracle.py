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

Under noisy sensing (``sensing.model`` other than exact) the ego sees tracks, with the tracker's ids, placed in the
map with its pose estimate. :func:`seen_through` then gives the truth as that observation carries it: every future
moved into the estimate's frame (the rigid motion that takes the true ego pose onto the estimate, as the sensor
places its detections), and every agent named by the id of the track that follows it (an optimal one-to-one pairing
within 2 m); an agent no track follows keeps a negative id (-1 - its simulator id), which no track carries. So
the bound is told every plan of the world it sees, and plans around the tracks it sees with their told futures,
not with a constant-velocity guess (what the planner gives an observed agent without a prediction).
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


def seen_through(truth: GroundTruth, world, obs: Observation, max_distance: float = 2.0) -> GroundTruth:
    """``truth`` (of ``world``'s current step) in the frame and with the agent ids of the noisy observation ``obs``
    (see the module docstring); the target spots are kept."""
    from dataclasses import replace

    from avp_sensing.noisy import pair_ids

    true_ego, est = np.asarray(world.ego, dtype=float), np.asarray(obs.ego_pose, dtype=float)
    dth = float(est[2] - true_ego[2])
    rot = np.array([[np.cos(dth), -np.sin(dth)], [np.sin(dth), np.cos(dth)]])

    def placed(xy: np.ndarray) -> np.ndarray:  # a true position where the sensor places it (the estimate's frame)
        return est[:2] + (np.asarray(xy, dtype=float).reshape(-1, 2) - true_ego[:2]) @ rot.T

    def moved(poses: np.ndarray) -> np.ndarray:
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        return np.column_stack([placed(poses[:, :2]), np.arctan2(np.sin(poses[:, 2] + dth), np.cos(poses[:, 2] + dth))])

    def ids(est_xy, est_ids, true_xy, true_ids) -> dict[int, int]:  # true id -> track id
        return {t: e for e, t in pair_ids(est_xy, est_ids, placed(true_xy), true_ids, max_distance).items()}

    veh = ids([v.history[-1][:2] for v in obs.vehicles], [v.id for v in obs.vehicles], world.states[:, :2],
              world.vehicle_ids)
    ped = ids([p.position for p in obs.pedestrians], [p.id for p in obs.pedestrians], world.ped_pos, world.ped_ids)
    trajs = tuple(replace(p, agent_id=veh.get(int(p.agent_id), -1 - int(p.agent_id)), poses=moved(p.poses))
                  for p in truth.trajectories)
    reacting = frozenset((is_ped, (ped if is_ped else veh).get(i, -1 - i)) for is_ped, i in truth.reacting)
    return GroundTruth(truth.target_spots, trajs, reacting)


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
