"""PiZero trained by OpenAI-ES on Ray, as a library and a command (``pizero``).

The public API (docs/api.md): ``train`` and ``resume`` a run dir, ``evaluate``
and ``compare`` runs, ``load_agent`` to act with a trained agent in a loop of
your own. Each is what the ``pizero`` command of the same name does. They
load on first use (``pizero_ray.api``): importing the math below them
(``pizero_ray.agent``, ``pizero_ray.es``) stays free of storage and Ray.
"""

from importlib import metadata

try:
    __version__ = metadata.version("pizero-ray")
except metadata.PackageNotFoundError:  # a checkout on sys.path, not installed
    __version__ = "unknown"

__all__ = ["TrainedAgent", "__version__", "compare", "evaluate", "load_agent", "resume", "train"]


def __getattr__(name: str):
    if name in __all__:
        from pizero_ray import api

        return getattr(api, name)
    raise AttributeError(f"module 'pizero_ray' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
