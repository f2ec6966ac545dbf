"""Proximal Policy Optimization (Schulman et al. 2017) for the shared loop in `agents.loop`.

Batch vocabulary follows Brax's PPO, so the paper's numbers (section "Training and evaluation")
carry over unchanged:

- `num_envs` environments step in parallel;
- one update consumes `batch_size * num_minibatches` unrolls of `unroll_length` steps, i.e.
  `batch_size * num_minibatches * unroll_length` env steps (paper: 512 * 64 * 10 = 327,680);
  each env contributes `batch_size * num_minibatches / num_envs` consecutive unrolls, so
  `num_envs` must divide `batch_size * num_minibatches`;
- the data is split into `num_minibatches` minibatches of `batch_size` unrolls and swept
  `updates_per_batch` times (epochs), one gradient step per minibatch.

As in Brax, advantages are computed within each unroll (GAE truncated at `unroll_length` steps,
bootstrapped with the value of the unroll's last next-observation).

Differences from Brax's PPO, as switches in `PPOConfig` (Brax's PPO with the paper's settings
collapsed after ~16M steps on the arm task): a learning-rate schedule, global gradient-norm
clipping, clipped observation normalisation, value-target normalisation with PopArt-style output
preservation, an optional KL guard, advantages recomputed with the current value function each
epoch, and truncated episodes bootstrapped from the terminal observation (Brax's auto-reset loses it).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

import jax
import jax.numpy as jnp
import optax
from flax import struct

from agents import networks, normalizer
from envs import validation
from agents.distributions import TanhNormal
from agents.loop import Parallel, Transition, env_random, per_env_keys

LR_SCHEDULES = ("constant", "linear", "cosine")


@dataclasses.dataclass(frozen=True)
class PPOConfig(networks.NetworkConfig):
    """PPO hyperparameters. Defaults: the paper's reach setting (relative control)."""

    num_envs: int = 8192
    """Parallel environments over all devices (not stated in the paper; its throughput figures use 8192)."""
    batch_size: int = 512
    """Unrolls per minibatch (Brax's meaning)."""
    num_minibatches: int = 64
    """Minibatches per update; an update collects batch_size * num_minibatches unrolls."""
    unroll_length: int = 10
    """Steps per unroll; GAE looks at most this far ahead."""
    updates_per_batch: int = 5
    """Epochs over each batch (paper: 5 for relative, 7 for absolute control)."""
    learning_rate: float = 8e-4
    """Adam step size at the start of training."""
    lr_schedule: Literal["constant", "linear", "cosine"] = "linear"
    """Learning-rate decay over num_timesteps (Brax: constant)."""
    lr_end_fraction: float = 0.1
    """Final learning rate as a fraction of learning_rate (linear and cosine schedules)."""
    discount: float = 0.97
    """Discount factor gamma."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    clip_epsilon: float = 0.3
    """Clipping range of the probability ratio (Brax's default)."""
    entropy_coef: float = 1e-4
    """Weight of the entropy bonus (Brax's default)."""
    value_loss_coef: float = 0.25
    """Weight of the mean squared value error (Brax uses 0.5 * 0.5)."""
    reward_scaling: float = 1.0
    """Rewards are multiplied by this before GAE."""
    normalize_observations: bool = True
    """Normalise observations with running statistics shared over envs and devices."""
    obs_clip: float = 10.0
    """Normalised observations are clipped to [-obs_clip, obs_clip] (0 disables)."""
    normalize_advantages: bool = True
    """Standardise advantages per minibatch (over all devices)."""
    normalize_value_targets: bool = True
    """Learn the value in normalised units (running target statistics, PopArt output preservation)."""
    value_norm_decay: float = 0.99
    """Per-update decay of the value-target statistics once past the exact running average."""
    max_grad_norm: float = 1.0
    """Clip the global gradient norm to this (0 disables; Brax: no clipping)."""
    target_kl: float = 0.0
    """KL guard: skip the rest of an update's gradient steps once the approximate KL to the
    behaviour policy exceeds 1.5 * target_kl (0 disables)."""
    recompute_advantages: bool = True
    """Recompute advantages with the current value function at the start of every epoch after the
    first (whose parameters give the update's initial advantages)."""
    value_hidden_sizes: tuple[int, ...] = (256, 256, 256)
    """Hidden layer widths of the value network."""
    failure_budget: float | None = None
    """PPO-Lagrangian (Ray et al. 2019, Safety Gym, with a cost of 1 per failure step): the share of the training
    episodes allowed to end in a failure (a termination: a collision, or NaN physics, in tasks where reaching does
    not terminate). A multiplier learned by dual ascent, in env-reward units, is subtracted from each failure
    step's reward (besides env.collision_penalty, before reward_scaling). None: no multiplier."""
    multiplier_lr: float = 3.0
    """Dual-ascent step of that multiplier after each update: it grows by multiplier_lr x (the batch's share of
    episodes ending in a failure - failure_budget), floored at 0. Per update, so its pace follows
    env_steps_per_update."""
    multiplier_start: int = 0
    """Env steps before that dual ascent begins: updates that begin earlier leave the multiplier at 0, so the agent
    learns to reach before failures cost it more (a curriculum). Counted in whole updates of env_steps_per_update."""

    @property
    def env_steps_per_update(self) -> int:
        return self.batch_size * self.num_minibatches * self.unroll_length

    @property
    def schedule_spans_run(self) -> bool:
        """The learning rate decays over num_timesteps, so a run's length changes its schedule."""
        return self.lr_schedule != "constant"

    def validate(self, num_devices: int = 1) -> None:
        """ValueError naming the field, its value and what is allowed."""
        for name in ("num_envs", "batch_size", "num_minibatches", "unroll_length", "updates_per_batch"):
            validation.integer("algo." + name, getattr(self, name), 1)
        unrolls = self.batch_size * self.num_minibatches
        if unrolls % self.num_envs:
            raise ValueError(
                f"algo.num_envs={self.num_envs} is invalid: it must divide algo.batch_size * algo.num_minibatches"
                f" = {unrolls}; allowed are its divisors, e.g. {_divisors_near(unrolls, self.num_envs)}."
            )
        if self.num_envs % num_devices:
            raise ValueError(f"algo.num_envs={self.num_envs} is invalid: it must be divisible by the {num_devices} devices.")
        if self.batch_size % num_devices:
            raise ValueError(f"algo.batch_size={self.batch_size} is invalid: it must be divisible by the {num_devices} devices.")
        validation.positive("algo.learning_rate", self.learning_rate)
        validation.in_range("algo.discount", self.discount, 0.0, 1.0)
        validation.in_range("algo.gae_lambda", self.gae_lambda, 0.0, 1.0)
        validation.in_range("algo.lr_end_fraction", self.lr_end_fraction, 0.0, 1.0)
        validation.in_range("algo.value_norm_decay", self.value_norm_decay, 0.0, 1.0)
        validation.positive("algo.clip_epsilon", self.clip_epsilon)
        for name in ("entropy_coef", "value_loss_coef", "max_grad_norm", "target_kl", "obs_clip"):
            validation.positive("algo." + name, getattr(self, name), strict=False)
        validation.choice("algo.lr_schedule", self.lr_schedule, LR_SCHEDULES)
        self.validate_networks("value_hidden_sizes")
        if self.failure_budget is not None:
            validation.in_range("algo.failure_budget", self.failure_budget, 0.0, 1.0)
        validation.positive("algo.multiplier_lr", self.multiplier_lr)
        validation.integer("algo.multiplier_start", self.multiplier_start, 0, 10 ** 15)  # env steps, never in JAX
        if self.multiplier_start and self.failure_budget is None:
            raise ValueError(f"algo.multiplier_start={self.multiplier_start} is invalid without algo.failure_budget: "
                             "allowed is 0, or a budget beside it.")


def _divisors_near(n: int, x: int) -> str:
    divs = [d for d in range(1, n + 1) if n % d == 0]
    divs.sort(key=lambda d: abs(math.log(d / max(x, 1))))
    return ", ".join(str(d) for d in sorted(divs[:4]))


# ----------------------------------------------------------------------------------------------
# The formulas (small named functions, unit-tested on hand-computed numbers).


def gae(rewards, values, next_values, terminations, dones, discount: float, lam: float):
    """Generalised advantage estimation (Schulman et al. 2016, eq. 16), time on axis 0.

    delta_t = r_t + discount * (1 - termination_t) * V(s'_t) - V(s_t), where s'_t is the step's next
    observation (the terminal one on truncation, so time-outs bootstrap and real terminations do
    not); A_t = delta_t + discount * lam * (1 - done_t) * A_{t+1}, the trace stopping at every episode
    boundary and at the end of the array (A_T = 0 there: the last delta already bootstraps).
    Returns (advantages, value targets = advantages + values).
    """
    deltas = rewards + discount * (1.0 - terminations) * next_values - values

    def backward(next_adv, x):
        delta, done = x
        adv = delta + discount * lam * (1.0 - done) * next_adv
        return adv, adv

    _, advantages = jax.lax.scan(backward, jnp.zeros_like(deltas[0]), (deltas, dones), reverse=True)
    return advantages, advantages + values


def ppo_loss_terms(log_prob, old_log_prob, advantages, values, value_targets, entropy, clip_epsilon: float):
    """The PPO objective's pieces (means over the minibatch), eq. 7 of Schulman et al. 2017."""
    log_ratio = log_prob - old_log_prob
    ratio = jnp.exp(log_ratio)
    clipped = jnp.clip(ratio, 1.0 - clip_epsilon, 1.0 + clip_epsilon)
    surrogate = jnp.minimum(ratio * advantages, clipped * advantages)
    return {
        "policy_loss": -jnp.mean(surrogate),
        "value_loss": jnp.mean(jnp.square(values - value_targets)),
        "entropy": jnp.mean(entropy),
        # k3 estimator of KL(behaviour || current): unbiased and >= 0 (Schulman's note on KL approximation).
        "approx_kl": jnp.mean((ratio - 1.0) - log_ratio),
        "clip_fraction": jnp.mean((jnp.abs(ratio - 1.0) > clip_epsilon).astype(jnp.float32)),
    }


def learning_rate(config: PPOConfig, progress: jax.Array) -> jax.Array:
    """Learning rate at `progress` in [0, 1] of the planned updates."""
    p = jnp.clip(progress, 0.0, 1.0)
    end = config.lr_end_fraction
    if config.lr_schedule == "linear":
        frac = 1.0 - (1.0 - end) * p
    elif config.lr_schedule == "cosine":
        frac = end + (1.0 - end) * 0.5 * (1.0 + jnp.cos(jnp.pi * p))
    else:
        frac = jnp.ones_like(p)
    return config.learning_rate * frac


def normalize_per_minibatch(advantages, pmean=lambda x: x):
    """Advantages standardised within each minibatch (leading axis), with statistics averaged over
    devices by `pmean`: what each gradient step would compute for its own minibatch, done for all
    of an epoch's minibatches at once (a gradient step then starts with its forward pass)."""
    axes = tuple(range(1, advantages.ndim))
    mean = pmean(jnp.mean(advantages, axis=axes, keepdims=True))
    var = pmean(jnp.mean(jnp.square(advantages - mean), axis=axes, keepdims=True))
    return (advantages - mean) / (jnp.sqrt(var) + 1e-8)


def popart_preserve(value_params, old: normalizer.RunningStats, new: normalizer.RunningStats):
    """Rescales the value head so its de-normalised outputs are unchanged by a statistics update
    (van Hasselt et al. 2016, "Learning values across many orders of magnitude", eq. 6)."""
    s_old, s_new = normalizer.std(old), normalizer.std(new)
    out = value_params["params"]["out"]
    out = {"kernel": out["kernel"] * s_old / s_new, "bias": (out["bias"] * s_old + old.mean - new.mean) / s_new}
    return {**value_params, "params": {**value_params["params"], "out": out}}


# ----------------------------------------------------------------------------------------------
# The learner.


@struct.dataclass
class PPOState:
    params: dict
    """{"policy": ..., "value": ...}"""
    opt_state: optax.OptState
    obs_stats: normalizer.RunningStats
    value_stats: normalizer.RunningStats
    updates: jax.Array
    """Updates done (drives the learning-rate schedule)."""
    multiplier: jax.Array | None = None
    """The failure multiplier of PPO-Lagrangian (`failure_budget`); None without a budget."""


class PPO:
    """PPO as a `agents.loop.Learner`. The objective is `loss`; `advantages` and `minibatches` are
    the other methods a variant typically overrides (notebooks/02_edit_an_algorithm.ipynb)."""

    transient_fields = ()  # every field of the learner state is checkpointed

    def __init__(self, config: PPOConfig, observation_size: int, action_size: int, total_updates: int):
        self.config = config
        self.observation_size, self.action_size = observation_size, action_size
        self.total_updates = max(1, int(total_updates))
        c = config
        self.unrolls_per_env = c.batch_size * c.num_minibatches // c.num_envs
        self.steps_per_update = self.unrolls_per_env * c.unroll_length
        self.policy_net = networks.policy_network(action_size, c.policy_hidden_sizes, c.activation, c.kernel_init, c.layer_norm)
        self.value_net = networks.value_network(c.value_hidden_sizes, c.activation, c.kernel_init, c.layer_norm)
        clip = [optax.clip_by_global_norm(c.max_grad_norm)] if c.max_grad_norm > 0 else []
        # Adam on one flat vector of all parameters: a few large GPU kernels per gradient step instead
        # of several per parameter array (the 320 steps of an update are launch-bound otherwise). The
        # clipping norm is summed per array, so each part can start as soon as its gradient exists.
        self.optimizer = optax.chain(*clip, optax.flatten(optax.scale_by_adam()))

    # -- pieces ---------------------------------------------------------------------------------

    def _obs(self, state: PPOState, obs):
        if not self.config.normalize_observations:
            return obs
        return normalizer.normalize(state.obs_stats, obs, self.config.obs_clip or None)

    def _dist(self, policy_params, x) -> TanhNormal:
        return TanhNormal.from_network_output(self.policy_net.apply(policy_params, x), self.config.min_std)

    def _value(self, value_params, value_stats, x):
        """De-normalised value estimate."""
        v = self.value_net.apply(value_params, x)[..., 0]
        return normalizer.denormalize(value_stats, v) if self.config.normalize_value_targets else v

    # -- Learner interface ----------------------------------------------------------------------

    def init(self, key) -> PPOState:
        k_pi, k_v = jax.random.split(key)
        dummy = jnp.zeros((1, self.observation_size))
        params = {"policy": self.policy_net.init(k_pi, dummy), "value": self.value_net.init(k_v, dummy)}
        multiplier = None if self.config.failure_budget is None else jnp.zeros(())
        return PPOState(params, self.optimizer.init(params), normalizer.init(self.observation_size), normalizer.init(()),
                        jnp.zeros((), jnp.int32), multiplier)

    def env_axes(self, state: PPOState):
        return jax.tree.map(lambda _: None, state)

    def act(self, state: PPOState, obs, key, par: Parallel):
        dist = self._dist(state.params["policy"], self._obs(state, obs))
        action, u, log_prob = dist.sample_with_noise(env_random(key, par, (self.action_size,)))
        return action, {"raw_action": u, "log_prob": log_prob}

    def policy(self, state: PPOState, obs):
        return self._dist(state.params["policy"], self._obs(state, obs)).mode()

    def stochastic_policy(self, state: PPOState, obs, key):
        return self._dist(state.params["policy"], self._obs(state, obs)).sample(key)

    def export_policy(self, state: PPOState):
        """(policy parameters, observation statistics): what `policy` reads, for `agents.export`."""
        return state.params["policy"], state.obs_stats

    def policy_state(self, policy_params, obs_stats) -> PPOState:
        """A state holding only what `policy` reads (the inverse of `export_policy`)."""
        return PPOState(params={"policy": policy_params}, opt_state=None, obs_stats=obs_stats, value_stats=None,
                        updates=None)

    def progress_note(self, updates_done: int) -> str | None:
        """For a run stopped before its decaying learning-rate schedule ends: where the rate stands (a
        policy evaluated there has not had the schedule's low-rate end). None otherwise."""
        c = self.config
        if not c.schedule_spans_run or updates_done >= self.total_updates:
            return None
        fraction = float(learning_rate(c, jnp.float32(updates_done / self.total_updates))) / c.learning_rate
        return (f"the learning rate is at {fraction:.0%} of its start: its {c.lr_schedule} schedule runs "
                f"{self.total_updates:,} updates ({updates_done:,} done). --resume continues it; for a shorter run, "
                "set --num-timesteps to the steps it will really train.")

    @jax.named_scope("advantages")
    def advantages(self, params, value_stats, obs, next_obs, data: Transition):
        """GAE per unroll; `data` leaves are (envs, unrolls, unroll_length, ...), `obs` and `next_obs`
        its observations already normalised."""
        c = self.config
        values = self._value(params["value"], value_stats, obs)
        next_values = self._value(params["value"], value_stats, next_obs)
        time_first = lambda x: jnp.moveaxis(x, 2, 0)
        adv, targets = gae(time_first(data.reward), time_first(values), time_first(next_values),
                           time_first(data.termination), time_first(data.done), c.discount, c.gae_lambda)
        return jnp.moveaxis(adv, 0, 2), jnp.moveaxis(targets, 0, 2)

    def minibatches(self, tree, key, par: Parallel):
        """Splits (envs, unrolls, ...) leaves into (num_minibatches, local batch, ...).

        Stratified so that it does not depend on the number of devices: each env's unrolls are
        permuted with a key of its global index, unroll slot s = env * unrolls_per_env + j goes to
        minibatch s mod num_minibatches, and the minibatch order is permuted with a shared key. Every
        minibatch therefore spreads over many envs and holds batch_size / devices unrolls per device.
        """
        m = self.config.num_minibatches
        k_perm, k_order = jax.random.split(key)
        perms = jax.vmap(lambda k: jax.random.permutation(k, self.unrolls_per_env))(per_env_keys(k_perm, par.env_ids()))
        order = jax.random.permutation(k_order, m)

        def arrange(x):
            x = jax.vmap(lambda xe, pe: xe[pe])(x, perms)
            x = x.reshape((-1, m) + x.shape[2:])
            return jnp.swapaxes(x, 0, 1)[order]

        return jax.tree.map(arrange, tree)

    def loss(self, params, mb: dict, value_stats: normalizer.RunningStats):
        """The PPO objective on one minibatch (Schulman et al. 2017, eq. 9): clipped surrogate, value
        error and entropy bonus. `mb`: normalised "obs", the behaviour's "raw_action" and "log_prob",
        (standardised) "advantages", de-normalised value "targets" and the entropy estimate's "noise".
        Returns (loss, metrics); every metric is averaged over the update and logged under its key."""
        c = self.config
        dist = self._dist(params["policy"], mb["obs"])
        values = self.value_net.apply(params["value"], mb["obs"])[..., 0]
        targets = normalizer.normalize(value_stats, mb["targets"]) if c.normalize_value_targets else mb["targets"]
        terms = ppo_loss_terms(dist.log_prob_raw(mb["raw_action"]), mb["log_prob"], mb["advantages"], values, targets,
                               dist.entropy_from_noise(mb["noise"]), c.clip_epsilon)
        loss = terms["policy_loss"] + c.value_loss_coef * terms["value_loss"] - c.entropy_coef * terms["entropy"]
        return loss, {"loss/total": loss, "loss/policy": terms["policy_loss"], "loss/value": terms["value_loss"],
                      "policy/entropy": terms["entropy"], "policy/approx_kl": terms["approx_kl"],
                      "policy/clip_fraction": terms["clip_fraction"], "policy/std": jnp.mean(dist.std)}

    @jax.named_scope("sgd_step")
    def sgd_step(self, carry, mb: dict, value_stats, lr, par: Parallel):
        """One gradient step of `loss` on a minibatch; carry = (params, opt_state, KL-guard stopped)."""
        c = self.config
        params, opt_state, stopped = carry
        (_, metrics), grads = jax.value_and_grad(self.loss, has_aux=True)(params, mb, value_stats)
        # Device-local loss and gradient; the global-batch ones are their means over devices.
        grads, metrics = par.mean_gradients(grads), par.pmean(metrics)
        if c.target_kl > 0:
            stopped = stopped | (metrics["policy/approx_kl"] > 1.5 * c.target_kl)
        updates, new_opt_state = self.optimizer.update(grads, opt_state, params)
        new_params = jax.tree.map(lambda w, u: w - lr * u, params, updates)
        if c.target_kl > 0:  # once stopped, the rest of the update's steps leave everything as is
            keep = lambda new, old: jax.tree.map(lambda a, b: jnp.where(stopped, b, a), new, old)
            new_params, new_opt_state = keep(new_params, params), keep(new_opt_state, opt_state)
        # grad_norm: the norm the clipping computes (the same expression, so XLA can merge the two).
        metrics = {**metrics, "optim/grad_norm": optax.tree.norm(grads), "optim/kl_skipped": stopped.astype(jnp.float32)}
        return (new_params, new_opt_state, stopped), metrics

    def epoch(self, carry, key, data: dict, value_stats, lr, par: Parallel):
        """One sweep over the batch in `num_minibatches` gradient steps. `data` leaves are
        (envs, unrolls, unroll_length, ...); returns (carry, per-step metrics)."""
        k_mb, k_ent = jax.random.split(key)
        # Noise of the one-sample entropy estimate, keyed by global env index (device-invariant).
        data = {**data, "noise": env_random(k_ent, par, data["raw_action"].shape[1:])}
        with jax.named_scope("minibatches"):
            mbs = self.minibatches(data, k_mb, par)
            if self.config.normalize_advantages:
                mbs["advantages"] = normalize_per_minibatch(mbs["advantages"], par.pmean)
        return jax.lax.scan(lambda cr, mb: self.sgd_step(cr, mb, value_stats, lr, par), carry, mbs)

    def update(self, state: PPOState, batch: Transition, key, par: Parallel):
        """`updates_per_batch` epochs on one batch of `(steps_per_update, local_envs)` transitions."""
        c = self.config
        n_seq, length = self.unrolls_per_env, c.unroll_length
        # (T, envs, ...) -> (envs, unrolls, unroll_length, ...): unroll j of env e covers steps
        # j * unroll_length ... (j + 1) * unroll_length - 1.
        data = jax.tree.map(lambda x: jnp.moveaxis(x.reshape((n_seq, length) + x.shape[1:]), 2, 0), batch)
        if state.multiplier is not None:
            data = data._replace(reward=data.reward - state.multiplier * data.termination)
        data = data._replace(reward=data.reward * c.reward_scaling)
        lr = learning_rate(c, state.updates.astype(jnp.float32) / self.total_updates)

        params, value_stats = state.params, state.value_stats
        # The observation statistics stay fixed during an update (they take this batch after it):
        # normalise the batch's observations once for every epoch and gradient step.
        obs, next_obs = self._obs(state, data.obs), self._obs(state, data.next_obs)
        adv0, targets0 = self.advantages(params, value_stats, obs, next_obs, data)
        if c.normalize_value_targets:
            new_stats = normalizer.update(value_stats, targets0, par.axis_name, decay=c.value_norm_decay)
            params = {**params, "value": popart_preserve(params["value"], value_stats, new_stats)}
            value_stats = new_stats
        fixed = {"obs": obs, "raw_action": data.extras["raw_action"], "log_prob": data.extras["log_prob"]}

        def later_epoch(carry, k):
            adv, targets = adv0, targets0
            if c.recompute_advantages:
                adv, targets = self.advantages(carry[0], value_stats, obs, next_obs, data)
            return self.epoch(carry, k, {**fixed, "advantages": adv, "targets": targets}, value_stats, lr, par)

        # The first epoch takes adv0: its parameters give the same values (PopArt preserves them).
        keys = jax.random.split(key, c.updates_per_batch)
        first = {**fixed, "advantages": adv0, "targets": targets0}
        carry, first_metrics = self.epoch((params, state.opt_state, jnp.zeros((), bool)), keys[0], first, value_stats,
                                          lr, par)
        (params, opt_state, _), metrics = jax.lax.scan(later_epoch, carry, keys[1:])
        metrics = jax.tree.map(lambda a, b: jnp.mean(jnp.concatenate([a[None], b])), first_metrics, metrics)
        obs_stats = state.obs_stats
        if c.normalize_observations:
            obs_stats = normalizer.update(obs_stats, batch.obs, par.axis_name)
        metrics = {**metrics, "optim/learning_rate": lr, "value/target_mean": par.pmean(jnp.mean(targets0))}
        multiplier = state.multiplier
        if multiplier is not None:
            multiplier, failure_share = self.dual_ascent(multiplier, batch, par, state.updates)
            metrics = {**metrics, "lagrange/multiplier": multiplier, "lagrange/failure_share": failure_share}
        return PPOState(params, opt_state, obs_stats, value_stats, state.updates + 1, multiplier), metrics

    def dual_ascent(self, multiplier, batch: Transition, par: Parallel, updates):
        """PPO-Lagrangian's multiplier step after update number `updates` (from 0): (new multiplier, the share of
        the batch's ended episodes that failed). A batch in which no episode ended, or one begun before
        `multiplier_start` env steps, leaves the multiplier as it is."""
        c = self.config
        failures, ended = par.psum((jnp.sum(batch.termination), jnp.sum(batch.done)))
        share = failures / jnp.maximum(ended, 1.0)
        started = updates >= -(-c.multiplier_start // c.env_steps_per_update)  # whole updates, rounded up
        step = jnp.where((ended > 0) & started, c.multiplier_lr * (share - c.failure_budget), 0.0)
        return jnp.maximum(multiplier + step, 0.0), share
