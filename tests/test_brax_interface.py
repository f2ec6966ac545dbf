"""Our environment plugs into Brax's own training pipeline unchanged (Brax is a reference only:
this test is the one place that imports it)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs

brax_ppo = pytest.importorskip("brax.training.agents.ppo.train", reason="brax is in the dev extra")


def _device_put_replicated(x, devices):
    # brax 0.14.2 still calls this; jax >= 0.10 removed it (one-line shim, as in Brax's own fix).
    return jax.tree.map(lambda a: jnp.stack([jnp.asarray(a)] * len(devices)), x)


def test_brax_ppo_trains_on_our_env(monkeypatch):
    if not hasattr(jax, "device_put_replicated"):
        monkeypatch.setattr(jax, "device_put_replicated", _device_put_replicated, raising=False)
    env = envs.make("point-mass")  # the arms share its env interface; compiling Brax's PPO on an arm takes minutes
    progress = []
    make_policy, params, metrics = brax_ppo.train(
        environment=env, num_timesteps=160, episode_length=10, num_envs=4, batch_size=4,
        num_minibatches=1, unroll_length=5, num_updates_per_batch=1, num_evals=2, num_eval_envs=4,
        normalize_observations=True, seed=0, progress_fn=lambda step, m: progress.append((step, m)),
    )
    policy = make_policy(params, deterministic=True)
    state = env.reset(jax.random.PRNGKey(1))
    action, _ = policy(state.obs, jax.random.PRNGKey(2))
    assert action.shape == (env.action_size,)
    assert np.all(np.abs(action) <= 1.0)
    assert progress
    assert progress[-1][0] >= 160
    # Brax's evaluator reports our env's metrics, so `step` kept every key of `reset`.
    assert "eval/episode_target_reached" in metrics
    assert np.isfinite(metrics["eval/episode_reward"])


def test_brax_sac_comparison_takes_brax_settings_or_refuses():
    from agents import presets
    from benchmarks.brax_reference import brax_comparable

    paper = presets.make_config("ur5e-reach-sac")
    same = brax_comparable(paper, "sac", action_size=6)
    assert same.algo.target_entropy == -3.0
    assert paper.algo.target_entropy is None  # Brax's -|A|/2
    assert same.algo.obs_clip == 0.0
    assert paper.algo.obs_clip == 10.0  # Brax's SAC does not clip
    assert dataclasses.replace(same.algo, target_entropy=None, obs_clip=10.0) == paper.algo
    with pytest.raises(ValueError, match=r"algo.n_step=3.*algo.distributional=True.*q_hidden_sizes=\(512, 512, 256\)"):
        brax_comparable(presets.make_config("ur5e-reach-sac-fast"), "sac", action_size=6)
    ppo = presets.make_config("ur5e-reach-ppo")
    assert brax_comparable(ppo, "ppo", action_size=6) is ppo


def test_brax_reference_trace_needs_a_second_brax_epoch(tmp_path):
    """Brax's first training epoch compiles, so --trace traces its second: one evaluation period is refused
    before anything is built."""
    from benchmarks import brax_reference

    with pytest.raises(ValueError, match=r"--evals=1 with --trace: allowed is 2 or more"):
        brax_reference.main(["--preset", "point-mass-sac", "--evals", "1", "--trace", str(tmp_path)])
    assert not any(tmp_path.iterdir())


def test_brax_sac_epochs_leave_out_the_prefill_and_the_trace_holds_one_epoch_alone():
    """Brax's SAC spends ceil(min_replay_size / num_envs) vector steps of its budget on the prefill, then splits
    the rest over num_evals - 1 epochs: the paper setting's 4 x 256 vector steps of 128 envs leave 56 a traced
    epoch, 4 x 456 leave 256. The trace starts at Brax's second progress
    call and ends when the next evaluation starts, whichever evaluator that is."""
    from benchmarks.brax_reference import EpochTrace, before_brax_evaluations, brax_sac_epochs

    assert brax_sac_epochs(4 * 256 * 128, 128, 102_400, 5) == (800, 56)
    assert brax_sac_epochs(4 * 456 * 128, 128, 102_400, 5) == (800, 256)
    assert brax_sac_epochs(1_100, 16, 1_000, 2) == (63, 6)  # ceil(1000/16) = 63; ceil((1100 - 1008) / 16) = 6
    events = []
    trace = EpochTrace("dir", start_trace=lambda d: events.append(("start", d)),
                       stop_trace=lambda: events.append("stop"))
    from brax.training import acting

    calls = []
    original = acting.Evaluator.run_evaluation

    def stand_in(self, *a):
        calls.append(a)

    try:
        acting.Evaluator.run_evaluation = stand_in
        with before_brax_evaluations(trace.stop):
            trace.progress(1)                                   # step 0
            acting.Evaluator.run_evaluation(None, "params", 1)  # after epoch 1 (it compiled)
            trace.progress(2)
            assert events == [("start", "dir")]
            assert trace.on
            acting.Evaluator.run_evaluation(None, "params", 2)  # after epoch 2: the trace ends here
            assert events == [("start", "dir"), "stop"]
            assert not trace.on
            trace.progress(3)
            trace.stop()                                        # ours, later: nothing more to stop
        assert events == [("start", "dir"), "stop"]
        assert calls == [("params", 1), ("params", 2)]
        assert acting.Evaluator.run_evaluation is stand_in  # what was there before the context is back
    finally:
        acting.Evaluator.run_evaluation = original


def test_brax_reference_refuses_a_sac_run_too_short_to_leave_the_replay_warmup(tmp_path, monkeypatch):
    """Brax's SAC raises deep inside its train() when its steps do not pass min_replay_size: point-mass-sac
    (16 env steps a vector step, min_replay_size 1,024) with 2 x 32 updates is 1,024 env steps, refused before
    anything is built or written."""
    from agents import presets
    from benchmarks import brax_reference

    with pytest.raises(ValueError, match=r"--evals=2 x --updates-per-eval=32 x 16 env steps = 1,024 env steps is "
                                         r"invalid for SAC: allowed is more than algo.min_replay_size=1,024"):
        brax_reference.main(["--preset", "point-mass-sac", "--evals", "2", "--updates-per-eval", "32",
                             "--out", str(tmp_path / "sub" / "out")])
    # A min_replay_size between vector steps: Brax prefills whole vector steps, ceil(1,000 / 16) x 16 = 1,008 env
    # steps, so 63 vector steps leave it nothing to train although they pass min_replay_size.
    make_config = presets.make_config
    monkeypatch.setattr(presets, "make_config", lambda name, **kw: dataclasses.replace(
        make_config(name, **kw), algo=dataclasses.replace(make_config(name, **kw).algo, min_replay_size=1000)))
    with pytest.raises(ValueError, match=r"= 1,008 env steps is invalid for SAC: allowed is more than "
                                         r"algo.min_replay_size=1,000 in whole vector steps \(1,008;"):
        brax_reference.main(["--preset", "point-mass-sac", "--evals", "1", "--updates-per-eval", "63",
                             "--out", str(tmp_path / "sub" / "out")])
    monkeypatch.undo()
    for flag in ("--evals", "--updates-per-eval", "--eval-envs"):
        with pytest.raises(ValueError, match=f"{flag}=0 is invalid: allowed is an integer >= 1"):
            brax_reference.main(["--preset", "point-mass-sac", flag, "0", "--out", str(tmp_path / "sub" / "out")])
    assert not any(tmp_path.iterdir())
