/* Small dense linear algebra for the mechanism DAE (dae.c): C99 and libm only, no allocation.
 *
 * Matrices are row-major arrays of doubles; sizes are a few dozen at most, so the textbook
 * algorithms are used, written out:
 * - LU factorisation with partial pivoting (LAPACK dgetrf's choice of pivot: the first entry of
 *   largest magnitude in the column), solves with it and its transpose, the sign of the
 *   determinant, for the dependent block of Phi_q (its Schur complement, or all of it; and the
 *   velocity ratio of the partition's review);
 * - Cholesky factorisation of a symmetric positive definite matrix (LAPACK dposv's role), for the
 *   range-space solve of eq. (11);
 * - the column order of a Householder QR factorisation with column pivoting (LAPACK dgeqp3's
 *   choice: the remaining column of largest norm, the first on ties), for choosing the
 *   independent coordinates.
 *
 * The functions are static and dae.c calls them with compile-time sizes.  For small sizes the
 * includer defines LINALG_UNROLL as a request to unroll the next loop completely (measured on a
 * four-bar's 8 x 8 blocks: a Cholesky factorisation 1086 -> 279 instructions, the loops'
 * bookkeeping was most of the work); a compiler that does not know the request ignores it.
 */
#ifndef MECHANISM_LINALG_H
#define MECHANISM_LINALG_H

#include <math.h>

#ifndef LINALG_UNROLL
#define LINALG_UNROLL
#endif
/* The includer may define LINALG_INLINE as a request to inline the LU kernels at every call (for
   sizes known at compile time; a call with another size it wraps in a function of its own). */
#ifndef LINALG_INLINE
#define LINALG_INLINE
#endif

/* LU = P A of the n x n matrix `a`, in place (unit lower L below the diagonal, U on and above),
   and inv_diag[k] = 1 / U[k][k].  piv[k] is the row exchanged with row k at step k.  Returns
   0, or k + 1 for the first k at which U[k][k] is exactly zero (dgetrf's info): then `a` is
   singular and must not be solved with.  Rows whose multiplier is zero are skipped. */
LINALG_INLINE static int lu_factor(int n, double *a, int *piv, double *inv_diag)
{
    int info = 0;
    LINALG_UNROLL
    for (int k = 0; k < n; k++) {
        int p = k;
        double big = fabs(a[k * n + k]);
        LINALG_UNROLL
        for (int i = k + 1; i < n; i++) {        /* selections, not branches: the winner is data */
            const double v = fabs(a[i * n + k]);
            const int larger = v > big;
            p = larger ? i : p;
            big = larger ? v : big;
        }
        piv[k] = p;
        LINALG_UNROLL
        for (int j = 0; j < n; j++) {             /* (p == k: the row with itself) */
            const double tmp = a[k * n + j];
            a[k * n + j] = a[p * n + j];
            a[p * n + j] = tmp;
        }
        const double pivot = a[k * n + k];
        if (pivot == 0.0) {
            if (!info) info = k + 1;
            inv_diag[k] = 0.0;
            continue;
        }
        const double inverse = 1.0 / pivot;
        inv_diag[k] = inverse;
        LINALG_UNROLL
        for (int i = k + 1; i < n; i++) {
            double *row_i = a + i * n;
            if (row_i[k] == 0.0) continue;
            const double l = row_i[k] * inverse;
            row_i[k] = l;
            LINALG_UNROLL
            for (int j = k + 1; j < n; j++) row_i[j] -= l * a[k * n + j];
        }
    }
    return info;
}

/* x = A^-1 b with lu_factor's result (b and x may be the same array).  Column by column: the
   updates that one solved entry makes are independent of each other, so the chain of dependent
   operations is n long rather than n^2 / 2. */
LINALG_INLINE static void lu_solve(int n, const double *lu, const int *piv, const double *inv_diag, const double *b, double *x)
{
    if (x != b) {
        LINALG_UNROLL
        for (int i = 0; i < n; i++) x[i] = b[i];
    }
    LINALG_UNROLL
    for (int k = 0; k < n; k++) {
        const double tmp = x[k];
        x[k] = x[piv[k]];
        x[piv[k]] = tmp;
    }
    LINALG_UNROLL
    for (int j = 0; j < n; j++) {
        const double xj = x[j];
        LINALG_UNROLL
        for (int i = j + 1; i < n; i++) x[i] -= lu[i * n + j] * xj;
    }
    LINALG_UNROLL
    for (int j = n - 1; j >= 0; j--) {
        const double xj = x[j] * inv_diag[j];
        x[j] = xj;
        LINALG_UNROLL
        for (int i = 0; i < j; i++) x[i] -= lu[i * n + j] * xj;
    }
}

/* x = A^-T b with lu_factor's result (A^T = U^T L^T P; b and x may be the same array). */
LINALG_INLINE static void lu_solve_transposed(int n, const double *lu, const int *piv, const double *inv_diag, const double *b,
                                double *x)
{
    if (x != b) {
        LINALG_UNROLL
        for (int i = 0; i < n; i++) x[i] = b[i];
    }
    LINALG_UNROLL
    for (int j = 0; j < n; j++) {                  /* U^T z = b: column j of U^T is row j of U */
        const double xj = x[j] * inv_diag[j];
        x[j] = xj;
        LINALG_UNROLL
        for (int i = j + 1; i < n; i++) x[i] -= lu[j * n + i] * xj;
    }
    LINALG_UNROLL
    for (int j = n - 1; j >= 0; j--) {             /* L^T w = z: unit upper triangular */
        const double xj = x[j];
        LINALG_UNROLL
        for (int i = 0; i < j; i++) x[i] -= lu[j * n + i] * xj;
    }
    LINALG_UNROLL
    for (int k = n - 1; k >= 0; k--) {             /* x = P^T w: the interchanges undone, last first */
        const double tmp = x[k];
        x[k] = x[piv[k]];
        x[piv[k]] = tmp;
    }
}

/* The sign of the determinant of A from lu_factor's result: (-1)^(row exchanges) times the signs of
   U's diagonal (dae.py's _det_sign of LAPACK's factors). */
LINALG_INLINE static int lu_det_sign(int n, const int *piv, const double *inv_diag)
{
    int negative = 0;
    LINALG_UNROLL
    for (int k = 0; k < n; k++) negative ^= (piv[k] != k) ^ (inv_diag[k] < 0.0);
    return negative ? -1 : 1;
}

/* Cholesky factor L of the symmetric positive definite n x n matrix `a` (its lower triangle is
   read, the upper is not), in place, with 1 / L[j][j] stored on the diagonal.  first[i] is the
   column of the first entry of row i that may be nonzero (the envelope; 0 for a dense matrix):
   L has no nonzero before it either, so the products start there -- the same arithmetic as
   the dense factorisation without its products of zeros.  Returns 0, or k + 1 when the leading
   minor of order k + 1 is not positive (dposv's info). */
static int cholesky_factor(int n, double *a, const int *first)
{
    LINALG_UNROLL
    for (int j = 0; j < n; j++) {
        double *row_j = a + j * n;
        double d = row_j[j];
        LINALG_UNROLL
        for (int k = first[j]; k < j; k++) d -= row_j[k] * row_j[k];
        if (!(d > 0.0)) return j + 1;
        const double inverse = 1.0 / sqrt(d);
        row_j[j] = inverse;
        LINALG_UNROLL
        for (int i = j + 1; i < n; i++) {
            if (first[i] > j) continue;
            double *row_i = a + i * n;
            double sum = row_i[j];
            LINALG_UNROLL
            for (int k = first[i] > first[j] ? first[i] : first[j]; k < j; k++) sum -= row_i[k] * row_j[k];
            row_i[j] = sum * inverse;
        }
    }
    return 0;
}

/* Solve L L^T x = b with cholesky_factor's result (and its envelope); b is overwritten with x.
   Column by column, as lu_solve. */
static void cholesky_solve(int n, const double *l, const int *first, double *b)
{
    LINALG_UNROLL
    for (int j = 0; j < n; j++) {
        const double xj = b[j] * l[j * n + j];
        b[j] = xj;
        LINALG_UNROLL
        for (int i = j + 1; i < n; i++)
            if (first[i] <= j) b[i] -= l[i * n + j] * xj;
    }
    LINALG_UNROLL
    for (int i = n - 1; i >= 0; i--) {
        double sum = b[i];
        LINALG_UNROLL
        for (int k = i + 1; k < n; k++)
            if (first[k] <= i) sum -= l[k * n + i] * b[k];
        b[i] = sum * l[i * n + i];
    }
}

/* perm (n entries): the column order a Householder QR factorisation with column pivoting of the
   m x n matrix `a` chooses (overwritten): at step k the column of largest remaining norm (rows
   k..m-1 of the transformed matrix), the first on ties.  Columns beyond min(m, n) keep their
   order after the chosen ones.  (Used rarely: not unrolled.) */
static void qr_pivot_order(int m, int n, double *a, int *perm)
{
    for (int j = 0; j < n; j++) perm[j] = j;
    const int steps = m < n ? m : n;
    for (int k = 0; k < steps; k++) {
        int best = k;
        double best_norm = -1.0;
        for (int j = k; j < n; j++) {
            double norm = 0.0;
            for (int i = k; i < m; i++) norm += a[i * n + j] * a[i * n + j];
            if (norm > best_norm) { best_norm = norm; best = j; }
        }
        if (best != k) {
            for (int i = 0; i < m; i++) {
                const double tmp = a[i * n + k];
                a[i * n + k] = a[i * n + best];
                a[i * n + best] = tmp;
            }
            const int tmp = perm[k];
            perm[k] = perm[best];
            perm[best] = tmp;
        }
        /* The Householder reflection H = I - 2 v v^T / (v^T v) that zeroes column k below row k. */
        double alpha = sqrt(best_norm > 0.0 ? best_norm : 0.0);
        if (alpha == 0.0) continue;
        if (a[k * n + k] > 0.0) alpha = -alpha;
        double vv = 0.0;
        a[k * n + k] -= alpha;                       /* v = column k, rows k..m-1, minus alpha e_k */
        for (int i = k; i < m; i++) vv += a[i * n + k] * a[i * n + k];
        if (vv > 0.0)
            for (int j = k + 1; j < n; j++) {
                double dot = 0.0;
                for (int i = k; i < m; i++) dot += a[i * n + k] * a[i * n + j];
                const double f = 2.0 * dot / vv;
                for (int i = k; i < m; i++) a[i * n + j] -= f * a[i * n + k];
            }
        a[k * n + k] = alpha;
        for (int i = k + 1; i < m; i++) a[i * n + k] = 0.0;
    }
}

#endif
