"""`pizero bench`'s measurements: how fast the population rollout, the Ray trainer and the driver are.

At the paper's agent (abstract state 64, hidden 64, k = 4, 10 simulations) on
TSP10, in two modes: ``exact`` (full-rank Gaussian noise) and ``low_rank``
(``perturbation_rank`` 1, the ``default`` preset's). One module per concern:

  plans            the full and quick plans, the bench agent's config
  timing           compiled rollouts timed against each other, repeats interleaved
  rollout          the project's rollout in this process, as a worker runs it: chunks over every local device
                   (agent-steps and simulations per second, compile time), and on one device
  straightforward  the baseline: the same agent as a plain vmap over members of a scan over the horizon,
                   a direct batch-1 mctx.muzero_policy per step, one device; the speed-ups are over it
  sweeps           the project's rollout across search budgets, populations and planners
  update           the update made entirely in the driver (every chunk's noise regenerated)
  trainer          the Ray trainer with 1 and 2 workers on the same cores (iteration time, distributed
                   efficiency, the driver's update share, a new worker's first result, a worker's memory)
  traffic          the bytes an iteration moves each way, as the trainer's pool counts them
  report           the measurements as one JSON object, or a table
  runner           one bench run of a plan (`run`)

Speed targets live here, not in timed tests.
"""

from pizero_ray.bench.plans import FULL, LOW_RANK, QUICK, BenchPlan, bench_config
from pizero_ray.bench.report import table, to_json
from pizero_ray.bench.runner import run

__all__ = ["FULL", "LOW_RANK", "QUICK", "BenchPlan", "bench_config", "run", "table", "to_json"]
