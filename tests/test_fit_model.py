"""The fit's forward model against independent computations (finite differences)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from softshadow import Pose, ShadowParams, SoftShadowModel, Sun
from softshadow.camera import look_at_camera
from softshadow.internal import plan_coordinate

K = 0.01


def _oblique_view():
    """A pillar's shadow seen obliquely (pixel footprints are neither square nor axis-aligned)."""
    from fitting.photos.views import PhotoView
    model = SoftShadowModel.from_mesh("pillar", profile="disk")
    sun = Sun(130.0, 35.0)
    camera = look_at_camera((2.0, 4.0, 2.5), (-1.5, 1.3, 0.0), 320, 240, 60.0)
    shading = np.asarray(model.camera_image(ShadowParams(K, 0.3), sun, Pose(), camera).shading)
    gray = np.nan_to_num(0.7 * shading, nan=0.7).astype(np.float32)
    view = PhotoView("oblique.png", gray, np.zeros(gray.shape, bool), camera=camera,
                     sun_azimuth_deg=sun.azimuth_deg, sun_elevation_deg=sun.elevation_deg,
                     sun_source="given")
    return model, sun, view


def test_pixel_gradient_of_u_matches_finite_differences():
    """|du/dpixel| = du/dT * |dT/dpixel| (what sets the blur in u units) against central
    differences of u between neighbouring pixels, on an oblique camera."""
    from fitting.solve.model import angular_pixel_gradient
    from fitting.samples.ground import select_samples
    from fitting.solve.group import _group_arrays
    model, sun, view = _oblique_view()
    samples = select_samples(model, Pose(), view, range_k_max=0.03, max_samples=4000, seed=0)
    group = _group_arrays([samples], [view])
    n = len(samples.observed)
    grad_t = np.asarray(angular_pixel_gradient(group, Pose(), K, "edge"))[:n]
    # dT/dpixel is a property of the geometry; a wide ramp puts many samples inside it.
    k_wide = 0.03
    u, dudt = (np.asarray(x)[:n] for x in plan_coordinate(group.ground, group.plan, Pose(), sun,
                                                          k_wide, with_slope=True))
    model_slope = grad_t * dudt

    def u_at(dcol, drow):
        cols, rows = samples.uv[:, 0] + dcol, samples.uv[:, 1] + drow
        pts, _, _ = view.ground_of_pixels(cols, rows)
        padded = np.zeros(np.shape(group.ground))
        padded[:n] = pts
        return np.asarray(plan_coordinate(jnp.asarray(padded), group.plan, Pose(), sun, k_wide))[:n]

    h = 0.05
    du_dcol = (u_at(h, 0) - u_at(-h, 0)) / (2 * h)
    du_drow = (u_at(0, h) - u_at(0, -h)) / (2 * h)
    fd_slope = np.hypot(du_dcol, du_drow)
    # A central difference across a kink (the nearest edge changes within +-h pixels, at the
    # outline's corners) is no derivative: keep the samples whose one-sided differences agree.
    u0 = u_at(0, 0)
    smooth = ((np.abs((u_at(h, 0) - u0) - (u0 - u_at(-h, 0))) <= 1e-3 * h * (np.abs(du_dcol) + 1e-9) + 1e-9)
              & (np.abs((u_at(0, h) - u0) - (u0 - u_at(0, -h))) <= 1e-3 * h * (np.abs(du_drow) + 1e-9) + 1e-9))
    inside = (np.abs(u) < 0.8) & np.isfinite(fd_slope) & smooth
    assert inside.sum() >= 20, "too few samples inside the penumbra to compare"
    np.testing.assert_allclose(model_slope[inside], fd_slope[inside], rtol=2e-3)


def test_residual_jacobian_matches_finite_differences():
    """The solver's Jacobian (custom JVPs for the shadow's shape and the blurred profile)
    against central differences of the residuals, at a generic point with blur and robust
    loss switched on."""
    import dataclasses

    from fitting.solve.model import FitConfig, FitParams, raw_from_k, residuals
    from fitting.samples.ground import select_samples
    from fitting.solve.group import _group_arrays, _prepare, initial_params
    model, sun, view = _oblique_view()
    samples = select_samples(model, Pose(), view, range_k_max=0.03, max_samples=400, seed=0)
    group = _group_arrays([samples], [view])
    params, _ = initial_params([samples])
    config = FitConfig.make("disk", True, True, 0.05, "edge")
    grad_t, _ = _prepare(params, jnp.asarray(raw_from_k(np.array([K]))), group, Pose(), config)
    group = dataclasses.replace(group, grad_t_pixel=grad_t)
    params = dataclasses.replace(params, raw_k=jnp.asarray(float(raw_from_k(0.008))), raw_blur=jnp.asarray([0.4]),
                                 sun_delta_deg=jnp.asarray([0.1, -0.05]))
    flat = params.vector()
    fn = lambda x: residuals(FitParams.from_vector(x, 1), (group, Pose(), config))
    jac = np.asarray(jax.jacfwd(fn)(flat))
    h = 1e-6
    for i in range(len(flat)):
        e = np.zeros(len(flat))
        e[i] = h
        fd = (np.asarray(fn(flat + e)) - np.asarray(fn(flat - e))) / (2 * h)
        np.testing.assert_allclose(jac[:, i], fd, atol=2e-6 * max(1.0, np.abs(fd).max()),
                                   err_msg=f"column {i}")
