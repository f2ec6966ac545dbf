"""MLP policy, value and twin-Q networks (flax.linen).

The paper trains 3x256 networks (4x256 for absolute control and reach-avoid) with Brax's defaults:
swish activations, LeCun-uniform kernels and zero biases; those are our defaults too.
"""

from __future__ import annotations

import dataclasses
import numbers
from typing import Callable, Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp

from envs import validation

ACTIVATIONS: dict[str, Callable[[jax.Array], jax.Array]] = {
    "swish": nn.swish,
    "relu": nn.relu,
    "tanh": nn.tanh,
    "elu": nn.elu,
    "gelu": nn.gelu,
}
KERNEL_INITS = ("lecun_uniform", "orthogonal", "glorot_uniform")
COMPUTE_DTYPES = {"float32": jnp.float32, "bfloat16": jnp.bfloat16}
"""Dtypes of the hidden layers' matmuls and activations; parameters and the output layer stay float32."""


def kernel_init(name: str, scale: float = 1.0):
    """Kernel initialiser by name; `scale` multiplies the weights of that layer."""
    if name == "lecun_uniform":
        return nn.initializers.variance_scaling(scale**2, "fan_in", "uniform")
    if name == "glorot_uniform":
        return nn.initializers.variance_scaling(scale**2, "fan_avg", "uniform")
    if name == "orthogonal":
        return nn.initializers.orthogonal(scale)
    raise ValueError(f"kernel_init={name!r} is unknown: allowed are {', '.join(KERNEL_INITS)}.")


class MLP(nn.Module):
    """Dense layers with an activation between them; the last layer is linear."""

    hidden_sizes: Sequence[int]
    out_size: int
    activation: str = "swish"
    kernel_init: str = "lecun_uniform"
    layer_norm: bool = False
    out_scale: float = 1.0
    """Weight scale of the output layer (e.g. 0.01 for a near-uniform initial policy)."""
    dtype: str = "float32"
    """Compute dtype of the hidden layers (`COMPUTE_DTYPES`): bfloat16 runs their matmuls on bf16 tensor cores;
    the parameters and the output layer stay float32, as do the losses and the optimiser state."""

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        act = ACTIVATIONS[self.activation]
        dtype = COMPUTE_DTYPES[self.dtype]
        for i, size in enumerate(self.hidden_sizes):
            x = nn.Dense(size, kernel_init=kernel_init(self.kernel_init), dtype=dtype, name=f"hidden_{i}")(x)
            if self.layer_norm:
                x = nn.LayerNorm(dtype=dtype, name=f"norm_{i}")(x)
            x = act(x)
        # The output layer in float32: values and logits keep full precision for the losses.
        return nn.Dense(self.out_size, kernel_init=kernel_init(self.kernel_init, self.out_scale), dtype=jnp.float32,
                        name="out")(x)


class TwinQ(nn.Module):
    """Two independent Q(s, a) MLPs; returns shape (..., 2), or (..., 2, out_size) with out_size > 1
    (the logits of a categorical return distribution per critic)."""

    hidden_sizes: Sequence[int]
    activation: str = "swish"
    kernel_init: str = "lecun_uniform"
    layer_norm: bool = False
    out_size: int = 1
    dtype: str = "float32"
    """Compute dtype of both critics (see `MLP.dtype`)."""
    stacked: bool = False
    """Both critics as one `nn.vmap` of the MLP, every parameter with a leading axis of 2 (parameters `q`, not `q0` and
    `q1`): the same two functions, but one batched matrix product, normalisation and activation per layer for both,
    so a GPU runs half the kernels of the critics' layers."""

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array) -> jax.Array:
        x = jnp.concatenate([obs, action], axis=-1)
        if self.stacked:
            pair = nn.vmap(MLP, variable_axes={"params": 0}, split_rngs={"params": True}, in_axes=None, out_axes=-2,
                           axis_size=2)
            q = pair(self.hidden_sizes, self.out_size, self.activation, self.kernel_init, self.layer_norm,
                     dtype=self.dtype, name="q")(x)  # (..., 2, out_size)
            return q[..., 0] if self.out_size == 1 else q
        qs = [
            MLP(self.hidden_sizes, self.out_size, self.activation, self.kernel_init, self.layer_norm, dtype=self.dtype,
                name=f"q{i}")(x)
            for i in range(2)
        ]
        if self.out_size == 1:
            return jnp.concatenate(qs, axis=-1)
        return jnp.stack(qs, axis=-2)


def policy_network(action_size: int, hidden_sizes, activation="swish", init="lecun_uniform", layer_norm=False,
                   dtype="float32") -> MLP:
    """Outputs 2 * action_size numbers: the mean and the raw scale of a `TanhNormal`."""
    return MLP(tuple(hidden_sizes), 2 * action_size, activation, init, layer_norm, dtype=dtype)


def value_network(hidden_sizes, activation="swish", init="lecun_uniform", layer_norm=False) -> MLP:
    """Outputs one number per observation (squeeze the last axis)."""
    return MLP(tuple(hidden_sizes), 1, activation, init, layer_norm)


def q_network(hidden_sizes, activation="swish", init="lecun_uniform", layer_norm=False, out_size=1,
              dtype="float32", stacked=False) -> TwinQ:
    return TwinQ(tuple(hidden_sizes), activation, init, layer_norm, out_size, dtype, stacked)


def unstack_twin_params(params):
    """The parameters of a stacked `TwinQ` (`q`, leading axis 2) as those of the separate one (`q0`, `q1`)."""
    stacked = params["params"]["q"]
    return {"params": {f"q{i}": jax.tree.map(lambda x, i=i: x[i], stacked) for i in range(2)}}


def validate_network_fields(hidden_field: str, hidden_sizes, activation: str, init: str, prefix: str = "algo.") -> None:
    """ValueErrors naming the offending config field (`hidden_field` names the layer-size field)."""
    if len(hidden_sizes) == 0 or any(not isinstance(h, numbers.Integral) or h < 1 for h in hidden_sizes):
        raise ValueError(f"{prefix}{hidden_field}={tuple(hidden_sizes)!r} is invalid: allowed is a non-empty tuple of integers >= 1.")
    validation.choice(prefix + "activation", activation, tuple(ACTIVATIONS))
    validation.choice(prefix + "kernel_init", init, KERNEL_INITS)


@dataclasses.dataclass(frozen=True)
class NetworkConfig:
    """The network fields PPO's and SAC's configs share (`agents.ppo.PPOConfig`, `agents.sac.SACConfig` inherit
    them; each adds the hidden sizes of its second network)."""

    min_std: float = 1e-3
    """Lower bound of the policy's pre-squash standard deviation."""
    policy_hidden_sizes: tuple[int, ...] = (256, 256, 256)
    """Hidden layer widths of the policy (paper: 3x256; 4x256 for absolute control / reach-avoid)."""
    activation: str = "swish"
    """Hidden activation: swish, relu, tanh, elu or gelu."""
    kernel_init: str = "lecun_uniform"
    """Weight initialiser: lecun_uniform, orthogonal or glorot_uniform."""
    layer_norm: bool = False
    """LayerNorm after each hidden layer (of every network)."""

    def validate_networks(self, other_hidden_field: str) -> None:
        """ValueErrors naming the field: the policy's and the other network's sizes (`other_hidden_field`), the
        activation, the initialiser and min_std."""
        validation.positive("algo.min_std", self.min_std)
        for field in ("policy_hidden_sizes", other_hidden_field):
            validate_network_fields(field, getattr(self, field), self.activation, self.kernel_init)
