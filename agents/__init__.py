"""Learners for the reach / reach-avoid benchmark: PPO and SAC on one shared, compiled loop.

    from agents import TrainConfig, train, PPOConfig
    import envs
    config = TrainConfig(env=envs.default_config("point-mass"), algo=PPOConfig(num_envs=64, batch_size=64,
                         num_minibatches=8), env_name="point-mass", num_timesteps=100_000)
    result = train(config)          # logs, checkpoints, final evaluation under result.logdir

`train.py` at the repository root wraps this with named presets and a generated command line.
"""

from agents import xla_flags

xla_flags.apply()  # before anything starts a JAX backend: see agents/xla_flags.py

from agents.checkpoint import Checkpointer  # noqa: E402
from agents.distributions import TanhNormal  # noqa: E402
from agents.driver import NonFiniteLossError, TrainConfig, TrainResult, config_from_json, evaluate, train, validate  # noqa: E402
from agents.loop import Learner, Parallel, Programs, TrainState, Transition, episode_metrics, make_chunk, make_evaluate  # noqa: E402
from agents.networks import MLP, TwinQ  # noqa: E402
from agents.normalizer import RunningStats  # noqa: E402
from agents.ppo import PPO, PPOConfig, gae, ppo_loss_terms  # noqa: E402
from agents.sac import SAC, SACConfig, critic_target, temperature_loss  # noqa: E402

__all__ = [
    "Checkpointer", "TanhNormal", "NonFiniteLossError", "TrainConfig", "TrainResult", "config_from_json", "evaluate",
    "train", "validate", "Learner", "Parallel", "Programs", "TrainState", "Transition", "make_chunk", "make_evaluate",
    "episode_metrics",
    "MLP", "TwinQ", "RunningStats", "PPO", "PPOConfig", "gae", "ppo_loss_terms", "SAC", "SACConfig", "critic_target",
    "temperature_loss",
]
