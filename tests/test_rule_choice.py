"""The fitter's choice of the penumbra's rule per group (``FitOptions.rule = "auto"``,
``fitting.solve.rule_choice``): a lone post keeps the ``edge`` rule, a fence of thin posts whose
gaps are narrower than the penumbra takes the ``wedge`` rule and then reads what the ``wedge``
rule asked for reads; the rule is reported. The fence is fitted once per rule for the whole
module (the ``wedge`` rule's solver is the dearest program here to compile)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from fitting import FitOptions, PhotoView, fit_group
from fitting.solve.options import sampling_rule
from fitting.solve.rule_choice import WEDGE_THRESHOLD
from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun
from gradcheck import assert_jacobian_matches_central_differences

SUN = Sun(200.0, 35.0)  # no face of the posts edge-on to the sun
RHO, LEVEL = 0.3, 0.6
HEIGHT = 0.3


def _posts(xs, width):
    """Vertical square posts (width, width, HEIGHT) standing at x = xs on the ground."""
    boxes = []
    for x in xs:
        box = trimesh.creation.box((width, width, HEIGHT))
        box.apply_translation((x, 0.0, HEIGHT / 2))
        boxes.append(box)
    return trimesh.util.concatenate(boxes)


def _view(mesh: trimesh.Trimesh, k: float, noise: float, *, centre: float, side_m: float, seed: int = 0
          ) -> PhotoView:
    """A top-down photo (96 x 96 px of side_m / 96) of the mesh's shadow drawn by the ``wedge``
    rule (the sun's hidden fraction, as sunlight does) at k, with Gaussian noise of that fraction
    of the lit level; centred at ``centre`` of the way from the foot to the shadow's tip."""
    light = np.asarray(SUN.light_np)
    tip = np.array([0.0, 0.0, HEIGHT]) + light * (HEIGHT / -light[2])
    grid = GroundGrid.around((centre * tip[0], centre * tip[1]), side_m, 96)
    truth = SoftShadowModel.from_mesh(mesh, rule="wedge", profile="disk")
    shading = np.asarray(truth.ground_map(ShadowParams(k, RHO), SUN, Pose(), grid), np.float64)
    rng = np.random.default_rng(seed)
    gray = LEVEL * (shading + rng.normal(0.0, noise, shading.shape))
    return PhotoView("top.png", gray.astype(np.float32), np.zeros(gray.shape, bool), grid=grid,
                     sun_azimuth_deg=float(SUN.azimuth_deg), sun_elevation_deg=float(SUN.elevation_deg),
                     sun_source="given")


def _fit(mesh: trimesh.Trimesh, view: PhotoView, rule: str = "auto", blur: bool = False):
    options = FitOptions(rule=rule, blur=(blur,), plots=False, max_samples_per_photo=900)
    return fit_group(SoftShadowModel.from_mesh(mesh), Pose(), [view], "g", None, options)


K_FENCE = 0.01


@pytest.fixture(scope="module")
def fence_fits():
    """The fence (posts 12 mm wide, 6 mm apart; the penumbra is 2 k d wide, up to 10 mm at the
    shadows' far end) fitted with ``auto`` and with the ``wedge`` rule asked for, the camera blur
    free (the wedge rule's footprints then follow the plain solve's blur); one fit of each, shared
    by the tests below (the wedge solver compiles once)."""
    fence = _posts(np.arange(-2.5, 3.0) * 0.018, 0.012)
    view = _view(fence, K_FENCE, 0.012, centre=0.5, side_m=0.48)
    return _fit(fence, view, "auto", True), _fit(fence, view, "wedge", True)


def test_the_wedge_and_auto_rules_sample_and_start_with_the_edge_rule():
    assert sampling_rule("auto") == sampling_rule("wedge") == "edge" and sampling_rule("paper") == "paper"


def test_a_lone_post_keeps_the_edge_rule():
    # The straight sides of its shadow in view (the tip, 0.43 m from the foot, is out of it), a
    # penumbra of one or two pixels and noise 1.2 % of the lit level, as the demo's photos: the
    # two rules are the same there.
    post = _posts([0.0], 0.05)
    g = _fit(post, _view(post, 0.01, 0.012, centre=0.4, side_m=0.288))
    assert g.error is None, g.error
    assert g.rule == "edge"
    assert g.rule_criterion is not None and g.rule_criterion <= WEDGE_THRESHOLD
    assert g.to_json()["rule"] == "edge"


def test_a_fence_with_gaps_narrower_than_the_penumbra_takes_the_wedge_rule(fence_fits):
    g, _ = fence_fits
    assert g.error is None, g.error
    assert g.rule == "wedge"
    assert g.rule_criterion > WEDGE_THRESHOLD
    assert g.to_json()["rule"] == "wedge" and g.to_json()["rule_criterion"] == pytest.approx(g.rule_criterion)
    # The wedge rule's own model of the photo reads its k (the photo is drawn by that rule).
    assert abs(g.range_k - K_FENCE) < 3 * g.range_stderr_stat + 0.02 * K_FENCE


def test_auto_taking_the_wedge_rule_is_the_wedge_rule_asked_for(fence_fits):
    # One fit, not a refit from the edge fit's solution over the edge fit's blur: the two read
    # the same k, rho and blur, and auto reports its criterion where the wedge rule asked for has none.
    auto, wedge = fence_fits
    assert auto.rule == wedge.rule == "wedge" and wedge.rule_criterion is None
    assert auto.range_k == pytest.approx(wedge.range_k, rel=1e-9)
    assert auto.rho == pytest.approx(wedge.rho, rel=1e-9)
    assert auto.range_stderr_stat == pytest.approx(wedge.range_stderr_stat, rel=1e-6)
    assert auto.blur_px == pytest.approx(wedge.blur_px, rel=1e-6, abs=1e-12)


def test_wedge_residual_jacobian_matches_finite_differences():
    """The solver's Jacobian under the ``wedge`` rule (the excess through the custom JVP of the
    shadow's shape) against central differences of the residuals, at a generic point with blur,
    the sun and the robust loss switched on, on an oblique camera (pixel footprints neither
    square nor axis-aligned)."""
    import dataclasses

    import jax
    import jax.numpy as jnp

    from fitting.samples.ground import select_samples
    from fitting.solve.group import _group_arrays, _with_wedge, initial_params
    from fitting.solve.model import FitConfig, FitParams, angular_pixel_gradient, raw_from_k, residuals
    from softshadow.camera import look_at_camera

    model = SoftShadowModel.from_mesh("pillar", profile="disk")
    sun = Sun(130.0, 35.0)
    camera = look_at_camera((2.0, 4.0, 2.5), (-1.5, 1.3, 0.0), 160, 120, 60.0)
    shading = np.asarray(model.camera_image(ShadowParams(0.01, 0.3), sun, Pose(), camera).shading)
    gray = np.nan_to_num(0.7 * shading, nan=0.7).astype(np.float32)
    view = PhotoView("oblique.png", gray, np.zeros(gray.shape, bool), camera=camera,
                     sun_azimuth_deg=float(sun.azimuth_deg), sun_elevation_deg=float(sun.elevation_deg),
                     sun_source="given")
    samples = select_samples(model, Pose(), view, range_k_max=0.03, max_samples=300, seed=0)
    group = _group_arrays([samples], [view])
    params, _ = initial_params([samples])
    params = dataclasses.replace(params, raw_k=jnp.asarray(float(raw_from_k(0.008))), raw_blur=jnp.asarray([0.4]),
                                 sun_delta_deg=jnp.asarray([0.1, -0.05]))
    config = FitConfig.make("disk", True, True, 0.05, "wedge")
    group = _with_wedge(group, model, Pose(), [samples], [view], FitOptions(), params, config)
    assert group.wedge_plan is not None and bool(np.any(np.asarray(group.wedge_plan.active)))
    # The samples' |dT/dpixel| as the solver's first solve sets it (``group._prepare``).
    group = dataclasses.replace(group, grad_t_pixel=angular_pixel_gradient(group, Pose(), 0.01, config.rule))
    flat = params.vector()
    fn = lambda x: residuals(FitParams.from_vector(x, 1), (group, Pose(), config))
    # One compiled program gives the residuals and their Jacobian (the differences use the former).
    both = jax.jit(lambda x: (fn(x), jax.jacfwd(fn)(x)))
    jac = np.asarray(both(flat)[1])
    assert_jacobian_matches_central_differences(lambda x: both(x)[0], np.asarray(flat), jac)
