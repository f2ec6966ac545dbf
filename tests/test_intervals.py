"""agents/intervals.py and the tables' "mean ± std [CI]" cells: rliable's bootstrap interval of the mean over seeds
against hand-computed bootstrap distributions and a plain NumPy bootstrap."""

import os
import subprocess
import sys

import numpy as np
import pytest

from agents import evaluation, intervals
from tools.results_cells import seed_stats


def test_two_seeds_give_the_range_of_their_bootstrap_means():
    """Resampling 2 values gives the means 0, 0.5, 1 with probabilities 1/4, 1/2, 1/4: the 2.5 and 97.5
    percentiles are 0 and 1."""
    assert intervals.mean_ci([0.0, 1.0]) == [0.0, 1.0]


def test_a_rare_high_resample_still_bounds_the_interval():
    """[0, 0, 1]: the mean 1 comes up with probability 1/27 = 3.7 % > 2.5 %, the mean 0 with 8/27."""
    assert intervals.mean_ci([0.0, 0.0, 1.0]) == [0.0, 1.0]


def test_equal_values_give_a_point():
    assert intervals.mean_ci([0.5, 0.5, 0.5]) == [0.5, 0.5]


def test_one_seed_has_no_interval():
    assert intervals.mean_ci([0.9]) is None


def test_nan_seeds_are_left_out():
    assert intervals.mean_ci([0.9, float("nan")]) is None


def test_the_interval_matches_a_plain_numpy_bootstrap():
    """5 seeds: the percentile interval of 200,000 NumPy resamples, within 5 % of the values' spread."""
    values = np.array([0.962, 0.955, 0.951, 0.960, 0.957])
    rng = np.random.default_rng(1)
    means = values[rng.integers(0, 5, (200_000, 5))].mean(axis=1)
    reference = np.percentile(means, [2.5, 97.5])
    np.testing.assert_allclose(intervals.mean_ci(values), reference, atol=0.05 * np.ptp(values))


def test_the_same_values_give_the_same_interval():
    values = [0.31, 0.42, 0.38, 0.29]
    assert intervals.mean_ci(values) == intervals.mean_ci(values)


def test_numpys_global_generator_is_left_as_it_was():
    np.random.seed(7)
    expected = np.random.rand()
    np.random.seed(7)
    intervals.mean_ci([0.1, 0.2, 0.4])
    assert np.random.rand() == expected


def test_a_rate_cell_shows_mean_sample_std_and_interval():
    """[0.90, 0.95]: mean 92.5 %, sample std 3.5 %, bootstrap means 0.90 / 0.925 / 0.95 -> [90.0, 95.0]."""
    assert seed_stats([0.90, 0.95], 1, 100.0, " %") == "92.5 ± 3.5 % [90.0, 95.0]"


def test_a_single_seed_cell_is_its_value():
    assert seed_stats([0.019], 3) == "0.019"


def test_eval_summaries_carry_the_interval_over_units():
    """Two units with episode means 0.25 and 0.75: the interval is [0.25, 0.75]; one unit has none."""
    summary = evaluation.summarize({"target_reached": np.array([[0.0, 0.0, 0.0, 1.0], [1.0, 1.0, 0.0, 1.0]])})
    assert summary["target_reached"]["ci95_units"] == [0.25, 0.75]
    assert evaluation.summarize({"target_reached": np.array([[0.0, 1.0]])})["target_reached"]["ci95_units"] is None


def test_the_eval_table_shows_the_sample_std_and_the_interval():
    """Two units 0.25 and 0.75: population std 0.25 (the summary's), sample std 0.25 * sqrt(2) = 0.354."""
    stats = {"mean": 0.5, "std_units": 0.25, "ci95_units": [0.25, 0.75], "units": 2}
    assert evaluation.fmt(stats, 3, ci=True) == "0.500 ± 0.354 [0.250, 0.750]"
    assert evaluation.fmt(stats, 3) == "0.500 ± 0.354"


def test_the_eval_table_leaves_out_the_spread_of_one_unit():
    assert evaluation.fmt({"mean": 0.5, "std_units": 0.0, "ci95_units": None, "units": 1}, 3, ci=True) == "0.500"


@pytest.mark.parametrize("values", [[0.2, 0.3, 0.7], [0.91, 0.93, 0.95, 0.96, 0.99]])
def test_the_interval_holds_the_mean(values):
    low, high = intervals.mean_ci(values)
    assert low <= np.mean(values) <= high


def test_train_and_eval_start_without_importing_rliable():
    """rliable (with arch and scipy.stats) is imported when an interval is first asked for, not at start-up."""
    code = "import sys, train, eval; print('rliable' in sys.modules, 'arch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    assert out.stdout.split()[-2:] == ["False", "False"]


def test_a_dependency_that_breaks_the_import_is_named(monkeypatch):
    """A package that is installed but fails to import (arch 7.2 under pandas 3 raises a TypeError) is refused like a
    missing one, by name, before any work."""
    real = intervals.importlib.import_module

    def breaking(name, *args):
        if name == "arch.bootstrap":
            raise TypeError("deprecate_kwarg() missing 1 required positional argument: 'new_arg_name'")
        return real(name, *args)

    monkeypatch.setattr(intervals.importlib, "import_module", breaking)
    with pytest.raises(ValueError, match=r"need arch \(TypeError: deprecate_kwarg"):
        intervals.check_installed()
