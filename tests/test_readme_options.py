"""The README's option table says what the declared settings say: the same flags, the same defaults."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from pizero_ray.cli import commands, training
from pizero_ray.config import Config
from pizero_ray.settings import Setting, declared
from pizero_ray.trainer.options import RunOptions

README = Path(__file__).resolve().parents[1] / "README.md"
HEADER = "| option | meaning | default |"
CLI_OWN = {"--preset"}  # train's own options in the table: not a field of Config or RunOptions
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:e-?\d+)?(?=\s|$)")


def _table() -> list[tuple[list[str], list[str]]]:
    """(flags, default items) of each row of the README's option table."""
    lines = README.read_text().splitlines()
    start = lines.index(HEADER) + 2  # past the header and its |---| line
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        option, _meaning, default = [cell.strip() for cell in line.strip().strip("|").split("|")]
        rows.append((re.findall(r"`(--[a-z][a-z-]*)", option), [item.strip() for item in default.split(", ")]))
    return rows


def _settings() -> dict[str, Setting]:
    return {s.flag: s for cls in (Config, RunOptions) for s in declared(cls) if s.flag}


def test_the_table_lists_every_declared_setting_and_nothing_else():
    table = [flag for flags, _ in _table() for flag in flags]
    assert len(table) == len(set(table)), "a flag is listed twice"
    declared_flags = set(_settings())
    assert declared_flags - set(table) == set(), "declared but missing from the README table"
    assert set(table) - declared_flags == CLI_OWN, "in the README table but not declared"
    (sub,) = [a for a in commands.build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    assert set(table) <= set(sub.choices["train"]._option_string_actions)


def test_the_defaults_in_the_table_are_the_declared_ones():
    settings = _settings()
    compared = 0
    for flags, items in _table():
        if len(items) != len(flags):
            continue  # one default for several flags: prose
        for flag, item in zip(flags, items):
            if flag in CLI_OWN:
                continue
            setting = settings[flag]
            default = training.DEFAULT_ITERATIONS if flag == "--iterations" else setting.default
            number = NUMBER.match(item)
            if number:  # "300", "0.01", "0 (off)"
                assert isinstance(default, (int, float)) and not isinstance(default, bool), (flag, item, default)
                assert float(number.group()) == default, f"README says {flag} defaults to {item}, declared {default}"
                compared += 1
            elif re.fullmatch(r"`[^`]+`", item) and setting.choices is not None:  # `muzero`
                assert item.strip("`") == default, f"README says {flag} defaults to {item}, declared {default!r}"
                compared += 1
    assert compared >= 25, compared  # the table was read
