/* The DAE of any mechanism: fmu_src/mechanism_model/dae.py's MechanismDAE in C (see dae.h).
 *
 * At every right-hand-side evaluation eq. (11)
 *
 *     [[M,     Phi_q^T],   [qdd   ]   [Q    ]
 *      [Phi_q, 0      ]] . [lambda] = [gamma]
 *
 * is solved for the accelerations (and the drivers' multipliers), with M qdd + Phi_q^T lambda = Q
 * (the joints act on the bodies with -Phi_q^T lambda).  dae.py solves its range-space form
 * (Phi_q M^-1 Phi_q^T) lambda = Phi_q M^-1 Q - gamma; here its null-space form gives the same
 * accelerations up to round-off with less work (accelerations()); the range-space solve, which
 * gives every multiplier, serves the outputs that need them (joint and driver forces).
 *
 * Constraint stabilisation is generalized-coordinate partitioning (Wehage and Haug): the
 * Runge-Kutta method (rk.c) integrates the independent coordinates, their rates and each work
 * output (the time integral of a generated power: eq_powers_force, a driver's -lambda[row] nu[row],
 * and eq_powers_state, a load's or the dissipation's); the dependent coordinates are recovered from
 * Phi(q, t) = 0 by Newton-Raphson from a prediction made from accepted states only (so the
 * assembly branch is kept by continuity: a stage of a rejected step may sit on the other
 * branch near a dead point), and their rates from Phi_q qd = nu.  Every reported state
 * satisfies both to round-off.  After every accepted Runge-Kutta step the partition is reviewed
 * at the step's end: when the independent coordinates' velocity ratio (velocity_ratio) exceeds
 * DAE_REPARTITION_AWAY, they change to those a column-pivoted QR factorisation of Phi_q picks if
 * their ratio is DAE_REPARTITION_GAIN times smaller, and the integrator restarts there (at the
 * communication point, from the reported state, when the step passed it); the declared ones come
 * back once their ratio is below DAE_REPARTITION_RETURN.  A parameter change keeps the declared
 * coordinates whatever the partition (dae_change_parameters).  A trial
 * stage that Newton-Raphson from the prediction does not reach, or reaches on the other
 * assembly branch (the sign of the dependent block's determinant, which changes only through a
 * dead point), is reached by continuation from the base (DAE_CONTINUATION_STEPS sub-steps);
 * where even that fails the evaluation fails and the Runge-Kutta step is rejected and retried
 * 5x shorter (rk.h: RK_FUNCTION_REJECT; dae.py returns inf there, which scipy's step control
 * rejects the same way).  Only a step size that collapses fails a step (a dead point between
 * two communication points): it restarts from the last reported state with the QR's choice, at
 * most DAE_RESCUES times per communication step.
 *
 * The same algorithm, tolerances and decisions as dae.py, computed with less work:
 * - for the declared partition, the right-hand side and the reported states solve the reduced
 *   constraints (fmu_src/c_reduction.py, eq_red_*): each body's x and y, solved in closed form
 *   from the joint rows that are linear in them, leave the loop closures in the dependent angles
 *   (2 for the four-bar, 4 for the Watt six-bar), which Newton-Raphson solves with their own
 *   Jacobian (the dependent block's Schur complement, so the assembly branch reads the same);
 *   rates and accelerations follow from the reduced derivatives and V^T M V as below
 *   (reduced_positions, reduced_rates, reduced_accelerations).  Where that does not converge or
 *   lands on another branch, the full system below decides (and continues from the base); after
 *   a re-partition the full system serves;
 * - where the loop closures are dyads and single rows (fmu_src/c_loops.py, eq_red_stage), they
 *   are solved in closed form, loop after loop (closed_positions): the intersection of two circles
 *   or of a line and the unit circle, the solution on the predicted angle's side; Newton-Raphson
 *   on the reduced constraints serves where a loop's two solutions are not clearly apart;
 * - the prediction is the quintic Hermite interpolant of the last accepted step's start and
 *   end (positions, rates and accelerations; 1.8 Newton-Raphson iterations per evaluation on
 *   the four-bar at 1e-10 against 3.0 with dae.py's second-order Taylor step from the end,
 *   which is used after a restart);
 * - the declared partition's dependent block is factorised by generated code (equations.c,
 *   eq_dep_*): Gaussian elimination on its constant pivots (each body's x and y have +-1 in their
 *   joints' rows), fixed when the FMU is built, leaves a small Schur complement in the
 *   dependent angles (2 x 2 for the four-bar, 4 x 4 for the Watt six-bar) for a dense LU with
 *   partial pivoting; any other partition (after a re-partition) takes a dense LU of the block;
 * - Newton-Raphson factorises the block at the prediction and reuses the factors while the
 *   corrections shrink fast (a chord iteration), refactorising when they do not.  A fresh
 *   factorisation stops as dae.py does (a correction of at most NEWTON_STEP (1 + |q_i|), whose
 *   square is the error left); a reused one stops once the error it leaves, estimated from the
 *   ratio of successive corrections, is at most NEWTON_STEP^2 (1 + |q_i|);
 * - at the solution the block is factorised once more, for the rates and the accelerations:
 *   V = [-block^-1 Phi_q[:, independent]; I] spans Phi_q's null space, qd = V qd[independent]
 *   (+ block^-1 nu with drivers), and qdd comes from the K x K system V^T M V (K: degrees of
 *   freedom) and one more solve;
 * - cos and sin of the angles at the prediction are rotated from the base's (libm's, once per
 *   accepted step) by a series exact to round-off, and moved through each Newton correction the
 *   same way;
 * - Phi_q's constant entries are written only where the generic code reads the whole matrix
 *   (a dense LU, the partition's review); the outputs are computed when a host reads them,
 *   a group at a time (fmi2Functions.c), the state's from the cos and sin the reported state was
 *   solved with (ModelState.tr) rather than libm's again;
 * - the small dense kernels are unrolled and inlined (linalg.h).
 * Results agree with dae.py's to round-off: tests/test_fmu_native.py.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "dae.h"

/* Small systems: ask the compiler to unroll the linear algebra's loops completely (linalg.h). */
#if defined(__GNUC__) && MECH_M <= 16 && MECH_N <= 32
#define LINALG_UNROLL _Pragma("GCC unroll 16")
#endif
/* ... and to inline the LU kernels: the Schur complement's (MECH_DEP_R, at every evaluation) where
   they are called; the whole block's (MECH_M, rarer) through the dense_* functions below. */
#if defined(__GNUC__)
#define LINALG_INLINE __attribute__((always_inline)) inline
#define NOINLINE __attribute__((noinline))
#else
#define NOINLINE
#endif
#include "linalg.h"

/* pi to double precision (C99 has no M_PI). */
#define M_PI_VALUE 3.14159265358979323846

enum {
    N = MECH_N,
    M = MECH_M,
    K = MECH_K,
    N_DRIVERS = MECH_N_DRIVERS,
    N_WORKS = MECH_N_WORKS,              /* the drivers' work first (MECH_N_FORCE_WORKS = N_DRIVERS) */
    N_ANGLES = MECH_N_ANGLES,
    MA = MECH_ALLOC(MECH_M),
    KA = MECH_ALLOC(MECH_K),
    TRIG = MECH_ALLOC(MECH_N_TRIG),
    R = MECH_DEP_R,                       /* the declared block's Schur complement (equations.h) */
    RA = MECH_ALLOC(MECH_DEP_R),
    FACTORS = MA * MA > MECH_DEP_W ? MA * MA : MECH_DEP_W
};
/* Angle changes up to this (rad) move cos and sin by the rotation's series: its truncation
   error, |delta|^6 / 720 and |delta|^7 / 5040, stays below 1e-20 (Newton-Raphson corrections) ... */
#define TRIG_STEP 1e-3
/* ... and changes up to this (rad) by a longer series, to delta^14 (|delta|^15 / 15! < 1e-21): from
   the base, whose cos and sin come from libm, to a prediction (libm calls cost more). */
#define TRIG_ROTATION 0.25

static const int INDEPENDENT[KA] = MECH_INDEPENDENT;
static const int DEP_ROWS[RA] = MECH_DEP_ROWS;
static const int DEP_COLS[RA] = MECH_DEP_COLS;
static const int ZEROS[KA] = {0};       /* a dense matrix's envelope (cholesky_factor) */
static const int ANGLES[MECH_ALLOC(MECH_N_ANGLES)] = MECH_ANGLES;
static const int S_ENVELOPE[MA] = MECH_RANGE_ENVELOPE;
static const int DRIVERS[MECH_ALLOC(MECH_N_DRIVERS)][3] = MECH_DRIVERS;
static const char *const ROW_NAMES[MA] = MECH_ROW_NAMES;
static const int OUTPUT_KINDS[MECH_N_OUTPUTS] = MECH_OUTPUT_KINDS;
static const int OUTPUT_INDICES[MECH_N_OUTPUTS] = MECH_OUTPUT_INDICES;
static const int STATE_GROUP[MECH_ALLOC(MECH_N_STATE_GROUP)] = MECH_STATE_GROUP;
static const char *const INTEGRATOR_NAMES[FMU_N_INTEGRATORS] = FMU_INTEGRATOR_NAMES;

static void declared_partition(int *independent, int *dependent);
static double length_scale(const double *q);

/* The whole dependent block's LU kernels (a partition other than the declared one, the review). */
static NOINLINE int dense_factor(double *a, int *piv, double *inv_diag)
{
    return lu_factor(M, a, piv, inv_diag);
}

static NOINLINE void dense_solve(const double *lu, const int *piv, const double *inv_diag, const double *b, double *x)
{
    lu_solve(M, lu, piv, inv_diag, b, x);
}

static NOINLINE void dense_solve_transposed(const double *lu, const int *piv, const double *inv_diag, const double *b,
                                            double *x)
{
    lu_solve_transposed(M, lu, piv, inv_diag, b, x);
}

double dae_snap_time(double t)
{
    return model_snap_time(t);
}

void dae_drive_at(const double *p, double t, double *d)
{
    for (int k = 0; k < N_DRIVERS; k++) {
        /* -1: a driver whose position is a function of t, whose row does not use d */
        d[3 * k] = DRIVERS[k][0] >= 0 ? p[DRIVERS[k][0]] : 0.0;
        d[3 * k + 1] = t;
        d[3 * k + 2] = DRIVERS[k][1] >= 0 ? p[DRIVERS[k][1]] : 0.0;
    }
}

/* The diagonal of M at q and its inverse. */
static void mass_inverse(const double *p, const double *q, const double *tr, double *mass, double *minv)
{
    eq_mass_diagonal(q, tr, p, mass);
    for (int i = 0; i < N; i++) minv[i] = 1.0 / mass[i];
}

/* tr (eq_trig's cos and sin of the angles) of q_new, from tr of q_old. */
static void trig_move(const double *q_old, const double *q_new, double *tr)
{
    for (int a = 0; a < N_ANGLES; a++) {
        const int i = ANGLES[a];
        const double delta = q_new[i] - q_old[i];
        if (delta == 0.0) continue;
        if (!(fabs(delta) <= TRIG_STEP)) {
            tr[2 * a] = cos(q_new[i]);
            tr[2 * a + 1] = sin(q_new[i]);
            continue;
        }
        const double d2 = delta * delta;
        const double c = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0));
        const double s = delta * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0)));
        const double c0 = tr[2 * a], s0 = tr[2 * a + 1];
        tr[2 * a] = c0 * c - s0 * s;
        tr[2 * a + 1] = s0 * c + c0 * s;
    }
}

/* tr of q_new from tr_old of q_old (libm's values there): each angle rotated by its change, by the
   series to delta^14 when that is within TRIG_ROTATION, else by libm. */
static void trig_rotate(const double *q_old, const double *tr_old, const double *q_new, double *tr)
{
    LINALG_UNROLL
    for (int a = 0; a < N_ANGLES; a++) {
        const int i = ANGLES[a];
        const double delta = q_new[i] - q_old[i];
        if (!(fabs(delta) <= TRIG_ROTATION)) {
            tr[2 * a] = cos(q_new[i]);
            tr[2 * a + 1] = sin(q_new[i]);
            continue;
        }
        /* Horner's scheme in delta^2 with the Taylor coefficients (-1)^k / (2k)! and (-1)^k / (2k+1)! */
        const double d2 = delta * delta;
        const double c = 1.0 + d2 * (-1.0 / 2.0 + d2 * (1.0 / 24.0 + d2 * (-1.0 / 720.0 + d2 * (1.0 / 40320.0
            + d2 * (-1.0 / 3628800.0 + d2 * (1.0 / 479001600.0 + d2 * (-1.0 / 87178291200.0)))))));
        const double sn = delta + delta * d2 * (-1.0 / 6.0 + d2 * (1.0 / 120.0 + d2 * (-1.0 / 5040.0 + d2 * (1.0
            / 362880.0 + d2 * (-1.0 / 39916800.0 + d2 * (1.0 / 6227020800.0))))));
        const double c0 = tr_old[2 * a], s0 = tr_old[2 * a + 1];
        tr[2 * a] = c0 * c - s0 * sn;
        tr[2 * a + 1] = s0 * c + c0 * sn;
    }
}

/* -- kinematics --------------------------------------------------------------------------- */

/* The dependent columns of the m x n Jacobian J, as an m x m block. */
static void dependent_block(const double *J, const int *dependent, double *block)
{
    LINALG_UNROLL
    for (int i = 0; i < M; i++) {
        const double *row = J + i * N;
        LINALG_UNROLL
        for (int j = 0; j < M; j++) block[i * M + j] = row[dependent[j]];
    }
}

/* The dependent block of Phi_q, LU-factorised: for the declared partition by eq_dep_factor (the
   static elimination on its constant pivots, equations.h) and a dense LU of its small Schur
   complement; for any other partition (after a re-partition) by a dense LU of the block. */
typedef struct {
    int dense;
    double lu[FACTORS];         /* dense: the block's LU; else eq_dep_factor's workspace, the Schur LU in it */
    int piv[MA];
    double inv_diag[MA];
    int sign;                   /* the sign of det(block) */
} Factors;

/* Factorise the block of J's columns `dependent` (declared: the declared partition's); 0, or 1 when
   it is singular. */
static int factor_block(int declared, const int *dependent, const double *J, Factors *f)
{
    f->dense = !declared;
    if (declared) {
        double *schur = f->lu + MECH_DEP_SCHUR;
        eq_dep_factor(J, f->lu);
        if (lu_factor(R, schur, f->piv, f->inv_diag)) return 1;
        f->sign = MECH_DEP_SIGN * lu_det_sign(R, f->piv, f->inv_diag);
        return 0;
    }
    dependent_block(J, dependent, f->lu);
    if (dense_factor(f->lu, f->piv, f->inv_diag)) return 1;
    f->sign = lu_det_sign(M, f->piv, f->inv_diag);
    return 0;
}

/* x = block^-1 b (b: the block's rows, x: its columns; not the same array). */
static void block_solve(const Factors *f, const double *b, double *x)
{
    double t[MA], g[RA];
    if (f->dense) {
        dense_solve(f->lu, f->piv, f->inv_diag, b, x);
        return;
    }
    memcpy(t, b, sizeof t);
    eq_dep_forward(f->lu, t);
    LINALG_UNROLL
    for (int a = 0; a < R; a++) g[a] = t[DEP_ROWS[a]];
    lu_solve(R, f->lu + MECH_DEP_SCHUR, f->piv, f->inv_diag, g, g);
    LINALG_UNROLL
    for (int a = 0; a < R; a++) x[DEP_COLS[a]] = g[a];
    eq_dep_backward(f->lu, t, x);
}

/* y = block^-T c (c: the block's columns, y: its rows; not the same array). */
static void block_solve_transposed(const Factors *f, const double *c, double *y)
{
    double g[RA];
    if (f->dense) {
        dense_solve_transposed(f->lu, f->piv, f->inv_diag, c, y);
        return;
    }
    eq_dep_forward_t(f->lu, c, y, g);
    lu_solve_transposed(R, f->lu + MECH_DEP_SCHUR, f->piv, f->inv_diag, g, g);
    LINALG_UNROLL
    for (int a = 0; a < R; a++) y[DEP_ROWS[a]] = g[a];
    eq_dep_backward_t(f->lu, y);
}

/* A configuration and what the right-hand side needs of it. */
typedef struct {
    double q[N], qd[N], tr[TRIG];
    double J[MA * N];           /* Phi_q at q */
    double nu[MA];
    Factors f;                  /* the dependent block: positions() leaves its last Newton-Raphson
                                   factorisation (near q), velocities() the one at q */
    int sign;                   /* sign of det(block) where positions() last factorised it: the branch */
    double v[KA][MA];           /* velocities(): -block^-1 Phi_q[:, independent j], the null space of Phi_q */
} Configuration;

/* c->q[dependent] with Phi(c->q, t) = 0, by Newton-Raphson from c->q (c->q[independent] fixed);
   c->tr is set for the result, c->f holds the last factorisation (module doc), and c->sign the
   sign of its determinant (dae.py's: of the last factorisation, near the solution).  declared:
   `dependent` is the declared partition's. */
static int positions(const double *p, const double *d, int declared, const int *dependent, double t,
                     Configuration *c, unsigned long *iterations, char *message)
{
    double phi[MA], dx[MA], ratio[MA], q_old[N];
    double *q = c->q;
    int fresh = 1;                       /* factorise Phi_q at the current q in this iteration */
    double previous = INFINITY;
    for (int iteration = 0; iteration < DAE_NEWTON_ITERATIONS; iteration++) {
        ++*iterations;
        if (fresh) {
            eq_constraints_jacobian(q, c->tr, t, p, d, phi, c->J);
            if (factor_block(declared, dependent, c->J, &c->f)) {
                snprintf(message, MODEL_MESSAGE, "the constraint Jacobian is singular there (a toggle or dead-point "
                         "configuration)");
                return DAE_ASSEMBLY;
            }
        } else {
            eq_constraints(q, c->tr, t, p, d, phi);
        }
        block_solve(&c->f, phi, dx);
        memcpy(q_old, q, sizeof q_old);
        LINALG_UNROLL
        for (int j = 0; j < M; j++) {
            const double qi = q[dependent[j]] - dx[j];
            q[dependent[j]] = qi;
            ratio[j] = fabs(dx[j]) / (1.0 + fabs(qi));
        }
        /* the largest correction, relative (NaN if any is: then it failed) */
        LINALG_UNROLL
        for (int width = 1; width < M; width *= 2) {
            LINALG_UNROLL
            for (int j = 0; j + width < M; j += 2 * width)
                ratio[j] = ratio[j + width] > ratio[j] || isnan(ratio[j + width]) ? ratio[j + width] : ratio[j];
        }
        const double step = ratio[0];
        if (!isfinite(step)) break;
        trig_move(q_old, q, c->tr);
        if (fresh ? step <= DAE_NEWTON_STEP
                  : step <= DAE_NEWTON_STEP && step * step <= DAE_NEWTON_STEP * DAE_NEWTON_STEP * previous) {
            c->sign = c->f.sign;
            return DAE_OK;
        }
        /* reuse the factors while the corrections shrink at least fourfold per iteration */
        fresh = !fresh && !(step <= 0.25 * previous);
        previous = step;
    }
    for (int i = 0; i < N; i++)
        if (isinf(q[i])) {                   /* dae.py: cos(inf) raised there */
            snprintf(message, MODEL_MESSAGE, "the loop cannot be closed: Newton-Raphson diverged");
            return DAE_ASSEMBLY;
        }
    eq_trig(q, c->tr);
    eq_constraints(q, c->tr, t, p, d, phi);
    int worst = 0;
    double largest = -1.0;
    for (int i = 0; i < M; i++) {          /* numpy's max and argmax: a NaN wins, the first one */
        const double v = fabs(phi[i]);
        if (isnan(v)) { worst = i; largest = v; break; }
        if (v > largest) { largest = v; worst = i; }
    }
    snprintf(message, MODEL_MESSAGE, "the loop cannot be closed: Phi = 0 has no solution near the previous "
             "configuration (Newton-Raphson left a residual of %.3g in joint %s)", largest, ROW_NAMES[worst]);
    return DAE_ASSEMBLY;
}

/* c->qd[dependent] from Phi_q qd = nu (c->J, c->nu at c->q) with c->qd[independent] given: the
   block is factorised at q (c->f, for the accelerations too) and solved for c->v, the rates of
   the dependent coordinates per unit rate of each independent one (Phi_q V = 0 with
   V = [c->v; I]), so that qd[dependent] = block^-1 nu + sum_j v_j qd[independent j] (nu = 0
   without drivers). */
static int velocities(int declared, const int *dependent, const int *independent, Configuration *c, char *message)
{
    double b[MA], w[MA];
    if (factor_block(declared, dependent, c->J, &c->f)) {
        snprintf(message, MODEL_MESSAGE, "the constraint Jacobian is singular: a toggle (dead-point) configuration");
        return DAE_ASSEMBLY;
    }
    for (int j = 0; j < K; j++) {
        eq_jacobian_column(c->J, independent[j], b);
        LINALG_UNROLL
        for (int i = 0; i < M; i++) b[i] = -b[i];
        block_solve(&c->f, b, c->v[j]);
    }
    if (N_DRIVERS > 0) block_solve(&c->f, c->nu, w);
    LINALG_UNROLL
    for (int i = 0; i < M; i++) {
        double x = N_DRIVERS > 0 ? w[i] : 0.0;
        for (int j = 0; j < K; j++) x += c->v[j][i] * c->qd[independent[j]];
        c->qd[dependent[i]] = x;
    }
    return DAE_OK;
}

/* A configuration's Jacobian with its constant entries (eq_constraints_jacobian and
   eq_jacobian_variable write the others): what the dense LU, the partition's review and choice
   read.  The declared partition's factorisation, the products and the columns (eq_jacobian_column)
   read only the entries that vary. */
static void configuration_init(Configuration *c)
{
    eq_jacobian_constants(c->J);
}

/* c->J and c->nu at c->q (c->tr set; c->J initialised). */
static void jacobian_at(const double *p, const double *d, double t, Configuration *c)
{
    eq_jacobian_variable(c->q, c->tr, p, c->J);
    eq_nu(t, p, d, c->nu);
}

/* -- the predictor ------------------------------------------------------------------------- */

/* The coordinates `list` of q (NULL: the first n) at time t predicted from the accepted states: the
   quintic Hermite interpolant of the last accepted step's start and end (positions, rates,
   accelerations), else (after a restart) the second-order Taylor step from the base that dae.py's
   _state takes. */
static void predict_listed(const ModelState *s, double t, const int *list, int n, double *q)
{
    const DaePoint *p1 = &s->base, *p0 = &s->before;
    if (!(p0->t < p1->t)) {
        const double dt = t - p1->t, half = 0.5 * dt * dt;
        for (int k = 0; k < n; k++) {
            const int i = list ? list[k] : k;
            q[i] = p1->q[i] + p1->qd[i] * dt + p1->qdd[i] * half;
        }
        return;
    }
    const double h = p1->t - p0->t, x = (t - p0->t) / h;
    const double x_2 = x * x, x_3 = x_2 * x, x_4 = x_3 * x, x_5 = x_4 * x;
    /* the quintic Hermite basis */
    const double H0 = 1.0 - 10.0 * x_3 + 15.0 * x_4 - 6.0 * x_5, H5 = 1.0 - H0;
    const double H1 = (x - 6.0 * x_3 + 8.0 * x_4 - 3.0 * x_5) * h, H4 = (-4.0 * x_3 + 7.0 * x_4 - 3.0 * x_5) * h;
    const double H2 = 0.5 * (x_2 - 3.0 * x_3 + 3.0 * x_4 - x_5) * h * h, H3 = 0.5 * (x_3 - 2.0 * x_4 + x_5) * h * h;
    for (int k = 0; k < n; k++) {
        const int i = list ? list[k] : k;
        q[i] = H0 * p0->q[i] + H1 * p0->qd[i] + H2 * p0->qdd[i] + H3 * p1->qdd[i] + H4 * p1->qd[i] + H5 * p1->q[i];
    }
}

/* All of q predicted (predict_listed). */
static void predict(const ModelState *s, double t, double *q)
{
    predict_listed(s, t, NULL, N, q);
}
/* c->q at (y's independent coordinates, t) by following the assembly branch from the base (dae.py's
   _continuation): the independent coordinates and time moved there in 2, 4, 8, then 32 equal
   steps, each solved by Newton-Raphson from the previous one and required to stay on the base's
   branch (the sign of the dependent block's determinant changes only through a dead point).
   For a trial stage the predictor does not reach (the integrator may try a step ten times its
   last one); DAE_ASSEMBLY when even 32 steps do not reach it (a dead point on the way). */
static int continuation(ModelState *s, double t, const double *y, Configuration *c)
{
    static const int STEPS[] = DAE_CONTINUATION_STEPS;
    const DaePoint *b = &s->base;
    s->continuations++;
    for (size_t a = 0; a < sizeof STEPS / sizeof *STEPS; a++) {
        const int n = STEPS[a];
        int k = 1;
        memcpy(c->q, b->q, sizeof c->q);
        for (; k <= n; k++) {
            const double f = (double)k / n;
            for (int j = 0; j < K; j++) {
                const int i = s->independent[j];
                c->q[i] = b->q[i] + f * (y[j] - b->q[i]);
            }
            eq_trig(c->q, c->tr);
            if (positions(s->p, s->d, s->declared, s->dependent, b->t + f * (t - b->t), c, &s->newton_iterations,
                          s->rhs_message) || c->sign != b->sign)
                break;
        }
        if (k > n) return DAE_OK;
    }
    snprintf(s->rhs_message, MODEL_MESSAGE, "Phi = 0 cannot be followed from t = %.9g s to %.9g s: the loop cannot "
             "be closed on the way (a dead point)", b->t, t);
    return DAE_ASSEMBLY;
}

/* The consistent configuration for the integrated y at time t (dae.py's _state): the prediction,
   q[independent] and qd[independent] from y, the rest from the constraints: by Newton-Raphson
   from the prediction, else (it diverged, or reached the other assembly branch) by continuation
   from the base. */
static int state_at(ModelState *s, double t, const double *y, Configuration *c)
{
    if (!s->declared) configuration_init(c);
    predict(s, t, c->q);
    for (int j = 0; j < K; j++) {
        c->q[s->independent[j]] = y[j];
        c->qd[s->independent[j]] = y[K + j];
    }
    trig_rotate(s->base.q, s->base.tr, c->q, c->tr);
    int r = positions(s->p, s->d, s->declared, s->dependent, t, c, &s->newton_iterations, s->rhs_message);
    if (r || c->sign != s->base.sign) r = continuation(s, t, y, c);
    if (r) return r;
    jacobian_at(s->p, s->d, t, c);
    return velocities(s->declared, s->dependent, s->independent, c, s->rhs_message);
}

/* -- dynamics ------------------------------------------------------------------------------ */

/* (qdd, lambda) of eq. (11) at a consistent configuration (c->J at c->q) by the range-space solve:
   every multiplier, for the outputs that need them (joint and driver forces). */
static int solve(const double *p, const double *d, const double *minv, double t, Configuration *c, double *qdd,
                 double *lam, char *message)
{
    double Q[N], S[MA * MA];
    eq_range_matrix(c->J, minv, S);
    if (cholesky_factor(M, S, S_ENVELOPE)) {
        snprintf(message, MODEL_MESSAGE, "Phi_q M^-1 Phi_q^T is singular: a toggle (dead-point) configuration");
        return DAE_INTEGRATION;
    }
    eq_range_rhs(c->q, c->tr, c->qd, t, p, d, c->J, minv, Q, lam);
    cholesky_solve(M, S, S_ENVELOPE, lam);
    eq_accelerations(c->J, minv, Q, lam, qdd);
    return DAE_OK;
}

/* qdd of eq. (11) at a consistent configuration whose dependent block is factorised at q (c->f,
   with c->v: velocities()) for the right-hand sides Q and gamma (M qdd + Phi_q^T lambda = Q,
   Phi_q qdd = gamma), and, with want_lam, the multipliers (every row), by the null-space form:
   with V = [c->v; I] (Phi_q V = 0) and qdd = c + V a, c = [block^-1 gamma; 0] (Phi_q c = gamma),
   the multipliers drop out of V^T (M qdd - Q) = 0: (V^T M V) a = V^T (Q - M c), a K x K system;
   then block^T lambda = (Q - M qdd)[dependent].  One solve with the block's factors (and one
   transposed for the multipliers) instead of forming and factorising Phi_q M^-1 Phi_q^T: the same
   accelerations up to round-off.  The right-hand side's (accelerations) and the directional
   derivatives' (dae_directional: the same matrix, other right-hand sides). */
static LINALG_INLINE int null_space_solve(const ModelState *s, const double *mass, Configuration *c,
                                          const double *Q, const double *gamma, double *qdd, double *lam,
                                          int want_lam)
{
    double particular[MA], b[MA], A[KA * KA], a[KA];
    double (*v)[MA] = c->v;
    const int *dependent = s->dependent, *independent = s->independent;
    block_solve(&c->f, gamma, particular);
    for (int j = 0; j < K; j++) {
        double sum = Q[independent[j]];
        LINALG_UNROLL
        for (int i = 0; i < M; i++) sum += v[j][i] * (Q[dependent[i]] - mass[dependent[i]] * particular[i]);
        a[j] = sum;
        for (int l = 0; l <= j; l++) {
            double m = j == l ? mass[independent[j]] : 0.0;
            LINALG_UNROLL
            for (int i = 0; i < M; i++) m += mass[dependent[i]] * v[j][i] * v[l][i];
            A[j * K + l] = m;
        }
    }
    if (K == 1) {
        a[0] /= A[0];
    } else if (K > 1) {
        if (cholesky_factor(K, A, ZEROS)) return DAE_INTEGRATION;
        cholesky_solve(K, A, ZEROS, a);
    }
    for (int j = 0; j < K; j++) qdd[independent[j]] = a[j];
    LINALG_UNROLL
    for (int i = 0; i < M; i++) {
        double x = particular[i];
        for (int j = 0; j < K; j++) x += v[j][i] * a[j];
        qdd[dependent[i]] = x;
    }
    if (want_lam) {
        LINALG_UNROLL
        for (int i = 0; i < M; i++) b[i] = Q[dependent[i]] - mass[dependent[i]] * qdd[dependent[i]];
        block_solve_transposed(&c->f, b, lam);
    }
    return DAE_OK;
}

/* qdd of eq. (11) at a consistent configuration prepared by velocities(), and the multipliers
   (lam: every row with want_lam, else only when there are drivers, whose power needs theirs). */
static LINALG_INLINE int accelerations(const ModelState *s, double t, Configuration *c, double *qdd, double *lam,
                                       int want_lam)
{
    double Q[N], gamma[MA], mass_q[N];
    const double *mass = MECH_MASS_IS_CONSTANT ? s->mass : mass_q;
    if (!MECH_MASS_IS_CONSTANT) eq_mass_diagonal(c->q, c->tr, s->p, mass_q);
    eq_dynamics(c->q, c->tr, c->qd, t, s->p, s->d, Q, gamma);
    return null_space_solve(s, mass, c, Q, gamma, qdd, lam, want_lam || N_DRIVERS > 0);
}

#if MECH_RED
/* -- the reduced system ------------------------------------------------------------------- */

enum { NE = MECH_RED_N_E, NEA = MECH_ALLOC(MECH_RED_N_E) };
static const int RED_Z[RA] = MECH_RED_Z;          /* the Schur complement's coordinates (indices in q) */
static const int RED_E[NEA] = MECH_RED_E;         /* the static pivots' coordinates, in closed form */
static const int RED_Z_ANGLE[RA] = MECH_RED_Z_ANGLE;     /* their angles' places in ANGLES (-1: none) */
static const int RED_E_ANGLE[NEA] = MECH_RED_E_ANGLE;
static const int RED_FIRST[MECH_ALLOC(MECH_RED_N_FIRST)] = MECH_RED_FIRST;   /* angles in closed form, first */
/* angles in closed form that depend on z: predicted, then moved to their closed forms after Newton-Raphson */
#define LATE_ANGLES (MECH_RED_E_ANGLES > 0 && !MECH_RED_ANGLES_FIRST)

/* The reduced path serves the declared partition with the independent coordinates in the file's
   order (the generated derivatives' columns), and at most one driver (its power below). */
static int reduced_applies(const ModelState *s)
{
    return s->declared && N_DRIVERS <= 1 && memcmp(s->independent, INDEPENDENT, K * sizeof(int)) == 0;
}

/* tr for the coordinates `list` (indices in q) whose angle places are `angle` (-1: not an angle),
   moved from q_old to q (trig_move's rule). */
static void trig_move_listed(const int *list, const int *angle, int count, const double *q_old, const double *q,
                             double *tr)
{
    for (int k = 0; k < count; k++) {
        const int a = angle[k], i = list[k];
        if (a < 0) continue;
        const double delta = q[i] - q_old[i];
        if (delta == 0.0) continue;
        if (!(fabs(delta) <= TRIG_STEP)) {
            tr[2 * a] = cos(q[i]);
            tr[2 * a + 1] = sin(q[i]);
            continue;
        }
        const double d2 = delta * delta;
        const double cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0));
        const double sd = delta * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0)));
        const double c0 = tr[2 * a], s0 = tr[2 * a + 1];
        tr[2 * a] = c0 * cd - s0 * sd;
        tr[2 * a + 1] = s0 * cd + c0 * sd;
    }
}

/* The reduced system's Jacobian S = dr/dz (the dependent block's Schur complement), factorised. */
typedef struct {
    double S[RA * RA], inv_diag[RA];
    int piv[RA];
} ReducedLU;

/* The reduced path's start (reduced_positions and closed_positions): the MECH_RED_Z coordinates
   (and the angles in closed form that depend on them) predicted, their values kept in q_pred
   (trig_move_listed's old values), the independent coordinates and rates from y, a driven angle
   exact before the rest reads its cos and sin, and cos and sin of every angle rotated from the
   base's. */
static void reduced_predict(const ModelState *s, double t, const double *y, Configuration *c, double *q_pred)
{
    double *q = c->q;
    predict_listed(s, t, RED_Z, R, q);
    if (LATE_ANGLES) predict_listed(s, t, RED_E, NE, q);     /* their cos and sin rotate from there */
    for (int a = 0; a < R; a++) q_pred[RED_Z[a]] = q[RED_Z[a]];
    if (LATE_ANGLES)
        for (int e = 0; e < NE; e++) if (RED_E_ANGLE[e] >= 0) q_pred[RED_E[e]] = q[RED_E[e]];
    for (int j = 0; j < K; j++) {
        q[INDEPENDENT[j]] = y[j];
        c->qd[INDEPENDENT[j]] = y[K + j];
    }
    if (MECH_RED_N_FIRST > 0) {
        double x[MECH_ALLOC(MECH_RED_N_FIRST)];
        eq_red_closed_angles(q, t, s->p, s->d, x);
        for (int k = 0; k < MECH_RED_N_FIRST; k++) q[RED_FIRST[k]] = x[k];
    }
    trig_rotate(s->base.q, s->base.tr, q, c->tr);
}

/* The reduced path's end: the MECH_RED_E coordinates from their closed forms at the solved z (the
   cos and sin of those that are angles moved from q_pred's values). */
static void reduced_eliminated(const ModelState *s, double t, Configuration *c, const double *q_pred)
{
    double x[NEA];
    eq_red_closed(c->q, c->tr, t, s->p, s->d, x);
    LINALG_UNROLL
    for (int e = 0; e < NE; e++) c->q[RED_E[e]] = x[e];
    if (LATE_ANGLES) trig_move_listed(RED_E, RED_E_ANGLE, NE, q_pred, c->q, c->tr);
}

#if MECH_RED_N_STAGES > 0
/* -- the reduced constraints in closed form (fmu_src/c_loops.py) ----------------------------- */

static const int RED_STAGES[2 * MECH_RED_N_STAGES] = MECH_RED_STAGES;
/* A stage's two solutions must be apart: (P x d)^2 > CLOSED_APART |u|^2 |d|^2 for a dyad (the angle
   between the dyad's two links seen from its base at least asin(0.1)), (gamma)^2 < (1 - CLOSED_APART)
   (alpha^2 + beta^2) for a single row.  There the circles' intersection loses at most ~5 ulp to
   cancellation (the error grows as 1 / sin of that angle); closer to a dead point Newton-Raphson,
   with its branch test and continuation, decides. */
#define CLOSED_APART 1e-2

/* The angle whose cos and sin are (ca, sa), nearest a0 (cos c0, sin c0): a0 plus the difference,
   asin of its sine to round-off when it is small (|s| <= 1e-3: the series' next term is
   5 s^7 / 112 < 1e-19 |s|), else atan2's. */
static double angle_near(double a0, double c0, double s0, double ca, double sa)
{
    const double s = sa * c0 - ca * s0, c = ca * c0 + sa * s0;     /* sin and cos of the difference */
    if (c > 0.0 && fabs(s) <= 1e-3) {
        const double s2 = s * s;
        return a0 + s * (1.0 + s2 * (1.0 / 6.0 + s2 * (3.0 / 40.0)));
    }
    return a0 + atan2(s, c);
}

/* A dyad R(a) u + R(b) w + c = 0 (k: u_x, u_y, w_x, w_y, c_x, c_y): P = R(a) u lies on the circle
   of radius |u| about 0 and on that of radius |w| about d = -c, at P . d = m and P . d_perp =
   +-h (d_perp = (-d_y, d_x)); the solution on the side of the predicted angle's P (cos pc, sin
   ps) is taken.  Writes cos and sin of a and of b; 1 when the two solutions are not clearly
   apart or the prediction is not near one of them. */
static int closed_dyad(const double *k, double pc, double ps, double *tr_a, double *tr_b)
{
    const double ux = k[0], uy = k[1], wx = k[2], wy = k[3], dx = -k[4], dy = -k[5];
    const double uu = ux * ux + uy * uy, ww = wx * wx + wy * wy, dd = dx * dx + dy * dy;
    const double m = 0.5 * (uu + dd - ww), h2 = uu * dd - m * m;
    if (!(h2 > CLOSED_APART * uu * dd)) return 1;
    const double h = sqrt(h2);
    const double side = -(pc * ux - ps * uy) * dy + (ps * ux + pc * uy) * dx;    /* R(a_pred) u . d_perp */
    const double root = side >= 0.0 ? h : -h;
    if (!(fabs(side - root) <= 0.5 * h)) return 1;
    /* three reciprocals for six quotients: the divisions are on the evaluation's critical path
       (measured in-process on the five-bar: 2.6 % less time per evaluation) */
    const double idd = 1.0 / dd, iuu = 1.0 / uu, iww = 1.0 / ww;
    const double px = (m * dx - root * dy) * idd, py = (m * dy + root * dx) * idd;
    const double qx = dx - px, qy = dy - py;                                     /* R(b) w */
    tr_a[0] = (px * ux + py * uy) * iuu;
    tr_a[1] = (ux * py - uy * px) * iuu;
    tr_b[0] = (qx * wx + qy * wy) * iww;
    tr_b[1] = (wx * qy - wy * qx) * iww;
    return 0;
}

/* A single row alpha cos(a) + beta sin(a) + gamma = 0 (k: alpha, beta, gamma): (cos a, sin a) on
   the line e . (alpha, beta) = -gamma and the unit circle, on the predicted angle's side of
   (alpha, beta). */
static int closed_single(const double *k, double pc, double ps, double *tr_a)
{
    const double alpha = k[0], beta = k[1], gamma = k[2];
    const double rr = alpha * alpha + beta * beta, h2 = rr - gamma * gamma;
    if (!(h2 > CLOSED_APART * rr)) return 1;
    const double h = sqrt(h2);
    const double side = -beta * pc + alpha * ps;
    const double root = side >= 0.0 ? h : -h;
    if (!(fabs(side - root) <= 0.5 * h)) return 1;
    const double irr = 1.0 / rr;
    tr_a[0] = (-gamma * alpha - root * beta) * irr;
    tr_a[1] = (-gamma * beta + root * alpha) * irr;
    return 0;
}

/* reduced_positions() in closed form: the same prediction, then the stages in turn, each angle
   taken nearest its prediction; the MECH_RED_E coordinates from their closed forms.  c->sign is
   left 0: reduced_rates() reads it off S's factorisation at the solution.  0, or 1 when a stage has
   no clear solution (reduced_positions() then runs Newton-Raphson). */
static int closed_positions(ModelState *s, double t, const double *y, Configuration *c)
{
    double q_pred[N], coefficients[6];
    double *q = c->q;
    const double *p = s->p, *d = s->d;
    reduced_predict(s, t, y, c, q_pred);
    for (int k = 0; k < MECH_RED_N_STAGES; k++) {
        const int a = RED_STAGES[2 * k], b = RED_STAGES[2 * k + 1];
        double *tr_a = c->tr + 2 * RED_Z_ANGLE[a], tr_b[2];
        const double ca = tr_a[0], sa = tr_a[1];
        eq_red_stage(k, q, c->tr, t, p, d, coefficients);
        if (b >= 0) {
            double *to_b = c->tr + 2 * RED_Z_ANGLE[b];
            if (closed_dyad(coefficients, ca, sa, tr_a, tr_b)) return 1;
            q[RED_Z[b]] = angle_near(q[RED_Z[b]], to_b[0], to_b[1], tr_b[0], tr_b[1]);
            to_b[0] = tr_b[0];
            to_b[1] = tr_b[1];
        } else if (closed_single(coefficients, ca, sa, tr_a)) {
            return 1;
        }
        q[RED_Z[a]] = angle_near(q[RED_Z[a]], ca, sa, tr_a[0], tr_a[1]);
    }
    c->sign = 0;
    reduced_eliminated(s, t, c, q_pred);
    return 0;
}
#endif

/* positions() on the reduced constraints (fmu_src/c_reduction.py): the prediction (predict()'s
   for the MECH_RED_Z coordinates and the angles in closed form), Newton-Raphson on r(z) = 0 for z
   only, with positions()'s stopping rule and chord iteration, then the MECH_RED_E coordinates
   from their closed forms.  c->q, c->tr, c->sign (the block's determinant's sign: MECH_DEP_SIGN
   times its Schur complement's) are set.  0, or 1 when the full path must decide (no
   convergence, a singular S, or another assembly branch than the base's: it then continues). */
static int reduced_positions(ModelState *s, double t, const double *y, Configuration *c)
{
    double r[RA], dz[RA], ratio[RA], z_old[RA], q_pred[N];
    ReducedLU f;
    double *q = c->q;
    const double *p = s->p, *d = s->d;
    int sign = 1;
#if MECH_RED_N_STAGES > 0
    if (!closed_positions(s, t, y, c)) return 0;
#endif
    reduced_predict(s, t, y, c, q_pred);
    if (R > 0) {
        int fresh = 1, converged = 0;
        double previous = INFINITY;
        for (int iteration = 0; iteration < DAE_NEWTON_ITERATIONS && !converged; iteration++) {
            s->newton_iterations++;
            if (fresh) {
                eq_red_newton(q, c->tr, t, p, d, r, f.S);
                if (lu_factor(R, f.S, f.piv, f.inv_diag)) return 1;
                sign = lu_det_sign(R, f.piv, f.inv_diag);
            } else {
                eq_red_residual(q, c->tr, t, p, d, r);
            }
            lu_solve(R, f.S, f.piv, f.inv_diag, r, dz);
            double step = 0.0;
            LINALG_UNROLL
            for (int a = 0; a < R; a++) {
                z_old[a] = q[RED_Z[a]];
                const double qi = z_old[a] - dz[a];
                q[RED_Z[a]] = qi;
                ratio[a] = fabs(dz[a]) / (1.0 + fabs(qi));
            }
            step = ratio[0];
            for (int a = 1; a < R; a++) step = ratio[a] > step || isnan(ratio[a]) ? ratio[a] : step;
            if (!isfinite(step)) return 1;
            for (int a = 0; a < R; a++) q_pred[RED_Z[a]] = z_old[a];
            trig_move_listed(RED_Z, RED_Z_ANGLE, R, q_pred, q, c->tr);
            converged = fresh ? step <= DAE_NEWTON_STEP
                              : step <= DAE_NEWTON_STEP && step * step <= DAE_NEWTON_STEP * DAE_NEWTON_STEP * previous;
            fresh = !fresh && !(step <= 0.25 * previous);
            previous = step;
        }
        if (!converged) return 1;
    }
    c->sign = MECH_DEP_SIGN * sign;
    if (c->sign != s->base.sign) return 1;
    reduced_eliminated(s, t, c, q_pred);
    return 0;
}

/* velocities() on the reduced system at reduced_positions()'s solution: S zd = -(B qd[independent]
   + r_t), the MECH_RED_E rates from their closed forms; f: S factorised there, B in B. */
static int reduced_rates(const ModelState *s, double t, Configuration *c, ReducedLU *f, double *B)
{
    double b[RA], zd[RA], x[NEA];
    eq_red_jacobians(c->q, c->tr, t, s->p, s->d, f->S, B);
    if (R > 0) {
        if (lu_factor(R, f->S, f->piv, f->inv_diag)) return 1;
        if (c->sign == 0) {          /* closed_positions(): the assembly branch read here */
            c->sign = MECH_DEP_SIGN * lu_det_sign(R, f->piv, f->inv_diag);
            if (c->sign != s->base.sign) return 1;
        }
        eq_red_rate_rhs(c->q, c->tr, c->qd, t, s->p, s->d, b);
        lu_solve(R, f->S, f->piv, f->inv_diag, b, zd);
        LINALG_UNROLL
        for (int a = 0; a < R; a++) c->qd[RED_Z[a]] = zd[a];
    }
    eq_red_closed_rates(c->q, c->tr, c->qd, t, s->p, s->d, x);
    LINALG_UNROLL
    for (int e = 0; e < NE; e++) c->qd[RED_E[e]] = x[e];
    return 0;
}

/* accelerations() on the reduced system: V = [dz/dq_independent; dq_E/dq_independent; I] from
   S vz_j = -B[:, j] and the closed forms' directions, the particular accelerations (zero
   independent ones) from S zdd = -gamma and the closed forms', then (V^T M V) a = V^T (Q - M
   particular), as null_space_solve.  *power: with one driver, its power -lambda nu =
   qd^T (M qdd - Q) (eq. (11) times qd; Phi_q qd = nu, which only the driver's row has). */
static int reduced_accelerations(const ModelState *s, double t, const Configuration *c, const ReducedLU *f,
                                 const double *B, double *qdd, double *power)
{
    double vz[KA][RA], ve[KA][NEA], zc[RA], ec[NEA], dq[N], Q[N], mass_q[N], A[KA * KA], acc[KA];
    const double *q = c->q, *qd = c->qd;
    memset(dq, 0, sizeof dq);
    for (int j = 0; j < K; j++) {
        double b[RA];
        LINALG_UNROLL
        for (int a = 0; a < R; a++) b[a] = -B[a * K + j];
        if (R > 0) lu_solve(R, f->S, f->piv, f->inv_diag, b, vz[j]);
        LINALG_UNROLL
        for (int a = 0; a < R; a++) dq[RED_Z[a]] = vz[j][a];
        for (int l = 0; l < K; l++) dq[INDEPENDENT[l]] = l == j ? 1.0 : 0.0;
        eq_red_closed_direction(q, c->tr, t, s->p, s->d, dq, ve[j]);
    }
    memset(dq, 0, sizeof dq);                     /* dq: the particular accelerations */
    if (R > 0) {
        double g[RA];
        eq_red_convective(q, c->tr, qd, t, s->p, s->d, g);
        LINALG_UNROLL
        for (int a = 0; a < R; a++) g[a] = -g[a];
        lu_solve(R, f->S, f->piv, f->inv_diag, g, zc);
        LINALG_UNROLL
        for (int a = 0; a < R; a++) dq[RED_Z[a]] = zc[a];
    }
    eq_red_closed_accelerations(q, c->tr, qd, dq, t, s->p, s->d, ec);
    const double *mass = MECH_MASS_IS_CONSTANT ? s->mass : mass_q;
    if (!MECH_MASS_IS_CONSTANT) eq_mass_diagonal(q, c->tr, s->p, mass_q);
    eq_forces(q, c->tr, qd, t, s->p, Q);
    for (int j = 0; j < K; j++) {
        double sum = Q[INDEPENDENT[j]];
        LINALG_UNROLL
        for (int a = 0; a < R; a++) sum += vz[j][a] * (Q[RED_Z[a]] - mass[RED_Z[a]] * zc[a]);
        LINALG_UNROLL
        for (int e = 0; e < NE; e++) sum += ve[j][e] * (Q[RED_E[e]] - mass[RED_E[e]] * ec[e]);
        acc[j] = sum;
        for (int l = 0; l <= j; l++) {
            double m = j == l ? mass[INDEPENDENT[j]] : 0.0;
            LINALG_UNROLL
            for (int a = 0; a < R; a++) m += mass[RED_Z[a]] * vz[j][a] * vz[l][a];
            LINALG_UNROLL
            for (int e = 0; e < NE; e++) m += mass[RED_E[e]] * ve[j][e] * ve[l][e];
            A[j * K + l] = m;
        }
    }
    if (K == 1) {
        acc[0] /= A[0];
    } else if (K > 1) {
        if (cholesky_factor(K, A, ZEROS)) return 1;
        cholesky_solve(K, A, ZEROS, acc);
    }
    for (int j = 0; j < K; j++) qdd[INDEPENDENT[j]] = acc[j];
    LINALG_UNROLL
    for (int a = 0; a < R; a++) {
        double v = zc[a];
        for (int j = 0; j < K; j++) v += vz[j][a] * acc[j];
        qdd[RED_Z[a]] = v;
    }
    LINALG_UNROLL
    for (int e = 0; e < NE; e++) {
        double v = ec[e];
        for (int j = 0; j < K; j++) v += ve[j][e] * acc[j];
        qdd[RED_E[e]] = v;
    }
    if (N_DRIVERS == 1) {
        double w = 0.0;
        for (int i = 0; i < N; i++) w += qd[i] * (mass[i] * qdd[i] - Q[i]);
        *power = w;
    }
    return 0;
}

/* The right-hand side's configuration, rates and accelerations on the reduced system: 0, or 1
   when the full path must take over (reduced_positions). */
static int reduced_evaluation(ModelState *s, double t, const double *y, Configuration *c, double *qdd,
                              double *power)
{
    ReducedLU f;
    double B[RA * KA];
    return reduced_positions(s, t, y, c) || reduced_rates(s, t, c, &f, B)
        || reduced_accelerations(s, t, c, &f, B, qdd, power);
}
#endif

/* dy/dt for y = (q[independent], qd[independent], work outputs): the Runge-Kutta right-hand side.  The
   evaluation is kept in s->last (a base when it ends an accepted step). */
/* Co-simulation's inputs at time t within a step (ModelState's input_poly from input_t0): what
   the host's input derivatives make of them; held (as set) when it gave none. */
static void inputs_at(ModelState *s, double t)
{
#if MECH_N_INPUTS > 0
    if (!s->interpolating) return;
    const double h = t - s->input_t0;
    for (int k = 0; k < MECH_N_INPUTS; k++)
        s->p[MECH_N_FILE_PARAMETERS + k] = s->input_poly[k][0] + h * (s->input_poly[k][1] + 0.5 * h * s->input_poly[k][2]);
#else
    (void)s;
    (void)t;
#endif
}

static int rhs(void *context, double t, const double *y, double *f)
{
    ModelState *s = (ModelState *)context;
    inputs_at(s, t);
    DaePoint *e = &s->last;
    Configuration c;
    double lam[MA];
    s->rhs_evaluations++;
    if (s->evaluation_limit && s->rhs_evaluations > s->evaluation_limit) {
        s->rhs_failed = DAE_INTEGRATION;    /* the bound on one doStep's work: dae_advance says so */
        return RK_FUNCTION_ERROR;
    }
    e->t = NAN;                   /* not an evaluation until it succeeds */
#if MECH_RED
    double power = 0.0;
    if (reduced_applies(s) && !reduced_evaluation(s, t, y, &c, e->qdd, &power)) {
        e->t = t;
        e->sign = c.sign;
        memcpy(e->q, c.q, sizeof e->q);
        memcpy(e->qd, c.qd, sizeof e->qd);
        memcpy(e->tr, c.tr, sizeof e->tr);
        if (t == s->base.t) s->base = *e;
        for (int j = 0; j < K; j++) {
            f[j] = y[K + j];
            f[K + j] = e->qdd[s->independent[j]];
        }
        if (N_DRIVERS == 1) f[2 * K] = power;
        if (N_WORKS > N_DRIVERS) eq_powers_state(c.q, c.tr, c.qd, t, s->p, s->d, f + 2 * K + N_DRIVERS);
        if (2 * K + N_WORKS == 0) f[0] = 0.0;
        return RK_FUNCTION_OK;
    }
#endif
    s->full_evaluations++;
    int r = state_at(s, t, y, &c);
    if (r == DAE_ASSEMBLY) {
        s->rhs_failed = r;        /* read only when the integrator reports a failure (a start's) */
        /* A trial point the branch cannot be followed to (a step too long for the predictor, or
           one across a dead point): the integrator rejects the step and tries one 5x shorter
           (dae.py returns an infinite derivative, whose error scipy's step control rejects). */
        s->failed_evaluations++;
        return RK_FUNCTION_REJECT;
    }
    if (!r) r = accelerations(s, t, &c, e->qdd, lam, 0);
    if (r) {
        snprintf(s->rhs_message, MODEL_MESSAGE, "the reduced mass matrix V^T M V is singular at t = %.9g s", t);
        s->rhs_failed = r;
        return RK_FUNCTION_ERROR;
    }
    e->t = t;
    e->sign = c.sign;
    memcpy(e->q, c.q, sizeof e->q);
    memcpy(e->qd, c.qd, sizeof e->qd);
    memcpy(e->tr, c.tr, sizeof e->tr);
    if (t == s->base.t) s->base = *e;     /* after a (re)start: the base's accelerations */
    for (int j = 0; j < K; j++) {
        f[j] = y[K + j];
        f[K + j] = e->qdd[s->independent[j]];
    }
    /* the work outputs' powers: a driver's, its constraint force -Phi_q^T lambda (its row) times qd, -lambda nu */
    if (N_DRIVERS > 0) eq_powers_force(c.q, c.tr, c.qd, lam, t, s->p, s->d, f + 2 * K);
    if (N_WORKS > N_DRIVERS) eq_powers_state(c.q, c.tr, c.qd, t, s->p, s->d, f + 2 * K + N_DRIVERS);
    if (2 * K + N_WORKS == 0) f[0] = 0.0;   /* nothing to integrate: one constant */
    return RK_FUNCTION_OK;
}

/* -- Model Exchange ------------------------------------------------------------------------ */

void dae_states(const ModelState *s, double *y)
{
    for (int j = 0; j < K; j++) {
        y[j] = s->q[s->independent[j]];
        y[K + j] = s->qd[s->independent[j]];
    }
    for (int k = 0; k < N_WORKS; k++) y[2 * K + k] = s->work[k];
}

/* The current state as the predictor's base (the integrator's start), on its assembly branch: the
   sign of the dependent block's determinant at q (dae.py's start); its accelerations come with
   the first evaluation there (dae.py solves for them at the start: the same numbers).  Returns
   the state vector y of that start. */
static void restart_base(ModelState *s, double *y)
{
    double J[MA * N], block[MA * MA], inv_diag[MA];
    int piv[MA];
    DaePoint e;
    memset(&e, 0, sizeof e);      /* padding too: the point is copied into FMU states, serialized byte by byte */
    e.t = s->t;
    memcpy(e.q, s->q, sizeof e.q);
    memcpy(e.qd, s->qd, sizeof e.qd);
    memset(e.qdd, 0, sizeof e.qdd);
    eq_trig(s->q, e.tr);
    eq_jacobian(s->q, e.tr, s->p, J);
    dependent_block(J, s->dependent, block);
    dense_factor(block, piv, inv_diag);
    e.sign = lu_det_sign(M, piv, inv_diag);
    s->base = s->last = e;
    s->before.t = NAN;
    memset(y, 0, RK_N * sizeof *y);
    dae_states(s, y);
    s->rhs_failed = 0;
    s->starts++;
}

/* Model Exchange's start: the base, and its accelerations from one evaluation there. */
int dae_me_start(ModelState *s)
{
    double y[RK_N], f[RK_N];
    restart_base(s, y);
    return dae_me_evaluate(s, s->t, y, f);
}

int dae_me_evaluate(ModelState *s, double t, const double *y, double *f)
{
    double yy[RK_N], ff[RK_N];
    memset(yy, 0, sizeof yy);
    memcpy(yy, y, DAE_N_STATES * sizeof *y);
    s->rhs_failed = 0;
    const int r = rhs(s, t, yy, ff);
    if (r != RK_FUNCTION_OK) {
        const int failed = s->rhs_failed ? s->rhs_failed : DAE_INTEGRATION;
        if (failed == DAE_ASSEMBLY && s->rhs_message[0] == '\0')
            snprintf(s->rhs_message, MODEL_MESSAGE, "Phi = 0 cannot be solved at t = %.9g s", t);
        return failed;
    }
    s->t = t;
    memcpy(s->q, s->last.q, sizeof s->q);
    memcpy(s->qd, s->last.qd, sizeof s->qd);
    memcpy(s->tr, s->last.tr, sizeof s->tr);
    for (int k = 0; k < N_WORKS; k++) s->work[k] = y[2 * K + k];
    memcpy(f, ff, DAE_N_STATES * sizeof *f);
    return DAE_OK;
}

void dae_me_accept(ModelState *s)
{
    if (!(s->last.t == s->last.t) || s->last.t == s->base.t) return;   /* nothing new since the base */
    s->before = s->base;
    s->base = s->last;
}

int dae_derivatives(ModelState *s, double *f)
{
    const DaePoint base = s->base, last = s->last;
    const unsigned long counts[5] = {s->rhs_evaluations, s->newton_iterations, s->continuations,
                                     s->failed_evaluations, s->full_evaluations};
    double y[RK_N], ff[RK_N];
    memset(y, 0, sizeof y);
    dae_states(s, y);
    s->rhs_failed = 0;
    const int r = rhs(s, s->t, y, ff);
    s->base = base;
    s->last = last;
    s->rhs_evaluations = counts[0];
    s->newton_iterations = counts[1];
    s->continuations = counts[2];
    s->failed_evaluations = counts[3];
    s->full_evaluations = counts[4];
    if (r != RK_FUNCTION_OK) return s->rhs_failed ? s->rhs_failed : DAE_INTEGRATION;
    memcpy(f, ff, DAE_N_STATES * sizeof *f);
    return DAE_OK;
}

/* The derivatives along a direction dy of the states (DAE_N_STATES) at the current consistent state
   (Model Exchange: the file's partition): df of the states' derivatives (DAE_N_STATES) and dout of
   the outputs (MECH_N_OUTPUTS, output order), and along du of the inputs (MECH_N_INPUTS).  Exact, from
   the generated derivatives (eq_dir_*; eq_dir_inputs: the partials along du, q, qd and lambda held):
   - positions: Phi(q, u) = 0 keeps the block's rows, so dq[dependent] = V dq[independent] - block^-1 Phi_u du;
   - rates: Phi_q qd = nu (nu depends on t and a driver input's rate only): block dqd[dependent] =
     -Phi_q[:, independent] dqd[independent] - d(Phi_q qd)/dq dq + nu_u du;
   - accelerations and multipliers: eq. (11) differentiated, M dqdd + Phi_q^T dlam = dQ - dM qdd -
     d(Phi_q^T lambda)/dq dq and Phi_q dqdd = dgamma - d(Phi_q qdd)/dq dq, solved as eq. (11) is
     (null_space_solve: the same matrix);
   - Q and gamma: their partials along du added to eq. (11)'s right-hand side;
   - the work outputs' powers: eq_dir_powers_* (a driver's -lambda[row] nu[row]: -dlam[row] nu[row]) plus
     their partials along du (eq_dir_inputs' dpowers; a driver's: -lambda[row] nu_u[row] du);
   - the outputs: eq_dir_outputs_*; a work output: its state's direction; the constraint residual
     is zero on every consistent state, so its derivative along them is 0.
   The same cost as about one evaluation of the right-hand side, without Newton-Raphson (the state
   is already consistent).  DAE_INTEGRATION or DAE_ASSEMBLY with the message in s->rhs_message. */
int dae_directional(ModelState *s, const double *dy, const double *du, double *df, double *dout)
{
    Configuration c;
    double qdd[N], lam[MA], dq[N], dqd[N], h[MA], w[MA], dQ[N], dgamma[MA], g[MA], G[N], dmass[N], dqdd[N],
        dlam[MA], mass_q[N];
    double values[MECH_ALLOC(MECH_N_STATE_OUTPUTS)], forces[MECH_ALLOC(MECH_N_FORCE_OUTPUTS)];
    /* the partial derivatives along the inputs' direction du (q, qd, lambda held) */
    double u_phi[MA], u_nu[MA], u_Q[N], u_gamma[MA], u_values[MECH_ALLOC(MECH_N_STATE_OUTPUTS)],
        u_forces[MECH_ALLOC(MECH_N_FORCE_OUTPUTS)], u_w[MA], u_powers[MECH_ALLOC(MECH_N_WORKS)];
    const int *dependent = s->dependent, *independent = s->independent;
    const double t = s->t;
    configuration_init(&c);
    memcpy(c.q, s->q, sizeof c.q);
    memcpy(c.qd, s->qd, sizeof c.qd);
    memcpy(c.tr, s->tr, sizeof c.tr);
    jacobian_at(s->p, s->d, t, &c);
    int r = velocities(s->declared, dependent, independent, &c, s->rhs_message);
    if (r) return r;
    const double *mass = MECH_MASS_IS_CONSTANT ? s->mass : mass_q;
    if (!MECH_MASS_IS_CONSTANT) eq_mass_diagonal(c.q, c.tr, s->p, mass_q);
    if (accelerations(s, t, &c, qdd, lam, 1)) {
        snprintf(s->rhs_message, MODEL_MESSAGE, "the reduced mass matrix V^T M V is singular at t = %.9g s", t);
        return DAE_INTEGRATION;
    }
    /* positions and rates */
    for (int j = 0; j < K; j++) {
        dq[independent[j]] = dy[j];
        dqd[independent[j]] = dy[K + j];
    }
    /* the inputs' partials at the state (the multipliers only for the force outputs: after eq. 11) */
    eq_dir_inputs(c.q, c.tr, c.qd, lam, t, s->p, s->d, du, u_phi, u_nu, u_Q, u_gamma, u_values, u_forces,
                  u_powers);
    /* Phi_q dq + Phi_u du = 0: the dependent block takes -Phi_u du */
    block_solve(&c.f, u_phi, u_w);
    for (int i = 0; i < M; i++) {
        double x = -u_w[i];
        for (int j = 0; j < K; j++) x += c.v[j][i] * dy[j];
        dq[dependent[i]] = x;
    }
    eq_dir_jacobian_product(c.q, c.tr, s->p, c.qd, dq, h);
    for (int i = 0; i < M; i++) h[i] -= u_nu[i];       /* Phi_q qd = nu(u) */
    block_solve(&c.f, h, w);
    for (int i = 0; i < M; i++) {
        double x = -w[i];
        for (int j = 0; j < K; j++) x += c.v[j][i] * dy[K + j];
        dqd[dependent[i]] = x;
    }
    /* accelerations and multipliers */
    eq_dir_dynamics(c.q, c.tr, c.qd, t, s->p, s->d, dq, dqd, dQ, dgamma);
    eq_dir_jacobian_product(c.q, c.tr, s->p, qdd, dq, h);
    for (int i = 0; i < M; i++) g[i] = dgamma[i] + u_gamma[i] - h[i];
    for (int k = 0; k < N; k++) dQ[k] += u_Q[k];
    eq_dir_jacobian_transpose_product(c.q, c.tr, s->p, lam, dq, G);
    eq_dir_mass_diagonal(c.q, c.tr, s->p, dq, dmass);
    for (int k = 0; k < N; k++) dQ[k] -= G[k] + dmass[k] * qdd[k];
    if (null_space_solve(s, mass, &c, dQ, g, dqdd, dlam, 1)) {
        snprintf(s->rhs_message, MODEL_MESSAGE, "the reduced mass matrix V^T M V is singular at t = %.9g s", t);
        return DAE_INTEGRATION;
    }
    for (int j = 0; j < K; j++) {
        df[j] = dqd[independent[j]];
        df[K + j] = dqdd[independent[j]];
    }
    if (N_DRIVERS > 0) eq_dir_powers_force(c.q, c.tr, c.qd, lam, t, s->p, s->d, dq, dqd, dlam, df + 2 * K);
    if (N_WORKS > N_DRIVERS) eq_dir_powers_state(c.q, c.tr, c.qd, t, s->p, s->d, dq, dqd, df + 2 * K + N_DRIVERS);
    for (int k = 0; k < N_WORKS; k++) df[2 * K + k] += u_powers[k];
    /* outputs */
    eq_dir_outputs_state(c.q, c.tr, c.qd, t, s->p, s->d, dq, dqd, values);
    eq_dir_outputs_force(c.q, c.tr, c.qd, lam, t, s->p, s->d, dq, dqd, dlam, forces);
    for (int k = 0; k < MECH_N_OUTPUTS; k++)
        switch (OUTPUT_KINDS[k]) {
        case MECH_OUTPUT_STATE: dout[k] = values[OUTPUT_INDICES[k]] + u_values[OUTPUT_INDICES[k]]; break;
        case MECH_OUTPUT_FORCE: dout[k] = forces[OUTPUT_INDICES[k]] + u_forces[OUTPUT_INDICES[k]]; break;
        case MECH_OUTPUT_WORK: dout[k] = dy[2 * K + OUTPUT_INDICES[k]]; break;
        default: dout[k] = 0.0; break;
        }
    return DAE_OK;
}

/* -- set-up -------------------------------------------------------------------------------- */

/* c->q at parameters p1 (drivers d1 when given, else at their start values at t) and independent
   coordinates `end`, by following the assembly branch from q0 at parameters p0 (dae.py's
   _follow): parameters and independent coordinates move along a straight path in 1, 8, 32, then
   128 equal steps, each solved by Newton-Raphson from the previous one, the dependent block's
   determinant keeping the sign `sign`.  DAE_ASSEMBLY when every try leaves the branch or fails. */
static int follow(ModelState *s, const double *q0, const double *p0, const double *p1, const double *d1,
                  const double *end, double t, int sign, Configuration *c)
{
    static const int STEPS[] = DAE_FOLLOW_STEPS;
    double p[MECH_ALLOC(MECH_N_PARAMETERS)], d[MECH_ALLOC(3 * MECH_N_DRIVERS)];
    for (size_t a = 0; a < sizeof STEPS / sizeof *STEPS; a++) {
        const int n = STEPS[a];
        int k = 1;
        memcpy(c->q, q0, sizeof c->q);
        for (; k <= n; k++) {
            const double f = (double)k / n;
            for (int i = 0; i < MECH_N_PARAMETERS; i++) p[i] = p0[i] + f * (p1[i] - p0[i]);
            if (d1) memcpy(d, d1, sizeof d);
            else dae_drive_at(p, t, d);
            for (int j = 0; j < K; j++) {
                const int i = s->independent[j];
                c->q[i] = q0[i] + f * (end[j] - q0[i]);
            }
            eq_trig(c->q, c->tr);
            if (positions(p, d, s->declared, s->dependent, t, c, &s->newton_iterations, s->rhs_message)
                || c->sign != sign)
                break;
        }
        if (k > n) return DAE_OK;
    }
    return DAE_ASSEMBLY;
}

int dae_assemble(ModelState *s, double t, const double *guess, const double *rates)
{
    static const double STARTS[FMU_N_VARIABLES] = FMU_REAL_STARTS;
    static const int PARAMETER_VRS[MECH_ALLOC(MECH_N_PARAMETERS)] = MECH_PARAMETER_VRS;
    static const int START_POSITION_VRS[KA] = MECH_START_POSITION_VRS;
    static const double GUESS[N] = MECH_GUESS;
    Configuration c;
    double p0[MECH_ALLOC(MECH_N_PARAMETERS)], d0[MECH_ALLOC(3 * MECH_N_DRIVERS)], q0[N], end[KA];
    int is_independent[N], r = DAE_ASSEMBLY;
    memset(is_independent, 0, sizeof is_independent);
    for (int j = 0; j < K; j++) {
        s->independent[j] = INDEPENDENT[j];            /* the file's order, as dae.py */
        is_independent[INDEPENDENT[j]] = 1;
    }
    for (int i = 0, j = 0; i < N; i++)
        if (!is_independent[i]) s->dependent[j++] = i;
    s->declared = 1;
    configuration_init(&c);
    /* The file's guesses assemble the mechanism at its default parameters and start values
       (checked before the build); from there the branch is followed to the parameters and
       independent coordinates asked for (dae.py's assemble), an angle possibly the other way
       round (+-2 pi), so that any start lands on the branch the file means. */
    for (int i = 0; i < MECH_N_PARAMETERS; i++) p0[i] = STARTS[PARAMETER_VRS[i]];
    memcpy(c.q, GUESS, sizeof c.q);
    for (int j = 0; j < K; j++) c.q[INDEPENDENT[j]] = STARTS[START_POSITION_VRS[j]];
    dae_drive_at(p0, t, d0);
    eq_trig(c.q, c.tr);
    if (!positions(p0, d0, 1, s->dependent, t, &c, &s->newton_iterations, s->rhs_message)) {
        const int sign = c.sign;
        int angles = 0;
        memcpy(q0, c.q, sizeof q0);
        for (int j = 0; j < K; j++)
            for (int a = 0; a < N_ANGLES; a++) angles |= ANGLES[a] == INDEPENDENT[j];
        static const double TURNS[3] = {0.0, 2.0 * M_PI_VALUE, -2.0 * M_PI_VALUE};
        for (int turn = 0; turn < (angles ? 3 : 1) && r; turn++) {
            for (int j = 0; j < K; j++) {
                int angle = 0;
                for (int a = 0; a < N_ANGLES; a++) angle |= ANGLES[a] == INDEPENDENT[j];
                end[j] = guess[INDEPENDENT[j]] + (angle ? TURNS[turn] : 0.0);
            }
            if (follow(s, q0, p0, s->p, NULL, end, t, sign, &c)) continue;
            for (int j = 0; j < K; j++) c.q[INDEPENDENT[j]] = guess[INDEPENDENT[j]];
            dae_drive_at(s->p, t, s->d);
            eq_trig(c.q, c.tr);
            r = positions(s->p, s->d, 1, s->dependent, t, &c, &s->newton_iterations, s->rhs_message);
            if (r) return r;
        }
    }
    dae_drive_at(s->p, t, s->d);
    if (r) {                                   /* the guesses themselves (fails with the reason) */
        memcpy(c.q, guess, sizeof c.q);
        eq_trig(c.q, c.tr);
        r = positions(s->p, s->d, 1, s->dependent, t, &c, &s->newton_iterations, s->rhs_message);
        if (r) return r;
    }
    memset(c.qd, 0, sizeof c.qd);
    for (int j = 0; j < K; j++) c.qd[s->independent[j]] = rates[s->independent[j]];
    jacobian_at(s->p, s->d, t, &c);
    r = velocities(1, s->dependent, s->independent, &c, s->rhs_message);
    if (r) return r;
    mass_inverse(s->p, c.q, c.tr, s->mass, s->minv);
    s->length_scale = length_scale(c.q);
    s->t = t;
    memcpy(s->q, c.q, sizeof s->q);
    memcpy(s->tr, c.tr, sizeof s->tr);
    memcpy(s->qd, c.qd, sizeof s->qd);
    memset(s->work, 0, sizeof s->work);
    return DAE_OK;
}

int dae_start(ModelState *s, double first_step)
{
    double y0[RK_N];
    const double bound = isfinite(s->stop_time) ? s->stop_time + 1.0 : INFINITY;
    restart_base(s, y0);
    if (rk_start(&s->solver, s->integrator, rhs, s, s->t, y0, bound, s->values[VR_rtol], s->values[VR_atol],
                 first_step) != RK_OK)
        return s->rhs_failed ? s->rhs_failed : DAE_INTEGRATION;
    return DAE_OK;
}

/* The new parameters' state keeping the current partition's independent coordinates and rates
   (dae.py's _reassembled); on failure nothing changed. */
static int reassembled(ModelState *s, const double *p)
{
    Configuration c;
    double d[MECH_ALLOC(3 * MECH_N_DRIVERS)], end[KA];
    Factors f;
    for (int k = 0; k < N_DRIVERS; k++) {
        const double s_ref = s->d[3 * k], t_ref = s->d[3 * k + 1], v = s->d[3 * k + 2];
        d[3 * k] = s_ref + v * (s->t - t_ref);
        d[3 * k + 1] = s->t;
        d[3 * k + 2] = DRIVERS[k][1] >= 0 ? p[DRIVERS[k][1]] : 0.0;
    }
    if (N_DRIVERS == 0) d[0] = 0.0;
    configuration_init(&c);
    /* the branch the state is on: the sign of the dependent block's determinant there */
    eq_trig(s->q, c.tr);
    eq_jacobian(s->q, c.tr, s->p, c.J);
    const int sign = factor_block(0, s->dependent, c.J, &f) ? 0 : f.sign;
    memcpy(c.q, s->q, sizeof c.q);
    memcpy(c.qd, s->qd, sizeof c.qd);
    int r = positions(p, d, s->declared, s->dependent, s->t, &c, &s->newton_iterations, s->rhs_message);
    if (r || c.sign != sign) {
        /* A large change: follow the branch from the parameters in use to the new ones (dae.py's
           change_parameters; the drivers continue from where they are on the way). */
        for (int j = 0; j < K; j++) end[j] = s->q[s->independent[j]];
        r = follow(s, s->q, s->p, p, d, end, s->t, sign, &c);
        if (r) {
            memcpy(c.q, s->q, sizeof c.q);
            eq_trig(c.q, c.tr);
            r = positions(p, d, s->declared, s->dependent, s->t, &c, &s->newton_iterations, s->rhs_message);
            if (!r) {
                snprintf(s->rhs_message, MODEL_MESSAGE, "the loop cannot be closed on the way to the new parameters");
                r = DAE_ASSEMBLY;
            }
            return r;                                   /* nothing changed */
        }
        r = positions(p, d, s->declared, s->dependent, s->t, &c, &s->newton_iterations, s->rhs_message);
    }
    if (!r) {
        jacobian_at(p, d, s->t, &c);
        memcpy(c.qd, s->qd, sizeof c.qd);
        r = velocities(s->declared, s->dependent, s->independent, &c, s->rhs_message);
    }
    if (r) return r;                                    /* nothing changed */
    memcpy(s->p, p, sizeof s->p);
    memcpy(s->d, d, sizeof s->d);
    memcpy(s->q, c.q, sizeof s->q);
    memcpy(s->tr, c.tr, sizeof s->tr);
    memcpy(s->qd, c.qd, sizeof s->qd);
    mass_inverse(s->p, c.q, c.tr, s->mass, s->minv);
    return DAE_OK;
}

int dae_change_parameters(ModelState *s, const double *p)
{
    int used_independent[KA], used_dependent[MA];
    const int used_declared = s->declared;
    memcpy(used_independent, s->independent, sizeof used_independent);
    memcpy(used_dependent, s->dependent, sizeof used_dependent);
    if (!used_declared) {
        /* the declared coordinates carry the re-assembly, whatever the integrator uses */
        declared_partition(s->independent, s->dependent);
        s->declared = 1;
    }
    int r = reassembled(s, p);
    if (!used_declared) {
        /* the integrator goes on with its coordinates (its review takes the declared ones back) */
        memcpy(s->independent, used_independent, sizeof used_independent);
        memcpy(s->dependent, used_dependent, sizeof used_dependent);
        s->declared = 0;
        /* at a dead point of the declared coordinates: the ones in use */
        if (r == DAE_ASSEMBLY) r = reassembled(s, p);
    }
    return r;
}

/* -- time stepping ------------------------------------------------------------------------- */

/* A failed right-hand side as dae.py reports it from advance: an assembly failure with the
   time it was asked for, a failed solve as it is. */
static int rhs_failure(ModelState *s, double t_end)
{
    if (s->rhs_failed == DAE_ASSEMBLY) {
        char text[MODEL_MESSAGE + 40];
        snprintf(text, sizeof text, "at t = %.9g s %s", t_end, s->rhs_message);
        memcpy(s->rhs_message, text, MODEL_MESSAGE - 1);
        s->rhs_message[MODEL_MESSAGE - 1] = '\0';
    }
    return s->rhs_failed ? s->rhs_failed : DAE_INTEGRATION;
}

/* The independent coordinates a column-pivoted QR factorisation of Phi_q (J) chooses: the columns
   it picks first form the best-conditioned dependent block (dae.py's choose_partition). */
static void choose_partition(const double *J, int *independent, int *dependent)
{
    double A[MA * N];
    int perm[N], chosen[N];
    memcpy(A, J, sizeof A);
    qr_pivot_order(M, N, A, perm);
    memset(chosen, 0, sizeof chosen);
    for (int j = 0; j < M; j++) chosen[perm[j]] = 1;     /* the first m columns: dependent */
    for (int i = 0, a = 0, b = 0; i < N; i++) {
        if (chosen[i]) dependent[a++] = i;
        else independent[b++] = i;
    }
}

static void set_partition(ModelState *s, const int *independent, const int *dependent)
{
    int is_independent[N];
    memset(is_independent, 0, sizeof is_independent);
    for (int j = 0; j < K; j++) is_independent[INDEPENDENT[j]] = 1;
    memcpy(s->independent, independent, sizeof s->independent);
    memcpy(s->dependent, dependent, sizeof s->dependent);
    /* the generated factorisation serves the declared dependent coordinates (in any order of the
       independent ones) */
    s->declared = 1;
    for (int j = 0; j < M; j++) s->declared &= !is_independent[dependent[j]];
    s->repartitions++;
}

/* The file's partition: INDEPENDENT (the file's order, as dae_assemble) and the other coordinates. */
static void declared_partition(int *independent, int *dependent)
{
    int is_independent[N];
    memset(is_independent, 0, sizeof is_independent);
    for (int j = 0; j < K; j++) {
        independent[j] = INDEPENDENT[j];
        is_independent[INDEPENDENT[j]] = 1;
    }
    for (int i = 0, j = 0; i < N; i++)
        if (!is_independent[i]) dependent[j++] = i;
}

/* Coordinate i's unit in the velocity ratio: 1 for an angle, the mechanism's size for a position. */
static double ratio_scale(const ModelState *s, int i)
{
    for (int a = 0; a < N_ANGLES; a++)
        if (ANGLES[a] == i) return 1.0;
    return s->length_scale;
}

/* The velocity ratio of a partition where Phi_q is J (whole; dae.py's velocity_ratio): the largest
   rate of a dependent coordinate per unit rate of the independent ones,
   ||diag(1/s_dep) block^-1 Phi_q[:, independent] diag(s_ind)||_inf; INFINITY where the block is
   singular (a dead point of the independent coordinates). */
static double velocity_ratio(const ModelState *s, const double *J, const int *independent, const int *dependent)
{
    double block[MA * MA], inv_diag[MA], b[MA], x[MA], sum[MA];
    int piv[MA];
    if (K == 0) return 0.0;
    dependent_block(J, dependent, block);
    if (dense_factor(block, piv, inv_diag)) return INFINITY;
    memset(sum, 0, sizeof sum);
    for (int j = 0; j < K; j++) {
        const double scale = ratio_scale(s, independent[j]);
        for (int i = 0; i < M; i++) b[i] = J[i * N + independent[j]];
        dense_solve(block, piv, inv_diag, b, x);
        for (int i = 0; i < M; i++) sum[i] += fabs(x[i]) * scale;
    }
    double ratio = 0.0;
    for (int i = 0; i < M; i++) {
        const double r = sum[i] / ratio_scale(s, dependent[i]);
        if (!(r <= ratio)) ratio = r;
    }
    return isfinite(ratio) ? ratio : INFINITY;
}

/* The mechanism's size at q (dae.py's length_scale): the largest distance between two bodies'
   centres, 1 m with fewer than two (or all at one point). */
static double length_scale(const double *q)
{
    static const int CENTRES[MECH_ALLOC(2 * MECH_N_CENTRES)] = MECH_CENTRES;
    double span = 0.0;
    for (int a = 0; a < MECH_N_CENTRES; a++)
        for (int b = a + 1; b < MECH_N_CENTRES; b++) {
            const double h = hypot(q[CENTRES[2 * a]] - q[CENTRES[2 * b]], q[CENTRES[2 * a + 1]] - q[CENTRES[2 * b + 1]]);
            if (h > span) span = h;
        }
    return span > 0.0 ? span : 1.0;
}

/* dae.py's review of the partition at a state whose Phi_q is J (whole): 1, with the new choice in
   independent and dependent, else 0.  The declared coordinates are kept while their velocity
   ratio is at most DAE_REPARTITION_AWAY; other coordinates give way to the declared ones once
   those are below DAE_REPARTITION_RETURN (hysteresis), and to the column-pivoted QR's choice when
   their own ratio exceeds DAE_REPARTITION_AWAY and that choice's is DAE_REPARTITION_GAIN times
   smaller. */
static int better_partition(const ModelState *s, const double *J, int *independent, int *dependent)
{
    if (K == 0) return 0;
    if (!s->declared) {
        declared_partition(independent, dependent);
        if (velocity_ratio(s, J, independent, dependent) < DAE_REPARTITION_RETURN) return 1;
    }
    const double ratio = velocity_ratio(s, J, s->independent, s->dependent);
    if (ratio <= DAE_REPARTITION_AWAY) return 0;
    choose_partition(J, independent, dependent);
    if (memcmp(independent, s->independent, K * sizeof(int)) == 0) return 0;
    return velocity_ratio(s, J, independent, dependent) * DAE_REPARTITION_GAIN < ratio;
}

/* The review of an accepted Runge-Kutta step, at its end (the base; dae.py's _better_partition at
   the state _review_at_accepted reads): 1, with the QR's choice, when other independent
   coordinates should take over; else 0. */
static int review_base(const ModelState *s, int *independent, int *dependent)
{
    double J[MA * N];
    const DaePoint *b = &s->base;
    if (K == 0) return 0;
    eq_jacobian(b->q, b->tr, s->p, J);
    return better_partition(s, J, independent, dependent);
}

/* After an accepted step that ends before the communication point (dae.py's _review_at_accepted):
   a crank can go from a pivot ratio of 0.15 to its dead point within one communication step, and
   an integrator that reaches a dead point in the old coordinates stops there (their rates go to
   zero while the mechanism moves on).  A better partition restarts the integrator at the step's
   end: 1 when it did (*result: dae_start's), 0 when nothing changed. */
static int review_at_accepted(ModelState *s, int *result)
{
    int independent[KA], dependent[MA];
    const DaePoint *b = &s->base;
    if (!review_base(s, independent, dependent)) return 0;
    s->t = b->t;
    memcpy(s->q, b->q, sizeof s->q);
    memcpy(s->tr, b->tr, sizeof s->tr);
    memcpy(s->qd, b->qd, sizeof s->qd);
    for (int k = 0; k < N_WORKS; k++) s->work[k] = s->solver.y[2 * K + k];
    set_partition(s, independent, dependent);
    *result = dae_start(s, s->solver.h_abs);
    return 1;
}

/* Restart at the last reported state with the QR's independent coordinates when they differ from
   the current ones (dae.py's _repartition): 1 when it did, 0 when there was nothing to try.  Not
   from the last accepted Runge-Kutta state: that one may be right at the dead point, where the
   old independent rates no longer determine the motion. */
static int repartition(ModelState *s)
{
    double J[MA * N], tr[TRIG];
    int independent[KA], dependent[MA];
    if (K == 0) return 0;
    eq_trig(s->q, tr);
    eq_jacobian(s->q, tr, s->p, J);
    choose_partition(J, independent, dependent);
    if (memcmp(independent, s->independent, K * sizeof(int)) == 0) return 0;
    set_partition(s, independent, dependent);
    return dae_start(s, s->solver.h_abs) == DAE_OK;
}

/* The reported state at a communication point (state_at's q, tr and qd): on the reduced system
   where it applies. */
static int reported_state(ModelState *s, double t, const double *y, Configuration *c)
{
#if MECH_RED
    if (reduced_applies(s)) {
        ReducedLU f;
        double B[RA * KA];
        if (!reduced_positions(s, t, y, c) && !reduced_rates(s, t, c, &f, B)) return DAE_OK;
    }
#endif
    return state_at(s, t, y, c);
}

static int advance(ModelState *s, double t_end)
{
    RKSolver *solver = &s->solver;
    const char *method = INTEGRATOR_NAMES[s->integrator];
    const double eps = 1e-12 * fmax(1.0, fabs(t_end));   /* a step ending within round-off reaches t_end */
    const double t_start = s->t;
    double y[RK_N];
    int rescues = 0, restarted, pending = 0, independent[KA], dependent[MA];
    Configuration c;
    while (solver->t < t_end - eps) {
        const RKResult r = rk_step(solver, rhs, s);
        if (r == RK_OK) {
            /* the integrator evaluates f at the end of every attempted step before its error test:
               after an accepted step that is the accepted state, the base of the next predictions.
               A stage of a rejected attempt never becomes a base: near a dead point one of them
               may have landed on the other assembly branch. */
            if (s->last.t == solver->t) {
                s->before = s->base;
                s->base = s->last;
                eq_trig(s->base.q, s->base.tr);     /* libm's: predictions rotate from them */
                if (solver->t < t_end - eps) {
                    if (review_at_accepted(s, &restarted) && restarted != DAE_OK) return restarted;
                } else {
                    /* a step that reaches t_end or passes it: reviewed at its end too; other
                       coordinates take over at t_end, from the reported state (this step's dense
                       output serves t_end first) */
                    pending = review_base(s, independent, dependent);
                }
            }
            continue;
        }
        if (r == RK_ERROR_RHS) return rhs_failure(s, t_end);
        if (r == RK_ERROR_FINISHED) {
            snprintf(s->rhs_message, MODEL_MESSAGE, "%s cannot step beyond t = %.9g s (the stop time + 1 s given "
                     "to fmi2SetupExperiment)", method, solver->t);
            return DAE_INTEGRATION;
        }
        /* The step size collapsed (the dependent block goes singular ahead: a dead point between
           two communication points): restart from the last reported state with other independent
           coordinates, at most DAE_RESCUES times per communication step. */
        if (rescues < DAE_RESCUES && repartition(s)) {
            rescues++;
            continue;
        }
        snprintf(s->rhs_message, MODEL_MESSAGE, "%s failed at t = %.9g s: Required step size is less than spacing "
                 "between numbers.", method, solver->t);
        return DAE_INTEGRATION;
    }
    if (fabs(solver->t - t_end) <= eps)
        memcpy(y, solver->y, sizeof y);
    else if (rk_dense(solver, rhs, s, t_end, y) != RK_OK)
        return rhs_failure(s, t_end);
    inputs_at(s, t_end);
    for (int j = 0; j < RK_N; j++)
        if (!isfinite(y[j])) {
            snprintf(s->rhs_message, MODEL_MESSAGE, "%s produced a non-finite state before t = %.9g s", method, t_end);
            return DAE_INTEGRATION;
        }
    int r = reported_state(s, t_end, y, &c);
    if (r) {
        s->rhs_failed = r;
        return rhs_failure(s, t_end);
    }
    s->last_step = t_end - t_start;
    s->t = t_end;
    memcpy(s->q, c.q, sizeof s->q);
    memcpy(s->tr, c.tr, sizeof s->tr);
    memcpy(s->qd, c.qd, sizeof s->qd);
    for (int k = 0; k < N_WORKS; k++) s->work[k] = y[2 * K + k];
    if (!pending) return DAE_OK;
    set_partition(s, independent, dependent);
    return dae_start(s, s->solver.h_abs);
}

int dae_advance(ModelState *s, double t_end, double max_evaluations)
{
    const unsigned long first = s->rhs_evaluations;
    const double t_start = s->t;
    /* the bound rhs() enforces: every evaluation past it fails (0: none) */
    s->evaluation_limit = max_evaluations >= (double)(unsigned long)-1 - (double)first ? 0
                          : first + (unsigned long)max_evaluations;
    int r = advance(s, t_end);
    if (r && s->evaluation_limit && s->rhs_evaluations > s->evaluation_limit) {
        snprintf(s->rhs_message, MODEL_MESSAGE, "the communication step from t = %.9g s to %.9g s needed more than "
                 "max_evaluations = %.17g right-hand-side evaluations; it reached t = %.9g s (raise max_evaluations, "
                 "a fixed parameter, to allow more work per step, or shorten the step)", t_start, t_end,
                 max_evaluations, s->solver.t);
        r = DAE_INTEGRATION;
    }
    s->evaluation_limit = 0;
    return r;
}

/* -- outputs ------------------------------------------------------------------------------- */

void dae_outputs_state(const double *p, const double *d, double t, const double *q, const double *tr_q,
                       const double *qd, const double *work, double *out)
{
    double tr[TRIG], values[MECH_ALLOC(MECH_N_STATE_OUTPUTS)];
    if (tr_q) memcpy(tr, tr_q, sizeof tr);
    else eq_trig(q, tr);
    eq_outputs_state(q, tr, qd, t, p, d, values);
    for (int g = 0; g < MECH_N_STATE_GROUP; g++) {
        const int k = STATE_GROUP[g];
        out[k] = OUTPUT_KINDS[k] == MECH_OUTPUT_STATE ? values[OUTPUT_INDICES[k]] : work[OUTPUT_INDICES[k]];
    }
}

double dae_output_state_one(const double *p, const double *d, double t, const double *q, const double *tr,
                            const double *qd, const double *work, int k)
{
    return OUTPUT_KINDS[k] == MECH_OUTPUT_STATE ? eq_output_state(OUTPUT_INDICES[k], q, tr, qd, t, p, d)
                                                : work[OUTPUT_INDICES[k]];
}

void dae_outputs_residual(const double *p, const double *d, double t, const double *q, const double *qd,
                          double *out)
{
    double tr[TRIG], J[MA * N], nu[MA], phi[MA];
    eq_trig(q, tr);
    /* max(|Phi|, |Phi_q qd - nu|), NaN-propagating */
    eq_jacobian(q, tr, p, J);
    eq_nu(t, p, d, nu);
    eq_constraints(q, tr, t, p, d, phi);
    double residual = 0.0;
    for (int i = 0; i < M; i++) {
        double v = -nu[i];
        for (int k = 0; k < N; k++) v += J[i * N + k] * qd[k];
        const double a = fabs(phi[i]), b = fabs(v);
        if (!(a <= residual)) residual = a;
        if (!(b <= residual)) residual = b;
    }
    for (int k = 0; k < MECH_N_OUTPUTS; k++)
        if (OUTPUT_KINDS[k] == MECH_OUTPUT_RESIDUAL) out[k] = residual;
}

int dae_outputs_force(const double *p, const double *d, double t, const double *q, const double *qd, double *out,
                      char *message)
{
    Configuration c;
    double qdd[N], lam[MA], mass[N], minv[N], values[MECH_ALLOC(MECH_N_FORCE_OUTPUTS)];
    if (MECH_N_FORCE_OUTPUTS == 0) return DAE_OK;
    memcpy(c.q, q, sizeof c.q);
    memcpy(c.qd, qd, sizeof c.qd);
    eq_trig(c.q, c.tr);
    eq_jacobian(c.q, c.tr, p, c.J);
    mass_inverse(p, c.q, c.tr, mass, minv);
    int r = solve(p, d, minv, t, &c, qdd, lam, message);
    if (r) return r;
    eq_outputs_force(c.q, c.tr, c.qd, lam, t, p, d, values);
    for (int k = 0; k < MECH_N_OUTPUTS; k++)
        if (OUTPUT_KINDS[k] == MECH_OUTPUT_FORCE) out[k] = values[OUTPUT_INDICES[k]];
    return DAE_OK;
}
