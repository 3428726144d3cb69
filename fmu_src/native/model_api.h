/* The interface the FMI layers (fmi2Functions.c, fmi3/fmi3Functions.c, fmi_layer.c) call, one for
 * every model behind them: a mechanism's (model.h: model.c, dae.c) and a component's (block/model.h:
 * block/block.c).  The including model.h defines ModelState first (with model_types.h), and
 * MODEL_N_OUTPUTS and MODEL_INPUTS_ALLOC (the sizes of a Directional's outputs and inputs); the
 * checks and messages every model shares are in model_checks.c, FMU-state bytes in saved_state.c.
 */
#ifndef MODEL_API_H
#define MODEL_API_H

#include <stddef.h>

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
   a mode of that type's state machine, indices in range (integrator; a mechanism's partition: a
   permutation of the coordinates), enumerations and flags of their values, the numbers the model computes from
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
/* Every problem with the set parameter values (positive, finite, within their bounds), "; "-separated
   in out (n bytes), as slave.py's _problem words them; 0 when none. */
int model_check_parameters(const ModelState *s, char *out, size_t n);
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
/* Model Exchange (model.c with dae.c, or block/block.c): the states (FMU_N_STATES values, value
   references FMU_STATE_VRS), set and evaluated lazily; the derivatives; an accepted integrator step; an event's parameter changes
   (a mechanism re-assembles keeping the states).  MODEL_ERROR after logging why. */
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
   (exact, from the generated derivatives: dae_directional, or a block's Jacobians).  A layer starts a Directional with
   model_me_directional_start, adds each known's seed (model_me_seed), computes
   (model_me_directional) and reads each unknown (model_me_sensitivity); a value reference of the
   wrong kind is MODEL_ERROR, logged naming the variable and the function. */
typedef struct {
    double dy[RK_N], df[RK_N], dout[MODEL_N_OUTPUTS];
    double du[MODEL_INPUTS_ALLOC];               /* the inputs' seeds */
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
