"""The penumbra profile seen through a Gaussian blur (JAX): a camera's optical blur plus the pixel.

A pixel sees the profile (``penumbra.profile_alpha``) through its own area and the camera's
blur. Across a shadow edge both together are well described by one Gaussian of standard
deviation tau in penumbra units u (tau = sqrt(1/12 + blur^2) |du/dpixel| for a box pixel of
variance 1/12 px^2 and a blur of ``blur`` px); ``blurred_profile_alpha`` is the profile
convolved with it, accurate for any tau:

- ``linear``: closed form, (tau / 2) (G((1 - u) / tau) - G((-1 - u) / tau)),
  G(y) = E[max(y + Z, 0)] = y Phi(y) + phi(y);
- ``disk``: for tau < WIDE_BLUR_TAU, Gauss-Hermite quadrature over the blur (12 nodes,
  within 2e-4 of the exact convolution); above, the integral over the penumbra of the
  profile's density times Phi((s - u) / tau), midpoint rule in theta with s = cos theta
  (24 nodes, within 1e-6: the disk's density times sin theta is smooth and periodic).

Gauss-Hermite alone is a staircase once tau exceeds the penumbra's half-width (off by 0.006 at
tau = 1 and 0.1 at tau = 5): the case of a penumbra of one or two pixels under a camera blur
of 0.5-0.9 px, where it read the blur low and k 20-33 % high (docs/fitting.md).

The renderer's own images average the profile over the pixel's exact footprint (a box in
each of the pixel's two directions, ``penumbra.footprint_profile_alpha``) and add no camera
blur; this Gaussian is the model of a photographed pixel, the fitter's (``fitting.solve.model``).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import ndtr

from .penumbra import PROFILES, Profile, profile_alpha, profile_slope

__all__ = ["WIDE_BLUR_TAU", "blurred_profile_alpha"]

#: Blur (standard deviation, u units) from which the disk's blurred profile integrates over
#: the penumbra instead of over the Gaussian (see the module's docstring).
WIDE_BLUR_TAU = 0.1
_WIDE_NODES = 24
_NARROW_NODES = 12
_SHARP_TAU = 1e-6  # below this the linear ramp is its unblurred self (keeps 1/tau finite)
_INV_SQRT_2PI = float(1.0 / np.sqrt(2.0 * np.pi))


@functools.cache
def _penumbra_nodes(profile: str, nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes s (M,) in (-1, 1) and weights (M,) of the integral over the penumbra of the
    profile's density -d alpha/ds: the midpoint rule in theta, s = cos theta."""
    theta = (np.arange(nodes) + 0.5) * np.pi / nodes
    s = np.cos(theta)
    with jax.ensure_compile_time_eval():  # constants of the trace, not traced values
        density = -np.asarray(profile_slope(jnp.asarray(s), profile))
    return s, density * np.sin(theta) * np.pi / nodes


def _gauss_hermite(nodes: int, dtype):
    """Nodes and weights (summing to 1) of Gauss-Hermite quadrature for a unit Gaussian."""
    z, w = np.polynomial.hermite_e.hermegauss(nodes)
    return jnp.asarray(z, dtype=dtype), jnp.asarray(w / w.sum(), dtype=dtype)


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _narrow_blurred_alpha(u, tau, profile: str):
    """Gauss-Hermite over the blur (accurate while tau is small against the penumbra). Its JVP
    is two arrays (d/du, d/dtau) formed in the primal pass, so each tangent direction costs one
    product, not a pass over the nodes (a fitter's Jacobian has many)."""
    z, w = _gauss_hermite(_NARROW_NODES, jnp.result_type(u))
    return profile_alpha(u[..., None] + tau[..., None] * z, profile) @ w


@_narrow_blurred_alpha.defjvp
def _narrow_blurred_alpha_jvp(profile, primals, tangents):
    (u, tau), (du, dtau) = primals, tangents
    z, w = _gauss_hermite(_NARROW_NODES, jnp.result_type(u))
    x = u[..., None] + tau[..., None] * z
    slope = profile_slope(x, profile)
    return profile_alpha(x, profile) @ w, (slope @ w) * du + (slope @ (w * z)) * dtau


def _expected_positive_part(y):
    """E[max(y + Z, 0)] for a unit Gaussian Z: y Phi(y) + phi(y)."""
    return y * ndtr(y) + jnp.exp(-0.5 * y * y) * _INV_SQRT_2PI


def blurred_profile_alpha(u, tau, profile: Profile = "linear"):
    """Alpha of ``profile`` seen through a Gaussian of standard deviation ``tau`` (u units).

    u, tau: arrays that broadcast (tau >= 0), float32 or float64; returns alpha of their
    broadcast shape and dtype, in [0, 1]. With tau = 0 it is ``profile_alpha``. Accurate for
    any tau (the linear ramp exactly, the disk within 2e-4); values and gradients in u and tau
    are finite everywhere (at tau = 0, at the branch switch WIDE_BLUR_TAU, far outside).
    """
    u, tau = jnp.broadcast_arrays(jnp.asarray(u), jnp.asarray(tau))
    if profile == "linear":
        sharp = tau < _SHARP_TAU
        t = jnp.where(sharp, 1.0, tau)  # double where: no 0/0 in the unused branch's gradient
        smooth = 0.5 * t * (_expected_positive_part((1.0 - u) / t) - _expected_positive_part((-1.0 - u) / t))
        return jnp.where(sharp, profile_alpha(u, profile), smooth)
    if profile not in PROFILES:
        raise ValueError(f"unknown penumbra profile {profile!r}; choose one of {PROFILES}")
    s, w = (jnp.asarray(a, dtype=u.dtype) for a in _penumbra_nodes(profile, _WIDE_NODES))
    narrow = tau < WIDE_BLUR_TAU
    t = jnp.where(narrow, 1.0, tau)
    wide = ndtr((s - u[..., None]) / t[..., None]) @ w
    return jnp.where(narrow, _narrow_blurred_alpha(u, tau, profile), wide)
