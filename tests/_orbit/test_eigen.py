"""Eigen-decompositions of batches that hold non-finite matrices (`tid_jax._orbit._eigen`): LAPACK
(`geev`) is never handed a NaN or inf entry, whose results are NaN; the finite matrices'
results are those of numpy's own LAPACK binding."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tid_jax._orbit import _eigen


def _batch():
    """Six random 4 x 4 matrices (the size of a monodromy matrix), three not finite."""
    matrices = np.random.default_rng(0).standard_normal((6, 4, 4))
    matrices[1, 0, 2] = np.nan
    matrices[3] = np.inf
    matrices[4, 3, 3] = -np.inf
    return matrices


def _finite(matrices):
    return np.all(np.isfinite(matrices), axis=(-2, -1))


def test_eigenvalues_of_finite_matrices_and_nan_for_the_others():
    matrices = _batch()
    values = np.asarray(_eigen.eigenvalues(matrices))
    assert values.shape == (6, 4)
    for matrix, value, finite in zip(matrices, values, _finite(matrices), strict=True):
        if finite:
            np.testing.assert_allclose(np.sort_complex(value),
                                       np.sort_complex(np.linalg.eigvals(matrix)), rtol=1e-12)
        else:
            assert np.all(np.isnan(value))


def test_eigensystem_decomposes_finite_matrices_and_is_nan_for_the_others():
    matrices = _batch()
    values, vectors = map(np.asarray, _eigen.eigensystem(matrices))
    for matrix, value, vector, finite in zip(matrices, values, vectors, _finite(matrices),
                                             strict=True):
        if finite:  # A V = V diag(lambda), with unit columns
            np.testing.assert_allclose(matrix @ vector, vector * value, atol=1e-12)
            np.testing.assert_allclose(np.linalg.norm(vector, axis=0), 1.0, rtol=1e-12)
        else:
            assert np.all(np.isnan(value)) and np.all(np.isnan(vector))


@pytest.mark.parametrize("name", ["eigenvalues", "eigensystem"])
def test_lapack_is_never_given_a_non_finite_matrix(monkeypatch, name):
    handed = []

    def spy(original):
        def call(matrix, *args, **kwargs):
            handed.append(np.asarray(matrix))
            return original(matrix, *args, **kwargs)
        return call

    monkeypatch.setattr(jnp.linalg, "eigvals", spy(jnp.linalg.eigvals))
    monkeypatch.setattr(jax.lax.linalg, "eig", spy(jax.lax.linalg.eig))
    matrices = _batch()
    getattr(_eigen, name)(matrices)
    assert len(handed) == 1 and handed[0].shape == matrices.shape
    assert np.all(np.isfinite(handed[0]))
    finite = _finite(matrices)
    np.testing.assert_array_equal(handed[0][finite], matrices[finite])


def test_derivatives_of_a_finite_matrix_are_unchanged_beside_a_non_finite_one():
    # The eigenvalues' derivatives along a direction, for the finite matrix of a batch
    # that also holds a NaN one, against central differences.
    matrix = _batch()[0]
    direction = np.random.default_rng(1).standard_normal((4, 4))

    @jax.jit
    def spectral_sum(t):
        batch = jnp.stack([matrix + t * direction, jnp.full((4, 4), jnp.nan)])
        return jnp.sum(jnp.abs(_eigen.eigensystem(batch)[0][0]) ** 2)

    h = 1e-6
    expected = (spectral_sum(h) - spectral_sum(-h)) / (2 * h)
    derivative = jax.jit(jax.jacfwd(spectral_sum))(0.0)
    assert float(derivative) == pytest.approx(float(expected), rel=1e-6)
