"""The ``wedge`` rule in the fitter off the ground plane (``fitting.solve.rule_choice``): a fence of
posts whose gaps are narrower than the penumbra casts its shadow on a ramp, seen as a mesh
receiver and as a range image of the same ramp. ``rule="wedge"`` is planned there (the samples
carry the receiver's normals) and recovers k and rho, ``auto`` reports its criterion and takes
the same fit, the solver's Jacobian through the wedge rule on the mesh receiver matches central
differences, and a group whose samples cannot be planned says that the rule asked for was not
used. The photos are drawn by the project's own ``wedge`` rule on the receiver with the fit's
brightness model (the sky the object hides left out on both sides: ``sky_occlusion=False``);
the fits share one compiled ``wedge`` solver (same sample and plan buckets)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import trimesh

from fitting import FitOptions, PhotoView, fit_group
from fitting.samples.photo_samples import PhotoSamples
from fitting.samples.receiver_light import plane_sky_fraction, shadow_factor, sun_incidence
from fitting.samples.receiver_points import ReceiverSurface
from fitting.solve.rule_choice import WEDGE_THRESHOLD, wedge_plan, wedge_unavailable
from softshadow import Pose, ShadowParams, SoftShadowModel, Sun, look_at_camera

SUN = Sun(200.0, 35.0)  # no face of the posts edge-on to the sun; the ramp faces it
RHO, LEVEL, K = 0.3, 0.6, 0.02
TILT_DEG = 12.0  # the ramp rises along +y (towards where the shadows point)
SIZE = (128, 96)


def _fence() -> trimesh.Trimesh:
    """Three square posts 12 mm wide, 6 mm apart, 0.3 m high, sunk 0.1 m (they cross the ramp)."""
    boxes = []
    for x in (-0.018, 0.0, 0.018):
        box = trimesh.creation.box((0.012, 0.012, 0.4))
        box.apply_translation((x, 0.0, 0.1))
        boxes.append(box)
    return trimesh.util.concatenate(boxes)


def _ramp() -> trimesh.Trimesh:
    """The plane z = y tan(TILT_DEG) over 2 x 2 m."""
    v = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    v[:, 2] = v[:, 1] * math.tan(math.radians(TILT_DEG))
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


def _view(kind: str, noise: float = 0.01, seed: int = 0) -> PhotoView:
    """A 128 x 96 photo of the fence's shadow on the ramp (receiver ``kind``: "mesh", or "depth":
    the ramp's range image), drawn by the ``wedge`` rule averaged over each pixel's footprint on
    the receiver, lit as ``receiver_light`` lights a tilted face, with Gaussian noise of ``noise``
    of the lit level."""
    camera = look_at_camera((0.45, -0.1, 0.5), (0.08, 0.2, 0.04), SIZE[0], SIZE[1], 40.0)
    blank = PhotoView("blank", np.ones(SIZE[::-1], np.float32), np.zeros(SIZE[::-1], bool), camera=camera)
    rows, cols = np.mgrid[0:SIZE[1], 0:SIZE[0]]
    surface = ReceiverSurface("mesh", mesh=_ramp())
    p, n, ok, jac = surface.at_pixels(blank, cols.ravel(), rows.ravel())
    if kind == "depth":
        depth = np.where(ok, p @ camera.R[2] + camera.t[2], np.nan).reshape(SIZE[::-1])
        surface = ReceiverSurface("depth", depth=depth)
        p, n, ok, jac = surface.at_pixels(blank, cols.ravel(), rows.ravel())
    truth = SoftShadowModel.from_mesh(_fence(), rule="wedge", profile="disk")
    shading = np.asarray(truth.at_points(ShadowParams(K, RHO), SUN, Pose(), p[ok], normals=n[ok],
                                         pixel_axes=np.swapaxes(jac[ok], 1, 2), range_k_max=K))
    alpha = (1.0 - shading) / (1.0 - RHO)
    s_dir = -np.asarray(SUN.light_np, np.float64)
    gray = np.full(ok.shape, LEVEL)
    gray[ok] = LEVEL * shadow_factor(alpha, RHO, sun_incidence(n[ok], s_dir), plane_sky_fraction(n[ok]))
    gray = gray + np.random.default_rng(seed).normal(0.0, noise * LEVEL, gray.shape)
    return PhotoView(f"{kind}.png", gray.reshape(SIZE[::-1]).astype(np.float32), np.zeros(SIZE[::-1], bool),
                     camera=camera, sun_azimuth_deg=float(SUN.azimuth_deg),
                     sun_elevation_deg=float(SUN.elevation_deg), sun_source="given", receiver=surface)


def _options(rule: str) -> FitOptions:
    # 150 a photo: the receiver takes three times that (``RECEIVER_SAMPLES_FACTOR``), 450 in one bucket.
    return FitOptions(rule=rule, blur=(True,), plots=False, max_samples_per_photo=150, sky_occlusion=False)


def _fit(view: PhotoView, rule: str, samples=None):
    return fit_group(SoftShadowModel.from_mesh(_fence()), Pose(), [view], "g", None, _options(rule), samples=samples)


@pytest.fixture(scope="module")
def fits():
    """{kind: (wedge fit, auto fit)} on the mesh and the range-image receiver."""
    out = {}
    for kind in ("mesh", "depth"):
        view = _view(kind)
        out[kind] = (_fit(view, "wedge"), _fit(view, "auto"))
    return out


@pytest.mark.parametrize("kind", ["mesh", "depth"])
def test_the_wedge_rule_asked_for_is_used_and_recovers_k_and_rho(fits, kind):
    g, _ = fits[kind]
    assert g.error is None, g.error
    assert g.rule == "wedge" and g.to_json()["rule"] == "wedge" and g.rule_criterion is None
    assert not any("rule asked for" in w for w in g.warnings), g.warnings
    # Within the stated errors, and within 3 statistical ones (the photo is drawn by the model
    # fitted, bar the pixel's Gaussian against its box: the edge rule's fit reads rho 0.34 here).
    assert abs(g.range_k - K) < g.range_stderr and abs(g.rho - RHO) < g.rho_stderr
    assert abs(g.range_k - K) < 3 * g.range_stderr_stat + 0.01 * K, (g.range_k, g.range_stderr_stat)
    assert abs(g.rho - RHO) < 3 * g.rho_stderr_stat + 0.005, (g.rho, g.rho_stderr_stat)


@pytest.mark.parametrize("kind", ["mesh", "depth"])
def test_auto_reports_its_criterion_and_takes_the_wedge_fit(fits, kind):
    # The gaps (6 mm) are narrower than the penumbra (2 k d, up to 12 mm): the edge rule lightens
    # the fence's umbra, and the wedge rule moves the edge fit's rho by many standard errors.
    wedge, auto = fits[kind]
    assert auto.error is None, auto.error
    assert auto.rule_criterion is not None and auto.rule_criterion > WEDGE_THRESHOLD
    assert auto.rule == "wedge" and auto.to_json()["rule_criterion"] == pytest.approx(auto.rule_criterion)
    assert auto.range_k == pytest.approx(wedge.range_k, rel=1e-9)
    assert auto.rho == pytest.approx(wedge.rho, rel=1e-9)


def test_the_wedge_plan_takes_the_receivers_normals():
    """Points on a face turned from the sun are in attached shadow in the wedge rule's plan (it
    is planned with the samples' normals); without normals a receiver's samples cannot be
    planned, and the reason names the photo."""
    s_dir = -np.asarray(SUN.light_np, np.float64)
    away = np.array([-s_dir[0], -s_dir[1], 0.0]) / np.hypot(s_dir[0], s_dir[1])  # a wall's face turned from the sun
    facing = np.array([0.0, -math.sin(math.radians(TILT_DEG)), math.cos(math.radians(TILT_DEG))])
    pts = np.array([[0.6, 0.6, 0.3], [0.7, 0.6, 0.3], [-0.5, -0.5, -0.5 * math.tan(math.radians(TILT_DEG))]])
    normals = np.array([away, away, facing])
    n = len(pts)
    jac = np.zeros((n, 3, 2))
    jac[:, 0, 0] = jac[:, 1, 1] = 0.002
    model = SoftShadowModel.from_mesh(_fence())
    edge_plan = model.plan_points(SUN, Pose(), pts, 0.03, normals=normals)
    samples = PhotoSamples("wall.png", np.zeros((n, 2)), pts, jac, np.ones(n), np.zeros(n, int), np.zeros((n, 2)),
                           np.zeros(n, int), edge_plan, 1, 5, normals=normals)
    view = PhotoView("wall.png", np.ones((4, 4), np.float32), np.zeros((4, 4), bool),
                     sun_azimuth_deg=float(SUN.azimuth_deg), sun_elevation_deg=float(SUN.elevation_deg),
                     receiver=ReceiverSurface("mesh", mesh=_ramp()))
    assert wedge_unavailable([samples], [view]) is None
    axes = np.broadcast_to(np.swapaxes(jac, 1, 2)[:1], (8, 2, 3)).copy()
    plan = wedge_plan(model, Pose(), [samples], [view], 0.03, axes)
    assert plan is not None
    assert np.asarray(plan.hard)[:n].tolist() == [1.0, 1.0, 0.0]
    bare = dataclasses.replace(samples, normals=None)
    reason = wedge_unavailable([bare], [view])
    assert reason is not None and "wall.png" in reason and "normals" in reason
    assert wedge_plan(model, Pose(), [bare], [view], 0.03, axes) is None


def test_a_group_that_cannot_take_the_wedge_rule_says_so(fits):
    """Samples without the receiver's normals (drawn elsewhere): the group is fitted with the edge
    rule, and its warnings say that the wedge rule asked for was not used, and why."""
    from fitting.solve.group import sample_views
    view = _view("mesh")
    model = SoftShadowModel.from_mesh(_fence())
    samples, used, no_shadow = sample_views(model, Pose(), [view], _options("wedge"))
    bare = [dataclasses.replace(s, normals=None) for s in samples]
    g = _fit(view, "wedge", samples=([view.name], bare, used, no_shadow))
    assert g.error is None, g.error
    assert g.rule == "edge"
    assert any("not the wedge rule asked for" in w and "normals" in w for w in g.warnings), g.warnings


def test_wedge_jacobian_on_a_mesh_receiver_matches_central_differences(fits):
    """The solver's Jacobian under the ``wedge`` rule on the mesh receiver (the excess through the
    custom JVP of the shadow's shape, camera blur free) is finite and matches central
    differences of the residuals in float64 at its solution (a generic point); the programs are
    those the fits compiled."""
    import jax.numpy as jnp

    from fitting.solve.group import (_group_arrays, _solve, _to_numpy, _with_wedge, initial_params, plain_config,
                                     plain_start, sample_views)
    from fitting.solve.model import FitConfig, FitParams
    from fitting.solve.rule_choice import _values_alpha

    view, options = _view("mesh"), _options("wedge")
    model = SoftShadowModel.from_mesh(_fence())
    samples, used, _ = sample_views(model, Pose(), [view], options)
    arrays = _group_arrays(samples, used)
    base, _ = initial_params(samples)
    plain, arrays, _ = plain_start(arrays, Pose(), base, options, False, "edge")
    arrays = _with_wedge(arrays, model, Pose(), samples, used, options, plain.params, plain_config(options, False))
    assert arrays.wedge_plan is not None and bool(np.any(np.asarray(arrays.wedge_plan.active)))
    config = FitConfig.make("disk", True, False, 0.0, "wedge")
    sol = _to_numpy(_solve(plain.params, (arrays, Pose(), config), options.max_steps, jnp.zeros(9), jnp.asarray(False)))
    jac = np.asarray(sol.jacobian)
    assert np.isfinite(jac).all()
    lay = FitParams.layout(1)
    assert np.abs(jac[:, lay["raw_k"]]).max() > 0 and np.abs(jac[:, lay["raw_blur"]]).max() > 0
    weight, observed = np.asarray(arrays.weight), np.asarray(arrays.observed)
    scale = np.asarray(arrays.scale)[np.asarray(arrays.photo)]

    def fn(x):
        values, _ = _values_alpha(FitParams.from_vector(jnp.asarray(x), 1), arrays, Pose(), config)
        return weight * (observed - np.asarray(values, np.float64)) / scale

    # Steps of 1e-5: the wedge rule's disk-segment areas carry float64 rounding of a few 1e-11 in
    # some samples' residuals here, which swamps central differences of smaller steps (1e-6: 1.6e-5
    # off in the k column, 1e-7: 3e-4; 1e-5: 2e-6, the steps' own error negligible).
    x0 = np.asarray(sol.params.vector(), np.float64)
    h = 1e-5
    for i in range(len(x0)):
        e = np.zeros(len(x0))
        e[i] = h
        fd = (fn(x0 + e) - fn(x0 - e)) / (2 * h)
        np.testing.assert_allclose(jac[:, i], fd, atol=1e-5 * max(1.0, np.abs(fd).max()), err_msg=f"column {i}")
