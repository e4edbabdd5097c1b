"""The sensing model (``sensing.*``; docs/perception.md, "Sensing"): what a real car's sensors would report of what
the rays touch, in place of the paper's exact observation.

The paper (§III-A): "We assume the ego correctly observes every spots and agents it senses, even though real life
sensors can have uncertainty about its observations, usually as a function of distance from the ego [Nawaz et
al.] ... which we leave as future work." ``sensing.model: exact`` is that assumption (the simulator publishes
:meth:`World.observe <avp_sim.core.world.World.observe>` as it is). Any other model gives, per step, a
:class:`~avp_world.detections.SensedFrame`:

* the ego's pose as a localisation estimate: a slowly and smoothly drifting bias (two Gauss-Markov stages of time
  constant ``localisation_bias_tau`` in cascade) plus a small white jitter, applied to everything sensed that step
  (it is correlated: every detection is placed in the map with the estimated pose);
* the vehicles the rays touch, each detected with a probability that falls linearly with range (``detect_near`` at
  the ego, ``detect_far`` at the edge of Q_0) and with the share of its outline the rays see (below
  ``detect_min_share`` it falls to 0 in proportion); each detection's centre, heading and size get errors whose
  spread grows with range, its heading is turned by 180 degrees at ``heading_flip_rate``, and it carries a speed
  estimate and a covariance; no id, no history;
* clutter: false vehicle detections, Poisson with mean ``clutter_rate`` a step, at the end of a random ray;
* the pedestrians the rays touch, detected with ``pedestrian_detect`` (times the range factor) and a position error;
* each spot the rays touch read as its status, or misread with a probability ``spot_misread_far`` x (r / R)^2 at
  range r (R: the sensing region's reach), as Nawaz et al.'s observation accuracy falls off with distance.

The noise comes from a generator of its own, seeded by the episode's seed and the ego's index: same seed, same
noise, and the world's own draws are untouched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from avp_world.detections import (
    ORIENTATION_AVAILABLE,
    PedestrianDetection,
    SensedFrame,
    VehicleDetection,
)
from avp_world.geometry import rect_corners

MODELS = ("exact", "realistic", "harsh", "custom")


@dataclass(frozen=True)
class SensingConfig:
    """One sensing model; the defaults are the ``realistic`` preset (each value's source: docs/perception.md)."""

    model: str = "exact"
    position_sigma: float = 0.10  # m, a detection's centre error (per axis) at range 0
    position_sigma_per_m: float = 0.01  # m of that sigma per m of range
    heading_sigma: float = 0.05  # rad at range 0
    heading_sigma_per_m: float = 0.003  # rad per m of range
    heading_flip_rate: float = 0.03  # share of detections whose heading is turned by pi
    size_sigma: float = 0.05  # relative error of length and width
    speed_sigma: float = 0.26  # m/s, the speed estimate's error
    detect_near: float = 0.95  # detection probability at the ego
    detect_far: float = 0.85  # ... at the edge of the sensing region
    detect_min_share: float = 0.25  # below this share of its outline seen, the probability falls in proportion
    clutter_rate: float = 0.05  # false vehicle detections a step (mean)
    pedestrian_sigma: float = 0.15  # m, a pedestrian's position error at range 0 (doubles at the region's edge)
    pedestrian_detect: float = 0.90  # a pedestrian's detection probability at the ego
    localisation_sigma: float = 0.01  # m, white noise of the ego's position estimate (a localiser's jitter)
    localisation_bias_sigma: float = 0.15  # m, the stationary spread of its slowly drifting bias (per axis)
    localisation_heading_sigma: float = 0.025  # rad, the stationary spread of the heading bias
    localisation_bias_tau: float = 10.0  # s, the bias's time constant
    spot_misread_far: float = 0.05  # probability of misreading a spot at the edge of the sensing region

    @property
    def exact(self) -> bool:
        return self.model == "exact"


REALISTIC = SensingConfig(model="realistic")
#: about twice the errors of ``realistic``, lower recall, more clutter and flips
HARSH = SensingConfig(model="harsh", position_sigma=0.20, position_sigma_per_m=0.02, heading_sigma=0.10,
                      heading_sigma_per_m=0.006, heading_flip_rate=0.08, size_sigma=0.10, speed_sigma=0.52,
                      detect_near=0.85, detect_far=0.65, detect_min_share=0.4, clutter_rate=0.2,
                      pedestrian_sigma=0.30, pedestrian_detect=0.75, localisation_sigma=0.02,
                      localisation_bias_sigma=0.30, localisation_heading_sigma=0.05, localisation_bias_tau=10.0,
                      spot_misread_far=0.10)
PRESETS = {"exact": SensingConfig(), "realistic": REALISTIC, "harsh": HARSH}
#: the fields that are probabilities (0..1)
PROBABILITIES = frozenset({"heading_flip_rate", "detect_near", "detect_far", "detect_min_share", "pedestrian_detect",
                           "spot_misread_far"})
#: what each ``sensing.<name>`` parameter is (docs/parameters.md)
DESCRIPTIONS = {
    "position_sigma": "custom: a detected vehicle's centre error per axis at range 0 [m].",
    "position_sigma_per_m": "custom: growth of that error per metre of range [m/m].",
    "heading_sigma": "custom: a detection's heading error at range 0 [rad].",
    "heading_sigma_per_m": "custom: its growth per metre of range [rad/m].",
    "heading_flip_rate": "custom: share of vehicle detections whose heading is turned by pi.",
    "size_sigma": "custom: relative error of a detection's length and width.",
    "speed_sigma": "custom: error of a detection's speed estimate [m/s].",
    "detect_near": "custom: a vehicle's detection probability at the ego.",
    "detect_far": "custom: ... at the edge of the sensing region (linear in between).",
    "detect_min_share": "custom: below this share of its outline seen by the rays, the probability falls in "
                        "proportion.",
    "clutter_rate": "custom: false vehicle detections a step (Poisson mean), at random ray ends.",
    "pedestrian_sigma": "custom: a pedestrian's position error at range 0 (twice at the region's edge) [m].",
    "pedestrian_detect": "custom: a pedestrian's detection probability at the ego.",
    "localisation_sigma": "custom: white noise of the ego's position estimate [m].",
    "localisation_bias_sigma": "custom: stationary spread of its slowly drifting bias, per axis [m].",
    "localisation_heading_sigma": "custom: stationary spread of the heading bias [rad].",
    "localisation_bias_tau": "custom: time constant of the bias's two Gauss-Markov stages [s].",
    "spot_misread_far": "custom: probability of misreading a spot at the region's edge (grows as range^2).",
}
#: the parameters of ``sensing.model: custom`` (sensing.<name>), in :class:`SensingConfig`'s order
FIELDS = tuple(f for f in SensingConfig.__dataclass_fields__ if f != "model")


def sensing_config(p: dict) -> SensingConfig:
    """The model of the simulator parameters ``p``: a preset, or (``custom``) the ``sensing.<name>`` values."""
    model = p.get("sensing.model", "exact")
    if model not in MODELS:
        raise ValueError(f"parameter 'sensing.model': expected one of {MODELS}, got {model!r}")
    if model != "custom":
        return PRESETS[model]
    return replace(REALISTIC, model="custom", **{f: float(p[f"sensing.{f}"]) for f in FIELDS if f"sensing.{f}" in p})


def _rot(th: float) -> np.ndarray:
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s], [s, c]])


def wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class _SmoothDrift:
    """A unit-variance smooth random drift of time constant ``tau``: a first-order Gauss-Markov process x1 (x1 <- a x1
    + sqrt(1 - a^2) n) low-pass filtered by a second stage (x2 <- a x2 + (1 - a) x1), scaled so that x2 has unit
    stationary variance. Its step-to-step change is of order (1 - a) where a single stage's is sqrt(1 - a^2):
    at dt = 0.1 s, tau = 10 s, about 2 % of its spread a step instead of 14 %."""

    def __init__(self, tau: float):
        self.tau = float(tau)
        self._cache: dict[float, tuple[float, float]] = {}

    def _coeffs(self, dt: float) -> tuple[float, float]:
        """(a, g): the stages' coefficient and the gain that gives x2 unit variance (from the stationary covariance
        of the two-stage system, solved by fixed-point iteration once per dt)."""
        if dt not in self._cache:
            a = math.exp(-dt / self.tau) if self.tau > 0 else 0.0
            A = np.array([[a, 0.0], [(1.0 - a) * a, a]])
            B = np.array([math.sqrt(1.0 - a * a), (1.0 - a) * math.sqrt(1.0 - a * a)])
            P = np.outer(B, B)
            for _ in range(20000):
                nxt = A @ P @ A.T + np.outer(B, B)
                if np.allclose(nxt, P, rtol=1e-10, atol=1e-14):
                    break
                P = nxt
            self._cache[dt] = (a, 1.0 / math.sqrt(P[1, 1]) if P[1, 1] > 0 else 1.0)
        return self._cache[dt]

    def step(self, stages: np.ndarray, noise: np.ndarray, dt: float) -> np.ndarray:
        """The stages (2, 3) one step on (stage 1 unit-variance, stage 2 scaled to unit variance)."""
        a, g = self._coeffs(dt)
        x1 = a * stages[0] + math.sqrt(max(0.0, 1.0 - a * a)) * noise
        x2 = a * stages[1] + (1.0 - a) * g * x1
        return np.stack([x1, x2])


class NoisySensor:
    """The sensing model of one ego in one episode (module docstring). :meth:`sense` is called once a step."""

    def __init__(self, config: SensingConfig, seed: int, reach: float, ego_index: int = 0):
        if config.exact:
            raise ValueError("NoisySensor: the exact model needs no sensor (World.observe)")
        self.cfg = config
        self.reach = max(float(reach), 1e-6)
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5E5E, int(ego_index)]))
        c = config
        self._bias_sigma = np.array([c.localisation_bias_sigma, c.localisation_bias_sigma,
                                     c.localisation_heading_sigma])
        # the drift: two first-order Gauss-Markov stages in cascade (a smooth path, as a filtered localiser's error is,
        # not a rough random walk), drawn from their stationary spread
        self._drift = _SmoothDrift(c.localisation_bias_tau)
        self._stages = self.rng.normal(0.0, 1.0, (2, 3))  # both stages have unit stationary variance
        self.bias = self._stages[1] * self._bias_sigma
        self._white_sigma = np.array([c.localisation_sigma, c.localisation_sigma, c.localisation_sigma * 0.1])
        self.last_ego_error = np.zeros(3)

    def _localise(self, true_pose: np.ndarray, dt: float) -> np.ndarray:
        """The ego's pose estimate this step: the drifting bias moves on (:class:`_SmoothDrift`), white noise on top."""
        self._stages = self._drift.step(self._stages, self.rng.normal(0.0, 1.0, 3), dt)
        self.bias = self._stages[1] * self._bias_sigma
        white = self.rng.normal(0.0, 1.0, 3) * self._white_sigma
        err = self.bias + white
        self.last_ego_error = err
        est = true_pose + err
        est[2] = wrap(float(est[2]))
        return est

    def sense(self, world, i: int = 0, obs=None) -> SensedFrame:
        """What ego ``i`` of ``world`` reports at its current step; ``obs``: its exact observation of this step if
        already made (``world.observe(i)`` just called), else it is made here."""
        obs = world.observe(i) if obs is None else obs
        scan = world.last_scan
        c, rng = self.cfg, self.rng
        true_ego = np.asarray(obs.ego_pose, dtype=float)
        est_ego = self._localise(true_ego, obs.dt)
        to_sensor = _rot(-true_ego[2])
        to_map = _rot(est_ego[2])
        dth = est_ego[2] - true_ego[2]

        def place(p: np.ndarray) -> np.ndarray:
            """A point measured relative to the ego, placed in the map with the estimated pose."""
            return est_ego[:2] + to_map @ (to_sensor @ (p - true_ego[:2]))

        n_agents = len(world.states)
        inc = float(obs.ray_angle_increment) or 2.0 * math.pi / max(len(obs.ray_ranges), 1)
        hits = np.bincount(scan.hit_vehicle[scan.hit_vehicle >= 0], minlength=len(scan.seen_vehicles))
        vehicles: list[VehicleDetection] = []
        for k in np.nonzero(scan.seen_vehicles[:n_agents])[0]:
            pose = world.states[k]
            length, width = (float(v) for v in world.vehicle_dims[k])
            r = float(math.hypot(pose[0] - true_ego[0], pose[1] - true_ego[1]))
            share = min(1.0, hits[k] / max(1.0, _angular_span(pose, length, width, true_ego[:2]) / inc))
            p_det = (c.detect_near + (c.detect_far - c.detect_near) * min(r / self.reach, 1.0)) \
                * min(1.0, share / c.detect_min_share if c.detect_min_share > 0 else 1.0)
            u, noise = rng.random(), rng.normal(0.0, 1.0, 6)
            if u >= p_det:
                continue
            sp = c.position_sigma + c.position_sigma_per_m * r
            sh = c.heading_sigma + c.heading_sigma_per_m * r
            flip = math.pi if rng.random() < c.heading_flip_rate else 0.0
            xy = place(pose[:2]) + noise[:2] * sp  # isotropic: the same in the sensor's frame
            th = wrap(float(pose[2]) + dth + noise[2] * sh + flip)
            speed = _speed(world.history[k], obs.dt) + noise[5] * c.speed_sigma
            vehicles.append(VehicleDetection(
                pose=np.array([xy[0], xy[1], th]), length=length * (1.0 + c.size_sigma * noise[3]),
                width=width * (1.0 + c.size_sigma * noise[4]), covariance=np.diag([sp * sp, sp * sp, sh * sh]),
                existence=float(np.clip(0.5 + 0.5 * share, 0.0, 1.0)), orientation=ORIENTATION_AVAILABLE,
                speed=float(speed), speed_variance=c.speed_sigma ** 2))
        vehicles += self._clutter(scan, place)
        peds: list[PedestrianDetection] = []
        for k in np.nonzero(scan.seen_pedestrians)[0]:
            pos = world.ped_pos[k]
            r = float(math.hypot(pos[0] - true_ego[0], pos[1] - true_ego[1]))
            p_det = c.pedestrian_detect * (1.0 - 0.5 * (1.0 - c.detect_far / max(c.detect_near, 1e-9))
                                           * min(r / self.reach, 1.0))
            u, noise = rng.random(), rng.normal(0.0, 1.0, 2)
            if u >= p_det:
                continue
            s = c.pedestrian_sigma * (1.0 + min(r / self.reach, 1.0))
            peds.append(PedestrianDetection(position=place(pos) + noise * s, radius=float(world.ped_radii[k]),
                                            covariance=np.diag([s * s, s * s]), existence=0.8))
        vac, occ = self._read_spots(world, obs, true_ego)
        return SensedFrame(step=obs.step, dt=obs.dt, ego_pose=est_ego,
                           ego_covariance=np.diag(np.square(self._bias_sigma) + np.square(self._white_sigma)),
                           ego_length=obs.ego_length, ego_width=obs.ego_width, ego_speed=obs.ego_speed,
                           vacant_spot_ids=vac, occupied_spot_ids=occ, vehicles=tuple(vehicles),
                           pedestrians=tuple(peds), ray_angle_min=obs.ray_angle_min,
                           ray_angle_increment=obs.ray_angle_increment, ray_ranges=obs.ray_ranges)

    def _clutter(self, scan, place) -> list[VehicleDetection]:
        """False vehicle detections (Poisson, mean ``clutter_rate``) at the ends of random rays."""
        c, rng = self.cfg, self.rng
        n = int(rng.poisson(c.clutter_rate)) if c.clutter_rate > 0 else 0
        out = []
        for _ in range(n):
            j = int(rng.integers(len(scan.endpoints)))
            noise = rng.normal(0.0, 1.0, 5)
            xy = place(scan.endpoints[j]) + noise[:2] * 0.5
            r = float(np.hypot(*(scan.endpoints[j] - scan.origin)))
            sp = c.position_sigma + c.position_sigma_per_m * r
            out.append(VehicleDetection(
                pose=np.array([xy[0], xy[1], wrap(float(rng.uniform(-math.pi, math.pi)))]),
                length=4.5 * (1.0 + 0.1 * noise[2]), width=1.9 * (1.0 + 0.1 * noise[3]),
                covariance=np.diag([sp * sp, sp * sp, 0.3]), existence=float(np.clip(0.3 + 0.1 * noise[4], 0, 1)),
                speed=0.0, speed_variance=c.speed_sigma ** 2))
        return out

    def _read_spots(self, world, obs, true_ego: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The seen spots' statuses, each misread with a probability growing as the square of its range."""
        c = self.cfg
        ids = np.concatenate([obs.vacant_spot_ids, obs.occupied_spot_ids]).astype(np.int64)
        occupied = np.concatenate([np.zeros(len(obs.vacant_spot_ids), bool), np.ones(len(obs.occupied_spot_ids),
                                                                                      bool)])
        if not len(ids):
            return obs.vacant_spot_ids, obs.occupied_spot_ids
        order = np.argsort(ids, kind="stable")
        ids, occupied = ids[order], occupied[order]
        lot = world.lot
        centres = lot.spot_poses[[lot.spot_index(int(s)) for s in ids], :2]
        r = np.hypot(centres[:, 0] - true_ego[0], centres[:, 1] - true_ego[1])
        misread = self.rng.random(len(ids)) < c.spot_misread_far * np.minimum(r / self.reach, 1.0) ** 2
        occupied = occupied ^ misread
        return ids[~occupied], ids[occupied]


def _angular_span(pose: np.ndarray, length: float, width: float, origin: np.ndarray) -> float:
    """The angle a box at ``pose`` subtends from ``origin`` [rad]."""
    corners = rect_corners(np.asarray(pose, dtype=float), length, width).reshape(-1, 2)
    centre = math.atan2(pose[1] - origin[1], pose[0] - origin[0])
    ang = np.array([wrap(math.atan2(q[1] - origin[1], q[0] - origin[0]) - centre) for q in corners])
    return float(ang.max() - ang.min())


def _speed(history: np.ndarray, dt: float) -> float:
    """The signed speed along the heading from the last two poses of ``history`` [m/s]."""
    if len(history) < 2 or dt <= 0:
        return 0.0
    d = history[-1, :2] - history[-2, :2]
    th = history[-1, 2]
    return float((d[0] * math.cos(th) + d[1] * math.sin(th)) / dt)


def truth_ids(world, obs, max_distance: float = 2.0) -> dict[int, int]:
    """For scoring only: the simulator id of the vehicle each of ``obs``'s tracks follows now (an optimal one-to-one
    pairing of the tracks' current estimates with the world's vehicles, within ``max_distance`` m); a track that
    follows no vehicle (clutter) is left out. The ego never sees this."""
    if not obs.vehicles or not len(world.states):
        return {}
    return pair_ids(np.array([v.history[-1][:2] for v in obs.vehicles]), [v.id for v in obs.vehicles],
                    world.states[:, :2], world.vehicle_ids, max_distance)


def pair_ids(est_xy: np.ndarray, est_ids, true_xy: np.ndarray, true_ids, max_distance: float) -> dict[int, int]:
    """{estimate id: true id} of an optimal one-to-one pairing of the points ``est_xy`` with ``true_xy`` (the sum of
    distances least), pairs within ``max_distance`` m only."""
    from scipy.optimize import linear_sum_assignment

    est_xy, true_xy = np.asarray(est_xy, float).reshape(-1, 2), np.asarray(true_xy, float).reshape(-1, 2)
    if not len(est_xy) or not len(true_xy):
        return {}
    d = np.hypot(est_xy[:, None, 0] - true_xy[None, :, 0], est_xy[:, None, 1] - true_xy[None, :, 1])
    rows, cols = linear_sum_assignment(np.where(d < max_distance, d, 1e9))
    return {int(est_ids[r]): int(true_ids[c]) for r, c in zip(rows, cols, strict=True) if d[r, c] < max_distance}
