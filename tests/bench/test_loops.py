"""The while-loop nest read from compiled programs: parsed from HLO text, and as the rollout compiles."""

from __future__ import annotations

import dataclasses

from pizero_ray.bench import loops
from pizero_ray.bench.rollout import pair_scorer_loops
from pizero_ray.config import build_config

HLO = """HloModule m

%cnd (p: (s32[])) -> pred[] {
  ROOT %c = pred[] constant(true)
}

%walk (p: (s32[])) -> (s32[]) {
  %m = f32[] multiply(f32[] %x, f32[] %x)
  %f = f32[] fusion(f32[] %x), kind=kLoop, calls=%cnd
  ROOT %t = (s32[]) tuple(s32[] %x)
}

%sims (p: (s32[])) -> (s32[]) {
  %w1 = (s32[]) while((s32[]) %p), condition=%cnd, body=%walk
  %w2 = (s32[]) while((s32[]) %p), condition=%cnd, body=%walk
  %rng = (s32[]) while((s32[]) %p), condition=%cnd, body=%walk, backend_config={"known_trip_count":{"n":"5"}}
  %s = f32[] add(f32[] %x, f32[] %x)
  ROOT %t = (s32[]) tuple(s32[] %x)
}

%branch (p: (s32[])) -> (s32[]) {
  ROOT %w = (s32[]) while((s32[]) %p), condition=%cnd, body=%sims, backend_config={"known_trip_count":{"n":"10"}}
}

%episode (p: (s32[])) -> (s32[]) {
  ROOT %c = (s32[]) conditional(pred[] %q, (s32[]) %p, (s32[]) %p), branch_computations={%branch, %walk}
}

ENTRY %main (a: s32[]) -> (s32[]) {
  %f = (s32[]) fusion(s32[] %a), kind=kLoop, calls=%walk
  ROOT %e = (s32[]) while((s32[]) %t), condition=%cnd, body=%episode
}
"""


def test_the_nest_is_read_through_calls_and_branches():
    (episode,) = loops.loop_nest(HLO)
    assert episode.trip_count is None
    (simulations,) = episode.inner
    assert simulations.trip_count == 10
    assert [loop.trip_count for loop in simulations.inner] == [None, None, 5]
    assert loops.summary(HLO) == {"while_loops": 5, "data_dependent_while_loops": 3, "deepest_loop_nest": 3,
                                  "data_dependent_loop_shape": "?[10[? ?]]",
                                  # a trip's instructions: a fusion is one, a conditional's branches count,
                                  # the nested loops do not
                                  "ops_per_trip_shape": "?:2[10:1[?:2 ?:2]]", "program_ops": 1}


def test_the_rollout_has_an_episode_loop_around_the_simulations_each_a_walk_and_a_backup():
    config = build_config("tiny", env="tsp", population=2, chunk_size=2, num_simulations=3)
    assert pair_scorer_loops(config)["data_dependent_loop_shape"] == "?[3[? ?]]"
    without = pair_scorer_loops(dataclasses.replace(config, planner="none"))
    assert without["data_dependent_loop_shape"] == "?"  # the episode loop alone


def test_a_horizon_episode_loop_has_a_known_length_and_unrolled_simulations_no_loop():
    config = build_config("tiny", env="tsp", population=2, chunk_size=2, num_simulations=3)
    horizon = pair_scorer_loops(dataclasses.replace(config, episode_loop="horizon"))
    assert horizon["data_dependent_loop_shape"] == "10[3[? ?]]"  # TSP10's 10 steps, known
    unrolled = pair_scorer_loops(dataclasses.replace(config, simulation_loop="unrolled"))
    assert unrolled["data_dependent_loop_shape"] == "?[? ? ? ? ? ?]"  # each simulation's walk and backup
    both = pair_scorer_loops(dataclasses.replace(config, episode_loop="horizon", simulation_loop="unrolled"))
    assert both["data_dependent_loop_shape"] == "10[? ? ? ? ? ?]"
    assert both["data_dependent_while_loops"] == 6
