"""`pizero bench`: the command's face over ``pizero_ray.bench``, where the measurements live."""

from pizero_ray.bench.plans import FULL, QUICK, BenchPlan
from pizero_ray.bench.run_plan import run
from pizero_ray.bench.summary import table, to_json

__all__ = ["FULL", "QUICK", "BenchPlan", "run", "table", "to_json"]
