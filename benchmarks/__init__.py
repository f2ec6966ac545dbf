"""Speed measurements: env throughput against the MJX physics ceiling (`env_throughput`), training
throughput against env only (`train_throughput`), Brax's PPO as a reference (`brax_reference`) and
a profiler trace's summary (`trace_summary`). Each runs as `python -m benchmarks.<name> --help` from
the repository root; the results they wrote are under results/."""
