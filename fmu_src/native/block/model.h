/* A component's model behind the mechanisms' FMI layers: the interface of ../model.h.
 *
 * A block file's model (fmu_src/block/) behind the same FMI layers as the mechanisms' (fmi2Functions.c, fmi3/fmi3Functions.c, fmi_layer.c): this header declares what
 * fmu_src/native/model.h declares, so the layers compile against either; block.c implements it.
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

#define MODEL_MESSAGE 512   /* longest message of one failure */

typedef enum { MODEL_OK = 0, MODEL_WARNING = 1, MODEL_DISCARD = 2, MODEL_ERROR = 3, MODEL_FATAL = 4 } ModelStatus;

/* The FMI state machines' states (as model.h's). */
typedef enum {
    MODE_INSTANTIATED = 1, MODE_INITIALIZATION = 2, MODE_STEP_COMPLETE = 4,
    MODE_STEP_FAILED = 8, MODE_TERMINATED = 16, MODE_ERROR = 32,
    MODE_EVENT = 128, MODE_CONTINUOUS = 256
} ModelMode;

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

typedef struct {
    int model_exchange;                 /* instantiated for model exchange (else co-simulation) */
    const void *host;                   /* the host's callbacks, as the FMI layer keeps them */
    void *environment;                  /* the host's environment pointer, passed back to its logger */
    char *instance_name;
    int logging_on;
    ModelState state;
} ModelInstance;

/* An FMU state (fmi2GetFMUstate, fmi3GetFMUState): a copy of the ModelState and the type of the
   instance that saved it (an instance of the other type refuses it). */
typedef struct {
    ModelState state;
    int model_exchange;
} SavedState;
/* Its serialized form, shared by the FMI layers: a header (`magic`, which tells the layers' states
   apart, the ModelState's size, the build's GUID, the type), then the ModelState's bytes.
   model_deserialize: 0 (*saved filled), or MODEL_WRONG_SIZE when `size` is not
   model_serialized_size(), MODEL_NOT_OURS when the bytes are not a state of this build and layer,
   or MODEL_INVALID when a field of the state cannot be used (model_check_state: why in `why`, n
   bytes); *saved is then unchanged. */
enum { MODEL_WRONG_SIZE = 1, MODEL_NOT_OURS = 2, MODEL_INVALID = 3 };
size_t model_serialized_size(void);
void model_serialize(const SavedState *saved, const char magic[8], unsigned char *bytes);
int model_deserialize(const unsigned char *bytes, size_t size, const char magic[8], SavedState *saved, char *why,
                      size_t n);
/* 0 when a ModelState from outside can be used by an instance of its type (model_exchange 0 or 1):
   a mode of that type's state machine, indices in range (integrator, the partition: a permutation
   of the coordinates), enumerations and flags of their values, the numbers the model computes from
   finite, the message terminated.  Else 1 with the first problem in `why` (n bytes). */
int model_check_state(const ModelState *s, int model_exchange, char *why, size_t n);

/* Logging through the host's callback, and memory (the host's, when it gives its allocator): defined
   by the FMI layer. */
void model_log(ModelInstance *m, ModelStatus status, const char *category, const char *fmt, ...);
void *model_allocate(const ModelInstance *m, size_t size);
void model_release(const ModelInstance *m, void *p);

/* A failure logged with the model's and the instance's names ("<name> '<instance>': ..."); returns
   MODEL_ERROR (model_checks.c, as the rest below). */
ModelStatus model_fail(ModelInstance *m, const char *fmt, ...);
/* v as Python's repr writes it, in buf (n bytes). */
const char *model_real_text(char *buf, size_t n, double v);
/* t on the FMU's 1 ns grid (round half to even, as Python's round()). */
double model_snap_time(double t);
void model_reset(ModelInstance *m);                       /* start values, mode instantiated */
ModelStatus model_initialize(ModelInstance *m);            /* check, assemble, start (exit init mode) */
ModelStatus model_do_step(ModelInstance *m, double current_time, double step);
/* 1, after logging why, when a step from current_time goes past a stop time the host defined
   (FMI 2.0 and 3.0: the FMU has to return an error), on the 1 ns grid the FMU's times live on. */
int model_past_stop_time(ModelInstance *m, const char *function, double current_time, double step);
/* 1, after logging why, when a communication step cannot be taken as given (FMI 2.0 and 3.0: the
   FMU returns an error): a current time, a step size or their sum that is not finite, a step
   size that is not positive, or one too small to advance the time on the FMU's 1 ns grid (the
   step would end where it starts). */
int model_bad_step(ModelInstance *m, const char *function, double current_time, double step);
/* 1, after logging why, when value[i] set to vr[i] (a Real parameter) is not finite: a setter
   refuses it changing nothing (naming the variable). */
int model_non_finite_values(ModelInstance *m, const char *function, const unsigned int *vr, const double *value,
                            size_t n);
/* 1, after logging why, when a continuous state the host sets (Model Exchange) is not finite. */
int model_non_finite_states(ModelInstance *m, const char *function, const double *x, size_t n);
/* Model Exchange (block.c): the states (FMU_N_STATES values, value references FMU_STATE_VRS), set and
   evaluated lazily; the derivatives; an accepted integrator step; an event's parameter changes
   (re-assembly keeping the states).  MODEL_ERROR after logging why. */
void model_me_get_states(ModelInstance *m, double *x);
void model_me_set_time(ModelInstance *m, double t);
void model_me_set_states(ModelInstance *m, const double *x);
ModelStatus model_me_derivatives(ModelInstance *m, double *dx);
ModelStatus model_me_completed_step(ModelInstance *m);
ModelStatus model_me_event_update(ModelInstance *m);
/* Model Exchange's directional derivatives (fmi2GetDirectionalDerivative, fmi3GetDirectionalDerivative):
   sensitivity_i = sum_j d unknown_i / d known_j seed_j at the current state (in initialization
   mode, the state the start values give), the knowns being the
   continuous states and the inputs, the unknowns the states' derivatives or outputs
   (exact: the generated Jacobians).  A layer starts a Directional with
   model_me_directional_start, adds each known's seed (model_me_seed), computes
   (model_me_directional) and reads each unknown (model_me_sensitivity); a value reference of the
   wrong kind is MODEL_ERROR, logged naming the variable and the function. */
typedef struct {
    double dy[RK_N], df[RK_N], dout[BLOCK_N_OUTPUTS];
    double du[BLOCK_ALLOC(MECH_N_INPUTS)];       /* the inputs' seeds */
} Directional;
void model_me_directional_start(Directional *d);
ModelStatus model_me_seed(ModelInstance *m, const char *function, Directional *d, unsigned long vr, double seed);
ModelStatus model_me_directional(ModelInstance *m, Directional *d);
ModelStatus model_me_sensitivity(ModelInstance *m, const char *function, const Directional *d, unsigned long vr,
                                 double *value);
/* Outputs into values[] before fmi2GetReal reads them: in initialization mode all those the start
   values give; afterwards the groups (FMU_GROUP_* bits) of `groups` that outputs_pending says are
   not yet the current state's (each fmi2DoStep only marks them all pending: a host that reads one
   output pays for its group only).  A failure (forces) is logged and leaves its group pending. */
void model_preview_outputs(ModelInstance *m, int groups);
/* In co-simulation, after the start: a read of at most MODEL_FEW_OUTPUTS value references whose
   pending groups (`groups`: FMU_GROUP_* bits read and pending) are the state's alone computes just
   those outputs (model_output_one, for each), the group left pending; 1 when that applies. */
#define MODEL_FEW_OUTPUTS 4
int model_few_outputs(const ModelInstance *m, int groups, size_t nvr);
void model_output_one(ModelInstance *m, unsigned long vr);
/* The host set the inputs vr[] (their values are in values[]): model exchange evaluates the
   derivatives and outputs with them at once; co-simulation applies them at the next step. */
void model_inputs_set(ModelInstance *m, const unsigned int *vr, size_t nvr);
/* Co-simulation: derivatives of order 1 or 2 of inputs (fmi2SetRealInputDerivatives), applied over
   the next steps as u + u' (t - t0) + u'' (t - t0)^2 / 2 from each step's start t0; MODEL_ERROR,
   logged, for a value reference that is not an input or another order (nothing set). */
ModelStatus model_set_input_derivatives(ModelInstance *m, const char *function, const unsigned int *vr, size_t nvr,
                                        const int *order, const double *value);

#endif
