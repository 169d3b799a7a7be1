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
  loops            the while loops of a compiled program, read from its HLO text: how they nest, which are
                   data-dependent, how many instructions each trip runs (what bounds a step on a GPU)
  population_sweep the population rollout on one device, point by point, each point one launch of a whole
                   population, as a GPU worker plays it (`make device-run`)
  update           the update made entirely in the driver (every chunk's noise regenerated)
  trainer          the Ray trainer with 1 and 2 workers on the same cores (iteration time, distributed
                   efficiency, the driver's update share, a new worker's first result, a worker's memory)
  traffic          the bytes an iteration moves each way, as the trainer's pool counts them
  report           the measurements as one JSON object, or a table
  runner           one bench run of a plan (`run`)

  stub_workers     Ray actors that import no JAX and answer chunks after a modelled delay: the scale model's
                   and the fault tests' workers
  scale            `pizero bench --scale`: the trainer's own costs from 1 to 512 workers and up to 100M
                   parameters, measured where this machine allows, modelled beyond
  scale_costs      the unit costs the scale model is built from: Ray's per-call and per-byte costs, and the
                   driver's update as the parameters grow
  scale_model      the scale model: an iteration's time at W workers, K chunks and D parameters, from the
                   measured unit costs (pure arithmetic, no Ray or JAX)

Speed targets live here, not in timed tests. The package imports nothing itself: a stub worker's process
loads numpy and Ray, not JAX.
"""
