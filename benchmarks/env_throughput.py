"""Environment throughput: env steps/s with random actions and auto-resets, next to the MJX
physics ceiling of the same robot model measured in the same run.

    python -m benchmarks.env_throughput --out results/throughput/env_throughput   # on the GPU machine

For each environment and batch size, one jitted `lax.scan` runs `--steps` environment steps of
the fully wrapped environment (episode limit, fresh auto-reset, vmap) with uniform random
actions. The ceiling is the robot's own MJCF (contacts disabled, as the envs use it) stepped with
`mjx.step` in a `lax.scan`, `substeps` physics steps per env step with random controls: no
policy, no collision checks, no observations, rewards or resets. Timing: compile and one warm-up
call first, then the median of `--repeats` timed calls, each ended by `block_until_ready`.
Writes `<out>.json` (every number plus device, versions, command) and `<out>.md` (a table).

`--variants` times each reach-avoid env once per named option set (`VARIANTS`: the paper's one
static obstacle, 3 static, 3 moving, and 3 moving with the predicted link distances observed) in the
same run, each row with its fraction of the paper variant's rate at that size (list `paper` first;
results/obstacles):

    python -m benchmarks.env_throughput --envs ur5e-reach-avoid panda-reach-avoid --sizes 8192 \
        --variants paper 3-static 3-moving 3-moving-ahead 3-moving-ahead-moving --out results/throughput/obstacles
"""

from __future__ import annotations

import argparse
import datetime
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import agents  # noqa: F401  (first: the project's XLA settings, agents/xla_flags.py, as in training)
import jax
import mujoco
from mujoco import mjx

import envs
from agents import provenance
from agents.presets import MOVING_OBSTACLES_3
from envs.fast_mjx import fast_mjx
from envs.robots import ROBOTS

_AHEAD = MOVING_OBSTACLES_3["observation"] + ("link_obstacle_ahead",)
VARIANTS = {"paper": {}, "3-static": dict(num_obstacles=3), "3-moving": MOVING_OBSTACLES_3,
            "3-moving-ahead": dict(MOVING_OBSTACLES_3, observation=_AHEAD),
            "3-moving-ahead-moving": dict(MOVING_OBSTACLES_3, observation=_AHEAD + ("link_obstacle_ahead_moving",))}
"""Reach-avoid option sets for `--variants` (options beyond the paper's, see `ReachAvoidConfig`); the
moving ones are the `-moving3` presets' obstacle setting, the last two with the link distances predicted with the
arm held still, then also with it moving on (the cost of observing them)."""


def time_calls(fn, args, repeats):
    jax.block_until_ready(fn(*args))  # compile + warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def env_rollout(name, num_envs, steps, substeps=None, auto_reset=True, config=None, options=None):
    """`(fn, args)`: a jitted `lax.scan` of `steps` env steps with uniform random actions, and its
    arguments. The env is `envs.from_config(name, config)` when `config` is given (a training preset's
    env, say), else the registry's default for `name` with `substeps` and `options` overridden."""
    if config is not None:
        env = envs.from_config(name, config)
    else:
        # MJX unless `options` name another backend: the ceiling beside it is MJX's (benchmarks.cpu_backends
        # compares the backends on a CPU).
        options = {"backend": "mjx", **(options or {})}
        env = envs.make(name, **options, **({} if substeps is None else {"substeps": substeps}))
    batched = envs.wrap(env) if auto_reset else envs.wrappers.VmapWrapper(env)
    state = jax.jit(batched.reset)(jax.random.split(jax.random.PRNGKey(0), num_envs))

    @jax.jit
    def rollout(state, key):
        def body(state, key):
            action = jax.random.uniform(key, (num_envs, env.action_size), minval=-1.0, maxval=1.0)
            return batched.step(state, action), None

        state, _ = jax.lax.scan(body, state, jax.random.split(key, steps))
        return state

    return rollout, (state, jax.random.PRNGKey(1))


def env_rate(name, num_envs, steps, repeats, substeps=None, auto_reset=True, config=None, options=None):
    """Env steps/s of `env_rollout(...)`: median of `repeats` timed calls after a warm-up."""
    fn, args = env_rollout(name, num_envs, steps, substeps, auto_reset, config, options)
    return num_envs * steps / time_calls(fn, args, repeats)


def ceiling_rate(robot_name, num_envs, steps, repeats, substeps, fast=None):
    """Raw `mjx.step` rate; `fast` as in `envs.fast_mjx.fast_mjx` (None: as the envs step, False:
    MJX as shipped)."""
    robot = ROBOTS[robot_name]()
    model = robot.mjx_model
    low, high = robot.joint_low, robot.joint_high

    def start(key):
        q = jax.random.uniform(key, (robot.nq,), minval=low, maxval=high)
        return robot.data_template.replace(qpos=q, ctrl=q)

    data = jax.jit(jax.vmap(start))(jax.random.split(jax.random.PRNGKey(0), num_envs))

    @jax.jit
    def rollout(data, key):
        def env_step(data, key):
            ctrl = jax.random.uniform(key, (num_envs, robot.nq), minval=low, maxval=high)
            data = data.replace(ctrl=ctrl)

            def physics(d, _):
                return jax.vmap(mjx.step, in_axes=(None, 0))(model, d), None

            data, _ = jax.lax.scan(physics, data, length=substeps)
            return data, None

        with jax.default_matmul_precision("highest"), fast_mjx(fast):
            data, _ = jax.lax.scan(env_step, data, jax.random.split(key, steps))
        return data

    seconds = time_calls(rollout, (data, jax.random.PRNGKey(1)), repeats)
    return num_envs * steps / seconds


def main():
    parser = argparse.ArgumentParser(prog="python -m benchmarks.env_throughput", description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=["ur5e-reach", "ur5e-reach-avoid", "panda-reach", "panda-reach-avoid"])
    parser.add_argument("--sizes", nargs="+", type=int, default=[1024, 8192, 32768])
    parser.add_argument("--steps", type=int, default=100, help="env steps per timed call")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--substeps", type=int, default=20)
    parser.add_argument("--no-reset-variant", action="store_true",
                        help="also time each env without auto-reset (shows what resets cost)")
    parser.add_argument("--stock-ceiling", action="store_true",
                        help="also measure the ceiling of MJX as shipped (without envs.fast_mjx)")
    parser.add_argument("--variants", nargs="+", default=["paper"], choices=list(VARIANTS),
                        help="reach-avoid option sets to time side by side (VARIANTS); reach envs run once")
    parser.add_argument("--out", default="results/throughput/env_throughput", help="output path without extension")
    args = parser.parse_args()

    device = jax.devices()[0]
    meta = {
        "device": device.device_kind, "platform": device.platform, "num_devices": jax.device_count(),
        "jax": jax.__version__, "mujoco": mujoco.__version__, "python": platform.python_version(),
        "date": datetime.date.today().isoformat(),
        "command": " ".join(["python", "-m", "benchmarks.env_throughput"] + sys.argv[1:]),
        "code": provenance.code_version(),
        "substeps": args.substeps, "steps_per_call": args.steps, "repeats": args.repeats,
        "variants": {v: VARIANTS[v] for v in args.variants},
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    robots = sorted({name.split("-")[0] for name in args.envs})
    for size in args.sizes:
        ceilings, stock = {}, {}
        for robot in robots:
            ceilings[robot] = ceiling_rate(robot, size, args.steps, args.repeats, args.substeps)
            print(f"{size:>6} envs  {robot:<18} ceiling {ceilings[robot]:>12,.0f} steps/s", flush=True)
            if args.stock_ceiling:
                stock[robot] = ceiling_rate(robot, size, args.steps, args.repeats, args.substeps, fast=False)
                print(f"{size:>6} envs  {robot:<18} stock MJX ceiling {stock[robot]:>12,.0f} steps/s", flush=True)
        for name in args.envs:
            obstacles = hasattr(envs.default_config(name), "num_obstacles")  # variants are reach-avoid options
            paper_rate = None
            for variant in (args.variants if obstacles else ["paper"]):
                options = VARIANTS[variant]
                rate = env_rate(name, size, args.steps, args.repeats, args.substeps, options=options)
                paper_rate = rate if variant == "paper" else paper_rate
                label = name if variant == "paper" else f"{name} ({variant})"
                row = {"env": name, "variant": variant, "num_envs": size, "steps_per_s": rate,
                       "ceiling_steps_per_s": ceilings[name.split("-")[0]],
                       "fraction_of_ceiling": rate / ceilings[name.split("-")[0]]}
                if paper_rate is not None and variant != "paper":
                    row["fraction_of_paper_variant"] = rate / paper_rate
                if args.stock_ceiling:
                    row["stock_ceiling_steps_per_s"] = stock[name.split("-")[0]]
                if args.no_reset_variant:
                    row["no_reset_steps_per_s"] = env_rate(name, size, args.steps, args.repeats, args.substeps,
                                                           auto_reset=False, options=options)
                rows.append(row)
                print(f"{size:>6} envs  {label:<30} {rate:>12,.0f} steps/s  ({row['fraction_of_ceiling']:.0%} of ceiling)"
                      + (f"  {row['fraction_of_paper_variant']:.0%} of one static obstacle"
                         if "fraction_of_paper_variant" in row else "")
                      + (f"  no reset {row['no_reset_steps_per_s']:,.0f}" if args.no_reset_variant else ""), flush=True)
                write_tables(out, meta, rows, args)  # after every row: a cut-off run keeps what it measured
    print(out.with_suffix(".md").read_text())


def write_tables(out: Path, meta: dict, rows: list, args) -> None:
    out.with_suffix(".json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    extra = (" no auto-reset |" if args.no_reset_variant else "") + (" stock MJX ceiling |" if args.stock_ceiling else "")
    lines = [
        f"# Environment throughput ({meta['device']}, {meta['date']})", "",
        f"Command: `{meta['command']}`  ",
        f"jax {meta['jax']}, mujoco {meta['mujoco']}, {args.substeps} substeps of 2 ms per env step, random actions,"
        " auto-reset with fresh sampling. Ceiling: the same robot model, raw `mjx.step` in `lax.scan`, no env logic,"
        " with the envs' GPU replacements (`envs.fast_mjx`); stock: MJX as shipped.", "",
        f"| env | envs | env steps/s | ceiling steps/s | fraction |{extra}",
        "|---|---:|---:|---:|---:|" + "---:|" * extra.count("|"),
    ]
    for r in rows:
        variant = r.get("variant", "paper")
        if variant != "paper":
            share = f", {r['fraction_of_paper_variant']:.0%} of 1 obstacle" if "fraction_of_paper_variant" in r else ""
            label = f"{r['env']} ({variant}{share})"
        else:
            label = r["env"]
        lines.append(f"| {label} | {r['num_envs']:,} | {r['steps_per_s']:,.0f} | {r['ceiling_steps_per_s']:,.0f} | "
                     f"{r['fraction_of_ceiling']:.0%} |"
                     + (f" {r['no_reset_steps_per_s']:,.0f} |" if args.no_reset_variant else "")
                     + (f" {r['stock_ceiling_steps_per_s']:,.0f} |" if args.stock_ceiling else ""))
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")

if __name__ == "__main__":
    main()
