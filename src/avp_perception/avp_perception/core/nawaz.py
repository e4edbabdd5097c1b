"""Spot occupancy inferred from trajectory predictions — the "Explicit, future" baseline of Table I (§VI-B-2).

Nawaz et al., "Occupancy-aware Trajectory Planning for Autonomous Valet Parking in Uncertain Dynamic
Environments" (arXiv 2509.09206), infer how likely each observed vacant spot is to be taken from the
*predicted future positions* of the other agents instead of from their intentions. Chung et al. (§VI-B-2)
compare against it with the oracle trajectories of Nawaz's code replaced by constant-velocity predictions.
The update rule follows the authors' public code (their ParkSim fork, ``belief_pred_utils.py``):

For every agent a (observed dynamic vehicle or pedestrian) take its predicted mean positions mu_a,k at
t + k h, k = 0..T (h = 0.5 s, T = 5: 2.5 s; k = 0 is the observed position), and a covariance

    vehicles:    Sigma_a,k = R(psi_a,k) (Sigma_a,k-1 + Q) R(psi_a,k)^T,  Sigma_a,0 = diag(l/2, w/2) (body frame),
                 Q = 0.5 I per step, R the rotation by the predicted heading (``covariance="reference_code"``:
                 the rotations compose as in the code; ``"body"``: R(psi_k) (Sigma_0 + (k+1) Q) R(psi_k)^T);
    pedestrians: Sigma_a,k = Sigma_0 + k Q_ped, Sigma_0 = 0.01 r I, Q_ped = 0.01 Q.

Per spot centre s and step k:

    d       = sqrt((s - mu)^T M (s - mu))   vehicles; M = Sigma (the code passes Sigma as scipy's *inverse*
                                             covariance argument, ``mahalanobis="reference_code"``) or
                                             M = Sigma^-1 (textbook Mahalanobis, ``"inverse"``)
            = |s - mu| / trace(Sigma)        pedestrians
    p_dist  = (alpha_g + 1) / (alpha_g + e^d),  alpha_g = 350   (1e-5 when d > ln(1000 alpha_g))
    gate    = 1 / (1 + exp(-g v.(s - mu) / sigma_v)),  g = 0.001,
              sigma_v = max(trace((2 Sigma + Q - 2 rho I) / h^2), 0.001),  rho = 0.8,
              v = (mu_k+1 - mu_k) / h (the last difference for k = T); v.(s - mu) := 1e5 when |v| or |s - mu| is 0
    p_new_k = 1 - prod_a (1 - p_dist gate)                        (any agent)

and the occupancy of an observed vacant spot is filtered over the horizon,

    P_0 = p_new_0,   P_k = alpha P_k-1 + p_new_k (1 - P_k-1),   alpha = 0.95,

the result being P_T (floored at 1e-4). Chung et al.'s pipeline is otherwise unchanged (§VI-A: "all compared
methods only differ in how they choose the ego's parking spot"): eq. (7) for observed / unobserved spots,
then P_T replaces eq. (8) on the observed vacant spots, and the planner's candidates are the observed
vacant spots with b <= delta = 0.3 — Nawaz's own threshold for vacant spots. Not carried over (they do not
apply here): the arrival/departure chain of unobserved spots (our sensing keeps eq. 7's memory), the
departure rule for spots occupied by a dynamic agent (our scenarios have no departing cars) and the
partial-observation Bayes update (the paper's sensing is exact, §III-A).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from avp_belief_map.belief import BeliefMap
from avp_predictors.prediction import ConstantVelocityPredictor
from avp_world.lot import LotMap
from avp_world.types import Observation, PredictedTrajectory

MAHALANOBIS_MODES = ("reference_code", "inverse")
COVARIANCE_MODES = ("reference_code", "body")
ZERO_DOT = 1e5  # v.(s - mu) used when the agent stands still or sits on the spot centre (reference code)
EPS = 1e-6


@dataclass(frozen=True)
class NawazConfig:
    """Constants of Nawaz et al.'s occupancy update (reference code values, facts sheet §4c)."""

    step: float = 0.5  # h: seconds between prediction samples (MOTION_RESOLUTION)
    n_steps: int = 5  # T: samples after the current one (T_pred = 2.5 s)
    sigma0_scale: float = 0.5  # vehicles: Sigma_0 = diag(scale l, scale w) in the body frame
    q: float = 0.5  # process noise Q = q I per step
    pedestrian_sigma0_scale: float = 0.01  # pedestrians: Sigma_0 = scale r I
    pedestrian_q_scale: float = 0.01  # Q_ped = scale Q
    alpha_g: float = 350.0  # p_dist = (alpha_g + 1) / (alpha_g + e^d)
    alpha: float = 0.95  # occupancy filter P_k = alpha P_k-1 + p_new (1 - P_k-1)
    rho: float = 0.8  # velocity-uncertainty correlation
    gate_gain: float = 0.001  # g of the heading/velocity gate
    floor: float = 1e-4  # smallest occupancy written into the belief map
    mahalanobis: str = "reference_code"  # "reference_code" (M = Sigma) or "inverse" (M = Sigma^-1)
    covariance: str = "reference_code"  # "reference_code" (composed rotations) or "body"

    def validate(self) -> NawazConfig:
        for name in ("step", "sigma0_scale", "alpha_g"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"NawazConfig.{name} must be a finite number > 0, got {v!r}")
        for name in ("q", "pedestrian_sigma0_scale", "pedestrian_q_scale", "rho", "gate_gain", "floor"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"NawazConfig.{name} must be a finite number >= 0, got {v!r}")
        if int(self.n_steps) != self.n_steps or self.n_steps < 0:
            raise ValueError(f"NawazConfig.n_steps must be an integer >= 0, got {self.n_steps!r}")
        if not 0.0 <= self.alpha <= 1.0:
            raise ValueError(f"NawazConfig.alpha must be in [0, 1], got {self.alpha!r}")
        if self.mahalanobis not in MAHALANOBIS_MODES:
            raise ValueError(f"NawazConfig.mahalanobis must be one of {MAHALANOBIS_MODES}, got {self.mahalanobis!r}")
        if self.covariance not in COVARIANCE_MODES:
            raise ValueError(f"NawazConfig.covariance must be one of {COVARIANCE_MODES}, got {self.covariance!r}")
        return self


@dataclass(frozen=True)
class AgentPaths:
    """Predicted means of A agents at t + k h, k = 0..T, and what the covariances need."""

    agent_ids: np.ndarray  # (A,)
    means: np.ndarray  # (A, T + 1, 2)
    headings: np.ndarray  # (A, T + 1)
    sigma0: np.ndarray  # (A, 2, 2) initial covariance (vehicles: body frame)
    is_pedestrian: np.ndarray  # (A,) bool


# ------------------------------------------------------------------------------------------ the rule


def rotation(theta: np.ndarray) -> np.ndarray:
    """(..., 2, 2) rotation matrices R(theta)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)


def propagate_covariances(paths: AgentPaths, cfg: NawazConfig) -> np.ndarray:
    """(A, T + 1, 2, 2) covariances Sigma_a,k of the module docstring."""
    a, t1 = paths.headings.shape
    q = cfg.q * np.eye(2)
    q_ped = cfg.pedestrian_q_scale * q
    out = np.empty((a, t1, 2, 2))
    ped = paths.is_pedestrian
    if a == 0:
        return out
    r = rotation(paths.headings)  # (A, T+1, 2, 2)
    s0 = paths.sigma0
    if cfg.covariance == "body":
        k = np.arange(1, t1 + 1)[None, :, None, None]
        body = s0[:, None] + k * q
        out[:] = r @ body @ np.swapaxes(r, -1, -2)
    else:  # reference code: k = 0 from Sigma_0 + Q, then Sigma <- R_k (Sigma + Q) R_k^T from Sigma_0 again
        out[:, 0] = r[:, 0] @ (s0 + q) @ np.swapaxes(r[:, 0], -1, -2)
        s = s0.copy()
        for k in range(1, t1):
            s = r[:, k] @ (s + q) @ np.swapaxes(r[:, k], -1, -2)
            out[:, k] = s
    if ped.any():  # pedestrians: isotropic, no rotation; k = 0 uses Sigma_0 + Q_ped like k = 1 (reference)
        k = np.maximum(np.arange(t1), 1) if cfg.covariance == "reference_code" else np.arange(1, t1 + 1)
        out[ped] = s0[ped][:, None] + k[None, :, None, None] * q_ped
    return out


def velocities(means: np.ndarray, step: float) -> np.ndarray:
    """(A, T + 1, 2): v_k = (mu_k+1 - mu_k) / h, the last difference repeated for k = T (zeros if T = 0)."""
    a, t1, _ = means.shape
    v = np.zeros((a, t1, 2))
    if t1 >= 2:
        d = np.diff(means, axis=1) / step
        v[:, :-1] = d
        v[:, -1] = d[:, -1]
    return v


def spot_agent_probabilities(spots: np.ndarray, means: np.ndarray, covs: np.ndarray, vels: np.ndarray,
                             is_pedestrian: np.ndarray, cfg: NawazConfig) -> np.ndarray:
    """(S, A) p_dist * gate of one time step for spot centres (S, 2) and agents (means (A, 2), covs (A, 2, 2),
    vels (A, 2))."""
    spots = np.asarray(spots, dtype=float).reshape(-1, 2)
    diff = spots[:, None, :] - means[None, :, :]  # (S, A, 2)
    if cfg.mahalanobis == "inverse":
        m = np.linalg.inv(covs)
    else:
        m = covs
    d_veh = np.sqrt(np.maximum(np.einsum("saj,ajk,sak->sa", diff, m, diff), 0.0))
    d_ped = np.linalg.norm(diff, axis=2) / np.trace(covs, axis1=1, axis2=2)[None, :]
    d = np.where(np.asarray(is_pedestrian, dtype=bool)[None, :], d_ped, d_veh)
    cutoff = math.log(1000.0 * cfg.alpha_g)
    p_dist = np.where(d > cutoff, 1e-5, (cfg.alpha_g + 1.0) / (cfg.alpha_g + np.exp(np.minimum(d, cutoff))))
    dot = np.einsum("aj,saj->sa", vels, diff)
    still = (np.linalg.norm(vels, axis=1) <= EPS)[None, :] | (np.linalg.norm(diff, axis=2) <= EPS)
    dot = np.where(still, ZERO_DOT, dot)
    q = cfg.q * np.eye(2)
    sig_v = np.trace((2.0 * covs + q - 2.0 * cfg.rho * np.eye(2)) / cfg.step**2, axis1=1, axis2=2)
    sig_v = np.maximum(sig_v, 0.001)
    gate = 1.0 / (1.0 + np.exp(-cfg.gate_gain * dot / sig_v[None, :]))
    return p_dist * gate


def any_agent(prob: np.ndarray) -> np.ndarray:
    """p_new = 1 - prod_a (1 - p_a) over the last axis (0 with no agent)."""
    return 1.0 - np.prod(1.0 - prob, axis=-1)


def occupancy_filter(p_new: np.ndarray, alpha: float) -> np.ndarray:
    """(T + 1, S) P_k: P_0 = p_new_0, P_k = alpha P_k-1 + p_new_k (1 - P_k-1)."""
    p_new = np.asarray(p_new, dtype=float)
    out = np.empty_like(p_new)
    if len(p_new) == 0:
        return out
    out[0] = p_new[0]
    for k in range(1, len(p_new)):
        out[k] = alpha * out[k - 1] + p_new[k] * (1.0 - out[k - 1])
    return out


def vacant_occupancy(spots: np.ndarray, paths: AgentPaths, cfg: NawazConfig) -> np.ndarray:
    """(T + 1, S) occupancy P_k of initially vacant spots centred at ``spots`` (S, 2), before the floor."""
    cfg = cfg.validate()
    s = len(np.asarray(spots).reshape(-1, 2))
    t1 = cfg.n_steps + 1
    if len(paths.agent_ids) == 0:
        return np.zeros((t1, s))
    covs = propagate_covariances(paths, cfg)
    vels = velocities(paths.means, cfg.step)
    p_new = np.stack([any_agent(spot_agent_probabilities(spots, paths.means[:, k], covs[:, k], vels[:, k],
                                                         paths.is_pedestrian, cfg)) for k in range(t1)])
    return occupancy_filter(p_new, cfg.alpha)


# --------------------------------------------------------------------------------- from predictions


def sample_prediction(current: np.ndarray, traj: PredictedTrajectory, times: np.ndarray) -> np.ndarray:
    """Poses (len(times), 3) at ``times`` (s after the observation; 0 = ``current``) along ``traj`` by linear
    interpolation (headings unwrapped); clamped to the last predicted pose beyond the prediction's end."""
    poses = np.asarray(traj.poses, dtype=float).reshape(-1, 3)
    t_src = np.concatenate([[0.0], traj.dt * np.arange(1, len(poses) + 1)])
    src = np.vstack([np.asarray(current, dtype=float)[None], poses])
    th = np.unwrap(src[:, 2])
    return np.column_stack([np.interp(times, t_src, src[:, 0]), np.interp(times, t_src, src[:, 1]),
                            np.interp(times, t_src, th)])


def agent_paths(obs: Observation, predictions: Iterable[PredictedTrajectory], cfg: NawazConfig) -> AgentPaths:
    """The most probable prediction of every observed dynamic vehicle and pedestrian, sampled at k h."""
    best: dict[tuple[bool, int], PredictedTrajectory] = {}
    for p in predictions:
        key = (bool(p.is_pedestrian), int(p.agent_id))
        if key not in best or p.probability > best[key].probability:
            best[key] = p
    times = cfg.step * np.arange(cfg.n_steps + 1)
    ids, means, heads, sig0, ped = [], [], [], [], []
    for v in obs.vehicles:
        p = best.get((False, int(v.id)))
        if v.is_static or p is None:
            continue
        s = sample_prediction(v.pose, p, times)
        ids.append(int(v.id))
        means.append(s[:, :2])
        heads.append(s[:, 2])
        sig0.append(np.diag([cfg.sigma0_scale * v.length, cfg.sigma0_scale * v.width]))
        ped.append(False)
    for q in obs.pedestrians:
        p = best.get((True, int(q.id)))
        if p is None:
            continue
        s = sample_prediction(np.array([*np.asarray(q.position, dtype=float), 0.0]), p, times)
        ids.append(int(q.id))
        means.append(s[:, :2])
        heads.append(np.zeros(len(times)))
        sig0.append(cfg.pedestrian_sigma0_scale * q.radius * np.eye(2))
        ped.append(True)
    n = len(ids)
    t1 = len(times)
    return AgentPaths(np.asarray(ids, dtype=np.int64), np.asarray(means, dtype=float).reshape(n, t1, 2),
                      np.asarray(heads, dtype=float).reshape(n, t1), np.asarray(sig0, dtype=float).reshape(n, 2, 2),
                      np.asarray(ped, dtype=bool))


class NawazOccupancy:
    """Belief update of the "Explicit, future" method: eq. (7), then Nawaz's P_T on observed vacant spots.

    Use after :meth:`BeliefMap.observe` (eq. 7) in place of eq. (8)::

        b_tilde = beliefs.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
        b = NawazOccupancy(lot).update(beliefs, obs, constant_velocity_predictions)
    """

    def __init__(self, lot: LotMap, config: NawazConfig = NawazConfig()):
        self.lot = lot
        self.config = config.validate()

    def vacant_probabilities(self, obs: Observation, predictions: Sequence[PredictedTrajectory],
                             vacant_idx: np.ndarray) -> np.ndarray:
        """P_T (floored) of the spots in rows ``vacant_idx``."""
        idx = np.asarray(vacant_idx, dtype=np.int64)
        paths = agent_paths(obs, predictions, self.config)
        occ = vacant_occupancy(self.lot.spot_poses[idx, :2], paths, self.config)
        return np.maximum(occ[-1], self.config.floor)

    def update(self, beliefs: BeliefMap, obs: Observation, predictions: Sequence[PredictedTrajectory]) -> np.ndarray:
        """b_t: ``beliefs.b_tilde`` with observed vacant spots set to P_T; stored in ``beliefs.values``."""
        b = beliefs.b_tilde.copy()
        vac = beliefs.vacant_idx
        if len(vac):
            b[vac] = self.vacant_probabilities(obs, predictions, vac)
        beliefs.values = b
        return b.copy()

    def constant_velocity_predictions(self, obs: Observation) -> list[PredictedTrajectory]:
        """§VI-B-2: the constant-velocity predictions Chung et al. feed Nawaz's rule (every observed dynamic
        vehicle and pedestrian, over the horizon T h that the rule samples)."""
        return ConstantVelocityPredictor(self.lot).predict(obs, (), horizon=self.config.n_steps * self.config.step)

    def update_constant_velocity(self, beliefs: BeliefMap, obs: Observation) -> np.ndarray:
        """:meth:`update` with :meth:`constant_velocity_predictions` — the "Explicit, future" method's b_t, as the
        belief node (``belief_source: nawaz``) and the in-process runner compute it."""
        return self.update(beliefs, obs, self.constant_velocity_predictions(obs))
