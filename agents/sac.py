"""Soft Actor-Critic (Haarnoja et al. 2018, "SAC algorithms and applications") for `agents.loop`.

Twin Q networks with Polyak-averaged targets, automatic temperature, and a replay buffer kept in
device memory inside the learner state. Each update is one environment step of all `num_envs`
environments (as in Brax), inserted into the buffer, then `grad_updates_per_step` gradient steps on
`batch_size` sampled transitions. Until the buffer holds `min_replay_size` transitions the actions
are uniform random and no gradient step is applied (Brax's prefill; these steps count towards
num_timesteps).

The buffer (`agents.replay`) holds max_replay_size / num_envs rows of every env's transition of one
step, its env axis split over devices like the environments.

Bootstrapping: the critic target uses the stored `next_obs`, which on a truncated step is the
terminal observation, and drops the bootstrap only on real terminations.

Switches for thousands of environments and large batches (as in FastTD3 / FastSAC, Seo et al. 2025):
`n_step` returns read from consecutive buffer rows (cut at episode ends, `agents.offpolicy`), and a
`distributional` critic: a categorical return distribution on `num_atoms` atoms in [v_min, v_max]
trained by cross-entropy against the projected target (Bellemare et al. 2017), with the clipped
double-Q choice made per sample by the two target critics' means.

A failure budget (`failure_budget`, SAC-Lagrangian: Ha et al. 2020; Ray et al. 2019) adds twin cost critics that
estimate the discounted chance of a failure ahead (a termination), and a multiplier learned by dual ascent that
weighs them in the actor's objective.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import optax
from flax import struct

from agents import networks, normalizer, offpolicy, replay as buffer
from agents.distributions import TanhNormal
from agents.loop import Parallel, Transition, env_random, per_env_keys
from agents.replay import Replay
from envs import validation


@dataclasses.dataclass(frozen=True)
class SACConfig(networks.NetworkConfig):
    """SAC hyperparameters. Defaults: the paper's SAC setting (section "Training and evaluation")."""

    num_envs: int = 128
    """Parallel environments over all devices; one update steps each of them once."""
    batch_size: int = 256
    """Transitions per gradient step (must divide or be a multiple of num_envs)."""
    learning_rate: float = 1e-4
    """Adam step size of the policy, the critics and the temperature."""
    discount: float = 0.97
    """Discount factor gamma."""
    reward_scaling: float = 20.0
    """Rewards are multiplied by this in the critic target."""
    tau: float = 0.005
    """Polyak factor of the target critics (Brax's default)."""
    min_replay_size: int = 102_400
    """Transitions collected with random actions before learning starts."""
    max_replay_size: int = 2_048_000
    """Replay capacity in transitions (a multiple of num_envs); oldest are overwritten."""
    grad_updates_per_step: int = 1
    """Gradient steps per environment step of all envs (Brax's default 1; not stated in the paper; the paper's
    SAC presets use 8, which learned fastest on the UR5e: results, SAC study)."""
    init_alpha: float = 1.0
    """Initial temperature."""
    target_entropy: float | None = None
    """Entropy target of the temperature update; None means -action_size (Haarnoja et al.). Brax's SAC, which the
    paper trained with, uses -0.5 * action_size, which learned more slowly on UR5e reach (results, SAC study)."""
    normalize_observations: bool = True
    """Normalise observations with running statistics (updated from every inserted step)."""
    obs_clip: float = 10.0
    """Normalised observations are clipped to [-obs_clip, obs_clip] (0 disables)."""
    max_grad_norm: float = 0.0
    """Clip each network's gradient norm to this (0 disables)."""
    q_hidden_sizes: tuple[int, ...] = (256, 256, 256)
    """Hidden layer widths of each Q network."""
    n_step: int = 1
    """Steps summed in each critic target before bootstrapping (cut at episode ends); 1 = one-step SAC."""
    distributional: bool = False
    """Categorical return distribution per critic (C51) instead of a scalar Q."""
    num_atoms: int = 101
    """Atoms of the distributional critic's support."""
    v_min: float = -10.0
    """Lowest atom: returns (times reward_scaling) below it are clipped onto it."""
    v_max: float = 10.0
    """Highest atom: returns (times reward_scaling) above it are clipped onto it."""
    compute_dtype: str = "float32"
    """Dtype of the policy's and critics' hidden layers: float32 or bfloat16 (FastTD3 trains with bf16 autocast
    by default; for large batches on GPUs with bf16 tensor cores). Parameters, output layers, losses and Adam stay
    float32."""
    stacked_critics: bool = False
    """The twin critics as one network with stacked parameters (`networks.TwinQ.stacked`): the same functions with
    fewer GPU kernels in the critics' layers; parameters initialised from other random numbers than separate critics."""
    failure_budget: float | None = None
    """SAC-Lagrangian: the share of the training episodes allowed to end in a failure (a termination: a collision,
    or NaN physics, in tasks where reaching does not terminate), as PPOConfig.failure_budget. Twin cost critics
    learn the discounted failures ahead, Q_c (the pessimistic one, their maximum, is used); the actor maximises
    min Q - reward_scaling x multiplier x Q_c, as if the multiplier (env-reward units) were subtracted from each
    failure step's reward. Their networks are the critics' (q_hidden_sizes) with one scalar output. None: no
    multiplier and no cost critics."""
    multiplier_lr: float = 0.001
    """Dual-ascent step of that multiplier per ended episode: after each update it grows by multiplier_lr x (the
    update's failed episodes - failure_budget x its ended episodes), floored at 0; none while the buffer fills
    (logged as lagrange/failed_episodes and lagrange/ended_episodes per update: their means' ratio is the share).
    0.001 is about PPOConfig's default pace per env step on the reach-avoid presets (3 per update of 327,680 steps,
    about 2,800 episodes)."""

    @property
    def env_steps_per_update(self) -> int:
        return self.num_envs

    @property
    def schedule_spans_run(self) -> bool:
        """No hyperparameter depends on the run's length."""
        return False

    def validate(self, num_devices: int = 1) -> None:
        """ValueError naming the field, its value and what is allowed."""
        for name in ("num_envs", "batch_size", "max_replay_size", "grad_updates_per_step"):
            validation.integer("algo." + name, getattr(self, name), 1)
        if self.batch_size % self.num_envs and self.num_envs % self.batch_size:
            raise ValueError(
                f"algo.batch_size={self.batch_size} is invalid with algo.num_envs={self.num_envs}: allowed are "
                f"multiples or divisors of num_envs (e.g. {self.num_envs}, {2 * self.num_envs})."
            )
        if self.num_envs % num_devices:
            raise ValueError(f"algo.num_envs={self.num_envs} is invalid: it must be divisible by the {num_devices} devices.")
        if self.batch_size % num_devices:
            raise ValueError(f"algo.batch_size={self.batch_size} is invalid: it must be divisible by the {num_devices} devices.")
        if self.max_replay_size % self.num_envs:
            raise ValueError(
                f"algo.max_replay_size={self.max_replay_size} is invalid: allowed are multiples of algo.num_envs={self.num_envs}."
            )
        if not 0 <= self.min_replay_size <= self.max_replay_size:
            raise ValueError(
                f"algo.min_replay_size={self.min_replay_size} is invalid: allowed is 0 ... algo.max_replay_size={self.max_replay_size}."
            )
        validation.integer("algo.n_step", self.n_step, 1)
        if self.max_replay_size < self.n_step * self.num_envs:
            raise ValueError(f"algo.max_replay_size={self.max_replay_size} is invalid with algo.n_step={self.n_step}: "
                             f"allowed is at least n_step * num_envs = {self.n_step * self.num_envs}.")
        validation.integer("algo.num_atoms", self.num_atoms, 2)
        for name in ("v_min", "v_max"):
            validation.finite("algo." + name, getattr(self, name))
        if not self.v_min < self.v_max:
            raise ValueError(f"algo.v_max={self.v_max!r} is invalid: allowed is a number > algo.v_min={self.v_min!r}.")
        validation.positive("algo.learning_rate", self.learning_rate)
        validation.positive("algo.reward_scaling", self.reward_scaling)
        validation.positive("algo.init_alpha", self.init_alpha)
        validation.in_range("algo.discount", self.discount, 0.0, 1.0)
        validation.in_range("algo.tau", self.tau, 0.0, 1.0)
        for name in ("max_grad_norm", "obs_clip"):
            validation.positive("algo." + name, getattr(self, name), strict=False)
        self.validate_networks("q_hidden_sizes")
        validation.choice("algo.compute_dtype", self.compute_dtype, tuple(networks.COMPUTE_DTYPES))
        if not isinstance(self.stacked_critics, bool):
            raise ValueError(f"algo.stacked_critics={self.stacked_critics!r} is invalid: allowed are True, False.")
        if self.failure_budget is not None:
            validation.in_range("algo.failure_budget", self.failure_budget, 0.0, 1.0)
        validation.positive("algo.multiplier_lr", self.multiplier_lr)


# ----------------------------------------------------------------------------------------------
# The formulas (unit-tested on hand-computed numbers).


def critic_target(reward, termination, next_q, next_log_prob, alpha, discount: float, reward_scaling: float):
    """y = s r + gamma (1 - termination) (min_i Q'_i(s', a') - alpha log pi(a'|s')), a' ~ pi(s')
    (Haarnoja et al. 2018, eqs. 3 and 5 with the clipped double-Q minimum). `next_q`: (..., 2)."""
    soft_value = jnp.min(next_q, axis=-1) - alpha * next_log_prob
    return reward_scaling * reward + discount * (1.0 - termination) * soft_value


def critic_loss(q, target):
    """0.5 * mean squared error of both critics against the (constant) target. `q`: (..., 2)."""
    return 0.5 * jnp.mean(jnp.square(q - jax.lax.stop_gradient(target)[..., None]))


def actor_loss(log_prob, q, alpha):
    """E[alpha log pi(a|s) - min_i Q_i(s, a)], a ~ pi(s) reparameterised (eq. 7)."""
    return jnp.mean(alpha * log_prob - jnp.min(q, axis=-1))


def temperature_loss(log_alpha, log_prob, target_entropy: float):
    """-log_alpha * E[log pi + target_entropy] (eq. 18 in log space): raises alpha while the
    policy's entropy -E[log pi] is below the target, lowers it above."""
    return -log_alpha * jnp.mean(jax.lax.stop_gradient(log_prob) + target_entropy)


def polyak(target, online, tau: float):
    return jax.tree.map(lambda t, o: (1.0 - tau) * t + tau * o, target, online)


def cost_critic_target(cost, next_cost_q, discount):
    """y_c = c + discount x max_i Q'_c,i(s', a'): the discounted failures ahead, with the pessimistic (larger) of
    the twin target cost critics. `cost` and `discount` from the (n-step) window, `next_cost_q`: (..., 2)."""
    return cost + discount * jnp.max(next_cost_q, axis=-1)


def dual_ascent(multiplier, failures, ended, failure_budget: float, multiplier_lr: float):
    """The Lagrange multiplier after one update: multiplier + multiplier_lr x (failures - failure_budget x ended),
    floored at 0 (the dual ascent of Ray et al. 2019, per ended episode)."""
    return jnp.maximum(multiplier + multiplier_lr * (failures - failure_budget * ended), 0.0)


# ----------------------------------------------------------------------------------------------


@struct.dataclass
class SACState:
    policy_params: dict
    q_params: dict
    target_q_params: dict
    log_alpha: jax.Array
    policy_opt: optax.OptState
    q_opt: optax.OptState
    alpha_opt: optax.OptState
    obs_stats: normalizer.RunningStats
    replay: Replay
    cost_q_params: dict | None = None
    """The twin cost critics of `failure_budget` (and below, their targets, optimiser state and the multiplier);
    None without a budget."""
    target_cost_q_params: dict | None = None
    cost_q_opt: optax.OptState | None = None
    multiplier: jax.Array | None = None


class SAC:
    """SAC as a `agents.loop.Learner`. The objectives are the methods `critic_target`, `critic_loss`,
    `actor_loss` and `temperature_loss`; a variant overrides the one it changes."""

    steps_per_update = 1
    transient_fields = ("replay",)
    """Learner-only checkpoints leave the buffer out (5 seeds x 2,048,000 UR5e transitions are
    ~1.2 GB); a run resumed from one refills it with min_replay_size uniform-random steps first."""

    def __init__(self, config: SACConfig, observation_size: int, action_size: int, total_updates: int = 1):
        c = self.config = config
        self.observation_size, self.action_size = observation_size, action_size
        self.rows = c.max_replay_size // c.num_envs
        self.target_entropy = -float(action_size) if c.target_entropy is None else float(c.target_entropy)
        self.policy_net = networks.policy_network(action_size, c.policy_hidden_sizes, c.activation, c.kernel_init, c.layer_norm,
                                                  c.compute_dtype)
        self.q_net = networks.q_network(c.q_hidden_sizes, c.activation, c.kernel_init, c.layer_norm,
                                        c.num_atoms if c.distributional else 1, c.compute_dtype, c.stacked_critics)
        self.support = offpolicy.categorical_support(c.v_min, c.v_max, c.num_atoms) if c.distributional else None
        self.cost_net = None if c.failure_budget is None else networks.q_network(
            c.q_hidden_sizes, c.activation, c.kernel_init, c.layer_norm, 1, c.compute_dtype, c.stacked_critics)
        clip = [optax.clip_by_global_norm(c.max_grad_norm)] if c.max_grad_norm > 0 else []
        # On one flat vector per network: few large GPU kernels per gradient step (see agents/ppo.py).
        self.optimizer = optax.flatten(optax.chain(*clip, optax.adam(c.learning_rate)))

    def _obs(self, stats, obs):
        if not self.config.normalize_observations:
            return obs
        return normalizer.normalize(stats, obs, self.config.obs_clip or None)

    def _dist(self, params, x) -> TanhNormal:
        return TanhNormal.from_network_output(self.policy_net.apply(params, x), self.config.min_std)

    def init(self, key) -> SACState:
        c = self.config
        k_pi, k_q = jax.random.split(key)
        obs = jnp.zeros((1, self.observation_size))
        policy_params = self.policy_net.init(k_pi, obs)
        q_params = self.q_net.init(k_q, obs, jnp.zeros((1, self.action_size)))
        log_alpha = jnp.log(jnp.asarray(c.init_alpha, jnp.float32))
        replay = buffer.empty(self.rows, c.num_envs, self.observation_size, self.action_size, c.n_step)
        state = SACState(policy_params, q_params, q_params, log_alpha, self.optimizer.init(policy_params),
                         self.optimizer.init(q_params), self.optimizer.init(log_alpha),
                         normalizer.init(self.observation_size), replay)
        if c.failure_budget is None:
            return state
        # Its own key, so that a run without a budget draws exactly what it drew before budgets existed.
        cost_q_params = self.cost_net.init(jax.random.fold_in(key, 1), obs, jnp.zeros((1, self.action_size)))
        return state.replace(cost_q_params=cost_q_params, target_cost_q_params=cost_q_params,
                             cost_q_opt=self.optimizer.init(cost_q_params), multiplier=jnp.zeros(()))

    def env_axes(self, state: SACState):
        """The replay buffer's env axis (1) is split over devices; everything else is replicated."""
        replay = Replay(data=jax.tree.map(lambda _: 1, state.replay.data), position=None, rows=None)
        return jax.tree.map(lambda _: None, state).replace(replay=replay)

    def _warming_up(self, state: SACState):
        c = self.config
        return state.replay.rows * c.num_envs < max(c.min_replay_size, c.n_step * c.num_envs)

    def act(self, state: SACState, obs, key, par: Parallel):
        dist = self._dist(state.policy_params, self._obs(state.obs_stats, obs))
        k_noise, k_uniform = jax.random.split(key)
        action, _, _ = dist.sample_with_noise(env_random(k_noise, par, (self.action_size,)))
        uniform = env_random(k_uniform, par, (self.action_size,), kind="uniform")
        return jnp.where(self._warming_up(state), uniform, action), {}

    def policy(self, state: SACState, obs):
        return self._dist(state.policy_params, self._obs(state.obs_stats, obs)).mode()

    def stochastic_policy(self, state: SACState, obs, key):
        return self._dist(state.policy_params, self._obs(state.obs_stats, obs)).sample(key)

    def export_policy(self, state: SACState):
        """(policy parameters, observation statistics): what `policy` reads, for `agents.export`."""
        return state.policy_params, state.obs_stats

    def policy_state(self, policy_params, obs_stats) -> SACState:
        """A state holding only what `policy` reads (the inverse of `export_policy`)."""
        return SACState(policy_params=policy_params, q_params=None, target_q_params=None, log_alpha=None,
                        policy_opt=None, q_opt=None, alpha_opt=None, obs_stats=obs_stats, replay=None)

    def progress_note(self, updates_done: int) -> str | None:
        """Nothing in SAC depends on how far the run got."""
        return None

    @jax.named_scope("insert")
    def insert(self, replay: Replay, batch: Transition) -> Replay:
        return buffer.insert(replay, batch, self.rows)

    @jax.named_scope("sample")
    def sample(self, replay: Replay, key, par: Parallel):
        """This device's share of a stratified batch: (transitions, global sample ids), `agents.replay.sample`."""
        return buffer.sample(replay, key, par, self.config, self.rows)

    # -- the objectives (each one overridable) --------------------------------------------------

    @jax.named_scope("critic_target")
    def critic_target(self, s: SACState, mb: dict, next_obs, noise, alpha):
        """The soft Bellman target of the sampled (n-step) transitions (eq. 3 with the clipped
        double-Q minimum): a number per sample, or with the distributional critic the projected
        target distribution (Bellemare et al. 2017, Algorithm 1) of the target critic whose mean is
        smaller. `mb["discount"]` is gamma^n, or 0 where the episode terminated in the window."""
        c = self.config
        next_action, _, next_log_prob = self._dist(s.policy_params, next_obs).sample_with_noise(noise)
        next_q = self.q_net.apply(s.target_q_params, next_obs, next_action)
        if not c.distributional:
            return critic_target(mb["reward"], 0.0, next_q, next_log_prob, alpha, mb["discount"], c.reward_scaling)
        probs = jax.nn.softmax(next_q, axis=-1)  # (batch, 2, atoms)
        means = offpolicy.categorical_mean(probs, self.support, is_logits=False)
        chosen = jnp.where((means[:, 0] <= means[:, 1])[:, None], probs[:, 0], probs[:, 1])
        shift = c.reward_scaling * mb["reward"] - mb["discount"] * alpha * next_log_prob
        return offpolicy.categorical_projection(chosen, shift, mb["discount"], self.support)

    def critic_loss(self, q_params, obs, action, target):
        """Both critics' error against the target (eq. 5; with the distributional critic the
        cross-entropy to the target distribution, summed over the critics); returns (loss, mean Q)."""
        q = self.q_net.apply(q_params, obs, action)
        if not self.config.distributional:
            return critic_loss(q, target), jnp.mean(q)
        loss = jnp.mean(jnp.sum(offpolicy.categorical_cross_entropy(q, target[:, None]), axis=-1))
        return loss, jnp.mean(offpolicy.categorical_mean(q, self.support, is_logits=True))

    def actor_loss(self, policy_params, q_params, obs, noise, alpha, cost=None):
        """E[alpha log pi(a|s) - min Q(s, a)] with reparameterised actions (eq. 7); returns (loss, log-probs).
        With a failure budget, `cost` = (cost critics' parameters, multiplier) and the actor maximises
        min Q - reward_scaling x multiplier x max Q_c instead of min Q."""
        action, _, log_prob = self._dist(policy_params, obs).sample_with_noise(noise)
        q = self.q_net.apply(q_params, obs, action)
        if self.config.distributional:
            q = offpolicy.categorical_mean(q, self.support, is_logits=True)
        if cost is not None:
            cost_q_params, multiplier = cost
            cost_q = jnp.max(self.cost_net.apply(cost_q_params, obs, action), axis=-1)
            q = q - (self.config.reward_scaling * multiplier * cost_q)[..., None]
        return actor_loss(log_prob, q, alpha), log_prob

    def cost_critic_loss(self, cost_q_params, obs, action, target):
        """Both cost critics' squared error against the (constant) target; returns (loss, mean Q_c)."""
        cost_q = self.cost_net.apply(cost_q_params, obs, action)
        return critic_loss(cost_q, target), jnp.mean(cost_q)

    def temperature_loss(self, log_alpha, log_prob):
        """Automatic temperature (eq. 18) towards the entropy target."""
        return temperature_loss(log_alpha, log_prob, self.target_entropy)

    # -- the update ------------------------------------------------------------------------------

    def _noise(self, key, ids):
        return jax.vmap(lambda k: jax.random.normal(k, (self.action_size,)))(per_env_keys(key, ids))

    def sgd_step(self, s: SACState, key, par: Parallel):
        """One gradient step of the critics, then the actor, then the temperature, on one sampled batch."""
        c = self.config
        k_sample, k_next, k_pi = jax.random.split(key, 3)
        mb, ids = self.sample(s.replay, k_sample, par)
        # Device-local losses and gradients; the global-batch ones are their means over devices.
        obs, next_obs = self._obs(s.obs_stats, mb["obs"]), self._obs(s.obs_stats, mb["next_obs"])
        alpha = jnp.exp(s.log_alpha)
        next_noise = self._noise(k_next, ids)  # the next actions' noise, for the cost critics' target too
        target = self.critic_target(s, mb, next_obs, next_noise, alpha)

        with jax.named_scope("critic_update"):
            (q_loss, q_mean), q_grads = jax.value_and_grad(self.critic_loss, has_aux=True)(s.q_params, obs, mb["action"],
                                                                                          target)
            q_grads, q_loss, q_mean = par.mean_gradients(q_grads), par.pmean(q_loss), par.pmean(q_mean)
            q_updates, q_opt = self.optimizer.update(q_grads, s.q_opt, s.q_params)
            q_params = optax.apply_updates(s.q_params, q_updates)

        cost, cost_metrics = None, {}
        if s.multiplier is not None:
            s, cost_metrics = self._cost_critic_step(s, mb, obs, next_obs, next_noise, par)
            cost = (s.cost_q_params, s.multiplier)

        with jax.named_scope("actor_update"):
            (pi_loss, log_prob), pi_grads = jax.value_and_grad(self.actor_loss, has_aux=True)(
                s.policy_params, q_params, obs, self._noise(k_pi, ids), alpha, cost)
            pi_grads, pi_loss = par.mean_gradients(pi_grads), par.pmean(pi_loss)
            pi_updates, policy_opt = self.optimizer.update(pi_grads, s.policy_opt, s.policy_params)
            policy_params = optax.apply_updates(s.policy_params, pi_updates)

        with jax.named_scope("temperature_update"):
            a_loss, a_grad = jax.value_and_grad(self.temperature_loss)(s.log_alpha, log_prob)
            a_grad, a_loss = par.mean_gradients(a_grad), par.pmean(a_loss)
            a_updates, alpha_opt = self.optimizer.update(a_grad, s.alpha_opt, s.log_alpha)
            log_alpha = optax.apply_updates(s.log_alpha, a_updates)

        with jax.named_scope("polyak"):
            target_q_params = polyak(s.target_q_params, q_params, c.tau)
        s = s.replace(policy_params=policy_params, q_params=q_params, log_alpha=log_alpha,
                      target_q_params=target_q_params,
                      policy_opt=policy_opt, q_opt=q_opt, alpha_opt=alpha_opt)
        metrics = {"loss/critic": q_loss, "loss/actor": pi_loss, "loss/temperature": a_loss,
                   "sac/alpha": alpha, "sac/entropy": par.pmean(-jnp.mean(log_prob)), "sac/q_mean": q_mean,
                   **cost_metrics}
        return s, metrics

    @jax.named_scope("cost_critic_update")
    def _cost_critic_step(self, s: SACState, mb: dict, obs, next_obs, next_noise, par: Parallel):
        """One gradient step of the cost critics towards `cost_critic_target` (the next action drawn with the reward
        critics' noise), and their Polyak average; returns (state, metrics)."""
        next_action, _, _ = self._dist(s.policy_params, next_obs).sample_with_noise(next_noise)
        next_cost_q = self.cost_net.apply(s.target_cost_q_params, next_obs, next_action)
        target = cost_critic_target(mb["cost"], next_cost_q, mb["discount"])
        (loss, cost_q_mean), grads = jax.value_and_grad(self.cost_critic_loss, has_aux=True)(
            s.cost_q_params, obs, mb["action"], target)
        grads, loss, cost_q_mean = par.mean_gradients(grads), par.pmean(loss), par.pmean(cost_q_mean)
        updates, cost_q_opt = self.optimizer.update(grads, s.cost_q_opt, s.cost_q_params)
        cost_q_params = optax.apply_updates(s.cost_q_params, updates)
        s = s.replace(cost_q_params=cost_q_params, cost_q_opt=cost_q_opt,
                      target_cost_q_params=polyak(s.target_cost_q_params, cost_q_params, self.config.tau))
        return s, {"loss/cost_critic": loss, "sac/cost_q_mean": cost_q_mean}

    def update(self, state: SACState, batch: Transition, key, par: Parallel):
        """Inserts the step into the buffer, then `grad_updates_per_step` gradient steps (none while
        the buffer holds fewer than `min_replay_size` transitions); with a failure budget, then the multiplier's
        dual-ascent step on the step's ended episodes (over all devices)."""
        c = self.config
        replay = self.insert(state.replay, batch)
        obs_stats = state.obs_stats
        if c.normalize_observations:
            obs_stats = normalizer.update(obs_stats, batch.obs, par.axis_name)
        state = state.replace(replay=replay, obs_stats=obs_stats)

        def train(s):
            s, metrics = jax.lax.scan(lambda s_, k: self.sgd_step(s_, k, par), s,
                                      jax.random.split(key, c.grad_updates_per_step))
            return s, jax.tree.map(jnp.mean, metrics)

        def skip(s):  # still filling the buffer: no gradient step, losses reported as 0
            metrics = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), jax.eval_shape(train, s)[1])
            return s, {**metrics, "sac/alpha": jnp.exp(s.log_alpha)}

        warming_up = self._warming_up(state)
        state, metrics = jax.lax.cond(warming_up, skip, train, state)
        metrics["replay/transitions"] = (state.replay.rows * c.num_envs).astype(jnp.float32)
        if state.multiplier is not None:
            failures, ended = par.psum((jnp.sum(batch.termination), jnp.sum(batch.done)))
            stepped = dual_ascent(state.multiplier, failures, ended, c.failure_budget, c.multiplier_lr)
            state = state.replace(multiplier=jnp.where(warming_up, state.multiplier, stepped))
            # Counts, not their ratio: many steps end no episode, and the logged means' ratio is the interval's share.
            metrics = {**metrics, "lagrange/multiplier": state.multiplier, "lagrange/failed_episodes": failures,
                       "lagrange/ended_episodes": ended}
        return state, metrics
