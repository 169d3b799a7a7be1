"""docs/options.md is what the declared settings and presets generate, and lists every option of `pizero train`."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from pizero_ray.cli import commands, reference
from pizero_ray.config import Config
from pizero_ray.settings import declared
from pizero_ray.trainer.options import RunOptions

PAGE = Path(__file__).resolve().parents[2] / "docs" / "options.md"


def _train_options() -> set[str]:
    (sub,) = [a for a in commands.build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return set(sub.choices["train"]._option_string_actions)


def test_the_page_is_what_the_declarations_generate():
    assert PAGE.read_text() == reference.options_reference(), \
        "docs/options.md is stale: python -m pizero_ray.cli.reference > docs/options.md"


def test_every_declared_flag_has_a_row_with_its_default_and_every_row_is_a_train_option():
    rows = [line for cls in (Config, RunOptions) for line in reference.options_table(cls) if line.startswith("| `--")]
    flags = [re.match(r"\| `(--[a-z-]+)", row).group(1) for row in rows]
    declared_flags = [s.flag for cls in (Config, RunOptions) for s in declared(cls) if s.flag]
    assert flags == declared_flags
    assert set(flags) <= _train_options()
    by_flag = dict(zip(flags, rows))
    assert by_flag["--lr"].endswith("| 0.01 |") and by_flag["--planner"].endswith("| muzero |")
    assert by_flag["--workers"].endswith("| 2 |")


def test_the_presets_table_shows_each_override_as_a_flag():
    table = "\n".join(reference.presets_table())
    assert "| every environment | `paper` |" in table and "`--population 1000`" in table
    assert "| `--method alphazero --env tsp` | any | `--simulations 32` |" in table
    assert "| `--env collect` | `default` | `--env-arg view=centred` |" in table
    assert ("| `--method pizero --env tsp` | `default`, `gpu` | `--decoder-inputs action,visits,value,qvalues` |"
            in table)


def test_every_flag_of_every_command_is_on_the_page():
    (sub,) = [a for a in commands.build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    page = PAGE.read_text()
    missing = sorted({f"pizero {name} {flag}" for name, parser in sub.choices.items()
                      for flag in parser._option_string_actions
                      if flag.startswith("--") and not re.search(rf"`{re.escape(flag)}[` ]", page)})
    assert not missing, f"docs/options.md does not name: {missing}"
