"""markerplace: plan fiducial marker (AprilTag) placement for visual localization (OMP).

Importing the package first points the caches of numba, matplotlib, Mesa and Dask at one
folder, ``$MARKERPLACE_CACHE`` (:mod:`markerplace.runtime.cache_home`), before any of them is
loaded: nothing is written outside ``--out`` and that folder.
"""

from markerplace.runtime.cache_home import setup as _setup_cache

_setup_cache()

__version__ = "0.1.0"
