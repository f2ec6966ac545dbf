"""The paper's tables, regenerated: markdown (and JSON with every number) under results/.

    # Baselines (no checkpoints needed), both robots, 1 and 2 cm targets, absolute and relative control:
    python -m tools.paper_tables --tables baselines --num-envs 4096 --seeds 5
    # Tables from trained runs (train.py logdirs, checkpoint step dirs or policy exports; several
    # comma-separated paths per role are pooled, e.g. one run per seed):
    python -m tools.paper_tables --tables action workspace obstacle \\
        --action relative=runs/rel absolute=runs/abs \\
        --workspace pandagym=runs/wp front=runs/wf upper=runs/wu full=runs/wl full-range=runs/wr \\
        --obstacle 0.025=runs/o1 0.05=runs/o2 0.1=runs/o3 0.2=runs/o4 0.3=runs/o5 reach=runs/reach

Tables (paper section in brackets):
- `baselines` ["Baselines", Table "reaching baselines"]: random, standstill, pseudo-IK on `<robot>-reach`
  (full workspace), target radius 0.01 and 0.02 m, in both action modes (the paper does not say
  which mode its baselines used; absolute control's match its numbers: results, baselines study). Rates are means
  over evaluation seeds (± std over seeds); the distance is mean ± std over all episodes, as in
  the paper's table.
- `action` ["Action space", precision table]: distance, steps in target, times left target of a
  relative- and an absolute-control agent, each on its own training env config.
- `workspace` ["Influence of the workspace size", cross-evaluation table]: the paper's 13 (trained,
  evaluated) pairs. An evaluation workspace's setting (fields `workspace`, `target_sampling`,
  `init_range`) is that of the checkpoint trained on it when given, else `WORKSPACE_DEFAULTS`;
  everything else (action mode, observation, ...) is the evaluated checkpoint's own. The paper's
  "Full" agent was trained with the limited initial joint range and "Full Range" with the full one.
- `obstacle` ["Influence of the obstacle size", cross-evaluation table]: reach-avoid agents trained
  with one obstacle radius evaluated on others, and a reach agent on `<robot>-reach-avoid` (its own
  observation; target radius that of the reach-avoid checkpoints, else the reach-avoid default).

A table whose checkpoints are not given is skipped with a message; no number is ever filled in
from anywhere but an evaluation run here. Each file states the checkpoints, seeds, env counts,
device and the command that made it.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shlex
import sys

import envs
from agents import evaluation, provenance
from tools import run_cli

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

TABLES = ("baselines", "action", "workspace", "obstacle")
WORKSPACE_ROLES = ("pandagym", "front", "upper", "full", "full-range")
WORKSPACE_NAMES = {"pandagym": "PandaGym", "front": "Front", "upper": "Upper", "full": "Full", "full-range": "Full Range"}
"""The paper's names of the workspace roles (its workspace table), for every table that shows them."""
WORKSPACE_DEFAULTS = {
    "pandagym": dict(workspace="pandagym", target_sampling="uniform", init_range="limited"),
    "front": dict(workspace="front", target_sampling="reachable", init_range="limited"),
    "upper": dict(workspace="upper", target_sampling="reachable", init_range="limited"),
    "full": dict(workspace="full", target_sampling="reachable", init_range="limited"),
    "full-range": dict(workspace="full", target_sampling="reachable", init_range="full"),
}
"""Evaluation settings of a workspace whose own checkpoint is not given (paper: the workspace
experiments start from the limited initial range, except "Full Range")."""
WORKSPACE_FIELDS = ("workspace", "target_sampling", "init_range")
WORKSPACE_PAIRS = [  # the paper's rows, in its order
    ("pandagym", "pandagym"), ("front", "front"), ("upper", "upper"), ("full", "full"), ("full-range", "full-range"),
    ("pandagym", "front"), ("pandagym", "full"), ("front", "full"), ("upper", "full"),
    ("front", "pandagym"), ("full", "pandagym"), ("full", "upper"),
    ("full", "full-range"),
]
OBSTACLE_SIZES = ("0.025", "0.05", "0.1", "0.2", "0.3")
OBSTACLE_ROLES = OBSTACLE_SIZES + ("reach",)


def _roles(items: list[str] | None, allowed, option: str) -> dict[str, list[str]]:
    out = {}
    for item in items or []:
        role, sep, paths = item.partition("=")
        if not sep or not paths:
            raise ValueError(f"{option} {item!r} is invalid: allowed is ROLE=PATH[,PATH...] with ROLE one of {', '.join(allowed)}.")
        if role not in allowed:
            raise ValueError(f"{option} role {role!r} is unknown: allowed are {', '.join(allowed)}.")
        out[role] = [p for p in paths.split(",") if p]
    return out


class Writer:
    """Collects one table's text and JSON and writes them under `out`."""

    def __init__(self, out: str, name: str, title: str, command: str, note: str = ""):
        self.out, self.name = out, name
        self.lines = [f"# {title}", "", note, ""] if note else [f"# {title}", ""]
        self.data = {"table": name, "command": command, "device": provenance.device_description(),
                     "code": provenance.code_version(), "date": datetime.date.today().isoformat(), "rows": []}
        self.command = command

    def table(self, header: list[str], rows: list[list[str]]) -> None:
        self.lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        self.lines += ["| " + " | ".join(r) + " |" for r in rows]
        self.lines.append("")

    def add(self, row: dict) -> None:
        self.data["rows"].append(row)

    def write(self, provenance: list[str]) -> str:
        self.lines += ["Provenance:", ""] + [f"- {p}" for p in provenance]
        import jax

        self.data["jax"] = jax.__version__
        self.lines += [f"- device: {self.data['device']}; jax {jax.__version__}; code {self.data['code']}; "
                       f"date {self.data['date']}",
                       f"- command: `{self.command}`", ""]
        os.makedirs(self.out, exist_ok=True)
        path = os.path.join(self.out, f"{self.name}.md")
        with open(path, "w") as f:
            f.write("\n".join(self.lines))
        with open(os.path.join(self.out, f"{self.name}.json"), "w") as f:
            json.dump(evaluation.jsonable(self.data), f, indent=2, allow_nan=False)
        print(f"wrote {path}", file=sys.stderr)
        return path


def _row_json(result, **labels) -> dict:
    return {**labels, **result.to_json()}


def _pooled_summary(results):
    if len(results) == 1:
        return results[0].summary()
    return evaluation.pooled(results)


def _units(results) -> str:
    return f"{sum(len(r.units) for r in results)} x {results[0].num_envs}"


def _progress(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _indented(text: str) -> None:
    _progress("  " + text)


# ------------------------------------------------------------------------------------------------


def baselines_table(args, command: str) -> str:
    w = Writer(args.out, args.name or "baselines", "Baselines on the reach task (paper, Table \"reaching baselines\")", command,
               "Full workspace, reachable targets, 125-step episodes, the env defaults otherwise. Rates: mean over "
               "evaluation seeds (± std over seeds when several); distance: mean ± std over all episodes (the paper's "
               "format); every baseline in both action modes (`agents/baselines.py` says what each means). "
               "\"distance, collided = 0\" counts episodes that ended in a collision as 0 m (what an evaluator that "
               "sums the last steps' distances over active steps reports; it matches the paper's pseudo-IK distance).")
    provenance = []
    for robot in args.robots:
        num_envs = args.panda_num_envs if robot == "panda" and args.panda_num_envs else args.num_envs
        seeds = args.panda_seeds if robot == "panda" and args.panda_seeds else args.seeds
        eval_seeds = [args.seed + i for i in range(seeds)]
        rows = []
        for radius in args.radii:
            for action in args.actions:
                config = envs.make_config(f"{robot}-reach", target_radius=radius, action=action, **args.env_overrides)
                for name in ("random", "standstill", "pseudo_ik"):
                    _progress(f"baselines: {robot} {name} {action} target {radius} ({seeds} x {num_envs} envs)")
                    r = evaluation.run(evaluation.baseline_policy(name), f"{robot}-reach", config, num_envs, eval_seeds,
                                       progress=_indented)
                    s = r.summary()
                    rows.append([{"random": "Random", "standstill": "Standstill", "pseudo_ik": "Pseudo IK"}[name], action,
                                 f"{radius:.2f} m", evaluation.fmt(s.get("target_reached"), 3),
                                 evaluation.fmt(s.get("self_collision"), 3),
                                 evaluation.fmt(s.get("distance"), 3, "std_episodes") + " m",
                                 evaluation.fmt(s.get("distance_collided_as_0"), 3, "std_episodes") + " m",
                                 evaluation.fmt(s.get("steps_in_target"), 1), evaluation.fmt(s.get("times_left_target"), 2)])
                    w.add(_row_json(r, robot=robot, agent=name, action=action, target_radius=radius))
        w.lines += [f"## {robot.upper() if robot == 'ur5e' else robot.capitalize()} ({seeds} seed{'s' if seeds > 1 else ''} x {num_envs} envs)", ""]
        if args.env_overrides:
            w.lines += [f"Env options replaced: {args.env_overrides}.", ""]
        w.table(["agent", "action mode", "target size", "target reached", "self collision", "distance to target",
                 "distance, collided = 0", "steps in target", "times left target"], rows)
        provenance.append(f"{robot}: {seeds} evaluation seed{'s' if seeds > 1 else ''} (from {eval_seeds[0]}) x {num_envs} envs per row")
    return w.write(provenance)


def action_table(args, command: str) -> str | None:
    roles = _roles(args.action, ("relative", "absolute"), "--action")
    if not roles:
        _progress("skipped table 'action': no --action relative=RUN absolute=RUN given.")
        return None
    w = Writer(args.out, "action_space", "Precision of relative vs absolute position control (paper, action-space table)",
               command, "Each agent on its own training env config; mean ± std over trained seeds / checkpoints.")
    rows, provenance = [], []
    for role in ("absolute", "relative"):
        if role not in roles:
            _progress(f"action table: no '{role}' checkpoint given, row skipped.")
            continue
        results = _evaluate_role(args, roles[role], lambda p: (p.train_env_name, {}))
        s = _pooled_summary(results)
        rows.append([{"absolute": "Position", "relative": "Relative"}[role], _units(results),
                     evaluation.fmt(s.get("distance"), 3), evaluation.fmt(s.get("steps_in_target"), 1),
                     evaluation.fmt(s.get("times_left_target"), 2), evaluation.fmt(s.get("target_reached"), 3)])
        for r in results:
            w.add(_row_json(r, role=role))
        provenance.append(f"{role}: {', '.join(roles[role])}")
    w.table(["control type", "seeds x envs", "distance to target (m)", "steps in target", "times left target",
             "target reached"], rows)
    return w.write(provenance)


def _evaluate_role(args, paths, setting):
    """Evaluates each checkpoint of a role; `setting(policy) -> (env_name, overrides)`."""
    results = []
    eval_seeds = [args.seed + i for i in range(args.seeds)]
    for path in paths:
        policy = evaluation.checkpoint_policy(path)
        env_name, overrides = setting(policy)
        config = envs.make_config(env_name, policy.train_env_config, **{**overrides, **args.env_overrides})
        _progress(f"evaluating {path} on {env_name} {overrides or ''} ({len(policy.units)} x {args.num_envs} envs)")
        results.append(evaluation.run(policy, env_name, config, args.num_envs, eval_seeds, progress=_indented))
    return results


def workspace_table(args, command: str) -> str | None:
    roles = _roles(args.workspace, WORKSPACE_ROLES, "--workspace")
    if not roles:
        _progress("skipped table 'workspace': no --workspace ROLE=RUN given.")
        return None
    settings = {}
    for role in WORKSPACE_ROLES:
        if role in roles:
            cfg = evaluation.checkpoint_policy(roles[role][0]).train_env_config
            settings[role] = {f: getattr(cfg, f) for f in WORKSPACE_FIELDS}
        else:
            settings[role] = WORKSPACE_DEFAULTS[role]
    w = Writer(args.out, "workspace_generalization",
               "Cross-evaluation of workspaces (paper, workspace generalization table)", command,
               "Mean ± std over trained seeds / checkpoints. Evaluation settings (workspace, target sampling, initial "
               "range): " + "; ".join(f"{WORKSPACE_NAMES[r]} = {settings[r]}" for r in WORKSPACE_ROLES) + ".")
    rows, provenance = [], []
    for trained, evaluated in WORKSPACE_PAIRS:
        if trained not in roles:
            continue
        results = _evaluate_role(args, roles[trained], lambda p: (p.train_env_name, settings[evaluated]))
        s = _pooled_summary(results)
        rows.append([WORKSPACE_NAMES[trained], WORKSPACE_NAMES[evaluated], _units(results),
                     evaluation.fmt(s.get("target_reached"), 3), evaluation.fmt(s.get("self_collision"), 3),
                     evaluation.fmt(s.get("distance"), 3) + " m"])
        for r in results:
            w.add(_row_json(r, trained=trained, evaluated=evaluated))
    missing = [WORKSPACE_NAMES[r] for r in WORKSPACE_ROLES if r not in roles]
    if missing:
        _progress(f"workspace table: no checkpoint for {', '.join(missing)}: their rows as trained workspace are skipped.")
    w.table(["training workspace", "evaluation workspace", "seeds x envs", "target reached", "self collision",
             "distance to target"], rows)
    provenance += [f"{WORKSPACE_NAMES[r]}: {', '.join(p)}" for r, p in roles.items()]
    return w.write(provenance)


def obstacle_table(args, command: str) -> str | None:
    roles = _roles(args.obstacle, OBSTACLE_ROLES, "--obstacle")
    if not roles:
        _progress("skipped table 'obstacle': no --obstacle SIZE=RUN given.")
        return None
    sized = [r for r in OBSTACLE_SIZES if r in roles]
    target_radius = None
    if sized:
        target_radius = evaluation.checkpoint_policy(roles[sized[0]][0]).train_env_config.target_radius
    w = Writer(args.out, "obstacle_size", "Cross-evaluation of obstacle sizes (paper, obstacle-size table)", command,
               "Reach-avoid agents trained with one obstacle radius (m) evaluated with others; `reach` is a reach agent "
               "on the reach-avoid env. Mean ± std over trained seeds / checkpoints.")
    rows, provenance = [], []

    def row(trained, size):
        def setting(policy):
            robot = envs.registry.spec(policy.train_env_name).robot
            if robot is None:
                raise ValueError(f"--obstacle {trained}={policy.name} is invalid: it was trained on {policy.train_env_name!r}, "
                                 "which has no robot; allowed are arm checkpoints (evaluated on their robot's reach-avoid env).")
            env_name = f"{robot}-reach-avoid"
            overrides = {"obstacle_radius": float(size)}
            if trained == "reach":
                overrides["target_radius"] = target_radius or envs.default_config(env_name).target_radius
            return env_name, overrides

        results = _evaluate_role(args, roles[trained], setting)
        s = _pooled_summary(results)
        rows.append([trained, size, _units(results), evaluation.fmt(s.get("target_reached"), 3),
                     evaluation.fmt(s.get("self_collision"), 3), evaluation.fmt(s.get("obstacle_collision"), 3)])
        for r in results:
            w.add(_row_json(r, trained=trained, evaluated=float(size)))

    for size in sized:
        row(size, size)
    for size in sized:
        if size != "0.1":
            row(size, "0.1")
    if "reach" in roles:
        for size in OBSTACLE_SIZES:
            row("reach", size)
    w.table(["trained size", "evaluated size", "seeds x envs", "target reached", "self collision",
             "obstacle collision"], rows)
    provenance += [f"{r}: {', '.join(p)}" for r, p in roles.items()]
    return w.write(provenance)


def parse(argv):
    p = argparse.ArgumentParser(prog="python -m tools.paper_tables", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter, allow_abbrev=False)
    p.add_argument("--tables", nargs="+", choices=TABLES, default=list(TABLES), help="tables to make (default: all)")
    p.add_argument("--out", default=os.path.join(ROOT, "results"), help="output directory (default results/)")
    p.add_argument("--num-envs", type=int, default=4096, help="envs per evaluation seed (default 4096)")
    p.add_argument("--seeds", type=int, default=1,
                   help="evaluation seeds (default 1; baselines: use 5, the paper's seed count)")
    p.add_argument("--seed", type=int, default=evaluation.DEFAULT_EVAL_SEED, help="first evaluation seed")
    p.add_argument("--robots", nargs="+", choices=list(envs.ROBOTS), default=list(envs.ROBOTS), help="baselines: robots")
    p.add_argument("--panda-num-envs", type=int, default=0, help="baselines: envs for the Panda (default: --num-envs)")
    p.add_argument("--panda-seeds", type=int, default=0, help="baselines: seeds for the Panda (default: --seeds)")
    p.add_argument("--actions", nargs="+", choices=("absolute", "relative"), default=["absolute", "relative"],
                   help="baselines: action modes (default both)")
    p.add_argument("--radii", nargs="+", type=float, default=[0.01, 0.02], help="baselines: target radii (m)")
    p.add_argument("--name", default="", help="baselines: output file name without extension (default baselines)")
    p.add_argument("--env-option", nargs="+", default=[], metavar="FIELD=VALUE",
                   help="env config fields replaced in every evaluation (values as JSON, else strings), e.g. "
                        "substeps=2 for a smoke test (changes the numbers)")
    p.add_argument("--action", nargs="+", metavar="ROLE=PATH", help="relative=RUN absolute=RUN")
    p.add_argument("--workspace", nargs="+", metavar="ROLE=PATH", help="ROLE in " + ", ".join(WORKSPACE_ROLES))
    p.add_argument("--obstacle", nargs="+", metavar="ROLE=PATH", help="ROLE in " + ", ".join(OBSTACLE_ROLES))
    args = p.parse_args(argv)
    for name in ("num_envs", "seeds"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')}={getattr(args, name)} is invalid: allowed is an integer >= 1.")
    args.env_overrides = {}
    for item in args.env_option:
        field, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--env-option {item!r} is invalid: allowed is FIELD=VALUE.")
        try:
            args.env_overrides[field] = json.loads(value)
        except json.JSONDecodeError:
            args.env_overrides[field] = value
    return args


def main(argv=None) -> list[str]:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse(argv)
    command = "python -m tools.paper_tables " + " ".join(shlex.quote(a) for a in argv)
    makers = {"baselines": baselines_table, "action": action_table, "workspace": workspace_table,
              "obstacle": obstacle_table}
    written = []
    for table in args.tables:
        path = makers[table](args, command)
        if path:
            written.append(path)
    return written


if __name__ == "__main__":
    run_cli(main)
