"""Learners for the reach / reach-avoid benchmark: PPO and SAC on one shared, compiled loop.

    from agents import train
    from agents.presets import make_config
    result = train(make_config("point-mass-ppo", num_timesteps=50_000))
    print(result.eval_metrics["episode/target_reached"])    # per seed

Layout: `registry` (algorithm name -> config and learner class), `config` (TrainConfig, validation,
JSON), `presets` (named setups), `driver` (the run: chunks, checkpoints, Ctrl-C), `loop` (the
compiled rollout + update), `ppo` / `sac` (one file per algorithm), `logger`, `export` (policy
exports), `evaluation` (evaluating checkpoints and baselines).
"""

from agents import xla_flags

xla_flags.apply()  # before anything starts a JAX backend: see agents/xla_flags.py

from agents import registry  # noqa: E402
from agents.checkpoint import Checkpointer  # noqa: E402
from agents.config import TrainConfig, config_from_json, validate  # noqa: E402
from agents.distributions import TanhNormal  # noqa: E402
from agents.driver import NonFiniteLossError, TrainResult, evaluate, train  # noqa: E402
from agents.loop import Learner, Parallel, Programs, TrainState, Transition, episode_metrics, make_chunk, make_evaluate  # noqa: E402
from agents.networks import MLP, TwinQ  # noqa: E402
from agents.normalizer import RunningStats  # noqa: E402
from agents.ppo import PPO, PPOConfig, gae, ppo_loss_terms  # noqa: E402
from agents.sac import SAC, SACConfig, critic_target, temperature_loss  # noqa: E402

__all__ = [
    "registry", "Checkpointer", "TanhNormal", "NonFiniteLossError", "TrainConfig", "TrainResult", "config_from_json",
    "evaluate", "train", "validate", "Learner", "Parallel", "Programs", "TrainState", "Transition", "make_chunk",
    "make_evaluate", "episode_metrics", "MLP", "TwinQ", "RunningStats", "PPO", "PPOConfig", "gae", "ppo_loss_terms",
    "SAC", "SACConfig", "critic_target", "temperature_loss",
]
