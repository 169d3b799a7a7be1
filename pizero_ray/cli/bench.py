"""`pizero bench`: the command's face over ``pizero_ray.bench``, where the measurements live."""

from pizero_ray.bench.plans import FULL, QUICK, BenchPlan
from pizero_ray.bench.report import table, to_json
from pizero_ray.bench.runner import run

__all__ = ["FULL", "QUICK", "BenchPlan", "run", "table", "to_json"]
