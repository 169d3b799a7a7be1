"""docs/options.md, generated from the settings declared once: every option of ``pizero train`` and what the
presets change. ``python -m pizero_ray.cli.reference > docs/options.md`` writes it; a test holds the file to it.

Pure Python: no Ray, no JAX.
"""

from __future__ import annotations

from typing import Any

from pizero_ray import presets
from pizero_ray.cli.training import DEFAULT_ITERATIONS
from pizero_ray.config import Config
from pizero_ray.settings import Setting, declared
from pizero_ray.trainer.options import RunOptions

HEADER = """# Options of `pizero train`

Generated from the settings declared once, in their fields of `Config`
(pizero_ray/config.py) and `RunOptions`/`PoolOptions` (pizero_ray/trainer/options.py),
and from pizero_ray/presets.py: `python -m pizero_ray.cli.reference > docs/options.md`
rewrites this page, and `tests/cli/test_reference.py` fails when it is stale.
`pizero train --help` is generated from the same declarations. `chaos` takes
the same options; `resume` the run options (the second table).

Every option is checked before anything is written: a bad value is a one-line
error naming it, exit code 2. `--preset NAME` (`default`, `paper`, `gpu`, `tiny`)
chooses the defaults an option overrides; a later section lists what each
preset changes, and the last every other command's own options.
"""


def _cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _default(s: Setting) -> str:
    if s.name == "iterations":  # train's own default, where neither --iterations nor --minutes is given
        return f"{DEFAULT_ITERATIONS} (with `--minutes` alone: no limit)"
    if not s.has_default or s.default is None or s.default == ():
        return "none"
    if s.type is bool:
        return "not given"  # a flag: given, it turns its setting's default around
    if s.name == "compile_cache":  # the same page whoever generates it, wherever
        return "`$PIZERO_COMPILE_CACHE`, else ~/.cache/pizero-ray/jax"
    if isinstance(s.default, tuple):
        return ",".join(map(str, s.default))
    return f"{s.default:g}" if isinstance(s.default, float) else str(s.default)


def _meaning(s: Setting) -> str:
    notes = presets.method_env_notes(s.name)
    text = s.help + (f" ({'; '.join(notes)})" if notes else "")
    return text + (f"; one of {', '.join(f'`{c}`' for c in s.allowed)}" if s.choices is not None else "")


def options_table(cls: type) -> list[str]:
    """A Markdown table of the declared settings of ``cls`` that have a flag."""
    rows = ["| option | meaning | default |", "|---|---|---|"]
    for s in declared(cls):
        if s.flag is not None:
            flag = f"`{s.flag} {s.metavar}`" if s.metavar else f"`{s.flag}`"
            rows.append(f"| {flag} | {_cell(_meaning(s))} | {_cell(_default(s))} |")
    return rows


def _overrides(values: dict[str, Any]) -> str:
    flags = {s.name: s.flag or s.name for s in declared(Config)}

    def shown(name: str, value: Any) -> str:
        if isinstance(value, dict):  # env_args
            return ", ".join(f"`--env-arg {k}={v}`" for k, v in value.items())
        if isinstance(value, tuple):  # a list setting, as its flag takes it
            return f"`{flags.get(name, name)} {','.join(map(str, value))}`"
        return f"`{flags.get(name, name)} {value}`"

    return "; ".join(shown(name, value) for name, value in values.items()) or "nothing"


def presets_table() -> list[str]:
    """What each preset changes, in the order ``build_config`` applies them."""
    rows = ["| applies to | preset | changes |", "|---|---|---|"]
    rows += [f"| every environment | `{name}` | {_overrides(values)} |" for name, values in presets.PRESETS.items()]
    for env in presets.ENV_PRESETS:  # as build_config reads them (the gpu preset takes the env's default)
        rows += [f"| `--env {env}` | `{name}` | {_overrides(values)} |" for name in presets.PRESETS
                 if (values := presets.env_preset(env, name))]
    rows += [f"| `--method {method}` | any | {_overrides(values)} |"
             for method, values in presets.METHOD_PRESETS.items()]
    rows += [f"| `--method {method} --env {env}` | any | {_overrides(values)} |"
             for (method, env), values in presets.METHOD_ENV_PRESETS.items()]
    rows += [f"| `--method pizero --env {env}` | {', '.join(f'`{name}`' for name in presets.PIZERO_PRESETS)} | "
             f"{_overrides(values)} |" for env, values in presets.PIZERO_ENV_PRESETS.items()]
    return rows


def _command_parsers() -> dict:
    import argparse

    from pizero_ray.cli import commands

    (sub,) = [a for a in commands.build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return sub.choices


# The commands whose declared settings are the tables above; every other command's options are listed whole.
_SETTINGS_COMMANDS = ("train", "chaos", "resume")
_EVERY_COMMANDS_OWN = ("-h", "--help", "--verbose")  # said once, in the section's first line


def command_tables() -> list[str]:
    """Every command's own options, from its argparse parser (train's, chaos's and resume's but the declared
    settings, which the tables above list): with them the page names every flag of the CLI."""
    import argparse

    settings = {s.flag for cls in (Config, RunOptions) for s in declared(cls) if s.flag}
    lines = []
    for name, parser in _command_parsers().items():
        skipped = set(_EVERY_COMMANDS_OWN) | (settings if name in _SETTINGS_COMMANDS else set())
        rows = []
        for action in parser._actions:
            flags = [flag for flag in action.option_strings if flag not in skipped]
            if not flags:
                continue
            shown = f"{flags[-1]} {action.metavar}" if action.metavar else flags[-1]
            default = action.default
            if default in (None, False, [], argparse.SUPPRESS):
                default = ""
            elif isinstance(default, tuple):
                default = ",".join(map(str, default))
            rows.append(f"| `{shown}` | {_cell(action.help or '')} | {_cell(default)} |")
        if rows:
            lines += [f"### `pizero {name}`", "", "| option | meaning | default |", "|---|---|---|", *rows, ""]
    return lines


def options_reference() -> str:
    """The whole of docs/options.md."""
    parts = [HEADER, "## What is computed (the run's config.json)", "",
             "`--preset NAME`: the defaults below are overridden by the preset's (`default` unless named).", "",
             *options_table(Config), "", "## How it runs (`train`, `resume`, `chaos`)", "",
             *options_table(RunOptions), "", "## What the presets change", "",
             "Applied in this order, then the options given: the preset, its environment's, the method's,",
             "the method's on that environment (PiZero's: in the `default` and `gpu` presets only).", "",
             *presets_table(), "",
             "## Every command's own options", "",
             "Besides the settings above, which `train`, `chaos` and `resume` take as the tables say. Every",
             "command also takes `--help` and `--verbose` (an unexpected error's whole traceback, not one line).",
             "",
             *command_tables()]
    return "\n".join(parts).rstrip("\n") + "\n"


if __name__ == "__main__":
    print(options_reference(), end="")
