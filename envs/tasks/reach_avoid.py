"""The reach-avoid task: reach the target without touching spherical obstacles (paper section
"Reach-Avoid Task": one static sphere of a fixed size; several, moving and random-size spheres and
noisy obstacle positions are options beyond it, see `ReachAvoidConfig`).

`info["obstacle_pos"]` holds every obstacle's centre at the state's time, flat (`3 * num_obstacles`,
so one obstacle keeps the paper's shape); a random radius adds `info["obstacle_radius"]`, a motion
its parameters (`info["obstacle_motion"]`) and `info["obstacle_vel"]`.
"""

import jax
import jax.numpy as jnp

from envs import rewards
from envs.config import ReachAvoidConfig
from envs.obstacles import MOTIONS
from envs.robots import first_valid
from envs.tasks.reach import Reach


PATH_STRIDE = 5
"""Control steps between two readings of a moving obstacle's path when it is drawn (`path_clear_of_fixed_geoms`)."""


class ReachAvoid(Reach):
    """Reach with sphere obstacles sampled per episode; see `ReachAvoidConfig`."""

    config: ReachAvoidConfig

    def __init__(self, robot, config: ReachAvoidConfig):
        super().__init__(robot, config)
        self.motion = MOTIONS[config.obstacle_motion]

    @property
    def noisy(self) -> bool:
        return super().noisy or self.config.obstacle_noise_std > 0

    def count_candidates(self, quantity: str) -> int:
        n = super().count_candidates(quantity)
        return 2 * n if quantity == "obstacle" and self.config.radius_bounds[1] > 0.15 else n

    def sample_task(self, key, kin0, target):
        """Each obstacle's centre uniform in the cube around the base, its position at time 0 clear of
        the initial pose (every robot geom, the base included) and not swallowing the target; its
        radius and motion are drawn with the candidate, so the check sees them. A moving obstacle's path
        over the episode also stays clear of the geoms no joint moves (`path_clear_of_fixed_geoms`)."""
        cfg, robot = self.config, self.robot
        region = cfg.obstacle_region
        shape = (cfg.num_obstacles, self.candidates("obstacle"))
        centers = jax.random.uniform(key, shape + (3,), minval=-region, maxval=region)
        if cfg.obstacle_radius_range is None:
            radii = jnp.full(shape, cfg.obstacle_radius)
        else:
            radii = jax.random.uniform(jax.random.fold_in(key, 1), shape, minval=cfg.radius_bounds[0],
                                       maxval=cfg.radius_bounds[1])
        start, params, clear_path = centers, {}, True
        if self.motion.moves:
            speeds = jax.random.uniform(jax.random.fold_in(key, 2), shape, minval=cfg.obstacle_speed_range[0],
                                        maxval=cfg.obstacle_speed_range[1])
            params = self.motion.sample(jax.random.fold_in(key, 3), centers, speeds, cfg.obstacle_period, region)
            start, _ = self.motion.state(params, 0.0, cfg.obstacle_period, region)
            clear_path = self.path_clear_of_fixed_geoms(params, radii, kin0)
        to_robot = robot.obstacle_distances(kin0.geom_xpos, kin0.geom_xmat, start, radii[..., None],
                                            geoms=robot.robot_geoms)
        clear_of_target = jnp.linalg.norm(start - target, axis=-1) > radii + cfg.target_radius
        index, ok = first_valid(jnp.all(to_robot > 0.0, axis=-1) & clear_of_target & clear_path)
        pick = lambda x: x[jnp.arange(cfg.num_obstacles), index]  # noqa: E731  (each obstacle's first valid candidate)
        info = {"obstacle_pos": jnp.ravel(pick(start))}
        if cfg.obstacle_radius_range is not None:
            info["obstacle_radius"] = pick(radii)
        if self.motion.moves:
            info["obstacle_motion"] = jax.tree.map(pick, params)
            info = self.task_at(info, 0)
        return info, jnp.all(ok)

    def path_clear_of_fixed_geoms(self, params, radii, kin0):
        """Whether each candidate motion keeps its obstacle clear of the geoms no joint moves (`robot.fixed_geoms`)
        for the whole episode (`config.episode_length` steps; a longer wrapper episode is not covered): an obstacle
        that runs into them collides whatever the policy does. The path is read every `PATH_STRIDE` control steps,
        each reading asked to be clear by half the way the fastest obstacle goes between two readings, so no time in
        between can touch."""
        cfg, robot = self.config, self.robot
        readings = -(-cfg.episode_length // PATH_STRIDE) + 1
        times = jnp.minimum(jnp.arange(readings) * PATH_STRIDE, cfg.episode_length) * self.dt
        margin = 0.5 * cfg.obstacle_speed_range[1] * PATH_STRIDE * self.dt

        def clear_at(t):
            position, _ = self.motion.state(params, t, cfg.obstacle_period, cfg.obstacle_region)
            distances = robot.obstacle_distances(kin0.geom_xpos, kin0.geom_xmat, position, radii[..., None],
                                                 geoms=robot.fixed_geoms)
            return jnp.all(distances > margin, axis=-1)

        return jnp.all(jax.vmap(clear_at)(times), axis=0)

    def task_at(self, info, physics_step):
        """Moving obstacles: their positions and velocities at physics step `physics_step`."""
        if not self.motion.moves:
            return info
        cfg = self.config
        position, velocity = self.motion.state(info["obstacle_motion"], physics_step * self.physics_dt,
                                               cfg.obstacle_period, cfg.obstacle_region)
        return {**info, "obstacle_pos": jnp.ravel(position), "obstacle_vel": jnp.ravel(velocity)}

    def obstacles(self, info):
        """(centres [n, 3], radii [n]) of the obstacles in `info`."""
        centers = jnp.reshape(info["obstacle_pos"], (-1, 3))
        if "obstacle_radius" in info:
            return centers, info["obstacle_radius"]
        return centers, jnp.full(centers.shape[0], self.config.obstacle_radius)

    def per_obstacle(self, info, fn):
        """`fn(centre, radius)` of each obstacle, stacked. One obstacle at a time, not batched over an
        obstacle axis: each is then the single-obstacle program, bit for bit (a batched axis changes
        XLA's fusion and the last bit of a distance)."""
        centers, radii = self.obstacles(info)
        return jnp.stack([fn(centers[j], radii[j]) for j in range(centers.shape[0])])

    @property
    def checked_geoms(self):
        """Robot geoms whose contact with an obstacle is a collision: the model's obstacle pairs (the geoms a joint
        moves; the paper's static obstacle can touch no other), and every robot geom when obstacles move, since a
        moving one could reach the base and the first link too (its path is drawn clear of them; a fallback reset's
        is not). The penalty and the link-distance observations stay on the pairs' links, which a policy moves."""
        return self.robot.robot_geoms if self.motion.moves else self.robot.obstacle_geoms

    def collision_distances(self, geom_xpos, geom_xmat, info):
        self_min = jnp.min(self.robot.self_distances(geom_xpos, geom_xmat))
        geoms = self.checked_geoms
        obstacle = self.per_obstacle(
            info, lambda c, r: self.robot.obstacle_distances(geom_xpos, geom_xmat, c, r, geoms))
        return jnp.stack([self_min, jnp.min(obstacle)])

    def link_distances(self, data, xpos, info):
        """The paper's d_i per obstacle and link, `[n, nlinks]` (see `ReachAvoidConfig.link_distance`)."""
        return self.per_obstacle(info, lambda c, r: self.robot.link_obstacle_distances(
            xpos, data.geom_xpos, data.geom_xmat, c, r, self.config.link_distance))

    def penalties(self):
        """Reach's penalties and eq. (3)'s, summed over the obstacles."""
        cfg = self.config

        def obstacle(data, info):
            distances = self.link_distances(data, data.xpos, info)
            return jnp.sum(rewards.obstacle_proximity(distances, cfg.w_obst, cfg.obstacle_tau))

        return {**super().penalties(), "obstacle": (cfg.w_obst, obstacle)}

    def perceived(self, data, info, key):
        """Reach's noisy joints, plus obstacle positions with `obstacle_noise_std` noise."""
        data, info = super().perceived(data, info, key)
        std = self.config.obstacle_noise_std
        if std > 0:
            noise = std * jax.random.normal(jax.random.fold_in(key, 1), info["obstacle_pos"].shape)
            info = {**info, "obstacle_pos": info["obstacle_pos"] + noise}
        return data, info

    def observation_parts(self, data, xpos, ee, info):
        parts = super().observation_parts(data, xpos, ee, info)
        parts.update(
            obstacle_pos=lambda: info["obstacle_pos"],
            obstacle_size=lambda: jnp.repeat(self.obstacles(info)[1], 3),  # the paper's 3D size of a sphere
            obstacle_radius=lambda: self.obstacles(info)[1],
            obstacle_vel=lambda: _velocity(info),
            # Per link, the nearest obstacle: one number per link whatever num_obstacles is.
            link_obstacle_dist=lambda: jnp.min(self.link_distances(data, xpos, info), axis=0),
            link_obstacle_ahead=lambda: self.link_distances_ahead(data, xpos, info),
            link_obstacle_ahead_moving=lambda: self.link_distances_ahead(data, xpos, info, arm_moving=True),
        )
        return parts

    def link_distances_ahead(self, data, xpos, info, arm_moving: bool = False):
        """Per horizon of `obstacle_lookahead`, each link's distance to the nearest obstacle moved on at its current
        velocity for that long, `[horizons * nlinks]`, horizon-major: the arm held still, or with `arm_moving` moved
        on too at its joint velocities, stopping at its joint limits (the agents' collisions measured in
        results/obstacles mostly need the arm's own motion). The angles are those the other kinematic parts see."""
        qpos = info.get("kinematic_qpos", data.qpos)
        out = []
        for horizon in self.config.obstacle_lookahead:
            moved = {**info, "obstacle_pos": info["obstacle_pos"] + horizon * _velocity(info)}
            posed, links = data, xpos
            if arm_moving:
                kin = self.robot.kinematics(
                    jnp.clip(qpos + horizon * data.qvel, self.robot.joint_low, self.robot.joint_high))
                posed, links = data.replace(geom_xpos=kin.geom_xpos, geom_xmat=kin.geom_xmat), kin.xpos
            out.append(jnp.min(self.link_distances(posed, links, moved), axis=0))
        return jnp.concatenate(out)


def _velocity(info) -> jax.Array:
    """Every obstacle's velocity, `[3 n]`: zero for static obstacles, whose info holds none."""
    return info["obstacle_vel"] if "obstacle_vel" in info else jnp.zeros_like(info["obstacle_pos"])
