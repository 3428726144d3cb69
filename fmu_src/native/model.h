/* A mechanism's model behind the generic FMI layers (fmi2Functions.c for FMI 2.0; an FMI 3.0
 * layer compiles against the same interface).  Nothing here depends on the FMI version: the
 * statuses are ModelStatus (numbered as ModelStatus and fmi3Status are), and the host's
 * callbacks are the layer's business (ModelInstance.host; model_log is defined by the layer).
 *
 * Everything an instance owns lives in one ModelInstance; everything that changes while it
 * runs lives in its ModelState, a plain struct without pointers, so fmi2GetFMUstate and
 * fmi2SetFMUstate are copies and serialization is the bytes of that struct.  No globals.
 * The sizes come from the generated equations.h (the mechanism) and variables.h (the FMU's
 * variables); the numerics that fill the DAE part are in dae.c.
 */
#ifndef MODEL_H
#define MODEL_H

#include <stddef.h>
#include "equations.h"
#include "variables.h"
#include "rk.h"

#define MODEL_MESSAGE 512   /* longest message of one failure */

/* What the model's functions return and log: the values of ModelStatus and fmi3Status. */
typedef enum { MODEL_OK = 0, MODEL_WARNING = 1, MODEL_DISCARD = 2, MODEL_ERROR = 3, MODEL_FATAL = 4 } ModelStatus;

/* Co-simulation: instantiated, initialization, stepComplete (stepFailed is never entered), terminated,
   error; Model Exchange: instantiated, initialization, eventMode, continuousTimeMode, terminated, error. */
typedef enum {
    MODE_INSTANTIATED = 1, MODE_INITIALIZATION = 2, MODE_STEP_COMPLETE = 4,
    MODE_STEP_FAILED = 8, MODE_TERMINATED = 16, MODE_ERROR = 32,
    MODE_EVENT = 128, MODE_CONTINUOUS = 256
} ModelMode;

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
/* Model Exchange (dae.h): the states (FMU_N_STATES values, value references FMU_STATE_VRS), set and
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
   (dae_directional: exact, from the generated derivatives).  A layer starts a Directional with
   model_me_directional_start, adds each known's seed (model_me_seed), computes
   (model_me_directional) and reads each unknown (model_me_sensitivity); a value reference of the
   wrong kind is MODEL_ERROR, logged naming the variable and the function. */
typedef struct {
    double dy[RK_N], df[RK_N], dout[MECH_N_OUTPUTS];
    double du[MECH_ALLOC(MECH_N_INPUTS)];        /* the inputs' seeds */
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
