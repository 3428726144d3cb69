/* The four-bar linkage's DAE as a co-simulation slave: the C twin of
 * fmu_src/fourbar_model/dae.py and fmu_src/fourbar_slave.py.
 *
 * Method (the same as the pythonfmu FMU's):
 * - generalized-coordinate partitioning: the Runge-Kutta method integrates y = (theta2, omega2);
 *   the other coordinates come from the closed-form loop closure on a fixed assembly branch,
 *   their rates from Phi_q qd = 0 (both generated from the sympy derivation);
 * - eq. (11) at every right-hand-side evaluation by the range-space form
 *   (Phi_q M^-1 Phi_q^T) lambda = Phi_q M^-1 Q - gamma, an 8x8 Cholesky solve, then
 *   qdd = M^-1 (Q - Phi_q^T lambda), with the sign convention M qdd + Phi_q^T lambda = Q;
 * - a change of a tunable parameter between steps re-assembles the linkage keeping theta2
 *   and omega2, and restarts the integrator with its last proposed step; nothing else
 *   restarts it;
 * - communication times are snapped to whole nanoseconds, and outputs are published only at
 *   the end of a step, so the values read at an event time show the state before the change.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "model.h"

#define BRANCH_OPEN 1.0     /* Table 1's assembly: the rocker tip above the ground line */
#define MSG 512

static const double REAL_STARTS[FB_N_VARIABLES] = FB_REAL_STARTS;
static const int PARAMETER_VRS[FB_N_PARAMETERS] = FB_PARAMETER_VRS;
static const char *const PARAMETER_NAMES[FB_N_PARAMETERS] = FB_PARAMETER_NAMES;
static const char *const INTEGRATOR_NAMES[FB_N_INTEGRATORS] = FB_INTEGRATOR_NAMES;

static fmi2Status fail(ModelInstance *m, const char *fmt, ...)
{
    char text[2 * MSG];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    model_log(m, fmi2Error, "logStatusError", "FourBar '%s': %s", m->instance_name, text);
    return fmi2Error;
}

/* A double as Python's repr writes it: the shorter of %.15g / %.17g that reads back as the
   same value, with ".0" on whole numbers (so messages read the same from both FMUs). */
static const char *real_text(char *buf, size_t n, double v)
{
    snprintf(buf, n, "%.15g", v);
    if (isfinite(v) && strtod(buf, NULL) != v) snprintf(buf, n, "%.17g", v);
    if (isfinite(v) && !strpbrk(buf, ".e")) strncat(buf, ".0", n - strlen(buf) - 1);
    return buf;
}

static double snap_time(double t)
{
    return nearbyint(t * 1e9) / 1e9;    /* round half to even, as Python's round() */
}

/* -- kinematics ---------------------------------------------------------------------- */

/* q of a crank angle on a branch, by the generated closure; 0, or 1 with a message. */
static int positions(const double *p, double branch, double th2, double *q, char *msg)
{
    double reach[3], angles[2];
    const double L1 = p[0], L2 = p[1], L3 = p[2], L4 = p[3];
    fb_closure_reach(th2, p, reach);
    const double d = reach[0], h2 = reach[2];
    if (!(h2 > 1e-18 * L3 * L3)) {
        snprintf(msg, MSG, "the loop %s: the crank tip is %.6g m from the rocker pivot at theta2 = %.6g deg, "
                 "but coupler L3 = %g m and rocker L4 = %g m can only span distances between %.6g m and "
                 "%.6g m (L1 = %g m, L2 = %g m)",
                 h2 >= 0.0 ? "is at a toggle (singular) position" : "cannot be closed", d,
                 th2 * (180.0 / 3.141592653589793), L3, L4, fabs(L3 - L4), L3 + L4, L1, L2);
        return 1;
    }
    fb_closure_angles(th2, d, reach[1], sqrt(h2), branch, p, angles);
    fb_positions(th2, angles[0], angles[1], p, q);
    return 0;
}

/* qd from Phi_q qd = 0 with theta2_d = omega2; 0, or 1 at a toggle position. */
static int rates(const double *p, const double *q, double omega2, double *qd, char *msg)
{
    fb_velocities(q, omega2, p, qd);
    for (int i = 0; i < FB_N_COORDINATES; i++)
        if (!isfinite(qd[i])) {
            snprintf(msg, MSG, "the constraint Jacobian is singular: the linkage is at a toggle position");
            return 1;
        }
    return 0;
}

static double branch_of(const double *q, const double *p)
{
    return fb_branch_indicator(q, p) >= 0.0 ? 1.0 : -1.0;
}

/* Solve S x = b for the symmetric positive definite S (lower triangle packed by rows). */
static int cholesky_solve(const double *S, const double *b, double *x)
{
    enum { N = FB_N_CONSTRAINTS };
    double L[N][N], z[N];
    for (int i = 0; i < N; i++)
        for (int j = 0; j <= i; j++) {
            double sum = S[i * (i + 1) / 2 + j];
            for (int k = 0; k < j; k++) sum -= L[i][k] * L[j][k];
            if (i == j) {
                if (!(sum > 0.0)) return 1;
                L[i][i] = sqrt(sum);
            } else {
                L[i][j] = sum / L[j][j];
            }
        }
    for (int i = 0; i < N; i++) {
        double sum = b[i];
        for (int k = 0; k < i; k++) sum -= L[i][k] * z[k];
        z[i] = sum / L[i][i];
    }
    for (int i = N - 1; i >= 0; i--) {
        double sum = z[i];
        for (int k = i + 1; k < N; k++) sum -= L[k][i] * x[k];
        x[i] = sum / L[i][i];
    }
    return 0;
}

/* dy/dt for y = (theta2, omega2): eq. (11) by the range-space solve. */
static int rhs(void *context, double t, const double *y, double *f)
{
    ModelInstance *m = (ModelInstance *)context;
    ModelState *s = &m->state;
    double q[FB_N_COORDINATES], qd[FB_N_COORDINATES];
    double S[FB_N_CONSTRAINTS * (FB_N_CONSTRAINTS + 1) / 2], r[FB_N_CONSTRAINTS], lam[FB_N_CONSTRAINTS];
    (void)t;
    s->rhs_evaluations++;
    if (positions(s->p, s->branch, y[0], q, s->rhs_message)) { s->rhs_failed = 1; return 1; }
    fb_rhs_terms(q, y[1], s->p, qd, S, r);
    if (cholesky_solve(S, r, lam)) {
        snprintf(s->rhs_message, MSG, "Phi_q M^-1 Phi_q^T is singular: the linkage is at a toggle position");
        s->rhs_failed = 1;
        return 1;
    }
    f[0] = y[1];
    f[1] = fb_independent_acceleration(lam, q, qd, s->p);
    return 0;
}

/* -- parameters ---------------------------------------------------------------------- */

/* Every problem with the set parameter values, "; "-separated; 0 when there is none. */
static int check_parameters(const ModelState *s, char *out, size_t n)
{
    static const int positive[] = {VR_L1, VR_L2, VR_L3, VR_L4, VR_m2, VR_m3, VR_m4};
    static const char *const positive_names[] = {"L1", "L2", "L3", "L4", "m2", "m3", "m4"};
    static const int finite[] = {VR_g, VR_theta2_start, VR_omega2_start};
    static const char *const finite_names[] = {"g", "theta2_start", "omega2_start"};
    static const int tolerance[] = {VR_rtol, VR_atol};
    static const char *const tolerance_names[] = {"rtol", "atol"};
    char num[40];
    size_t used = 0;
    int count = 0;
    out[0] = '\0';
#define ADD(...) do { if (used < n) used += snprintf(out + used, n - used, "%s", count++ ? "; " : ""); \
                      if (used < n) used += snprintf(out + used, n - used, __VA_ARGS__); } while (0)
    for (size_t i = 0; i < sizeof positive / sizeof *positive; i++) {
        double v = s->values[positive[i]];
        if (!(isfinite(v) && v > 0.0))
            ADD("%s = %s %s: must be a finite positive number", positive_names[i], real_text(num, sizeof num, v),
                positive_names[i][0] == 'L' ? "m" : "kg");
    }
    for (size_t i = 0; i < sizeof finite / sizeof *finite; i++) {
        double v = s->values[finite[i]];
        if (!isfinite(v)) ADD("%s = %s: must be finite", finite_names[i], real_text(num, sizeof num, v));
    }
    for (size_t i = 0; i < sizeof tolerance / sizeof *tolerance; i++) {
        double v = s->values[tolerance[i]];
        if (!(isfinite(v) && v > 0.0))
            ADD("%s = %s: must be a finite positive number", tolerance_names[i], real_text(num, sizeof num, v));
    }
#undef ADD
    return count;
}

static void set_parameters_from_values(const ModelState *s, double *p)
{
    for (int i = 0; i < FB_N_PARAMETERS; i++) p[i] = s->values[PARAMETER_VRS[i]];
}

/* -- outputs ------------------------------------------------------------------------- */

static void publish(ModelState *s, const double *q, const double *qd, const double *p)
{
    double energy[2];
    s->values[VR_x2] = q[0]; s->values[VR_y2] = q[1]; s->values[VR_theta2] = q[2];
    s->values[VR_x3] = q[3]; s->values[VR_y3] = q[4]; s->values[VR_theta3] = q[5];
    s->values[VR_x4] = q[6]; s->values[VR_y4] = q[7]; s->values[VR_theta4] = q[8];
    s->values[VR_omega2] = qd[2]; s->values[VR_omega3] = qd[5]; s->values[VR_omega4] = qd[8];
    fb_energy(q, qd, p, energy);
    s->values[VR_energy] = energy[0] + energy[1];
    s->values[VR_constraint_residual] = fb_constraint_residual(q, qd, p);
}

void model_preview_outputs(ModelInstance *m)
{
    ModelState *s = &m->state;
    double p[FB_N_PARAMETERS], q[FB_N_COORDINATES], qd[FB_N_COORDINATES];
    char msg[MSG], problems[MSG];
    if (check_parameters(s, problems, sizeof problems)) return;
    set_parameters_from_values(s, p);
    if (positions(p, BRANCH_OPEN, s->values[VR_theta2_start], q, msg)) return;
    if (rates(p, q, s->values[VR_omega2_start], qd, msg)) return;
    publish(s, q, qd, p);
}

/* -- life cycle ---------------------------------------------------------------------- */

void model_reset(ModelInstance *m)
{
    ModelState *s = &m->state;
    memset(s, 0, sizeof *s);
    memcpy(s->values, REAL_STARTS, sizeof s->values);
    s->integrator = 0;
    s->start_time = 0.0;
    s->stop_time = INFINITY;
    s->branch = BRANCH_OPEN;
    s->mode = MODE_INSTANTIATED;
}

/* (Re)start the integrator at s->t from the consistent (q, qd) already in s. */
static fmi2Status start(ModelInstance *m, double first_step)
{
    ModelState *s = &m->state;
    const double y0[RK_N] = {s->q[FB_INDEPENDENT], s->qd[FB_INDEPENDENT]};
    const double bound = isfinite(s->stop_time) ? s->stop_time + 1.0 : INFINITY;
    s->rhs_failed = 0;
    s->starts++;
    if (rk_start(&s->solver, s->integrator, rhs, m, s->t, y0, bound, s->values[VR_rtol], s->values[VR_atol],
                 first_step) != RK_OK)
        return fail(m, "at t = %.9g s %s", s->t, s->rhs_message);
    return fmi2OK;
}

fmi2Status model_initialize(ModelInstance *m)
{
    ModelState *s = &m->state;
    char problems[4 * MSG], msg[MSG], num[40];
    if (check_parameters(s, problems, sizeof problems)) return fail(m, "invalid parameters: %s", problems);
    set_parameters_from_values(s, s->p);
    const double th2 = s->values[VR_theta2_start];
    if (positions(s->p, BRANCH_OPEN, th2, s->q, msg) || rates(s->p, s->q, s->values[VR_omega2_start], s->qd, msg))
        return fail(m, "initial assembly with theta2_start = %s rad failed: %s", real_text(num, sizeof num, th2), msg);
    s->t = snap_time(s->start_time);
    s->branch = branch_of(s->q, s->p);
    if (start(m, 0.0) != fmi2OK) return fmi2Error;
    publish(s, s->q, s->qd, s->p);
    return fmi2OK;
}

/* Integrate to t_end and store the consistent state (dae.py's FourBarDAE.advance). */
static fmi2Status advance(ModelInstance *m, double t_end)
{
    ModelState *s = &m->state;
    RKSolver *solver = &s->solver;
    const char *method = INTEGRATOR_NAMES[s->integrator];
    const double eps = 1e-12 * fmax(1.0, fabs(t_end));
    double y[RK_N], q[FB_N_COORDINATES], qd[FB_N_COORDINATES];
    char msg[MSG];
    while (solver->t < t_end - eps) {
        RKResult r = rk_step(solver, rhs, m);
        if (r == RK_ERROR_RHS) return fail(m, "at t = %.9g s %s", t_end, s->rhs_message);
        if (r == RK_ERROR_STEP_TOO_SMALL)
            return fail(m, "%s failed at t = %.9g s: Required step size is less than spacing between numbers.",
                        method, solver->t);
        if (r == RK_ERROR_FINISHED)
            return fail(m, "%s cannot step beyond t = %.9g s (the stop time + 1 s given to "
                        "fmi2SetupExperiment)", method, solver->t);
    }
    if (fabs(solver->t - t_end) <= eps) {
        y[0] = solver->y[0];
        y[1] = solver->y[1];
    } else if (rk_dense(solver, rhs, m, t_end, y) != RK_OK) {
        return fail(m, "at t = %.9g s %s", t_end, s->rhs_message);
    }
    if (!(isfinite(y[0]) && isfinite(y[1])))
        return fail(m, "%s produced a non-finite state before t = %.9g s", method, t_end);
    if (positions(s->p, s->branch, y[0], q, msg) || rates(s->p, q, y[1], qd, msg))
        return fail(m, "at t = %.9g s %s", t_end, msg);
    memcpy(s->q, q, sizeof q);
    memcpy(s->qd, qd, sizeof qd);
    s->t = t_end;
    return fmi2OK;
}

/* Apply the set parameters when they differ from the ones in use (re-assembly). */
static fmi2Status apply_parameter_changes(ModelInstance *m, double current_time)
{
    ModelState *s = &m->state;
    double p[FB_N_PARAMETERS], q[FB_N_COORDINATES], qd[FB_N_COORDINATES];
    char changed[MSG], problems[4 * MSG], msg[MSG];
    size_t used = 0;
    int differs = 0;
    set_parameters_from_values(s, p);
    changed[0] = '\0';
    for (int i = 0; i < FB_N_PARAMETERS; i++)
        if (p[i] != s->p[i]) {
            if (used < sizeof changed)
                used += snprintf(changed + used, sizeof changed - used, "%s%s %g -> %g", differs ? ", " : "",
                                 PARAMETER_NAMES[i], s->p[i], p[i]);
            differs = 1;
        }
    if (!differs) return fmi2OK;
    if (check_parameters(s, problems, sizeof problems)) return fail(m, "at t = %.9g s: %s", current_time, problems);
    const double branch = branch_of(s->q, s->p);
    if (positions(p, branch, s->q[FB_INDEPENDENT], q, msg) || rates(p, q, s->qd[FB_INDEPENDENT], qd, msg))
        return fail(m, "cannot apply %s at t = %.9g s: %s", changed, current_time, msg);
    memcpy(s->p, p, sizeof p);
    memcpy(s->q, q, sizeof q);
    memcpy(s->qd, qd, sizeof qd);
    s->branch = branch;
    if (start(m, s->solver.h_abs) != fmi2OK) return fmi2Error;
    model_log(m, fmi2OK, "logAll", "applied %s at t = %.9g s (re-assembled keeping theta2, omega2)", changed,
              current_time);
    return fmi2OK;
}

fmi2Status model_do_step(ModelInstance *m, double current_time, double step)
{
    ModelState *s = &m->state;
    char a[40], b[40];
    if (fabs(snap_time(current_time) - s->t) > 1e-9 * fmax(1.0, fabs(s->t)))
        return fail(m, "do_step at t = %s s, but the model is at t = %s s", real_text(a, sizeof a, current_time),
                    real_text(b, sizeof b, s->t));
    if (apply_parameter_changes(m, current_time) != fmi2OK) return fmi2Error;
    if (advance(m, snap_time(current_time + step)) != fmi2OK) return fmi2Error;
    publish(s, s->q, s->qd, s->p);
    return fmi2OK;
}
