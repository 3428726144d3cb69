/* In-process cost of the native FMU's model: Cases 1 and 2 (100 s, 0.01 s grid) through the
 * FMI functions, with no host in between.  Linked with the FMU's shipped sources by
 * benchmarks/native_fmu.py.  Prints one line per case:
 *   case wall_ms rhs_evaluations integrator_starts x2_at_100s
 * Arguments: [repeat (5)] [rtol = atol (0: Table 1's rtol 1e-9, atol 1e-6)] [cases (12: both; 1: Case 1 only,
 * e.g. under callgrind)]
 */
#define _POSIX_C_SOURCE 199309L   /* clock_gettime */
#include <stdio.h>
#include <stdlib.h>
#include <stdarg.h>
#include <time.h>
#include "fmi2Functions.h"
#include "model.h"

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

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static int run(int fault, int repeat, double tol)
{
    fmi2CallbackFunctions functions = {logger, calloc, free, NULL, NULL};
    const fmi2ValueReference l2 = VR_L2, x2 = VR_x2;
    double best = 1e300, value = 0.0;
    unsigned long evaluations = 0, starts = 0;
    for (int r = 0; r < repeat; r++) {
        fmi2Component c = fmi2Instantiate("bench", fmi2CoSimulation, FMU_GUID, "", &functions, fmi2False, fmi2False);
        if (!c) return 1;
        double t0 = now();
        fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, 100.0);
        {
            const fmi2ValueReference tols[2] = {VR_rtol, VR_atol};
            const double values[2] = {tol > 0.0 ? tol : 1e-9, tol > 0.0 ? tol : 1e-6};
            fmi2SetReal(c, tols, 2, values);
        }
        fmi2EnterInitializationMode(c);
        if (fmi2ExitInitializationMode(c) != fmi2OK) return 1;
        for (int k = 0; k < 10000; k++) {
            if (fault && k == 1000) {
                const double v = 1.1;
                fmi2SetReal(c, &l2, 1, &v);
            }
            const double t = k * 0.01;
            if (fmi2DoStep(c, t, (k + 1) * 0.01 - t, fmi2True) != fmi2OK) return 1;
            fmi2GetReal(c, &x2, 1, &value);
        }
        double wall = now() - t0;
        if (wall < best) best = wall;
        evaluations = ((ModelInstance *)c)->state.rhs_evaluations;
        starts = ((ModelInstance *)c)->state.starts;
        fmi2FreeInstance(c);
    }
    printf("%s %.4f %lu %lu %.17g\n", fault ? "case2" : "case1", best * 1e3, evaluations, starts, value);
    return 0;
}

int main(int argc, char **argv)
{
    int repeat = argc > 1 ? atoi(argv[1]) : 5;
    double tol = argc > 2 ? atof(argv[2]) : 0.0;    /* rtol = atol; 0: Table 1's (not the FMU's defaults) */
    const int case2 = argc > 3 ? atoi(argv[3]) != 1 : 1;
    return run(0, repeat, tol) || (case2 && run(1, repeat, tol));
}
