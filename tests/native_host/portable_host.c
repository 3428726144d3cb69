/* A plain FMI host that builds for Linux (gcc, dlopen) and for Windows (mingw-w64, LoadLibrary;
   run under wine here): it loads a native FMU's extracted binary and runs the paper's Case 2
   (L2 1.0 -> 1.1 m at t = 10 s) for 20 s, writing time, x2..y4 and L2 at every 0.01 s as CSV.
   tests/test_fmu_windows.py builds it both ways and compares the Windows DLL's runs with the
   Linux library's, in each of the four flavours the native FMUs offer:

     fmi2-cs  FMI 2.0 co-simulation: fmi2DoStep of 0.01 s, the FMU's own integrator at
              rtol = atol = 1e-12 (its rtol and atol parameters); L2 set before the step from 10 s.
     fmi3-cs  FMI 3.0 co-simulation: the same with fmi3DoStep.
     fmi2-me  FMI 2.0 model exchange: the host integrates the states itself (below); at t = 10 s
              L2 is set in event mode (fmi2EnterEventMode, fmi2SetReal, fmi2NewDiscreteStates,
              fmi2EnterContinuousTimeMode).
     fmi3-me  FMI 3.0 model exchange: the same with fmi3SetTime, fmi3SetContinuousStates,
              fmi3GetContinuousStateDerivatives, fmi3CompletedIntegratorStep; the fault through
              fmi3EnterEventMode, fmi3SetFloat64, fmi3UpdateDiscreteStates,
              fmi3EnterContinuousTimeMode.

   Model exchange's integrator: classic fourth-order Runge-Kutta with a fixed step of 0.5 ms
   (SUBSTEPS = 20 per 0.01 s row, so the rows and the fault fall on step boundaries; every time
   is computed from an integer step count, never summed).  Its error over Case 2's 20 s,
   against co-simulation at 1e-12: 3.3e-11 m (1 ms: 4.8e-10 m; 2 ms: 1.05e-8 m).  Each stage sets the time
   and the states and reads the derivatives; after each step the host sets the step's end
   point and calls CompletedIntegratorStep there, whose outputs are the row's.  The row at
   t = 10.00 s is read before the fault, as in co-simulation.

   usage: portable_host MODE LIBRARY TOKEN VR_L2 VR_RTOL VR_ATOL VR_X2 NX OUT.csv
     MODE     fmi2-cs | fmi2-me | fmi3-cs | fmi3-me
     TOKEN    the GUID (FMI 2.0) or instantiationToken (FMI 3.0) of the model description
     VR_*     value references; x2..y4 are six consecutive ones from VR_X2; VR_RTOL and VR_ATOL
              are set in co-simulation only (model exchange does not use the FMU's integrator)
     NX       the number of continuous states (model exchange; in FMI 3.0 checked against
              fmi3GetNumberOfContinuousStates); 0 in co-simulation
   Exit status: 0 done ("ok" on stdout), 1 an FMI call failed (stderr names it and its status,
   after the FMU's own messages), 2 bad arguments. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _WIN32
#include <windows.h>
#define LOAD(path) ((void *)LoadLibraryA(path))
#define SYMBOL(lib, name) ((void *)GetProcAddress((HMODULE)(lib), name))
#else
#include <dlfcn.h>
#define LOAD(path) dlopen(path, RTLD_NOW | RTLD_LOCAL)
#define SYMBOL(lib, name) dlsym(lib, name)
#endif
#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

#define ROWS 2000            /* 20 s of 0.01 s rows (plus the row at 0) */
#define ROW_STEP 0.01        /* s */
#define FAULT_ROW 1000       /* t = 10.00 s */
#define SUBSTEPS 20          /* model exchange: Runge-Kutta steps per row */
#define ME_STEPS_PER_SECOND (SUBSTEPS * 100.0)   /* t = k / ME_STEPS_PER_SECOND: correctly rounded */
#define STOP_TIME (ROWS * ROW_STEP)
#define MAX_STATES 64
#define N_OUT 7              /* x2 y2 x3 y3 x4 y4 L2 */

static const double TIGHT = 1e-12, L2_AFTER = 1.1;   /* rtol = atol of co-simulation; the fault's L2 (m) */

/* -- the two FMI versions behind one set of operations ------------------------------------- */

typedef struct {
    fmi2InstantiateTYPE *fmi2Instantiate;
    fmi2SetupExperimentTYPE *fmi2SetupExperiment;
    fmi2EnterInitializationModeTYPE *fmi2EnterInitializationMode;
    fmi2ExitInitializationModeTYPE *fmi2ExitInitializationMode;
    fmi2SetRealTYPE *fmi2SetReal;
    fmi2GetRealTYPE *fmi2GetReal;
    fmi2DoStepTYPE *fmi2DoStep;
    fmi2EnterEventModeTYPE *fmi2EnterEventMode;
    fmi2NewDiscreteStatesTYPE *fmi2NewDiscreteStates;
    fmi2EnterContinuousTimeModeTYPE *fmi2EnterContinuousTimeMode;
    fmi2CompletedIntegratorStepTYPE *fmi2CompletedIntegratorStep;
    fmi2SetTimeTYPE *fmi2SetTime;
    fmi2SetContinuousStatesTYPE *fmi2SetContinuousStates;
    fmi2GetContinuousStatesTYPE *fmi2GetContinuousStates;
    fmi2GetDerivativesTYPE *fmi2GetDerivatives;
    fmi2TerminateTYPE *fmi2Terminate;
    fmi2FreeInstanceTYPE *fmi2FreeInstance;
} Fmi2;

typedef struct {
    fmi3InstantiateCoSimulationTYPE *fmi3InstantiateCoSimulation;
    fmi3InstantiateModelExchangeTYPE *fmi3InstantiateModelExchange;
    fmi3EnterInitializationModeTYPE *fmi3EnterInitializationMode;
    fmi3ExitInitializationModeTYPE *fmi3ExitInitializationMode;
    fmi3SetFloat64TYPE *fmi3SetFloat64;
    fmi3GetFloat64TYPE *fmi3GetFloat64;
    fmi3DoStepTYPE *fmi3DoStep;
    fmi3EnterEventModeTYPE *fmi3EnterEventMode;
    fmi3UpdateDiscreteStatesTYPE *fmi3UpdateDiscreteStates;
    fmi3EnterContinuousTimeModeTYPE *fmi3EnterContinuousTimeMode;
    fmi3CompletedIntegratorStepTYPE *fmi3CompletedIntegratorStep;
    fmi3SetTimeTYPE *fmi3SetTime;
    fmi3SetContinuousStatesTYPE *fmi3SetContinuousStates;
    fmi3GetContinuousStatesTYPE *fmi3GetContinuousStates;
    fmi3GetContinuousStateDerivativesTYPE *fmi3GetContinuousStateDerivatives;
    fmi3GetNumberOfContinuousStatesTYPE *fmi3GetNumberOfContinuousStates;
    fmi3TerminateTYPE *fmi3Terminate;
    fmi3FreeInstanceTYPE *fmi3FreeInstance;
} Fmi3;

typedef struct {
    int fmi3, cs;            /* which FMI version, co-simulation or model exchange */
    size_t nx;               /* continuous states (model exchange) */
    Fmi2 f2;
    Fmi3 f3;
    void *instance;          /* fmi2Component or fmi3Instance */
} Fmu;

/* Every FMI call goes through this: a status worse than warning is reported with the call's name. */
static int failed(int status, const char *call)
{
    static const char *names[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};
    if (status <= 1) return 0;       /* fmi2OK/fmi3OK, fmi2Warning/fmi3Warning */
    fprintf(stderr, "%s returned %s\n", call, status >= 0 && status <= 5 ? names[status] : "an unknown status");
    return 1;
}
#define CALL(expr, name) if (failed((int)(expr), name)) return 1

static void log_fmi2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                 fmi2String message, ...)
{
    va_list args;
    (void)env;
    (void)category;
    if (status == fmi2OK) return;
    fprintf(stderr, "[%s %d] ", name ? name : "?", (int)status);
    va_start(args, message);
    vfprintf(stderr, message, args);
    va_end(args);
    fprintf(stderr, "\n");
}

static void log_fmi3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    (void)category;
    if (status != fmi3OK) fprintf(stderr, "[portable %d] %s\n", (int)status, message ? message : "");
}

#define BIND(table, type, name) \
    if (!((table)->name = (type *)SYMBOL(lib, #name))) { fprintf(stderr, "%s: missing %s\n", path, #name); return 1; }

static int load_library(Fmu *f, const char *path)
{
    void *lib = LOAD(path);
    if (!lib) { fprintf(stderr, "cannot load %s\n", path); return 1; }
    if (!f->fmi3) {
        Fmi2 *t = &f->f2;
        BIND(t, fmi2InstantiateTYPE, fmi2Instantiate)
        BIND(t, fmi2SetupExperimentTYPE, fmi2SetupExperiment)
        BIND(t, fmi2EnterInitializationModeTYPE, fmi2EnterInitializationMode)
        BIND(t, fmi2ExitInitializationModeTYPE, fmi2ExitInitializationMode)
        BIND(t, fmi2SetRealTYPE, fmi2SetReal)
        BIND(t, fmi2GetRealTYPE, fmi2GetReal)
        BIND(t, fmi2TerminateTYPE, fmi2Terminate)
        BIND(t, fmi2FreeInstanceTYPE, fmi2FreeInstance)
        if (f->cs) {
            BIND(t, fmi2DoStepTYPE, fmi2DoStep)
        } else {
            BIND(t, fmi2EnterEventModeTYPE, fmi2EnterEventMode)
            BIND(t, fmi2NewDiscreteStatesTYPE, fmi2NewDiscreteStates)
            BIND(t, fmi2EnterContinuousTimeModeTYPE, fmi2EnterContinuousTimeMode)
            BIND(t, fmi2CompletedIntegratorStepTYPE, fmi2CompletedIntegratorStep)
            BIND(t, fmi2SetTimeTYPE, fmi2SetTime)
            BIND(t, fmi2SetContinuousStatesTYPE, fmi2SetContinuousStates)
            BIND(t, fmi2GetContinuousStatesTYPE, fmi2GetContinuousStates)
            BIND(t, fmi2GetDerivativesTYPE, fmi2GetDerivatives)
        }
    } else {
        Fmi3 *t = &f->f3;
        BIND(t, fmi3EnterInitializationModeTYPE, fmi3EnterInitializationMode)
        BIND(t, fmi3ExitInitializationModeTYPE, fmi3ExitInitializationMode)
        BIND(t, fmi3SetFloat64TYPE, fmi3SetFloat64)
        BIND(t, fmi3GetFloat64TYPE, fmi3GetFloat64)
        BIND(t, fmi3TerminateTYPE, fmi3Terminate)
        BIND(t, fmi3FreeInstanceTYPE, fmi3FreeInstance)
        if (f->cs) {
            BIND(t, fmi3InstantiateCoSimulationTYPE, fmi3InstantiateCoSimulation)
            BIND(t, fmi3DoStepTYPE, fmi3DoStep)
        } else {
            BIND(t, fmi3InstantiateModelExchangeTYPE, fmi3InstantiateModelExchange)
            BIND(t, fmi3EnterEventModeTYPE, fmi3EnterEventMode)
            BIND(t, fmi3UpdateDiscreteStatesTYPE, fmi3UpdateDiscreteStates)
            BIND(t, fmi3EnterContinuousTimeModeTYPE, fmi3EnterContinuousTimeMode)
            BIND(t, fmi3CompletedIntegratorStepTYPE, fmi3CompletedIntegratorStep)
            BIND(t, fmi3SetTimeTYPE, fmi3SetTime)
            BIND(t, fmi3SetContinuousStatesTYPE, fmi3SetContinuousStates)
            BIND(t, fmi3GetContinuousStatesTYPE, fmi3GetContinuousStates)
            BIND(t, fmi3GetContinuousStateDerivativesTYPE, fmi3GetContinuousStateDerivatives)
            BIND(t, fmi3GetNumberOfContinuousStatesTYPE, fmi3GetNumberOfContinuousStates)
        }
    }
    return 0;
}

static int get(Fmu *f, const unsigned vr[], size_t n, double v[])
{
    if (!f->fmi3) { CALL(f->f2.fmi2GetReal(f->instance, vr, n, v), "fmi2GetReal"); }
    else {
        fmi3ValueReference refs[N_OUT];
        for (size_t i = 0; i < n; i++) refs[i] = vr[i];
        CALL(f->f3.fmi3GetFloat64(f->instance, refs, n, v, n), "fmi3GetFloat64");
    }
    return 0;
}

static int set(Fmu *f, const unsigned vr[], size_t n, const double v[])
{
    if (!f->fmi3) { CALL(f->f2.fmi2SetReal(f->instance, vr, n, v), "fmi2SetReal"); }
    else {
        fmi3ValueReference refs[N_OUT];
        for (size_t i = 0; i < n; i++) refs[i] = vr[i];
        CALL(f->f3.fmi3SetFloat64(f->instance, refs, n, v, n), "fmi3SetFloat64");
    }
    return 0;
}

/* Instantiation and initialization; co-simulation sets the FMU's integrator tolerances there.
   Model exchange leaves initialization in event mode: the event iteration follows (event()). */
static int start(Fmu *f, const char *token, const unsigned tolerances[2])
{
    const double tight[2] = {TIGHT, TIGHT};
    if (!f->fmi3) {
        static fmi2CallbackFunctions callbacks = {log_fmi2, calloc, free, NULL, NULL};
        f->instance = f->f2.fmi2Instantiate("portable", f->cs ? fmi2CoSimulation : fmi2ModelExchange, token, "",
                                            &callbacks, fmi2False, fmi2False);
        if (!f->instance) { fprintf(stderr, "fmi2Instantiate failed\n"); return 1; }
        CALL(f->f2.fmi2SetupExperiment(f->instance, fmi2False, 0.0, 0.0, fmi2True, STOP_TIME), "fmi2SetupExperiment");
        CALL(f->f2.fmi2EnterInitializationMode(f->instance), "fmi2EnterInitializationMode");
        if (f->cs && set(f, tolerances, 2, tight)) return 1;
        CALL(f->f2.fmi2ExitInitializationMode(f->instance), "fmi2ExitInitializationMode");
    } else {
        f->instance = f->cs ? f->f3.fmi3InstantiateCoSimulation("portable", token, NULL, fmi3False, fmi3False,
                                                                fmi3False, fmi3False, NULL, 0, NULL, log_fmi3, NULL)
                            : f->f3.fmi3InstantiateModelExchange("portable", token, NULL, fmi3False, fmi3False,
                                                                 NULL, log_fmi3);
        if (!f->instance) {
            fprintf(stderr, "fmi3Instantiate%s failed\n", f->cs ? "CoSimulation" : "ModelExchange");
            return 1;
        }
        if (!f->cs) {
            size_t nx = 0;
            CALL(f->f3.fmi3GetNumberOfContinuousStates(f->instance, &nx), "fmi3GetNumberOfContinuousStates");
            if (nx != f->nx) {
                fprintf(stderr, "the FMU has %u continuous states, NX says %u\n", (unsigned)nx, (unsigned)f->nx);
                return 1;
            }
        }
        CALL(f->f3.fmi3EnterInitializationMode(f->instance, fmi3False, 0.0, 0.0, fmi3True, STOP_TIME),
             "fmi3EnterInitializationMode");
        if (f->cs && set(f, tolerances, 2, tight)) return 1;
        CALL(f->f3.fmi3ExitInitializationMode(f->instance), "fmi3ExitInitializationMode");
    }
    return 0;
}

static int do_step(Fmu *f, double t, double h)
{
    if (!f->fmi3) { CALL(f->f2.fmi2DoStep(f->instance, t, h, fmi2True), "fmi2DoStep"); }
    else {
        fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
        fmi3Float64 reached = t;
        CALL(f->f3.fmi3DoStep(f->instance, t, h, fmi3True, &event, &terminate, &early, &reached), "fmi3DoStep");
        if (terminate || early || fabs(reached - (t + h)) > 1e-9) {   /* the FMU's time resolution: 1 ns */
            fprintf(stderr, "fmi3DoStep from %.17g s: terminateSimulation %d, earlyReturn %d, reached %.17g s\n",
                    t, (int)terminate, (int)early, reached);
            return 1;
        }
    }
    return 0;
}

static int set_time(Fmu *f, double t)
{
    if (!f->fmi3) { CALL(f->f2.fmi2SetTime(f->instance, t), "fmi2SetTime"); }
    else { CALL(f->f3.fmi3SetTime(f->instance, t), "fmi3SetTime"); }
    return 0;
}

static int get_states(Fmu *f, double x[])
{
    if (!f->fmi3) { CALL(f->f2.fmi2GetContinuousStates(f->instance, x, f->nx), "fmi2GetContinuousStates"); }
    else { CALL(f->f3.fmi3GetContinuousStates(f->instance, x, f->nx), "fmi3GetContinuousStates"); }
    return 0;
}

/* Sets time and states, reads the derivatives there. */
static int derivatives(Fmu *f, double t, const double x[], double dx[])
{
    if (set_time(f, t)) return 1;
    if (!f->fmi3) {
        CALL(f->f2.fmi2SetContinuousStates(f->instance, x, f->nx), "fmi2SetContinuousStates");
        CALL(f->f2.fmi2GetDerivatives(f->instance, dx, f->nx), "fmi2GetDerivatives");
    } else {
        CALL(f->f3.fmi3SetContinuousStates(f->instance, x, f->nx), "fmi3SetContinuousStates");
        CALL(f->f3.fmi3GetContinuousStateDerivatives(f->instance, dx, f->nx), "fmi3GetContinuousStateDerivatives");
    }
    return 0;
}

/* The event iteration, from event mode to continuous-time mode; L2 is set first when `vr_l2`
   is given.  Then the states are read back into x: the FMU's start states after initialization;
   after the fault the same states (valuesOfContinuousStatesChanged is false for a re-assembly,
   which the host does not rely on). */
static int event(Fmu *f, const unsigned *vr_l2, double l2, double x[])
{
    int again = 1, rounds = 0;
    if (vr_l2 && set(f, vr_l2, 1, &l2)) return 1;
    while (again) {
        if (++rounds > 100) { fprintf(stderr, "the event iteration did not end after 100 rounds\n"); return 1; }
        if (!f->fmi3) {
            fmi2EventInfo info;
            memset(&info, 0, sizeof info);
            CALL(f->f2.fmi2NewDiscreteStates(f->instance, &info), "fmi2NewDiscreteStates");
            again = info.newDiscreteStatesNeeded;
            if (info.terminateSimulation) { fprintf(stderr, "fmi2NewDiscreteStates: terminateSimulation\n"); return 1; }
        } else {
            fmi3Boolean need = fmi3False, terminate = fmi3False, nominals = fmi3False, values = fmi3False,
                        timed = fmi3False;
            fmi3Float64 next = 0.0;
            CALL(f->f3.fmi3UpdateDiscreteStates(f->instance, &need, &terminate, &nominals, &values, &timed, &next),
                 "fmi3UpdateDiscreteStates");
            again = need;
            if (terminate) { fprintf(stderr, "fmi3UpdateDiscreteStates: terminateSimulation\n"); return 1; }
        }
    }
    if (!f->fmi3) { CALL(f->f2.fmi2EnterContinuousTimeMode(f->instance), "fmi2EnterContinuousTimeMode"); }
    else { CALL(f->f3.fmi3EnterContinuousTimeMode(f->instance), "fmi3EnterContinuousTimeMode"); }
    return get_states(f, x);
}

static int enter_event_mode(Fmu *f)
{
    if (!f->fmi3) { CALL(f->f2.fmi2EnterEventMode(f->instance), "fmi2EnterEventMode"); }
    else { CALL(f->f3.fmi3EnterEventMode(f->instance), "fmi3EnterEventMode"); }
    return 0;
}

/* The accepted point (t, x): set, then CompletedIntegratorStep there; an event the FMU asks for
   is iterated at once. */
static int complete(Fmu *f, double t, double x[])
{
    int enter = 0, terminate = 0;
    if (set_time(f, t)) return 1;
    if (!f->fmi3) {
        fmi2Boolean e = fmi2False, s = fmi2False;
        CALL(f->f2.fmi2SetContinuousStates(f->instance, x, f->nx), "fmi2SetContinuousStates");
        CALL(f->f2.fmi2CompletedIntegratorStep(f->instance, fmi2True, &e, &s), "fmi2CompletedIntegratorStep");
        enter = e, terminate = s;
    } else {
        fmi3Boolean e = fmi3False, s = fmi3False;
        CALL(f->f3.fmi3SetContinuousStates(f->instance, x, f->nx), "fmi3SetContinuousStates");
        CALL(f->f3.fmi3CompletedIntegratorStep(f->instance, fmi3True, &e, &s), "fmi3CompletedIntegratorStep");
        enter = e, terminate = s;
    }
    if (terminate) { fprintf(stderr, "CompletedIntegratorStep at %.17g s: terminateSimulation\n", t); return 1; }
    return enter ? enter_event_mode(f) || event(f, NULL, 0.0, x) : 0;
}

/* One classic Runge-Kutta step of h from (t, x). */
static int rk4(Fmu *f, double t, double h, double x[])
{
    double k[4][MAX_STATES], y[MAX_STATES];
    const double c[4] = {0.0, 0.5, 0.5, 1.0};
    for (int s = 0; s < 4; s++) {
        for (size_t i = 0; i < f->nx; i++) y[i] = s == 0 ? x[i] : x[i] + c[s] * h * k[s - 1][i];
        if (derivatives(f, t + c[s] * h, y, k[s])) return 1;
    }
    for (size_t i = 0; i < f->nx; i++) x[i] += h / 6.0 * (k[0][i] + 2.0 * k[1][i] + 2.0 * k[2][i] + k[3][i]);
    return 0;
}

static void finish(Fmu *f)
{
    if (!f->fmi3) {
        f->f2.fmi2Terminate(f->instance);
        f->f2.fmi2FreeInstance(f->instance);
    } else {
        f->f3.fmi3Terminate(f->instance);
        f->f3.fmi3FreeInstance(f->instance);
    }
}

/* -- Case 2 ------------------------------------------------------------------------------- */

static int run(Fmu *f, const unsigned out[N_OUT], FILE *csv)
{
    double v[N_OUT], x[MAX_STATES];
    if (!f->cs && event(f, NULL, 0.0, x)) return 1;      /* from initialization: event mode */
    for (int n = 0; n <= ROWS; n++) {
        if (get(f, out, N_OUT, v)) return 1;
        fprintf(csv, "%.2f", n * ROW_STEP);
        for (int i = 0; i < N_OUT; i++) fprintf(csv, ",%.17g", v[i]);
        fprintf(csv, "\n");
        if (n == ROWS) break;
        if (f->cs) {
            if (n == FAULT_ROW) {
                const double l2 = L2_AFTER;
                if (set(f, &out[N_OUT - 1], 1, &l2)) return 1;
            }
            if (do_step(f, n * ROW_STEP, ROW_STEP)) {
                fprintf(stderr, "the step from %.2f s failed\n", n * ROW_STEP);
                return 1;
            }
        } else {
            if (n == FAULT_ROW && (enter_event_mode(f) || event(f, &out[N_OUT - 1], L2_AFTER, x))) return 1;
            for (int s = 0; s < SUBSTEPS; s++) {
                const long k = (long)n * SUBSTEPS + s;
                const double t = k / ME_STEPS_PER_SECOND, h = 1.0 / ME_STEPS_PER_SECOND;
                if (rk4(f, t, h, x) || complete(f, (k + 1) / ME_STEPS_PER_SECOND, x)) {
                    fprintf(stderr, "the Runge-Kutta step from %.4f s failed\n", t);
                    return 1;
                }
            }
        }
    }
    return 0;
}

static int parse_unsigned(const char *text, const char *what, unsigned long limit, unsigned *value)
{
    char *end = NULL;
    unsigned long v = strtoul(text, &end, 10);
    if (!*text || *end || text[0] == '-' || v > limit) {
        fprintf(stderr, "%s must be a whole number from 0 to %lu (got '%s')\n", what, limit, text);
        return 1;
    }
    *value = (unsigned)v;
    return 0;
}

int main(int argc, char **argv)
{
    static const char *const modes[] = {"fmi2-cs", "fmi2-me", "fmi3-cs", "fmi3-me"};
    Fmu f;
    unsigned l2, tolerances[2], x2, nx, out[N_OUT];
    int mode = -1;
    memset(&f, 0, sizeof f);
    if (argc != 10) {
        fprintf(stderr, "usage: %s fmi2-cs|fmi2-me|fmi3-cs|fmi3-me LIBRARY TOKEN VR_L2 VR_RTOL VR_ATOL VR_X2 NX "
                "OUT.csv\n", argv[0]);
        return 2;
    }
    for (int i = 0; i < 4; i++)
        if (!strcmp(argv[1], modes[i])) mode = i;
    if (mode < 0) {
        fprintf(stderr, "MODE must be fmi2-cs, fmi2-me, fmi3-cs or fmi3-me (got '%s')\n", argv[1]);
        return 2;
    }
    f.fmi3 = mode >= 2;
    f.cs = mode % 2 == 0;
    if (parse_unsigned(argv[4], "VR_L2", 0xffffffffUL, &l2)
        || parse_unsigned(argv[5], "VR_RTOL", 0xffffffffUL, &tolerances[0])
        || parse_unsigned(argv[6], "VR_ATOL", 0xffffffffUL, &tolerances[1])
        || parse_unsigned(argv[7], "VR_X2", 0xffffffffUL - 6, &x2) || parse_unsigned(argv[8], "NX", MAX_STATES, &nx))
        return 2;
    if (f.cs != (nx == 0)) {
        fprintf(stderr, "NX must be 0 in co-simulation and the number of continuous states (1 to %d) in model "
                "exchange (got %u for %s)\n", MAX_STATES, nx, argv[1]);
        return 2;
    }
    f.nx = nx;
    for (int i = 0; i < 6; i++) out[i] = x2 + (unsigned)i;
    out[6] = l2;
    if (load_library(&f, argv[2]) || start(&f, argv[3], tolerances)) return 1;
    FILE *csv = fopen(argv[9], "w");
    if (!csv) { fprintf(stderr, "cannot write %s\n", argv[9]); return 1; }
    fprintf(csv, "time,x2,y2,x3,y3,x4,y4,L2\n");
    const int status = run(&f, out, csv);
    fclose(csv);
    if (status) return 1;
    finish(&f);
    printf("ok\n");
    return 0;
}
