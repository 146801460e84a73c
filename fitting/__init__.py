"""fitting: range k and brightness rho of outdoor soft shadows, per time of day, from photos.

Its subpackages, one job each, top floor first (each imports only those below it):

- ``folder``: the entry points: one folder (``fit_folder``, ``fit_and_report``), many folders on Dask
  (``fit_many``), the resume store;
- ``solve``: one time of day: the pixel model, optimistix least squares, errors, levels of detail;
- ``verdict``: the rule book: reliable, identifiable, bounds and warnings from the fit's evidence;
- ``samples``: which pixels a fit uses, on every kind of receiver;
- ``edges``: the no-geometry path: shadow edges found and measured in one photo;
- ``photos``: reading photos, their times, cameras (a ChArUco board), suns and groups;
- ``report``: results.json, the paper's Table 2, plots and index.html.

Fits run in float64, scoped to the fitting call (``jax.enable_x64``), so the caller's own precision is kept.
"""

import lazy_loader as _lazy

# The public names are listed in ``__init__.pyi``; each is imported on first use (PEP 562,
# ``lazy_loader``): a folder of photos without geometry is measured without loading JAX,
# optimistix or trimesh, whose imports take seconds.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
