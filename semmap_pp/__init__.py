"""semmap_pp: abstract semantic maps from 2D occupancy grids.

Data-driven reversible-jump MCMC over worlds of rectangular space units, with a prior and a
sensor model shaped by editable logic rules (Liu & von Wichert, IROS 2013, re-implemented).
"""

__version__ = "0.1.0"

# cache and config folders that can be written (semmap_pp/userdirs.py: a private one when HOME
# cannot be used), then numba's cache keyed by this package's source (semmap_pp/jitcache.py): set
# before any module defines a compiled function.
from semmap_pp import userdirs as _userdirs  # noqa: E402

_userdirs.configure()

from semmap_pp import jitcache as _jitcache  # noqa: E402

_jitcache.configure()
