"""What a run writes while it trains: `metrics.csv`, TensorBoard events, a progress line, and the
final evaluation's summary in the paper's terms; other loggers (`agents.wandb_logger`) get the same rows."""

from __future__ import annotations

import csv
import datetime
import os
import sys
from collections.abc import Sequence

import numpy as np

# The paper's evaluation metrics (section "Evaluation metrics") as printed after training:
# metric key of the evaluation -> (label, format).
SUMMARY_METRICS = {
    "episode/target_reached": ("target reached", "{:.1%}"),
    "episode/self_collision": ("self collision", "{:.1%}"),
    "episode/obstacle_collision": ("obstacle collision", "{:.1%}"),
    "episode/distance_last10": ("distance to target, last 10 steps (m)", "{:.4f}"),
    "episode/steps_in_target": ("steps in target", "{:.1f}"),
    "episode/times_left_target": ("times left target", "{:.2f}"),
    "episode/return": ("episode return", "{:.4g}"),
    "episode/length": ("episode length", "{:.1f}"),
}


def summary_lines(eval_metrics: dict) -> list[str]:
    """The evaluation's paper metrics, one `label: mean (min - max over seeds)` line each, in the
    order of `SUMMARY_METRICS`; metrics the env does not report are left out."""
    lines = []
    for key, (label, fmt) in SUMMARY_METRICS.items():
        values = eval_metrics.get(key)
        if values is None:
            continue
        values = np.asarray(values, dtype=float)
        line = f"  {label}: {fmt.format(np.mean(values))}"
        if values.size > 1:
            line += f" ({fmt.format(np.min(values))} - {fmt.format(np.max(values))} over {values.size} seeds)"
        lines.append(line)
    return lines


def cut_rows_after(csv_path: str, step: int) -> int:
    """Drops the rows of `csv_path` logged after env step `step` (a run killed after its last checkpoint logged
    them; the resume from that checkpoint logs those steps again, so each step appears once). Rewrites the file
    atomically; returns the number of rows dropped (0 leaves the file untouched)."""
    if not os.path.exists(csv_path):
        return 0
    with open(csv_path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or "env_steps" not in rows[0]:
        return 0
    column = rows[0].index("env_steps")
    kept = [rows[0]] + [r for r in rows[1:] if len(r) > column and r[column] and float(r[column]) <= step]
    if len(kept) == len(rows):
        return 0
    temporary = csv_path + ".tmp"
    with open(temporary, "w", newline="") as f:
        csv.writer(f).writerows(kept)
    os.replace(temporary, csv_path)
    return len(rows) - len(kept)


def si(x: float) -> str:
    """1234567 -> '1.23M'."""
    for unit, scale in (("G", 1e9), ("M", 1e6), ("k", 1e3)):
        if abs(x) >= scale:
            return f"{x / scale:.2f}{unit}"
    return f"{x:.0f}"


class Logger:
    """CSV rows (one per seed and log step), TensorBoard scalars per seed, and the progress line. `sinks`: other
    loggers (`agents.wandb_logger.WandbLogger`) that get every `log` call, the final evaluation and `close`."""

    def __init__(self, logdir: str, seed: int, seeds: int, label: str, tensorboard: bool = True,
                 progress: bool = True, sinks: Sequence = ()):
        self.seed, self.seeds, self.label, self.show_progress = seed, seeds, label, progress
        self.sinks = list(sinks)
        self.csv_path = os.path.join(logdir, "metrics.csv")
        self.columns = None
        self.writers = []
        if tensorboard:
            try:
                from tensorboardX import SummaryWriter
                self.writers = [SummaryWriter(os.path.join(logdir, "tb", f"seed_{seed + i}")) for i in range(seeds)]
            except ImportError:
                print("tensorboardX is not installed: no TensorBoard logs (CSV only).", file=sys.stderr)
        self.tty = sys.stdout.isatty()
        self.last_len = 0

    def log(self, step: int, metrics: dict, extra: dict) -> None:
        """`metrics`: {name: per-seed values}; `extra`: scalars shared by the seeds (speed, time)."""
        names = sorted(metrics)
        if self.columns is None:
            self.columns = ["env_steps", "seed", *sorted(extra), *names]
            header = self._existing_header()
            if header is None:
                with open(self.csv_path, "w", newline="") as f:
                    csv.writer(f).writerow(self.columns)
            else:  # a resumed run appends under the file's own header, whatever this code logs
                left_out = [c for c in self.columns if c not in header]
                if left_out:
                    print(f"{self.csv_path} has no column for {', '.join(left_out)} (the run began with other "
                          "code): not written there (TensorBoard still gets them).", file=sys.stderr)
                self.columns = header
        with open(self.csv_path, "a", newline="") as f:
            w = csv.writer(f)
            for i in range(self.seeds):
                row = {"env_steps": step, "seed": self.seed + i, **extra, **{k: float(metrics[k][i]) for k in names}}
                w.writerow([row.get(c, "") for c in self.columns])
        for i, writer in enumerate(self.writers):
            for k in names:
                writer.add_scalar(k, float(metrics[k][i]), step)
            for k, v in extra.items():
                writer.add_scalar("perf/" + k, v, step)
            writer.flush()
        for sink in self.sinks:
            sink.log(step, metrics, extra)

    def log_eval(self, step: int, eval_metrics: dict) -> None:
        """The final evaluation ({name: per-seed values}, eval.json's per_seed) of env step `step`, for the sinks."""
        for sink in self.sinks:
            sink.log_eval(step, eval_metrics)

    def _existing_header(self) -> list[str] | None:
        """The header row of an existing, non-empty metrics.csv (a resumed run's), else None."""
        if not os.path.exists(self.csv_path):
            return None
        with open(self.csv_path, newline="") as f:
            return next(csv.reader(f), None) or None

    def progress(self, step: int, total: int, rate: float, metrics: dict, compiled: bool = False) -> None:
        """A status line. `compiled`: the chunk's time includes compiling the programs, so its rate says little
        about the rest and no ETA is shown."""
        eta = datetime.timedelta(seconds=int((total - step) / rate)) if rate > 0 else "?"
        speed = [f"{si(rate)} steps/s incl. compiling", "ETA after the next chunk"] if compiled else \
            [f"{si(rate)} steps/s", f"ETA {eta}"]
        parts = [f"[{self.label}] {si(step)}/{si(total)} steps ({100 * step / total:.1f}%)", *speed]
        for k in ["episode/return"] + [k for k in sorted(metrics) if k.startswith("episode/") and k != "episode/return"][:4]:
            values = np.asarray(metrics.get(k, np.nan), np.float64)
            if np.any(np.isfinite(values)):  # all NaN when no episode ended in the chunk: left out, without a warning
                parts.append(f"{k.split('/', 1)[1]} {np.nanmean(values):.3g}")
        self.say(" | ".join(parts), transient=True)

    def say(self, line: str, transient: bool = False) -> None:
        """Prints a status line; on a terminal a transient one is overwritten by the next."""
        if not self.show_progress:
            return
        if self.tty:
            end = "" if transient else "\n"
            print("\r" + line.ljust(self.last_len), end=end, flush=True)
            self.last_len = len(line) if transient else 0
        else:
            print(line, flush=True)

    def close(self) -> None:
        if self.tty and self.show_progress and self.last_len:
            print()
        for w in self.writers:
            w.close()
        for sink in self.sinks:
            sink.close()
