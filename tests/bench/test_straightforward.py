"""The straightforward rollout is the trainer's agent playing the trainer's game, written the plain way."""

import jax
import numpy as np
import pytest

from pizero_ray import es
from pizero_ray.bench import straightforward
from pizero_ray.config import build_config
from pizero_ray.es import population
from tests.bench.counting import count_environment_steps


def _config(**changes):
    # More search than the tiny preset's (2 simulations over 2 abstract actions), so that the search shapes the game.
    return build_config("tiny", population=4, chunk_size=4, num_simulations=4, num_abstract_actions=3, **changes)


CONFIG = _config()


def _trainers_scores(config, env, theta, layout, seed):
    """Scores [population, 2] of the population as a worker computes them: one chunk, the noise handed in."""
    evaluate = population.make_pair_scorer(config, env, layout)
    noise = es.gradient_parts(config, layout.perturbation).noise(np.uint32(seed), np.int32(0))
    return np.asarray(evaluate(theta, np.uint32(seed), np.arange(config.population, dtype=np.int32), noise))


@pytest.mark.parametrize("root_noise", [0.0, 0.25])
def test_its_scores_are_the_trainers_rollouts_bit_for_bit(tsp_env, root_noise):
    # Root noise 0: the trainer's search skips muzero_policy's Dirichlet draw, and builds the same tree
    # (tests/agent/test_planner.py); 0.25: the trainer's search is muzero_policy itself, with the same key.
    config = _config(root_noise=root_noise)
    theta, layout = population.flat_params(config, tsp_env)
    plain = straightforward.make_population_scorer(config, tsp_env, layout)
    games = []
    for seed in (3, 7):
        theirs = _trainers_scores(config, tsp_env, theta, layout, seed)
        ours = np.asarray(plain(theta, np.uint32(seed)))
        np.testing.assert_array_equal(ours, theirs)
        games.append(ours)
    assert len(np.unique(np.concatenate(games))) > config.population  # not one game for all: instances differ


def test_agent_steps_are_the_environment_steps_of_one_iteration(monkeypatch):
    steps = count_environment_steps(monkeypatch)
    run = straightforward.compile_straightforward(CONFIG)  # compiles, and plays a warm-up iteration
    jax.effects_barrier()
    steps.clear()
    run.one_iteration(1)
    jax.effects_barrier()
    assert sum(steps) == run.agent_steps > 0
    assert run.devices == 1


@pytest.mark.parametrize("change", [dict(perturbation_rank=1), dict(planner="gumbel"), dict(episodes_per_member=2),
                                    dict(chance_outcomes=2)])
def test_it_refuses_an_agent_it_would_not_play_as_the_trainer_does(tsp_env, change):
    config = build_config("tiny", **change)
    with pytest.raises(ValueError, match=next(iter(change))):
        straightforward.make_member_score(config, tsp_env)
