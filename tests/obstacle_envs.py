"""What the obstacle tests share: a compiled UR5e reach-avoid variant, its observation split by part, and a hand
reference of a straight path bouncing in the obstacles' cube."""

import jax
import jax.numpy as jnp
import numpy as np

import envs

N = 8
"""Envs per batch of the moving-obstacle variant."""


class Compiled:
    """One UR5e reach-avoid variant with its jitted, vmapped reset and step."""

    def __init__(self, **options):
        self.env = envs.make("ur5e-reach-avoid", **options)
        self.reset = jax.jit(jax.vmap(self.env.reset))
        self.step = jax.jit(jax.vmap(self.env.step))

    def start(self, seed, n=N):
        return self.reset(jax.random.split(jax.random.PRNGKey(seed), n))


def split_obs(env, obs):
    """The observation's parts by name (sizes from the env)."""
    sizes = env.observation_part_sizes
    out, at = {}, 0
    for part in env.config.observation:
        out[part] = np.asarray(obs)[..., at:at + sizes[part]]
        at += sizes[part]
    assert at == obs.shape[-1]
    return out


def standstill(env, n=N):
    return jnp.zeros((n, env.action_size))


def reflect_by_hand(x, low, high):
    """Unfold a straight path into [low, high] by walking it bounce by bounce (not the closed form)."""
    out = []
    for v in np.ravel(x):
        while v > high or v < low:
            v = 2 * high - v if v > high else 2 * low - v
        out.append(v)
    return np.reshape(out, np.shape(x))
