"""The results on every page, generated from docs/results/summary.json (and docs/results/planning.json).

Usage::

    python scripts/render_results.py            # rewrites every generated block of README.md and docs/*.md
    python scripts/render_results.py --check    # exit 1, naming the pages, if rewriting would change one

A generated block sits between ``<!-- generated: NAME (python scripts/render_results.py) -->`` and
``<!-- end generated -->``; the rest of a page is hand-written. The blocks:

- ``results`` (README.md): one row per environment, one column per agent, the target, and "what the plan is
  worth" from docs/results/planning.json once it is committed (its shuffled-plan and one-simulation paired
  differences for PiZero at its default configuration, averaged over seeds, and the runs' training minutes; "not
  measured yet" while the file has no such rows);
  then which targets are reached and the paired comparisons.
- ``scores``, ``paired`` and ``hand`` (docs/learning.md): every agent's seeds with their intervals, the paired
  comparisons, and the figures that exist only in the docs.
- ``current-best`` (each environment's page): its agents, references, target and paired comparisons, and the
  commands that reproduce them.
- ``baselines`` (docs/baselines.md): AlphaZero and MuZero on every environment.

Scores are higher-is-better everywhere (TSP's is minus the tour length, written beside it).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from decimal import Decimal
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SUMMARY = REPO / "docs" / "results" / "summary.json"
PLANNING = REPO / "docs" / "results" / "planning.json"
BEGIN = "<!-- generated: {name} (python scripts/render_results.py) -->"
END = "<!-- end generated -->"
BLOCK = re.compile(r"<!-- generated: (\S+) \(python scripts/render_results\.py\) -->\n.*?<!-- end generated -->",
                   re.DOTALL)
NOT_MEASURED = "not measured yet"
COLUMNS = (("alphazero", "AlphaZero (true simulator)"), ("muzero", "MuZero (learned model)"),
           ("pizero", "PiZero (ES, planner)"), ("none", "no planner (ES)"))


# ------------------------------------------------------------------ numbers as written

def number(value: float, decimals: int, sign: bool = False) -> str:
    """``value`` at ``decimals`` places (thousands separated when whole), as Python formats it: the rounding
    every figure the pages quote was first written with."""
    text = f"{value:,.{decimals}f}" if decimals == 0 else f"{value:.{decimals}f}"
    if text.startswith("-") and not text.strip("-0.,"):
        text = text[1:]
    return ("+" + text) if sign and not text.startswith("-") else text


def as_written(value: float | int) -> str:
    """A number set by hand (a target) as it was set: no digits added or dropped."""
    return f"{value:,}" if isinstance(value, int) else repr(value)


def interval(ci95: list[float], decimals: int, sign: bool = False) -> str:
    return f"({number(ci95[0], decimals, sign)}, {number(ci95[1], decimals, sign)})"


def _places(env: dict, seed: dict | None = None) -> int:
    return seed.get("decimals", env["decimals"]) if seed else env["decimals"]


def seed_score(env: dict, seed: dict, with_interval: bool = True) -> str:
    text = number(seed["score"], _places(env, seed))
    if with_interval:
        text += " " + interval(seed["ci95"], _places(env, seed))
    return text


def seed_name(seed: dict) -> str:
    return seed["label"] if seed.get("label") else f"seed {seed['seed']}"


def _mean(env: dict, agent: dict) -> str:
    return number(agent["mean"], env["decimals"])


def _link(page: str, target: str) -> str:
    """A relative link from ``page`` to ``target`` (both repo paths)."""
    return os.path.relpath(target, start=os.path.dirname(page) or ".")


def _sources(env: dict, agent: dict, page: str) -> str:
    files = []
    for seed in agent["seeds"]:
        if isinstance(seed["source"], dict):
            if seed["source"]["file"] not in files:
                files.append(seed["source"]["file"])
        elif "docs only" not in files:
            files.append("docs only")
    return ", ".join(f"[{Path(f).stem}]({_link(page, f)})" if f != "docs only" else "docs only (below)" for f in files)


# ------------------------------------------------------------------ the README's table

def _best(env: dict) -> dict:
    shown = [a for a in env["agents"] if a["column"]]
    return max(shown, key=lambda a: a["mean"])


def readme_cell(env: dict, agent: dict, best: dict) -> str:
    mean = _mean(env, agent)
    if agent is best:
        mean = f"**{mean}**"
    if agent["n_seeds"] == 1:
        (seed,) = agent["seeds"]
        return f"{mean} {interval(seed['ci95'], _places(env, seed))}, 1 seed"
    each = ", ".join(seed_score(env, s, with_interval=False) + (f" ({s['label']})" if s.get("label") else "")
                     for s in agent["seeds"])
    return f"{mean}, {agent['n_seeds']} seeds: {each}"


def plan_worth(env: dict, planning: dict | None) -> str:
    """What the plan is worth for PiZero at its default configuration, trained for the longest budget measured:
    the mean over seeds of the paired difference (ablated minus intact) with the plan shuffled and with 1
    simulation."""
    if not planning:
        return NOT_MEASURED
    rows = [r for r in planning.get("ablations", []) if r["env"] == env["env"] and r.get("default")]
    minutes = max((r["minutes"] for r in rows), default=None)  # the longest-trained agents
    rows = [r for r in rows if r["minutes"] == minutes]
    parts, seeds = [], set()
    for ablation, name in (("shuffled", "shuffled"), ("simulations=1", "1 simulation")):
        found = [r for r in rows if r["ablation"] == ablation]
        if found:
            value = float(sum(Decimal(repr(r["paired_difference"])) for r in found) / len(found))
            parts.append(f"{name} {number(value, env['decimals'], sign=True)}")
            seeds |= {r["seed"] for r in found}
    if not parts:
        return NOT_MEASURED
    return f"{', '.join(parts)} ({len(seeds)} seed{'s' if len(seeds) != 1 else ''}, {minutes} minutes)"


def _target_cell(env: dict) -> str:
    return f">= {as_written(env['target']['score'])}"


def _references(env: dict, page: str | None = None) -> str:
    return ", ".join(f"{r['name']} {number(r['score'], r.get('decimals', env['decimals']))}"
                     for r in env["references"])


def _agent_name(env: dict, key: str) -> str:
    return {"pizero": "PiZero", "none": "no planner"}.get(key) or next(
        a["label"] for a in env["agents"] if a["key"] == key)


def _below(env: dict, agent: dict) -> str:
    """A reached target's caveat: how many seeds' intervals reach back past it."""
    low = len([s for s in agent["seeds"] if s["ci95"][0] < env["target"]["score"]])
    if not low:
        return ""
    if low == agent["n_seeds"]:
        return f", though each of its {low} seeds' intervals reaches below the target"
    return f", though {low} of its {agent['n_seeds']} seeds' intervals reach below the target"


def reached_lines(summary: dict) -> list[str]:
    reached, short = [], []
    for env in summary["environments"]:
        by = [a for a in env["agents"] if a["reached"]]
        target = as_written(env["target"]["score"])
        if by:
            means = "; ".join(f"{_agent_name(env, a['key'])} {_mean(env, a)}{_below(env, a)}" for a in by)
            extra = ", each seed above its memory zeroed" if env["target"].get("beats_memory_zeroed") else ""
            reached.append(f"{env['env']} (target {target}{extra}: {means})")
        else:
            short.append(env["env"])
    return [f"**Targets** count as reached only when the mean over at least 3 seeds is past them. "
            f"Reached: {'; '.join(reached)}. Not reached: {', '.join(short)}."]


def paired_text(env: dict, pair: dict) -> str:
    places = env["decimals"]
    return (f"{env['env']}, seed {pair['seed']}, {pair['budget']}: "
            f"{number(pair['difference'], places, sign=True)} {interval(pair['ci95'], places, sign=True)}")


def paired_lines(summary: dict) -> list[str]:
    pairs = [paired_text(env, p) for env in summary["environments"] for p in env["paired"]]
    if not pairs:
        return []
    return ["**Paired**, PiZero minus the planner-free agent of the same seed on the same 1,000 episodes "
            "(`pizero compare`, 95% BCa interval; below zero: the planner costs): " + "; ".join(pairs) + "."]


def block_results(summary: dict, planning: dict | None, page: str) -> list[str]:
    head = "| env (score) | references | target | " + " | ".join(name for _, name in COLUMNS) + \
           " | what the plan is worth |"
    lines = [head, "|" + "---|" * (len(COLUMNS) + 4)]
    for env in summary["environments"]:
        best = _best(env)
        cells = []
        for column, _ in COLUMNS:
            agents = [a for a in env["agents"] if a["column"] == column]
            parts = [readme_cell(env, a, best) if i == 0 else f"{a['short']}: {readme_cell(env, a, best)}"
                     for i, a in enumerate(agents)]
            cells.append("; ".join(parts) if parts else "")
        name = f"[{env['env']}]({_link(page, env['page'])}) ({env['score']})"
        lines.append(f"| {name} | {_references(env)} | {_target_cell(env)} | " + " | ".join(cells) +
                     f" | {plan_worth(env, planning)} |")
    lines += ["", "Bold: the best point estimate (the mean where there are several seeds). "
              + reached_lines(summary)[0]]
    paired = paired_lines(summary)
    if paired:
        lines += ["", *paired]
    return lines


# ------------------------------------------------------------------ docs/learning.md

def _status(env: dict, agent: dict) -> str:
    if agent["reached"]:
        return "reached"
    if agent["n_seeds"] < 3:
        return f"{agent['n_seeds']} seed{'s' if agent['n_seeds'] > 1 else ''}: not counted"
    return "not reached"


def block_scores(summary: dict, planning: dict | None, page: str) -> list[str]:
    lines = ["| env (target) | agent | setting | each seed (95% interval) | mean | target | budget | figures |",
             "|---|---|---|---|---|---|---|---|"]
    for env in summary["environments"]:
        for agent in env["agents"]:
            each = "; ".join(f"{seed_score(env, s)} ({seed_name(s)})" for s in agent["seeds"])
            mean = _mean(env, agent) if agent["n_seeds"] > 1 else ""
            lines.append(f"| [{env['env']}]({_link(page, env['page'])}) ({_target_cell(env)}) | {agent['label']} | "
                         f"{agent['setting']} | {each} | {mean} | {_status(env, agent)} | {agent['budget']} | "
                         f"{_sources(env, agent, page)} |")
    return lines


def block_paired(summary: dict, planning: dict | None, page: str) -> list[str]:
    lines = ["| env | seed | budget | PiZero | no planner | PiZero minus no planner (95% BCa) | "
             "episodes PiZero ahead / tied / behind | iterations (PiZero, no planner) | figures |",
             "|---|---|---|---|---|---|---|---|---|"]
    for env in summary["environments"]:
        places = env["decimals"]
        for p in env["paired"]:
            shares = (f"{p['share_a_higher']:.1%} / {p['share_tied']:.1%} / {p['share_b_higher']:.1%}"
                      if "share_a_higher" in p else "")
            its = f"{p['iterations_a']:,}, {p['iterations_b']:,}" if "iterations_a" in p else ""
            source = (f"[{Path(p['source']['file']).stem}]({_link(page, p['source']['file'])})"
                      if isinstance(p["source"], dict) else "docs only (below)")
            lines.append(f"| {env['env']} | {p['seed']} | {p['budget']} | {number(p['score_a'], places)} | "
                         f"{number(p['score_b'], places)} | {number(p['difference'], places, sign=True)} "
                         f"{interval(p['ci95'], places, sign=True)} | {shares} | {its} | {source} |")
    return lines


def block_hand(summary: dict, planning: dict | None, page: str) -> list[str]:
    lines = []
    for env in summary["environments"]:
        for r in env["references"]:
            if r.get("hand"):
                lines.append(f"- {env['env']}, reference {r['name']} "
                             f"{number(r['score'], r.get('decimals', env['decimals']))}: {r['source']}.")
        for agent in env["agents"]:
            for s in agent["seeds"]:
                if s.get("hand"):
                    lines.append(f"- {env['env']}, {agent['label']}, {seed_name(s)}: {seed_score(env, s)}, "
                                 f"{s['iterations']:,} iterations. Source: {s['source']}.")
                zeroed = s.get("memory_zeroed") or {}
                if zeroed.get("hand") and not s.get("hand"):
                    lines.append(f"- {env['env']}, {agent['label']}, {seed_name(s)}, memory zeroed: "
                                 f"{number(zeroed['score'], env['decimals'])} "
                                 f"{interval(zeroed['ci95'], env['decimals'])}. Source: {zeroed['source']}.")
        for p in env["paired"]:
            if p.get("hand"):
                lines.append(f"- {paired_text(env, p)} (PiZero {number(p['score_a'], env['decimals'])}, no planner "
                             f"{number(p['score_b'], env['decimals'])}; `{p['command']}`). Source: {p['source']}.")
    return lines


# ------------------------------------------------------------------ each environment's page

def _extra_columns(envs: list[dict]) -> list[tuple[str, callable]]:
    columns = []
    if any("natural_unit" in env for env in envs):
        columns.append(("tour length (mean)", lambda env, agent: number(-agent["mean"], env["decimals"])
                        if "natural_unit" in env else ""))
    if any("memory_zeroed" in s for env in envs for a in env["agents"] for s in a["seeds"]):
        columns.append(("memory zeroed, each seed", lambda env, agent: "; ".join(
            seed_score(env, s["memory_zeroed"]) for s in agent["seeds"] if "memory_zeroed" in s)))
    if any("solved_fraction" in s for env in envs for a in env["agents"] for s in a["seeds"]):
        columns.append(("levels solved", lambda env, agent: "; ".join(
            f"{s['solved_fraction']:.1%}" for s in agent["seeds"] if "solved_fraction" in s)))
    return columns


def _target_line(env: dict) -> str:
    target = env["target"]
    head = f"**Target ({env['env']}): {target['text']}."
    if target["reached"]:
        by = ", ".join(f"{_agent_name(env, a['key'])} ({a['n_seeds']}-seed mean {_mean(env, a)}{_below(env, a)})"
                       for a in env["agents"] if a["reached"])
        extra = ", each seed above the same agent with its memory zeroed" if target.get("beats_memory_zeroed") else ""
        return f"{head} Reached** by {by}{extra}."
    counted = [a for a in env["agents"] if a["n_seeds"] >= 3]
    if counted:
        best = max(counted, key=lambda a: a["mean"])
        return (f"{head} Not reached:** the best mean over 3 seeds is {_mean(env, best)} "
                f"({_agent_name(env, best['key'])}).")
    return f"{head} Not reached.**"


def _commands(envs: list[dict]) -> list[str]:
    lines = ["```bash"]
    setups = {env["setup"] for env in envs if "setup" in env}
    lines += sorted(setups)
    for env in envs:
        for agent in env["agents"]:
            seeds = ", ".join(str(s["seed"]) for s in agent["seeds"] if s["seed"] is not None)
            what = f" (S = {seeds})" if " --seed S " in agent["command"] else ""
            lines.append(f"# {env['env']}: {agent['label']}, {agent['setting']}{what}")
            lines += [part.strip() for part in agent["command"].split("; ")]
        if any(not p.get("hand") for p in env["paired"]):
            lines += [f"# {env['env']}: paired, PiZero against the planner-free run of the same seed",
                      "pizero compare R_PIZERO R_NONE --episodes 1000 --seed 0"]
    return lines + ["```"]


def block_current_best(summary: dict, planning: dict | None, page: str) -> list[str]:
    envs = [env for env in summary["environments"] if env["page"] == page]
    if not envs:
        raise ValueError(f"{page}: no environment of docs/results/summary.json has this page")
    several = len(envs) > 1
    extra = _extra_columns(envs)
    head = ["env"] * several + ["agent", "setting", "each seed (95% interval)", "mean"] + \
        [name for name, _ in extra] + ["iterations", "budget"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for env in envs:
        best = _best(env)
        for agent in env["agents"]:
            each = "; ".join(seed_score(env, s) + (f" ({s['label']})" if s.get("label") else "")
                             for s in agent["seeds"])
            mean = _mean(env, agent) if agent["n_seeds"] > 1 else ""
            if agent is best:
                mean, each = (f"**{mean}**", each) if mean else ("", f"**{each}**")
            cells = [env["env"]] * several + [agent["label"], agent["setting"], each, mean] + \
                [fn(env, agent) for _, fn in extra] + \
                [", ".join(f"{s['iterations']:,}" for s in agent["seeds"]), agent["budget"]]
            lines.append("| " + " | ".join(cells) + " |")
    lines += ["", f"Held-out score: `{summary['evaluation']}`, {summary['interval']}, after {summary['budget']}. "
              "Higher is better"
              + (" (TSP's score is minus the tour length)" if any("natural_unit" in e for e in envs) else "")
              + ". Bold: the best point estimate" + (" of each environment" if several else "") + "."]
    for env in envs:
        lines += ["", f"References on the same episodes ({env['env']}): {_references(env)}.", "", _target_line(env)]
        pairs = [paired_text(env, p) for p in env["paired"]]
        if pairs:
            lines += ["", "Paired, PiZero minus the planner-free agent on the same 1,000 episodes (`pizero "
                          "compare`, 95% BCa interval): " + "; ".join(pairs) + "."]
    lines += ["", "Reproduce each row (`R` a new run directory, `S` the seed):", "", *_commands(envs)]
    return lines


def block_baselines(summary: dict, planning: dict | None, page: str) -> list[str]:
    lines = ["| env (score) | AlphaZero (true simulator) | MuZero (learned model) |", "|---|---|---|"]
    for env in summary["environments"]:
        cells = []
        for key in ("alphazero", "muzero"):
            agent = next(a for a in env["agents"] if a["key"] == key)
            cells.append(f"{seed_score(env, agent['seeds'][0])}; {agent['setting']}")
        lines.append(f"| [{env['env']}]({_link(page, env['page'])}) ({env['score']}) | " + " | ".join(cells) + " |")
    return lines


BLOCKS = {"results": block_results, "scores": block_scores, "paired": block_paired, "hand": block_hand,
          "current-best": block_current_best, "baselines": block_baselines}


def render(text: str, page: str, summary: dict, planning: dict | None) -> str:
    """``text`` with every generated block rewritten from ``summary`` (and ``planning``)."""
    def replace(match: re.Match) -> str:
        name = match.group(1)
        if name not in BLOCKS:
            raise ValueError(f"{page}: unknown generated block {name!r}")
        body = BLOCKS[name](summary, planning, page)
        return "\n".join([BEGIN.format(name=name), *body, END])
    return BLOCK.sub(replace, text)


def pages(repo: Path = REPO) -> list[Path]:
    return [repo / "README.md", *sorted((repo / "docs").glob("*.md"))]


def committed(path: Path) -> bool:
    """Whether ``path`` is part of the repository: tracked by git (a measurement still writing an untracked
    file has no result yet), or, outside a git work tree, present."""
    def git(*args: str) -> int:
        return subprocess.run(["git", *args], cwd=path.parent, capture_output=True).returncode
    try:
        if git("rev-parse", "--is-inside-work-tree") != 0:
            return path.exists()
        return path.exists() and git("ls-files", "--error-unmatch", path.name) == 0
    except FileNotFoundError:  # no git
        return path.exists()


def load(summary_path: Path = SUMMARY, planning_path: Path | None = None) -> tuple[dict, dict | None]:
    """summary.json, and planning.json: ``planning_path`` if given and present, else docs/results/planning.json
    if it is committed, else None ("not measured yet")."""
    summary = json.loads(summary_path.read_text())
    if planning_path is None:
        planning_path = PLANNING if committed(PLANNING) else None
    planning = json.loads(planning_path.read_text()) if planning_path and planning_path.exists() else None
    return summary, planning


def stale(repo: Path = REPO, summary_path: Path = SUMMARY, planning_path: Path | None = None,
          write: bool = False) -> list[str]:
    """The pages whose generated blocks differ from what the JSONs give (rewritten when ``write``)."""
    summary, planning = load(summary_path, planning_path)
    changed = []
    for path in pages(repo):
        text = path.read_text()
        new = render(text, str(path.relative_to(repo)), summary, planning)
        if new != text:
            changed.append(str(path.relative_to(repo)))
            if write:
                path.write_text(new)
    return changed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a page disagrees with its JSON")
    parser.add_argument("--planning", type=Path, default=None,
                        help="read this planning JSON (default: docs/results/planning.json once it is committed)")
    args = parser.parse_args(argv)
    changed = stale(planning_path=args.planning, write=not args.check)
    if args.check and changed:
        print("stale: " + ", ".join(changed) + " (python scripts/render_results.py)", file=sys.stderr)
        return 1
    for page in changed:
        print(f"rewrote {page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
