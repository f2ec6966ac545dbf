"""Hang guards for tests that run a subprocess or a notebook: limits far above what any machine that runs the
suite needs (the slowest such test takes a few minutes on a shared 2-core CPU), so that a hang fails the test
instead of the CI run while speed is never checked here (speeds belong in benchmarks/)."""

HANG_GUARD_S = 3600
"""Seconds a subprocess, a notebook or one of its cells may run before the test calls it hung."""
