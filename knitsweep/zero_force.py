"""Deprecated import path: the zero-force stage lives in ``knitsweep.relax.zero_force``.

``zero_force`` and ``ZeroForce``, the public API documented under this name before the
move, are re-exported here with a DeprecationWarning; import them from
``knitsweep.relax.zero_force``.
"""

import warnings

from .relax.zero_force import ZeroForce, zero_force

warnings.warn("knitsweep.zero_force is deprecated: import zero_force and ZeroForce from "
              "knitsweep.relax.zero_force", DeprecationWarning, stacklevel=2)  # fmt: skip

__all__ = ["ZeroForce", "zero_force"]
