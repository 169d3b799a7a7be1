"""scripts/flp_instance_use.py: an agent that ignores the instance scores what its average placement scores."""

import numpy as np
import pytest

from tests.scripts_loading import load_script


@pytest.fixture(scope="module")
def script():
    return load_script("flp_instance_use")


def test_placement_score_is_minus_the_objective(script):
    clients = np.array([[[0.0, 0.0], [1.0, 0.0]]])  # one instance, two clients
    facility = np.array([[0.0, 0.0]])
    assert script.placement_score(facility, clients, "max") == pytest.approx([-1.0])
    assert script.placement_score(facility, clients, "mean") == pytest.approx([-0.5])


@pytest.mark.parametrize("objective", ["max", "mean"])
def test_a_fixed_placement_has_no_spread_and_scores_itself(script, objective):
    clients = np.random.default_rng(0).uniform(size=(50, 20, 2))
    placement = np.array([[0.2, 0.3], [0.7, 0.8], [0.5, 0.1]])
    facilities = np.broadcast_to(placement, (50, 3, 2))
    scores = script.placement_score(facilities, clients, objective)
    summary = script.summarise_placements(scores, clients, facilities, objective)
    assert summary["spread"] == [0.0, 0.0, 0.0]
    assert summary["agent_average_placement"] == pytest.approx(summary["agent"])


def test_placements_that_follow_the_clients_beat_their_average(script):
    clients = np.random.default_rng(1).uniform(size=(200, 3, 2))
    facilities = clients.copy()  # a facility on every client: cost 0
    scores = script.placement_score(facilities, clients, "max")
    summary = script.summarise_placements(scores, clients, facilities, "max")
    assert summary["agent"] == pytest.approx(0.0)
    assert summary["agent_average_placement"] < -0.1
    assert min(summary["spread"]) > 0.3
