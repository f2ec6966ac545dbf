"""Weights & Biases logging for `logger="wandb"`: one W&B run per seed, grouped by the run's logdir, with the rows of
metrics.csv, the run's config and the final evaluation. Offline by default: the W&B files go to `<logdir>/wandb/`
and nothing leaves the machine until `wandb sync`.

The W&B run ids are kept in `<logdir>/wandb/run_ids.json`, so that `--resume` continues the same W&B runs. Offline,
each train.py call writes its own `offline-run-*` directory under those ids; `wandb sync` uploads the directories
of one id in order of their start times, into one W&B run.
"""

from __future__ import annotations

import json
import os
import sys

from agents.checkpoint import write_atomic
from agents.config import TrainConfig, config_json

DIRNAME = "wandb"
"""Folder of the logdir that holds the W&B files (wandb.init gets the logdir as its dir and adds this name)."""
RUN_IDS = "run_ids.json"
"""File in `DIRNAME`: {seed: W&B run id}, read by --resume to continue the same W&B runs."""
STEP = "env_steps"
"""The x axis of every logged metric: env steps per seed, as in metrics.csv's env_steps column."""
EVAL_PREFIX = "eval/"
"""Prefix of the final evaluation's metrics in each W&B run's summary (eval.json's names after it)."""


class WandbLogger:
    """The W&B runs of one training run, one per seed: `log` takes what `agents.logger.Logger.log` takes,
    `log_eval` the final evaluation, `close` finishes the runs."""

    def __init__(self, config: TrainConfig):
        import wandb  # optional: only logger="wandb" needs it (agents.config.validate checks that it is installed)

        self.wandb = wandb
        self.seeds = [config.seed + i for i in range(config.seeds)]
        known = read_run_ids(config.logdir) if config.resume else {}
        self.runs = []
        try:
            for seed in self.seeds:
                self.runs.append(self._start(config, seed, known.get(str(seed))))
        except BaseException:
            self.close()
            raise
        if config.wandb_mode != "disabled":  # disabled runs have made-up ids
            save_run_ids(config.logdir, {str(seed): run.id for seed, run in zip(self.seeds, self.runs)})

    def _start(self, config: TrainConfig, seed: int, run_id: str | None):
        """The W&B run of `seed`: the one of id `run_id` continued, or a new one; every metric plotted over `STEP`."""
        try:
            run = self.wandb.init(project=config.wandb_project, mode=config.wandb_mode, dir=config.logdir, id=run_id,
                                  resume="allow" if run_id else None, reinit="create_new", group=group_name(config),
                                  name=f"{os.path.basename(group_name(config))}-seed{seed}",
                                  tags=[config.preset or config.env_name, config.algo_name],
                                  config={**config_json(config), "run_seed": seed})
        except self.wandb.errors.Error as error:
            raise ValueError(f"wandb_mode={config.wandb_mode!r}: W&B could not start a run ({error}): allowed is "
                             "wandb_mode='offline', or 'online' after `wandb login`.") from error
        run.define_metric(STEP)
        run.define_metric("*", step_metric=STEP)
        return run

    def log(self, step: int, metrics: dict, extra: dict) -> None:
        """`metrics`: {name: per-seed values}, logged under their names; `extra`: scalars shared by the seeds,
        logged as perf/<name> (TensorBoard's names)."""
        shared = {"perf/" + k: float(v) for k, v in extra.items()}
        for i, run in enumerate(self.runs):
            run.log({STEP: step, **{k: float(v[i]) for k, v in metrics.items()}, **shared})

    def log_eval(self, step: int, eval_metrics: dict) -> None:
        """The final evaluation ({name: per-seed values}, as in eval.json's per_seed) into each seed's run summary,
        as eval/<name>, with the env step it evaluated as eval/env_steps."""
        for i, run in enumerate(self.runs):
            run.summary.update({EVAL_PREFIX + STEP: step,
                                **{EVAL_PREFIX + k: float(v[i]) for k, v in eval_metrics.items()}})

    def close(self) -> None:
        """Finishes the runs (offline, W&B's service may write their last records out after this returns;
        `wandb.teardown()` waits for it); a second call does nothing."""
        runs, self.runs = self.runs, []
        for run in runs:
            run.finish()


def group_name(config: TrainConfig) -> str:
    """The W&B group of the seeds' runs: the logdir (W&B allows 128 characters: its last 128)."""
    return os.path.normpath(config.logdir)[-128:]


def run_ids_path(logdir: str) -> str:
    return os.path.join(logdir, DIRNAME, RUN_IDS)


def read_run_ids(logdir: str) -> dict[str, str]:
    """{seed: W&B run id} stored by the run in `logdir`; {} (new W&B runs, with a warning if the file is damaged)
    if there is none."""
    path = run_ids_path(logdir)
    if not os.path.exists(path):
        return {}
    try:
        with open(path) as f:
            ids = json.load(f)
    except (OSError, ValueError) as error:
        print(f"{path} cannot be read ({error}): the resumed run logs to new W&B runs.", file=sys.stderr)
        return {}
    return {str(seed): str(run_id) for seed, run_id in ids.items()} if isinstance(ids, dict) else {}


def save_run_ids(logdir: str, ids: dict[str, str]) -> None:
    os.makedirs(os.path.join(logdir, DIRNAME), exist_ok=True)
    write_atomic(run_ids_path(logdir), json.dumps(ids, indent=2))
