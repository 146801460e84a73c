"""The fit's forward model and residuals (JAX, float64).

Per sample pixel of photo p with albedo class c:

    observed ~ level[p, c] * (1 + g_p . uv) * ((1 - rho) c (1 - alpha) + rho (1 - h)),
    alpha = profile(u) blurred by a Gaussian of tau = sqrt(blur^2 + 1/12) |du/dpixel|
            (``softshadow.blurred_profile_alpha``, accurate for any tau),

where u is softshadow's penumbra coordinate at the pixel's ground point (a
function of k, the sun and the pose), the 1/12 is the pixel's own area (a
box of one pixel), blur is the camera's optical blur in pixels, and h the
sky fraction hidden from the pixel's receiver point (``softshadow.sky``; 0 on open
ground, where rho and level are defined) and c the sun's incidence on the
receiver over the open ground's (1 on the ground; ``fitting.samples.receiver_light``).
On the ground this is level (1 - alpha (1 - rho) - rho h). Bounds
are kept by reparameterisation: k = K_SCALE softplus(raw_k),
rho = sigmoid(raw_rho), blur variance = raw_blur[p] (pixels^2, added to the
pixel's 1/12), one per photo: photos of one group are shot with different focus
and shake, and with a penumbra of one or two pixels a blur shared by all of them
is confounded with k (3 photos blurred 0.61/0.66/0.87 px read k 65 % high with
one blur, within 1 % with the same blur in all three).

With the ``wedge`` rule (``FitConfig.rule``) alpha is the blurred profile of the nearest edge (the
``edge`` rule's u) plus ``wedge_excess``: the wedge rule's pixel mean less the edge rule's, 0 along
a lone straight edge, so the fit's blur, slope and u keep their meaning.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from softshadow import Pose, Sun, blurred_profile_alpha, light_direction
from softshadow.internal import PROFILES, PointPlan, plan_alpha, plan_coordinate_light

from ..samples.receiver_light import shadow_factor

__all__ = ["GroupArrays", "FitConfig", "FitParams", "Prediction", "K_SCALE", "k_from_raw", "raw_from_k", "rho_from_raw",
           "raw_from_rho", "predict", "angular_pixel_gradient", "residuals", "pseudo_huber",
           "k_rho_slopes", "sample_light", "edge_terms", "shadow_terms", "residuals_of", "coordinate_rule", "wedge_excess"]

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


def k_rho_slopes(raw_k, raw_rho) -> tuple[float, float]:
    """dk/draw_k and drho/draw_rho at the raw values (NumPy floats, after the solve): the
    reparameterisation's first-order slopes, K_SCALE sigmoid(raw_k) and rho (1 - rho)."""
    rho = 1.0 / (1.0 + np.exp(-float(raw_rho)))
    return float(K_SCALE / (1.0 + np.exp(-float(raw_k)))), float(rho * (1.0 - rho))


class GroupArrays(eqx.Module):
    """All samples of one group as flat JAX arrays (padding has weight 0).

    ground (n, 3) receiver points; jac (n, 3, 2) d(point)/d(col, row); observed (n,); weight (n,); photo (n,) photo index;
    albedo_class (n,); uv_norm (n, 2); plan: one plan for all photos (their edges
    stacked); sun_azimuth_deg, sun_elevation_deg, scale (P,) per photo;
    grad_t_pixel (n,) |dT/dpixel| at the start; sky_hidden (n,) the sky fraction the object
    hides from each sample (``softshadow.sky``); wedge_plan: the ``wedge`` rule's plan at the same
    samples (its own edges; None when the fit does not use that rule), planned over the footprints
    wedge_axes (n, 2, 3): each sample's pixel widened by its photo's camera blur (``wedge_excess``).
    """

    ground: Float[Array, "n 3"]
    jac: Float[Array, "n 3 2"]
    observed: Float[Array, " n"]
    weight: Float[Array, " n"]
    photo: Int[Array, " n"]
    albedo_class: Int[Array, " n"]
    uv_norm: Float[Array, "n 2"]
    plan: PointPlan
    sun_azimuth_deg: Float[Array, " P"]
    sun_elevation_deg: Float[Array, " P"]
    scale: Float[Array, " P"]
    grad_t_pixel: Float[Array, " n"]
    sky_hidden: Float[Array, " n"]
    sun_cos: Float[Array, " n"]
    wedge_plan: PointPlan | None = None
    wedge_axes: Float[Array, "n 2 3"] | None = None


class FitParams(eqx.Module):
    """The fit's parameters (float64 scalars and arrays), bounds kept by reparameterisation.

    raw_k: k = K_SCALE softplus(raw_k). raw_rho: rho = sigmoid(raw_rho).
    raw_blur (P,): each photo's camera blur variance (pixels^2, added to the pixel's own 1/12;
    free in sign). sun_delta_deg (2,): azimuth and elevation corrections (degrees) to every photo's
    sun. log_level (P, 2): each photo's log lit level of the ground (0) and paper (1) classes.
    gradient (P, 2): each photo's linear brightness gradient over the normalised image
    coordinates (exposure, vignetting).

    ``vector`` and ``from_vector`` lay the parameters out in one explicit order (``layout``),
    which the covariance and its named entries use.
    """

    raw_k: Float[ArrayLike, ""]
    raw_rho: Float[ArrayLike, ""]
    raw_blur: Float[ArrayLike, " P"]
    sun_delta_deg: Float[ArrayLike, "2"]
    log_level: Float[ArrayLike, "P 2"]
    gradient: Float[ArrayLike, "P 2"]

    @staticmethod
    def layout(n_photos: int) -> dict[str, slice]:
        """Where each parameter sits in ``vector`` (p = 4 + 5 n_photos entries)."""
        sizes = {"raw_k": 1, "raw_rho": 1, "raw_blur": n_photos, "sun_delta_deg": 2,
                 "log_level": 2 * n_photos, "gradient": 2 * n_photos}
        out, start = {}, 0
        for name, size in sizes.items():
            out[name] = slice(start, start + size)
            start += size
        return out

    @property
    def n_photos(self) -> int:
        return int(self.log_level.shape[0])

    def vector(self):
        """All parameters as one vector (p,), in ``layout`` order."""
        return jnp.concatenate([jnp.reshape(getattr(self, name), -1)
                                for name in self.layout(self.n_photos)])

    @classmethod
    def from_vector(cls, x, n_photos: int) -> "FitParams":
        """Inverse of ``vector`` (x (p,), JAX or NumPy)."""
        lay = cls.layout(n_photos)
        shapes = {"raw_k": (), "raw_rho": (), "raw_blur": (n_photos,), "sun_delta_deg": (2,),
                  "log_level": (n_photos, 2), "gradient": (n_photos, 2)}
        return cls(**{name: x[lay[name]].reshape(shapes[name]) for name in lay})


class FitConfig(eqx.Module):
    """Choices of a fit. ``profile`` and ``rule`` are static (one compiled solver each); the
    switches are traced (0/1), so their combinations share one compiled solver: fit_blur,
    fit_sun (a switched-off term keeps its parameter with zero effect), huber_delta (0: plain
    least squares)."""

    fit_blur: Float[Array, ""]
    fit_sun: Float[Array, ""]
    huber_delta: Float[Array, ""]
    profile: str = eqx.field(static=True, default="linear")
    rule: str = eqx.field(static=True, default="edge")

    @classmethod
    def make(cls, profile="linear", fit_blur=False, fit_sun=False, huber_delta=0.0, rule="edge"):
        if profile not in PROFILES:
            raise ValueError(f"unknown penumbra profile {profile!r}; choose one of {PROFILES}")
        f = lambda x: jnp.asarray(float(x), dtype=jnp.float64)
        return cls(f(fit_blur), f(fit_sun), f(huber_delta), profile, rule)


def pseudo_huber(r, delta):
    """Residual transform whose square is the pseudo-Huber loss (robust to clutter)."""
    # = sign(r) sqrt(2 delta^2 (sqrt(1 + (r/delta)^2) - 1)), written without a sqrt at 0.
    return r * jnp.sqrt(2.0 / (1.0 + jnp.sqrt(1.0 + (r / delta) ** 2)))


def sample_light(group: GroupArrays, sun_delta_deg, fit_sun) -> Float[Array, "n 3"]:
    """Light direction (n, 3) at each sample: its photo's sun plus the fitted correction."""
    az = group.sun_azimuth_deg + fit_sun * sun_delta_deg[0]
    el = group.sun_elevation_deg + fit_sun * sun_delta_deg[1]
    return light_direction(az, el).T[group.photo]


@eqx.filter_jit
def angular_pixel_gradient(group: GroupArrays, pose: Pose, k, rule: str = "edge"):
    """|dT/dpixel| (n,): how fast the angular tangent T changes per image pixel.

    It depends on the geometry only (not on k), so it is computed once per solve;
    the model then gets |du/dpixel| = du/dT * this, without differentiating u twice.
    """
    light = sample_light(group, jnp.zeros(2), 0.0)

    def coord(points):
        return plan_coordinate_light(points, group.plan, pose, light, k, coordinate_rule(rule), with_slope=True)

    # Along the receiver's two pixel directions (the columns of d(point)/d(col, row)) in one
    # batched JVP: one trace of the edge geometry, and any receiver surface (not only z = 0).
    axes = jnp.moveaxis(group.jac, -1, 0)  # (2, n, 3)
    (_, dudt), (du, _) = jax.vmap(lambda t: jax.jvp(coord, (group.ground,), (t,)),
                                  out_axes=((None, None), (0, 0)))(axes)
    grad_pixel = du.T
    slope = jnp.sqrt(jnp.sum(grad_pixel**2, -1))
    ok = dudt > 0
    return jnp.where(ok, slope / jnp.where(ok, dudt, 1.0), 0.0)


def _shape_vector(params: FitParams) -> Float[Array, " shape"]:  # (3 + P,)
    """The parameters the shadow's shape depends on: raw_k, sun azimuth and elevation
    corrections (degrees), then each photo's raw_blur (P,). The rest (levels, gradients, rho)
    enter linearly."""
    return jnp.concatenate([jnp.stack([params.raw_k, params.sun_delta_deg[0], params.sun_delta_deg[1]]),
                            jnp.reshape(params.raw_blur, -1)])


def _edge_terms_per_sample(geometry: Float[Array, "3"], raw_blur: Float[Array, " n"], group: GroupArrays,
                           pose: Pose, config: FitConfig):
    """``edge_terms`` from raw_k and the sun corrections (3,) and each sample's own raw blur (n,)."""
    k = k_from_raw(geometry[0])
    light = sample_light(group, geometry[1:3], config.fit_sun)
    u, dudt = plan_coordinate_light(group.ground, group.plan, pose, light, k, coordinate_rule(config.rule),
                                    with_slope=True)
    # Blur variance (px^2) added to the pixel's own 1/12, free in sign so that "no blur" is an
    # interior point (a regular minimum, quick to converge) rather than a boundary.
    variance = 1.0 / 12.0 + config.fit_blur * raw_blur
    slope = dudt * group.grad_t_pixel
    tau = jnp.sqrt(jnp.maximum(variance, 1e-3)) * slope
    alpha = blurred_profile_alpha(u, tau, config.profile)
    if config.rule == "wedge":
        alpha = jnp.clip(alpha + wedge_excess(group, pose, light, k, config.profile), 0.0, 1.0)
    return alpha, u, slope


def coordinate_rule(rule: str) -> str:
    """The rule whose penumbra coordinate u the fit uses: the ``wedge`` rule's alpha is the nearest
    edge's (``edge`` rule) plus ``wedge_excess``, so u, the pixel's slope and the blur are the edge
    rule's there."""
    return "edge" if rule == "wedge" else rule


class _SampleSun(Sun):
    """A sun whose light direction is given per sample (n, 3) (each photo's sun with the fit's
    correction); ``plan_alpha`` reads only ``light``."""

    per_sample: Float[Array, "n 3"]

    def __init__(self, per_sample):
        super().__init__(180.0, 45.0)
        self.per_sample = per_sample

    @property
    def light(self):
        return self.per_sample


def wedge_excess(group: GroupArrays, pose: Pose, light: Float[Array, "n 3"], k, profile: str) -> Float[Array, " n"]:
    """The ``wedge`` rule's alpha less the nearest edge's (``edge`` rule), both as means over each
    sample's footprint ``group.wedge_axes`` (n,): 0 where one straight edge governs it (the two
    means are the same there), and what crowded edges change elsewhere (gaps narrower than the
    penumbra, overlapping parts, corners). The footprint is the pixel widened to the variance of
    the pixel and its photo's camera blur (a box of side sqrt(1 + 12 b^2) pixels, b the blur of
    the edge fit the wedge plan was made after), so the excess is seen through about the blur the
    nearest edge's ramp is (``blurred_profile_alpha``, with the fit's own blur)."""
    if group.wedge_plan is None or group.wedge_axes is None:
        raise ValueError("the wedge rule needs the samples' wedge plan (GroupArrays.wedge_plan, wedge_axes)")
    axes = group.wedge_axes
    sun = _SampleSun(light)
    wedge = plan_alpha(group.ground, group.wedge_plan, pose, sun, k, "wedge", profile, pixel_axes=axes)
    edge = plan_alpha(group.ground, group.plan, pose, sun, k, "edge", profile, pixel_axes=axes)
    return wedge - edge


def edge_terms(shape: Float[Array, " shape"], group: GroupArrays, pose: Pose, config: FitConfig):
    """Alpha (n,), penumbra coordinate u (n,) and |du/dpixel| (n,) from the shape vector."""
    return _edge_terms_per_sample(shape[:3], shape[3:][group.photo], group, pose, config)


@jax.custom_jvp
def shadow_terms(shape: Float[Array, " shape"], group: GroupArrays, pose: Pose, config: FitConfig):
    """Alpha, u and |du/dpixel| (n,) each, as ``edge_terms``, differentiable in ``shape`` only
    (the fit's constants group, pose and config get no derivative).

    Its JVP forms the (n, 3) Jacobians of the geometry and the (n,) derivatives in each
    sample's own blur once, in the primal pass (a photo's blur moves only its own samples, so
    P blurs cost one pass, not P); the solver's Jacobian with respect to all the fit's
    parameters (3 + 5 per photo + rho) then costs one small product per column instead of a
    pass through the edge geometry each (the tangents of outputs nobody uses are dropped by XLA).
    """
    return edge_terms(shape, group, pose, config)


@shadow_terms.defjvp
def _shadow_terms_jvp(primals, tangents):
    shape, group, pose, config = primals
    (tangent,) = tangents[:1]
    blur = shape[3:][group.photo]
    out, linear = jax.linearize(lambda g, b: _edge_terms_per_sample(g, b, group, pose, config), shape[:3], blur)
    jacs = jax.vmap(lambda e: linear(e, jnp.zeros_like(blur)), out_axes=1)(jnp.eye(3, dtype=shape.dtype))
    # Sample i depends on its own blur only: one pass with all ones gives every derivative.
    dblur = linear(jnp.zeros(3, dtype=shape.dtype), jnp.ones_like(blur))
    tangent_blur = tangent[3:][group.photo]
    return out, tuple(j @ tangent[:3] + d * tangent_blur for j, d in zip(jacs, dblur))


def _shaded(params: FitParams, group: GroupArrays, alpha):
    """Linear values (n,): each photo's open-ground lit level and gradient times the shadow
    factor on the receiver (``receiver_light.shadow_factor``: rho is the sky's share on open
    horizontal ground; the sun's incidence and the sky seen set a tilted face's levels)."""
    rho = rho_from_raw(params.raw_rho)
    level = jnp.exp(params.log_level[group.photo, group.albedo_class])
    level = level * (1.0 + jnp.sum(group.uv_norm * params.gradient[group.photo], -1))
    return level * shadow_factor(alpha, rho, group.sun_cos, 1.0 - group.sky_hidden)


class Prediction(NamedTuple):
    """The model at every sample: linear values (n,), alpha (n,), penumbra coordinate u (n,)
    and |du/dpixel| (n,)."""

    values: Float[Array, " n"]
    alpha: Float[Array, " n"]
    u: Float[Array, " n"]
    slope: Float[Array, " n"]


def predict(params: FitParams, group: GroupArrays, pose: Pose, config: FitConfig) -> Prediction:
    """The model's values and edge terms at every sample (``Prediction``)."""
    alpha, u, slope = shadow_terms(_shape_vector(params), group, pose, config)
    return Prediction(_shaded(params, group, alpha), alpha, u, slope)


def residuals_of(prediction: Prediction, group: GroupArrays, config: FitConfig):
    """Weighted residuals (n,) of a prediction, relative to each photo's lit level
    (robust-transformed if asked)."""
    r = group.weight * (group.observed - prediction.values) / group.scale[group.photo]
    robust = pseudo_huber(r, jnp.maximum(config.huber_delta, 1e-12))
    return jnp.where(config.huber_delta > 0, robust, r)


def residuals(params: FitParams, args):
    """``residuals_of`` the model at ``params``; args = (group, pose, config)."""
    group, pose, config = args
    return residuals_of(predict(params, group, pose, config), group, config)
