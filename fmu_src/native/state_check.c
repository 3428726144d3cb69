/* A mechanism's saved state checked field by field before an instance may use it (model.h,
 * model_check_state; saved_state.c reads the bytes).  Every integer that selects something (the
 * mode, the integrator, the partition's indices, enumerations, flags) must be one of its values and
 * every floating-point number the model computes from must be finite, so that no array is
 * addressed out of bounds and no NaN reaches an output with a status OK.  A file of its own, so
 * that a build replacing model.c (the benchmark's floor model) keeps it.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "model.h"

static int finite_all(const double *x, size_t n, size_t *at)
{
    for (size_t i = 0; i < n; i++)
        if (!isfinite(x[i])) {
            *at = i;
            return 0;
        }
    return 1;
}

static int is_sign(int v) { return v == -1 || v == 0 || v == 1; }
static int is_flag(int v) { return v == 0 || v == 1; }

/* The first problem, as "field = value: expected ..." in why (n bytes). */
#define BAD(...) do { snprintf(why, n, __VA_ARGS__); return 1; } while (0)
/* An array of doubles that must be finite. */
#define FINITE(array, count, name) do { size_t at_; \
        if (!finite_all((array), (count), &at_)) BAD("%s[%u] = %g: must be finite", (name), (unsigned)at_, (array)[at_]); \
    } while (0)

/* The partition: independent[MECH_K] and dependent[MECH_M], each increasing, together every
   coordinate once.  Before the first assembly (instantiated, initialization mode) it is still all
   zeros, which `assembled` 0 accepts. */
static int check_partition(const ModelState *s, int assembled, char *why, size_t n)
{
    int seen[MECH_N];
    int zeros = 1;
    for (int j = 0; j < MECH_K; j++) zeros &= s->independent[j] == 0;
    for (int j = 0; j < MECH_M; j++) zeros &= s->dependent[j] == 0;
    if (zeros && !assembled) return 0;
    memset(seen, 0, sizeof seen);
    for (int j = 0; j < MECH_K + MECH_M; j++) {
        const int is_independent = j < MECH_K;
        const int k = is_independent ? j : j - MECH_K;
        const int v = is_independent ? s->independent[k] : s->dependent[k];
        const char *name = is_independent ? "independent" : "dependent";
        if (v < 0 || v >= MECH_N) BAD("%s[%d] = %d: must be a coordinate's index in [0, %d)", name, k, v, MECH_N);
        if (k > 0 && v <= (is_independent ? s->independent[k - 1] : s->dependent[k - 1]))
            BAD("%s[%d] = %d: the indices must increase", name, k, v);
        if (seen[v]) BAD("%s[%d] = %d: coordinate %d is in the partition twice", name, k, v, v);
        seen[v] = 1;
    }
    return 0;
}

static int check_point(const DaePoint *p, const char *name, int finite, char *why, size_t n)
{
    char field[40];
    if (!is_sign(p->sign)) BAD("%s.sign = %d: must be -1, 0 or 1", name, p->sign);
    if (!finite) return 0;
    snprintf(field, sizeof field, "%s.t", name);
    FINITE(&p->t, 1, field);
    snprintf(field, sizeof field, "%s.q", name);
    FINITE(p->q, MECH_N, field);
    snprintf(field, sizeof field, "%s.qd", name);
    FINITE(p->qd, MECH_N, field);
    snprintf(field, sizeof field, "%s.qdd", name);
    FINITE(p->qdd, MECH_N, field);
    snprintf(field, sizeof field, "%s.tr", name);
    FINITE(p->tr, MECH_N_TRIG, field);
    return 0;
}

int model_check_state(const ModelState *s, int model_exchange, char *why, size_t n)
{
    static const int KINDS[FMU_N_VARIABLES] = FMU_VARIABLE_KINDS;
    const int cs_modes = MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_TERMINATED;
    const int me_modes = MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED;
    const int modes = model_exchange ? me_modes : cs_modes;
    const int groups = FMU_GROUP_STATE | FMU_GROUP_RESIDUAL | FMU_GROUP_FORCE | FMU_GROUP_STATES;
    const int mode = (int)s->mode;
    /* the mode: one state of the type's state machine a state can be saved in (not error) */
    int single = 0;
    for (int bit = 1; bit <= MODE_CONTINUOUS; bit <<= 1) single += mode == bit;
    if (!single || !(mode & modes))
        BAD("mode = %d: not a state a %s instance saves", mode, model_exchange ? "model-exchange" : "co-simulation");
    const int assembled = mode != MODE_INSTANTIATED && mode != MODE_INITIALIZATION;
    for (int vr = 0; vr < FMU_N_VARIABLES; vr++)
        if ((KINDS[vr] == 0 || KINDS[vr] == 1 || KINDS[vr] == 6) && !isfinite(s->values[vr]))
            BAD("values[%d] (a parameter or input) = %g: must be finite", vr, s->values[vr]);
    if (s->integrator < 0 || s->integrator >= FMU_N_INTEGRATORS)
        BAD("integrator = %d: must be in [0, %d)", s->integrator, FMU_N_INTEGRATORS);
    if (s->outputs_pending & ~groups) BAD("outputs_pending = %d: not a set of output groups", s->outputs_pending);
    FINITE(&s->start_time, 1, "start_time");
    if (isnan(s->stop_time) || s->stop_time < s->start_time)
        BAD("stop_time = %g: must not be before start_time = %g", s->stop_time, s->start_time);
    FINITE(s->p, MECH_N_PARAMETERS, "p");
    FINITE(&s->input_poly[0][0], 3 * MECH_N_INPUTS, "input_poly");
    FINITE(&s->input_der[0][0], 2 * MECH_N_INPUTS, "input_der");
    FINITE(&s->input_t0, 1, "input_t0");
    if (!is_flag(s->interpolating)) BAD("interpolating = %d: must be 0 or 1", s->interpolating);
    FINITE(s->d, 3 * MECH_N_DRIVERS, "d");
    if (check_partition(s, assembled, why, n)) return 1;
    FINITE(&s->t, 1, "t");
    FINITE(s->q, MECH_N, "q");
    FINITE(s->qd, MECH_N, "qd");
    FINITE(s->tr, MECH_N_TRIG, "tr");
    FINITE(s->work, MECH_N_WORKS, "work");
    if (!is_flag(s->declared)) BAD("declared = %d: must be 0 or 1", s->declared);
    if (assembled && !(isfinite(s->length_scale) && s->length_scale > 0.0))
        BAD("length_scale = %g: must be finite, > 0", s->length_scale);
    FINITE(s->mass, MECH_N, "mass");
    FINITE(s->minv, MECH_N, "minv");
    if (check_point(&s->base, "base", 1, why, n)) return 1;
    if (check_point(&s->before, "before", !isnan(s->before.t), why, n)) return 1;
    if (check_point(&s->last, "last", 0, why, n)) return 1;
    if (!isfinite(s->last_step) || s->last_step < 0.0) BAD("last_step = %g: must be finite, >= 0", s->last_step);
    /* the integrator: started in co-simulation only (model exchange leaves it zero) */
    const RKSolver *r = &s->solver;
    if (r->method < 0 || r->method >= FMU_N_INTEGRATORS)
        BAD("solver.method = %d: must be in [0, %d)", r->method, FMU_N_INTEGRATORS);
    if (!is_flag(r->dense_ready)) BAD("solver.dense_ready = %d: must be 0 or 1", r->dense_ready);
    if (!is_flag(r->has_step)) BAD("solver.has_step = %d: must be 0 or 1", r->has_step);
    if ((int)r->status < RK_RUNNING || (int)r->status > RK_FAILED)
        BAD("solver.status = %d: must be 0, 1 or 2", (int)r->status);
    FINITE(&r->t, 1, "solver.t");
    FINITE(&r->t_old, 1, "solver.t_old");
    if (isnan(r->t_bound)) BAD("solver.t_bound = %g: must not be NaN", r->t_bound);
    FINITE(r->y, RK_N, "solver.y");
    FINITE(r->y_old, RK_N, "solver.y_old");
    FINITE(r->f, RK_N, "solver.f");
    if (!isfinite(r->h_abs) || r->h_abs < 0.0) BAD("solver.h_abs = %g: must be finite, >= 0", r->h_abs);
    FINITE(&r->h_previous, 1, "solver.h_previous");
    /* the integrator's interval: t_old <= t <= t_bound, or a step would run backwards for ever */
    if (!(r->t_old <= r->t && r->t <= r->t_bound))
        BAD("solver.t = %g: must lie within [solver.t_old, solver.t_bound] = [%g, %g]", r->t, r->t_old, r->t_bound);
    if (s->evaluation_limit != 0) BAD("evaluation_limit = %lu: must be 0 between calls", s->evaluation_limit);
    if (!model_exchange && assembled) {
        /* the model's time within the integrator's last step (within round-off: dae_advance) */
        const double slack = 1e-9 * fmax(1.0, fabs(s->t));
        if (!(r->t_old - slack <= s->t && s->t <= r->t + slack))
            BAD("t = %g: must lie within the integrator's last step [%g, %g]", s->t, r->t_old, r->t);
        if (r->method != s->integrator)
            BAD("solver.method = %d: the integrator is %d", r->method, s->integrator);
        if (!(isfinite(r->rtol) && r->rtol > 0.0)) BAD("solver.rtol = %g: must be finite, > 0", r->rtol);
        if (!(isfinite(r->atol) && r->atol > 0.0)) BAD("solver.atol = %g: must be finite, > 0", r->atol);
    }
    if (s->rhs_failed < 0 || s->rhs_failed > 2) BAD("rhs_failed = %d: must be 0, 1 or 2", s->rhs_failed);
    if (!memchr(s->rhs_message, '\0', sizeof s->rhs_message)) BAD("rhs_message: not terminated");
    FINITE(&s->me_t, 1, "me_t");
    FINITE(s->me_y, RK_N, "me_y");
    if (!is_flag(s->me_fresh)) BAD("me_fresh = %d: must be 0 or 1", s->me_fresh);
    if (s->me_fresh) FINITE(s->me_f, RK_N, "me_f");
    return 0;
}
#undef BAD
#undef FINITE
