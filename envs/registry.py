"""Environment names and `make`.

`make(name, **options)` builds the config of that environment with `options` replacing its
defaults, validates it (a `ValueError` names the field, the value and what is allowed) and returns
the unwrapped, single environment. A config is checked where it enters (`make`, `make_config`,
`from_config`, or `agents.validate` for a training run); `build` and the env classes below them trust it.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

from envs.base import Env


@dataclasses.dataclass(frozen=True)
class EnvSpec:
    """How to build one registered environment."""

    default_config: Callable[[], object]
    """Returns the environment's default config (a frozen dataclass)."""
    build: Callable[[object], Env]
    """Builds the environment from a checked config (`check_config`); it checks nothing itself."""
    description: str
    """One line shown by `envs.names()` users and error messages."""
    robot: str | None = None
    """The arm's name (a key of `envs.robots.ROBOTS`), None for envs without one (the point mass):
    a policy moves only the robot it was trained on, and only arms can be rendered."""
    check: Callable[[object], None] | None = None
    """Validates a config for this env beyond its own `validate` (e.g. bounds from the robot); None:
    `config.validate()` alone."""


_REGISTRY: dict[str, EnvSpec] = {}


def register(name: str, spec: EnvSpec) -> None:
    """Adds an environment under `name` (later registrations replace earlier ones)."""
    _REGISTRY[name] = spec


def names() -> list[str]:
    """The registered environment names."""
    return sorted(_REGISTRY)


def spec(name: str) -> EnvSpec:
    """The registry entry of `name`; a `ValueError` lists the valid names otherwise."""
    if not isinstance(name, str) or name not in _REGISTRY:
        raise ValueError(f"env={name!r} is unknown: allowed are {', '.join(names())}.")
    return _REGISTRY[name]


def default_config(name: str):
    """The default config of environment `name`."""
    return spec(name).default_config()


def make_config(name: str, base=None, /, **options):
    """The config of `name`: `base` (default: the env's defaults) with `options` replacing fields;
    validated. A `base` of another config class (a reach checkpoint's config for a reach-avoid env)
    gives the fields both classes have, the rest from `name`'s defaults."""
    config = default_config(name)
    if base is not None and type(base) is type(config):
        config = base
    elif base is not None:
        names = {f.name for f in dataclasses.fields(config)}
        config = dataclasses.replace(config, **{f.name: getattr(base, f.name) for f in dataclasses.fields(base)
                                                if f.name in names})
    fields = {f.name for f in dataclasses.fields(config)}
    unknown = sorted(set(options) - fields)
    if unknown:
        raise ValueError(
            f"option {unknown[0]!r} does not exist for env {name!r}: allowed are {', '.join(sorted(fields))}."
        )
    config = dataclasses.replace(config, **options)
    check_config(name, config)
    return config


def check_config(name: str, config) -> None:
    """ValueError naming the field, the value and what is allowed, for `config` as the config of env
    `name` (its `validate` plus the env's own `check`); nothing is built or traced. TypeError for a config of
    another class (a reach-avoid config for a reach env would fail at reset, missing the obstacle)."""
    entry = spec(name)
    expected = type(default_config(name))
    if type(config) is not expected:
        raise TypeError(f"config of type {type(config).__name__} is invalid for env {name!r}: allowed is "
                        f"{expected.__name__} (envs.make_config({name!r}, config) converts the fields both have).")
    if entry.check is None:
        config.validate()
    else:
        entry.check(config)


def make(name: str, **options) -> Env:
    """Builds environment `name` with config fields overridden by `options`.

    Example: `envs.make("ur5e-reach-avoid", obstacle_radius=0.2, workspace="front")`.
    """
    return build(name, make_config(name, **options))


def from_config(name: str, config) -> Env:
    """Builds environment `name` from a complete config (for example one stored in a checkpoint), checked first."""
    check_config(name, config)
    return build(name, config)


def build(name: str, config) -> Env:
    """Builds environment `name` from a config already checked for it where it was made (`make_config`,
    `from_config`, `agents.validate`); nothing is checked again, so code below those entry points uses this."""
    return spec(name).build(config)
