"""Options of the reach and reach-avoid tasks: one frozen dataclass each, defaults = the paper's
best configuration for that task (paper sections "Experiments" and "Results").

`validate()` runs where a config enters the package (`envs.make`, `envs.make_config`, `envs.from_config`), before
anything is traced, and raises a `ValueError` naming the field, the value and what is allowed; the envs trust it.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar, Literal, Optional

from envs.obstacles import MAX_OBSTACLES, MOTIONS
from envs.validation import below, choice, integer, interval, positive

ACTIONS = ("relative", "absolute")
RELATIVE_BASES = ("position", "target")
ACTION_UNITS = ("radian", "joint_range")
INTEGRATORS = ("model", "implicitfast", "euler")
REWARDS = ("sparse", "semi_sparse", "dense")
SUCCESS_MODES = ("reach_and_stay", "reach_and_terminate")
WORKSPACES = ("full", "front", "upper", "pandagym")
TARGET_SAMPLINGS = ("reachable", "uniform")
INIT_RANGES = ("full", "limited")
LINK_DISTANCES = ("origin", "surface")
REACH_OBSERVATIONS = (
    "joint_pos", "joint_vel", "joint_acc", "ee_pos", "ee_vel", "target_pos", "ee_to_target", "prev_action",
    "joint_sin_cos", "self_dist", "link_pos",
)
BACKENDS = ("auto", "mjx", "mujoco")
JOINT_NOISE_MODELS = ("angles", "encoders")
# Observation parts computed from the joint angles: with joint_noise_model="encoders" they come from the noisy ones.
KINEMATIC_OBSERVATIONS = ("ee_pos", "ee_to_target", "self_dist", "link_pos", "link_obstacle_dist",
                          "link_obstacle_ahead", "link_obstacle_ahead_moving")
MAX_LOOKAHEADS = 8
"""Most horizons of the link_obstacle_ahead(_moving) observations (each adds one number per link)."""
OBSTACLE_OBSERVATIONS = ("obstacle_pos", "obstacle_size", "link_obstacle_dist", "obstacle_radius", "obstacle_vel",
                         "link_obstacle_ahead", "link_obstacle_ahead_moving")


def _observed_if_set(field: str, std: float, observation: tuple[str, ...], noisy_parts: tuple[str, ...]) -> None:
    """Sensor noise must reach the observation: a noise level without any part it perturbs is a mistake."""
    if std > 0 and not set(noisy_parts) & set(observation):
        raise ValueError(f"{field}={std!r} is invalid: allowed is 0 unless one of {', '.join(noisy_parts)} is "
                         f"observed (observation={tuple(observation)!r}).")


@dataclasses.dataclass(frozen=True)
class ReachConfig:
    """Reach task: move the end effector to a sampled target and stay there."""

    TRACED_FIELDS: ClassVar[tuple[str, ...]] = ()
    """Fields that may be traced arrays in `ArmEnv.with_config` (see ReachAvoidConfig); none for reach."""

    action: Literal["relative", "absolute"] = "relative"
    """Joint position control: `relative` adds `action_scale * action` to the current joint
    positions; `absolute` maps [-1, 1] onto the joint range. Targets are clipped to the range."""
    action_scale: float = 0.2
    """Radians per step commanded by a relative action of magnitude 1 (ignored for absolute). The
    paper does not state it; 0.2 trained the UR5e reach much faster than 0.1 and the UR5e presets
    use 0.3 (results: action-scale study). The joints' damping keeps them within their velocity limits."""
    action_unit: Literal["radian", "joint_range"] = "radian"
    """What a relative step of `action_scale` counts in: `radian`, the same step on every joint; `joint_range`, a
    fraction of each joint's range width (UR5e: 4 pi rad, the elbow 2 pi; Panda 3.0-5.8 rad), so wide joints move
    further. The paper states neither (results/fidelity)."""
    relative_to: Literal["position", "target"] = "position"
    """What a relative action's delta is added to: `position`, the current joint positions (the paper's
    "deltas that are added to the current joint positions"); `target`, the previous step's joint targets, so
    a zero action holds the commanded pose exactly (not in the paper; results/fidelity)."""
    observation: tuple[str, ...] = ("joint_pos", "ee_pos", "target_pos", "ee_to_target")
    """Observation parts, concatenated in this order. Reach: joint_pos, joint_vel, joint_acc,
    ee_pos, ee_vel, target_pos, ee_to_target, prev_action, and three not in the paper: joint_sin_cos
    (sin and cos of each joint angle: one value per physical pose, where a UR5e joint's 720 degree
    range gives each pose up to two angles), self_dist (signed distance of each self-collision
    pair, < 0 in collision) and link_pos (the world position of each link frame origin, from which
    eq. 3's d_i is measured with the default link_distance="origin", 3 per link: where the links are,
    without learning the arm's kinematics);
    reach-avoid adds obstacle_pos, obstacle_size, link_obstacle_dist and, beyond the paper,
    obstacle_radius and obstacle_vel (see ReachAvoidConfig)."""
    reward: Literal["sparse", "semi_sparse", "dense"] = "dense"
    """Reward formulation: sparse (+1 in target), semi_sparse (paper eq. 1), dense (paper eq. 2)."""
    w_reach: float = 1.0
    """Weight of the in-target bonus (sparse and semi_sparse)."""
    w_dist: float = 1.0
    """Weight of the distance term (semi_sparse and dense)."""
    d_max: Optional[float] = None
    """Maximum reach in the semi_sparse term w_dist * (2 d_max - d); None: the robot's reach."""
    alpha: float = 20.0
    """Sharpness of the dense reward w_dist * exp(-alpha * d)."""
    w_joint_vel: float = 0.0
    """Penalty weight on the L2 norm of the joint velocities (semi_sparse and dense)."""
    w_joint_acc: float = 0.0
    """Penalty weight on the L2 norm of the joint accelerations (semi_sparse and dense)."""
    w_joint_limit: float = 0.0
    """Penalty weight near the joint range limits (semi_sparse and dense; not in the paper, which has 0):
    w_joint_limit * sum_i max(0, 1 - m_i / joint_limit_margin), m_i the joint's distance (rad) to the
    nearer end of its range. UR5e policies that miss mostly end with a joint pinned at its +-360 deg
    limit; this makes approaching a limit cost something (results: joint-limit study)."""
    joint_limit_margin: float = 0.5
    """Distance from a joint limit (rad) at which the w_joint_limit penalty starts (0.5 in every run
    we made with it)."""
    collision_penalty: float = 0.0
    """Reward subtracted on the step that collides (the paper uses 0: termination alone)."""
    target_radius: float = 0.01
    """The end effector is in the target when closer than this to its centre (m)."""
    success: Literal["reach_and_stay", "reach_and_terminate"] = "reach_and_stay"
    """reach_and_stay continues after reaching; reach_and_terminate ends the episode there."""
    workspace: Literal["full", "front", "upper", "pandagym"] = "full"
    """Where targets lie: full (ball of the robot's reach around the shoulder), front (its x >= 0
    half), upper (its z >= 0 part, above the base plane), pandagym (PandaGym's 30 cm cube)."""
    target_sampling: Literal["reachable", "uniform"] = "reachable"
    """reachable: end effector of a random collision-free pose inside the workspace; uniform:
    uniform in the workspace volume (not every such point is reachable)."""
    init_range: Literal["full", "limited"] = "full"
    """Initial joint positions uniform over the full joint range or the robot's limited range
    (UR5e: 360 instead of 720 degrees); colliding poses are rejected."""
    episode_length: int = 125
    """Steps per episode before truncation (125 x 40 ms = 5 s)."""
    substeps: int = 20
    """Physics steps of 2 ms per environment step."""
    gravity_compensation: bool = False
    """Compensate gravity in the joints as the real arms' controllers do (not in the paper)."""
    integrator: Literal["model", "implicitfast", "euler"] = "model"
    """MuJoCo's integrator: `model`, the robot model's own (UR5e implicitfast as Menagerie's, Panda Euler;
    assets/README.md), or implicitfast or euler (MuJoCo's default, for an `<option>` that names none: the paper
    lists its solver options but no integrator; results/fidelity)."""
    backend: Literal["auto", "mjx", "mujoco"] = "auto"
    """Physics backend (`envs.physics`): mjx (MuJoCo MJX inside the jitted step: GPU training), mujoco
    (MuJoCo's C library on the CPU cores through a callback: evaluation, notebooks and Gymnasium on a CPU,
    no physics to compile) or auto (mujoco when JAX runs on the CPU, mjx on a GPU). Same model, options
    and task logic; results agree to float tolerance."""
    sampling_candidates: int = 8
    """Candidates drawn at once per rejection-sampled quantity; targets in the front/upper
    workspaces and obstacles over 0.15 m use more (see `ArmEnv.count_candidates`, `ReachAvoid.count_candidates`).
    A reset that finds none valid is counted in the `reset_fallback` metric (expected rate about 1e-6)."""
    joint_noise_std: float = 0.0
    """Standard deviation (rad) of Gaussian noise on the observed joint angles (joint_pos and joint_sin_cos, and
    with joint_noise_model="encoders" the parts computed from them; the physics and reward see the true ones);
    0 = off. Not in the paper, whose Discussion names realistic noise models as future work. Drawn from the
    episode's reset key and the step count, so the same key gives the same noise."""
    joint_noise_model: Literal["angles", "encoders"] = "angles"
    """Which observation parts the joint noise reaches: `angles`, only joint_pos and joint_sin_cos; `encoders`,
    also every part a real arm computes from its encoder readings (ee_pos, ee_to_target, self_dist, link_pos and,
    with obstacles, link_obstacle_dist, link_obstacle_ahead and link_obstacle_ahead_moving: the forward kinematics of
    the noisy angles). ee_vel is refused with
    `encoders` (it would need the previous step's noisy pose). Physics, reward and collisions stay exact."""
    action_latency: int = 0
    """0: a step applies its own action; 1: it applies the action of the step before (prev_action, so
    that observation part shows the action the next step applies; the first step of an episode holds
    the initial pose), a one-step actuation delay as on real arms (not in the paper, see joint_noise_std)."""

    @property
    def task(self) -> str:
        return "reach"

    def allowed_observations(self) -> tuple[str, ...]:
        return REACH_OBSERVATIONS

    def validate(self) -> None:
        """Raises `ValueError` on an impossible or unknown value."""
        choice("action", self.action, ACTIONS)
        choice("relative_to", self.relative_to, RELATIVE_BASES)
        choice("action_unit", self.action_unit, ACTION_UNITS)
        choice("integrator", self.integrator, INTEGRATORS)
        choice("reward", self.reward, REWARDS)
        choice("success", self.success, SUCCESS_MODES)
        choice("workspace", self.workspace, WORKSPACES)
        choice("target_sampling", self.target_sampling, TARGET_SAMPLINGS)
        choice("init_range", self.init_range, INIT_RANGES)
        choice("backend", self.backend, BACKENDS)
        if not isinstance(self.observation, tuple) or not self.observation:  # a list would not hash (jit caches)
            raise ValueError(f"observation={self.observation!r} is invalid: allowed is a non-empty tuple of "
                             f"{', '.join(self.allowed_observations())}.")
        for part in self.observation:
            if part not in self.allowed_observations():
                extra = " (obstacle parts need a reach-avoid env)" if part in OBSTACLE_OBSERVATIONS else ""
                raise ValueError(f"observation part {part!r} is invalid for the {self.task} task{extra}: "
                                 f"allowed are {', '.join(self.allowed_observations())}.")
        if len(set(self.observation)) != len(self.observation):
            raise ValueError(f"observation={self.observation!r} is invalid: a part appears twice.")
        for name in ("action_scale", "alpha", "target_radius", "joint_limit_margin"):
            positive(name, getattr(self, name))
        for name in ("w_reach", "w_dist", "w_joint_vel", "w_joint_acc", "w_joint_limit", "collision_penalty"):
            positive(name, getattr(self, name), strict=False)
        if self.d_max is not None:
            positive("d_max", self.d_max)
        integer("episode_length", self.episode_length, 1)
        integer("substeps", self.substeps, 1)
        integer("sampling_candidates", self.sampling_candidates, 1)
        if not isinstance(self.gravity_compensation, bool):
            raise ValueError(f"gravity_compensation={self.gravity_compensation!r} is invalid: allowed are True, False.")
        positive("joint_noise_std", self.joint_noise_std, strict=False)
        choice("joint_noise_model", self.joint_noise_model, JOINT_NOISE_MODELS)
        if self.joint_noise_model == "encoders":
            if self.joint_noise_std == 0:
                raise ValueError("joint_noise_model='encoders' is invalid: allowed is 'angles' unless "
                                 "joint_noise_std > 0 (there is no noise to pass through the kinematics).")
            if "ee_vel" in self.observation:
                raise ValueError("joint_noise_model='encoders' is invalid: allowed is 'angles' while ee_vel is "
                                 "observed (a noisy velocity would need the previous step's noisy pose).")
        noisy = ("joint_pos", "joint_sin_cos") + (KINEMATIC_OBSERVATIONS if self.joint_noise_model == "encoders" else ())
        _observed_if_set("joint_noise_std", self.joint_noise_std, self.observation, noisy)
        integer("action_latency", self.action_latency, 0, maximum=1)
        if self.target_sampling == "reachable" and self.workspace == "pandagym":
            raise ValueError(
                "target_sampling='reachable' is invalid with workspace='pandagym': random poses rarely put "
                "the end effector in the 30 cm cube (and every point of it is reachable); allowed is "
                "target_sampling='uniform' there.")

    def relative_step(self, joint_low, joint_high):
        """Radians a relative action of 1 moves each joint's target (`action_scale` in `action_unit`)."""
        return self.action_scale * ((joint_high - joint_low) if self.action_unit == "joint_range" else 1.0)

    def validate_for_robot(self, robot: str, reach: float, joint_range_width: float) -> None:
        """`validate` plus bounds from the robot's workspace (`envs.robots.base.bounds`): a target
        radius below its reach, a relative step at most its widest joint range. Finite absurd values
        (a 1e6 m target) otherwise train and evaluate without an error but mean nothing."""
        self.validate()
        below("target_radius", self.target_radius, reach, f"below the {robot}'s reach, m")
        if self.action_unit == "joint_range":
            below("action_scale", self.action_scale, 1.0, "at most 1 (a whole joint range) with action_unit="
                  "'joint_range'", inclusive=True)
        else:
            below("action_scale", self.action_scale, joint_range_width, f"at most the {robot}'s widest joint range, rad",
                  inclusive=True)


@dataclasses.dataclass(frozen=True)
class ReachAvoidConfig(ReachConfig):
    """Reach-avoid task: reach the target without touching spherical obstacles (the paper: one, static,
    of a fixed size; the options num_obstacles, obstacle_radius_range, obstacle_motion and
    obstacle_noise_std go beyond it, towards the future work its Discussion names)."""

    TRACED_FIELDS: ClassVar[tuple[str, ...]] = ("obstacle_radius",)
    """Float fields the env reads only inside its traced functions or in `count_candidates` (`ArmEnv.with_config`), so
    a sweep over one evaluates with one compiled program whose argument it is (`agents.sweep`); tests/test_sweep.py
    holds each to the program compiled per value."""

    def inert_fields(self) -> dict[str, str]:
        """Fields without effect under this config, and why (a sweep over one is refused)."""
        if self.obstacle_radius_range is not None:
            return {"obstacle_radius": f"obstacle_radius_range={self.obstacle_radius_range!r} draws the radii"}
        return {}

    observation: tuple[str, ...] = ("joint_pos", "ee_pos", "target_pos", "ee_to_target", "obstacle_pos",
                                    "link_obstacle_dist")
    """Observation parts, concatenated in this order (see ReachConfig); the paper found the
    link-to-obstacle distances critical and the obstacle size useless at a fixed size."""
    reward: Literal["sparse", "semi_sparse", "dense"] = "semi_sparse"
    """Reward formulation; semi_sparse was slightly safer than dense on reach-avoid (paper)."""
    target_radius: float = 0.02
    """The end effector is in the target when closer than this to its centre (m)."""
    obstacle_radius: float = 0.1
    """Radius of the spherical obstacle (m); the paper evaluates 0.025 to 0.3. Unused when
    obstacle_radius_range is set."""
    obstacle_region: float = 0.6
    """Obstacles are sampled uniformly in the cube [-obstacle_region, obstacle_region]^3 around the
    robot base (paper: a 1.2 m cube), rejecting ones that touch the initial pose or the target."""
    num_obstacles: int = 1
    """Spheres per episode (the paper: 1), each sampled as the one obstacle is, clear of the initial pose
    and the target (obstacles may overlap each other). The collision check and the proximity penalty
    cover all of them; obstacle_pos, obstacle_size, obstacle_radius and obstacle_vel list them all."""
    obstacle_radius_range: Optional[tuple[float, float]] = None
    """(min, max): each obstacle's radius is drawn uniformly from it per episode (observed by the
    obstacle_radius part); None: every obstacle has obstacle_radius (the paper's fixed size)."""
    obstacle_motion: Literal["static", "linear", "sinusoid"] = "static"
    """static (paper); linear: constant velocity from the sampled centre, reflected at the faces of the
    obstacle_region cube; sinusoid: oscillation about the sampled centre along a random direction with
    a random phase and period obstacle_period, its amplitude capped to stay in the cube. A closed-form
    function of episode time (`envs.obstacles`): the collision check uses the obstacles' positions at
    every physics substep, the penalty and the observation those at the end of the step. A moving
    obstacle starts clear of the initial pose and the target and may cross both later. It is checked
    against every robot geom (`ReachAvoid.checked_geoms`), and drawn with a path that stays clear of the
    geoms no joint moves, the base and the first link, which no policy could move out of its way
    (`ReachAvoid.path_clear_of_fixed_geoms`; a reset that falls back, `reset_fallback`, is not held to it)."""
    obstacle_speed_range: tuple[float, float] = (0.05, 0.2)
    """(min, max) speed (m/s) drawn per obstacle and episode: linear's speed, sinusoid's peak speed
    (amplitude = speed * period / 2 pi before the cap); ignored for static."""
    obstacle_period: float = 2.0
    """Period (s) of the sinusoid motion."""
    obstacle_noise_std: float = 0.0
    """Standard deviation (m) of Gaussian noise on the observed obstacle positions (obstacle_pos and the
    link_obstacle_dist computed from them; collisions and the penalty use the true ones); 0 = off."""
    w_obst: float = 0.1
    """Weight of the link-proximity penalty w_obst * sum_i max(0, 1 - d_i / obstacle_tau) (eq. 3)."""
    obstacle_tau: float = 0.1
    """Distance (m) under which a link's proximity to the obstacle is penalised."""
    link_distance: Literal["origin", "surface"] = "origin"
    """How d_i is measured: origin (paper: link frame origin to the obstacle centre, minus the
    radius) or surface (exact distance between the link's capsules and the obstacle). With several
    obstacles the link_obstacle_dist observation gives each link's distance to the nearest one: one
    number per link whatever num_obstacles is, and the nearest obstacle is the one to avoid first;
    the penalty sums eq. (3) over every (link, obstacle) pair."""
    obstacle_lookahead: tuple[float, ...] = (0.5, 1.0)
    """Horizons (s) of the link_obstacle_ahead observation (not in the paper): per horizon and link, the distance
    link_obstacle_dist would have if every obstacle moved on at its current velocity for that long (the arm held
    still; a bounce off the cube's faces is not foreseen). A prediction of where a moving obstacle meets the arm.
    link_obstacle_ahead_moving: the same with the arm moved on too, at its current joint velocities (stopping at
    its joint limits)."""

    @property
    def radius_bounds(self) -> tuple[float, float]:
        """(smallest, largest) obstacle radius an episode can have."""
        if self.obstacle_radius_range is None:
            return self.obstacle_radius, self.obstacle_radius
        return tuple(map(float, self.obstacle_radius_range))

    @property
    def task(self) -> str:
        return "reach-avoid"

    def allowed_observations(self) -> tuple[str, ...]:
        return REACH_OBSERVATIONS + OBSTACLE_OBSERVATIONS

    def constant_observations(self) -> dict[str, str]:
        """Observation parts that hold one value in every episode under this config, each with the setting that
        fixes it: obstacle_vel (0) when the obstacles are static, obstacle_size and obstacle_radius when every
        obstacle has one radius. A policy trained on one of them has never seen it change
        (`agents.evaluation.unseen_constants`)."""
        low, high = self.radius_bounds
        fixed = {"obstacle_vel": f"obstacle_motion={self.obstacle_motion!r}"} if self.obstacle_motion == "static" else {}
        if low == high:
            fixed |= {part: f"obstacle radius {low:g} m" for part in ("obstacle_size", "obstacle_radius")}
        return fixed

    def validate(self) -> None:
        super().validate()
        positive("obstacle_radius", self.obstacle_radius)
        positive("obstacle_region", self.obstacle_region)
        positive("w_obst", self.w_obst, strict=False)
        positive("obstacle_tau", self.obstacle_tau)
        choice("link_distance", self.link_distance, LINK_DISTANCES)
        integer("num_obstacles", self.num_obstacles, 1, maximum=MAX_OBSTACLES)
        if self.obstacle_radius_range is not None:
            interval("obstacle_radius_range", self.obstacle_radius_range)
        choice("obstacle_motion", self.obstacle_motion, tuple(MOTIONS))
        interval("obstacle_speed_range", self.obstacle_speed_range, strict=False)
        positive("obstacle_period", self.obstacle_period)
        positive("obstacle_noise_std", self.obstacle_noise_std, strict=False)
        _observed_if_set("obstacle_noise_std", self.obstacle_noise_std, self.observation,
                         ("obstacle_pos", "link_obstacle_dist", "link_obstacle_ahead", "link_obstacle_ahead_moving"))
        if not (isinstance(self.obstacle_lookahead, tuple) and 1 <= len(self.obstacle_lookahead) <= MAX_LOOKAHEADS):
            raise ValueError(f"obstacle_lookahead={self.obstacle_lookahead!r} is invalid: allowed is a tuple of 1 to "
                             f"{MAX_LOOKAHEADS} horizons (s).")
        for i, horizon in enumerate(self.obstacle_lookahead):
            positive(f"obstacle_lookahead[{i}]", horizon)

    def validate_for_robot(self, robot: str, reach: float, joint_range_width: float) -> None:
        """ReachConfig's bounds plus the obstacle's: a radius below the robot's reach (a larger one
        leaves no clear start, every reset falls back), a sampling cube within twice the reach (the
        obstacle farther out never meets the arm)."""
        super().validate_for_robot(robot, reach, joint_range_width)
        below("obstacle_radius", self.obstacle_radius, reach, f"below the {robot}'s reach, m")
        if self.radius_bounds[1] >= reach:
            raise ValueError(f"obstacle_radius_range={self.obstacle_radius_range!r} is invalid: allowed is a max below "
                             f"the {robot}'s reach ({reach:g} m).")
        below("obstacle_region", self.obstacle_region, 2 * reach, f"at most twice the {robot}'s reach, m",
              inclusive=True)
