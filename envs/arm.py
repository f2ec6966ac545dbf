"""The shared logic of the arm tasks (the paper's abstract `Env`): physics stepping with collision
checks, action mapping, sampling of initial pose and target, observation assembly, metrics.

Tasks (`envs.tasks`) subclass `ArmEnv` and add what is theirs (the obstacle of reach-avoid).
Robots (`envs.robots`) supply model, limits, kinematics and collision geometry.

One environment step = `config.substeps` physics steps of 2 ms holding one position target per joint,
by MJX or by C MuJoCo (`config.backend`, `envs.physics`). Contacts are disabled in the model: after every
substep the robot's geom poses are checked analytically against the model's collision pairs, so a
collision anywhere inside the step ends the episode.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import operator

import jax
import jax.numpy as jnp

from envs import fast_mjx, physics, rewards, workspaces
from envs.base import Env, State, check_action, check_state
from envs.cache import LRU
from envs.config import ReachConfig
from envs.robots import Robot, first_valid

_PART_SIZES = LRU(256)
"""`ArmEnv.observation_part_sizes`' key (what decides the sizes) -> the sizes (a sweep builds an env per setting)."""

LAST_DISTANCES = 10
"""Steps over which the final distance to the target is averaged (paper: last 10 steps)."""

METRICS = (
    "distance", "distance_last10", "in_target", "target_reached", "steps_in_target", "times_left_target",
    "self_collision", "obstacle_collision", "physics_nan", "reset_fallback", "mean_joint_vel",
    "mean_joint_acc",
)
"""Per-step metrics; on the last step of an episode they describe the whole episode. `mean_joint_vel` and
`mean_joint_acc`: the episode's mean so far of ||qvel|| and ||qacc|| as each step leaves them (qacc: the last
physics substep's), the norms the joint penalties weigh (paper, "Reward formulations": the acceleration
penalty's effect on the mean acceleration)."""


def _total(terms: dict) -> jax.Array:
    """The reward terms summed left to right in their order (a + (-p) is a - p exactly: the rewards of the
    formulation-minus-penalties code before the terms existed)."""
    return functools.reduce(operator.add, terms.values())


def _take(tree, index):
    return jax.tree.map(lambda x: x[index], tree)


def _raw_key(key):
    """A key as plain uint32 data: info entries pass through `jnp.where` on auto-reset, typed keys do not."""
    return jax.random.key_data(key) if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key) else key


class ArmEnv(Env):
    """A robot arm that must bring its end effector to a target. See `ReachConfig`. Build it with `envs.make` or
    `envs.from_config`, which check the config: the constructor trusts it and checks nothing."""

    def __init__(self, robot: Robot, config: ReachConfig):
        self.robot = robot
        self.config = config
        self.d_max = config.d_max if config.d_max is not None else robot.reach
        self.physics_dt = float(robot.mj_model.opt.timestep)
        self.dt = self.physics_dt * config.substeps
        self._init_low, self._init_high = robot.joint_range(config.init_range)
        self._backend = physics.resolve(config.backend)
        self.physics = physics.PHYSICS[self._backend](robot, config.substeps)
        # Array shapes decided from the config once, here: `with_config` keeps them (`program_key`).
        self.candidate_counts = {q: self.count_candidates(q) for q in ("pose", "target", "obstacle")}

    def program_key(self) -> tuple:
        """What this env decided at construction that a field of `TRACED_FIELDS` may change: envs alike in it trace
        into one program for every value of such a field (`with_config`)."""
        return tuple(sorted(self.candidate_counts.items()))

    def with_config(self, config: ReachConfig) -> ArmEnv:
        """This env reading `config` in its traced functions, with what it decided at construction kept (candidate
        counts, physics backend, joint ranges): `config` may differ from the env's own only in its class's
        `TRACED_FIELDS`, whose values may be traced arrays (one evaluation program for many settings, `agents.sweep`)."""
        traced = type(config).TRACED_FIELDS
        other = [f.name for f in dataclasses.fields(config) if f.name not in traced
                 and getattr(config, f.name) != getattr(self.config, f.name)]
        if type(config) is not type(self.config) or other:
            raise ValueError(f"with_config: the config differs in {other or type(config).__name__} besides "
                             f"TRACED_FIELDS={traced!r}; allowed are configs differing only in those.")
        env = copy.copy(self)
        env.config = config
        return env

    # ----------------------------------------------------------------------------------------
    # Interface

    @functools.cached_property
    def observation_part_sizes(self) -> dict[str, int]:
        """Length of each configured observation part, in order: the size of its value in `observation_parts`
        on a reset state, traced abstractly (nothing runs), so a part's name, value and size are one entry. Envs
        built alike (env class and its `observation_parts` and `_reset` as defined now, robot class and options,
        config) share one tracing per process."""
        cls = type(self)
        key = (cls, cls.observation_parts, cls._reset, type(self.robot), self.robot.gravity_compensation,
               self.robot.integrator, self.config)
        try:
            hash(key)
        except TypeError:  # a config holding a traced value (`with_config`) is not hashable: traced each time
            return self._traced_part_sizes()
        return dict(_PART_SIZES.get(key, self._traced_part_sizes))

    def _traced_part_sizes(self) -> dict[str, int]:
        def parts(rng):
            state = self._reset(rng)
            data = state.pipeline_state
            values = self.observation_parts(data, data.xpos, data.site_xpos[self.robot.ee_site], state.info)
            return {part: jnp.ravel(values[part]()) for part in self.config.observation}

        shapes = jax.eval_shape(parts, jax.random.PRNGKey(0))
        return {part: int(shapes[part].shape[0]) for part in self.config.observation}

    @property
    def observation_size(self) -> int:
        return sum(self.observation_part_sizes.values())

    @property
    def action_size(self) -> int:
        return self.robot.nq

    @property
    def backend(self) -> str:
        """The physics backend stepping this env, "mjx" or "mujoco" (`config.backend` resolved)."""
        return self._backend

    def reset(self, rng: jax.Array) -> State:
        # Physics and kinematics in full float32: TF32 matmuls on recent GPUs change MJX results.
        with jax.default_matmul_precision("highest"):
            return self._reset(rng)

    def step(self, state: State, action: jax.Array) -> State:
        # GPU-friendly replacements of MJX's Cholesky calls and line-search loop (`envs.fast_mjx`):
        # the same numbers with far fewer kernel and graph launches per step.
        check_state(state, f"one {self.robot.name} env", self.robot.nq)
        check_action(action, (self.action_size,), f"one {self.robot.name} env (one action per joint)")
        with jax.default_matmul_precision("highest"), fast_mjx.fast_mjx():
            return self._step(state, action)

    def _reset(self, rng: jax.Array) -> State:
        cfg, robot = self.config, self.robot
        k_pose, k_target, k_task = jax.random.split(rng, 3)
        qpos, kin, free = robot.sample_poses(k_pose, self.candidates("pose"), self._init_low, self._init_high)
        index, pose_ok = first_valid(free)
        q0, kin0 = qpos[index], _take(kin, index)
        target, target_qpos, target_ok = self.sample_target(k_target)
        task_info, task_ok = self.sample_task(k_task, kin0, target)

        data = robot.data_template
        mocap = data.mocap_pos.at[robot.target_mocap].set(target)
        if "obstacle_pos" in task_info:  # the model's one obstacle body: the first obstacle at the episode's start
            mocap = mocap.at[robot.obstacle_mocap].set(task_info["obstacle_pos"][:3])
        # Kinematic fields filled in, so the initial state can be rendered or inspected as is.
        data = data.replace(qpos=q0, ctrl=q0, mocap_pos=mocap, xpos=kin0.xpos, geom_xpos=kin0.geom_xpos,
                            geom_xmat=kin0.geom_xmat, site_xpos=kin0.site_xpos)
        distance = jnp.linalg.norm(kin0.ee_pos - target)
        fallback = 1.0 - (pose_ok & target_ok & task_ok).astype(jnp.float32)
        info = {
            "target_pos": target,
            "target_qpos": target_qpos,
            # With latency, the action the first step applies: one that holds the initial pose.
            "prev_action": self.hold_action(q0) if cfg.action_latency else jnp.zeros(robot.nq),
            "prev_ee_pos": kin0.ee_pos,
            "in_target": jnp.zeros(()),
            "reached": jnp.zeros(()),
            "steps_in_target": jnp.zeros(()),
            "times_left_target": jnp.zeros(()),
            "mean_joint_vel": jnp.zeros(()),
            "mean_joint_acc": jnp.zeros(()),
            "recent_distances": jnp.full((LAST_DISTANCES,), distance),
            "num_steps": jnp.zeros((), jnp.int32),
            "reward_sums": {name: jnp.zeros(()) for name in self.reward_term_names()},
            "reset_fallback": fallback,
            **task_info,
        }
        if self.noisy:
            # A fourth key of `rng`, independent of the three above (which stay those of a noise-free env).
            info["noise_key"] = _raw_key(jax.random.split(rng, 4)[3])
        obs = self.observation(data, kin0.xpos, kin0.ee_pos, info)
        zero = jnp.zeros(())
        metrics = {name: zero for name in METRICS} | {"reward/" + name: zero for name in self.reward_term_names()}
        metrics.update(distance=distance, distance_last10=distance, reset_fallback=fallback)
        return State(pipeline_state=data, obs=obs, reward=zero, done=zero, metrics=metrics, info=info)

    def _step(self, state: State, action: jax.Array) -> State:
        cfg, robot = self.config, self.robot
        action = jnp.clip(action, -1.0, 1.0)
        # One-step latency applies the action chosen a step earlier (kept in prev_action).
        applied = state.info["prev_action"] if cfg.action_latency else action
        data = state.pipeline_state
        data = data.replace(ctrl=self.action_to_ctrl(applied, data.ctrl if cfg.relative_to == "target" else data.qpos))
        start = state.info["num_steps"] * cfg.substeps  # physics steps of the episode before this one

        def distances(geom_xpos, geom_xmat, k):
            # at substep k's start, against the task (moving obstacles) at that time
            return self.collision_distances(geom_xpos, geom_xmat, self.task_at(state.info, start + k))

        data, closest = self.physics.run(data, distances)
        # Poses of the final configuration (mjx.step computed those of the last substep's start).
        kin = robot.kinematics(data.qpos)
        data = data.replace(xpos=kin.xpos, geom_xpos=kin.geom_xpos, geom_xmat=kin.geom_xmat, site_xpos=kin.site_xpos)
        info = self.task_at(dict(state.info), start + cfg.substeps)  # the reward and observation see the step's end
        closest = jnp.minimum(closest, self.collision_distances(data.geom_xpos, data.geom_xmat, info))

        nan = ~(jnp.all(jnp.isfinite(data.qpos)) & jnp.all(jnp.isfinite(data.qvel)))
        self_collision = (closest[0] < 0) & ~nan
        obstacle_collision = (closest[1] < 0) & ~nan
        collided = self_collision | obstacle_collision
        failed = collided | nan

        ee = data.site_xpos[robot.ee_site]
        # A NaN step (e.g. a NaN action) keeps the last finite distance, so averages over episodes stay finite.
        distance = jnp.where(nan, info["recent_distances"][0], jnp.linalg.norm(ee - info["target_pos"]))
        in_target = (distance < cfg.target_radius) & ~failed
        reached = jnp.maximum(info["reached"], in_target)
        left = (info["in_target"] > 0) & ~in_target & ~failed
        recent = jnp.roll(info["recent_distances"], 1).at[0].set(distance)
        num_steps = info["num_steps"] + 1
        mean_vel = self.running_mean(info["mean_joint_vel"], jnp.linalg.norm(data.qvel), num_steps, nan)
        mean_acc = self.running_mean(info["mean_joint_acc"], jnp.linalg.norm(data.qacc), num_steps, nan)

        terms = self.reward_terms(data, distance, in_target.astype(jnp.float32), info)
        reward = _total(terms)
        collision = -cfg.collision_penalty * collided
        reward = jnp.where(failed, collision, reward)
        terms = {name: jnp.where(failed, 0.0, value) for name, value in terms.items()}  # what the step really earned
        if cfg.collision_penalty > 0:
            terms["collision"] = jnp.where(failed, collision, 0.0)
        done = failed | ((cfg.success == "reach_and_terminate") & in_target)

        info.update(
            prev_action=action,
            prev_ee_pos=jnp.where(nan, info["prev_ee_pos"], ee),
            in_target=in_target.astype(jnp.float32),
            reached=reached,
            steps_in_target=info["steps_in_target"] + in_target,
            times_left_target=info["times_left_target"] + left,
            mean_joint_vel=mean_vel,
            mean_joint_acc=mean_acc,
            recent_distances=recent,
            num_steps=num_steps,
            reward_sums={name: info["reward_sums"][name] + terms[name] for name in info["reward_sums"]},
        )
        obs = self.observation(data, data.xpos, ee, {**info, "prev_ee_pos": state.info["prev_ee_pos"]})
        obs = jnp.where(nan, state.obs, obs)  # NaN never reaches an observation
        count = jnp.minimum(num_steps, LAST_DISTANCES)
        last10 = jnp.sum(jnp.where(jnp.arange(LAST_DISTANCES) < count, recent, 0.0)) / count
        metrics = {
            **state.metrics,  # keys added by outer wrappers (Brax adds some) are kept
            "distance": distance,
            "distance_last10": last10,
            "in_target": in_target.astype(jnp.float32),
            "target_reached": reached * ~failed,
            "steps_in_target": info["steps_in_target"],
            "times_left_target": info["times_left_target"],
            "self_collision": self_collision.astype(jnp.float32),
            "obstacle_collision": obstacle_collision.astype(jnp.float32),
            "physics_nan": nan.astype(jnp.float32),
            "reset_fallback": info["reset_fallback"],
            "mean_joint_vel": mean_vel,
            "mean_joint_acc": mean_acc,
            **{"reward/" + name: value for name, value in info["reward_sums"].items()},
        }
        return state.replace(pipeline_state=data, obs=obs, reward=reward, done=done.astype(jnp.float32),
                             metrics=metrics, info=info)

    # ----------------------------------------------------------------------------------------
    # Pieces a task or a researcher may change

    @property
    def noisy(self) -> bool:
        """Whether observations carry sensor noise (then `info["noise_key"]` seeds it)."""
        return self.config.joint_noise_std > 0

    @staticmethod
    def running_mean(mean, value, count, nan) -> jax.Array:
        """The mean of `count` values from that of the first `count - 1` and `value`; a NaN step adds nothing."""
        return jnp.where(nan | ~jnp.isfinite(value), mean, mean + (value - mean) / count)

    def hold_action(self, qpos: jax.Array) -> jax.Array:
        """The action whose joint targets are `qpos` (within the joint range)."""
        if self.config.action == "absolute":
            low, high = self.robot.joint_low, self.robot.joint_high
            return 2.0 * (qpos - low) / (high - low) - 1.0
        return jnp.zeros_like(qpos)

    def action_to_ctrl(self, action: jax.Array, base: jax.Array) -> jax.Array:
        """Joint position targets from an action in [-1, 1], clipped to the joint range; a relative
        action is a delta from `base` (the joint positions or the last targets, `config.relative_to`)."""
        low, high = self.robot.joint_low, self.robot.joint_high
        if self.config.action == "absolute":
            target = low + 0.5 * (action + 1.0) * (high - low)
        else:
            target = base + self.config.relative_step(low, high) * action
        return jnp.clip(target, low, high)

    def candidates(self, quantity: str) -> int:
        """Rejection-sampling candidates for "pose", "target" or "obstacle" (`count_candidates` at construction)."""
        return self.candidate_counts[quantity]

    def count_candidates(self, quantity: str) -> int:
        """Rejection-sampling candidates for "pose", "target" or "obstacle".

        Sized from measured acceptance rates (uniform full-range configurations; 20,000 samples
        each, UR5e / Panda): collision-free pose 0.80 / 0.94; reachable target in the full
        workspace 0.80 / 0.94, front 0.40 / 0.48, upper 0.50 / 0.89; uniform upper 0.62 / 0.75;
        obstacle clear of pose and target 0.94 (0.1 m) and 0.67 (0.3 m). With the default 8, and
        3x, 2x or 2x where acceptance is lower, a reset falls back with probability about 1e-6. A moving
        obstacle's path must also stay clear of the base and the first link: none of 4,096 resets of the
        -moving3 presets fell back; obstacles of 1-2 m/s (a wider margin) did in 1 of 12.
        Every candidate costs forward kinematics and collision checks in every step's reset, so
        more than needed measurably slows training.
        """
        cfg = self.config
        n = cfg.sampling_candidates
        if quantity == "target" and cfg.workspace in ("front", "upper"):
            return n * (3 if cfg.target_sampling == "reachable" else 2)
        return n

    def sample_target(self, key):
        """Target position, the joint configuration that reaches it (zeros if unknown) and whether
        sampling succeeded."""
        cfg, robot = self.config, self.robot
        center = robot.workspace_center
        if cfg.target_sampling == "uniform":
            points, valid = workspaces.sample_uniform(cfg.workspace, key, self.candidates("target"), center, robot.reach)
            index, ok = first_valid(valid)
            return points[index], jnp.zeros(robot.nq), ok
        # Reachable: the end effector of a random collision-free pose, inside the workspace.
        points, qpos, free = robot.sample_reachable(key, self.candidates("target"))
        index, ok = first_valid(free & workspaces.contains(cfg.workspace, points, center, robot.reach))
        return points[index], qpos[index], ok

    def sample_task(self, key, kin0, target):
        """Task-specific episode data (the reach task has none) and whether sampling succeeded."""
        return {}, jnp.array(True)

    def task_at(self, info: dict, physics_step) -> dict:
        """`info` with the task's time-dependent entries (moving obstacles) at physics step
        `physics_step` of the episode; the reach task has none."""
        return info

    def collision_distances(self, geom_xpos, geom_xmat, info) -> jax.Array:
        """Closest signed distance of (self-collision pairs, obstacle pairs); < 0 is a collision."""
        self_min = jnp.min(self.robot.self_distances(geom_xpos, geom_xmat))
        return jnp.stack([self_min, jnp.inf])

    def penalties(self) -> dict:
        """Penalty terms of the reward: name -> (weight, f(data, info) -> the weighted penalty, >= 0). A term
        of weight 0 is left out of the reward (no cost, no number changed) and of the logs."""
        cfg, robot = self.config, self.robot
        return {
            "joint_vel": (cfg.w_joint_vel, lambda data, info: rewards.l2_penalty(data.qvel, cfg.w_joint_vel)),
            "joint_acc": (cfg.w_joint_acc, lambda data, info: rewards.l2_penalty(data.qacc, cfg.w_joint_acc)),
            "joint_limit": (cfg.w_joint_limit, lambda data, info: rewards.joint_limit_proximity(
                data.qpos, robot.joint_low, robot.joint_high, cfg.w_joint_limit, cfg.joint_limit_margin)),
        }

    def reward_term_names(self) -> tuple[str, ...]:
        """The terms of `reward_terms` in their order, then "collision" when `collision_penalty` > 0; each is
        logged per episode as the metric reward/<name> (its sum over the episode's steps)."""
        cfg = self.config
        penalties = tuple(name for name, (weight, _) in self.penalties().items() if weight > 0)
        return (cfg.reward,) + penalties + (("collision",) if cfg.collision_penalty > 0 else ())

    def reward_terms(self, data, distance, in_target, info) -> dict[str, jax.Array]:
        """The reward of a step that did not collide as named terms: the formulation (paper eqs. 1-2,
        `rewards.TASK_REWARDS[config.reward]`), then each penalty of non-zero weight, negated."""
        cfg = self.config
        terms = {cfg.reward: rewards.TASK_REWARDS[cfg.reward](cfg, distance, in_target, self.d_max)}
        for name, (weight, penalty) in self.penalties().items():
            if weight > 0:  # static: a config without the term compiles the program it had before the term existed
                terms[name] = -penalty(data, info)
        return terms

    def reward(self, data, distance, in_target, info) -> jax.Array:
        """Reward of a step that did not collide: the terms summed in their order."""
        return _total(self.reward_terms(data, distance, in_target, info))

    def perceived(self, data, info, key):
        """(data, info) as the sensors report them: joint angles with `joint_noise_std` noise; with
        `joint_noise_model="encoders"` the body and geom poses too, from the kinematics of the noisy angles.
        info["kinematic_qpos"]: the angles the poses come from (the true ones under `angles`), for parts that
        compute poses of their own."""
        std = self.config.joint_noise_std
        if std > 0:
            info = {**info, "kinematic_qpos": data.qpos}
            data = data.replace(qpos=data.qpos + std * jax.random.normal(jax.random.fold_in(key, 0), data.qpos.shape))
            if self.config.joint_noise_model == "encoders":
                info["kinematic_qpos"] = data.qpos
                kin = self.robot.kinematics(data.qpos)
                data = data.replace(xpos=kin.xpos, geom_xpos=kin.geom_xpos, geom_xmat=kin.geom_xmat,
                                    site_xpos=kin.site_xpos)
        return data, info

    def observation_parts(self, data, xpos, ee, info) -> dict:
        """Functions computing each observation part (only the configured ones are called)."""
        return {
            "joint_pos": lambda: data.qpos,
            "joint_vel": lambda: data.qvel,
            "joint_acc": lambda: data.qacc,
            "ee_pos": lambda: ee,
            "ee_vel": lambda: (ee - info["prev_ee_pos"]) / self.dt,
            "target_pos": lambda: info["target_pos"],
            "ee_to_target": lambda: info["target_pos"] - ee,
            "prev_action": lambda: info["prev_action"],
            "joint_sin_cos": lambda: jnp.concatenate([jnp.sin(data.qpos), jnp.cos(data.qpos)]),
            "self_dist": lambda: self.robot.self_distances(data.geom_xpos, data.geom_xmat),
            "link_pos": lambda: self.robot.link_positions(xpos),  # [nlinks, 3], link-major once ravelled
        }

    def observation(self, data, xpos, ee, info) -> jax.Array:
        if self.noisy:  # fresh noise every step of the episode, from its reset key
            data, info = self.perceived(data, info, jax.random.fold_in(info["noise_key"], info["num_steps"]))
            xpos, ee = data.xpos, data.site_xpos[self.robot.ee_site]  # the poses as perceived (`perceived`)
        parts = self.observation_parts(data, xpos, ee, info)
        return jnp.concatenate([jnp.ravel(parts[p]()) for p in self.config.observation]).astype(jnp.float32)
