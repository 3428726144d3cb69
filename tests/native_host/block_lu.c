/* The generated factorisation of the declared partition's dependent block (equations.c: eq_dep_*)
 * against a dense LU with partial pivoting (linalg.h), on a native FMU's shipped sources
 * (tests/test_fmu_native.py).
 *
 * At TRIALS configurations drawn at random (angles in [-pi, pi], lengths' coordinates in
 * [-3, 3], the FMU's start parameters; assembled or not, a linear-algebra check), with a
 * Jacobian whose constant entries are NaN (so that code reading them shows it): solves
 * block x = b and block^T y = c with random right-hand sides both ways, and prints one line
 *   trials T backward B backward_t BT sign_mismatches S columns C non_finite F
 * B, BT: the largest backward error |block x - b|_inf / (|block|_inf |x|_inf) of the generated
 * solves; S: configurations where the generated and dense determinants' signs differ (those
 * where the dense block is nearly singular, a pivot ratio under 1e-8, are skipped); C: the
 * largest difference between eq_jacobian_column and the whole Jacobian's columns; F: solves
 * that gave a non-finite value.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "equations.h"
#include "variables.h"
#include "linalg.h"

#define TRIALS 2000
enum { N = MECH_N, M = MECH_M, MA = MECH_ALLOC(MECH_M), R = MECH_DEP_R, RA = MECH_ALLOC(MECH_DEP_R) };

static double uniform(double lo, double hi)
{
    return lo + (hi - lo) * (rand() / (double)RAND_MAX);
}

static double norm_inf(const double *v, int n)
{
    double m = 0.0;
    for (int i = 0; i < n; i++) m = fmax(m, fabs(v[i]));
    return m;
}

int main(void)
{
    static const double STARTS[FMU_N_VARIABLES] = FMU_REAL_STARTS;
    static const int PARAMETER_VRS[MECH_ALLOC(MECH_N_PARAMETERS)] = MECH_PARAMETER_VRS;
    static const int INDEPENDENT[MECH_ALLOC(MECH_K)] = MECH_INDEPENDENT;
    static const int ANGLES[MECH_ALLOC(MECH_N_ANGLES)] = MECH_ANGLES;
    static const int ROWS[RA] = MECH_DEP_ROWS, COLS[RA] = MECH_DEP_COLS;
    double p[MECH_ALLOC(MECH_N_PARAMETERS)], q[N], tr[MECH_ALLOC(MECH_N_TRIG)], J[MA * N], Jv[MA * N];
    double block[MA * MA], lu[MA * MA], inv_diag[MA], w[MECH_DEP_W], schur_inv[RA];
    double b[MA], c[MA], x[MA], y[MA], t[MA], g[RA], column[MA];
    int piv[MA], spiv[RA], dependent[MA], is_independent[N];
    double backward = 0.0, backward_t = 0.0, columns = 0.0;
    int mismatches = 0, non_finite = 0;
    srand(20261124);
    for (int i = 0; i < MECH_N_PARAMETERS; i++) p[i] = STARTS[PARAMETER_VRS[i]];
    memset(is_independent, 0, sizeof is_independent);
    for (int j = 0; j < MECH_K; j++) is_independent[INDEPENDENT[j]] = 1;
    for (int i = 0, j = 0; i < N; i++)
        if (!is_independent[i]) dependent[j++] = i;
    for (int trial = 0; trial < TRIALS; trial++) {
        for (int i = 0; i < N; i++) q[i] = uniform(-3.0, 3.0);
        for (int a = 0; a < MECH_N_ANGLES; a++) q[ANGLES[a]] = uniform(-3.141592653589793, 3.141592653589793);
        eq_trig(q, tr);
        eq_jacobian(q, tr, p, J);
        for (int i = 0; i < MA * N; i++) Jv[i] = NAN;       /* the generated code must not read these */
        eq_jacobian_variable(q, tr, p, Jv);
        for (int k = 0; k < N; k++) {
            eq_jacobian_column(Jv, k, column);
            for (int i = 0; i < M; i++) columns = fmax(columns, fabs(column[i] - J[i * N + k]));
        }
        for (int i = 0; i < M; i++)
            for (int j = 0; j < M; j++) block[i * M + j] = lu[i * M + j] = J[i * N + dependent[j]];
        for (int i = 0; i < M; i++) { b[i] = uniform(-1.0, 1.0); c[i] = uniform(-1.0, 1.0); }
        if (lu_factor(M, lu, piv, inv_diag)) continue;
        double lo = INFINITY, hi = 0.0;
        for (int i = 0; i < M; i++) { lo = fmin(lo, fabs(lu[i * M + i])); hi = fmax(hi, fabs(lu[i * M + i])); }
        const int dense_sign = lu_det_sign(M, piv, inv_diag);
        /* generated: factor, solve, transposed solve, sign */
        eq_dep_factor(Jv, w);
        if (lu_factor(R, w + MECH_DEP_SCHUR, spiv, schur_inv)) { if (lo / hi > 1e-8) mismatches++; continue; }
        const int sign = MECH_DEP_SIGN * lu_det_sign(R, spiv, schur_inv);
        if (sign != dense_sign && lo / hi > 1e-8) mismatches++;
        memcpy(t, b, sizeof t);
        eq_dep_forward(w, t);
        for (int a = 0; a < R; a++) g[a] = t[ROWS[a]];
        lu_solve(R, w + MECH_DEP_SCHUR, spiv, schur_inv, g, g);
        for (int a = 0; a < R; a++) x[COLS[a]] = g[a];
        eq_dep_backward(w, t, x);
        eq_dep_forward_t(w, c, y, g);
        lu_solve_transposed(R, w + MECH_DEP_SCHUR, spiv, schur_inv, g, g);
        for (int a = 0; a < R; a++) y[ROWS[a]] = g[a];
        eq_dep_backward_t(w, y);
        double r[MA], rt[MA], norm = 0.0;
        for (int i = 0; i < M; i++) {
            double row = 0.0;
            r[i] = -b[i];
            rt[i] = -c[i];
            for (int j = 0; j < M; j++) {
                r[i] += block[i * M + j] * x[j];
                rt[i] += block[j * M + i] * y[j];
                row += fabs(block[i * M + j]);
            }
            norm = fmax(norm, row);
        }
        if (!isfinite(norm_inf(x, M)) || !isfinite(norm_inf(y, M))) { non_finite++; continue; }
        backward = fmax(backward, norm_inf(r, M) / (norm * norm_inf(x, M)));
        backward_t = fmax(backward_t, norm_inf(rt, M) / (norm * norm_inf(y, M)));
    }
    printf("trials %d backward %.3g backward_t %.3g sign_mismatches %d columns %.3g non_finite %d\n", TRIALS,
           backward, backward_t, mismatches, columns, non_finite);
    return 0;
}
