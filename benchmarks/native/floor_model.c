/* The FMPy floor for benchmarks/native_fmu.py: model.h implemented with no numerics.
 *
 * Compiled in place of fmu_src/native/model.c, it gives an FMU with the native FMU's FMI
 * layer, variables and value references whose doStep only copies a number, so the wall
 * time of a run through FMPy is FMPy's own cost: the floor the native FMU is compared with.
 * The checks of a step and of the values a host sets are the real ones (fmu_src/native/model_checks.c).
 */
#include <math.h>
#include <string.h>
#include "model.h"

static const double REAL_STARTS[FMU_N_VARIABLES] = FMU_REAL_STARTS;

void model_reset(ModelInstance *m)
{
    memset(&m->state, 0, sizeof m->state);
    memcpy(m->state.values, REAL_STARTS, sizeof m->state.values);
    m->state.stop_time = INFINITY;
    m->state.mode = MODE_INSTANTIATED;
}

ModelStatus model_initialize(ModelInstance *m)
{
    m->state.t = m->state.start_time;
    return MODEL_OK;
}

ModelStatus model_do_step(ModelInstance *m, double current_time, double step)
{
    m->state.t = current_time + step;
    m->state.values[VR_x2] = m->state.t;
    return MODEL_OK;
}

void model_preview_outputs(ModelInstance *m, int groups)
{
    (void)m;
    (void)groups;
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
    (void)m;
    (void)vr;
}

/* Model Exchange: the states are copies, the derivatives zero. */
void model_me_get_states(ModelInstance *m, double *x)
{
    memcpy(x, m->state.me_y, FMU_N_STATES * sizeof *x);
}

void model_me_set_time(ModelInstance *m, double t)
{
    m->state.me_t = t;
}

void model_me_set_states(ModelInstance *m, const double *x)
{
    memcpy(m->state.me_y, x, FMU_N_STATES * sizeof *x);
}

ModelStatus model_me_derivatives(ModelInstance *m, double *dx)
{
    (void)m;
    memset(dx, 0, FMU_N_STATES * sizeof *dx);
    return MODEL_OK;
}

ModelStatus model_me_completed_step(ModelInstance *m)
{
    (void)m;
    return MODEL_OK;
}

ModelStatus model_me_event_update(ModelInstance *m)
{
    (void)m;
    return MODEL_OK;
}

/* Directional derivatives: every known accepted, every sensitivity zero (the derivatives are). */
void model_me_directional_start(Directional *d)
{
    memset(d, 0, sizeof *d);
}

ModelStatus model_me_seed(ModelInstance *m, const char *function, Directional *d, unsigned long vr, double seed)
{
    (void)m; (void)function; (void)d; (void)vr; (void)seed;
    return MODEL_OK;
}

ModelStatus model_me_directional(ModelInstance *m, Directional *d)
{
    (void)m; (void)d;
    return MODEL_OK;
}

ModelStatus model_me_sensitivity(ModelInstance *m, const char *function, const Directional *d, unsigned long vr,
                                 double *value)
{
    (void)m; (void)function; (void)d; (void)vr;
    *value = 0.0;
    return MODEL_OK;
}

void model_inputs_set(ModelInstance *m, const unsigned int *vr, size_t nvr)
{
    (void)m; (void)vr; (void)nvr;
}

ModelStatus model_set_input_derivatives(ModelInstance *m, const char *function, const unsigned int *vr, size_t nvr,
                                        const int *order, const double *value)
{
    (void)m; (void)function; (void)vr; (void)nvr; (void)order; (void)value;
    return MODEL_OK;
}
