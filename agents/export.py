"""Policy exports: what evaluation needs of a run, small and loadable on a CPU.

A checkpoint (`agents.checkpoint`) holds the whole `TrainState`: optimiser state, env states and,
for SAC, a replay buffer of ~570 MB per seed at paper size. Evaluating needs only the policy. The
training driver therefore writes, next to each checkpoint, `<step dir>/policy/`:

- `policy.json`: format version, env steps, algorithm, observation and action sizes, seeds, and
  the run's full config JSON (the one `agents.config.config_from_json` reads);
- `policy.npz`: the policy network's parameters and the observation normaliser's statistics, each
  with the run's leading seed axis (`policy/params/hidden_0/kernel`, ..., `obs_stats/mean`, ...).

`select` copies an export keeping only some trained seeds (`tools/ship_checkpoint.py` makes
the checkpoints under `results/checkpoints/` with it).

`load` rebuilds the learner's own deterministic policy from it (the registered learner's `policy`
on the state its `policy_state` builds from these arrays), so the export acts exactly as the trained learner does, without
building or compiling the training programs. An export directory can be copied anywhere (e.g.
`results/checkpoints/<name>/`) and loaded from there.
"""

from __future__ import annotations

import dataclasses
import json
import os
import zipfile

import jax
import numpy as np

from agents import normalizer, registry
from agents.checkpoint import write_atomic
from agents.config import config_from_json

DIRNAME = "policy"
"""Name of the export directory inside a checkpoint's step directory."""
FORMAT = 1


def _flatten(tree, prefix="") -> dict:
    out = {}
    for key, value in tree.items():
        name = f"{prefix}/{key}" if prefix else str(key)
        if isinstance(value, dict):
            out.update(_flatten(value, name))
        else:
            out[name] = np.asarray(value)
    return out


def _unflatten(flat: dict) -> dict:
    tree: dict = {}
    for name, value in flat.items():
        node = tree
        *path, leaf = name.split("/")
        for part in path:
            node = node.setdefault(part, {})
        node[leaf] = value
    return tree


def save(directory: str, learner, learner_state, config_json: dict, env_steps: int) -> str:
    """Writes the export of `learner`'s seed-batched state to `directory`; returns it."""
    params, stats = jax.device_get(learner.export_policy(learner_state))
    flat = _flatten({"policy": params})
    flat.update({"obs_stats/count": np.asarray(stats.count), "obs_stats/mean": np.asarray(stats.mean),
                 "obs_stats/var": np.asarray(stats.var)})
    seeds = int(flat["obs_stats/mean"].shape[0])
    first_kernel = flat["policy/params/hidden_0/kernel"]
    meta = {
        "format": FORMAT,
        "env_steps": int(env_steps),
        "algo_name": config_json["algo_name"],
        "env_name": config_json["env_name"],
        "seeds": [int(config_json["seed"]) + i for i in range(seeds)],
        "observation_size": int(first_kernel.shape[-2]),
        "action_size": int(flat["policy/params/out/bias"].shape[-1] // 2),
        "config": config_json,
    }
    return _write(directory, flat, meta)


def _write(directory: str, flat: dict, meta: dict) -> str:
    """policy.npz, then policy.json, each through a temporary file and a rename: a reader (or a run killed
    half way) finds each file whole, the old or the new one, and policy.json only beside its arrays."""
    os.makedirs(directory, exist_ok=True)
    npz = os.path.join(directory, "policy.npz")
    tmp = f"{npz}.tmp-{os.getpid()}"
    try:
        with open(tmp, "wb") as f:  # a file object: np.savez would append ".npz" to the temporary name
            np.savez(f, **flat)
        os.replace(tmp, npz)
    finally:
        if os.path.exists(tmp):  # a failed write (a full disk) leaves the old export and no debris
            os.remove(tmp)
    write_atomic(os.path.join(directory, "policy.json"), json.dumps(meta, indent=2))
    return directory


@dataclasses.dataclass
class PolicyExport:
    """A loaded export: the run's config, the seed-batched policy arrays and what they act with."""

    path: str
    """The export directory."""
    meta: dict
    """policy.json (format, env_steps, algo_name, env_name, seeds, sizes, config)."""
    config: object
    """The run's `agents.config.TrainConfig`."""
    learner: object
    """The registered learner built from the config (no compilation); `policy(state, obs)` acts."""
    state: object
    """The learner's state holding only the policy parameters and observation statistics, each
    with the leading seed axis (vmap `learner.policy` over it)."""

    @property
    def env_name(self) -> str:
        return self.config.env_name

    @property
    def env_steps(self) -> int:
        return int(self.meta["env_steps"])

    @property
    def seeds(self) -> list[int]:
        return list(self.meta["seeds"])

    @property
    def observation_size(self) -> int:
        return int(self.meta["observation_size"])

    @property
    def action_size(self) -> int:
        return int(self.meta["action_size"])


def find(path: str) -> str:
    """The export directory that `path` names: an export directory itself, a checkpoint step
    directory (`<logdir>/checkpoints/<step>`) or a train.py logdir (its newest checkpoint).
    ValueError if there is none; `MissingExport` if a checkpoint exists without an export."""
    path = os.path.abspath(path)
    if not os.path.exists(path):
        raise ValueError(f"checkpoint {path!r} does not exist: allowed is a train.py logdir, a checkpoint step "
                         "directory or a policy export directory.")
    if os.path.isfile(path):
        if os.path.basename(path) in ("policy.json", "policy.npz"):
            return os.path.dirname(path)
        raise ValueError(f"checkpoint {path!r} is a file: allowed is a train.py logdir, a checkpoint step directory or a "
                         "policy export directory.")
    if os.path.isfile(os.path.join(path, "policy.json")):
        return path
    if os.path.isfile(os.path.join(path, DIRNAME, "policy.json")):
        return os.path.join(path, DIRNAME)
    step_root = os.path.join(path, "checkpoints") if os.path.isdir(os.path.join(path, "checkpoints")) else path
    steps = sorted((int(d) for d in os.listdir(step_root) if d.isdigit() and os.path.isdir(os.path.join(step_root, d))))
    if steps:
        newest = os.path.join(step_root, str(steps[-1]))
        if os.path.isfile(os.path.join(newest, DIRNAME, "policy.json")):
            return os.path.join(newest, DIRNAME)
        raise MissingExport(newest)
    if os.path.isdir(os.path.join(path, "state")) and os.path.isdir(os.path.join(path, "config")):
        raise MissingExport(path)
    raise ValueError(f"checkpoint {path!r} holds no checkpoint and no policy export: allowed is a train.py logdir, "
                     "a checkpoint step directory or a policy export directory.")


class MissingExport(ValueError):
    """A checkpoint step directory without a policy export (a run from before exports existed)."""

    def __init__(self, step_dir: str):
        super().__init__(f"checkpoint {step_dir!r} has no policy export ({DIRNAME}/policy.json); write one with "
                         f"`python eval.py --checkpoint {step_dir}` (restores the full training state once).")
        self.step_dir = step_dir


class CorruptExport(ValueError):
    """A policy export whose file cannot be read; `step_dir` is its checkpoint's step directory if
    that holds a full checkpoint to rebuild it from (else None)."""

    def __init__(self, directory: str, name: str, error: BaseException):
        super().__init__(f"policy export {directory!r} is corrupt or unreadable: {name}: {type(error).__name__}: "
                         f"{str(error).splitlines()[0] if str(error) else ''}")
        parent = os.path.dirname(directory)
        full = os.path.basename(directory) == DIRNAME and all(
            os.path.isdir(os.path.join(parent, d)) for d in ("state", "config"))
        self.step_dir = parent if full else None


def load(path: str) -> PolicyExport:
    """Loads the export that `path` names (see `find`). ValueError if it is missing or corrupt
    (`CorruptExport` naming the file)."""
    directory = find(path)
    name = "policy.json"
    try:
        with open(os.path.join(directory, name)) as f:
            meta = json.load(f)
        if meta.get("format") != FORMAT:
            raise ValueError(f"format {meta.get('format')!r} is unsupported (allowed: {FORMAT})")
        config = config_from_json(meta["config"])
        name = "policy.npz"
        with np.load(os.path.join(directory, name)) as data:
            flat = {k: np.asarray(data[k]) for k in data.files}
        tree = _unflatten(flat)
        stats = normalizer.RunningStats(tree["obs_stats"]["count"], tree["obs_stats"]["mean"], tree["obs_stats"]["var"])
        params = tree["policy"]
    except (OSError, KeyError, TypeError, ValueError, AttributeError, json.JSONDecodeError, zipfile.BadZipFile,
            EOFError) as error:
        raise CorruptExport(directory, name, error) from None
    learner = registry.make_learner(config.algo, int(meta["observation_size"]), int(meta["action_size"]))
    _check_shapes(directory, learner, params, stats, meta)
    return PolicyExport(directory, meta, config, learner, learner.policy_state(params, stats))


def _check_shapes(directory, learner, params, stats, meta) -> None:
    """The arrays must be what the config's network expects (else a clear error, not one from jit)."""
    expected, _ = jax.eval_shape(lambda: learner.export_policy(learner.init(jax.random.PRNGKey(0))))
    exp_flat = {k: v.shape for k, v in _flatten(jax.tree.map(lambda s: np.zeros(s.shape), expected)).items()}
    got_flat = {k: v.shape[1:] for k, v in _flatten(params).items()}
    seeds = {v.shape[0] for v in _flatten(params).values()} | {stats.mean.shape[0]}
    if exp_flat != got_flat or len(seeds) != 1 or stats.mean.shape[1:] != (int(meta["observation_size"]),):
        raise ValueError(f"policy export {directory!r} is corrupt: its arrays {got_flat} do not match the network of "
                         f"its config {exp_flat}.")


def select(path: str, directory: str, seeds: list[int] | None = None) -> str:
    """Writes the export that `path` names (see `find`) to `directory`, keeping only the trained
    `seeds` (seed numbers as in policy.json, e.g. [3]; None keeps all); returns `directory`.
    The new policy.json records where it came from under "selected_from"."""
    source = find(path)
    with open(os.path.join(source, "policy.json")) as f:
        meta = json.load(f)
    available = [int(s) for s in meta["seeds"]]
    seeds = available if seeds is None else [int(s) for s in seeds]
    unknown = [s for s in seeds if s not in available]
    if not seeds or unknown or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds={seeds!r} is invalid for {source!r}: allowed are distinct seeds out of {available}.")
    if os.path.abspath(directory) == source:
        raise ValueError(f"directory={directory!r} is invalid: it is the source export; allowed is another directory.")
    index = np.array([available.index(s) for s in seeds])
    with np.load(os.path.join(source, "policy.npz")) as data:
        flat = {k: np.asarray(data[k])[index] for k in data.files}
    shown = os.path.relpath(source)
    meta = dict(meta, seeds=seeds, selected_from={"path": source if shown.startswith("..") else shown, "seeds": available})
    return _write(directory, flat, meta)

