"""tools/link_distance_probe.py: its summary on hand-made distances, the long links' blind spot on the UR5e, and its
options' checks."""

import numpy as np
import pytest

from tools import link_distance_probe as probe


def test_summary_reads_the_origin_distance_where_each_link_touches():
    """Link a touches in poses 0 and 1 (origin 0.05 and 0.3 m: median 0.175, one of two over 10 cm), link b in pose 1
    (0.01); the nearest link's origin distance in those poses: 0.05 and 0.01 (median 0.03, none over 10 cm)."""
    origin = np.array([[0.05, 0.2], [0.3, 0.01], [0.02, 0.5]])
    surface = np.array([[-0.01, 0.1], [-0.02, -0.001], [0.05, 0.2]])
    summary = probe.summarize(origin, surface, ["a", "b"])
    assert summary["links"]["a"] == pytest.approx({"contacts": 2, "origin_median": 0.175, "origin_p90": 0.275,
                                                   "share_far": 0.5})
    assert summary["links"]["b"] == pytest.approx({"contacts": 1, "origin_median": 0.01, "origin_p90": 0.01,
                                                   "share_far": 0.0})
    assert summary["nearest"] == pytest.approx({"contacts": 2, "origin_median": 0.03, "origin_p90": 0.046,
                                                "share_far": 0.0})


def test_a_link_without_contacts_says_so():
    summary = probe.summarize(np.array([[0.3]]), np.array([[0.2]]), ["a"])
    assert summary["links"]["a"] == {"contacts": 0}


def test_the_ur5e_forearm_hides_more_contacts_than_its_last_wrist_link():
    """The forearm is 0.39 m long, wrist 3 a few centimetres: a contact along the forearm sits far from its origin."""
    links = probe.probe("ur5e-reach-avoid", 4_000, 0.12, 0)["links"]
    assert links["forearm_link"]["origin_median"] > links["wrist_3_link"]["origin_median"] + 0.05


@pytest.mark.parametrize("argv, named", [(["--num-poses", "0"], "--num-poses 0"), (["--offset", "0"], "--offset 0"),
                                         (["--env", "point-mass"], "--env 'point-mass'")])
def test_impossible_options_are_refused_naming_them(argv, named):
    with pytest.raises(ValueError, match=named):
        probe.main(argv)
