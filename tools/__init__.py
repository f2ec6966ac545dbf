"""User tools around trained policies: the paper's tables (`paper_tables`), why a policy fails
(`failure_report`), shipping a policy export (`ship_checkpoint`), figures (`plots`, the README's `readme_media`),
algorithms compared over tasks with rliable (`compare_runs`), the MPPI planner beside the shipped policies
(`planner_table`), the results tables (`results_index`), the UR5e's
fidelity to the paper (`fidelity`, `fidelity_train`) and the experiments (`experiments`: registry, state,
launching, tables). Each runs as
`python -m tools.<name> --help` from the repository root and imports as `from tools import <name>`."""

import ast
import sys


def run_cli(main) -> None:
    """Runs a tool's `main()`; bad input (a ValueError naming the field and what is allowed) prints
    `error: ...` and exits with status 2 instead of a traceback; otherwise it exits with `main()`'s status where
    that is a number, else 0."""
    try:
        code = main()
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        raise SystemExit(2)
    raise SystemExit(code if isinstance(code, int) else 0)


def literal_or_text(text: str):
    """A value as typed on a command line: a Python literal (0.1, 125, True, None, (256, 256)) or else the text
    itself (a name such as "front" or "bfloat16")."""
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text
