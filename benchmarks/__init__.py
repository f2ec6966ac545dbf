"""Measurement, table and picture scripts (throughput, the Brax reference, the paper's tables, plots,
rendering). Each module runs as `python benchmarks/<name>.py --help`; `render`, `plots` and
`paper_tables` are also imported by eval.py and the notebooks."""

import sys


def run_cli(main) -> None:
    """Runs a script's `main()`; bad input (a ValueError naming the field and what is allowed) prints
    `error: ...` and exits with status 2 instead of a traceback."""
    try:
        main()
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        raise SystemExit(2)
