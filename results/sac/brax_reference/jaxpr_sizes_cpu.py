"""The traced size of one env step of 128 UR5e reach envs under our training wrappers and under Brax's
(`brax.envs.training.wrap`, as benchmarks/brax_reference.py gives Brax), on the CPU with MJX physics and
fast_mjx's GPU path forced: equations in each program and in each of its loops (path, length, equations).

    python results/sac/brax_reference/jaxpr_sizes_cpu.py > results/sac/brax_reference/jaxpr_sizes_cpu.txt
"""

import dataclasses

import jax
import jax.numpy as jnp
from brax.envs import training as brax_training

import envs
from agents import presets

SUBJAXPRS = ("body_jaxpr", "jaxpr", "cond_jaxpr", "branches", "call_jaxpr", "fun_jaxpr")


def sub_jaxprs(eqn):
    for param in SUBJAXPRS:
        value = eqn.params.get(param)
        for item in value if isinstance(value, (list, tuple)) else [value]:
            inner = getattr(item, "jaxpr", item)
            if hasattr(inner, "eqns"):
                yield param, inner


def size(jaxpr) -> int:
    return sum(1 + sum(size(inner) for _, inner in sub_jaxprs(e)) for e in jaxpr.eqns)


def loops(jaxpr, path=""):
    found = []
    for e in jaxpr.eqns:
        for param, inner in sub_jaxprs(e):
            if e.primitive.name in ("while", "scan") and param in ("body_jaxpr", "jaxpr"):
                found.append((f"{path}/{e.primitive.name}", e.params.get("length"), size(inner)))
            found += loops(inner, f"{path}/{e.primitive.name}")
    return found


def main():
    config = presets.make_config("ur5e-reach-sac", progress=False, tensorboard=False)
    env = envs.from_config(config.env_name, dataclasses.replace(config.env, backend="mjx"))
    jax.default_backend = lambda: "gpu"  # envs.fast_mjx switches on by the backend at trace time
    keys = jax.random.split(jax.random.PRNGKey(0), 128)
    actions = jnp.zeros((128, env.action_size))
    for name, wrapped in (("ours (envs.wrap)", envs.wrap(env)),
                          ("Brax (brax.envs.training.wrap)", brax_training.wrap(env, config.env.episode_length))):
        jaxpr = jax.make_jaxpr(wrapped.step)(jax.eval_shape(wrapped.reset, keys), actions).jaxpr
        print(f"{name}: {size(jaxpr):,} equations; loops (path, length, equations):")
        for loop in sorted(loops(jaxpr), key=lambda x: -x[2]):
            print(f"  {loop}")


if __name__ == "__main__":
    main()
