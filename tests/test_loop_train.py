"""train.py end to end: checkpoints that load back, exact resume, time limits, NaN stop, and the two-device
data-parallel path. Presets, overrides and refused input: tests/test_train_config.py."""

import csv
import dataclasses
import json
import os
import subprocess
import sys
import textwrap
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from agents import driver, loop, presets
from agents.config import config_from_json, config_json, num_devices, total_updates, validate
from agents.checkpoint import Checkpointer
from agents.ppo import PPO, PPOConfig
from limits import HANG_GUARD_S

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHORT = 30_720  # 6 updates of the PPO probe preset (2 seeds: the program of tests/test_agents_learning.py's 2-seed run)
QUIET = dict(tensorboard=False, progress=False)
PROBE = dict(num_timesteps=SHORT, seeds=2, eval_envs=0, log_every=5120, **QUIET)
"""The in-process PPO runs of this module: one compiled program (a stop or a time limit changes no program)."""
SAC_PROBE = dict(num_timesteps=3_200, eval_envs=0, log_every=1_600, **QUIET)
"""The in-process SAC runs of this module, likewise (the program of tests/test_agents_learning.py's SAC run: SAC's
program does not depend on the run's length)."""


def _subprocess_env(**extra):
    """The environment of a train.py subprocess: this checkout importable, and the tests' compilation cache (the
    runs of this module share programs across processes)."""
    path = os.pathsep.join(p for p in (ROOT, os.environ.get("PYTHONPATH", "")) if p)
    return dict(os.environ, PYTHONPATH=path, JAX_COMPILATION_CACHE_DIR=jax.config.jax_compilation_cache_dir, **extra)


def test_train_cli_writes_checkpoints_logs_and_eval_that_load_back(tmp_path):
    logdir = tmp_path / "run"
    cmd = [sys.executable, "train.py", "point-mass-ppo", "--num-timesteps", "10240", "--checkpoint-every", "5120",
           "--eval-envs", "32", "--logdir", str(logdir), "--no-progress", "--env.goal-radius", "0.15"]
    proc = subprocess.run(cmd, cwd=ROOT, env=_subprocess_env(), capture_output=True, text=True, timeout=HANG_GUARD_S)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "done after 10,240 env steps" in proc.stdout
    # The closing summary names the paper's metrics and says what to run next.
    assert "\n  target reached: " in proc.stdout
    assert "episode return: " in proc.stdout
    assert f"next: python eval.py --checkpoint {logdir}" in proc.stdout

    saved = json.loads((logdir / "config.json").read_text())
    config = config_from_json(saved)
    assert config == presets.make_config("point-mass-ppo", num_timesteps=10240, checkpoint_every=5120, eval_envs=32,
                                           logdir=str(logdir), progress=False,
                                           env=config.env.__class__(goal_radius=0.15))
    ckpt = Checkpointer(str(logdir / "checkpoints"))
    assert ckpt.manager.all_steps() == [5120, 10240]
    programs = driver.programs_for(config)
    state, stored_config = ckpt.restore(10240, programs.abstract_state)
    assert stored_config == saved
    assert int(state.updates[0]) == 2
    assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(state.learner.params))
    assert float(state.learner.obs_stats.count[0]) == 2 * 5120  # normaliser statistics were saved
    ev = json.loads((logdir / "checkpoints" / "10240" / "eval.json").read_text())
    assert ev["eval_envs"] == 32
    assert 0 <= ev["mean"]["episode/target_reached"] <= 1

    rows = (logdir / "metrics.csv").read_text().splitlines()
    header = rows[0].split(",")
    for column in ("env_steps", "steps_per_second", "episode/return", "episode/target_reached", "episode/distance",
                   "loss/policy", "loss/value", "policy/entropy", "policy/approx_kl", "policy/clip_fraction"):
        assert column in header
    assert len(rows) == 1 + 2
    assert any(name.startswith("events.out.tfevents") for name in os.listdir(logdir / "tb" / "seed_0"))


TWO_CPU_DEVICES = "--xla_force_host_platform_device_count=2"
"""XLA_FLAGS of a subprocess with two CPU devices."""


@pytest.fixture(scope="module")
def arm_run(tmp_path_factory):
    """`train.py ur5e-reach-ppo-cpu` for one update (native physics, 2 substeps) on two CPU devices, split the default
    way (multi_device="gspmd"): its logdir. test_two_devices_match_one_device trains the same run split by
    shard_map."""
    logdir = tmp_path_factory.mktemp("arm") / "arm"
    cmd = [sys.executable, "train.py", "ur5e-reach-ppo-cpu", "--num-timesteps", "1280", "--eval-envs", "4",
           "--logdir", str(logdir), "--no-progress", "--env.substeps", "2", "--env.sampling-candidates", "4",
           "--devices", "2"]
    proc = subprocess.run(cmd, cwd=ROOT, env=_subprocess_env(XLA_FLAGS=TWO_CPU_DEVICES), capture_output=True,
                          text=True, timeout=HANG_GUARD_S)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return logdir


def _restored_arm_run(logdir):
    """(config, the full state of its checkpoint at 1280 env steps restored onto this process's one device)."""
    config = config_from_json(json.loads((logdir / "config.json").read_text()))
    ckpt = Checkpointer(str(logdir / "checkpoints"))
    state, _ = ckpt.restore(1280, driver.programs_for(dataclasses.replace(config, devices=1)).abstract_state)
    return config, state


def test_train_cli_on_the_arm_writes_a_checkpoint_that_loads_back(arm_run):
    """The main job on the real env (here on two devices): its state (with MJX's zero-size fields) checkpoints
    and restores, onto one device."""
    logdir = arm_run
    config, state = _restored_arm_run(logdir)
    assert config.env_name == "ur5e-reach"
    assert config.env.substeps == 2
    assert config.devices == 2
    assert int(state.updates[0]) == 1
    assert state.env_state.pipeline_state.act.shape[-1] == 0  # zero-size MJX fields come back
    np.testing.assert_array_less(np.abs(np.asarray(state.env_state.pipeline_state.qpos)), 2 * np.pi + 1e-3)
    ev = json.loads((logdir / "eval.json").read_text())
    assert set(ev["mean"]) >= {"episode/target_reached", "episode/self_collision", "episode/distance_last10"}
    header = (logdir / "metrics.csv").read_text().splitlines()[0].split(",")
    assert "episode/reward/dense" in header  # the reward's one term, logged per episode


def _full_state(result):
    return jax.tree.leaves(jax.device_get(result.state))


def test_resume_reproduces_an_unbroken_run_bit_for_bit(tmp_path):
    base = PROBE
    unbroken = driver.train(presets.make_config("point-mass-ppo", logdir=str(tmp_path / "a"), **base))
    first = driver.train(presets.make_config("point-mass-ppo", logdir=str(tmp_path / "b"), stop_after_steps=15_360, **base))
    assert first.status == "stopped"
    assert first.env_steps == 15_360
    resumed = driver.train(presets.make_config("point-mass-ppo", logdir=str(tmp_path / "b"), resume=True, **base))
    assert resumed.status == "done"
    assert resumed.env_steps == SHORT
    for a, b in zip(_full_state(unbroken), _full_state(resumed)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # A time limit shorter than one chunk: the first chunk (one log interval) runs, then the run stops in time.
    timed = driver.train(presets.make_config("point-mass-ppo", logdir=str(tmp_path / "c"), stop_after_seconds=1e-3, **base))
    assert timed.status == "stopped"
    assert timed.env_steps == 5120
    resumed = driver.train(presets.make_config("point-mass-ppo", logdir=str(tmp_path / "c"), resume=True, **base))
    for a, b in zip(_full_state(unbroken), _full_state(resumed)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # The run did change the parameters (the comparison is not vacuous).
    init = driver.programs_for(unbroken.config).init(driver.seed_keys(unbroken.config))
    assert not np.allclose(np.asarray(jax.tree.leaves(init.learner.params)[0]),
                           np.asarray(jax.tree.leaves(unbroken.state.learner.params)[0]))
    # A differing algorithm setting is refused on resume.
    with pytest.raises(ValueError, match="algo.learning_rate"):
        changed = presets.make_config("point-mass-ppo", logdir=str(tmp_path / "b"), resume=True, **base)
        driver.train(dataclasses.replace(changed, algo=dataclasses.replace(changed.algo, learning_rate=1.0)))


def test_time_limit_counts_from_the_start_at_the_last_chunk_speed(monkeypatch):
    config = presets.make_config("point-mass-ppo", stop_after_seconds=100.0)
    monkeypatch.setattr(driver.time, "perf_counter", lambda: 1000.0 + 60.0)  # 60 s after the start
    assert not driver.out_of_time(config, 1000.0, None, 50)  # the first chunk: speed unknown, it runs
    assert not driver.out_of_time(config, 1000.0, 0.8, 50)  # 60 + 40 s: ends at the limit
    assert driver.out_of_time(config, 1000.0, 0.81, 50)  # 60 + 40.5 s: past it
    assert not driver.out_of_time(dataclasses.replace(config, stop_after_seconds=0.0), 1000.0, 10.0, 50)  # no limit
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="stop_after_seconds"):
            validate(dataclasses.replace(config, stop_after_seconds=bad))


class _TimedPrograms:
    """A run's programs on a simulated clock: the first chunk call compiles (50 s) unless compiled ahead, every
    chunk then takes 1 s."""

    def __init__(self, inner, clock):
        self._inner, self._clock = inner, clock

    def __getattr__(self, name):
        return getattr(self._inner, name)

    def chunk(self, state, n):
        _simulated_compile(self._clock)
        self._clock["now"] += 1.0
        return self._inner.chunk(state, n)


def _simulated_compile(clock):
    if not clock["compiled"]:
        clock["now"] += 50.0
        clock["compiled"] = True


def test_a_time_limit_judges_the_next_chunk_by_its_speed_not_the_compilation(tmp_path, monkeypatch):
    """A 50 s compilation and 1 s chunks under a 54.5 s limit: compiled ahead, the run trains 4 of its 6 chunks (the
    5th would end at 55 s); judged by a first chunk that included the compilation (51 s) it would stop after one.
    The logged time of the first chunk keeps the compilation."""
    clock = {"now": 0.0, "compiled": False}
    real_programs_for = driver.programs_for

    def compile_ahead(programs, state):
        start = clock["now"]
        _simulated_compile(clock)
        return clock["now"] - start

    monkeypatch.setattr(driver, "time", types.SimpleNamespace(perf_counter=lambda: clock["now"]))
    monkeypatch.setattr(driver, "compile_ahead", compile_ahead)
    monkeypatch.setattr(driver, "programs_for",
                        lambda config, learner_cls=None: _TimedPrograms(real_programs_for(config, learner_cls), clock))
    config = presets.make_config("point-mass-ppo", logdir=str(tmp_path / "t"), stop_after_seconds=54.5, **PROBE)
    result = driver.train(config)
    assert result.status == "stopped"
    assert result.env_steps == 4 * 5120
    with open(tmp_path / "t" / "metrics.csv") as f:
        seconds = [float(row["wall_seconds"]) for row in csv.DictReader(f) if row["seed"] == "0"]
    assert seconds == [51.0] + [1.0] * 3


@pytest.mark.parametrize("restarts", ["fresh", "first"])
def test_episode_restarts_reach_the_training_envs_auto_reset(restarts):
    config = presets.make_config("point-mass-ppo", episode_restarts=restarts, **PROBE)
    assert driver.programs_for(config).env.env.restarts == restarts  # VmapWrapper(AutoResetWrapper(...))


def test_compile_ahead_leaves_the_jit_call_nothing_to_compile(caplog):
    """The executable compiled ahead is the one the jit call runs. Fresh programs, not the in-memory ones of the
    tests above (which ran already): they compile, or load what the tests above put in the persistent compilation
    cache, and jax logs either as a compilation."""
    config = presets.make_config("point-mass-ppo", **PROBE)
    programs = driver.build_programs.__wrapped__(config.env_name, config.env, config.algo, config.seeds,
                                                 num_devices(config), total_updates(config), config.eval_envs,
                                                 config.eval_last_steps, PPO, config.multi_device)
    assert programs is not driver.programs_for(config)
    state = programs.init(driver.seed_keys(config))
    with jax.log_compiles(True), caplog.at_level("WARNING"):
        assert driver.compile_ahead(programs, state) > 0.0
        compiled_ahead = [r.getMessage() for r in caplog.records if "XLA compilation of jit(chunk)" in r.getMessage()]
        caplog.clear()
        jax.block_until_ready(programs.chunk(state, jnp.int32(1)))
        at_call = [r.getMessage() for r in caplog.records if "XLA compilation of jit(chunk)" in r.getMessage()]
    # jax logs "Finished XLA compilation of jit(chunk)" where it compiles (or loads from the persistent cache).
    assert compiled_ahead
    assert not at_call, at_call


def _stored_leaf_names(step_dir: str) -> list[str]:
    """Names of the arrays an orbax checkpoint holds (its tree metadata; the files are OCDBT shards)."""
    with open(os.path.join(step_dir, "state", "_METADATA")) as f:
        return list(json.load(f)["tree_metadata"])


def test_tracing_a_chunk_steps_the_env_once():
    """The chunk learns its update's metric shapes from a batch made without stepping the env: tracing it runs the
    env's step function once (inside the rollout's scan), not twice."""
    env = envs.wrap(envs.make("point-mass"))
    learner = PPO(PPOConfig(num_envs=4, batch_size=4, num_minibatches=1, unroll_length=5), env.observation_size,
                  env.action_size, total_updates=1)
    state = loop.init_train_state(jax.random.PRNGKey(0), env, learner, 4)
    step, calls = env.step, []
    env.step = lambda *args: calls.append(1) or step(*args)
    chunk = loop.make_chunk(env, learner, loop.Parallel(4))
    jax.jit(chunk).lower(state, 1)
    assert len(calls) == 1


def test_checkpoint_without_envs_resumes_the_learner_with_fresh_episodes(tmp_path):
    base = dict(PROBE, checkpoint_envs=False)
    logdir = str(tmp_path / "small")
    first = driver.train(presets.make_config("point-mass-ppo", logdir=logdir, stop_after_steps=15_360, **base))
    assert first.status == "stopped"
    ckpt = Checkpointer(os.path.join(logdir, "checkpoints"))
    stored = _stored_leaf_names(ckpt.step_dir(15_360))
    programs = driver.programs_for(first.config)
    n_env_leaves = len(jax.tree.leaves(programs.abstract_state.env_state))
    n_learner_leaves = len(jax.tree.leaves(programs.abstract_state.learner))
    assert any("learner" in name for name in stored)
    assert n_env_leaves > 0
    assert not any("env_state" in name for name in stored)  # no env state on disk
    saved = driver.restore_state(ckpt, 15_360, programs, first.config, with_envs=False)
    assert len(jax.tree.leaves(saved.learner)) == n_learner_leaves
    for a, b in zip(jax.tree.leaves(jax.device_get(first.state.learner)), jax.tree.leaves(jax.device_get(saved.learner))):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))  # the learner comes back exactly
    np.testing.assert_array_equal(np.asarray(saved.key), np.asarray(first.state.key))
    np.testing.assert_array_equal(np.asarray(saved.episode_length), 0)  # ...with fresh episodes
    assert not np.allclose(np.asarray(saved.env_state.obs), np.asarray(first.state.env_state.obs))
    resumed = driver.train(presets.make_config("point-mass-ppo", logdir=logdir, resume=True, **base))
    assert resumed.status == "done"
    assert resumed.env_steps == SHORT


def test_learner_only_checkpoint_of_sac_leaves_out_the_replay_buffer_and_refills_it(tmp_path):
    base = dict(SAC_PROBE, checkpoint_envs=False)
    logdir = str(tmp_path / "sac")
    first = driver.train(presets.make_config("point-mass-sac", logdir=logdir, stop_after_steps=1_600, **base))
    assert first.status == "stopped"
    assert int(first.state.learner.replay.rows[0]) == 100  # 1,600 steps of 16 envs were in the buffer
    ckpt = Checkpointer(os.path.join(logdir, "checkpoints"))
    stored = _stored_leaf_names(ckpt.step_dir(1_600))
    assert any("q_params" in name for name in stored)
    assert not any("replay" in name or "env_state" in name for name in stored)
    programs = driver.programs_for(first.config)
    saved = driver.restore_state(ckpt, 1_600, programs, first.config, with_envs=False)
    np.testing.assert_array_equal(np.asarray(saved.learner.replay.rows), 0)  # an empty buffer again
    assert saved.learner.replay.data["obs"].shape == first.state.learner.replay.data["obs"].shape
    for name in ("policy_params", "q_params", "target_q_params", "log_alpha", "q_opt", "obs_stats"):
        for a, b in zip(jax.tree.leaves(jax.device_get(getattr(first.state.learner, name))),
                        jax.tree.leaves(jax.device_get(getattr(saved.learner, name)))):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))  # everything else comes back exactly
    resumed = driver.train(presets.make_config("point-mass-sac", logdir=logdir, resume=True, **base))
    assert resumed.status == "done"
    assert resumed.env_steps == 3_200
    assert int(resumed.state.learner.replay.rows[0]) == 100  # refilled after the resume only
    assert np.any(np.asarray(resumed.state.learner.replay.data["obs"][0, :100]) != 0)


class _PoisonedPPO(PPO):
    """PPO whose parameters and losses become NaN from its 4th update on."""

    def update(self, state, batch, key, par):
        state, metrics = super().update(state, batch, key, par)
        bad = state.updates >= 4
        poison = lambda x: jnp.where(bad, jnp.nan, x)
        state = state.replace(params=jax.tree.map(poison, state.params))
        metrics = {**metrics, "loss/total": poison(metrics["loss/total"])}
        return state, metrics


def test_nan_loss_stops_the_run_and_keeps_the_last_good_checkpoint(tmp_path):
    # The probe's 6 updates (its initial state is the same program for any learner class: compiled once).
    config = presets.make_config("point-mass-ppo", checkpoint_every=2 * 5120, logdir=str(tmp_path / "nan"), **PROBE)
    with pytest.raises(driver.NonFiniteLossError, match=r"loss/total .*env step 20480.*last good checkpoint \(env step 10240\)"):
        driver.train(config, learner_cls=_PoisonedPPO)  # the user's learner class (notebooks/02)
    ckpt = Checkpointer(str(tmp_path / "nan" / "checkpoints"))
    assert ckpt.latest_step() == 10240
    state, _ = ckpt.restore(10240, driver.programs_for(config).abstract_state)
    assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(state.learner.params))


TWO_DEVICES = textwrap.dedent("""
    import json, sys
    import jax, numpy as np
    from agents import driver
    from agents.config import config_from_json
    assert jax.local_device_count() == 2
    for path in sys.argv[1:]:  # one run per config.json; its learner state and what the test checks beside it
        with open(path) as f:
            r = driver.train(config_from_json(json.load(f)))
        metrics = {f"metric {k}": v for k, v in r.last_metrics.items()
                   if k.startswith("loss/") or k == "episode/return"}
        leaves = {f"leaf {i}": np.asarray(x) for i, x in enumerate(jax.tree.leaves(jax.device_get(r.state.learner)))}
        np.savez(path + ".npz", env_shards=len(r.state.env_state.obs.sharding.device_set), **metrics, **leaves)
""")
"""Trains each config.json given on the command line in a process with two CPU devices (XLA_FLAGS)."""

TWO_DEVICE_MODES = ("shard_map", "gspmd")


def _two_device_runs(tmp_path, runs: dict) -> dict:
    """{(name, mode): the run's npz} of each (config, modes) in `runs` trained on two devices each of those ways,
    in one subprocess (the programs of the one-device runs stay in this process)."""
    paths = {}
    for name, (config, modes) in runs.items():
        for mode in modes:
            path = tmp_path / f"{name}-{mode}.json"
            two = dataclasses.replace(config, devices=2, multi_device=mode, logdir=str(tmp_path / f"{name}-{mode}"))
            path.write_text(json.dumps(config_json(two)))
            paths[name, mode] = path
    env = _subprocess_env(XLA_FLAGS=TWO_CPU_DEVICES)
    proc = subprocess.run([sys.executable, "-c", TWO_DEVICES, *map(str, paths.values())], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=HANG_GUARD_S)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {key: dict(np.load(str(path) + ".npz")) for key, path in paths.items()}


def _leaves(npz: dict) -> list:
    return [npz[f"leaf {i}"] for i in range(sum(k.startswith("leaf ") for k in npz))]


def test_two_devices_match_one_device(tmp_path, arm_run):
    """Two updates of PPO (2 seeds), 36 vector steps of SAC updates and 24 of fast SAC's with a failure budget (1
    seed each; GSPMD only) on the point mass, on two devices split by shard_map and by GSPMD, end where the same run
    on one device ends (the one-device runs are this module's probe programs, compiled once here); the UR5e arm
    (native physics: every device's envs call C MuJoCo) trains one PPO update on two devices split by shard_map to
    the state that `arm_run` (GSPMD) checkpointed."""
    ppo = presets.make_config("point-mass-ppo", logdir=str(tmp_path / "ppo"), stop_after_steps=2 * 5120, **PROBE)
    sac = presets.make_config("point-mass-sac", logdir=str(tmp_path / "sac"), stop_after_steps=1_600, **SAC_PROBE)
    # Fast SAC: n-step windows and the categorical projection, 9 updates after its 15 steps of warm-up, with a
    # failure budget (the cost critics' gradients averaged and the failures counted over both devices); GSPMD only
    # (the default, whose partitioner the batched sample is written for; each device's share of a sample as
    # shard_map sees it: tests/test_sac_fast.py). A small multiplier step: with a multiplier near 0.2 the actor's
    # gradient follows the larger of the twin cost critics, a choice that reduction-order differences flip for
    # near ties, and the runs drift apart by up to 2 % of a leaf's scale within these 9 updates.
    fast = presets.make_config("point-mass-sac-fast", logdir=str(tmp_path / "fast"), stop_after_steps=24 * 64,
                               num_timesteps=48 * 64, eval_envs=0, log_every=24 * 64, **QUIET)
    fast = dataclasses.replace(fast, algo=dataclasses.replace(fast.algo, failure_budget=0.05, multiplier_lr=1e-6))
    arm_config, arm_state = _restored_arm_run(arm_run)
    arm = dataclasses.replace(arm_config, eval_envs=0)  # the evaluation after training changes no state
    two = _two_device_runs(tmp_path, {"ppo": (ppo, TWO_DEVICE_MODES), "sac": (sac, TWO_DEVICE_MODES),
                                      "fast": (fast, ("gspmd",)), "arm": (arm, ("shard_map",))})
    for name, config, modes in (("ppo", ppo, TWO_DEVICE_MODES), ("sac", sac, TWO_DEVICE_MODES),
                                ("fast", fast, ("gspmd",))):
        one = driver.train(config)
        assert one.status == "stopped"
        reference = [np.asarray(x) for x in jax.tree.leaves(jax.device_get(one.state.learner))]
        programs = driver.programs_for(config)
        policy = lambda state: jax.tree.leaves(jax.device_get(programs.learner.export_policy(state.learner)[0]))
        moved = zip(policy(programs.init(driver.seed_keys(config))), policy(one.state))
        assert not all(np.allclose(a, b) for a, b in moved)  # the policy trained: the comparison is not vacuous
        if name == "fast":  # the multiplier moved (failures were counted): its comparison is not vacuous either
            assert np.asarray(one.state.learner.multiplier).max() > 0
        for mode in modes:
            run = two[name, mode]
            assert run["env_shards"] == 2, (name, mode)  # the environments really were split over both devices
            leaves = _leaves(run)
            assert len(leaves) == len(reference)
            max_diff = max(float(np.max(np.abs(x - y)) / (np.max(np.abs(x)) + 1e-3)) if x.size else 0.0
                           for x, y in zip(reference, leaves))
            assert max_diff < 1e-4, (name, mode, max_diff)  # relative to each leaf's scale
            np.testing.assert_allclose(run["metric episode/return"], one.last_metrics["episode/return"], rtol=1e-4)
    arm_two = two["arm", "shard_map"]
    assert arm_two["env_shards"] == 2
    losses = [k for k in arm_two if k.startswith("metric loss/")]
    assert losses
    assert all(np.isfinite(arm_two[k]).all() for k in losses)
    gspmd = [np.asarray(x) for x in jax.tree.leaves(jax.device_get(arm_state.learner))]
    assert len(gspmd) == len(_leaves(arm_two))
    for a, b in zip(gspmd, _leaves(arm_two)):
        np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-5)  # the same update
