"""The algorithms a run can use: name -> (config class, learner class).

The rest of the code asks this registry instead of testing types, so a new learner touches its own
file and one `register` line below. A learner class is built as
`learner_cls(config, observation_size, action_size, total_updates)` and implements
`agents.loop.Learner`.
"""

from __future__ import annotations

import dataclasses

from agents.ppo import PPO, PPOConfig
from agents.sac import SAC, SACConfig


@dataclasses.dataclass(frozen=True)
class Algorithm:
    name: str
    """Short name stored in checkpoints and exports ("ppo")."""
    config_cls: type
    """Frozen dataclass of hyperparameters; has `num_envs`, `env_steps_per_update`, `validate(num_devices)`."""
    learner_cls: type
    """The learner (agents.loop.Learner) built from a config of `config_cls`."""


ALGORITHMS: dict[str, Algorithm] = {}


def register(name: str, config_cls: type, learner_cls: type) -> Algorithm:
    """Adds an algorithm; its name must be new and its config class not registered under another name."""
    if name in ALGORITHMS or any(a.config_cls is config_cls for a in ALGORITHMS.values()):
        raise ValueError(f"algorithm {name!r} ({config_cls.__name__}) is registered already.")
    ALGORITHMS[name] = Algorithm(name, config_cls, learner_cls)
    return ALGORITHMS[name]


def by_name(name: str) -> Algorithm:
    if name not in ALGORITHMS:
        raise ValueError(f"algo_name={name!r} is unknown: allowed are {', '.join(ALGORITHMS)}.")
    return ALGORITHMS[name]


def of_config(algo_config) -> Algorithm:
    """The algorithm whose config class `algo_config` is an instance of (exact type)."""
    for algorithm in ALGORITHMS.values():
        if type(algo_config) is algorithm.config_cls:
            return algorithm
    allowed = ", ".join(a.config_cls.__name__ for a in ALGORITHMS.values())
    raise ValueError(f"algo={type(algo_config).__name__} is unknown: allowed are {allowed}.")


def make_learner(algo_config, observation_size: int, action_size: int, total_updates: int = 1,
                 learner_cls: type | None = None):
    """The learner of `algo_config` (or `learner_cls`, e.g. a subclass, built with the same arguments)."""
    cls = learner_cls or of_config(algo_config).learner_cls
    return cls(algo_config, observation_size, action_size, total_updates)


register("ppo", PPOConfig, PPO)
register("sac", SACConfig, SAC)
