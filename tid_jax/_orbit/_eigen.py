"""Eigenvalues of matrices that may hold NaN or inf entries.

On the CPU, JAX's eigenvalues come from LAPACK's `geev` (scipy's OpenBLAS), which first
balances the matrix (`gebal`). With a non-finite entry that step fails, and `geev` goes
on with the balancing indices unset: the later steps (`gehrd`, `hseqr`) read
uninitialised memory, which can corrupt memory (OpenMathLib/OpenBLAS issue 5250). An
orbit that was not found has a NaN monodromy matrix, so every eigen-decomposition of
this package goes through these functions: LAPACK is given the identity in place of a
matrix that is not finite, whose results are NaN.
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Complex, Float


def _finite(matrix: Float[Array, "*batch n n"]) -> tuple[Bool[Array, "*batch"], Array]:
    """Which matrices of the batch are finite, and the batch with the others replaced by
    the identity."""
    finite = jnp.all(jnp.isfinite(matrix), axis=(-2, -1))
    eye = jnp.eye(matrix.shape[-1], dtype=matrix.dtype)
    return finite, jnp.where(finite[..., None, None], matrix, eye)


def eigenvalues(matrix: Float[Array, "*batch n n"]) -> Complex[Array, "*batch n"]:
    """The eigenvalues of each matrix of the batch (`jnp.linalg.eigvals`), NaN for a
    matrix with a NaN or inf entry."""
    finite, safe = _finite(matrix)
    return jnp.where(finite[..., None], jnp.linalg.eigvals(safe), jnp.nan)


def eigensystem(
    matrix: Float[Array, "*batch n n"],
) -> tuple[Complex[Array, "*batch n"], Complex[Array, "*batch n n"]]:
    """The eigenvalues and right eigenvectors of each matrix of the batch, differentiable
    (`jax.lax.linalg.eig` with the eigenvectors' derivatives), NaN for a matrix with a NaN
    or inf entry."""
    finite, safe = _finite(matrix)
    values, vectors = jax.lax.linalg.eig(
        safe, compute_left_eigenvectors=False, enable_eigvec_derivs=True
    )
    return (jnp.where(finite[..., None], values, jnp.nan),
            jnp.where(finite[..., None, None], vectors, jnp.nan))
