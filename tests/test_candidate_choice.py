"""The choice among a point's candidate edges (``penumbra._choose``): a slot that repeats an
earlier one (plans fill missing slots with the first edge) changes nothing, for either
expansion rule, with or without the plan's boundary flag. Under the paper rule the ramp is not
symmetric about the edge's plane, so a repeated slot without the first slot's boundary flag
took the other side (u +0.48 against -0.42 at a point beside the edge) whenever that side was
nearer."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from softshadow.penumbra import corner_alpha, edge_alpha, edge_coordinate

# Two edges 1 m above the ground meeting at a right angle, the sun from above and aside.
EDGES = np.array([[[-1.0, 0.0, 1.0], [1.0, 0.0, 1.0]], [[1.0, 0.0, 1.0], [1.0, 2.0, 1.0]]])
SIGN = np.array([1.0, 1.0])
NEIGHBOURS = np.array([[-1, 1], [0, -1]])
LIGHT = np.array([0.0, 0.3, -1.0]) / np.linalg.norm([0.0, 0.3, -1.0])


@pytest.mark.parametrize("rule", ["edge", "paper"])
@settings(max_examples=30, deadline=None)
@given(x=st.floats(-0.6, 0.6), dy=st.floats(-0.04, 0.04), tilt=st.floats(-1.0, 1.0),
       inside=st.sampled_from([0.0, 1.0]), near=st.sampled_from([0.0, 1.0]))
def test_a_repeated_slot_changes_nothing(rule, x, dy, tilt, inside, near):
    with jax.enable_x64(True):
        point = jnp.array([[x, 0.3 + dy, 0.0]])  # beside the first edge's shadow (y = 0.3)
        normals = jnp.array([[0.0, 1.0, tilt], [1.0, 0.0, tilt]]) / np.sqrt(1.0 + tilt * tilt)
        args = (jnp.asarray(EDGES), jnp.asarray(SIGN), jnp.asarray(LIGHT), 0.05, jnp.array([inside]), rule,
                normals)
        nb = jnp.array([near])
        one, padded = jnp.array([[0, 1]]), jnp.array([[0, 1, 0, 0, 1]])
        for ids, distinct in ((jnp.array([[0, 0, 0]]), jnp.array([[0]])), (padded, one)):
            np.testing.assert_allclose(edge_coordinate(point, ids, *args, near_boundary=nb),
                                       edge_coordinate(point, distinct, *args, near_boundary=nb), atol=1e-12)
        np.testing.assert_allclose(edge_alpha(point, padded, *args[:6], "linear", normals, near_boundary=nb),
                                   edge_alpha(point, one, *args[:6], "linear", normals, near_boundary=nb),
                                   atol=1e-12)
        np.testing.assert_allclose(
            corner_alpha(point, padded, *args[:5], jnp.asarray(NEIGHBOURS), rule, "linear", normals, nb),
            corner_alpha(point, one, *args[:5], jnp.asarray(NEIGHBOURS), rule, "linear", normals, nb), atol=1e-12)
