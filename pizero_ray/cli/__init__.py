"""The ``pizero`` command and its reports (eval, render, plot, bench): the thin impure shell."""

from pizero_ray.cli.commands import main

__all__ = ["main"]
