"""Learners for the reach / reach-avoid benchmark: PPO and SAC on one shared, compiled loop.

    from agents import TrainConfig, train, PPOConfig
    import envs
    config = TrainConfig(env=envs.default_config("point-mass"), algo=PPOConfig(num_envs=64, batch_size=64,
                         num_minibatches=8), env_name="point-mass", num_timesteps=100_000)
    result = train(config)          # logs, checkpoints, final evaluation under result.logdir

`train.py` at the repository root wraps this with named presets and a generated command line.
"""

from agents.checkpoint import Checkpointer
from agents.distributions import TanhNormal
from agents.driver import NonFiniteLossError, TrainConfig, TrainResult, config_from_json, evaluate, train, validate
from agents.loop import Learner, Parallel, Programs, TrainState, Transition, episode_metrics, make_chunk, make_evaluate
from agents.networks import MLP, TwinQ
from agents.normalizer import RunningStats
from agents.ppo import PPO, PPOConfig, gae, ppo_loss_terms
from agents.sac import SAC, SACConfig, critic_target, temperature_loss

__all__ = [
    "Checkpointer", "TanhNormal", "NonFiniteLossError", "TrainConfig", "TrainResult", "config_from_json", "evaluate",
    "train", "validate", "Learner", "Parallel", "Programs", "TrainState", "Transition", "make_chunk", "make_evaluate",
    "episode_metrics",
    "MLP", "TwinQ", "RunningStats", "PPO", "PPOConfig", "gae", "ppo_loss_terms", "SAC", "SACConfig", "critic_target",
    "temperature_loss",
]
