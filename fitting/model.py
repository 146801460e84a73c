"""The fit's forward model and residuals (JAX, float64).

Per sample pixel of photo p with albedo class c:

    observed ~ level[p, c] * (1 + g_p . uv) * (1 - alpha * (1 - rho)),
    alpha = profile(u) blurred by a Gaussian of tau = sqrt(blur^2 + 1/12) |du/dpixel|,

where u is softshadow's penumbra coordinate at the pixel's ground point (a
function of k, the sun and the pose), the 1/12 is the pixel's own area (a
box of one pixel), and blur is the camera's optical blur in pixels. Bounds
are kept by reparameterisation: k = K_SCALE softplus(raw_k),
rho = sigmoid(raw_rho), blur = raw_blur^2 (pixels).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from softshadow.params import Pose, Sun
from softshadow.penumbra import blurred_profile_alpha
from softshadow.plan import PointPlan, plan_coordinate

__all__ = ["PhotoArrays", "FitConfig", "K_SCALE", "k_from_raw", "raw_from_k", "rho_from_raw",
           "raw_from_rho", "predict_photo", "angular_pixel_gradient", "residuals", "pseudo_huber"]

K_SCALE = 0.01


def k_from_raw(raw):
    return K_SCALE * jax.nn.softplus(raw)


def raw_from_k(k):
    x = np.asarray(k, dtype=np.float64) / K_SCALE
    return np.where(x > 30, x, np.log(np.expm1(np.maximum(x, 1e-12))))


def rho_from_raw(raw):
    return jax.nn.sigmoid(raw)


def raw_from_rho(rho):
    rho = np.clip(np.asarray(rho, dtype=np.float64), 1e-6, 1 - 1e-6)
    return np.log(rho / (1 - rho))


class PhotoArrays(eqx.Module):
    """One photo's samples as JAX arrays (padded: weight 0 on padding)."""

    ground: Float[Array, "n 3"]
    jac: Float[Array, "n 2 2"]
    observed: Float[Array, " n"]
    weight: Float[Array, " n"]
    albedo_class: Int[Array, " n"]
    uv_norm: Float[Array, "n 2"]
    plan: PointPlan
    sun_azimuth_deg: Float[Array, ""]
    sun_elevation_deg: Float[Array, ""]
    scale: Float[Array, ""]  # the photo's lit level, so residuals are relative
    grad_t_pixel: Float[Array, " n"]  # |d T / d pixel| at the start (T: the angular tangent)


class FitConfig(eqx.Module):
    """Choices of a fit. Only ``rule`` is static; the switches are traced (0/1), so every
    combination shares one compiled solver: disk (profile: 0 linear, 1 disk), fit_blur,
    fit_sun (a switched-off term keeps its parameter with zero effect), huber_delta (0: plain
    least squares)."""

    disk: Float[Array, ""]
    fit_blur: Float[Array, ""]
    fit_sun: Float[Array, ""]
    huber_delta: Float[Array, ""]
    rule: str = eqx.field(static=True, default="edge")

    @classmethod
    def make(cls, profile="linear", fit_blur=False, fit_sun=False, huber_delta=0.0, rule="edge"):
        f = lambda x: jnp.asarray(float(x))
        return cls(f(profile == "disk"), f(fit_blur), f(fit_sun), f(huber_delta), rule)

    @property
    def profile(self) -> str:
        return "disk" if float(self.disk) > 0.5 else "linear"


def pseudo_huber(r, delta):
    """Residual transform whose square is the pseudo-Huber loss (robust to clutter)."""
    # = sign(r) sqrt(2 delta^2 (sqrt(1 + (r/delta)^2) - 1)), written without a sqrt at 0.
    return r * jnp.sqrt(2.0 / (1.0 + jnp.sqrt(1.0 + (r / delta) ** 2)))


@eqx.filter_jit
def angular_pixel_gradient(photo: PhotoArrays, pose: Pose, sun: Sun, k, rule: str = "edge"):
    """|dT/dpixel| (n,): how fast the angular tangent T changes per image pixel.

    It depends on the geometry only (not on k), so it is computed once per solve;
    the model then gets |du/dpixel| = du/dT * this, without differentiating u twice.
    """
    u, grad_pixel = _coordinate_and_pixel_gradient(photo, pose, sun, k, rule)
    _, dudt = plan_coordinate(photo.ground, photo.plan, pose, sun, k, rule, with_slope=True)
    slope = jnp.sqrt(jnp.sum(grad_pixel**2, -1))
    ok = dudt > 0
    return jnp.where(ok, slope / jnp.where(ok, dudt, 1.0), 0.0)


def _coordinate_and_pixel_gradient(photo: PhotoArrays, pose: Pose, sun: Sun, k, rule: str):
    def coord(points):
        return plan_coordinate(points, photo.plan, pose, sun, k, rule)

    ex = jnp.zeros_like(photo.ground).at[:, 0].set(1.0)
    ey = jnp.zeros_like(photo.ground).at[:, 1].set(1.0)
    u, du_dx = jax.jvp(coord, (photo.ground,), (ex,))
    _, du_dy = jax.jvp(coord, (photo.ground,), (ey,))
    grad_ground = jnp.stack([du_dx, du_dy], -1)  # (n, 2)
    grad_pixel = jnp.einsum("nij,ni->nj", photo.jac, grad_ground)  # J^T grad
    return u, grad_pixel


def predict_photo(params: dict, index: int, photo: PhotoArrays, pose: Pose, config: FitConfig):
    """Predicted linear values (n,) and alpha (n,) for photo ``index``."""
    k = k_from_raw(params["raw_k"])
    rho = rho_from_raw(params["raw_rho"])
    az = photo.sun_azimuth_deg + config.fit_sun * params["sun_delta_deg"][0]
    el = photo.sun_elevation_deg + config.fit_sun * params["sun_delta_deg"][1]
    u, dudt = plan_coordinate(photo.ground, photo.plan, pose, Sun(az, el), k, config.rule,
                              with_slope=True)
    blur = config.fit_blur * params["raw_blur"] ** 2  # blur = raw^2: a regular minimum at 0
    slope = dudt * photo.grad_t_pixel
    tau = jnp.sqrt(blur**2 + 1.0 / 12.0) * slope
    alpha = ((1.0 - config.disk) * blurred_profile_alpha(u, tau, "linear")
             + config.disk * blurred_profile_alpha(u, tau, "disk"))
    level = jnp.exp(params["log_level"][index][photo.albedo_class])
    level = level * (1.0 + photo.uv_norm @ params["gradient"][index])
    return level * (1.0 - alpha * (1.0 - rho)), alpha


def residuals(params: dict, args):
    """Weighted relative residuals of all photos, concatenated (robust-transformed if asked)."""
    photos, pose, config = args
    out = []
    for i, photo in enumerate(photos):
        pred, _ = predict_photo(params, i, photo, pose, config)
        r = photo.weight * (photo.observed - pred) / photo.scale
        robust = pseudo_huber(r, jnp.maximum(config.huber_delta, 1e-12))
        out.append(jnp.where(config.huber_delta > 0, robust, r))
    return jnp.concatenate(out)
