"""What `pizero bench` measures, and at which agent: the plans (full, quick) and the bench's config."""

from __future__ import annotations

from dataclasses import dataclass

from pizero_ray.config import Config, build_config, largest_divisor_at_most

LOW_RANK = 1  # the perturbation rank the benchmark's low-rank mode uses
# The paper's agent (abstract state 64, hidden 64, k = 4); the search budget and the planner are bench_config's.
BENCH_AGENT = {"hidden_size": 64, "latent_size": 64, "memory_size": 64, "num_abstract_actions": 4}


@dataclass(frozen=True)
class BenchPlan:
    population: int
    chunk_size: int  # exact mode: larger chunks were no faster (docs/performance.md)
    low_rank_chunk_size: int  # low-rank mode: bigger chunks make bigger shared matrix products
    repeats: int
    trainer_iterations: int
    simulation_sweep: tuple[int, ...]
    population_sweep: tuple[int, ...]
    sweep_modes: tuple[str, ...]  # which modes the sweeps cover
    planner_sweep: tuple[str, ...]  # exact mode, population as above
    straightforward: bool  # also time the straightforward rollout (``straightforward``) and the speed-ups over it
    # Also time the project's rollout on one device with mctx.muzero_policy's Dirichlet draw (the figure the
    # bench called "straightforward" before the plain rollout existed), and the speed-ups over it.
    one_device_with_dirichlet_draw: bool
    one_device: bool  # with several local devices, also measure each mode on one of them
    exact_trainer_workers: tuple[int, ...]  # the first run starts with a cold compile cache; 2 must be among them
    low_rank_trainer_workers: tuple[int, ...]


FULL = BenchPlan(population=1000, chunk_size=40, low_rank_chunk_size=250, repeats=7, trainer_iterations=10,
                 simulation_sweep=(1, 10, 50), population_sweep=(64, 256, 1000), sweep_modes=("exact", "low_rank"),
                 planner_sweep=("muzero", "gumbel", "none"), straightforward=True,
                 one_device_with_dirichlet_draw=True, one_device=True,
                 exact_trainer_workers=(1, 2), low_rank_trainer_workers=(1, 2))
QUICK = BenchPlan(population=64, chunk_size=16, low_rank_chunk_size=32, repeats=3, trainer_iterations=3,
                  simulation_sweep=(10,), population_sweep=(64,), sweep_modes=("exact",),
                  planner_sweep=(), straightforward=False, one_device_with_dirichlet_draw=False, one_device=False,
                  exact_trainer_workers=(2,), low_rank_trainer_workers=())


def bench_config(population: int, chunk_size: int, simulations: int = 10, perturbation_rank: int = 0,
                 root_noise: float = 0.0, planner: str = "muzero", devices: int = 1, **overrides) -> Config:
    """The paper's agent on TSP10 (one trial per member, as the trainer's default), with any other Config
    settings in ``overrides`` (e.g. a smaller agent, or how the loops are compiled).

    The chunk is the largest divisor of the population not above ``chunk_size``
    that still gives each of ``devices`` devices a chunk.
    """
    chunk = largest_divisor_at_most(population, max(1, min(chunk_size, population // devices)))
    return build_config(
        "default", env="tsp", population=population, chunk_size=chunk, perturbation_rank=perturbation_rank,
        num_simulations=simulations, root_noise=root_noise, planner=planner, **{**BENCH_AGENT, **overrides},
    )
