/* A mechanism's model behind the generic FMI layers (fmi2Functions.c for FMI 2.0; an FMI 3.0
 * layer compiles against the same interface).  Nothing here depends on the FMI version: the
 * statuses are ModelStatus (numbered as ModelStatus and fmi3Status are), and the host's
 * callbacks are the layer's business (ModelInstance.host; model_log is defined by the layer).
 *
 * Everything an instance owns lives in one ModelInstance; everything that changes while it
 * runs lives in its ModelState, a plain struct without pointers, so fmi2GetFMUstate and
 * fmi2SetFMUstate are copies and serialization is the bytes of that struct.  No globals.
 * The sizes come from the generated equations.h (the mechanism) and variables.h (the FMU's
 * variables); the numerics that fill the DAE part are in dae.c.  The functions the layers call are
 * declared in model_api.h, the same for a component's model (block/model.h).
 */
#ifndef MODEL_H
#define MODEL_H

#include <stddef.h>
#include "equations.h"
#include "variables.h"
#include "rk.h"
#include "model_types.h"

/* One consistent state of the mechanism and its accelerations: a Newton-Raphson predictor's base,
   with the sign of the determinant of its dependent block of Phi_q (its assembly branch). */
typedef struct {
    double t;
    double q[MECH_N], qd[MECH_N], qdd[MECH_N];
    double tr[MECH_ALLOC(MECH_N_TRIG)];          /* cos and sin of q's angles (eq_trig) */
    int sign;
} DaePoint;

typedef struct {
    ModelMode mode;
    double values[FMU_N_VARIABLES];     /* Real variables by value reference: set values and outputs */
    int integrator;                    /* index of FMU_INTEGRATOR_NAMES */
    int outputs_pending;               /* the output groups (FMU_GROUP_*) not yet computed for the current state */
    double start_time, stop_time;      /* stop_time = INFINITY when not defined */
    /* The DAE (valid from fmi2ExitInitializationMode on; dae.c). */
    double p[MECH_ALLOC(MECH_N_PARAMETERS)];    /* parameters in use, in equations.h's order */
    double d[MECH_ALLOC(3 * MECH_N_DRIVERS)];   /* per driver (s_ref, t_ref, v) */
    int independent[MECH_ALLOC(MECH_K)];        /* the partition of q, each in increasing order */
    int dependent[MECH_ALLOC(MECH_M)];
    double t;                                   /* model time, on the 1 ns grid */
    double q[MECH_N], qd[MECH_N];               /* consistent: Phi(q, t) = 0, Phi_q qd = nu */
    double tr[MECH_ALLOC(MECH_N_TRIG)];          /* cos and sin of q's angles (eq_trig's, to round-off): dae.c sets
                                                   them with q */
    double work[MECH_ALLOC(MECH_N_WORKS)];      /* each work output since the start, J (equations.h) */
    int declared;                               /* the partition's dependent coordinates are the file's */
    double length_scale;                        /* the velocity ratio's length, m (dae.c: set at assembly) */
    double mass[MECH_N], minv[MECH_N];          /* diagonal of M and its inverse for p (MECH_MASS_IS_CONSTANT) */
    DaePoint base;                              /* the predictor's base: the last accepted step's end */
    DaePoint before;                            /* the accepted step's start (t NaN after a (re)start) */
    DaePoint last;                              /* the last right-hand-side evaluation */
    double last_step;                           /* the last communication step, s */
    RKSolver solver;
    unsigned long rhs_evaluations;
    unsigned long starts;                       /* integrator (re)starts */
    unsigned long repartitions;
    unsigned long newton_iterations;
    unsigned long continuations;                /* trial points reached by continuation from the base */
    unsigned long failed_evaluations;           /* trial points not reached: the step was rejected */
    unsigned long full_evaluations;             /* right-hand sides not served by the reduced system (dae.c) */
    unsigned long most_step_evaluations;        /* the most right-hand-side evaluations of one doStep */
    unsigned long evaluation_limit;             /* during dae_advance: rhs_evaluations may not pass it (0: none) */
    int rhs_failed;                             /* DAE_ASSEMBLY or DAE_INTEGRATION (dae.h), with: */
    char rhs_message[MODEL_MESSAGE];
    /* Model Exchange: the states the host set (at time t) and, when me_fresh, the current state is
       their evaluation (dae_me_evaluate) and me_f its derivatives. */
    double me_t, me_y[RK_N], me_f[RK_N];
    int me_fresh;
    /* Co-simulation inputs over a step (dae.c's inputs_at): from input_t0, the step's start, input k is
       input_poly[k][0] + input_poly[k][1] (t - t0) + input_poly[k][2] (t - t0)^2 / 2 when interpolating, else
       held; input_der: the derivatives of order 1 and 2 the host set (fmi2SetRealInputDerivatives). */
    double input_poly[MECH_ALLOC(MECH_N_INPUTS)][3];
    double input_der[MECH_ALLOC(MECH_N_INPUTS)][2];
    double input_t0;
    int interpolating;
} ModelState;

/* The sizes of a Directional (model_api.h). */
#define MODEL_N_OUTPUTS MECH_N_OUTPUTS
#define MODEL_INPUTS_ALLOC MECH_ALLOC(MECH_N_INPUTS)
#include "model_api.h"

#endif
