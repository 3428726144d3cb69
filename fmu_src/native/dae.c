/* The DAE of any mechanism: fmu_src/mechanism_model/dae.py's MechanismDAE in C (see dae.h).
 *
 * At every right-hand-side evaluation eq. (11)
 *
 *     [[M,     Phi_q^T],   [qdd   ]   [Q    ]
 *      [Phi_q, 0      ]] . [lambda] = [gamma]
 *
 * is solved for the accelerations and the multipliers, with M qdd + Phi_q^T lambda = Q (the
 * joints act on the bodies with -Phi_q^T lambda).  M is diagonal, so the solve is the
 * range-space form (Phi_q M^-1 Phi_q^T) lambda = Phi_q M^-1 Q - gamma, a Cholesky
 * factorisation, then qdd = M^-1 (Q - Phi_q^T lambda).
 *
 * Constraint stabilisation is generalized-coordinate partitioning (Wehage and Haug): the
 * Runge-Kutta method (rk.c) integrates the independent coordinates, their rates and each
 * driver's work (power -lambda[row] nu[row]); the dependent coordinates are recovered from
 * Phi(q, t) = 0 by Newton-Raphson from a prediction made from accepted states only (so the
 * assembly branch is kept by continuity: a stage of a rejected step may sit on the other
 * branch near a dead point), and their rates from Phi_q qd = nu.  Every reported state
 * satisfies both to round-off.  At every communication point the partition is reviewed: when
 * the dependent block's LU pivots spread by more than 1 / DAE_REPARTITION_REVIEW, the
 * independent coordinates change to those a column-pivoted QR factorisation of Phi_q picks if
 * their dependent block is DAE_REPARTITION_GAIN times better conditioned, and the integrator
 * restarts.  A trial stage that Newton-Raphson from the prediction does not reach, or reaches
 * on the other assembly branch (the sign of the dependent block's determinant, which changes
 * only through a dead point), is reached by continuation from the base (DAE_CONTINUATION_STEPS
 * sub-steps); where even that fails the evaluation fails and the Runge-Kutta step is rejected
 * and retried 5x shorter (rk.h: RK_FUNCTION_REJECT; dae.py returns inf there, which scipy's step
 * control rejects the same way).  Only a step size that collapses fails a step (a dead point
 * between two communication points): it restarts from the last reported state with the QR's
 * choice, at most DAE_RESCUES times per communication step.
 *
 * The same algorithm, tolerances and decisions as dae.py, computed with less work.  Measured on
 * the four-bar at rtol = atol = 1e-10 (100 s): dae.py's way takes 2.4 Newton-Raphson
 * iterations per evaluation, each with an LU factorisation, and one more factorisation for the
 * rates; here 1.8 iterations and one factorisation, 0.8 us per evaluation instead of 1.8:
 * - the prediction is the quintic Hermite interpolant of the last accepted step's start and
 *   end (positions, rates and accelerations; 1.8 iterations against 3.0 with dae.py's
 *   second-order Taylor step from the end, which is used after a restart);
 * - Newton-Raphson factorises the dependent block of Phi_q at the prediction and reuses the
 *   factors while the corrections shrink fast (a chord iteration), refactorising when they do
 *   not.  A fresh factorisation stops as dae.py does (a correction of at most NEWTON_STEP
 *   (1 + |q_i|), whose square is the error left); a reused one stops once the error it leaves,
 *   estimated from the ratio of successive corrections, is at most NEWTON_STEP^2 (1 + |q_i|);
 * - the rates solve Phi_q qd = nu at the converged q by iterative refinement from the
 *   prediction's rates with those factors, until the error left is at most NEWTON_STEP^2 of the
 *   rates (velocities() says how that is estimated), else by a factorisation at q;
 * - cos and sin of the angles are moved through a Newton correction by the rotation it makes
 *   (a short series, exact to round-off for corrections up to 1e-3 rad) instead of libm calls;
 * - Phi_q M^-1 Phi_q^T, its right-hand side and qdd(lambda) are printed from Phi_q's sparsity
 *   (equations.c); the small dense kernels are unrolled (linalg.h).
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
#include "linalg.h"

enum {
    N = MECH_N,
    M = MECH_M,
    K = MECH_K,
    N_DRIVERS = MECH_N_DRIVERS,
    N_ANGLES = MECH_N_ANGLES,
    MA = MECH_ALLOC(MECH_M),
    KA = MECH_ALLOC(MECH_K),
    TRIG = MECH_ALLOC(MECH_N_TRIG)
};

/* Velocity refinements before the dependent block is factorised at q itself ... */
#define REFINEMENTS 3
/* ... at once when the factors were computed farther than this (relative) from q: each
   refinement then gains less than six digits, and three cost more than a factorisation
   (measured at Table 1's tolerances, where Runge-Kutta steps are long: -10 % time). */
#define REFACTOR_BEYOND 1e-6
/* Angle changes up to this (rad) move cos and sin by the rotation's series: its truncation
   error, |delta|^6 / 720 and |delta|^7 / 5040, stays below 1e-20. */
#define TRIG_STEP 1e-3

static const int INDEPENDENT[KA] = MECH_INDEPENDENT;
static const int ANGLES[MECH_ALLOC(MECH_N_ANGLES)] = MECH_ANGLES;
static const int S_ENVELOPE[MA] = MECH_RANGE_ENVELOPE;
static const int DRIVERS[MECH_ALLOC(MECH_N_DRIVERS)][3] = MECH_DRIVERS;
static const char *const ROW_NAMES[MA] = MECH_ROW_NAMES;
static const int OUTPUT_KINDS[MECH_N_OUTPUTS] = MECH_OUTPUT_KINDS;
static const int OUTPUT_INDICES[MECH_N_OUTPUTS] = MECH_OUTPUT_INDICES;
static const char *const INTEGRATOR_NAMES[FB_N_INTEGRATORS] = FB_INTEGRATOR_NAMES;

double dae_snap_time(double t)
{
    return nearbyint(t * 1e9) / 1e9;    /* round half to even, as Python's round() */
}

void dae_drive_at(const double *p, double t, double *d)
{
    for (int k = 0; k < N_DRIVERS; k++) {
        d[3 * k] = p[DRIVERS[k][0]];
        d[3 * k + 1] = t;
        d[3 * k + 2] = p[DRIVERS[k][1]];
    }
}

/* 1 / the diagonal of M at q. */
static void mass_inverse(const double *p, const double *q, const double *tr, double *minv)
{
    eq_mass_diagonal(q, tr, p, minv);
    for (int i = 0; i < N; i++) minv[i] = 1.0 / minv[i];
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

/* A configuration and what the right-hand side needs of it. */
typedef struct {
    double q[N], qd[N], tr[TRIG];
    double J[MA * N];           /* Phi_q at q */
    double nu[MA];
    double block[MA * MA];      /* the dependent block of Phi_q at (or near) q, LU-factorised */
    int piv[MA];
    double inv_diag[MA];
    int sign;                   /* sign of det(block) where positions() last factorised it: the branch */
    double moved;               /* how far q is from where block was factorised, relative */
    int S_wanted;               /* state_at factorises S = Phi_q M^-1 Phi_q^T at q (Cholesky) too */
    int S_singular;             /* ... and it was not positive definite */
    double S[MA * MA];
    double minv[N];             /* 1 / diag(M) at q, when M depends on q */
} Configuration;

/* c->q[dependent] with Phi(c->q, t) = 0, by Newton-Raphson from c->q (c->q[independent] fixed);
   c->tr is set for the result, c->block and c->piv hold the last factorisation (module doc), and
   c->sign the sign of its determinant (dae.py's: of the last factorisation, near the solution). */
static int positions(const double *p, const double *d, const int *dependent, double t, Configuration *c,
                     unsigned long *iterations, char *message)
{
    double phi[MA], dx[MA], q_old[N];
    double *q = c->q;
    int fresh = 1;                       /* factorise Phi_q at the current q in this iteration */
    double previous = INFINITY;
    eq_trig(q, c->tr);
    for (int iteration = 0; iteration < DAE_NEWTON_ITERATIONS; iteration++) {
        ++*iterations;
        if (fresh) {
            c->moved = 0.0;
            eq_constraints_jacobian(q, c->tr, t, p, d, phi, c->J);
            dependent_block(c->J, dependent, c->block);
            if (lu_factor(M, c->block, c->piv, c->inv_diag)) {
                snprintf(message, MODEL_MESSAGE, "the constraint Jacobian is singular there (a toggle or dead-point "
                         "configuration)");
                return DAE_ASSEMBLY;
            }
        } else {
            eq_constraints(q, c->tr, t, p, d, phi);
        }
        lu_solve(M, c->block, c->piv, c->inv_diag, phi, dx);
        memcpy(q_old, q, sizeof q_old);
        double step = 0.0;
        for (int j = 0; j < M; j++) {
            const double qi = q[dependent[j]] - dx[j];
            q[dependent[j]] = qi;
            const double r = fabs(dx[j]) / (1.0 + fabs(qi));
            if (!(r <= step)) step = r;
        }
        if (!isfinite(step)) break;
        c->moved += step;
        trig_move(q_old, q, c->tr);
        if (fresh ? step <= DAE_NEWTON_STEP
                  : step <= DAE_NEWTON_STEP && step * step <= DAE_NEWTON_STEP * DAE_NEWTON_STEP * previous) {
            c->sign = lu_det_sign(M, c->piv, c->inv_diag);
            return DAE_OK;
        }
        /* reuse the factors while the corrections shrink at least fourfold per iteration */
        fresh = !fresh && !(step <= 0.25 * previous);
        previous = step;
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
    snprintf(message, MODEL_MESSAGE, "Phi = 0 has no solution near the previous configuration (Newton-Raphson "
             "left a residual of %.3g in joint %s): the loop cannot be closed", largest, ROW_NAMES[worst]);
    return DAE_ASSEMBLY;
}

/* c->qd[dependent] from Phi_q qd = nu (c->J, c->nu at c->q) with c->qd[independent] given, by iterative refinement from c->qd[dependent] (a guess) with the
   factors in c->block.  Each correction leaves an error of about its size times the rate rho at
   which the refinement converges: c->moved (the factors were computed that far from q) for the
   first, the ratio of successive corrections after.  Accepted once that is at most
   NEWTON_STEP^2 of the rates (and the correction at most NEWTON_STEP of them), as Newton-Raphson
   is; after REFINEMENTS corrections, or at once when the factors are from farther than
   REFACTOR_BEYOND, the block is factorised at q and one solve gives the rates. */
static int velocities(const int *dependent, Configuration *c, char *message)
{
    double r[MA], dx[MA];
    double previous = INFINITY;
    /* factors from too far away would take more refinements than a factorisation costs */
    for (int refinement = c->moved > REFACTOR_BEYOND ? REFINEMENTS : 0;; refinement++) {
        if (refinement == REFINEMENTS) {           /* slow: factorise at q itself */
            dependent_block(c->J, dependent, c->block);
            if (lu_factor(M, c->block, c->piv, c->inv_diag)) {
                snprintf(message, MODEL_MESSAGE, "the constraint Jacobian is singular: a toggle (dead-point) "
                         "configuration");
                return DAE_ASSEMBLY;
            }
            c->moved = 0.0;
        }
        eq_jacobian_product(c->J, c->qd, r);           /* r = nu - Phi_q qd */
        LINALG_UNROLL
        for (int i = 0; i < M; i++) r[i] = c->nu[i] - r[i];
        lu_solve(M, c->block, c->piv, c->inv_diag, r, dx);
        double size = 0.0, change = 0.0;
        LINALG_UNROLL
        for (int j = 0; j < M; j++) {
            const double x = c->qd[dependent[j]] + dx[j];
            c->qd[dependent[j]] = x;
            if (!(fabs(x) <= size)) size = fabs(x);
            if (!(fabs(dx[j]) <= change)) change = fabs(dx[j]);
        }
        const double rho = refinement == 0 ? c->moved : fmax(c->moved, change / previous);
        if (refinement == REFINEMENTS || (change <= DAE_NEWTON_STEP * size
                                          && change * rho <= DAE_NEWTON_STEP * DAE_NEWTON_STEP * size))
            break;
        previous = change;
    }
    return DAE_OK;
}

/* c->J and c->nu at c->q (c->tr set). */
static void jacobian_at(const double *p, const double *d, double t, Configuration *c)
{
    eq_jacobian(c->q, c->tr, p, c->J);
    eq_nu(t, p, d, c->nu);
}

/* -- the predictor ------------------------------------------------------------------------- */

/* q and qd at time t predicted from the accepted states: the quintic Hermite interpolant of the
   last accepted step's start and end (positions, rates, accelerations), else (after a restart)
   the second-order Taylor step from the base that dae.py's _state takes. */
static void predict(const ModelState *s, double t, double *q, double *qd)
{
    const DaePoint *p1 = &s->base, *p0 = &s->before;
    if (!(p0->t < p1->t)) {
        const double dt = t - p1->t, half = 0.5 * dt * dt;
        LINALG_UNROLL
        for (int i = 0; i < N; i++) {
            q[i] = p1->q[i] + p1->qd[i] * dt + p1->qdd[i] * half;
            qd[i] = p1->qd[i] + p1->qdd[i] * dt;
        }
        return;
    }
    const double h = p1->t - p0->t, x = (t - p0->t) / h;
    const double x_2 = x * x, x_3 = x_2 * x, x_4 = x_3 * x, x_5 = x_4 * x;
    /* the quintic Hermite basis: values, and derivatives in t */
    const double H0 = 1.0 - 10.0 * x_3 + 15.0 * x_4 - 6.0 * x_5, H5 = 1.0 - H0;
    const double H1 = (x - 6.0 * x_3 + 8.0 * x_4 - 3.0 * x_5) * h, H4 = (-4.0 * x_3 + 7.0 * x_4 - 3.0 * x_5) * h;
    const double H2 = 0.5 * (x_2 - 3.0 * x_3 + 3.0 * x_4 - x_5) * h * h, H3 = 0.5 * (x_3 - 2.0 * x_4 + x_5) * h * h;
    const double D0 = (-30.0 * x_2 + 60.0 * x_3 - 30.0 * x_4) / h, D5 = -D0;
    const double D1 = 1.0 - 18.0 * x_2 + 32.0 * x_3 - 15.0 * x_4, D4 = -12.0 * x_2 + 28.0 * x_3 - 15.0 * x_4;
    const double D2 = 0.5 * (2.0 * x - 9.0 * x_2 + 12.0 * x_3 - 5.0 * x_4) * h;
    const double D3 = 0.5 * (3.0 * x_2 - 8.0 * x_3 + 5.0 * x_4) * h;
    LINALG_UNROLL
    for (int i = 0; i < N; i++) {
        q[i] = H0 * p0->q[i] + H1 * p0->qd[i] + H2 * p0->qdd[i] + H3 * p1->qdd[i] + H4 * p1->qd[i] + H5 * p1->q[i];
        qd[i] = D0 * p0->q[i] + D1 * p0->qd[i] + D2 * p0->qdd[i] + D3 * p1->qdd[i] + D4 * p1->qd[i] + D5 * p1->q[i];
    }
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
            if (positions(s->p, s->d, s->dependent, b->t + f * (t - b->t), c, &s->newton_iterations,
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
    predict(s, t, c->q, c->qd);
    for (int j = 0; j < K; j++) {
        c->q[s->independent[j]] = y[j];
        c->qd[s->independent[j]] = y[K + j];
    }
    int r = positions(s->p, s->d, s->dependent, t, c, &s->newton_iterations, s->rhs_message);
    if (r || c->sign != s->base.sign) r = continuation(s, t, y, c);
    if (r) return r;
    jacobian_at(s->p, s->d, t, c);
    /* Phi_q M^-1 Phi_q^T depends on q only: factorised before the rates are solved for, so that
       the two chains of dependent operations can overlap in the processor. */
    if (c->S_wanted) {
        if (!MECH_MASS_IS_CONSTANT) mass_inverse(s->p, c->q, c->tr, c->minv);
        eq_range_matrix(c->J, MECH_MASS_IS_CONSTANT ? s->minv : c->minv, c->S);
        c->S_singular = cholesky_factor(M, c->S, S_ENVELOPE) != 0;
    }
    return velocities(s->dependent, c, s->rhs_message);
}

/* -- dynamics ------------------------------------------------------------------------------ */

/* (qdd, lambda) of eq. (11) at a consistent configuration by the range-space solve (S factorised
   here, unless state_at did: c->S_wanted). */
static int solve(const double *p, const double *d, const double *minv, double t, Configuration *c, double *qdd,
                 double *lam, char *message)
{
    double Q[N];
    if (!c->S_wanted) {
        eq_range_matrix(c->J, minv, c->S);
        c->S_singular = cholesky_factor(M, c->S, S_ENVELOPE) != 0;
    }
    if (c->S_singular) {
        snprintf(message, MODEL_MESSAGE, "Phi_q M^-1 Phi_q^T is singular: a toggle (dead-point) configuration");
        return DAE_INTEGRATION;
    }
    eq_range_rhs(c->q, c->tr, c->qd, t, p, d, c->J, minv, Q, lam);
    cholesky_solve(M, c->S, S_ENVELOPE, lam);
    eq_accelerations(c->J, minv, Q, lam, qdd);
    return DAE_OK;
}

/* dy/dt for y = (q[independent], qd[independent], work): the Runge-Kutta right-hand side. */
static int rhs(void *context, double t, const double *y, double *f)
{
    ModelState *s = (ModelState *)context;
    Configuration c;
    DaePoint e;
    double lam[MA];
    s->rhs_evaluations++;
    c.S_wanted = 1;
    int r = state_at(s, t, y, &c);
    if (!r) r = solve(s->p, s->d, MECH_MASS_IS_CONSTANT ? s->minv : c.minv, t, &c, e.qdd, lam, s->rhs_message);
    if (r == DAE_ASSEMBLY) {
        s->rhs_failed = r;        /* read only when the integrator reports a failure (a start's) */
        /* A trial point the branch cannot be followed to (a step too long for the predictor, or
           one across a dead point): the integrator rejects the step and tries one 5x shorter
           (dae.py returns an infinite derivative, whose error scipy's step control rejects). */
        s->failed_evaluations++;
        return RK_FUNCTION_REJECT;
    }
    if (r) {
        s->rhs_failed = r;
        return RK_FUNCTION_ERROR;
    }
    e.t = t;
    e.sign = c.sign;
    memcpy(e.q, c.q, sizeof e.q);
    memcpy(e.qd, c.qd, sizeof e.qd);
    s->last = e;
    if (t == s->base.t) s->base = e;     /* after a (re)start: the base's accelerations */
    for (int j = 0; j < K; j++) {
        f[j] = y[K + j];
        f[K + j] = e.qdd[s->independent[j]];
    }
    for (int k = 0; k < N_DRIVERS; k++) {
        /* the driver's power: its constraint force -Phi_q^T lambda (row `row`) times qd, -lambda nu */
        const int row = DRIVERS[k][2];
        f[2 * K + k] = -lam[row] * c.nu[row];
    }
    if (2 * K + N_DRIVERS == 0) f[0] = 0.0;   /* nothing to integrate: one constant */
    return RK_FUNCTION_OK;
}

/* -- set-up -------------------------------------------------------------------------------- */

int dae_assemble(ModelState *s, double t, const double *guess, const double *rates)
{
    Configuration c;
    int is_independent[N];
    memset(is_independent, 0, sizeof is_independent);
    for (int j = 0; j < K; j++) {
        s->independent[j] = INDEPENDENT[j];            /* the file's order, as dae.py */
        is_independent[INDEPENDENT[j]] = 1;
    }
    for (int i = 0, j = 0; i < N; i++)
        if (!is_independent[i]) s->dependent[j++] = i;
    dae_drive_at(s->p, t, s->d);
    memcpy(c.q, guess, sizeof c.q);
    int r = positions(s->p, s->d, s->dependent, t, &c, &s->newton_iterations, s->rhs_message);
    if (r) return r;
    memset(c.qd, 0, sizeof c.qd);              /* the rates' first guess: at rest */
    for (int j = 0; j < K; j++) c.qd[s->independent[j]] = rates[s->independent[j]];
    jacobian_at(s->p, s->d, t, &c);
    r = velocities(s->dependent, &c, s->rhs_message);
    if (r) return r;
    mass_inverse(s->p, c.q, c.tr, s->minv);
    s->t = t;
    memcpy(s->q, c.q, sizeof s->q);
    memcpy(s->qd, c.qd, sizeof s->qd);
    memset(s->work, 0, sizeof s->work);
    return DAE_OK;
}

int dae_start(ModelState *s, double first_step)
{
    double y0[RK_N], J[MA * N], tr[TRIG], block[MA * MA], inv_diag[MA];
    int piv[MA];
    DaePoint e;
    const double bound = isfinite(s->stop_time) ? s->stop_time + 1.0 : INFINITY;
    /* The predictor's base is the current state; its accelerations come with the integrator's
       first evaluation, at this time (dae.py solves for them here: the same numbers). */
    e.t = s->t;
    memcpy(e.q, s->q, sizeof e.q);
    memcpy(e.qd, s->qd, sizeof e.qd);
    memset(e.qdd, 0, sizeof e.qdd);
    /* its assembly branch: the sign of the dependent block's determinant at q (dae.py's start) */
    eq_trig(s->q, tr);
    eq_jacobian(s->q, tr, s->p, J);
    dependent_block(J, s->dependent, block);
    lu_factor(M, block, piv, inv_diag);
    e.sign = lu_det_sign(M, piv, inv_diag);
    s->base = s->last = e;
    s->before.t = NAN;
    memset(y0, 0, sizeof y0);
    for (int j = 0; j < K; j++) {
        y0[j] = s->q[s->independent[j]];
        y0[K + j] = s->qd[s->independent[j]];
    }
    for (int k = 0; k < N_DRIVERS; k++) y0[2 * K + k] = s->work[k];
    s->rhs_failed = 0;
    s->starts++;
    if (rk_start(&s->solver, s->integrator, rhs, s, s->t, y0, bound, s->values[VR_rtol], s->values[VR_atol],
                 first_step) != RK_OK)
        return s->rhs_failed ? s->rhs_failed : DAE_INTEGRATION;
    return DAE_OK;
}

int dae_change_parameters(ModelState *s, const double *p)
{
    Configuration c;
    double d[MECH_ALLOC(3 * MECH_N_DRIVERS)];
    for (int k = 0; k < N_DRIVERS; k++) {
        const double s_ref = s->d[3 * k], t_ref = s->d[3 * k + 1], v = s->d[3 * k + 2];
        d[3 * k] = s_ref + v * (s->t - t_ref);
        d[3 * k + 1] = s->t;
        d[3 * k + 2] = p[DRIVERS[k][1]];
    }
    if (N_DRIVERS == 0) d[0] = 0.0;
    memcpy(c.q, s->q, sizeof c.q);
    memcpy(c.qd, s->qd, sizeof c.qd);
    int r = positions(p, d, s->dependent, s->t, &c, &s->newton_iterations, s->rhs_message);
    if (!r) {
        jacobian_at(p, d, s->t, &c);
        r = velocities(s->dependent, &c, s->rhs_message);
    }
    if (r) return r;                                    /* nothing changed */
    memcpy(s->p, p, sizeof s->p);
    memcpy(s->d, d, sizeof s->d);
    memcpy(s->q, c.q, sizeof s->q);
    memcpy(s->qd, c.qd, sizeof s->qd);
    mass_inverse(s->p, c.q, c.tr, s->minv);
    return DAE_OK;
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
    memcpy(s->independent, independent, sizeof s->independent);
    memcpy(s->dependent, dependent, sizeof s->dependent);
    s->repartitions++;
}

/* Review the partition at the current state (c: its configuration): when the dependent block is
   ill-conditioned, change to the QR's choice if that is clearly better (dae.py's _check_partition). */
static int check_partition(ModelState *s, const Configuration *c)
{
    double block[MA * MA], inv_diag[MA];
    int piv[MA], independent[KA], dependent[MA];
    if (K == 0) return DAE_OK;
    /* c->block was factorised near q (within c->moved): decide on the block at q itself when that
       could matter. */
    if (lu_pivot_ratio(M, c->block) >= 2.0 * DAE_REPARTITION_REVIEW) return DAE_OK;
    dependent_block(c->J, s->dependent, block);
    if (!lu_factor(M, block, piv, inv_diag) && lu_pivot_ratio(M, block) >= DAE_REPARTITION_REVIEW) return DAE_OK;
    choose_partition(c->J, independent, dependent);
    if (memcmp(independent, s->independent, K * sizeof(int)) == 0) return DAE_OK;
    dependent_block(c->J, s->dependent, block);
    const double now = condition_number(M, block);
    dependent_block(c->J, dependent, block);
    const double chosen = condition_number(M, block);
    if (!(chosen * DAE_REPARTITION_GAIN < now)) return DAE_OK;
    set_partition(s, independent, dependent);
    return dae_start(s, s->solver.h_abs);
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

int dae_advance(ModelState *s, double t_end)
{
    RKSolver *solver = &s->solver;
    const char *method = INTEGRATOR_NAMES[s->integrator];
    const double eps = 1e-12 * fmax(1.0, fabs(t_end));   /* a step ending within round-off reaches t_end */
    double y[RK_N];
    int rescues = 0;
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
    for (int j = 0; j < RK_N; j++)
        if (!isfinite(y[j])) {
            snprintf(s->rhs_message, MODEL_MESSAGE, "%s produced a non-finite state before t = %.9g s", method, t_end);
            return DAE_INTEGRATION;
        }
    c.S_wanted = 0;
    int r = state_at(s, t_end, y, &c);
    if (r) {
        s->rhs_failed = r;
        return rhs_failure(s, t_end);
    }
    s->last_step = t_end - s->t;
    s->t = t_end;
    memcpy(s->q, c.q, sizeof s->q);
    memcpy(s->qd, c.qd, sizeof s->qd);
    for (int k = 0; k < N_DRIVERS; k++) s->work[k] = y[2 * K + k];
    return check_partition(s, &c);
}

/* -- outputs ------------------------------------------------------------------------------- */

void dae_outputs_state(const double *p, const double *d, double t, const double *q, const double *qd,
                       const double *work, double *out)
{
    double tr[TRIG], J[MA * N], nu[MA], phi[MA], values[MECH_ALLOC(MECH_N_STATE_OUTPUTS)];
    eq_trig(q, tr);
    eq_outputs_state(q, tr, qd, t, p, d, values);
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
        switch (OUTPUT_KINDS[k]) {
        case MECH_OUTPUT_STATE: out[k] = values[OUTPUT_INDICES[k]]; break;
        case MECH_OUTPUT_WORK: out[k] = work[OUTPUT_INDICES[k]]; break;
        case MECH_OUTPUT_RESIDUAL: out[k] = residual; break;
        default: break;
        }
}

int dae_outputs_force(const double *p, const double *d, double t, const double *q, const double *qd, double *out,
                      char *message)
{
    Configuration c;
    double qdd[N], lam[MA], minv[N], values[MECH_ALLOC(MECH_N_FORCE_OUTPUTS)];
    if (MECH_N_FORCE_OUTPUTS == 0) return DAE_OK;
    memcpy(c.q, q, sizeof c.q);
    memcpy(c.qd, qd, sizeof c.qd);
    eq_trig(c.q, c.tr);
    eq_jacobian(c.q, c.tr, p, c.J);
    mass_inverse(p, c.q, c.tr, minv);
    c.S_wanted = 0;
    int r = solve(p, d, minv, t, &c, qdd, lam, message);
    if (r) return r;
    eq_outputs_force(c.q, c.tr, c.qd, lam, t, p, d, values);
    for (int k = 0; k < MECH_N_OUTPUTS; k++)
        if (OUTPUT_KINDS[k] == MECH_OUTPUT_FORCE) out[k] = values[OUTPUT_INDICES[k]];
    return DAE_OK;
}
