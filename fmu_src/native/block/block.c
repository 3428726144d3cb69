/* A component's model (model.h beside this file): what every block does alike.
 *
 * Behind the shared FMI layers; the equations are
 * generated (equations.c: f, y and their Jacobians); this file holds what every block does alike:
 * parameters checked and used as set (a tunable parameter changed between steps applies at the
 * next step, in Model Exchange at the next evaluation), the co-simulation step (the states
 * integrated by rk.c from the step's start to its end, restarted at each step; the inputs held, or
 * with derivatives from the host the polynomial u + u' (t - t0) + u'' (t - t0)^2 / 2), Model
 * Exchange (the host's states and time), the directional derivatives (the exact Jacobians), and
 * the FMU state's serialized form (checked field by field before use).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "model.h"

#define MSG MODEL_MESSAGE
#define NX BLOCK_N_STATES
#define NU MECH_N_INPUTS
#define NY BLOCK_N_OUTPUTS

static const double REAL_STARTS[FMU_N_VARIABLES] = FMU_REAL_STARTS;
static const int KINDS[FMU_N_VARIABLES] = FMU_VARIABLE_KINDS;
static const char *const NAMES[FMU_N_VARIABLES] = FMU_VARIABLE_NAMES;
static const int PARAMETER_VRS[BLOCK_ALLOC(BLOCK_N_PARAMETERS)] = BLOCK_PARAMETER_VRS;
static const int INPUT_VRS[BLOCK_ALLOC(NU)] = BLOCK_INPUT_VRS;
static const int OUTPUT_VRS[NY] = BLOCK_OUTPUT_VRS;
static const int STATE_VRS[BLOCK_ALLOC(NX)] = FMU_STATE_VRS;
static const int STATE_START_VRS[BLOCK_ALLOC(NX)] = FMU_STATE_START_VRS;
static const int DERIVATIVE_VRS[BLOCK_ALLOC(NX)] = FMU_DERIVATIVE_VRS;
enum { KIND_TUNABLE = 0, KIND_FIXED = 1, KIND_INPUT = 6 };
#define ALL_GROUPS (FMU_GROUP_STATE | FMU_GROUP_STATES)

/* -- parameters ---------------------------------------------------------------------- */

static void parameters_of(const ModelState *s, double *p)
{
    for (int i = 0; i < BLOCK_N_PARAMETERS; i++) p[i] = s->values[PARAMETER_VRS[i]];
    if (BLOCK_N_PARAMETERS == 0) p[0] = 0.0;
}

static void inputs_set_now(const ModelState *s, double *u)
{
    for (int k = 0; k < NU; k++) u[k] = s->values[INPUT_VRS[k]];
    if (NU == 0) u[0] = 0.0;
}

static void start_states(const ModelState *s, double *x)
{
    for (int k = 0; k < NX; k++) x[k] = s->values[STATE_START_VRS[k]];
    if (NX == 0) x[0] = 0.0;
}

static int input_index(unsigned long vr)
{
    for (int k = 0; k < NU; k++)
        if ((unsigned long)INPUT_VRS[k] == vr) return k;
    return -1;
}

/* -- outputs ------------------------------------------------------------------------- */

/* The outputs, states and derivatives at (p, u, x) into values[]. */
static void store(ModelState *s, const double *p, const double *u, const double *x)
{
    double y[NY], f[RK_N];
    block_outputs(p, u, x, y);
    block_derivatives(p, u, x, f);
    for (int k = 0; k < NY; k++) s->values[OUTPUT_VRS[k]] = y[k];
    for (int k = 0; k < NX; k++) {
        s->values[STATE_VRS[k]] = x[k];
        s->values[DERIVATIVE_VRS[k]] = f[k];
    }
    s->outputs_pending = 0;
}

/* The point the instance is at: before the start the start values; in co-simulation (t, x,
   u_now); in Model Exchange the host's states and the inputs as set. */
static void current_point(const ModelInstance *m, double *p, double *u, double *x)
{
    const ModelState *s = &m->state;
    parameters_of(s, p);
    if (s->mode == MODE_INSTANTIATED || s->mode == MODE_INITIALIZATION) {
        inputs_set_now(s, u);
        start_states(s, x);
    } else if (m->model_exchange) {
        inputs_set_now(s, u);
        memcpy(x, s->me_y, sizeof(double) * RK_N);
    } else {
        memcpy(u, s->u_now, sizeof(double) * BLOCK_ALLOC(NU));
        memcpy(x, s->x, sizeof(double) * RK_N);
    }
}

void model_preview_outputs(ModelInstance *m, int groups)
{
    double p[BLOCK_ALLOC(BLOCK_N_PARAMETERS)], u[BLOCK_ALLOC(NU)], x[RK_N];
    char why[MSG];
    (void)groups;                        /* a block computes all its outputs at once: cheap */
    if ((m->state.mode == MODE_INSTANTIATED || m->state.mode == MODE_INITIALIZATION)
        && model_check_parameters(&m->state, why, sizeof why))
        return;                          /* fmi2ExitInitializationMode says why */
    current_point(m, p, u, x);
    store(&m->state, p, u, x);
}

int model_few_outputs(const ModelInstance *m, int groups, size_t nvr)
{
    (void)m;
    (void)groups;
    (void)nvr;
    return 0;
}

void model_output_one(ModelInstance *m, unsigned long vr)
{
    (void)vr;
    model_preview_outputs(m, ALL_GROUPS);
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
    s->mode = MODE_INSTANTIATED;
}

ModelStatus model_initialize(ModelInstance *m)
{
    ModelState *s = &m->state;
    char problems[4 * MSG];
    if (model_check_parameters(s, problems, sizeof problems))
        return model_fail(m, "invalid parameters: %s", problems);
    s->t = model_snap_time(s->start_time);
    start_states(s, s->x);
    inputs_set_now(s, s->u_now);
    s->me_t = s->t;
    memcpy(s->me_y, s->x, sizeof s->me_y);
    s->solver.method = s->integrator;
    s->solver.t = s->solver.t_old = s->solver.t_bound = s->t;
    s->outputs_pending = ALL_GROUPS;
    return MODEL_OK;
}

/* -- co-simulation ------------------------------------------------------------------- */

typedef struct {
    const ModelState *s;
    double p[BLOCK_ALLOC(BLOCK_N_PARAMETERS)];
    unsigned long limit;                 /* most evaluations of this step */
    unsigned long *count;
} StepContext;

static void inputs_at(const ModelState *s, double t, double *u)
{
    const double h = t - s->input_t0;
    for (int k = 0; k < NU; k++)
        u[k] = s->input_poly[k][0] + s->input_poly[k][1] * h + s->input_poly[k][2] * h * h / 2.0;
    if (NU == 0) u[0] = 0.0;
}

static int rhs(void *context, double t, const double *y, double *f)
{
    StepContext *c = (StepContext *)context;
    double u[BLOCK_ALLOC(NU)];
    if (++*c->count > c->limit) return RK_FUNCTION_ERROR;
    inputs_at(c->s, t, u);
    block_derivatives(c->p, u, y, f);
    for (int k = 0; k < NX; k++)
        if (!isfinite(f[k])) return RK_FUNCTION_REJECT;
    return RK_FUNCTION_OK;
}

ModelStatus model_do_step(ModelInstance *m, double current_time, double step)
{
    ModelState *s = &m->state;
    char a[40], b[40], problems[4 * MSG];
    if (fabs(model_snap_time(current_time) - s->t) > 1e-9 * fmax(1.0, fabs(s->t)))
        return model_fail(m, "do_step at t = %s s, but the model is at t = %s s",
                          model_real_text(a, sizeof a, current_time), model_real_text(b, sizeof b, s->t));
    if (model_check_parameters(s, problems, sizeof problems))
        return model_fail(m, "at t = %.9g s: %s", current_time, problems);
    const double t_end = model_snap_time(current_time + step);
    s->input_t0 = s->t;
    for (int k = 0; k < NU; k++) {
        s->input_poly[k][0] = s->values[INPUT_VRS[k]];
        s->input_poly[k][1] = s->input_der[k][0];
        s->input_poly[k][2] = s->input_der[k][1];
    }
    if (NX > 0) {
        StepContext c;
        unsigned long count = 0;
        c.s = s;
        parameters_of(s, c.p);
        c.count = &count;
        c.limit = s->values[VR_max_evaluations] >= 4e9 ? 4000000000UL : (unsigned long)s->values[VR_max_evaluations];
        RKResult r = rk_start(&s->solver, s->integrator, rhs, &c, s->t, s->x, t_end, s->values[VR_rtol],
                              s->values[VR_atol], 0.0);
        while (r == RK_OK && s->solver.status == RK_RUNNING) r = rk_step(&s->solver, rhs, &c);
        s->rhs_evaluations += count;
        s->starts++;
        if (count > s->most_step_evaluations) s->most_step_evaluations = count;
        if (r != RK_OK || s->solver.status != RK_FINISHED) {
            if (count > c.limit)
                return model_fail(m, "the communication step from t = %.9g s to %.9g s needed more than "
                                  "max_evaluations = %.17g right-hand-side evaluations (raise max_evaluations, a "
                                  "fixed parameter, or shorten the step)", s->t, t_end, s->values[VR_max_evaluations]);
            return model_fail(m, "the integration from t = %.9g s to %.9g s failed at t = %.9g s (the derivatives "
                              "are not finite, or the step size fell below round-off)", s->t, t_end, s->solver.t);
        }
        memcpy(s->x, s->solver.y, sizeof s->x);
    }
    s->t = t_end;
    inputs_at(s, t_end, s->u_now);        /* the inputs at the step's end: held, or interpolated */
    s->outputs_pending = ALL_GROUPS;
    return MODEL_OK;
}

void model_inputs_set(ModelInstance *m, const unsigned int *vr, size_t nvr)
{
    ModelState *s = &m->state;
    for (size_t i = 0; i < nvr; i++) {       /* a direct feedthrough sees the new inputs at once */
        const int k = input_index(vr[i]);
        if (k >= 0) s->u_now[k] = s->values[vr[i]];
    }
    s->outputs_pending = ALL_GROUPS;
}

ModelStatus model_set_input_derivatives(ModelInstance *m, const char *function, const unsigned int *vr, size_t nvr,
                                        const int *order, const double *value)
{
    char buf[40], num[40];
    for (size_t i = 0; i < nvr; i++) {
        if (input_index(vr[i]) < 0)
            return model_fail(m, "%s: %s is not an input (nothing was set)", function,
                        vr[i] < FMU_N_VARIABLES ? NAMES[vr[i]] : (snprintf(buf, sizeof buf, "value reference %u",
                                                                          (unsigned)vr[i]), buf));
        if (order[i] != 1 && order[i] != 2)
            return model_fail(m, "%s: order %d for %s: the FMU interpolates inputs with derivatives of order 1 and 2 "
                        "(nothing was set)", function, order[i], NAMES[vr[i]]);
        if (!isfinite(value[i]))
            return model_fail(m, "%s: the derivative of order %d of %s = %s: must be finite (nothing was set)",
                              function, order[i], NAMES[vr[i]], model_real_text(num, sizeof num, value[i]));
    }
    for (size_t i = 0; i < nvr; i++) m->state.input_der[input_index(vr[i])][order[i] - 1] = value[i];
    return MODEL_OK;
}

/* -- Model Exchange ------------------------------------------------------------------ */

void model_me_get_states(ModelInstance *m, double *x)
{
    if (NX > 0) memcpy(x, m->state.me_y, NX * sizeof *x);
}

void model_me_set_time(ModelInstance *m, double t)
{
    m->state.me_t = t;
    m->state.outputs_pending = ALL_GROUPS;
}

void model_me_set_states(ModelInstance *m, const double *x)
{
    if (NX > 0) memcpy(m->state.me_y, x, NX * sizeof *x);
    m->state.outputs_pending = ALL_GROUPS;
}

ModelStatus model_me_derivatives(ModelInstance *m, double *dx)
{
    double p[BLOCK_ALLOC(BLOCK_N_PARAMETERS)], u[BLOCK_ALLOC(NU)], x[RK_N], f[RK_N];
    char text[40];
    current_point(m, p, u, x);
    block_derivatives(p, u, x, f);
    m->state.rhs_evaluations++;
    for (int k = 0; k < NX; k++)
        if (!isfinite(f[k]))
            return model_fail(m, "at t = %.9g s: the derivative der(%s) = %s is not finite at the states the host set",
                        m->state.me_t, NAMES[STATE_VRS[k]], model_real_text(text, sizeof text, f[k]));
    if (NX > 0) memcpy(dx, f, NX * sizeof *dx);
    return MODEL_OK;
}

ModelStatus model_me_completed_step(ModelInstance *m)
{
    (void)m;
    return MODEL_OK;
}

/* An event: tunable parameters set in event mode are checked (they apply at once). */
ModelStatus model_me_event_update(ModelInstance *m)
{
    char problems[4 * MSG];
    if (model_check_parameters(&m->state, problems, sizeof problems))
        return model_fail(m, "at t = %.9g s: %s", m->state.me_t, problems);
    m->state.outputs_pending = ALL_GROUPS;
    return MODEL_OK;
}

void model_me_directional_start(Directional *d)
{
    memset(d, 0, sizeof *d);
}

static const char *variable_name(unsigned long vr, char *buf, size_t n)
{
    if (vr < FMU_N_VARIABLES) return NAMES[vr];
    snprintf(buf, n, "value reference %lu", vr);
    return buf;
}

ModelStatus model_me_seed(ModelInstance *m, const char *function, Directional *d, unsigned long vr, double seed)
{
    char buf[40];
    const int initializing = m->state.mode == MODE_INITIALIZATION;
    if (input_index(vr) >= 0) {
        d->du[input_index(vr)] += seed;
        return MODEL_OK;
    }
    for (int k = 0; k < NX; k++)
        if ((unsigned long)STATE_VRS[k] == vr || (initializing && (unsigned long)STATE_START_VRS[k] == vr)) {
            d->dy[k] += seed;
            return MODEL_OK;
        }
    return model_fail(m, "%s: %s is not a continuous state or an input: the knowns of a directional derivative are the "
                "states and the inputs%s", function, variable_name(vr, buf, sizeof buf),
                initializing ? " (in initialization mode also the states' start parameters)" : "");
}

ModelStatus model_me_directional(ModelInstance *m, Directional *d)
{
    double p[BLOCK_ALLOC(BLOCK_N_PARAMETERS)], u[BLOCK_ALLOC(NU)], x[RK_N];
    double f_x[BLOCK_ALLOC(NX * NX)], f_u[BLOCK_ALLOC(NX * NU)], y_x[BLOCK_ALLOC(NY * NX)], y_u[BLOCK_ALLOC(NY * NU)];
    char why[MSG];
    if (m->state.mode == MODE_INITIALIZATION && model_check_parameters(&m->state, why, sizeof why))
        return model_fail(m, "the start values give no state to differentiate at: %s", why);
    current_point(m, p, u, x);
    block_jacobians(p, u, x, f_x, f_u, y_x, y_u);
    for (int i = 0; i < NX; i++) {
        double v = 0.0;
        for (int j = 0; j < NX; j++) v += f_x[i * NX + j] * d->dy[j];
        for (int j = 0; j < NU; j++) v += f_u[i * NU + j] * d->du[j];
        d->df[i] = v;
    }
    for (int i = 0; i < NY; i++) {
        double v = 0.0;
        for (int j = 0; j < NX; j++) v += y_x[i * NX + j] * d->dy[j];
        for (int j = 0; j < NU; j++) v += y_u[i * NU + j] * d->du[j];
        d->dout[i] = v;
    }
    return MODEL_OK;
}

ModelStatus model_me_sensitivity(ModelInstance *m, const char *function, const Directional *d, unsigned long vr,
                                 double *value)
{
    char buf[40];
    for (int k = 0; k < NX; k++)
        if ((unsigned long)DERIVATIVE_VRS[k] == vr) {
            *value = d->df[k];
            return MODEL_OK;
        }
    if (m->state.mode == MODE_INITIALIZATION)
        for (int k = 0; k < NX; k++)
            if ((unsigned long)STATE_VRS[k] == vr) {
                *value = d->dy[k];
                return MODEL_OK;
            }
    for (int k = 0; k < NY; k++)
        if ((unsigned long)OUTPUT_VRS[k] == vr) {
            *value = d->dout[k];
            return MODEL_OK;
        }
    return model_fail(m, "%s: %s is neither a state's derivative nor an output: the unknowns of a directional "
                "derivative are those of <ModelStructure>", function, variable_name(vr, buf, sizeof buf));
}

/* -- FMU state ----------------------------------------------------------------------- */

static int first_non_finite(const double *x, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (!isfinite(x[i])) return (int)i;
    return -1;
}

#define BAD(...) do { snprintf(why, n, __VA_ARGS__); return 1; } while (0)
#define FINITE(array, count, name) do { const int at_ = first_non_finite((array), (count)); \
        if (at_ >= 0) BAD("%s[%d] = %g: must be finite", (name), at_, (array)[at_]); } while (0)

int model_check_state(const ModelState *s, int model_exchange, char *why, size_t n)
{
    const int cs_modes = MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_TERMINATED;
    const int me_modes = MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED;
    const int mode = (int)s->mode;
    int single = 0;
    for (int bit = 1; bit <= MODE_CONTINUOUS; bit <<= 1) single += mode == bit;
    if (!single || !(mode & (model_exchange ? me_modes : cs_modes)))
        BAD("mode = %d: not a state a %s instance saves", mode, model_exchange ? "model-exchange" : "co-simulation");
    for (int vr = 0; vr < FMU_N_VARIABLES; vr++)
        if ((KINDS[vr] == KIND_TUNABLE || KINDS[vr] == KIND_FIXED || KINDS[vr] == KIND_INPUT)
            && !isfinite(s->values[vr]))
            BAD("values[%d] (a parameter or input) = %g: must be finite", vr, s->values[vr]);
    if (s->integrator < 0 || s->integrator >= FMU_N_INTEGRATORS)
        BAD("integrator = %d: must be in [0, %d)", s->integrator, FMU_N_INTEGRATORS);
    if (s->outputs_pending & ~ALL_GROUPS) BAD("outputs_pending = %d: not a set of output groups", s->outputs_pending);
    FINITE(&s->start_time, 1, "start_time");
    if (isnan(s->stop_time) || s->stop_time < s->start_time)
        BAD("stop_time = %g: must not be before start_time = %g", s->stop_time, s->start_time);
    FINITE(&s->t, 1, "t");
    FINITE(s->x, RK_N, "x");
    FINITE(s->u_now, BLOCK_ALLOC(NU), "u_now");
    FINITE(&s->input_poly[0][0], 3 * BLOCK_ALLOC(NU), "input_poly");
    FINITE(&s->input_der[0][0], 2 * BLOCK_ALLOC(NU), "input_der");
    FINITE(&s->input_t0, 1, "input_t0");
    FINITE(&s->me_t, 1, "me_t");
    FINITE(s->me_y, RK_N, "me_y");
    const RKSolver *r = &s->solver;
    if (r->method < 0 || r->method >= FMU_N_INTEGRATORS)
        BAD("solver.method = %d: must be in [0, %d)", r->method, FMU_N_INTEGRATORS);
    if ((int)r->status < RK_RUNNING || (int)r->status > RK_FAILED)
        BAD("solver.status = %d: must be 0, 1 or 2", (int)r->status);
    return 0;
}
#undef BAD
#undef FINITE
