"""LAPACK's dpotrf, a triangular solve and the sigma points' moments as plain loops, for the
compiled step (kernel.py): its blocks are so small (at most 18 x 18) that a call into LAPACK
or NumPy would cost more than the arithmetic."""

from __future__ import annotations

import math


def cholesky_into(A, L):
    """Lower Cholesky factor of A (n, n) (from its lower triangle) into L (n, n), zeros above
    the diagonal; False where A is not positive definite (or has a NaN), as LAPACK's dpotrf
    reports it."""
    n = A.shape[0]
    for j in range(n):
        for i in range(j):
            L[i, j] = 0.0
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / d
    return True


def forward_solve_into(L, B):
    """B <- L^-1 B in place, L (n, n) lower triangular, B (n, c)."""
    n, c = B.shape
    for i in range(n):
        d = L[i, i]
        for col in range(c):
            t = B[i, col]
            for k in range(i):
                t -= L[i, k] * B[k, col]
            B[i, col] = t / d


def moments_into(W, wm, wc, mean, C):
    """Weighted means of W's columns (one row per sigma point) and their covariance; W is
    centred in place. The covariance is accumulated point by point, so the innermost loop runs
    along contiguous rows with no reduction in it (a dependency chain of one long sum per entry
    would cost several times more)."""
    S, rows = W.shape
    for r in range(rows):
        mean[r] = 0.0
    for s in range(S):
        for r in range(rows):
            mean[r] += W[s, r] * wm[s]
    for r in range(rows):
        for c in range(rows):
            C[r, c] = 0.0
    for s in range(S):
        for r in range(rows):
            W[s, r] -= mean[r]
        for r in range(rows):
            a = W[s, r] * wc[s]
            for c in range(r + 1):
                C[r, c] += a * W[s, c]
    for r in range(rows):
        for c in range(r):
            C[c, r] = C[r, c]
