"""Array types for annotations checked at test time (jaxtyping with beartype).

``AnyArray``: a JAX or a NumPy array, for functions that take an array module ``xp`` or serve
both the differentiable (JAX) and the discrete (NumPy) steps. ``ArrayLike``: what JAX accepts as
an array (Python scalars, NumPy and JAX arrays), for inputs converted inside.
"""

from __future__ import annotations

import numpy as np
from jaxtyping import Array, ArrayLike

__all__ = ["AnyArray", "ArrayLike"]

AnyArray = Array | np.ndarray
