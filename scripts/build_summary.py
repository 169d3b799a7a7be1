"""docs/results/summary.json: every published 30-minute result, each figure taken from the committed JSON that holds it.

Usage::

    python scripts/build_summary.py              # rewrites docs/results/summary.json
    python scripts/build_summary.py --check      # exit 1 if rebuilding would change it

The pages (README's results table, docs/learning.md, each environment page's
current best) are generated from summary.json by ``python
scripts/render_results.py``. ``SPEC`` below says, per environment and agent,
which run of which committed JSON (docs/results/...) each seed's held-out
score is; the score, its 95% interval and its iterations are read from there,
never typed here. A figure that exists only in the docs (no JSON was
committed for it) is typed once, in a ``hand(...)`` entry whose ``source``
says where it was published; those are listed by ``--hand``.

Scores are "higher is better" everywhere: TSP's score is minus the tour
length (the tour length is beside it as the natural unit).
"""

from __future__ import annotations

import argparse
import json
import sys
from decimal import Decimal
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "docs" / "results"
OUT = RESULTS / "summary.json"
T = "thirty_minutes/"  # most sources live there

EVAL = "pizero eval R --episodes 1000 --seed 0"
TRAIN = "--run-dir R --minutes 30 --eval-every-minutes 5 --eval-episodes 200 --no-progress"
ONE_CORE = "--workers 1 --cpus-per-worker 1"
L = "../shared/boxoban/unfiltered"
STATE_AND_PLAN = "state,action,visits,value"  # the decoder's inputs where PiZero's default reads only the plan


def run(file: str, name: str, **extra) -> dict:
    """One seed's held-out score: run ``name`` of docs/results/``file``.json."""
    return {"file": file + ".json", "run": name, **extra}


def hand(seed, score, ci95, iterations, source: str, decimals: int | None = None, label: str | None = None,
         **extra) -> dict:
    """A seed's figure published only in the docs: typed here once, with where it was published."""
    out = {"hand": True, "seed": seed, "score": score, "ci95": ci95, "iterations": iterations, "source": source}
    if decimals is not None:
        out["decimals"] = decimals
    if label is not None:
        out["label"] = label
    out.update(extra)
    return out


def refs(file: str, name: str, **keys: str) -> dict:
    """References (random play, heuristics, the optimum) from a run's held-out evaluation: label -> key."""
    return {"file": file + ".json", "run": name, "keys": keys}


def agent(key: str, column: str | None, label: str, setting: str, budget: str, command: str, runs: list,
          short: str | None = None) -> dict:
    """An agent at one setting: ``column`` is its column in the README's table (None: its page only)."""
    return {"key": key, "column": column, "label": label, "setting": setting, "budget": budget,
            "command": command, "runs": runs, **({"short": short} if short else {})}


SOKOBAN_PAIRS = (0, 1, 2)  # seeds of PiZero's Sokoban default trained side by side with the planner-free agent
COLLECT_OUTSIDE = ("docs only: published in docs/collect.md, docs/learning.md and the README before this summary; "
                   "an outside check of the same command with another training seed, reported to the project, "
                   "not run in this repository (no JSON or run dir here)")
FIXED_PLACEMENT = ("docs only: docs/notebook/flp.md, 'A yardstick: the best placement that ignores the instance', "
                   "measured by scripts/flp_fixed_placement.py at commit 6a90615 (removed since; "
                   "git show 6a90615:scripts/flp_fixed_placement.py), which wrote no JSON")
SEED2_DOCS = "docs only: published in {pages} (commit {commit}); its summary JSON was not committed"

SPEC = [
    {
        "env": "tsp", "title": "TSP10", "page": "docs/tsp.md", "score": "minus the tour length",
        "natural_unit": "tour length", "decimals": 3,
        "about": "10 uniform cities; the closed tour's length on 1,000 held-out instances",
        "target": {"score": -2.93, "text": "-2.93 or higher, a tour of at most 2.93"},
        "references": refs(T + "tsp_flp", "tsp-pizero", **{"optimal (Held-Karp)": "optimal_score",
                                                             "nearest neighbour": "nearest_neighbour_score",
                                                             "random tours": "random_score"}),
        "agents": [
            agent("alphazero", "alphazero", "AlphaZero (true simulator)", "32 simulations, its TSP default",
                  "30 min, 1 core",
                  f"pizero train --env tsp --method alphazero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "baseline_candidates", "tsp-alphazero-sims32")]),
            agent("muzero", "muzero", "MuZero (learned model)", "trained at lr 3e-4", "30 min, 1 core",
                  f"pizero train --env tsp --method muzero --lr 3e-4 --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "tsp_baselines", "tsp-muzero")]),
            agent("pizero", "pizero", "PiZero (ES, muzero planner)",
                  "the `default`: 10 simulations, the decoder reads only the plan", "30 min, 1 core each",
                  "pizero train --env tsp --seed S --run-dir R --minutes 10 --eval-every-minutes 5 --eval-episodes 200 "
                  f"--no-progress --workers 1; pizero resume R --minutes 30 --workers 1 --no-progress; {EVAL}",
                  [run(T + "tsp_pizero_reads_only_the_plan", f"seed{seed}") for seed in range(3)]),
            agent("pizero-reads-state", None, "PiZero, the decoder reading the state too",
                  f"`--decoder-inputs {STATE_AND_PLAN}`", "30 min, 1 core each",
                  f"pizero train --env tsp --decoder-inputs {STATE_AND_PLAN} --seed S {TRAIN} {ONE_CORE}; {EVAL}",
                  [run(T + "tsp_flp", "tsp-pizero"), run(T + "tsp_planner_against_none_seeds_1_2", "pizero-seed1"),
                   run(T + "tsp_planner_against_none_seeds_1_2", "pizero-seed2")]),
            agent("none", "none", "no planner (ES, `--planner none`)", "the `default`: one instance per member",
                  "30 min, 1 core each",
                  f"pizero train --env tsp --planner none --seed S {TRAIN} {ONE_CORE}; {EVAL}",
                  [run(T + "tsp_flp", "tsp-none"), run(T + "tsp_planner_against_none_seeds_1_2", "none-seed1"),
                   run(T + "tsp_planner_against_none_seeds_1_2", "none-seed2")]),
            agent("none-8", "none", "no planner, 8 instances per member", "`--episodes-per-member 8`",
                  "30 min, 1 core each",
                  f"pizero train --env tsp --planner none --seed S --episodes-per-member 8 {TRAIN} {ONE_CORE} "
                  f"--no-pin-cores; {EVAL}",
                  [run(T + "tsp_episodes_per_member", "e8_seed0"), run(T + "tsp_episodes_per_member", "e8_seed1"),
                   run(T + "sokoban_tsp_planner_free_seed2", "tsp-none-ep8-seed2")],
                  short="with `--episodes-per-member 8`"),
        ],
        "paired": [
            {"a": "pizero-reads-state", "b": "none",
             "budget": "equal time (30 minutes, one core each), the decoder reading the state too",
             "file": T + "tsp_planner_against_none_seeds_1_2.json", "key": ["paired_comparisons", "seed1"],
             "run_a": "pizero-seed1", "run_b": "none-seed1"},
            {"a": "pizero-reads-state", "b": "none",
             "budget": "equal time (30 minutes, one core each), the decoder reading the state too",
             "file": T + "tsp_planner_against_none_seeds_1_2.json", "key": ["paired_comparisons", "seed2"],
             "run_a": "pizero-seed2", "run_b": "none-seed2"},
            {"a": "pizero-reads-state", "b": "none",
             "budget": "equal iterations (200, `make train`), the decoder reading the state too", "hand": True,
             "seed": 0, "difference": -0.016, "ci95": [-0.028, -0.003], "score_a": -2.990, "score_b": -2.974,
             "command": "make train (PiZero, 200 iterations, seed 0) and the same run with --planner none; "
                        "pizero compare RUN_PIZERO RUN_NONE --episodes 1000",
             "source": "docs only: published in the README (2026-12-04); no JSON was committed"},
        ],
    },
    {
        "env": "collect", "title": "Collect", "page": "docs/collect.md", "score": "minus the coins left",
        "decimals": 3, "about": "12 coins on an 8x8 walled grid, 20 moves; minus the coins left",
        "target": {"score": -2.0, "text": "-2.0 or higher, at most 2 coins left"},
        "references": refs(T + "collect_rank1", "collect-pizero", **{"optimal": "optimal_score",
                                                                     "greedy nearest-coin": "greedy_score",
                                                                     "random walker": "random_score"}),
        "agents": [
            agent("alphazero", "alphazero", "AlphaZero (true simulator)", "its defaults", "30 min, 1 core",
                  f"pizero train --env collect --method alphazero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "collect_sokoban_baselines", "collect-alphazero")]),
            agent("muzero", "muzero", "MuZero (learned model)", "1,024 episodes of replay, its Collect default",
                  "30 min, 1 core", f"pizero train --env collect --method muzero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "baseline_candidates", "collect-muzero-replay1024")]),
            agent("pizero", "pizero", "PiZero (ES, gumbel planner)",
                  "the `default`: Gumbel search, 4 simulations (one per abstract action)", "30 min, 1 core each",
                  "pizero train --env collect --seed S --run-dir R --minutes 30 --eval-every-minutes 10 "
                  f"--eval-episodes 200 --no-progress --workers 1; {EVAL}",
                  [*(run(T + "collect_pizero_gumbel", f"seed{seed}") for seed in range(3)),
                   *(run(T + "collect_pizero_gumbel_side_by_side", f"pizero-seed{seed}") for seed in (3, 4))]),
            agent("pizero-muzero-10", None, "PiZero, MuZero's search", "`--planner muzero --simulations 10`",
                  "30 min, 1 core",
                  f"pizero train --env collect --planner muzero --simulations 10 --seed 0 {TRAIN} {ONE_CORE}; {EVAL}",
                  [run(T + "collect_rank1", "collect-pizero")]),
            agent("none", "none", "no planner (ES, `--planner none`)", "the `default`, the whole machine",
                  "30 min, 2 workers (the whole 2-core machine)",
                  f"pizero train --env collect --planner none --seed S {TRAIN} --workers 2 --cpus-per-worker 1 "
                  f"--no-pin-cores; {EVAL}",
                  [run(T + "collect_two_workers_faster_machine", "default_two_workers_seed0"),
                   run(T + "collect_two_workers_faster_machine", "default_two_workers_seed1"),
                   hand(None, -2.65, [-2.72, -2.58], 35082, COLLECT_OUTSIDE, decimals=2,
                        label="an outside check with another training seed")]),
            agent("none-one-core", None, "no planner, one core", "the `default`, beside PiZero", "30 min, 1 core",
                  f"pizero train --env collect --planner none --seed 0 {TRAIN} {ONE_CORE}; {EVAL}",
                  [run(T + "collect_rank1", "collect-none")]),
            agent("none-beside-default", None, "no planner, one core", "the `default`, side by side with PiZero's",
                  "30 min, 1 core each",
                  "pizero train --env collect --method es --seed S --run-dir R --minutes 30 --eval-every-minutes 10 "
                  f"--eval-episodes 200 --no-progress --workers 1; {EVAL}",
                  [run(T + "collect_pizero_gumbel_side_by_side", f"none-seed{seed}") for seed in (3, 4)]),
        ],
        "paired": [],
    },
    {
        "env": "sokoban", "title": "Sokoban", "page": "docs/sokoban.md", "score": "goals covered, of 4",
        "decimals": 3,
        "about": "Boxoban levels (10x10, 4 boxes, 50 moves), trained on unfiltered train, scored on 1,000 "
                 "unfiltered valid levels; goals covered at the end",
        "target": {"score": 1.0, "text": "1.0 goals covered or more"},
        "references": refs(T + "sokoban", "sokoban-pizero", **{"random": "random_score"}),
        "setup": f"L={L}",
        "agents": [
            agent("alphazero", "alphazero", "AlphaZero (true simulator)", "its defaults", "30 min, 1 core",
                  f"pizero train --env sokoban --method alphazero --seed 0 --env-arg levels=$L/train "
                  f"--eval-env-arg levels=$L/valid {TRAIN}; {EVAL} --env-arg levels=$L/valid",
                  [run(T + "collect_sokoban_baselines", "sokoban-alphazero")]),
            agent("muzero", "muzero", "MuZero (learned model)", "its defaults", "30 min, 1 core",
                  f"pizero train --env sokoban --method muzero --seed 0 --env-arg levels=$L/train "
                  f"--eval-env-arg levels=$L/valid {TRAIN}; {EVAL} --env-arg levels=$L/valid",
                  [run(T + "collect_sokoban_baselines", "sokoban-muzero")]),
            agent("pizero", "pizero", "PiZero (ES, gumbel planner)",
                  "the `default`: Gumbel search, 4 simulations (one per abstract action), four levels per member",
                  "30 min, 1 core each",
                  "pizero train --env sokoban --seed S --env-arg levels=$L/train --eval-env-arg levels=$L/valid "
                  "--run-dir R --minutes 30 --eval-every-minutes 10 --eval-episodes 200 --no-progress --workers 1; "
                  f"{EVAL} --env-arg levels=$L/valid",
                  [run(T + "sokoban_pizero_gumbel_side_by_side", f"pizero-seed{seed}") for seed in SOKOBAN_PAIRS]),
            agent("pizero-muzero-10", None, "PiZero, MuZero's search",
                  "`--planner muzero --simulations 10 --episodes-per-member 1`", "30 min, 1 core",
                  "pizero train --env sokoban --planner muzero --simulations 10 --seed 0 --episodes-per-member 1 "
                  "--env-arg levels=$L/train "
                  f"--eval-env-arg levels=$L/valid {TRAIN} {ONE_CORE}; {EVAL} --env-arg levels=$L/valid",
                  [run(T + "sokoban", "sokoban-pizero")]),
            agent("none", "none", "no planner (ES, `--planner none`)", "the `default`: four levels per member",
                  "30 min, 1 core each",
                  f"pizero train --env sokoban --planner none --seed S --episodes-per-member 4 "
                  f"--env-arg levels=$L/train --eval-env-arg levels=$L/valid {TRAIN} {ONE_CORE} --no-pin-cores; "
                  f"{EVAL} --env-arg levels=$L/valid",
                  [run(T + "sokoban_sampled_actions", "argmax, 4 levels per member"),
                   run(T + "sokoban_levels_per_member_seed1", "four_levels_seed1"),
                   run(T + "sokoban_tsp_planner_free_seed2", "sokoban-none-seed2")]),
            agent("none-beside-default", None, "no planner, one core", "the `default`, side by side with PiZero's",
                  "30 min, 1 core each",
                  "pizero train --env sokoban --method es --seed S --env-arg levels=$L/train --eval-env-arg "
                  "levels=$L/valid --run-dir R --minutes 30 --eval-every-minutes 10 --eval-episodes 200 --no-progress "
                  f"--workers 1; {EVAL} --env-arg levels=$L/valid",
                  [run(T + "sokoban_pizero_gumbel_side_by_side", f"none-seed{seed}") for seed in SOKOBAN_PAIRS]),
        ],
        "paired": [],
    },
    {
        "env": "2048", "title": "2048", "page": "docs/2048.md", "score": "game score at 1,000 moves",
        "decimals": 0, "about": "Jumanji's 2048 cut at 1,000 moves; the game score on 1,000 held-out games",
        "target": {"score": 5000, "text": "5,000 or more at horizon 1,000"},
        "references": refs(T + "2048_planner_and_hidden_128", "pizero-planner",
                           **{"greedy one-step": "greedy_score", "random": "random_score"}),
        "agents": [
            agent("alphazero", "alphazero", "AlphaZero (true simulator)",
                  "sampled futures; self-play on 200-move games with log2 tiles, its 2048 default",
                  "30 min, 1 core",
                  f"pizero train --env 2048 --method alphazero --seed 0 {TRAIN} --eval-env-arg horizon=1000; "
                  f"{EVAL} --env-arg horizon=1000",
                  [run(T + "alphazero_sampled", "2048-alphazero-sampled")]),
            agent("muzero", "muzero", "MuZero (learned model)", "200-move games, log2 tiles", "30 min, 1 core",
                  f"pizero train --env 2048 --method muzero --seed 0 {TRAIN} --eval-env-arg horizon=1000; "
                  f"{EVAL} --env-arg horizon=1000",
                  [run(T + "2048_baselines", "2048-muzero")]),
            agent("pizero", "pizero", "PiZero (ES, muzero planner)",
                  "MuZero's search with 10 simulations, two games per member (the `default`: Gumbel's with 4, four "
                  "games)", "30 min, 1 core",
                  f"pizero train --env 2048 --planner muzero --simulations 10 --seed 0 --episodes-per-member 2 {TRAIN} "
                  f"{ONE_CORE}; "
                  f"{EVAL} --env-arg horizon=1000",
                  [run(T + "2048_planner_and_hidden_128", "pizero-planner")]),
            agent("none", "none", "no planner (ES, `--planner none`)",
                  "the `default`: four games per member, the whole machine",
                  "30 min, 2 workers (the whole 2-core machine)",
                  f"pizero train --env 2048 --planner none --seed S --episodes-per-member 4 {TRAIN} --workers 2 "
                  f"--cpus-per-worker 1 --no-pin-cores; {EVAL} --env-arg horizon=1000",
                  [run(T + "2048_episodes_per_member_faster_machine", "four_games_two_workers_seed0"),
                   run(T + "2048_episodes_per_member_faster_machine", "four_games_two_workers_seed1"),
                   hand(2, 5075, [4903, 5246], 968,
                        SEED2_DOCS.format(pages="the README, docs/learning.md and docs/2048.md", commit="3837d5b"))]),
            agent("none-one-core", None, "no planner, one core", "four games per member", "30 min, 1 core",
                  f"pizero train --env 2048 --planner none --seed 0 --episodes-per-member 4 {TRAIN} {ONE_CORE}; "
                  f"{EVAL} --env-arg horizon=1000",
                  [run(T + "2048_episodes_per_member_second_round", "one-hot-tiles-4-episodes-per-member")]),
        ],
        "paired": [],
    },
    {
        "env": "flp", "title": "flp", "page": "docs/flp.md", "score": "minus the largest client distance",
        "decimals": 4, "about": "3 facilities for 20 uniform clients; minus the largest client-to-facility distance",
        "target": {"score": -0.403, "text": "-0.403 or higher, k-means' score"},
        "references": refs(T + "flp_pizero_today_default", "pizero_flp_seed0",
                           **{"Lloyd": "lloyd_score", "k-means": "kmeans_score",
                              "farthest-first": "farthest_first_score", "random placement": "random_score"}),
        "hand_references": [
            {"name": "best placement that ignores the instance", "score": -0.4361, "source": FIXED_PLACEMENT}],
        "agents": [
            agent("alphazero", "alphazero", "AlphaZero (true simulator)",
                  "16x16 grid of actions, 32 simulations, its FLP default", "30 min, 1 core",
                  f"pizero train --env flp --method alphazero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "flp_baseline_candidates", "flp-alphazero-sims32")]),
            agent("muzero", "muzero", "MuZero (learned model)", "8x8 grid of actions, its FLP default",
                  "30 min, 1 core", f"pizero train --env flp --method muzero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "flp_baseline_candidates", "flp-muzero-grid8")]),
            agent("pizero", "pizero", "PiZero (ES, muzero planner)",
                  "the `default`: grid view, weight decay 0.01, 12 instances per member", "30 min, 1 core each",
                  f"pizero train --env flp --seed S {TRAIN} {ONE_CORE} --no-pin-cores; {EVAL}",
                  [run(T + "flp_pizero_today_default", "pizero_flp_seed0"),
                   run(T + "flp_planner_against_none_seed1_paired", "pizero-seed1")]),
            agent("none", "none", "no planner (ES, `--planner none`)", "the `default`", "30 min, 1 core each",
                  f"pizero train --env flp --planner none --seed S --weight-decay 0.01 --episodes-per-member 12 "
                  f"{TRAIN} {ONE_CORE} --no-pin-cores; {EVAL}",
                  [run(T + "flp_twelve_instances_sokoban_one_level",
                       "flp weight decay 0.01, 12 instances per member, seed 0"),
                   run(T + "flp_twelve_instances_seeds", "flp_12_instances_seed1"),
                   hand(2, -0.4467, [-0.4494, -0.4441], 19817,
                        SEED2_DOCS.format(pages="the README, docs/learning.md and docs/flp.md", commit="1dc325c"))]),
        ],
        "paired": [
            {"a": "pizero", "b": "none", "budget": "equal time (30 minutes, one core each)",
             "file": T + "flp_planner_against_none_seed1_paired.json", "key": ["paired_comparison"],
             "run_a": "pizero-seed1", "run_b": "none-seed1"},
        ],
    },
    {
        "env": "flp-mean", "title": "flp-mean", "page": "docs/flp.md", "score": "minus the mean client distance",
        "decimals": 4, "about": "the same game as flp; minus the mean client-to-facility distance",
        "target": {"score": -0.201, "text": "-0.201 or higher, k-means' score"},
        "references": refs(T + "flp_pizero_today_default", "pizero_flp_mean_seed0",
                           **{"Lloyd": "lloyd_score", "k-means": "kmeans_score",
                              "farthest-first": "farthest_first_score", "random placement": "random_score"}),
        "hand_references": [
            {"name": "best placement that ignores the instance", "score": -0.2353, "source": FIXED_PLACEMENT}],
        "agents": [
            agent("alphazero", "alphazero", "AlphaZero (true simulator)", "as on flp", "30 min, 1 core",
                  f"pizero train --env flp-mean --method alphazero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "flp_baseline_candidates", "flp-mean-alphazero-sims32")]),
            agent("muzero", "muzero", "MuZero (learned model)", "as on flp", "30 min, 1 core",
                  f"pizero train --env flp-mean --method muzero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "flp_baseline_candidates", "flp-mean-muzero-grid8")]),
            agent("pizero", "pizero", "PiZero (ES, muzero planner)", "the `default`", "30 min, 1 core",
                  f"pizero train --env flp-mean --seed 0 {TRAIN} {ONE_CORE} --no-pin-cores; {EVAL}",
                  [run(T + "flp_pizero_today_default", "pizero_flp_mean_seed0")]),
            agent("none", "none", "no planner (ES, `--planner none`)", "the `default`", "30 min, 1 core each",
                  f"pizero train --env flp-mean --planner none --seed S --weight-decay 0.01 --episodes-per-member 12 "
                  f"{TRAIN} {ONE_CORE} --no-pin-cores; {EVAL}",
                  [run(T + "flp_twelve_instances_seeds", "flp_mean_12_instances_seed0"),
                   run(T + "flp_twelve_instances_seeds", "flp_mean_12_instances_seed1"),
                   hand(2, -0.2340, [-0.2354, -0.2326], 19737,
                        SEED2_DOCS.format(pages="the README, docs/learning.md and docs/flp.md", commit="1dc325c"))]),
        ],
        "paired": [],
    },
    {
        "env": "pacman", "title": "Pac-Man", "page": "docs/pacman.md", "score": "reward sum over 128 steps",
        "decimals": 0, "about": "Jumanji's PacMan cut at 128 steps; the reward sum on 1,000 held-out games",
        "target": {"score": 400, "text": "400 or more (stretch: 800)"},
        "references": refs(T + "pacman_sampled", "pacman-es-seed0", **{"random": "random_score"}),
        "agents": [
            agent("alphazero", "alphazero", "AlphaZero (true simulator)", "sampled futures, its default",
                  "30 min, 1 core", f"pizero train --env pacman --method alphazero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "alphazero_sampled", "pacman-alphazero-sampled")]),
            agent("muzero", "muzero", "MuZero (learned model)", "1,024 episodes of replay, its Pac-Man default",
                  "30 min, 1 core", f"pizero train --env pacman --method muzero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "baseline_candidates", "pacman-muzero-replay1024")]),
            agent("pizero", "pizero", "PiZero (ES, muzero planner)", "the `default`: sampled actions",
                  "30 min, 1 core each", f"pizero train --env pacman --seed S {TRAIN} {ONE_CORE}; {EVAL}",
                  [run(T + "pacman_sampled", "pacman-pizero-seed0"),
                   run(T + "pacman_pizero_seeds_1_2", "pacman-pizero-seed1"),
                   run(T + "pacman_pizero_seeds_1_2", "pacman-pizero-seed2")]),
            agent("none", "none", "no planner (ES, `--planner none`)", "the `default`", "30 min, 1 core each",
                  f"pizero train --env pacman --planner none --seed S {TRAIN} {ONE_CORE}; {EVAL}",
                  [run(T + "pacman_sampled", "pacman-es-seed0"), run(T + "pacman_sampled", "pacman-es-seed1"),
                   hand(2, 1930, [1930, 1930], 6952,
                        SEED2_DOCS.format(pages="the README, docs/learning.md and docs/pacman.md",
                                          commit="61e6e40"))]),
        ],
        "paired": [],
    },
    {
        "env": "pacman-po", "title": "pacman-po", "page": "docs/pacman.md", "score": "reward sum over 128 steps",
        "decimals": 0,
        "about": "Pac-Man seen through a 5x5 window; the agent must remember the rest in its memory",
        "target": {"score": 300, "text": "300 or more, and above the same agent with its memory zeroed",
                   "beats_memory_zeroed": True},
        "references": refs(T + "pacman_sampled", "pacman-po-es-seed0", **{"random": "random_score"}),
        "agents": [
            agent("alphazero", "alphazero", "AlphaZero (true simulator)", "as on pacman", "30 min, 1 core",
                  f"pizero train --env pacman-po --method alphazero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "alphazero_sampled", "pacman-po-alphazero-sampled")]),
            agent("muzero", "muzero", "MuZero (learned model)", "as on pacman", "30 min, 1 core",
                  f"pizero train --env pacman-po --method muzero --seed 0 {TRAIN}; {EVAL}",
                  [run(T + "baseline_candidates", "pacman-po-muzero-replay1024")]),
            agent("pizero", "pizero", "PiZero (ES, muzero planner)", "as on pacman", "30 min, 1 core each",
                  f"pizero train --env pacman-po --seed S {TRAIN} {ONE_CORE}; {EVAL} [--zero-memory]",
                  [run(T + "pacman_sampled", "pacman-po-pizero-seed0",
                       zeroed="pacman-po-pizero-seed0-memory-zeroed"),
                   run(T + "pacman_pizero_seeds_1_2", "pacman-po-pizero-seed1",
                       zeroed_hand={"score": 70, "ci95": [68, 73],
                                    "source": "docs only: published in docs/pacman.md (commit 1dc325c); "
                                              "the JSON holds the intact score only"}),
                   run(T + "pacman_pizero_seeds_1_2", "pacman-po-pizero-seed2",
                       zeroed_hand={"score": 177, "ci95": [174, 180],
                                    "source": "docs only: published in docs/pacman.md (commit 1dc325c); "
                                              "the JSON holds the intact score only"})]),
            agent("none", "none", "no planner (ES, `--planner none`)", "as on pacman", "30 min, 1 core each",
                  f"pizero train --env pacman-po --planner none --seed S {TRAIN} {ONE_CORE}; "
                  f"{EVAL} [--zero-memory]",
                  [run(T + "pacman_sampled", "pacman-po-es-seed0", zeroed="pacman-po-es-seed0-memory-zeroed"),
                   run(T + "pacman_sampled", "pacman-po-es-seed1", zeroed="pacman-po-es-seed1-memory-zeroed"),
                   hand(2, 2038, [2031, 2044], 7560,
                        SEED2_DOCS.format(pages="the README, docs/learning.md and docs/pacman.md", commit="61e6e40"),
                        zeroed={"score": 123, "ci95": [120, 126]})]),
        ],
        "paired": [],
    },
]

RULE = "a target counts as reached only when the mean over at least 3 seeds is past it"


def _load(file: str, cache: dict) -> dict:
    if file not in cache:
        cache[file] = json.loads((RESULTS / file).read_text())
    return cache[file]


def mean(values: list[float]) -> float:
    """The mean of figures as written (decimal, so that rounding it half up gives what a reader computes)."""
    return float(sum(Decimal(repr(v)) for v in values) / len(values))


def _seed(entry: dict, cache: dict) -> dict:
    if entry.get("hand"):
        out = {k: v for k, v in entry.items() if k != "zeroed"}
        if "zeroed" in entry:
            out["memory_zeroed"] = {**entry["zeroed"], "hand": True, "source": entry["source"]}
        return out
    data = _load(entry["file"], cache)
    found = data["runs"][entry["run"]]
    held = found["held_out"]
    out = {"seed": found["seed"], "score": held["mean_score"], "ci95": held["ci95"],
           "iterations": found["iterations"], "source": {"file": "docs/results/" + entry["file"], "run": entry["run"]}}
    solved = held.get("references", {}).get("solved_fraction")
    if solved is not None:
        out["solved_fraction"] = solved
    if "zeroed" in entry:
        zeroed = data["runs"][entry["zeroed"]]["held_out"]
        out["memory_zeroed"] = {"score": zeroed["mean_score"], "ci95": zeroed["ci95"],
                                "source": {"file": "docs/results/" + entry["file"], "run": entry["zeroed"]}}
    if "zeroed_hand" in entry:
        out["memory_zeroed"] = {**entry["zeroed_hand"], "hand": True}
    return out


def _reached(target: dict, seeds: list[dict], value: float) -> bool:
    if len(seeds) < 3 or value < target["score"]:
        return False
    if target.get("beats_memory_zeroed"):
        return all("memory_zeroed" in s and s["score"] > s["memory_zeroed"]["score"] for s in seeds)
    return True


def _paired(spec: dict, cache: dict) -> dict:
    if spec.get("hand"):
        return {k: v for k, v in spec.items()}
    data = _load(spec["file"], cache)
    found = data
    for key in spec["key"]:
        found = found[key]
    run_a, run_b = data["runs"][spec["run_a"]], data["runs"][spec["run_b"]]
    if (run_a["iterations"], run_b["iterations"]) != (found["iteration_a"], found["iteration_b"]) \
            or run_a["seed"] != run_b["seed"]:
        raise ValueError(f"{spec['file']}: {spec['run_a']} and {spec['run_b']} are not the compared runs")
    return {"a": spec["a"], "b": spec["b"], "budget": spec["budget"], "seed": run_a["seed"],
            "difference": found["mean_difference"], "ci95": found["ci95"],
            "score_a": found["mean_score_a"], "score_b": found["mean_score_b"],
            "iterations_a": found["iteration_a"], "iterations_b": found["iteration_b"],
            "share_a_higher": found["share_a_higher"], "share_tied": found["share_tied"],
            "share_b_higher": found["share_b_higher"], "episodes": found["episodes"],
            "command": data["command"],
            "source": {"file": "docs/results/" + spec["file"], "key": spec["key"],
                       "runs": [spec["run_a"], spec["run_b"]]}}


def build() -> dict:
    cache: dict = {}
    environments = []
    for spec in SPEC:
        ref_data = _load(spec["references"]["file"], cache)["runs"][spec["references"]["run"]]["held_out"]
        references = [{"name": name, "score": ref_data["references"][key],
                       "source": {"file": "docs/results/" + spec["references"]["file"],
                                  "run": spec["references"]["run"], "key": key}}
                      for name, key in spec["references"]["keys"].items()]
        references += [{**r, "hand": True} for r in spec.get("hand_references", [])]
        agents = []
        for a in spec["agents"]:
            seeds = [_seed(entry, cache) for entry in a["runs"]]
            value = mean([s["score"] for s in seeds])
            agents.append({**{k: v for k, v in a.items() if k != "runs"}, "seeds": seeds, "n_seeds": len(seeds),
                           "mean": value, "reached": _reached(spec["target"], seeds, value)})
        target = dict(spec["target"])
        target["reached_by"] = [a["key"] for a in agents if a["reached"]]
        target["reached"] = bool(target["reached_by"])
        target["source"] = "the project's targets for 30 minutes of training (set before any of these runs)"
        environments.append({
            **{k: spec[k] for k in ("env", "title", "page", "score", "decimals", "about")},
            "higher_is_better": True,
            **({"natural_unit": {"name": spec["natural_unit"], "is": "minus the score"}}
               if "natural_unit" in spec else {}),
            **({"setup": spec["setup"]} if "setup" in spec else {}),
            "target": target, "references": references, "agents": agents,
            "paired": [_paired(p, cache) for p in spec["paired"]],
        })
    sources = {}
    for file in sorted(cache):
        data = cache[file]
        sources["docs/results/" + file] = {k: data[k] for k in ("command", "summarised_at_commit", "commit", "machine")
                                           if k in data}
    return {
        "about": "Every published 30-minute result: per environment and agent, each seed's held-out score "
                 "(pizero eval R --episodes 1000 --seed 0, 95% interval over the episodes), the mean over seeds, "
                 "the target and whether it is reached, and the paired comparisons. Higher is better everywhere. "
                 "Built by python scripts/build_summary.py from the JSONs in sources; pages by "
                 "python scripts/render_results.py. Entries with hand: true exist only in the docs (their source "
                 "says where).",
        "evaluation": EVAL,
        "interval": "95% interval over the 1,000 episodes",
        "budget": "30 minutes of training on a 2-core CPU machine",
        "rule": RULE,
        "environments": environments,
        "sources": sources,
    }


def text() -> str:
    return json.dumps(build(), indent=1, ensure_ascii=False) + "\n"


def hand_entries(summary: dict) -> list[str]:
    """Every figure typed here rather than read from a JSON, one line each."""
    lines = []
    for env in summary["environments"]:
        for ref in env["references"]:
            if ref.get("hand"):
                lines.append(f"{env['env']} reference {ref['name']}: {ref['score']} ({ref['source']})")
        for a in env["agents"]:
            for s in a["seeds"]:
                if s.get("hand"):
                    lines.append(f"{env['env']} {a['key']} seed {s['seed']}: {s['score']} {s['ci95']} ({s['source']})")
                zeroed = s.get("memory_zeroed", {})
                if zeroed.get("hand"):
                    lines.append(f"{env['env']} {a['key']} seed {s['seed']} memory zeroed: {zeroed['score']} "
                                 f"{zeroed['ci95']} ({zeroed['source']})")
        for p in env["paired"]:
            if p.get("hand"):
                lines.append(f"{env['env']} paired {p['a']}-{p['b']} {p['budget']}: {p['difference']} {p['ci95']} "
                             f"({p['source']})")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if docs/results/summary.json is stale")
    parser.add_argument("--hand", action="store_true", help="list the figures that exist only in the docs")
    args = parser.parse_args(argv)
    new = text()
    if args.hand:
        print("\n".join(hand_entries(json.loads(new))))
        return 0
    if args.check:
        if not OUT.exists() or OUT.read_text() != new:
            print("docs/results/summary.json is stale: python scripts/build_summary.py", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(new)
    return 0


if __name__ == "__main__":
    sys.exit(main())
