"""The reach-avoid task: reach the target without touching a static spherical obstacle."""

import jax
import jax.numpy as jnp

from envs import rewards
from envs.config import ReachAvoidConfig
from envs.robots import first_valid
from envs.tasks.reach import Reach


class ReachAvoid(Reach):
    """Reach with a sphere obstacle sampled per episode; see `ReachAvoidConfig`."""

    config: ReachAvoidConfig

    def sample_task(self, key, kin0, target):
        """Obstacle centre uniform in the cube around the base, clear of the initial pose (every
        robot geom, the base included) and not swallowing the target."""
        cfg, robot = self.config, self.robot
        centers = jax.random.uniform(key, (self.candidates("obstacle"), 3), minval=-cfg.obstacle_region,
                                     maxval=cfg.obstacle_region)
        to_robot = robot.obstacle_distances(kin0.geom_xpos, kin0.geom_xmat, centers, cfg.obstacle_radius,
                                            geoms=robot.robot_geoms)
        clear_of_target = jnp.linalg.norm(centers - target, axis=-1) > cfg.obstacle_radius + cfg.target_radius
        index, ok = first_valid(jnp.all(to_robot > 0.0, axis=-1) & clear_of_target)
        return {"obstacle_pos": centers[index]}, ok

    def collision_distances(self, geom_xpos, geom_xmat, info):
        self_min = jnp.min(self.robot.self_distances(geom_xpos, geom_xmat))
        obstacle = self.robot.obstacle_distances(geom_xpos, geom_xmat, info["obstacle_pos"], self.config.obstacle_radius)
        return jnp.stack([self_min, jnp.min(obstacle)])

    def link_distances(self, data, xpos, info):
        """The paper's d_i per link (see `ReachAvoidConfig.link_distance`)."""
        return self.robot.link_obstacle_distances(xpos, data.geom_xpos, data.geom_xmat, info["obstacle_pos"],
                                                  self.config.obstacle_radius, self.config.link_distance)

    def reward(self, data, distance, in_target, info):
        cfg = self.config
        penalty = rewards.obstacle_proximity(self.link_distances(data, data.xpos, info), cfg.w_obst, cfg.obstacle_tau)
        return super().reward(data, distance, in_target, info) - penalty

    def _observation_sizes(self):
        return {**super()._observation_sizes(), "obstacle_pos": 3, "obstacle_size": 3,
                "link_obstacle_dist": len(self.robot.link_bodies)}

    def observation_parts(self, data, xpos, ee, info):
        parts = super().observation_parts(data, xpos, ee, info)
        parts.update(
            obstacle_pos=lambda: info["obstacle_pos"],
            obstacle_size=lambda: jnp.full(3, self.config.obstacle_radius),
            link_obstacle_dist=lambda: self.link_distances(data, xpos, info),
        )
        return parts
