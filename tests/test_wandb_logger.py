"""`--logger wandb`: offline W&B runs, one per seed, that hold the metrics.csv rows, the run's config and the final
evaluation (read back from the `.wandb` files), continued under the same ids by a resume; and the validation of
the logger fields, a missing wandb package included."""

import csv
import dataclasses
import glob
import importlib.util
import json
import os
import struct

import pytest
import wandb
from wandb.proto import wandb_internal_pb2

import train as train_cli
from agents import driver, presets, wandb_logger
from agents import logdir as logdirs
from agents.config import validate

STEPS = 15_360  # 3 updates of the PPO probe preset: 2 before the stop, 1 after the resume
QUIET = dict(tensorboard=False, progress=False)


@pytest.fixture(scope="module", autouse=True)
def wandb_offline(tmp_path_factory):
    """W&B quiet, offline and without system-metric sampling, its settings and caches in a temporary folder, for
    every test of the module: nothing here may reach the network."""
    home = str(tmp_path_factory.mktemp("wandb-home"))
    env = pytest.MonkeyPatch()
    for name, value in (("WANDB_MODE", "offline"), ("WANDB_SILENT", "true"), ("WANDB_X_DISABLE_STATS", "true"),
                        ("WANDB_DISABLE_CODE", "true"), ("WANDB_DISABLE_GIT", "true"), ("WANDB_CONFIG_DIR", home),
                        ("WANDB_CACHE_DIR", home), ("WANDB_DATA_DIR", home)):
        env.setenv(name, value)
    env.delenv("WANDB_API_KEY", raising=False)
    yield
    env.undo()


# ----------------------------------------------------------------------------------------------
# Reading offline runs back. wandb has no reader of its `.wandb` files: they are a LevelDB-style log (a 7-byte
# header ":W&B", 0xBEE1, version 0, then 32 KiB blocks of chunks with a 7-byte header: CRC, length, type) of
# `wandb_internal_pb2.Record` messages.

BLOCK = 32 * 1024
CHUNK_HEADER = struct.Struct("<IHB")
FULL, LAST = 1, 4


def read_records(path: str) -> list:
    """The protobuf records of one `.wandb` file, in the order they were written."""
    with open(path, "rb") as f:
        data = f.read()
    assert data[:7] == struct.pack("<4sHB", b":W&B", 0xBEE1, 0), f"{path} is not a W&B log"
    records, pieces, pos = [], b"", 7
    while pos + CHUNK_HEADER.size <= len(data):
        if BLOCK - pos % BLOCK < CHUNK_HEADER.size:  # a block's tail too short for a header is padding
            pos += BLOCK - pos % BLOCK
            continue
        _, length, kind = CHUNK_HEADER.unpack_from(data, pos)
        if kind == 0:  # zeros past the last chunk
            break
        pieces += data[pos + CHUNK_HEADER.size:pos + CHUNK_HEADER.size + length]
        pos += CHUNK_HEADER.size + length
        if kind in (FULL, LAST):
            record = wandb_internal_pb2.Record()
            record.ParseFromString(pieces)
            records.append(record)
            pieces = b""
    return records


def _key(item) -> str:
    return item.key or ".".join(item.nested_key)


def run_files(logdir, run_id: str) -> list[str]:
    """The `.wandb` files of one W&B run id under the logdir, oldest first (one per train.py call). Their folders
    are offline-run-<start second>-<id>, with "-1", "-2", ... appended by W&B to a name already taken, so the
    files are ordered by the start times their runs record."""
    return sorted(glob.glob(os.path.join(logdir, "wandb", "offline-run-*", f"run-{run_id}.wandb")), key=start_time)


def start_time(path: str) -> int:
    """Microseconds since the epoch at which the run of a `.wandb` file started."""
    return run_record(path).start_time.ToMicroseconds()


def run_record(path: str):
    (run,) = [r.run for r in read_records(path) if r.WhichOneof("record_type") == "run"]
    return run


def history(paths) -> list[dict]:
    """The logged rows of the files, {key: value}, in order."""
    return [{_key(item): json.loads(item.value_json) for item in r.history.item}
            for path in paths for r in read_records(path) if r.WhichOneof("record_type") == "history"]


def summary(paths) -> dict:
    """The run summary the files leave: their summary updates applied in order."""
    out = {}
    for path in paths:
        for r in read_records(path):
            if r.WhichOneof("record_type") == "summary":
                out.update({_key(item): json.loads(item.value_json) for item in r.summary.update})
    return out


def run_config(path: str) -> dict:
    """The W&B config a file's run started with."""
    return {_key(item): json.loads(item.value_json) for item in run_record(path).config.update}


def csv_column(logdir, seed: int, column: str) -> dict[int, float]:
    """{env step: value} of one metrics.csv column for one seed."""
    with open(os.path.join(logdir, "metrics.csv"), newline="") as f:
        return {int(row["env_steps"]): float(row[column]) for row in csv.DictReader(f) if int(row["seed"]) == seed}


# ----------------------------------------------------------------------------------------------
# A run of two seeds, stopped after two updates and resumed for the third and the evaluation.


@pytest.fixture(scope="module")
def resumed_run(tmp_path_factory):
    """(logdir, {seed: W&B run id}) of the run, its metrics.csv and eval.json beside the W&B files."""
    logdir = str(tmp_path_factory.mktemp("wandb-run") / "run")
    base = dict(logdir=logdir, num_timesteps=STEPS, log_every=5120, seeds=2, eval_envs=8, logger="wandb", **QUIET)
    first = driver.train(presets.make_config("point-mass-ppo", stop_after_steps=10_240, **base))
    assert first.status == "stopped"
    second = driver.train(presets.make_config("point-mass-ppo", resume=True, **base))
    assert second.status == "done"
    # `finish` returns before W&B's service has always written the files out (a busy machine showed a file without
    # its run record); shutting the service down waits for it.
    wandb.teardown()
    with open(wandb_logger.run_ids_path(logdir)) as f:
        return logdir, {int(seed): run_id for seed, run_id in json.load(f).items()}


def test_each_seed_has_its_own_w_and_b_run(resumed_run):
    _, ids = resumed_run
    assert sorted(ids) == [0, 1]


def test_seeds_have_different_run_ids(resumed_run):
    _, ids = resumed_run
    assert ids[0] != ids[1]


@pytest.mark.parametrize("seed", [0, 1])
def test_the_resume_continues_the_same_w_and_b_run(resumed_run, seed):
    """Offline, each train.py call writes its own directory under the run's id (wandb sync joins them)."""
    logdir, ids = resumed_run
    assert len(run_files(logdir, ids[seed])) == 2


@pytest.mark.parametrize("seed", [0, 1])
def test_the_logged_steps_are_the_csv_steps(resumed_run, seed):
    logdir, ids = resumed_run
    rows = history(run_files(logdir, ids[seed]))
    assert [row["env_steps"] for row in rows] == [5120, 10_240, 15_360]


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("metric", ["loss/value", "policy/entropy", "perf/steps_per_second"])
def test_the_logged_values_equal_the_csv_rows(resumed_run, seed, metric):
    logdir, ids = resumed_run
    logged = {row["env_steps"]: row[metric] for row in history(run_files(logdir, ids[seed]))}
    column = metric.removeprefix("perf/")  # metrics.csv names the shared speed and time columns without it
    assert logged == csv_column(logdir, seed, column)


def test_the_seeds_logged_different_values(resumed_run):
    """The per-seed comparison above is not vacuous: the two seeds' runs differ."""
    logdir, ids = resumed_run
    assert csv_column(logdir, 0, "loss/value") != csv_column(logdir, 1, "loss/value")


@pytest.mark.parametrize("field, value", [("seed", 0), ("num_timesteps", STEPS), ("seeds", 2), ("logger", "wandb"),
                                          ("preset", "point-mass-ppo"), ("algo_name", "ppo")])
def test_the_config_is_the_runs_config(resumed_run, field, value):
    logdir, ids = resumed_run
    assert run_config(run_files(logdir, ids[1])[0])[field] == value


@pytest.mark.parametrize("seed", [0, 1])
def test_the_config_names_the_seed_of_its_run(resumed_run, seed):
    logdir, ids = resumed_run
    assert run_config(run_files(logdir, ids[seed])[0])["run_seed"] == seed


def test_the_config_holds_the_algorithm_settings(resumed_run):
    logdir, ids = resumed_run
    with open(os.path.join(logdir, "config.json")) as f:
        saved = json.load(f)
    assert run_config(run_files(logdir, ids[0])[0])["algo"] == saved["algo"]


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("metric", ["episode/target_reached", "episode/return", "episode/distance_last10"])
def test_the_summary_holds_the_final_evaluation(resumed_run, seed, metric):
    logdir, ids = resumed_run
    with open(os.path.join(logdir, "eval.json")) as f:
        evaluated = json.load(f)["per_seed"][metric][seed]
    assert summary(run_files(logdir, ids[seed]))["eval/" + metric] == evaluated


def test_the_summary_names_the_evaluated_step(resumed_run):
    logdir, ids = resumed_run
    assert summary(run_files(logdir, ids[0]))["eval/env_steps"] == STEPS


def test_a_disabled_w_and_b_writes_no_w_and_b_files_but_the_csv(resumed_run, tmp_path):
    """The resumed run's settings (its compiled programs, cached), stopped after one update."""
    logdir = tmp_path / "run"
    driver.train(presets.make_config("point-mass-ppo", logdir=str(logdir), num_timesteps=STEPS, log_every=5120,
                                     seeds=2, eval_envs=8, stop_after_steps=5120, logger="wandb",
                                     wandb_mode="disabled", **QUIET))
    assert not (logdir / "wandb").exists()
    assert len((logdir / "metrics.csv").read_text().splitlines()) == 3  # the header and a row per seed


# ----------------------------------------------------------------------------------------------
# Options and validation.


def test_the_command_line_selects_w_and_b():
    config = train_cli.parse(["point-mass-ppo", "--logger", "wandb"])
    assert config.logger == "wandb"


def test_w_and_b_is_offline_by_default():
    assert presets.make_config("point-mass-ppo").wandb_mode == "offline"


def test_the_command_line_sets_the_w_and_b_mode_and_project():
    config = train_cli.parse(["point-mass-ppo", "--logger", "wandb", "--wandb-mode", "online", "--wandb-project", "p"])
    assert (config.wandb_mode, config.wandb_project) == ("online", "p")


@pytest.mark.parametrize("overrides, message", [
    (dict(logger="tensorboard"), r"logger='tensorboard' is unknown: allowed are csv, wandb\."),
    (dict(wandb_mode="cloud"), r"wandb_mode='cloud' is unknown: allowed are offline, online, disabled\."),
    (dict(wandb_project="team/project"), r"wandb_project='team/project' is invalid: allowed is a name of 1 to 128 "),
    (dict(wandb_project=""), r"wandb_project='' is invalid: allowed is a name of 1 to 128 characters"),
    (dict(wandb_project="x" * 129), r"wandb_project='x{129}' is invalid"),
])
def test_a_bad_logger_field_is_refused(overrides, message):
    with pytest.raises(ValueError, match=message):
        validate(dataclasses.replace(presets.make_config("point-mass-ppo"), **overrides))


def test_a_project_name_of_128_characters_is_allowed():
    validate(presets.make_config("point-mass-ppo", wandb_project="x" * 128))  # no error


@pytest.fixture
def without_wandb(monkeypatch):
    """wandb not installed, as far as the config's check can tell."""
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a, **k: None if name == "wandb" else find_spec(name, *a, **k))


def test_w_and_b_without_wandb_installed_names_the_extra(without_wandb):
    with pytest.raises(ValueError, match=r"logger='wandb' needs the wandb package, which is not installed: .*"
                                         r'`pip install -e "\.\[wandb\]"`'):
        validate(presets.make_config("point-mass-ppo", logger="wandb"))


def test_the_csv_logger_does_not_need_wandb(without_wandb):
    validate(presets.make_config("point-mass-ppo"))  # no error


def test_train_py_refuses_w_and_b_without_wandb_before_it_compiles(without_wandb, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(driver, "programs_for", lambda *a, **k: pytest.fail("compiled despite the missing package"))
    code = train_cli.cli(["point-mass-ppo", "--logger", "wandb", "--logdir", str(tmp_path / "run")])
    assert code == 2


def test_train_py_says_which_extra_installs_wandb(without_wandb, tmp_path, capsys):
    train_cli.cli(["point-mass-ppo", "--logger", "wandb", "--logdir", str(tmp_path / "run")])
    assert 'pip install -e ".[wandb]"' in capsys.readouterr().err


def test_train_py_refuses_w_and_b_without_wandb_before_it_writes(without_wandb, tmp_path):
    train_cli.cli(["point-mass-ppo", "--logger", "wandb", "--logdir", str(tmp_path / "run")])
    assert not (tmp_path / "run").exists()


def test_overwrite_sets_the_replaced_runs_wandb_folder_aside(tmp_path):
    """--overwrite treats wandb/ as one of the run's files: it moves aside with the rest (and is deleted once the new
    run saves its first checkpoint), so `wandb sync <logdir>/wandb/offline-run-*` uploads the new run only."""
    (tmp_path / "wandb" / "offline-run-old").mkdir(parents=True)
    (tmp_path / "config.json").write_text("{}")
    prepared = logdirs.prepare(str(tmp_path), resume=False, overwrite=True)
    assert not (tmp_path / "wandb").exists()
    assert os.path.isdir(os.path.join(prepared.aside, "wandb", "offline-run-old"))
