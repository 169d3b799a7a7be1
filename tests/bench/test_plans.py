"""The bench's agent and plans."""

from pizero_ray.bench import plans as bench


def test_bench_config_is_the_papers_agent():
    config = bench.bench_config(1000, 40)
    assert (config.hidden_size, config.latent_size, config.num_abstract_actions, config.num_simulations) == (
        64, 64, 4, 10)
    assert config.env == "tsp" and config.num_chunks == 25 and config.episodes_per_member == 1


def test_bench_chunks_divide_any_population():
    assert bench.bench_config(256, 40).chunk_size == 32
    assert bench.bench_config(64, 40).chunk_size == 32
    assert bench.bench_config(7, 40).chunk_size == 7
    assert bench.bench_config(64, 40, devices=4).chunk_size == 16  # every device gets a chunk
    assert bench.bench_config(1000, 250, devices=2).chunk_size == 250


def test_bench_modes_differ_only_in_the_perturbation_and_the_chunk():
    exact = bench.bench_config(1000, 40)
    low_rank = bench.bench_config(1000, 100, perturbation_rank=bench.LOW_RANK)
    assert (exact.perturbation_rank, low_rank.perturbation_rank) == (0, bench.LOW_RANK)
    assert {k: v for k, v in vars(exact).items() if k not in ("perturbation_rank", "chunk_size")} == {
        k: v for k, v in vars(low_rank).items() if k not in ("perturbation_rank", "chunk_size")}


def test_plans_run_what_their_figures_need():
    assert bench.QUICK.low_rank_trainer_workers == () and set(bench.FULL.sweep_modes) == {"exact", "low_rank"}
    assert bench.FULL.straightforward and bench.FULL.one_device_with_dirichlet_draw
    for plan in (bench.QUICK, bench.FULL):  # distributed efficiency and the traffic need the 2-worker run
        assert 2 in plan.exact_trainer_workers
