"""Measurement, table and picture scripts (throughput, the Brax reference, the paper's tables, plots,
rendering). Each module runs as `python benchmarks/<name>.py --help`; `render`, `plots` and
`paper_tables` are also imported by eval.py and the notebooks."""
