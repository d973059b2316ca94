"""Small dense linear algebra for the normal with covariance D + W Wᵀ, in plain XLA ops.

The posterior's covariance has a few dozen rows and a low-rank factor W of a dozen columns
(samples, calibration groups, rotation settings); the whitening regression has at most four
coefficients. At these sizes the LAPACK custom calls behind ``jnp.linalg.cholesky`` and
``solve_triangular`` cost more in call overhead than in arithmetic, cannot be fused by XLA,
and — vmapped over draws and run from several threads at once on a CPU — they wait on the
intra-op thread pool that another execution holds (the deadlock of concurrent batches).
Here the factorisation and the triangular solves are unrolled over the (static) matrix size
into elementwise and outer-product operations that XLA fuses, differentiates and vmaps like
any other expression.

Every function takes one matrix (vmap for many). Sizes are static; the loops unroll at trace
time (n steps of O(n²) work: a 12 × 12 Cholesky is ≈ 2 k flops).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

LOG_2PI = math.log(2.0 * math.pi)


def cholesky(matrix: jnp.ndarray) -> jnp.ndarray:
    """Lower Cholesky factor L of a symmetric positive-definite (n, n) matrix, L Lᵀ = matrix.

    Right-looking: column j is the current column over the square root of its pivot, then
    its outer product leaves the Schur complement. Only the lower triangle is read. A 0 × 0
    matrix (a factor W without shared columns) is its own factor.
    """
    size = matrix.shape[-1]
    if size == 0:
        return matrix
    below = jnp.arange(size)
    rest = matrix
    columns = []
    for j in range(size):
        column = jnp.where(below >= j, rest[:, j] / jnp.sqrt(rest[j, j]), 0.0)
        columns.append(column)
        rest = rest - jnp.outer(column, column)
    return jnp.stack(columns, axis=1)


def solve_lower(lower: jnp.ndarray, rhs: jnp.ndarray) -> jnp.ndarray:
    """X with L X = rhs for a lower-triangular L (n, n); rhs (n,) or (n, m)."""
    if lower.shape[0] == 0:
        return rhs
    rest = rhs
    solution = []
    for j in range(lower.shape[0]):
        value = rest[j] / lower[j, j]
        solution.append(value)
        rest = rest - _outer(lower[:, j], value)  # L[:j, j] = 0: rows already solved keep
    return jnp.stack(solution)


def solve_upper_transposed(lower: jnp.ndarray, rhs: jnp.ndarray) -> jnp.ndarray:
    """X with Lᵀ X = rhs for a lower-triangular L (n, n); rhs (n,) or (n, m)."""
    size = lower.shape[0]
    if size == 0:
        return rhs
    rest = rhs
    solution = [None] * size
    for j in reversed(range(size)):
        value = rest[j] / lower[j, j]
        solution[j] = value
        rest = rest - _outer(lower[j, :], value)  # row j of L is column j of Lᵀ
    return jnp.stack(solution)


def _outer(column: jnp.ndarray, value: jnp.ndarray) -> jnp.ndarray:
    return column * value if value.ndim == 0 else jnp.outer(column, value)


class BlockCholesky:
    """Cholesky factor of an SPD matrix whose leading ``diagonal`` × ``diagonal`` block is
    diagonal: L = [[√A, 0], [X/√A, L_S]] with L_S the unrolled factor of the Schur
    complement S = M − (X/√A)(X/√A)ᵀ. The diagonal block costs one vector operation instead
    of one unrolled step per column.

    Args:
        matrix: (n, n), symmetric positive definite, ``matrix[:d, :d]`` diagonal.
        diagonal: d, the size of the diagonal leading block (static).
    """

    def __init__(self, matrix: jnp.ndarray, diagonal: int = 0):
        self.size = diagonal
        self.root = jnp.sqrt(jnp.diagonal(matrix)[:diagonal])
        self.lower_left = matrix[diagonal:, :diagonal] / self.root
        self.tail = cholesky(matrix[diagonal:, diagonal:] - self.lower_left @ self.lower_left.T)

    def solve_lower(self, rhs: jnp.ndarray) -> jnp.ndarray:
        """X with L X = rhs; rhs (n,) or (n, m)."""
        head = rhs[: self.size] / (self.root if rhs.ndim == 1 else self.root[:, None])
        tail = solve_lower(self.tail, rhs[self.size :] - self.lower_left @ head)
        return jnp.concatenate([head, tail])

    def log_diagonal_sum(self) -> jnp.ndarray:
        """Σ ln Lᵢᵢ (half the log determinant)."""
        return jnp.sum(jnp.log(self.root)) + jnp.sum(jnp.log(jnp.diagonal(self.tail)))


class Whitened:
    """D^(-1/2)-scaled views of the rows under Cov = D + W Wᵀ, and the capacitance's factor.

    With B = D^(-1/2) W and C = I + Bᵀ B = L_C L_Cᵀ (Woodbury),
    Xᵀ (D + W Wᵀ)⁻¹ Y = X'ᵀ Y' − (L_C⁻¹ Bᵀ X')ᵀ (L_C⁻¹ Bᵀ Y') for X' = D^(-1/2) X.

    Args:
        factor: W (n, q).
        diagonal: D (n,), > 0.
        disjoint: the leading columns of W whose rows do not overlap (each row in at most
            one of them: the per-sample effects), which make C's leading block diagonal.
    """

    def __init__(self, factor: jnp.ndarray, diagonal: jnp.ndarray, disjoint: int = 0):
        self.root = jnp.sqrt(diagonal)
        self.diagonal = diagonal
        self.scaled_factor = factor / self.root[:, None]
        rank = factor.shape[1]
        gram = jnp.eye(rank) + self.scaled_factor.T @ self.scaled_factor
        self.capacitance = BlockCholesky(gram, disjoint)

    def scale(self, values: jnp.ndarray) -> jnp.ndarray:
        """D^(-1/2) X for X (n,) or (n, m)."""
        return values / (self.root if values.ndim == 1 else self.root[:, None])

    def project(self, scaled: jnp.ndarray) -> jnp.ndarray:
        """L_C⁻¹ Bᵀ X' for an already scaled X' (n,) or (n, m)."""
        return self.capacitance.solve_lower(self.scaled_factor.T @ scaled)

    def log_determinant(self) -> jnp.ndarray:
        """ln |D + W Wᵀ| = Σ ln D + 2 Σ ln diag L_C (matrix determinant lemma)."""
        return jnp.sum(jnp.log(self.diagonal)) + 2.0 * self.capacitance.log_diagonal_sum()


def low_rank_normal_log_density(
    value: jnp.ndarray,
    mean: jnp.ndarray,
    factor: jnp.ndarray,
    diagonal: jnp.ndarray,
    count: jnp.ndarray | float | None = None,
    disjoint: int = 0,
) -> jnp.ndarray:
    """ln N(value; mean, D + W Wᵀ).

    Args:
        value, mean: (n,).
        factor: W (n, q).
        diagonal: D (n,), > 0.
        count: the number of rows that count for the 2π normalisation (default n). Rows that
            a mask removes carry residual 0, W row 0 and D = 1, so they add nothing else.
        disjoint: leading columns of W with non-overlapping rows (:class:`Whitened`).
    """
    whitened = Whitened(factor, diagonal, disjoint)
    residual = whitened.scale(value - mean)
    projected = whitened.project(residual)
    mahalanobis = jnp.sum(residual**2) - jnp.sum(projected**2)
    count = value.shape[-1] if count is None else count
    return -0.5 * (count * LOG_2PI + whitened.log_determinant() + mahalanobis)


def leave_one_out_conditionals(
    value: jnp.ndarray,
    mean: jnp.ndarray,
    factor: jnp.ndarray,
    diagonal: jnp.ndarray,
    disjoint: int = 0,
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(mean, sd) of yᵢ | y₋ᵢ for y ~ N(mean, D + W Wᵀ), every row i.

    With precision Q, yᵢ | y₋ᵢ ~ N(yᵢ − (Q(y − μ))ᵢ / Qᵢᵢ, 1/Qᵢᵢ);
    Q = D⁻¹ − D^(-1/2) Vᵀ V D^(-1/2), V = L_C⁻¹ Bᵀ (q, n).
    """
    whitened = Whitened(factor, diagonal, disjoint)
    projection = whitened.capacitance.solve_lower(whitened.scaled_factor.T)  # V, (q, n)
    residual = whitened.scale(value - mean)
    precision_residual = (residual - projection.T @ (projection @ residual)) / whitened.root
    precision_diagonal = (1.0 - jnp.sum(projection**2, axis=0)) / diagonal
    return value - precision_residual / precision_diagonal, 1.0 / jnp.sqrt(precision_diagonal)


def log_density_over_scales(
    value: jnp.ndarray,
    mean: jnp.ndarray,
    factor: jnp.ndarray,
    diagonal: jnp.ndarray,
    scaled: int,
    scales: jnp.ndarray,
) -> jnp.ndarray:
    """ln N(value; mean, D + W(τ) W(τ)ᵀ) at every τ of ``scales`` (k,), W(τ) being W with
    its first ``scaled`` columns multiplied by τ: :func:`low_rank_normal_log_density` at k
    scales for about the cost of one.

    With A = D^(-1/2) W, r = D^(-1/2) (value − mean) and S = diag(τ on the scaled columns,
    1 elsewhere), Woodbury gives rᵀ r − (S Aᵀ r)ᵀ C⁻¹ (S Aᵀ r) for the quadratic form and
    ln|D| + ln|C| for the log-determinant, C = I + S Aᵀ A S: the rows enter once, through
    Aᵀ A, Aᵀ r and rᵀ r, and each τ costs a (q, q) Cholesky factorisation.
    """
    from jax.scipy.linalg import solve_triangular

    root = jnp.sqrt(diagonal)
    whitened = factor / root[:, None]
    residual = (value - mean) / root
    gram, projected = whitened.T @ whitened, whitened.T @ residual
    constant = value.shape[-1] * LOG_2PI + jnp.sum(jnp.log(diagonal)) + residual @ residual
    columns = factor.shape[-1]

    def one(scale):
        s = jnp.where(jnp.arange(columns) < scaled, scale, 1.0)
        lower = jnp.linalg.cholesky(jnp.eye(columns) + s[:, None] * gram * s[None, :])
        solved = solve_triangular(lower, s * projected, lower=True)
        log_determinant = 2.0 * jnp.sum(jnp.log(jnp.diagonal(lower)))
        return -0.5 * (constant + log_determinant - solved @ solved)

    return jax.vmap(one)(scales)
