"""Where the GPU time of a profiled program goes: a text summary of a JAX profiler trace.

    python -m benchmarks.train_throughput --trace traces/      # writes traces/<setting>/...
    python -m benchmarks.trace_summary traces/1dev             # summary of that trace

Reads the `perfetto_trace.json.gz` that `jax.profiler.trace(..., create_perfetto_trace=True)`
writes (the newest one under the given directory). For each device it reports the traced span,
the time at least one kernel ran (busy; the rest of the span is launch and synchronisation
overhead), the kernel count, the device time per *scope*, and per CUDA graph its launches,
kernels and device time (which attributes a program without our scopes). A kernel's scope is the first of
`--scopes` in the name stack of the HLO op that launched it, read from the compiled program's HLO
text (`--hlo`; train_throughput.py writes `chunk.hlo.txt` beside its trace): `agents.loop` labels
"act", "env_step" and "update", `agents.ppo` "advantages", "minibatches" and "sgd_step" (with
`jax.named_scope`). The order of `--scopes` decides: put nested (more specific) scopes first.
"""

from __future__ import annotations

import argparse
import collections
import gzip
import json
import re
from pathlib import Path

DEFAULT_SCOPES = ("sgd_step", "advantages", "minibatches", "act", "env_step", "update")


def load_events(path: Path) -> tuple[list[dict], dict[int, str]]:
    """(complete events, process names) of the newest perfetto trace under `path` (or `path` itself)."""
    files = [path] if path.is_file() else sorted(path.rglob("perfetto_trace.json.gz"), key=lambda p: p.stat().st_mtime)
    if not files:
        raise ValueError(f"trace={str(path)!r} holds no perfetto_trace.json.gz: allowed is a directory written by "
                         "jax.profiler.trace(..., create_perfetto_trace=True) or such a file.")
    with gzip.open(files[-1], "rt") as f:
        events = json.load(f)["traceEvents"]
    names = {e["pid"]: e["args"]["name"] for e in events if e.get("ph") == "M" and e.get("name") == "process_name"}
    return [e for e in events if e.get("ph") == "X"], names


def busy_time(intervals: list[tuple[float, float]]) -> float:
    """Length of the union of (start, end) intervals."""
    total, end = 0.0, float("-inf")
    for a, b in sorted(intervals):
        if b <= end:
            continue
        total += b - max(a, end)
        end = b
    return total


def _key(op: str) -> str:
    # Kernel names spell an HLO op's "." and "-" as "_" ("loop_add_fusion.12" -> "loop_add_fusion_12").
    return re.sub(r"[.\-]", "_", op)


def op_names(hlo_text: str) -> dict[str, str]:
    """HLO instruction name -> its `op_name` metadata (the JAX name stack), from compiled HLO text."""
    out = {}
    for m in re.finditer(r'^\s*(?:ROOT\s+)?%?([\w.\-]+)\s*=[^\n]*?metadata=\{[^}\n]*?op_name="([^"]*)"', hlo_text, re.M):
        out[_key(m.group(1))] = m.group(2)
    return out


def op_stack(event: dict, names: dict[str, str]) -> str | None:
    """The JAX name stack of the HLO op that launched a kernel: from the compiled HLO's metadata, else
    the trace's own `name` argument (recent profilers record it); None without either."""
    args = event.get("args", {})
    # A kernel inside a CUDA graph names the graph ("command_buffer_12") as its hlo_op, but its
    # own name is its fusion's; ops outside graphs carry the name stack in args["name"].
    return names.get(_key(event["name"])) or names.get(_key(args.get("hlo_op", ""))) or args.get("name") or None


LAUNCH_ARGS = ("correlation_id", "cuda_graph_id", "cuda_graph_node_id", "scope_range_id")
"""Kernel arguments that change from one launch of an op to the next: left out of `name_stack`'s
fallback, so that the kernels of one op group together."""


def name_stack(event: dict, names: dict[str, str]) -> str:
    """`op_stack`, or without one the kernel's name and its arguments that do not change between launches."""
    stack = op_stack(event, names)
    if stack:
        return stack
    args = event.get("args", {})
    return " ".join([event["name"]] + [str(v) for k, v in args.items() if k not in LAUNCH_ARGS])


def scope_of(event: dict, scopes, names: dict[str, str]) -> str:
    """The first scope of `scopes` in the event's name stack, else "other"."""
    text = name_stack(event, names)
    for scope in scopes:
        if re.search(r"(^|[/ (])" + re.escape(scope) + r"($|[/ )])", text):
            return scope
    return "other"


def kernel_family(name: str) -> str:
    """A kernel name without XLA's numeric suffixes ("loop_add_fusion_12" -> "loop_add_fusion")."""
    return re.sub(r"([._]\d+)+$", "", name)


def summarize(events: list[dict], process_names: dict[int, str], scopes=DEFAULT_SCOPES, top: int = 15,
              hlo_names: dict[str, str] | None = None, process: str = "GPU|TPU", detail: int = 0) -> dict:
    """Per device (processes whose name matches the regex `process`): span, busy time and kernel
    count (microseconds), time per scope and the top kernel families. With `detail` > 0 also, per
    scope, its `detail` most expensive kernel families, each with the name stack of its most
    expensive op (where in the program it comes from). On a CPU trace pass `process="host:CPU"`:
    only events naming an HLO op count there."""
    out, names = {}, hlo_names or {}
    for pid, pname in sorted(process_names.items()):
        if not re.search(process, pname):
            continue
        kernels = [e for e in events if e["pid"] == pid and e.get("dur", 0) > 0
                   and ("GPU" in pname or "TPU" in pname or "hlo_op" in e.get("args", {}))]
        if not kernels:
            continue
        start = min(e["ts"] for e in kernels)
        end = max(e["ts"] + e["dur"] for e in kernels)
        per_scope = collections.Counter()
        count_scope = collections.Counter()
        families = collections.Counter()
        family_count = collections.Counter()
        op_time, op_count = collections.Counter(), collections.Counter()
        for e in kernels:
            s = scope_of(e, scopes, names)
            per_scope[s] += e["dur"]
            count_scope[s] += 1
            f = kernel_family(e["name"])
            families[f] += e["dur"]
            family_count[f] += 1
            if detail:
                op_time[s, f, name_stack(e, names)] += e["dur"]
                op_count[s, f] += 1
        out[pname] = {
            "span_us": end - start,
            "busy_us": busy_time([(e["ts"], e["ts"] + e["dur"]) for e in kernels]),
            "kernels": len(kernels),
            "scopes": {s: {"us": per_scope[s], "kernels": count_scope[s]} for s, _ in per_scope.most_common()},
            "top_kernels": [{"name": f, "us": t, "count": family_count[f]} for f, t in families.most_common(top)],
            "graphs": graph_summary(kernels, names, top),
        }
        if detail:
            rows = scope_kernels(op_time, op_count, detail)
            out[pname]["scope_kernels"] = {s: rows[s] for s in per_scope}
    return out


def graph_summary(kernels: list[dict], names: dict[str, str], top: int = 10) -> list[dict]:
    """The CUDA graphs (XLA command buffers) that launched `kernels`, by device time: each one's launches
    (the kernels of one launch share its correlation id; None where a kernel has none), kernels, device
    time, and the op whose kernels took most of its time (`op_stack`, among the stacks no other of the
    graph extends; without one, its costliest kernel's `name_stack`). Attributes a program without our
    named scopes (Brax's, say): a graph launched 20 times per vector step is a physics substep's loop
    body. Kernels outside graphs are left out."""
    time, count, unmarked = collections.Counter(), collections.Counter(), collections.Counter()
    launches, op_time, costliest = collections.defaultdict(set), collections.Counter(), {}
    for e in kernels:
        args = e.get("args", {})
        graph = args.get("cuda_graph_id")
        if graph is None:
            continue
        time[graph] += e["dur"]
        count[graph] += 1
        if args.get("correlation_id") is None:
            unmarked[graph] += 1
        else:
            launches[graph].add(args["correlation_id"])
        stack = op_stack(e, names)
        if stack:
            op_time[graph, stack] += e["dur"]
        if graph not in costliest or e["dur"] > costliest[graph][0]:
            costliest[graph] = (e["dur"], name_stack(e, names))
    stacks = collections.defaultdict(set)
    for graph, stack in op_time:
        stacks[graph].add(stack)
    where = {}
    for (graph, stack), _ in op_time.most_common():
        # a leaf op: the enclosing stacks (".../while/body") hold the loose kernels of many ops
        if not any(other.startswith(stack + "/") for other in stacks[graph]):
            where.setdefault(graph, stack)
    return [{"graph": g, "launches": None if unmarked[g] else len(launches[g]), "kernels": count[g], "us": t,
             "where": where.get(g, costliest[g][1])} for g, t in time.most_common(top)]


def scope_kernels(op_time: collections.Counter, op_count: collections.Counter, n: int) -> dict[str, list[dict]]:
    """Per scope, its `n` most expensive kernel families from device time per (scope, family, name
    stack) and kernel counts per (scope, family); each names the stack of its most expensive op."""
    family_time, where = collections.Counter(), {}
    for (s, f, stack), t in op_time.most_common():
        family_time[s, f] += t
        where.setdefault((s, f), stack)
    out = collections.defaultdict(list)
    for (s, f), t in family_time.most_common():
        if len(out[s]) < n:
            out[s].append({"name": f, "us": t, "count": op_count[s, f], "where": where[s, f]})
    return out


def host_summary(events: list[dict], process_names: dict[int, str], top: int = 12) -> list[dict]:
    """The host events that repeat (at least 10 times), by total host time: on a GPU, the thunks
    the host executes one by one (graph launches, library calls, loops). When the device is idle
    part of the span, these are what it waits for."""
    hosts = {pid for pid, name in process_names.items() if "host" in name.lower()}
    total, count = collections.Counter(), collections.Counter()
    for e in events:
        if e["pid"] in hosts and not e["name"].startswith("$"):
            key = e["name"] + (f" ({e['args']['hlo_op']})" if "hlo_op" in e.get("args", {}) else "")
            total[key] += e.get("dur", 0.0)
            count[key] += 1
    return [{"name": k, "us": t, "count": count[k]} for k, t in total.most_common() if count[k] >= 10][:top]


def format_summary(summary: dict, host: list[dict] | None = None) -> str:
    lines = []
    if host:
        lines += ["## host: repeated events by total time", "", "| event | host ms | count | us each |", "|---|---:|---:|---:|"]
        lines += [f"| {h['name'][:70]} | {h['us'] / 1e3:.1f} | {h['count']:,} | {h['us'] / h['count']:.1f} |" for h in host]
        lines.append("")
    for device, d in summary.items():
        span, busy = d["span_us"], d["busy_us"]
        lines += [f"## {device}",
                  f"span {span / 1e3:.1f} ms, kernels busy {busy / 1e3:.1f} ms ({busy / max(span, 1e-9):.0%}), "
                  f"{d['kernels']:,} kernels ({span / max(d['kernels'], 1):.1f} us of span per kernel)",
                  "", "| scope | device ms | kernels |", "|---|---:|---:|"]
        lines += [f"| {s} | {v['us'] / 1e3:.1f} | {v['kernels']:,} |" for s, v in d["scopes"].items()]
        lines += ["", "| kernel family | device ms | count |", "|---|---:|---:|"]
        lines += [f"| {k['name'][:70]} | {k['us'] / 1e3:.1f} | {k['count']:,} |" for k in d["top_kernels"]]
        lines.append("")
        if d.get("graphs"):
            lines += ["| CUDA graph | launches | kernels | kernels per launch | device ms | us per launch | from (the op "
                      "with most of its time) |", "|---|---:|---:|---:|---:|---:|---|"]
            for g in d["graphs"]:
                n = g["launches"]
                per = (f"{n:,} | {g['kernels']:,} | {g['kernels'] / n:.0f} | {g['us'] / 1e3:.1f} | {g['us'] / n:.1f}" if n
                       else f"? | {g['kernels']:,} | ? | {g['us'] / 1e3:.1f} | ?")
                lines.append(f"| {g['graph']} | {per} | {g['where'][-90:]} |")
            lines.append("")
        for scope, rows in d.get("scope_kernels", {}).items():
            lines += [f"### {scope}: top kernel families", "", "| kernel family | device ms | count | from (name stack) |",
                      "|---|---:|---:|---|"]
            lines += [f"| {k['name'][:60]} | {k['us'] / 1e3:.1f} | {k['count']:,} | {k['where'][-110:]} |" for k in rows]
            lines.append("")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(prog="python -m benchmarks.trace_summary", description=__doc__.split("\n\n")[0])
    parser.add_argument("trace", help="trace directory (or perfetto_trace.json.gz file)")
    parser.add_argument("--scopes", nargs="+", default=list(DEFAULT_SCOPES), help="scope names, most specific first")
    parser.add_argument("--top", type=int, default=15, help="kernel families and CUDA graphs listed per device")
    parser.add_argument("--hlo", help="compiled HLO text of the traced program (default: *.hlo.txt beside the trace)")
    parser.add_argument("--process", default="GPU|TPU", help="regex of the trace processes to summarise (CPU: host:CPU)")
    parser.add_argument("--detail", type=int, default=0, metavar="N",
                        help="also list each scope's N most expensive kernel families and where they come from")
    parser.add_argument("--json", help="also write the summary as JSON here")
    args = parser.parse_args()
    trace = Path(args.trace)
    events, names = load_events(trace)
    hlo = [Path(args.hlo)] if args.hlo else sorted(trace.rglob("*.hlo.txt")) if trace.is_dir() else []
    hlo_names = {}
    for path in hlo:
        hlo_names.update(op_names(path.read_text()))
    summary = summarize(events, names, args.scopes, args.top, hlo_names, args.process, args.detail)
    if not summary:
        raise ValueError(f"trace={args.trace!r} has no device events (a CPU-only trace has none).")
    host = host_summary(events, names)
    print(format_summary(summary, host))
    if args.json:
        from agents import provenance  # jax: imported only for the record

        meta = provenance.stamp()
        meta["device"] = (f"{', '.join(summary)} of the trace (it does not name the model); summarised on "
                          f"{meta['device']}")
        Path(args.json).write_text(json.dumps({"meta": meta, "devices": summary, "host": host}, indent=2))


if __name__ == "__main__":
    try:
        main()
    except ValueError as e:
        raise SystemExit(f"error: {e}")
