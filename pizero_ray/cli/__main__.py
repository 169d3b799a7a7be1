"""``python -m pizero_ray.cli``: the ``pizero`` command."""

import sys

from pizero_ray.cli.commands import main

sys.exit(main())
