"""On an NVIDIA GPU: kept noise is regenerated noise, bit for bit, and GPU workers keep the trainer deterministic.

Marked ``gpu`` and skipped where JAX sees no GPU (CI, the 2-core machines);
``make device-check`` runs them with ``JAX_PLATFORMS=cuda,cpu``.
"""

import numpy as np
import pytest

from pizero_ray.config import build_config


def _gpus() -> list:
    import jax

    try:
        return jax.devices("gpu")
    except RuntimeError:  # no GPU backend (JAX_PLATFORMS=cpu, or no CUDA JAX)
        return []


pytestmark = [pytest.mark.gpu, pytest.mark.skipif(not _gpus(), reason="JAX sees no GPU")]


def test_kept_and_regenerated_noise_are_bit_identical_on_the_gpu():
    import jax

    from pizero_ray import envs, es
    from pizero_ray.es import population
    from pizero_ray.trainer import chunk_scoring

    config = build_config("default", env="tsp", population=64, chunk_size=32)
    chunks = chunk_scoring.ChunkScorer(config, max_devices=1)
    assert chunks.devices[0].platform == "gpu"
    theta, layout = population.flat_params(config, envs.make("tsp"))
    seed, first_pair = 12345, 32
    scores = chunks.score(np.asarray(theta), seed, first_pair)
    assert scores.shape == (32, 2) and np.isfinite(scores).all()
    weights = np.random.default_rng(0).standard_normal(32).astype(np.float32)
    kept = chunks.gradient_part(seed, first_pair, weights)
    assert chunks.regenerated_parts == 0  # the part came from the noise kept on the GPU
    with jax.default_device(_gpus()[0]):
        regenerated = es.gradient_parts(config, layout.perturbation).regenerated(seed, first_pair, weights)
    assert kept.shape == (layout.size,) and np.abs(kept).sum() > 0
    np.testing.assert_array_equal(kept, regenerated)


def test_one_and_two_gpu_workers_give_the_same_parameters(ray_cluster, tmp_path, compile_cache_dir):
    """Two workers on one GPU (half each) against one worker with the whole GPU: the same hash."""
    import ray

    from pizero_ray import envs
    from pizero_ray.es import population
    from pizero_ray.storage import run_dir, runs
    from pizero_ray.trainer import driver, workers

    node = ray_cluster.add_node(num_cpus=2, num_gpus=1, resources={"gpu_test_node": 2})
    ray_cluster.wait_for_nodes()
    config = build_config("tiny", env="tsp", population=8, chunk_size=2)
    hashes = {}
    try:
        probe = workers.start_worker(config.to_json(), 1.0, 1.0, compile_cache_dir, {"gpu_test_node": 1.0})
        assert "cuda" in ray.get(probe.ready.remote(), timeout=600)["device"].lower()  # a GPU worker runs on it
        ray.kill(probe)
        for count in (1, 2):
            path = tmp_path / f"workers-{count}"
            run_dir.write_config(path, config)
            options = driver.RunOptions.create(
                iterations=3, workers=count, gpus_per_worker=1.0 / count, checkpoint_every=0,
                compile_cache=compile_cache_dir, worker_resources=(("gpu_test_node", 1.0),))
            result = driver.train(path, config, options)
            assert result["iteration"] == 3
            hashes[count] = result["parameter_hash"]
    finally:
        ray_cluster.remove_node(node)
    untrained = np.asarray(population.flat_params(config, envs.make("tsp"))[0])
    assert hashes[1] == hashes[2]
    assert hashes[1] != runs.parameter_hash(untrained)  # training moved the parameters


@pytest.mark.parametrize("rank", [0, 1])
def test_a_launchs_chunks_score_and_form_parts_the_same_however_they_are_asked_for_on_the_gpu(rank):
    """--chunks-per-launch 8 on the GPU: a chunk asked for alone scores as in its whole launch, and the parts of
    a call, formed in one program, are the bits a GPU regenerates for each chunk (a surviving GPU worker
    regenerates a lost chunk's part)."""
    import jax

    from pizero_ray import envs, es
    from pizero_ray.es import population
    from pizero_ray.trainer import chunk_scoring

    config = build_config("default", env="tsp", population=256, chunk_size=32, chunks_per_launch=8,
                          perturbation_rank=rank)
    theta = np.asarray(population.flat_params(config, envs.make("tsp"))[0])
    layout = population.flat_params(config, envs.make("tsp"))[1]
    firsts = list(range(0, 256, 32))
    together = chunk_scoring.ChunkScorer(config, max_devices=1)
    assert together.devices[0].platform == "gpu"
    launched = together.score_many(theta, 7, firsts)
    alone = chunk_scoring.ChunkScorer(config, max_devices=1)
    np.testing.assert_array_equal(alone.score(theta, 7, 96), launched[3])
    weights = np.random.default_rng(1).standard_normal((len(firsts), 32)).astype(np.float32)
    parts = together.gradient_parts(7, firsts, weights)
    assert together.regenerated_parts == 0
    with jax.default_device(_gpus()[0]):
        regenerate = es.gradient_parts(config, layout.perturbation).regenerated
        for first, part, row in zip(firsts, parts, weights):
            np.testing.assert_array_equal(part, regenerate(7, first, row))


def test_the_loops_compiled_do_not_change_the_scores_on_the_gpu():
    """--episode-loop horizon and --simulation-loop unrolled change the program's while loops on the GPU, not its
    scores (the GPU's own fusions and kernels may differ from the CPU's)."""
    import dataclasses

    from pizero_ray.trainer import chunk_scoring

    config = build_config("default", env="tsp", population=64, chunk_size=64)
    theta = None
    scores = {}
    for episode_loop in ("until_done", "horizon"):
        for simulation_loop in ("fori", "unrolled"):
            variant = dataclasses.replace(config, episode_loop=episode_loop, simulation_loop=simulation_loop)
            chunks = chunk_scoring.ChunkScorer(variant, max_devices=1)
            if theta is None:
                from pizero_ray import envs
                from pizero_ray.es import population

                theta = np.asarray(population.flat_params(config, envs.make("tsp"))[0])
            scores[(episode_loop, simulation_loop)] = chunks.score(theta, 3, 0)
    first = scores[("until_done", "fori")]
    for variant, got in scores.items():
        np.testing.assert_array_equal(got, first, err_msg=str(variant))
