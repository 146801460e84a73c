"""Saved traced programs (fitting.solve.saved_programs): a later process loads the fitter's solver
instead of tracing it, with the same results, and anything that cannot be saved or loaded
falls back to tracing."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fitting.solve import saved_programs
from fitting.solve.saved_programs import call_saved
from softshadow.internal import SAVED_PROGRAMS_ENV

TRACES = []


class Scaled(eqx.Module):
    """A pytree with an array leaf and a static choice, like the fitter's configuration."""
    x: jax.Array
    power: int = eqx.field(static=True, default=2)


def _fn(a: Scaled, b, steps: int):
    TRACES.append(1)  # runs only while JAX traces the function
    y = a.x ** a.power + b
    for _ in range(steps):
        y = jnp.sin(y)
    return y, jnp.linalg.qr(jnp.outer(y, y) + jnp.eye(y.shape[0]))[0].sum(), jnp.sum(y)


def _new_process():
    """What a new process starts with: no loaded programs, nothing marked failed."""
    saved_programs._LOADED.clear()
    saved_programs._FAILED.clear()


@pytest.fixture
def saving(tmp_path, monkeypatch):
    monkeypatch.setenv(SAVED_PROGRAMS_ENV, str(tmp_path))
    _new_process()
    yield tmp_path
    _new_process()


def _expected(a, b, steps):
    return [np.asarray(v) for v in eqx.filter_jit(_fn)(a, b, steps)]


def test_off_without_a_folder(monkeypatch):
    monkeypatch.delenv(SAVED_PROGRAMS_ENV, raising=False)
    a, b = Scaled(jnp.arange(4.0)), jnp.ones(4)
    out = call_saved("test.fn", _fn, a, b, 3)
    for got, want in zip(out, _expected(a, b, 3)):
        np.testing.assert_allclose(got, want, rtol=1e-6)
    assert saved_programs.saved_programs_dir() is None


def test_a_new_process_loads_the_program_without_tracing(saving):
    a, b = Scaled(jnp.arange(4.0)), jnp.linspace(0.0, 1.0, 4)
    first = call_saved("test.fn", _fn, a, b, 3)
    files = list(saving.glob("test.fn-*.jaxexport"))
    assert len(files) == 1
    _new_process()
    TRACES.clear()
    second = call_saved("test.fn", _fn, a, b + 1.0, 3)  # new values, same shapes: the same program
    assert TRACES == []  # loaded, not traced
    for got, want in zip(second, _expected(a, b + 1.0, 3)):
        np.testing.assert_allclose(np.asarray(got), want, rtol=1e-12, atol=1e-12)
    for got, want in zip(first, _expected(a, b, 3)):
        np.testing.assert_allclose(np.asarray(got), want, rtol=1e-12, atol=1e-12)


def test_shapes_and_static_choices_are_part_of_the_key(saving):
    a, b = Scaled(jnp.arange(4.0)), jnp.ones(4)
    call_saved("test.fn", _fn, a, b, 3)
    call_saved("test.fn", _fn, Scaled(jnp.arange(5.0)), jnp.ones(5), 3)  # other shapes
    call_saved("test.fn", _fn, Scaled(jnp.arange(4.0), power=3), b, 3)  # another static field
    out = call_saved("test.fn", _fn, a, b, 4)  # another static argument
    assert len(list(saving.glob("test.fn-*.jaxexport"))) == 4
    for got, want in zip(out, _expected(a, b, 4)):
        np.testing.assert_allclose(np.asarray(got), want, rtol=1e-12)


def test_a_damaged_file_is_replaced(saving):
    a, b = Scaled(jnp.arange(3.0)), jnp.ones(3)
    call_saved("test.fn", _fn, a, b, 2)
    (path,) = saving.glob("test.fn-*.jaxexport")
    path.write_bytes(b"not a program")
    _new_process()
    out = call_saved("test.fn", _fn, a, b, 2)
    for got, want in zip(out, _expected(a, b, 2)):
        np.testing.assert_allclose(np.asarray(got), want, rtol=1e-12)
    assert path.read_bytes() != b"not a program"


def test_a_program_that_cannot_be_exported_is_traced(saving):
    def with_callback(x):
        y = jax.pure_callback(lambda v: np.asarray(v) * 2.0, jax.ShapeDtypeStruct(x.shape, x.dtype), x)
        return (y + 1.0,)

    (out,) = call_saved("test.callback", with_callback, jnp.arange(3.0))
    np.testing.assert_allclose(np.asarray(out), [1.0, 3.0, 5.0])
    assert not list(saving.glob("test.callback-*"))
    (out,) = call_saved("test.callback", with_callback, jnp.arange(3.0))  # marked: traced at once
    np.testing.assert_allclose(np.asarray(out), [1.0, 3.0, 5.0])


def test_a_fit_through_the_saved_solver_equals_the_traced_one(tmp_path, monkeypatch):
    """The fitter's solver saved, then loaded as a new process would: the same k and rho."""
    from data_synth import model_topdown_folder
    from fitting import FitOptions, fit_folder
    folder = model_topdown_folder(tmp_path / "f", k=0.012, rho=0.25, noise=0.004, size=96)
    options = FitOptions(plots=False)
    monkeypatch.delenv(SAVED_PROGRAMS_ENV, raising=False)
    (traced,) = fit_folder(folder, options=options).groups
    monkeypatch.setenv(SAVED_PROGRAMS_ENV, str(tmp_path / "programs"))
    _new_process()
    (exported,) = fit_folder(folder, options=options).groups
    assert list((tmp_path / "programs").glob("fitting.solve.group-*.jaxexport"))
    _new_process()
    (loaded,) = fit_folder(folder, options=options).groups
    _new_process()
    for g in (exported, loaded):
        assert g.error is None
        assert g.range_k == pytest.approx(traced.range_k, rel=1e-9)
        assert g.rho == pytest.approx(traced.rho, rel=1e-9)
        assert g.range_stderr == pytest.approx(traced.range_stderr, rel=1e-6)
