/* A component's model behind the mechanisms' FMI layers: the interface of ../model.h.
 *
 * A block file's model (fmu_src/block/) behind the same FMI layers as the mechanisms'
 * (fmi2Functions.c, fmi3/fmi3Functions.c, fmi_layer.c): this header defines the block's ModelState
 * and, as ../model.h does, includes model_types.h and model_api.h, so the layers compile against
 * either; block.c implements the interface.
 * The model: states x integrated within a co-simulation step by rk.c (restarted at each step),
 * inputs u held or, with input derivatives, a polynomial over the step; outputs y(p, u, x) and
 * derivatives f(p, u, x) with their exact Jacobians from the generated equations.c.
 *
 * As the mechanisms': everything that changes while an instance runs lives in ModelState, a plain
 * struct without pointers (FMU state get/set are copies, serialization its bytes).  No globals.
 */
#ifndef MODEL_H
#define MODEL_H

#include <stddef.h>
#include "equations.h"
#include "variables.h"
#include "rk.h"
#include "model_types.h"

typedef struct {
    ModelMode mode;
    double values[FMU_N_VARIABLES];     /* Real variables by value reference: set values and outputs */
    int integrator;                    /* index of FMU_INTEGRATOR_NAMES */
    int outputs_pending;               /* output groups (FMU_GROUP_*) not yet computed for the current state */
    double start_time, stop_time;      /* stop_time = INFINITY when not defined */
    double t;                          /* co-simulation: the model time */
    double x[RK_N];                    /* co-simulation: the states at t */
    double u_now[BLOCK_ALLOC(MECH_N_INPUTS)];   /* co-simulation: the inputs at t (set, or interpolated) */
    RKSolver solver;
    /* Co-simulation inputs over a step from input_t0: input_poly[k][0] + [1] (t - t0) + [2] (t - t0)^2 / 2;
       input_der: the derivatives of order 1 and 2 the host set (fmi2SetRealInputDerivatives). */
    double input_poly[BLOCK_ALLOC(MECH_N_INPUTS)][3];
    double input_der[BLOCK_ALLOC(MECH_N_INPUTS)][2];
    double input_t0;
    /* Model Exchange: the time and states the host set. */
    double me_t, me_y[RK_N];
    /* The integration's statistics (fmi_terminate logs them; a block has no DAE: most stay 0). */
    unsigned long rhs_evaluations, full_evaluations, continuations, failed_evaluations, newton_iterations, starts,
        repartitions, most_step_evaluations;
} ModelState;

/* The sizes of a Directional (model_api.h). */
#define MODEL_N_OUTPUTS BLOCK_N_OUTPUTS
#define MODEL_INPUTS_ALLOC BLOCK_ALLOC(MECH_N_INPUTS)
#include "model_api.h"

#endif
