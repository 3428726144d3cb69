/* What the two FMI layers (fmi2Functions.c, fmi3/fmi3Functions.c) share: the FMI state machines as
 * one table of the calls allowed per state, and the work of every call both standards define alike
 * (argument checks, variable access, the FMU-state functions, a co-simulation step, the model-exchange
 * calls).  Each flavour is described once (an FmiLayer: the states it names, its types' names) and
 * each entry point is then one check against the table (ENTER), its argument checks and one call
 * here.  Messages name the calling function (__func__), so each layer's
 * messages are its own standard's; what else differs between them is their FmiLayer (fmi_layer.c).
 *
 * The table (fmi_layer.c, FMI_CALLS) has a row per call and a column per FMI version: the states
 * (ModelMode bits) the call is allowed in, as the Reference-FMUs' masks, and the instance type it
 * belongs to.  An instance is in the states of its type only.
 */
#ifndef FMI_LAYER_H
#define FMI_LAYER_H

#include <stddef.h>
#include "model.h"

/* The states no instance of this FMU enters, named because calls are defined for them only:
   a synchronous doStep (FMI 2.0's stepInProgress; FMI 3.0's stepDiscarded: it never discards),
   no structural parameters (configurationMode, reconfigurationMode), no intermediate update and
   no clocks (intermediateUpdateMode, clockActivationMode).  FMI 2.0's stepFailed is
   MODE_STEP_FAILED (model.h); FMI 3.0's stepMode is MODE_STEP_COMPLETE. */
enum {
    MODE_STEP_IN_PROGRESS = 64, MODE_CONFIGURATION = 512, MODE_RECONFIGURATION = 1024,
    MODE_INTERMEDIATE_UPDATE = 2048, MODE_CLOCK_ACTIVATION = 4096, MODE_STEP_DISCARDED = 8192
};

/* The rows of the table: one per call, or per group of calls with the same rule. */
typedef enum {
    CALL_ANY_STATE,              /* SetDebugLogging, Reset, the FMU-state bookkeeping */
    CALL_NOT_IN_ERROR,           /* GetFMUState, FMI 3.0's dependencies and EvaluateDiscreteStates */
    CALL_ENTER_INITIALIZATION,   /* also fmi2SetupExperiment */
    CALL_EXIT_INITIALIZATION,
    CALL_TERMINATE,
    CALL_GET,                    /* the getters of variables */
    CALL_GET_DEFINED,            /* FMI 3.0's clock getters, directional and adjoint derivatives */
    CALL_SET,                    /* the setters of variables (parameters: not in continuousTimeMode) */
    CALL_SET_REAL,               /* fmi2SetReal, fmi3SetFloat64: also inputs, in continuousTimeMode too */
    CALL_ENTER_CONFIGURATION,
    CALL_EXIT_CONFIGURATION,
    CALL_ACTIVATE_PARTITION,
    CALL_DO_STEP,
    CALL_CANCEL_STEP,
    CALL_GET_STATUS,
    CALL_INPUT_DERIVATIVES,
    CALL_OUTPUT_DERIVATIVES,
    CALL_ENTER_STEP_MODE,
    CALL_ENTER_EVENT_MODE,
    CALL_UPDATE_DISCRETE_STATES,
    CALL_ENTER_CONTINUOUS_TIME,
    CALL_COMPLETED_STEP,
    CALL_SET_TIME,
    CALL_SET_STATES,
    CALL_GET_DERIVATIVES,
    CALL_GET_STATES,             /* continuous states and event indicators */
    CALL_GET_NOMINALS,
    CALL_GET_NUMBER_OF,          /* FMI 3.0's structural numbers */
    FMI_N_CALLS
} FmiCall;

/* A state's name in a layer's messages. */
typedef struct {
    int mode;
    const char *name;
} FmiState;

/* What differs between the layers' messages. */
typedef struct {
    int column;                      /* the table's column: 0 FMI 2.0, 1 FMI 3.0 */
    const char *prefix;              /* "fmi2", "fmi3" */
    const FmiState *states;          /* the standard's states, in the order messages list them */
    size_t n_states;
    const char *after_error;         /* appended to a call refused in the error state */
    const char *real;                /* the Real type's name: "Real", "Float64" */
    const char *const *kind_text;    /* per variable kind (and FMI 3.0's time), what it is */
    const char *count_expected;      /* "this FMU has", "expected" */
    const char *token;               /* "GUID", "instantiation token" */
    int has_time;                    /* the independent variable time is value reference FMU_N_VARIABLES */
    const char *magic;               /* the mark of the layer's serialized FMU states (8 bytes) */
} FmiLayer;
/* The two flavours (fmi_layer.c): each layer names its own as LAYER. */
extern const FmiLayer FMI2_LAYER, FMI3_LAYER;

/* 1 when `function` may be called in the instance's state and is of its type (the table's row
   `call`); else logs why and returns 0.  A NULL instance gives 0 without a message. */
int fmi_allowed(ModelInstance *m, const FmiLayer *layer, FmiCall call, const char *function);
/* 1 when `p` is not NULL; else logs which argument is missing (n: an array's length, 0 for one). */
int fmi_present(ModelInstance *m, const char *function, const void *p, const char *name, size_t n);
/* 1 when n == expected; else logs how many `what` were given. */
int fmi_count_is(ModelInstance *m, const FmiLayer *layer, const char *function, size_t n, size_t expected,
                 const char *what);
const char *fmi_type_name(int model_exchange);

/* The first statement of every entry point: names the instance `m` (from the layer's LAYER_INSTANCE
   argument) and returns LAYER_ERROR when it is NULL or the table does not allow the call. */
#define ENTER(call) \
    ModelInstance *const m = (ModelInstance *)LAYER_INSTANCE; \
    if (!fmi_allowed(m, &LAYER, (call), __func__)) return LAYER_ERROR
#define REQUIRE(p) if (!fmi_present(m, __func__, (const void *)(p), #p, 0)) return LAYER_ERROR
#define REQUIRE_ARRAY(p, n) if ((n) > 0 && !fmi_present(m, __func__, (const void *)(p), #p, (n))) return LAYER_ERROR

/* Instantiation: `probe` is the instance being made, its host's callbacks set (its name may be
   NULL).  fmi_named: 1 when the name is not empty, else logs it.  fmi_create: a new instance of
   `size` bytes (a ModelInstance first: the layer's struct around it), the probe's host, a copy of
   its name, start values; NULL after logging why (a token of another build, out of memory).
   fmi_free_instance: frees it (NULL is ignored). */
int fmi_named(ModelInstance *probe, const char *function);
ModelInstance *fmi_create(ModelInstance *probe, const FmiLayer *layer, const char *function, const char *token,
                          size_t size, int logging_on, int model_exchange);
void fmi_free_instance(ModelInstance *m);

/* The calls' work, after ENTER and REQUIRE: each returns MODEL_OK, or MODEL_ERROR (MODEL_DISCARD)
   after logging why, numbered as both standards' statuses. */
ModelStatus fmi_set_debug_logging(ModelInstance *m, const char *function, int logging_on, size_t n,
                                  const char *const categories[]);
ModelStatus fmi_setup_experiment(ModelInstance *m, const char *function, double start, int stop_defined,
                                 double stop);
ModelStatus fmi_exit_initialization(ModelInstance *m);
ModelStatus fmi_terminate(ModelInstance *m);
ModelStatus fmi_get_float64(ModelInstance *m, const FmiLayer *layer, const char *function, const unsigned int vr[],
                            size_t nvr, double value[]);
ModelStatus fmi_set_float64(ModelInstance *m, const FmiLayer *layer, const char *function, const unsigned int vr[],
                            size_t nvr, const double value[]);
ModelStatus fmi_get_string(ModelInstance *m, const FmiLayer *layer, const char *function, const unsigned int vr[],
                           size_t nvr, const char *value[]);
ModelStatus fmi_set_string(ModelInstance *m, const FmiLayer *layer, const char *function, const unsigned int vr[],
                           size_t nvr, const char *const value[]);
/* A type the FMU has no variables of (`type` NULL: "of that type"): every value reference is unknown. */
ModelStatus fmi_no_variables(ModelInstance *m, const char *function, const unsigned int vr[], size_t nvr,
                             const char *type);
ModelStatus fmi_get_fmu_state(ModelInstance *m, const char *function, void **state);
ModelStatus fmi_set_fmu_state(ModelInstance *m, const char *function, const void *state);
ModelStatus fmi_free_fmu_state(ModelInstance *m, void **state);
ModelStatus fmi_serialized_size(size_t *size);
ModelStatus fmi_serialize(ModelInstance *m, const FmiLayer *layer, const char *function, const void *state,
                          unsigned char *bytes, size_t size);
ModelStatus fmi_deserialize(ModelInstance *m, const FmiLayer *layer, const char *function,
                            const unsigned char *bytes, size_t size, void **state);
ModelStatus fmi_directional(ModelInstance *m, const char *function, const unsigned int unknowns[], size_t n_unknowns,
                            const unsigned int knowns[], size_t n_knowns, const double seed[], double sensitivity[]);
/* A co-simulation step; a bad step, one past the stop time or a failed one leaves the error state. */
ModelStatus fmi_do_step(ModelInstance *m, const char *function, double current_time, double step);
/* Model exchange: each failed evaluation leaves the error state. */
ModelStatus fmi_update_discrete_states(ModelInstance *m);
ModelStatus fmi_enter_continuous_time(ModelInstance *m);
ModelStatus fmi_completed_step(ModelInstance *m);
ModelStatus fmi_set_time(ModelInstance *m, const char *function, double time);
ModelStatus fmi_set_states(ModelInstance *m, const FmiLayer *layer, const char *function, const double x[], size_t nx);
/* The states (derivatives: FMU_DERIVATIVE_VRS) or their derivatives; in initialization mode the
   values the start values give (model_preview_outputs). */
ModelStatus fmi_get_states(ModelInstance *m, const FmiLayer *layer, const char *function, double x[], size_t nx);
ModelStatus fmi_get_derivatives(ModelInstance *m, const FmiLayer *layer, const char *function, double dx[],
                                size_t nx);
ModelStatus fmi_get_nominals(ModelInstance *m, const FmiLayer *layer, const char *function, double x[], size_t nx);

#endif
