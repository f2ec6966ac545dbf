"""Named training setups: one `Preset` per experiment of the paper, plus our own rows and small
CPU / probe settings. `train.py PRESET` starts from one; `make_config` builds it in Python.

Where a preset departs from the paper's settings (section "Training and evaluation"), its comment
says why in a clause and names the study under `results/` that measured it.
"""

from __future__ import annotations

import dataclasses

import envs
from agents.config import TrainConfig
from agents.ppo import PPOConfig
from agents.sac import SACConfig


@dataclasses.dataclass(frozen=True)
class Preset:
    description: str
    """One line shown by `train.py --help`."""
    env_name: str
    """Registered environment (envs.names())."""
    algo: object
    """Algorithm config (a registered config class, agents.registry)."""
    env: dict = dataclasses.field(default_factory=dict)
    """Environment options replacing the env's defaults (fields of its config dataclass)."""
    run: dict = dataclasses.field(default_factory=dict)
    """TrainConfig fields replacing its defaults (num_timesteps, eval_envs, ...)."""


# The paper's settings: batch 512, 64 minibatches, lr 8e-4, gamma 0.97, 5 epochs, unroll 10, 3x256.
PPO_PAPER = PPOConfig()
PPO_PAPER_ABSOLUTE = dataclasses.replace(PPO_PAPER, updates_per_batch=7, policy_hidden_sizes=(256,) * 4,
                                         value_hidden_sizes=(256,) * 4)
PPO_PAPER_REACH_AVOID = dataclasses.replace(PPO_PAPER, policy_hidden_sizes=(256,) * 4, value_hidden_sizes=(256,) * 4)
# Discount 0.99 on reach: with 0.97 UR5e policies pinned joints at their limits and missed (results: discount study).
PPO_REACH = dataclasses.replace(PPO_PAPER, discount=0.99)
# Panda reach-avoid: 0.98 balanced reaching and obstacle collisions best (results: discount study).
PPO_PANDA_REACH_AVOID = dataclasses.replace(PPO_PAPER_REACH_AVOID, discount=0.98)
# The paper's SAC (128 envs, batch 256, lr 1e-4, reward scale 20); it does not state the gradient steps per
# env step: 8 learned fastest of 1, 8 and 32 (results: SAC study).
SAC_PAPER = SACConfig(grad_updates_per_step=8)

# Fast SAC for thousands of envs (FastTD3 / FastSAC's recipe, agents/sac.py): 4,096 envs, batch 16,384, 4 gradient
# steps per vector step, 3-step returns, a categorical critic, LayerNorm, tau 0.1, a small initial temperature; wider
# critics learned faster per env step on UR5e reach, and bfloat16 hidden layers train them faster to the same
# success there (results/sac/fast).
SAC_FAST = SACConfig(num_envs=4096, batch_size=16_384, learning_rate=3e-4, discount=0.97, reward_scaling=1.0, tau=0.1,
                     min_replay_size=4096 * 8, max_replay_size=4096 * 512, grad_updates_per_step=4, init_alpha=0.01,
                     layer_norm=True, n_step=3, distributional=True, num_atoms=101, v_min=-10.0, v_max=40.0,
                     max_grad_norm=0.0, q_hidden_sizes=(512, 512, 256), compute_dtype="bfloat16")
# UR5e reach: 8,192 envs (4 gradient steps per 8,192 env steps, half SAC_FAST's per env step) train at 1.7x the env
# steps per second; given 170M steps they end above 4,096 envs at 100M in the same training time (results/sac/fast).
# The replay sizes stay SAC_FAST's: 256 vector steps kept instead of 512.
SAC_FAST_UR5E_REACH = dataclasses.replace(SAC_FAST, num_envs=8192)
# Reach-avoid's semi-sparse reward is larger per step: a wider support.
SAC_FAST_REACH_AVOID = dataclasses.replace(SAC_FAST, v_min=-20.0, v_max=120.0)
# The buffer is left out of checkpoints (checkpoint_envs=False): saving and resuming take seconds and a resume
# refills min_replay_size transitions first.
_FAST_RUN = dict(checkpoint_envs=False)

_ABSOLUTE = dict(action="absolute", observation=("joint_pos", "ee_pos", "target_pos", "ee_to_target", "prev_action"))
# The paper does not state the relative action scale; 0.3 beat 0.2 on the UR5e (results: action-scale study).
_UR5E_RELATIVE = dict(action_scale=0.3)
# Not in the paper: a penalty near the joint limits, where most UR5e misses ended (results: joint-limit study).
_UR5E_REACH = dict(_UR5E_RELATIVE, w_joint_limit=0.05, joint_limit_margin=0.5)
_UR5E_REACH_AVOID = dict(_UR5E_RELATIVE, w_joint_limit=1.0, joint_limit_margin=0.5)
# Not in the paper: sin/cos of the joint angles and self-collision distances observed (results: observation study).
_PLUS_REACH = ("joint_pos", "joint_sin_cos", "ee_pos", "target_pos", "ee_to_target", "self_dist")
_UR5E_PLUS = dict(_UR5E_RELATIVE, observation=_PLUS_REACH)
_PLUS_REACH_AVOID = _PLUS_REACH + ("obstacle_pos", "link_obstacle_dist")
_UR5E_PLUS_AVOID = dict(_UR5E_RELATIVE, observation=_PLUS_REACH_AVOID)
# Beyond the paper (the future work of its Discussion): 3 obstacles of random radius moving in straight
# lines that bounce off the sampling cube; their radii and velocities observed.
MOVING_OBSTACLES_3 = dict(
    num_obstacles=3, obstacle_motion="linear", obstacle_radius_range=(0.05, 0.1), obstacle_speed_range=(0.05, 0.2),
    observation=("joint_pos", "ee_pos", "target_pos", "ee_to_target", "obstacle_pos", "obstacle_radius", "obstacle_vel",
                 "link_obstacle_dist"))
MOVING_OBSTACLES_3_PLUS = dict(MOVING_OBSTACLES_3, observation=_PLUS_REACH + tuple(
    p for p in MOVING_OBSTACLES_3["observation"] if p not in _PLUS_REACH))
# The paper's rows with only its stated settings (section "Training and evaluation") and the literal reading of its
# relative control, "deltas that are added to the current joint positions": an action in [-1, 1] is a delta in
# radians (action scale 1); the envs' 0.2 is our own choice. Nothing else tuned (results/fidelity).
_PAPER_RELATIVE = dict(action_scale=1.0)
PPO_CPU = dataclasses.replace(PPO_PAPER, num_envs=16, batch_size=32, num_minibatches=4)

# Small, fast settings of the pure-JAX probe task (CPU: well under a minute).
_PROBE_NETS = dict(policy_hidden_sizes=(64, 64))
PPO_PROBE = PPOConfig(num_envs=64, batch_size=64, num_minibatches=8, unroll_length=10, updates_per_batch=4,
                      learning_rate=3e-3, value_hidden_sizes=(64, 64), **_PROBE_NETS)
SAC_PROBE = SACConfig(num_envs=16, batch_size=256, learning_rate=1e-3, reward_scaling=1.0, min_replay_size=1024,
                      max_replay_size=32_000, grad_updates_per_step=4, q_hidden_sizes=(64, 64), **_PROBE_NETS)
# float32 here: bfloat16 matmuls pay off on GPUs, and the probe runs in the CPU tests.
SAC_FAST_PROBE = dataclasses.replace(SAC_FAST, num_envs=64, batch_size=512, learning_rate=1e-3, min_replay_size=1024,
                                     max_replay_size=64 * 500, grad_updates_per_step=2, v_min=-5.0, v_max=25.0,
                                     q_hidden_sizes=(64, 64), compute_dtype="float32", **_PROBE_NETS)

PRESETS: dict[str, Preset] = {
    "point-mass-ppo": Preset("probe task, PPO (checks the learner in seconds)", "point-mass", PPO_PROBE,
                             run=dict(num_timesteps=150_000, eval_envs=256)),
    "point-mass-sac": Preset("probe task, SAC (checks the learner in seconds)", "point-mass", SAC_PROBE,
                             run=dict(num_timesteps=40_000, eval_envs=256)),
    "point-mass-sac-fast": Preset("probe task, fast SAC's ingredients at a small scale (checks the learner in seconds)",
                                  "point-mass", SAC_FAST_PROBE, run=dict(num_timesteps=60_000, eval_envs=256, **_FAST_RUN)),
    # The paper's experiments; each env's default config is the paper's best configuration for that task.
    "ur5e-reach-ppo": Preset("UR5e reach, full workspace, relative control (action scale 0.3), dense reward (paper) with a "
                             "joint-limit penalty of 0.05, discount 0.99", "ur5e-reach", PPO_REACH, env=_UR5E_REACH,
                             run=dict(num_timesteps=150_000_000)),
    "panda-reach-ppo": Preset("Panda reach, full workspace, relative control, dense reward (paper), discount 0.99",
                              "panda-reach", PPO_REACH, run=dict(num_timesteps=65_000_000)),
    "ur5e-reach-absolute-ppo": Preset("UR5e reach with absolute position control (paper: + previous action, 4x256, 7 epochs)",
                                      "ur5e-reach", PPO_PAPER_ABSOLUTE, env=_ABSOLUTE, run=dict(num_timesteps=200_000_000)),
    "ur5e-reach-sac": Preset("UR5e reach with SAC (paper; 8 gradient steps per env step)", "ur5e-reach", SAC_PAPER,
                             run=dict(num_timesteps=40_000_000)),
    "panda-reach-sac": Preset("Panda reach with SAC (paper; 8 gradient steps per env step)", "panda-reach", SAC_PAPER,
                              run=dict(num_timesteps=40_000_000)),
    "ur5e-reach-sac-limited": Preset("UR5e reach with SAC from the limited initial joint range (paper)", "ur5e-reach",
                                     SAC_PAPER, env=dict(init_range="limited"), run=dict(num_timesteps=40_000_000)),
    # Fast SAC (not in the paper): the same tasks and env options as the PPO presets.
    "ur5e-reach-sac-fast": Preset("UR5e reach with fast SAC (8,192 envs, n-step, categorical critic), ur5e-reach-ppo's "
                                  "env options + joint sin/cos and self-collision distances observed", "ur5e-reach",
                                  SAC_FAST_UR5E_REACH, env=dict(_UR5E_REACH, observation=_PLUS_REACH),
                                  run=dict(num_timesteps=170_000_000, **_FAST_RUN)),
    "panda-reach-sac-fast": Preset("Panda reach with fast SAC (4,096 envs, n-step, categorical critic) + joint sin/cos and "
                                   "self-collision distances observed", "panda-reach", SAC_FAST,
                                   env=dict(observation=_PLUS_REACH), run=dict(num_timesteps=200_000_000, **_FAST_RUN)),
    "ur5e-reach-avoid-sac-fast": Preset("UR5e reach-avoid with fast SAC (4,096 envs, n-step, categorical critic), "
                                        "ur5e-reach-avoid-ppo's env options + joint sin/cos and self-collision "
                                        "distances observed", "ur5e-reach-avoid", SAC_FAST_REACH_AVOID,
                                        env=dict(_UR5E_REACH_AVOID, observation=_PLUS_REACH_AVOID),
                                        run=dict(num_timesteps=200_000_000, **_FAST_RUN)),
    "panda-reach-avoid-sac-fast": Preset("Panda reach-avoid with fast SAC (4,096 envs, n-step, categorical critic) + "
                                         "joint sin/cos and self-collision distances observed", "panda-reach-avoid",
                                         SAC_FAST_REACH_AVOID, env=dict(observation=_PLUS_REACH_AVOID),
                                         run=dict(num_timesteps=200_000_000, **_FAST_RUN)),
    "ur5e-reach-avoid-ppo": Preset("UR5e reach-avoid, 0.1 m obstacle, semi-sparse reward (paper) with a joint-limit "
                                   "penalty of 1.0, 4x256 (paper), action scale 0.3", "ur5e-reach-avoid",
                                   PPO_PAPER_REACH_AVOID, env=_UR5E_REACH_AVOID, run=dict(num_timesteps=192_000_000)),
    "panda-reach-avoid-ppo": Preset("Panda reach-avoid, 0.1 m obstacle, semi-sparse reward, 4x256 (paper), discount 0.98",
                                    "panda-reach-avoid", PPO_PANDA_REACH_AVOID, run=dict(num_timesteps=100_000_000)),
    # Ours beyond the paper: the reach-avoid presets with 3 moving obstacles of random size (results/obstacles).
    # The UR5e one takes ur5e-reach-avoid-ppo-plus's options: with the paper's observation and the joint-limit
    # penalty it reached 5 % (results/obstacles/README.md).
    "ur5e-reach-avoid-ppo-moving3": Preset("ur5e-reach-avoid-ppo-plus with 3 obstacles of radius 0.05-0.1 m moving at "
                                           "0.05-0.2 m/s, their radii and velocities observed (not in the paper)",
                                           "ur5e-reach-avoid", PPO_PAPER_REACH_AVOID,
                                           env=dict(_UR5E_PLUS_AVOID, **MOVING_OBSTACLES_3_PLUS),
                                           run=dict(num_timesteps=192_000_000)),
    "panda-reach-avoid-ppo-moving3": Preset("panda-reach-avoid-ppo with 3 obstacles of radius 0.05-0.1 m moving at "
                                            "0.05-0.2 m/s, their radii and velocities observed (not in the paper)",
                                            "panda-reach-avoid", PPO_PANDA_REACH_AVOID, env=MOVING_OBSTACLES_3,
                                            run=dict(num_timesteps=100_000_000)),
    # The paper's settings only (no tuning of ours): one preset per row of the paper (results/fidelity).
    "ur5e-reach-ppo-paper": Preset("UR5e reach with the paper's settings only: relative control read literally (a delta "
                                   "of up to 1 rad), dense reward, discount 0.97, 3x256", "ur5e-reach", PPO_PAPER,
                                   env=_PAPER_RELATIVE, run=dict(num_timesteps=150_000_000)),
    "ur5e-reach-avoid-ppo-paper": Preset("UR5e reach-avoid with the paper's settings only: relative control read "
                                         "literally, semi-sparse reward, 0.1 m obstacle, discount 0.97, 4x256",
                                         "ur5e-reach-avoid", PPO_PAPER_REACH_AVOID, env=_PAPER_RELATIVE,
                                         run=dict(num_timesteps=192_000_000)),
    "panda-reach-ppo-paper": Preset("Panda reach with the paper's settings only: relative control read literally, dense "
                                    "reward, discount 0.97, 3x256", "panda-reach", PPO_PAPER, env=_PAPER_RELATIVE,
                                    run=dict(num_timesteps=65_000_000)),
    "panda-reach-avoid-ppo-paper": Preset("Panda reach-avoid with the paper's settings only: relative control read "
                                          "literally, semi-sparse reward, 0.1 m obstacle, discount 0.97, 4x256",
                                          "panda-reach-avoid", PPO_PAPER_REACH_AVOID, env=_PAPER_RELATIVE,
                                          run=dict(num_timesteps=100_000_000)),
    "ur5e-reach-sac-paper": Preset("UR5e reach with SAC and the paper's settings only: relative control read literally, "
                                   "128 envs, batch 256, lr 1e-4, reward scale 20, full initial range", "ur5e-reach",
                                   SAC_PAPER, env=_PAPER_RELATIVE, run=dict(num_timesteps=40_000_000)),
    # Ours beyond the paper: its presets plus the observation parts joint_sin_cos and self_dist.
    "ur5e-reach-ppo-plus": Preset("ur5e-reach-ppo without its joint-limit penalty, + joint sin/cos and self-collision "
                                  "distances observed (not in the paper)",
                                  "ur5e-reach", PPO_REACH, env=_UR5E_PLUS, run=dict(num_timesteps=150_000_000)),
    "ur5e-reach-avoid-ppo-plus": Preset("ur5e-reach-avoid-ppo without its joint-limit penalty, + joint sin/cos and "
                                        "self-collision distances observed (not in the paper)", "ur5e-reach-avoid",
                                        PPO_PAPER_REACH_AVOID, env=_UR5E_PLUS_AVOID, run=dict(num_timesteps=160_000_000)),
    "ur5e-reach-sac-plus": Preset("ur5e-reach-sac + joint sin/cos and self-collision distances observed (not in the paper)",
                                  "ur5e-reach", SAC_PAPER, env=dict(observation=_PLUS_REACH), run=dict(num_timesteps=40_000_000)),
    # Trained with the paper's discount 0.97, before the reach presets moved to 0.99.
    "panda-reach-ppo-plus": Preset("panda-reach-ppo + joint sin/cos and self-collision distances observed (not in the "
                                   "paper), discount 0.97", "panda-reach", PPO_PAPER, env=dict(observation=_PLUS_REACH),
                                   run=dict(num_timesteps=65_000_000)),
    # A few minutes on a laptop CPU: checks the whole pipeline on an arm, learns little.
    "ur5e-reach-ppo-cpu": Preset("UR5e reach, tiny batch for a CPU smoke run (minutes)", "ur5e-reach", PPO_CPU,
                                 run=dict(num_timesteps=10_240, eval_envs=16)),
}


def make_config(preset: str, **overrides) -> TrainConfig:
    """The preset's TrainConfig with `overrides` (TrainConfig fields) replacing its values; not checked here
    (`agents.validate`, which `agents.train` runs, checks the config a run is given)."""
    if preset not in PRESETS:
        raise ValueError(f"preset={preset!r} is unknown: allowed are {', '.join(sorted(PRESETS))}.")
    p = PRESETS[preset]
    env_config = dataclasses.replace(envs.default_config(p.env_name), **p.env)
    config = TrainConfig(env=env_config, algo=p.algo, env_name=p.env_name, preset=preset, **p.run)
    return dataclasses.replace(config, **overrides)
