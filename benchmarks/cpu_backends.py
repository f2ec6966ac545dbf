"""The two physics backends on a CPU: env steps/s and start-up of MJX and native MuJoCo (`envs.physics`).

    python -m benchmarks.cpu_backends --out results/throughput/cpu_backends            # env rates, both backends
    python -m benchmarks.cpu_backends --eval --out results/throughput/cpu_backends     # + eval.py wall-clock

For each env, batch size and backend, one jitted `lax.scan` of env steps with uniform random actions
and auto-reset (`benchmarks.env_throughput.env_rollout`, the GPU benchmark's program): the first call
(building the env, compiling and running it) is timed as start-up, then the median of `--repeats`
timed calls as the rate. MJX gets fewer steps per call (`--mjx-steps`): on a CPU it runs a few env
steps per second. `--bridge` times the Gymnasium bridge (numpy in and out, 16 envs), `--panda-gym` panda-gym's
joint-control reach task if it is installed, `--sb3` Stable-Baselines3's PPO training on each (run those
under `taskset -c 0` for one core). `--eval` also times the README's evaluation commands (`EVAL_COMMANDS`, a fresh
process each, shipped 5-seed checkpoints, 64 envs) on the default backend (native on a CPU).
Writes `<out>.json` (every number, the machine, versions, command) and `<out>.md` (a table).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shlex
import statistics
import subprocess
import sys
import time

import jax
import mujoco

from agents import provenance
from benchmarks.env_throughput import env_rollout
from envs import native

EVAL_COMMANDS = (
    "eval.py --checkpoint results/checkpoints/ur5e-reach-ppo --num-envs 64",
    "eval.py --checkpoint results/checkpoints/panda-reach-avoid-ppo --num-envs 64",
    "eval.py --checkpoint results/checkpoints/ur5e-reach-ppo --num-envs 64 --seeds 5",
    "eval.py --checkpoint results/checkpoints/panda-reach-avoid-ppo --num-envs 64 --seeds 5",
)
"""Evaluations of shipped checkpoints (ur5e-reach-ppo holds 5 trained seeds, panda-reach-avoid-ppo 1), with
1 and 5 eval seeds, each timed in a fresh process (start-up included)."""


def cpu_name() -> str:
    """The CPU's model name (Linux), else the platform's processor string."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def measure(name: str, num_envs: int, backend: str, steps: int, repeats: int) -> dict:
    """Start-up (build, compile, first call) and env steps/s of one env on one backend."""
    start = time.perf_counter()
    fn, (state, key) = env_rollout(name, num_envs, steps, options={"backend": backend})
    state = jax.block_until_ready(fn(state, key))
    startup = time.perf_counter() - start
    times = []
    for i in range(repeats):
        t0 = time.perf_counter()
        state = jax.block_until_ready(fn(state, jax.random.PRNGKey(i + 2)))
        times.append(time.perf_counter() - t0)
    return {"env": name, "num_envs": num_envs, "backend": backend, "steps_per_call": steps,
            "startup_s": round(startup, 2), "env_steps_per_s": num_envs * steps / statistics.median(times)}


def bridge_rate(name: str, num_envs: int, steps: int) -> dict:
    """Env steps/s through the Gymnasium bridge (`envs.gymnasium.make_vec`, numpy in and out, random
    actions): what a torch learner sees, on the default backend."""
    from envs import gymnasium as eg

    vec = eg.make_vec(name, num_envs=num_envs)
    vec.reset(seed=0)
    actions = [vec.action_space.sample() for _ in range(steps)]
    vec.step(actions[0])  # compile
    t0 = time.perf_counter()
    for a in actions:
        vec.step(a)
    seconds = time.perf_counter() - t0
    return {"env": name, "num_envs": num_envs, "backend": vec.env.backend,
            "env_steps_per_s": num_envs * steps / seconds}


def panda_gym_rate(steps: int) -> dict | None:
    """Env steps/s of panda-gym's joint-control reach task (PyBullet; one env, random actions, resets at
    episode ends), for comparison with the bridge; None if panda-gym is not installed."""
    try:
        import gymnasium
        import panda_gym  # noqa: F401  (registers the Panda tasks)
    except ImportError:
        return None
    env = gymnasium.make("PandaReachJoints-v3")
    env.reset(seed=0)
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    seconds = time.perf_counter() - t0
    env.close()
    return {"env": "panda-gym PandaReachJoints-v3", "num_envs": 1, "env_steps_per_s": steps / seconds}


def sb3_ppo_rate(which: str, num_envs: int = 16, rollouts: int = 3) -> dict | None:
    """Env steps/s of Stable-Baselines3's PPO (128-step rollouts, 4 epochs of 256-sample minibatches) training
    on `which`: "bridge" (our panda-reach through `envs.gymnasium.to_sb3`) or "panda-gym"
    (PandaReachJoints-v3 in SB3's DummyVecEnv); None if SB3 (or panda-gym) is missing. The same learner on
    both, so the difference is the env's cost."""
    try:
        import stable_baselines3 as sb3
        from stable_baselines3.common.env_util import make_vec_env
        if which == "panda-gym":
            import panda_gym  # noqa: F401
    except ImportError:
        return None
    if which == "bridge":
        from envs import gymnasium as eg
        venv, policy, name = eg.to_sb3(eg.make_vec("panda-reach", num_envs=num_envs)), "MlpPolicy", "panda-reach (bridge)"
    else:
        venv, policy, name = make_vec_env("PandaReachJoints-v3", n_envs=num_envs), "MultiInputPolicy", "panda-gym PandaReachJoints-v3"
    model = sb3.PPO(policy, venv, n_steps=128, batch_size=256, n_epochs=4, device="cpu", seed=0)
    model.learn(num_envs * 128)  # warm-up (and our env's compilation)
    t0 = time.perf_counter()
    model.learn(num_envs * 128 * rollouts, reset_num_timesteps=False)
    seconds = time.perf_counter() - t0
    venv.close()
    return {"env": f"SB3 PPO on {name}", "num_envs": num_envs, "env_steps_per_s": num_envs * 128 * rollouts / seconds}


def time_command(command: str) -> dict:
    """Wall-clock of `python <command>` in a fresh process from the repository root."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable] + shlex.split(command), cwd=root, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"python {command} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    return {"command": "python " + command, "wall_s": round(seconds, 1), "table": done.stdout.strip()}


def markdown(report: dict) -> str:
    rows = ["| env | envs | MJX env steps/s | native env steps/s | native / MJX | MJX start-up (s) | native start-up (s) |",
            "|---|---:|---:|---:|---:|---:|---:|"]
    by_key = {(r["env"], r["num_envs"], r["backend"]): r for r in report["rates"]}
    for (env, n, backend), r in by_key.items():
        if backend != "mujoco":
            continue
        m = by_key.get((env, n, "mjx"))
        ratio = f"{r['env_steps_per_s'] / m['env_steps_per_s']:.0f}x" if m else ""
        rows.append(f"| {env} | {n} | {m['env_steps_per_s']:,.1f} | {r['env_steps_per_s']:,.0f} | {ratio} | "
                    f"{m['startup_s']:.0f} | {r['startup_s']:.1f} |" if m else
                    f"| {env} | {n} |  | {r['env_steps_per_s']:,.0f} |  |  | {r['startup_s']:.1f} |")
    text = "\n".join(rows)
    for b in report.get("bridge", []):
        what = b["env"] if b["env"].startswith(("panda-gym", "SB3")) else f"Gymnasium bridge, {b['env']}"
        how = "training" if b["env"].startswith("SB3") else "random actions"
        text += f"\n\n{what}, {b['num_envs']} env(s), {how}: {b['env_steps_per_s']:,.0f} env steps/s"
    for e in report.get("eval", []):
        text += f"\n\n`{e['command']}`: {e['wall_s']} s wall-clock (fresh process, start-up included)"
    return text + f"\n\n{report['machine']}; jax {report['jax']}, mujoco {report['mujoco']}; {report['date']}\n"


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.cpu_backends", description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=["ur5e-reach", "panda-reach"])
    parser.add_argument("--sizes", nargs="+", type=int, default=[8, 64])
    parser.add_argument("--backends", nargs="+", default=["mjx", "mujoco"], choices=["mjx", "mujoco"])
    parser.add_argument("--steps", type=int, default=125, help="env steps per timed call (native)")
    parser.add_argument("--mjx-steps", type=int, default=4, help="env steps per timed call (MJX)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--eval", action="store_true", help="also time EVAL_COMMANDS")
    parser.add_argument("--bridge", action="store_true", help="also time the Gymnasium bridge (16 envs, random actions)")
    parser.add_argument("--panda-gym", action="store_true", help="also time panda-gym's PandaReachJoints-v3 (if installed)")
    parser.add_argument("--sb3", action="store_true", help="also time SB3's PPO on the bridge and on panda-gym")
    parser.add_argument("--out", default="results/throughput/cpu_backends", help="output path without extension")
    args = parser.parse_args(argv)
    for name, value in (("steps", args.steps), ("mjx-steps", args.mjx_steps), ("repeats", args.repeats)):
        if value < 1:
            raise SystemExit(f"error: --{name}={value} is invalid: allowed is an integer >= 1.")

    report = {
        "machine": f"{cpu_name()}, {native.num_threads()} cores usable, {platform.system()}",
        "jax": jax.__version__, "mujoco": mujoco.__version__, "python": platform.python_version(),
        "jax_device": jax.devices()[0].platform,
        "device": provenance.device_description(),
        "date": datetime.date.today().isoformat(),
        "command": "python -m benchmarks.cpu_backends " + " ".join(shlex.quote(a) for a in (argv or sys.argv[1:])),
        "code": provenance.code_version(),
        "rates": [], "eval": [], "bridge": [],
    }
    for name in args.envs:
        for n in args.sizes:
            for backend in args.backends:
                steps = args.mjx_steps if backend == "mjx" else args.steps
                row = measure(name, n, backend, steps, args.repeats)
                report["rates"].append(row)
                print(f"{name:18s} {n:5d} envs  {backend:6s}  {row['env_steps_per_s']:10,.1f} env steps/s  "
                      f"start-up {row['startup_s']:.1f} s", flush=True)
    if args.bridge:
        for name in args.envs:
            report["bridge"].append(bridge_rate(name, 16, 200))
            print(f"bridge {name}: {report['bridge'][-1]['env_steps_per_s']:,.0f} env steps/s", flush=True)
    if args.panda_gym:
        row = panda_gym_rate(2000)
        if row is None:
            print("panda-gym is not installed: skipped", flush=True)
        else:
            report["bridge"].append(row)
            print(f"{row['env']}: {row['env_steps_per_s']:,.0f} env steps/s", flush=True)
    if args.sb3:
        for which in ("bridge", "panda-gym"):
            row = sb3_ppo_rate(which)
            if row is None:
                print(f"SB3 PPO on {which}: stable-baselines3 or panda-gym missing, skipped", flush=True)
            else:
                report["bridge"].append(row)
                print(f"{row['env']}: {row['env_steps_per_s']:,.0f} env steps/s", flush=True)
    if args.eval:
        for command in EVAL_COMMANDS:
            report["eval"].append(time_command(command))
            print(f"{command}: {report['eval'][-1]['wall_s']} s", flush=True)
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out + ".json", "w") as f:
        json.dump(report, f, indent=2)
    with open(args.out + ".md", "w") as f:
        f.write(markdown(report))
    print(markdown(report))


if __name__ == "__main__":
    main()
