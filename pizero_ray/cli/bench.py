"""`pizero bench`: the command's face over ``pizero_ray.bench``, where the measurements live."""

from pizero_ray.bench import FULL, QUICK, BenchPlan, run, table, to_json

__all__ = ["FULL", "QUICK", "BenchPlan", "run", "table", "to_json"]
