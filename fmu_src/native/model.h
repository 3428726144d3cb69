/* The four-bar model behind the generic FMI 2.0 layer (fmi2Functions.c).
 *
 * Everything an instance owns lives in one ModelInstance; everything that changes while it
 * runs lives in its ModelState, a plain struct without pointers, so fmi2GetFMUstate and
 * fmi2SetFMUstate are copies and serialization is the bytes of that struct.  No globals.
 */
#ifndef MODEL_H
#define MODEL_H

#include <stddef.h>
#include "fmi2Functions.h"
#include "fourbar_equations.h"
#include "fourbar_variables.h"
#include "rk.h"

typedef enum {
    MODE_INSTANTIATED = 1, MODE_INITIALIZATION = 2, MODE_STEP_COMPLETE = 4,
    MODE_STEP_FAILED = 8, MODE_TERMINATED = 16, MODE_ERROR = 32
} ModelMode;

typedef struct {
    ModelMode mode;
    double values[FB_N_VARIABLES];     /* Real variables by value reference: set values and outputs */
    int integrator;                    /* index of FB_INTEGRATOR_NAMES */
    double start_time, stop_time;      /* stop_time = INFINITY when not defined */
    /* The DAE (valid from fmi2ExitInitializationMode on). */
    double p[FB_N_PARAMETERS];         /* parameters in use: (L1, L2, L3, L4, m2, m3, m4, g) */
    double branch;                     /* assembly branch, +1 or -1 */
    double t;                          /* model time, on the 1 ns grid */
    double q[FB_N_COORDINATES], qd[FB_N_COORDINATES];
    RKSolver solver;
    unsigned long rhs_evaluations;
    unsigned long starts;
    int rhs_failed;                    /* set by the right-hand side, with message below */
    char rhs_message[512];
} ModelState;

typedef struct {
    const fmi2CallbackFunctions *functions;
    fmi2ComponentEnvironment environment;
    char *instance_name;
    int logging_on;
    ModelState state;
} ModelInstance;

/* Logging through the host's callback (defined in fmi2Functions.c); `status` is an fmi2Status. */
void model_log(ModelInstance *m, fmi2Status status, const char *category, const char *fmt, ...);

void model_reset(ModelInstance *m);                       /* start values, mode instantiated */
fmi2Status model_initialize(ModelInstance *m);            /* check, assemble, start (exit init mode) */
fmi2Status model_do_step(ModelInstance *m, double current_time, double step);
void model_preview_outputs(ModelInstance *m);             /* outputs from the start values (init mode) */

#endif
