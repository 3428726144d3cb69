/* A Runge-Kutta step far too long for the Newton-Raphson predictor, forced (tests/test_fmu_native.py).
 *
 * Linked with a native FMU's shipped sources.  Runs the FMU through its FMI functions on the
 * 0.01 s grid to `stop` at rtol = atol = `tol`; at t = 1 s it restarts the integrator (dae_start)
 * with a first step of `first_step` seconds (0: no restart), which no step control would propose:
 * its stages lie where neither the predictor nor, often, the continuation from the last accepted
 * state reaches, and the integrator must reject it and retry shorter steps.  Prints one line:
 *   <the outputs at stop, %.17g, in value-reference order> | <rhs evaluations> <continuations>
 *   <failed evaluations> <integrator starts> <re-partitions> <evaluations on the full system>
 *   <Newton-Raphson iterations>
 * Exit status 1 (with the FMU's message on stderr) when a call fails.
 * Arguments: first_step tol stop
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include "fmi2Functions.h"
#include "model.h"
#include "dae.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    va_list args;
    (void)env; (void)name; (void)status; (void)category;
    va_start(args, message);
    vfprintf(stderr, message, args);
    va_end(args);
    fputc('\n', stderr);
}

static const int KINDS[FMU_N_VARIABLES] = FMU_VARIABLE_KINDS;

int main(int argc, char **argv)
{
    if (argc != 4) {
        fprintf(stderr, "usage: long_step FIRST_STEP TOL STOP\n");
        return 2;
    }
    const double first_step = atof(argv[1]), tol = atof(argv[2]), stop = atof(argv[3]);
    fmi2CallbackFunctions functions = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("long_step", fmi2CoSimulation, FMU_GUID, "", &functions, fmi2False, fmi2False);
    if (!c) return 1;
    const fmi2ValueReference tols[2] = {VR_rtol, VR_atol};
    const double values[2] = {tol, tol};
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop) != fmi2OK || fmi2SetReal(c, tols, 2, values)
        || fmi2EnterInitializationMode(c) != fmi2OK || fmi2ExitInitializationMode(c) != fmi2OK)
        return 1;
    ModelState *s = &((ModelInstance *)c)->state;
    const long steps = lround(stop / 0.01);
    for (long k = 0; k < steps; k++) {
        if (k == 100 && first_step > 0.0 && dae_start(s, first_step) != DAE_OK) {
            fprintf(stderr, "dae_start: %s\n", s->rhs_message);
            return 1;
        }
        const double t = k * 0.01;
        if (fmi2DoStep(c, t, (k + 1) * 0.01 - t, fmi2True) != fmi2OK) return 1;
    }
    for (unsigned vr = 0; vr < FMU_N_VARIABLES; vr++) {
        double v;
        if (KINDS[vr] != 3) continue;                 /* outputs only (variables.h: kind 3) */
        if (fmi2GetReal(c, &vr, 1, &v) != fmi2OK) return 1;
        printf("%.17g ", v);
    }
    printf("| %lu %lu %lu %lu %lu %lu %lu\n", s->rhs_evaluations, s->continuations, s->failed_evaluations, s->starts,
           s->repartitions, s->full_evaluations, s->newton_iterations);
    fmi2FreeInstance(c);
    return 0;
}
