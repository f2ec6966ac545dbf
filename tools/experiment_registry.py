"""The registered experiments: the paper's experiments, our own studies beyond it, and a point-mass demo that
shows the launch machinery in two minutes on a CPU. Adding one: `register(Experiment(...))` in
tools/registry_paper_tasks.py (the paper's four tasks) or tools/registry_obstacles.py (several and moving
obstacles); `python -m tools.experiments list` shows it, and `tests/test_experiment_registry.py` validates every
run's config.

Seeds: 5 where the paper states numbers (tables, text), 3 for comparisons it shows only as curves or words;
fewer where a row's question was answered before its seeds were all trained (its experiment's note says so).
Budgets: the presets' (the paper states none per experiment), except where a run's `num_timesteps` says otherwise
(its table names it beside the overrides). The paper's numbers beside a run (`paper=`) come from
assets/paper_numbers.json (`paper_row`).
"""

# Imported for their registrations, in the order the index lists the experiments: the paper's tasks, the obstacles,
# then this demo.
from tools import registry_paper_tasks  # noqa: F401, I001
from tools import registry_obstacles  # noqa: F401
from tools.experiment_spec import Experiment, Run, register

register(Experiment(
    "point-mass-demo", "Point mass, PPO: launch, requeue and build in two minutes on a CPU",
    "not in the paper (a demo of launch, requeue and build)",
    (Run("ppo", "point-mass-ppo", {"eval_envs": 64, "tensorboard": False}, seeds=1, num_timesteps=4_000_000),),
    metrics=("target_reached", "distance", "wall_clock"), curves=("episode/target_reached",),
    note="One seed of the probe task, long enough that a job with a one-minute limit is requeued at least once."))
