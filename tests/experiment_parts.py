"""A toy experiment on the point mass and hand-made part folders, shared by the experiment tools' tests."""

import json
import os

from agents.config import config_json
from tools import experiment_spec as spec
from tools import experiment_state as state

TOY_RUN = dict(eval_envs=16, tensorboard=False, progress=False)
# point-mass-ppo trains 5,120 env steps per update: two updates per run. The runs differ in their seeds
# only, so they share one compiled program (the test takes a minute on a loaded 2-core CPU, not two).
TOY = spec.Experiment("toy", "point mass: two sets of seeds", "not in the paper", (
    spec.Run("a", "point-mass-ppo", dict(TOY_RUN), seeds=2, num_timesteps=10_240, paper=dict(target_reached=0.5)),
    spec.Run("b", "point-mass-ppo", {**TOY_RUN, "seed": 10}, seeds=2, num_timesteps=10_240),
), metrics=("target_reached", "distance", "wall_clock"), curves=("episode/target_reached",),
    cross=(spec.Cross("a", "wide-goal", {"goal_radius": 0.5}), spec.Cross("a", "sampled", {}, stochastic=True)))


def write_file(path, text):
    """`text` into `path`, its folders made."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)


def metrics_csv(path, steps, seeds, rate, wall):
    """A metrics.csv of `seeds` seeds logged at `steps` with the given speed and chunk times."""
    rows = ["env_steps,seed,steps_per_second,wall_seconds,episode/target_reached"]
    rows += [f"{s},{i},{rate * seeds},{w},0.5" for s, w in zip(steps, wall) for i in range(seeds)]
    write_file(path, "\n".join(rows) + "\n")


def make_part(run, runs_dir, exp, run_name, first, count, steps=(), evaluated=None, metrics=None, config=None,
          device=None):
    """A hand-made part folder: config.json, checkpoint folders, eval.json (with `device` where given) and
    metrics.csv as given."""
    logdir = os.path.join(runs_dir, exp, run_name, state.part_name(first, count))
    config = config or run.config(logdir, first_seed=first, seeds=count)
    write_file(os.path.join(logdir, "config.json"), json.dumps(config_json(config)))
    for step in steps:
        os.makedirs(os.path.join(logdir, "checkpoints", str(step)))
    if evaluated is not None:
        per_seed = {"episode/target_reached": [0.1 * (first + i) for i in range(count)]}
        write_file(os.path.join(logdir, "eval.json"), json.dumps({"env_steps": evaluated, "eval_envs": 16, "per_seed": per_seed,
                                                              **({"device": device} if device else {})}))
    if metrics is not None:
        metrics_csv(os.path.join(logdir, "metrics.csv"), *metrics)
    return logdir


def fake_cross(events: list):
    """A stand-in for `state.cross_evaluate`: notes ("cross", first seed, cross name) in `events` and writes the part's
    cross-<name>.json as the real one would."""
    def cross_evaluate(run, part, cross):
        events.append(("cross", part.first, cross.name))
        path = os.path.join(part.logdir, f"cross-{cross.name}.json")
        write_file(path, json.dumps({"env_steps": 10240, "eval_envs": 16, "per_seed": {"episode/target_reached": [0.5]}}))
        return path

    return cross_evaluate
