"""Interval estimates over trained seeds with rliable (Agarwal et al., "Deep RL at the Edge of the Statistical
Precipice", NeurIPS 2021): the 95 % stratified-bootstrap confidence interval of the mean over seeds, the field's
standard for comparisons over few seeds, reported beside the sample std."""

from __future__ import annotations

import contextlib
import importlib
import warnings

import numpy as np

CONFIDENCE = 0.95
"""Coverage of the intervals."""
REPS = 1000
"""Bootstrap resamples per interval (rliable resamples in Python: about 0.1 s each on a CPU core; tables cache them)."""
SEED = 0
"""Seed of the resampling, so that the same values always give the same interval (tables are regenerated)."""


NEEDS = ("rliable.library", "arch.bootstrap")
"""The modules an interval imports: rliable's and its bootstrap's (arch)."""


def check_installed() -> None:
    """ValueError before any work when a module of NEEDS does not import (missing, or broken by a dependency):
    intervals are computed after the evaluations, where the error would lose their results."""
    broken = []
    for name in NEEDS:
        try:
            importlib.import_module(name)
        except Exception as error:  # a dependency's break shows as any error (arch 7.2 under pandas 3: TypeError)
            broken.append(f"{name.split('.')[0]} ({type(error).__name__}: {error})")
    if broken:
        raise ValueError(f"confidence intervals over seeds need {' and '.join(broken)}: allowed is an install where "
                         "they import (pip install -e .).")


def _rliable():
    """rliable's library, imported when an interval is first asked for (a summary over two or more seeds): it imports
    arch and scipy.stats, which a one-seed run or a baseline evaluation never needs."""
    from rliable import library

    return library


@contextlib.contextmanager
def seeded_numpy(seed: int):
    """NumPy's global generator seeded inside, restored after: rliable's bootstrap (arch) draws from it whatever
    random_state it is given, so this makes its intervals repeatable without touching the caller's draws."""
    saved = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)  # arch: random_state is deprecated
            yield
    finally:
        np.random.set_state(saved)


def mean_ci(values, confidence: float = CONFIDENCE, reps: int = REPS, seed: int = SEED) -> list[float] | None:
    """[low, high]: the percentile bootstrap interval of the mean of `values` (one per seed) by rliable's
    `get_interval_estimates`; None for fewer than 2 finite values (no interval over one seed)."""
    values = np.asarray(values, np.float64)
    values = values[np.isfinite(values)]
    if values.size < 2:
        return None
    with seeded_numpy(seed):
        _, intervals = _rliable().get_interval_estimates(
            {"runs": values.reshape(-1, 1)}, lambda s: np.array([np.mean(s)]), reps=reps, confidence_interval_size=confidence)
    low, high = intervals["runs"][:, 0]
    return [float(low), float(high)]
