/* Any mechanism as a co-simulation slave: the C twin of fmu_src/mechanism_model/slave.py.
 *
 * - Parameters are checked as the pythonfmu slave checks them (the generated variables.h says
 *   which must be positive, their bounds and units), with the same messages.
 * - fmi2ExitInitializationMode assembles the mechanism at its start values (Newton-Raphson from
 *   the positions the file gives) and starts the integrator (dae.c).
 * - A change of a tunable parameter between steps re-assembles the mechanism keeping its
 *   independent coordinates and their rates (the drivers continue from where they are) and
 *   restarts the integrator with its last proposed step.
 * - Communication times are snapped to whole nanoseconds, and outputs are published only at the
 *   end of a step, so the values read at an event time show the state before the change.  The
 *   outputs that need the multipliers (joint and driver forces: one more solve of eq. (11)) are
 *   computed when first read after a step, not at every step (slave.py computes every output at
 *   every step; the values are the same).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "model.h"
#include "dae.h"

#define MSG MODEL_MESSAGE

static const double REAL_STARTS[FMU_N_VARIABLES] = FMU_REAL_STARTS;
static const char *const NAMES[FMU_N_VARIABLES] = FMU_VARIABLE_NAMES;
static const int PARAMETER_VRS[MECH_ALLOC(MECH_N_PARAMETERS)] = MECH_PARAMETER_VRS;
static const int INDEPENDENT[MECH_ALLOC(MECH_K)] = MECH_INDEPENDENT;
static const int START_POSITION_VRS[MECH_ALLOC(MECH_K)] = MECH_START_POSITION_VRS;
static const int START_RATE_VRS[MECH_ALLOC(MECH_K)] = MECH_START_RATE_VRS;
static const double GUESS[MECH_N] = MECH_GUESS;
static const int OUTPUT_VRS[MECH_N_OUTPUTS] = MECH_OUTPUT_VRS;
static const int OUTPUT_KINDS[MECH_N_OUTPUTS] = MECH_OUTPUT_KINDS;
static const int STATE_GROUP[MECH_ALLOC(MECH_N_STATE_GROUP)] = MECH_STATE_GROUP;
static const char *const COORDINATES[MECH_N] = MECH_COORDINATE_NAMES;
static const int STATE_VRS[] = FMU_STATE_VRS;
static const int STATE_START_VRS[] = FMU_STATE_START_VRS;
static const int DERIVATIVE_VRS[] = FMU_DERIVATIVE_VRS;

/* -- parameters ---------------------------------------------------------------------- */

/* p: the file's parameters, then the inputs (as set: held). */
static void parameters_from_values(const ModelState *s, double *p)
{
    for (int i = 0; i < MECH_N_PARAMETERS; i++) p[i] = s->values[PARAMETER_VRS[i]];
}

/* The index among the inputs of value reference vr, or -1. */
static int input_index(unsigned long vr)
{
    for (int k = MECH_N_FILE_PARAMETERS; k < MECH_N_PARAMETERS; k++)
        if ((unsigned long)PARAMETER_VRS[k] == vr) return k - MECH_N_FILE_PARAMETERS;
    return -1;
}

/* Where assembly starts (the file's positions) and the rates, with the start parameters' values. */
static void start_configuration(const ModelState *s, double *guess, double *rates)
{
    memcpy(guess, GUESS, sizeof GUESS);
    memset(rates, 0, MECH_N * sizeof *rates);
    for (int j = 0; j < MECH_K; j++) {
        guess[INDEPENDENT[j]] = s->values[START_POSITION_VRS[j]];
        rates[INDEPENDENT[j]] = s->values[START_RATE_VRS[j]];
    }
}

/* -- outputs ------------------------------------------------------------------------- */

/* The outputs of the current state (slave.py's _publish computes them all at every step): marked
   pending, computed when first read (model_preview_outputs), a group at a time. */
static ModelStatus publish(ModelInstance *m)
{
    m->state.outputs_pending = FMU_GROUP_STATE | FMU_GROUP_RESIDUAL | FMU_GROUP_FORCE | FMU_GROUP_STATES;
    return MODEL_OK;
}

/* Copy the outputs of kind `kind` from out (output order) into values[]; MECH_OUTPUT_STATE: the
   state group (MECH_STATE_GROUP: the work outputs with the state's expressions). */
static void store_outputs(ModelState *s, const double *out, int kind)
{
    if (kind == MECH_OUTPUT_STATE) {                 /* read at every step: its own list */
        for (int g = 0; g < MECH_N_STATE_GROUP; g++) s->values[OUTPUT_VRS[STATE_GROUP[g]]] = out[STATE_GROUP[g]];
        return;
    }
    for (int k = 0; k < MECH_N_OUTPUTS; k++)
        if (OUTPUT_KINDS[k] == kind) s->values[OUTPUT_VRS[k]] = out[k];
}

/* The continuous states and their derivatives f into values[] (Model Exchange's variables). */
static void store_states(ModelState *s, const double *f)
{
    double y[RK_N];
    dae_states(s, y);
    for (int k = 0; k < FMU_N_STATES; k++) {
        s->values[STATE_VRS[k]] = y[k];
        s->values[DERIVATIVE_VRS[k]] = f[k];
    }
}

/* Model Exchange: the current state is the evaluation of the states the host set (dae_me_evaluate). */
static ModelStatus me_evaluate(ModelInstance *m)
{
    ModelState *s = &m->state;
    if (s->me_fresh) return MODEL_OK;
    const double t = s->t;
    for (int k = MECH_N_FILE_PARAMETERS; k < MECH_N_PARAMETERS; k++)     /* the inputs as set now */
        s->p[k] = s->values[PARAMETER_VRS[k]];
    if (dae_me_evaluate(s, s->me_t, s->me_y, s->me_f)) {
        s->t = t;
        return model_fail(m, "at t = %.9g s: %s", s->me_t, s->rhs_message);
    }
    for (int k = 0; k < FMU_N_STATES; k++)
        if (!isfinite(s->me_f[k])) {       /* states of no physical size (1e308) overflow */
            char a[40];
            return model_fail(m, "at t = %.9g s: the derivative der(%s) = %s is not finite at the states the host set "
                        "(are they of a physical size?)", s->me_t, NAMES[STATE_VRS[k]],
                        model_real_text(a, sizeof a, s->me_f[k]));
        }
    s->me_fresh = 1;
    publish(m);
    return MODEL_OK;
}

/* In initialization mode: the state the start values give, assembled in *scratch (a copy of the
   instance's state); 0, else 1 with why in `why` (invalid values, or no assembly). */
static int initial_state(const ModelState *s, ModelState *scratch, char *why, size_t n)
{
    double guess[MECH_N], rates[MECH_N];
    if (model_check_parameters(s, why, n)) return 1;
    *scratch = *s;
    parameters_from_values(scratch, scratch->p);
    start_configuration(scratch, guess, rates);
    if (dae_assemble(scratch, dae_snap_time(scratch->start_time), guess, rates)) {
        snprintf(why, n, "%s", scratch->rhs_message);
        return 1;
    }
    return 0;
}

void model_preview_outputs(ModelInstance *m, int groups)
{
    ModelState *s = &m->state;
    double out[MECH_N_OUTPUTS];
    if (s->mode == MODE_INITIALIZATION || s->mode == MODE_INSTANTIATED) {
        /* the outputs the start values give (nothing when they are invalid or cannot be
           assembled: fmi2ExitInitializationMode will say why); in instantiated (FMI 3.0's
           getters) at the default start time */
        ModelState scratch;
        char problems[MSG];
        if (initial_state(s, &scratch, problems, sizeof problems)) return;
        dae_outputs_state(scratch.p, scratch.d, scratch.t, scratch.q, scratch.tr, scratch.qd, scratch.work, out);
        dae_outputs_residual(scratch.p, scratch.d, scratch.t, scratch.q, scratch.qd, out);
        if (dae_outputs_force(scratch.p, scratch.d, scratch.t, scratch.q, scratch.qd, out, scratch.rhs_message))
            return;
        double f[RK_N];
        if (dae_me_start(&scratch) || dae_derivatives(&scratch, f)) return;
        for (int k = 0; k < MECH_N_OUTPUTS; k++) s->values[OUTPUT_VRS[k]] = out[k];
        store_states(&scratch, f);
        for (int k = 0; k < FMU_N_STATES; k++) {
            s->values[STATE_VRS[k]] = scratch.values[STATE_VRS[k]];
            s->values[DERIVATIVE_VRS[k]] = scratch.values[DERIVATIVE_VRS[k]];
        }
        return;
    }
    if (m->model_exchange && me_evaluate(m) != MODEL_OK) return;
    groups &= s->outputs_pending;
    if (groups & FMU_GROUP_STATE) {
        dae_outputs_state(s->p, s->d, s->t, s->q, s->tr, s->qd, s->work, out);
        store_outputs(s, out, MECH_OUTPUT_STATE);
        s->outputs_pending &= ~FMU_GROUP_STATE;
    }
    if (groups & FMU_GROUP_RESIDUAL) {
        dae_outputs_residual(s->p, s->d, s->t, s->q, s->qd, out);
        store_outputs(s, out, MECH_OUTPUT_RESIDUAL);
        s->outputs_pending &= ~FMU_GROUP_RESIDUAL;
    }
    if ((groups & FMU_GROUP_FORCE) && MECH_N_FORCE_OUTPUTS > 0) {
        if (dae_outputs_force(s->p, s->d, s->t, s->q, s->qd, out, s->rhs_message)) {
            model_fail(m, "at t = %.9g s %s", s->t, s->rhs_message);
            return;
        }
        store_outputs(s, out, MECH_OUTPUT_FORCE);
        s->outputs_pending &= ~FMU_GROUP_FORCE;
    }
    if (groups & FMU_GROUP_STATES) {
        double f[RK_N];
        if (m->model_exchange) {
            memcpy(f, s->me_f, sizeof f);
        } else if (dae_derivatives(s, f)) {
            model_fail(m, "at t = %.9g s %s", s->t, s->rhs_message);
            return;
        }
        store_states(s, f);
        s->outputs_pending &= ~FMU_GROUP_STATES;
    }
}

/* A host that records one or two outputs (FMPy's simulate_fmu with `output`) reads them after
   every step: each is computed on its own (eq_output_state) rather than the state's whole group
   (measured in-process, 100 s at 1e-10 on the 0.01 s grid reading x2: five-bar 180.9 -> 173.5
   million instructions, Watt six-bar 185.9 -> 176.5). */
int model_few_outputs(const ModelInstance *m, int groups, size_t nvr)
{
    return groups == FMU_GROUP_STATE && nvr <= MODEL_FEW_OUTPUTS && !m->model_exchange
        && m->state.mode != MODE_INSTANTIATED && m->state.mode != MODE_INITIALIZATION;
}

void model_output_one(ModelInstance *m, unsigned long vr)
{
    static const int OUTPUT_OF_VR[MECH_N_VRS] = MECH_OUTPUT_OF_VR;
    ModelState *s = &m->state;
    if (vr >= MECH_N_VRS || OUTPUT_OF_VR[vr] < 0) return;
    const int k = OUTPUT_OF_VR[vr];
    if (OUTPUT_KINDS[k] == MECH_OUTPUT_STATE || OUTPUT_KINDS[k] == MECH_OUTPUT_WORK)
        s->values[vr] = dae_output_state_one(s->p, s->d, s->t, s->q, s->tr, s->qd, s->work, k);
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
    char problems[4 * MSG], given[MSG], num[40];
    double guess[MECH_N], rates[MECH_N];
    if (model_check_parameters(s, problems, sizeof problems))
        return model_fail(m, "invalid parameters: %s", problems);
    parameters_from_values(s, s->p);
    start_configuration(s, guess, rates);
    if (dae_assemble(s, dae_snap_time(s->start_time), guess, rates)) {
        size_t used = 0;
        given[0] = '\0';
        for (int j = 0; j < MECH_K && used < sizeof given; j++)
            used += snprintf(given + used, sizeof given - used, "%s%s = %s", j ? ", " : "",
                             NAMES[START_POSITION_VRS[j]],
                             model_real_text(num, sizeof num, s->values[START_POSITION_VRS[j]]));
        return model_fail(m, "initial assembly with %s failed: %s", MECH_K ? given : "the drivers' start values",
                    s->rhs_message);
    }
    if (m->model_exchange) {
        if (dae_me_start(s)) return model_fail(m, "%s", s->rhs_message);
        s->me_t = s->t;
        dae_states(s, s->me_y);
        s->me_fresh = 0;
    } else if (dae_start(s, 0.0)) {
        return model_fail(m, "%s", s->rhs_message);
    }
    return publish(m);
}

/* Apply the set parameters when they differ from the ones in use (re-assembly; the inputs as
   they are in use). */
static ModelStatus apply_parameter_changes(ModelInstance *m, double current_time)
{
    ModelState *s = &m->state;
    double p[MECH_ALLOC(MECH_N_PARAMETERS)];
    char changed[MSG], problems[4 * MSG], kept[MSG];
    size_t used = 0;
    int differs = 0;
    memcpy(p, s->p, sizeof p);
    for (int i = 0; i < MECH_N_FILE_PARAMETERS; i++) p[i] = s->values[PARAMETER_VRS[i]];
    changed[0] = '\0';
    for (int i = 0; i < MECH_N_FILE_PARAMETERS; i++)
        if (p[i] != s->p[i]) {
            if (used < sizeof changed)
                used += snprintf(changed + used, sizeof changed - used, "%s%s %g -> %g", differs ? ", " : "",
                                 NAMES[PARAMETER_VRS[i]], s->p[i], p[i]);
            differs = 1;
        }
    if (!differs) return MODEL_OK;
    if (model_check_parameters(s, problems, sizeof problems))
        return model_fail(m, "at t = %.9g s: %s", current_time, problems);
    int r = dae_change_parameters(s, p);
    if (!r) r = m->model_exchange ? dae_me_start(s) : dae_start(s, s->solver.h_abs);
    if (!r && m->model_exchange) {        /* the states are kept: the new current state is their evaluation */
        s->me_t = s->t;
        dae_states(s, s->me_y);
        s->me_fresh = 0;
    }
    if (r == DAE_ASSEMBLY)
        return model_fail(m, "cannot apply %s at t = %.9g s: %s", changed, current_time, s->rhs_message);
    if (r) return model_fail(m, "%s", s->rhs_message);
    used = 0;
    kept[0] = '\0';
    for (int j = 0; j < MECH_K && used < sizeof kept; j++)
        used += snprintf(kept + used, sizeof kept - used, "%s%s", j ? ", " : "", COORDINATES[s->independent[j]]);
    model_log(m, MODEL_OK, "logAll", "applied %s at t = %.9g s (re-assembled keeping %s)", changed, current_time,
              MECH_K ? kept : "the drivers");
    return MODEL_OK;
}

/* Co-simulation: the inputs over the step from current_time (the values set, with the derivatives
   set, if any, as a polynomial: dae.c's inputs_at); when they differ from those in use, or vary
   within a step, the dependent coordinates are re-solved with them (a driver's input position
   moves the linkage) and the integrator restarted there. */
static ModelStatus apply_inputs(ModelInstance *m, double current_time)
{
#if MECH_N_INPUTS > 0
    ModelState *s = &m->state;
    double p[MECH_ALLOC(MECH_N_PARAMETERS)];
    int differs = 0, interpolating = 0;
    static const int INPUT_DRIVERS[MECH_ALLOC(MECH_N_INPUT_DRIVERS)] = MECH_INPUT_DRIVERS;
    memcpy(p, s->p, sizeof p);
    for (int k = 0; k < MECH_N_INPUTS; k++) {
        const double u = s->values[PARAMETER_VRS[MECH_N_FILE_PARAMETERS + k]];
        if (u != p[MECH_N_FILE_PARAMETERS + k]) differs = 1;
        p[MECH_N_FILE_PARAMETERS + k] = u;
        s->input_poly[k][0] = u;
        s->input_poly[k][1] = s->input_der[k][0];
        s->input_poly[k][2] = s->input_der[k][1];
    }
    /* A driver input without derivatives from the host moves on its own rate and acceleration over
       the step (u + u_d (t - t0) + u_dd (t - t0)^2 / 2, u_d + u_dd (t - t0)): held, its position
       would contradict its rate. */
    for (int j = 0; j < MECH_N_INPUT_DRIVERS; j++) {
        const int k = INPUT_DRIVERS[j];
        int given = 0;
        for (int i = k; i < k + 3; i++) given |= s->input_der[i][0] != 0.0 || s->input_der[i][1] != 0.0;
        if (given) continue;
        s->input_poly[k][1] = s->input_poly[k + 1][0];
        s->input_poly[k][2] = s->input_poly[k + 2][0];
        s->input_poly[k + 1][1] = s->input_poly[k + 2][0];
    }
    for (int k = 0; k < MECH_N_INPUTS; k++)
        if (s->input_poly[k][1] != 0.0 || s->input_poly[k][2] != 0.0) interpolating = 1;
    if (!differs && !interpolating && !s->interpolating) return MODEL_OK;
    s->input_t0 = s->t;
    s->interpolating = interpolating;
    int r = dae_change_parameters(s, p);
    if (!r) r = dae_start(s, s->solver.h_abs);
    if (r == DAE_ASSEMBLY)
        return model_fail(m, "cannot apply the inputs at t = %.9g s: %s", current_time, s->rhs_message);
    if (r) return model_fail(m, "%s", s->rhs_message);
#else
    (void)m;
    (void)current_time;
#endif
    return MODEL_OK;
}

void model_inputs_set(ModelInstance *m, const unsigned int *vr, size_t nvr)
{
    (void)vr;
    (void)nvr;
    if (m->model_exchange && m->state.mode != MODE_INSTANTIATED && m->state.mode != MODE_INITIALIZATION) {
        m->state.me_fresh = 0;
        publish(m);
    }
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

ModelStatus model_do_step(ModelInstance *m, double current_time, double step)
{
    ModelState *s = &m->state;
    char a[40], b[40];
    if (fabs(dae_snap_time(current_time) - s->t) > 1e-9 * fmax(1.0, fabs(s->t)))
        return model_fail(m, "do_step at t = %s s, but the model is at t = %s s",
                          model_real_text(a, sizeof a, current_time), model_real_text(b, sizeof b, s->t));
    if (apply_parameter_changes(m, current_time) != MODEL_OK) return MODEL_ERROR;
    if (apply_inputs(m, current_time) != MODEL_OK) return MODEL_ERROR;
    const unsigned long before = s->rhs_evaluations;
    if (dae_advance(s, dae_snap_time(current_time + step), s->values[VR_max_evaluations]))
        return model_fail(m, "%s", s->rhs_message);
    if (s->rhs_evaluations - before > s->most_step_evaluations) s->most_step_evaluations = s->rhs_evaluations - before;
    return publish(m);
}

/* -- Model Exchange ------------------------------------------------------------------ */

void model_me_get_states(ModelInstance *m, double *x)
{
    memcpy(x, m->state.me_y, FMU_N_STATES * sizeof *x);
}

void model_me_set_time(ModelInstance *m, double t)
{
    ModelState *s = &m->state;
    if (t != s->me_t) {
        s->me_fresh = 0;
        publish(m);
    }
    s->me_t = t;
}

void model_me_set_states(ModelInstance *m, const double *x)
{
    ModelState *s = &m->state;
    if (memcmp(x, s->me_y, FMU_N_STATES * sizeof *x) != 0) {
        s->me_fresh = 0;
        publish(m);
    }
    memcpy(s->me_y, x, FMU_N_STATES * sizeof *x);
}

ModelStatus model_me_derivatives(ModelInstance *m, double *dx)
{
    if (me_evaluate(m) != MODEL_OK) return MODEL_ERROR;
    memcpy(dx, m->state.me_f, FMU_N_STATES * sizeof *dx);
    return MODEL_OK;
}

void model_me_directional_start(Directional *d)
{
    memset(d, 0, sizeof *d);
}

/* A variable's name for a message (value references past the table are named by number). */
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
    for (int k = 0; k < FMU_N_STATES; k++)
        /* in initialization mode a state's start parameter too: the state is its start value there */
        if ((unsigned long)STATE_VRS[k] == vr || (initializing && STATE_START_VRS[k] >= 0 &&
                                                  (unsigned long)STATE_START_VRS[k] == vr)) {
            d->dy[k] += seed;
            return MODEL_OK;
        }
    if (initializing)
        return model_fail(m, "%s: %s is neither a continuous state, an input nor a state's start parameter: in "
                    "initialization mode those are the knowns of a directional derivative (derivatives with respect "
                    "to other parameters are not provided)", function, variable_name(vr, buf, sizeof buf));
    return model_fail(m, "%s: %s is not a continuous state or an input: the knowns of a directional derivative are "
                "the states and the inputs", function, variable_name(vr, buf, sizeof buf));
}

ModelStatus model_me_directional(ModelInstance *m, Directional *d)
{
    ModelState *s = &m->state;
    if (s->mode == MODE_INITIALIZATION) {     /* at the state the start values give */
        ModelState scratch;
        char why[MSG];
        if (initial_state(s, &scratch, why, sizeof why))
            return model_fail(m, "the start values give no state to differentiate at: %s", why);
        if (dae_me_start(&scratch) || dae_directional(&scratch, d->dy, d->du, d->df, d->dout))
            return model_fail(m, "at the start: %s", scratch.rhs_message);
        return MODEL_OK;
    }
    if (me_evaluate(m) != MODEL_OK) return MODEL_ERROR;
    if (dae_directional(s, d->dy, d->du, d->df, d->dout))
        return model_fail(m, "at t = %.9g s: %s", s->t, s->rhs_message);
    return MODEL_OK;
}

ModelStatus model_me_sensitivity(ModelInstance *m, const char *function, const Directional *d, unsigned long vr,
                                 double *value)
{
    char buf[40];
    for (int k = 0; k < FMU_N_STATES; k++)
        if ((unsigned long)DERIVATIVE_VRS[k] == vr) {
            *value = d->df[k];
            return MODEL_OK;
        }
    if (m->state.mode == MODE_INITIALIZATION)    /* the states are initial unknowns there */
        for (int k = 0; k < FMU_N_STATES; k++)
            if ((unsigned long)STATE_VRS[k] == vr) {
                *value = d->dy[k];
                return MODEL_OK;
            }
    for (int k = 0; k < MECH_N_OUTPUTS; k++)
        if ((unsigned long)OUTPUT_VRS[k] == vr) {
            *value = d->dout[k];
            return MODEL_OK;
        }
    return model_fail(m, "%s: %s is neither a state's derivative nor an output: the unknowns of a directional "
                "derivative are those of <ModelStructure>", function, variable_name(vr, buf, sizeof buf));
}

ModelStatus model_me_completed_step(ModelInstance *m)
{
    if (me_evaluate(m) != MODEL_OK) return MODEL_ERROR;
    dae_me_accept(&m->state);
    return MODEL_OK;
}

ModelStatus model_me_event_update(ModelInstance *m)
{
    ModelState *s = &m->state;
    if (me_evaluate(m) != MODEL_OK) return MODEL_ERROR;
    return apply_parameter_changes(m, s->t);
}
