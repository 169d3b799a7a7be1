"""Chunks dealt over several local devices score exactly as on one device."""

import threading

import jax
import numpy as np
import pytest

from pizero_ray import envs, es
from pizero_ray.config import build_config
from pizero_ray.es import population
from pizero_ray.trainer import chunk_scoring

CONFIG = build_config("tiny", population=8, chunk_size=2)
FIRST_PAIRS = range(0, CONFIG.population, CONFIG.chunk_size)
SEED = 12345


@pytest.fixture(scope="module")
def theta_and_reference():
    """Initial parameters, and every chunk's scores from the plain jitted functions on the default device."""
    env = envs.make(CONFIG.env, **CONFIG.env_kwargs())
    theta, layout = population.flat_params(CONFIG, env)
    evaluate = population.make_pair_scorer(CONFIG, env, layout)
    noise = es.gradient_parts(CONFIG, layout.perturbation).noise
    reference = [np.asarray(evaluate(theta, np.uint32(SEED), np.arange(first, first + CONFIG.chunk_size),
                                     noise(np.uint32(SEED), np.int32(first))))
                 for first in FIRST_PAIRS]
    return np.asarray(theta), reference


@pytest.fixture(scope="module")
def chunks():
    return chunk_scoring.ChunkScorer(CONFIG)


def test_the_test_process_has_two_cpu_devices(chunks):
    assert len(jax.local_devices()) == 2  # tests/conftest.py, as a 2-core worker
    assert chunks.num_devices == 2 and chunks.devices[0] != chunks.devices[1]
    assert chunks.agent_steps_per_pair == 2 * CONFIG.episodes_per_member * 10  # TSP10


def test_chunks_dealt_over_both_devices_score_as_on_one(chunks, theta_and_reference):
    theta, reference = theta_and_reference
    scores = chunks.score_all(theta, SEED, FIRST_PAIRS)
    assert len(scores) == len(reference)
    for got, want in zip(scores, reference):
        np.testing.assert_array_equal(got, want)
        assert got.dtype == np.float32 and got.shape == (CONFIG.chunk_size, 2)


def test_a_chunks_gradient_part_from_kept_noise_equals_the_regenerated_one(chunks, theta_and_reference):
    theta, _ = theta_and_reference
    weights = np.linspace(-1, 1, CONFIG.chunk_size).astype(np.float32)
    layout = population.flat_params(CONFIG, envs.make(CONFIG.env, **CONFIG.env_kwargs()))[1]
    driver_parts = es.gradient_parts(CONFIG, layout.perturbation)  # as the driver regenerates a part
    for first in (0, 2):  # one chunk on each device, as two threads of a worker would run them
        chunks.score(theta, SEED, first)
    for first in (0, 2):
        regenerated_before = chunks.regenerated_parts
        kept = chunks.gradient_part(SEED, first, weights)
        assert chunks.regenerated_parts == regenerated_before  # from the kept noise
        assert kept.shape == (chunks.parameters,) and np.abs(kept).sum() > 0
        np.testing.assert_array_equal(kept, driver_parts.regenerated(SEED, first, weights))
        np.testing.assert_array_equal(kept, chunks.gradient_part(SEED, first, weights))  # used up: regenerated
        assert chunks.regenerated_parts == regenerated_before + 1
    chunks.score(theta, SEED + 1, 2)
    assert not np.array_equal(chunks.gradient_part(SEED + 1, 2, weights), kept)


def test_a_straggler_of_an_older_iteration_keeps_the_newer_ones_noise(chunks, theta_and_reference):
    theta, _ = theta_and_reference
    weights = np.ones(CONFIG.chunk_size, np.float32)
    old, new = SEED + 100, SEED + 101
    chunks.score(theta, old, 0)
    chunks.score(theta, new, 0)
    chunks.score(theta, new, 2)
    chunks.score(theta, old, 4)  # the old iteration's straggler finishes during the new one
    regenerated_before = chunks.regenerated_parts
    chunks.gradient_part(new, 0, weights)
    chunks.gradient_part(new, 2, weights)
    assert chunks.regenerated_parts == regenerated_before  # both parts from the kept noise


def test_chunks_scored_together_in_one_call_score_as_alone_and_keep_their_noise(chunks, theta_and_reference):
    theta, reference = theta_and_reference
    seed = SEED + 200  # a seed no other test uses: the cache keeps the newest seeds' noise only
    together = chunks.score_many(theta, seed, FIRST_PAIRS)
    regenerated_before = chunks.regenerated_parts
    chunks.gradient_part(seed, FIRST_PAIRS[-1], np.ones(CONFIG.chunk_size, np.float32))
    assert chunks.regenerated_parts == regenerated_before  # score_many kept the chunk's noise
    alone = [chunks.score(theta, seed, first) for first in FIRST_PAIRS]
    assert len(together) == len(FIRST_PAIRS)
    for got, want in zip(together, alone):
        np.testing.assert_array_equal(got, want)
    reference_seed = chunks.score_many(theta, SEED, FIRST_PAIRS)
    for got, want in zip(reference_seed, reference):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("rank", [0, 1])
def test_a_launchs_chunks_score_and_form_parts_the_same_however_they_are_asked_for(rank):
    """--chunks-per-launch 4: the four chunks run as one device call, whether asked for together, alone or out of
    order; a chunk asked for after its launch ran is served from it. Each chunk's part from the kept noise (the
    parts of a call in one program) is the bits the driver regenerates."""
    config = build_config("tiny", population=16, chunk_size=2, chunks_per_launch=4, perturbation_rank=rank)
    theta, layout = population.flat_params(config, envs.make(config.env, **config.env_kwargs()))
    theta = np.asarray(theta)
    firsts = list(range(0, 16, 2))
    together = chunk_scoring.ChunkScorer(config, max_devices=1)
    expected = together.score_many(theta, SEED, firsts)
    assert together.launches_run == 2
    piecemeal = chunk_scoring.ChunkScorer(config, max_devices=1)
    got = {6: piecemeal.score(theta, SEED, 6)}  # runs chunks 0-3's launch
    got.update(zip([2, 0], piecemeal.score_many(theta, SEED, [2, 0])))  # kept from that launch
    assert piecemeal.launches_run == 1
    got.update(zip([14, 4, 8], piecemeal.score_many(theta, SEED, [14, 4, 8])))
    assert piecemeal.launches_run == 2
    for first, want in zip(firsts, expected):
        if first in got:
            np.testing.assert_array_equal(got[first], want)
    weights = np.stack([np.linspace(-1, 1, 2) * (k + 1) for k in range(len(firsts))]).astype(np.float32)
    driver_parts = es.gradient_parts(config, layout.perturbation)
    parts = together.gradient_parts(SEED, firsts, weights)
    assert together.regenerated_parts == 0
    for first, row, part in zip(firsts, weights, parts):
        np.testing.assert_array_equal(part, driver_parts.regenerated(SEED, first, row))


def test_chunks_per_launch_must_divide_the_population():
    with pytest.raises(ValueError, match="population 8 is not a multiple of chunk_size 2 x chunks_per_launch 3"):
        build_config("tiny", population=8, chunk_size=2, chunks_per_launch=3)


def test_a_scorer_that_keeps_no_noise_regenerates_every_part(theta_and_reference):
    """Where the driver forms every part (--gradient-on driver, or auto with rank-1 noise on CPU workers)
    nobody asks a worker for one: keeping the noise would only hold memory."""
    theta, _ = theta_and_reference
    scorer = chunk_scoring.ChunkScorer(CONFIG, max_devices=1, keep_noise=False)
    scorer.score(theta, SEED, 0)
    assert len(scorer._kept) == 0
    weights = np.linspace(-1, 1, CONFIG.chunk_size).astype(np.float32)
    layout = population.flat_params(CONFIG, envs.make(CONFIG.env, **CONFIG.env_kwargs()))[1]
    np.testing.assert_array_equal(scorer.gradient_part(SEED, 0, weights),
                                  es.gradient_parts(CONFIG, layout.perturbation).regenerated(SEED, 0, weights))
    assert scorer.regenerated_parts == 1


def test_the_chunk_cache_keeps_the_two_newest_seeds_within_its_byte_cap():
    cache = chunk_scoring.ChunkCache(chunk_bytes=10, max_bytes=30)
    cache.keep(1, 0, "1/0")
    cache.keep(2, 0, "2/0")
    cache.keep(1, 2, "1/2")  # a straggler of the seed before: kept, evicts nothing
    assert len(cache) == 3
    cache.keep(2, 2, "2/2")  # over the byte cap: not kept
    assert len(cache) == 3 and cache.take(2, 2) is None
    cache.keep(3, 0, "3/0")  # a new iteration: seed 1 is over
    assert cache.take(1, 0) is None and cache.take(1, 2) is None
    cache.keep(1, 4, "1/4")  # a late straggler of seed 1 is not mistaken for a new iteration
    assert cache.take(1, 4) is None
    assert cache.take(2, 0) == "2/0" and cache.take(3, 0) == "3/0"
    assert cache.take(3, 0) is None  # a part is asked for once
    assert len(cache) == 0 and cache.misses == 5


def test_concurrent_calls_each_borrow_a_device_and_score_as_on_one(chunks, theta_and_reference):
    theta, reference = theta_and_reference
    for _ in range(2):  # a device not given back would leave the second round waiting
        results = {}

        def evaluate(index, first, results=results):
            results[index] = chunks.score(theta, SEED, first)

        threads = [threading.Thread(target=evaluate, args=(i, first)) for i, first in enumerate(FIRST_PAIRS)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(timeout=120)
        assert sorted(results) == list(range(len(reference)))
        for index, want in enumerate(reference):
            np.testing.assert_array_equal(results[index], want)


def test_a_worker_with_two_cpus_runs_two_devices(ray_session, compile_cache_dir, theta_and_reference):
    from pizero_ray.trainer import workers

    theta, reference = theta_and_reference
    actor = workers.start_worker(CONFIG.to_json(), 2.0, 0.0, compile_cache_dir)
    try:
        info = ray_session.get(actor.ready.remote(), timeout=300)
        assert ray_session.get(actor.compiled.remote(), timeout=300)["devices"] == 2  # both, once compiled
        if chunk_scoring.cpu_count() == 2:
            assert info["pinned_cores"] == []  # both cores: nothing to pin
        refs = [actor.score_chunk.remote(theta, SEED, first) for first in FIRST_PAIRS]
        for got, want in zip(ray_session.get(refs, timeout=300), reference):
            np.testing.assert_array_equal(got, want)
    finally:
        ray_session.kill(actor)


_CLAIM = """
import json, os, sys
from pizero_ray.trainer.chunk_scoring import CoreClaim
claim = CoreClaim.claim(int(sys.argv[1]), sys.argv[2])
print(json.dumps([sorted(claim.cores), sorted(os.sched_getaffinity(0))]), flush=True)
sys.stdin.readline()  # hold the claim until told to go
"""


def _claimant(count, lock_dir):
    """A process that claims ``count`` cores and holds them until its stdin gets a line."""
    import json
    import subprocess
    import sys

    process = subprocess.Popen([sys.executable, "-c", _CLAIM, str(count), str(lock_dir)],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    cores, affinity = json.loads(process.stdout.readline())
    return process, cores, affinity


def test_processes_claim_cores_of_their_own_and_free_them_on_exit(tmp_path):
    cores = chunk_scoring.cpu_count()
    if cores < 2:
        pytest.skip("needs two cores")
    first, first_cores, first_affinity = _claimant(1, tmp_path)
    second, second_cores, _ = _claimant(cores - 1, tmp_path)
    try:
        assert len(first_cores) == 1 and first_affinity == first_cores  # pinned to the core it holds
        assert len(second_cores) == cores - 1 and not set(first_cores) & set(second_cores)
        third, third_cores, third_affinity = _claimant(1, tmp_path)  # every core is held: runs unpinned
        third.communicate("\n", timeout=60)
        assert third_cores == [] and len(third_affinity) == cores
    finally:
        first.communicate("\n", timeout=60)
    again, again_cores, _ = _claimant(1, tmp_path)  # the first claimant's exit freed its core
    again.communicate("\n", timeout=60)
    second.communicate("\n", timeout=60)
    assert again_cores == first_cores
    whole, whole_cores, whole_affinity = _claimant(cores, tmp_path)  # all of them: nothing to pin
    whole.communicate("\n", timeout=60)
    assert whole_cores == [] and len(whole_affinity) == cores


_CPU_ONLY = """
import jax
from jax._src import xla_bridge
import pizero_ray.trainer.workers  # what a Ray worker process imports before the actor's __init__ runs
assert not xla_bridge.backends_are_initialized(), "importing the worker module started a JAX backend"
from pizero_ray.trainer import chunk_scoring
chunk_scoring.use_cpu_only()
chunk_scoring.configure_cpu_devices(2)
print(jax.config.jax_platforms, sorted({device.platform for device in jax.devices()}), len(jax.devices()))
"""


def test_a_cpu_worker_chooses_jax_cpu_itself_before_any_backend_starts():
    """CPU workers start without a runtime_env (so in Ray's pre-started processes): JAX_PLATFORMS is not set
    for them, and the choice made in __init__ holds only if nothing imported before it started a backend."""
    import os
    import subprocess
    import sys

    env = {key: value for key, value in os.environ.items() if key != "JAX_PLATFORMS"}
    out = subprocess.run([sys.executable, "-c", _CPU_ONLY], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["cpu", "['cpu']", "2"]
