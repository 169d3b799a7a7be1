"""The bytes the bench reports are the bytes that moved, against a count from the run's shapes alone.

A tiny run with one worker: 4 chunks of 2 pairs, P parameters. Each way, the
payloads are known from the shapes (float32 arrays: 4 bytes a number); every
object adds its framing, at most FRAMING bytes (a float32 array's pickle
header is about 120 bytes, an integer's 15, an object id 28).
"""

import pytest

from pizero_ray import envs
from pizero_ray.bench import training_runs
from pizero_ray.config import build_config
from pizero_ray.es import population

CONFIG = build_config("tiny", population=8, planner="none")  # no planner: this is about the pool, not the search
FRAMING = 200


@pytest.mark.parametrize("gradient_on", ["driver", "workers"])
def test_bytes_each_way_are_the_objects_that_moved(ray_session, compile_cache_dir, gradient_on):
    result = training_runs.trainer(CONFIG, workers=1, iterations=2, cache_dir=compile_cache_dir,
                                   gradient_on=gradient_on)
    parameters = population.flat_params(CONFIG, envs.make(CONFIG.env))[1].size
    chunks, pairs = CONFIG.num_chunks, CONFIG.chunk_size
    parts_asked = gradient_on == "workers"  # on the driver, no part is asked of a worker: none comes back
    # where the parts formed, as the run measured it: on the driver every chunk's, else none
    assert result["gradient_parts_on_driver"] == (chunks if gradient_on == "driver" else 0)

    # Back: each chunk's scores (2 per pair), and each chunk's gradient part (a parameter vector) if asked.
    back = chunks * pairs * 2 * 4 + parts_asked * chunks * parameters * 4
    objects_back = chunks * (1 + parts_asked)
    assert back < result["bytes_from_workers"] <= back + objects_back * FRAMING

    # Out: the parameters once (one worker, one node); per chunk a call (reference, seed, first pair) and,
    # if parts are asked, a second one with the chunk's weights (one per pair).
    out = parameters * 4 + parts_asked * chunks * pairs * 4
    objects_out = 1 + chunks * 3 * (1 + parts_asked)
    assert out < result["bytes_to_workers"] <= out + objects_out * FRAMING
