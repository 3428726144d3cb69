/* What both FMI layers do alike (fmi_layer.h): the state table and the calls' shared work. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi_layer.h"

static const int KINDS[FMU_N_VARIABLES] = FMU_VARIABLE_KINDS;
static const char *const NAMES[FMU_N_VARIABLES] = FMU_VARIABLE_NAMES;
static const char *const INTEGRATORS[FMU_N_INTEGRATORS] = FMU_INTEGRATOR_NAMES;
static const int READ_COMPUTED[FMU_N_VARIABLES] = FMU_READ_COMPUTED;
static const int STATE_VRS[] = FMU_STATE_VRS;
static const int DERIVATIVE_VRS[] = FMU_DERIVATIVE_VRS;
enum { KIND_TUNABLE = 0, KIND_FIXED = 1, KIND_STRING = 2, KIND_OUTPUT = 3, KIND_LOCAL = 4, KIND_TIME = 5,
       KIND_INPUT = 6 };
#define KIND(k) (1 << (k))

/* -- the FMI state machines ------------------------------------------------------------ */

/* FMI 2.0 (sections 3.2.3 and 4.2.4, as the Reference-FMUs, except that no value can be read in
   the error state).  fmi2DoStep is synchronous: stepInProgress is never entered, named because
   fmi2CancelStep and the status inquiries are defined for it.  The state fatal is never entered
   either: the FMU shares nothing between instances and never returns fmi2Fatal. */
#define FMI2_ALL (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_STEP_FAILED | \
                  MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED | MODE_ERROR)
#define FMI2_INITIALIZED (MODE_STEP_COMPLETE | MODE_STEP_FAILED | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)
#define FMI2_READABLE (MODE_INITIALIZATION | FMI2_INITIALIZED)                       /* fmi2GetXXX */
#define FMI2_STATUS (MODE_STEP_COMPLETE | MODE_STEP_IN_PROGRESS | MODE_STEP_FAILED | MODE_TERMINATED)
/* FMI 3.0 (sections 3.2 and 4.2, as the Reference-FMUs' masks, except that no value can be read
   in the error state). */
#define FMI3_ALL (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_EVENT | MODE_CONTINUOUS | \
                  MODE_TERMINATED | MODE_ERROR)
#define FMI3_READABLE (MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)
/* Both: parameters and inputs; in continuousTimeMode inputs only (fmi_set_float64 checks). */
#define SETTABLE (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_EVENT)
#define ME_READABLE (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)

enum { BOTH = -1, CS = 0, ME = 1 };     /* the instance type a call belongs to (model_exchange) */

static const struct {
    int states[2];          /* FMI 2.0, FMI 3.0 */
    int type;
} FMI_CALLS[FMI_N_CALLS] = {
    /*                               FMI 2.0                      FMI 3.0                    type */
    [CALL_ANY_STATE]            = {{FMI2_ALL,                   FMI3_ALL},                  BOTH},
    [CALL_NOT_IN_ERROR]         = {{FMI2_ALL & ~MODE_ERROR,     FMI3_ALL & ~MODE_ERROR},    BOTH},
    [CALL_ENTER_INITIALIZATION] = {{MODE_INSTANTIATED,          MODE_INSTANTIATED},         BOTH},
    [CALL_EXIT_INITIALIZATION]  = {{MODE_INITIALIZATION,        MODE_INITIALIZATION},       BOTH},
    [CALL_TERMINATE]            = {{MODE_STEP_COMPLETE | MODE_STEP_FAILED | MODE_EVENT | MODE_CONTINUOUS,
                                    MODE_STEP_COMPLETE | MODE_EVENT | MODE_CONTINUOUS},     BOTH},
    /* FMI 3.0's getters also in instantiated (FMI 3.0, 2.3.2; FMI 2.0's start in initialization
       mode): the start values, and the outputs and states they give */
    [CALL_GET]                  = {{FMI2_READABLE,              MODE_INSTANTIATED | FMI3_READABLE}, BOTH},
    [CALL_GET_DEFINED]          = {{FMI2_READABLE,              FMI3_READABLE},             BOTH},
    [CALL_SET]                  = {{SETTABLE | MODE_CONTINUOUS, SETTABLE | MODE_CONTINUOUS}, BOTH},
    [CALL_ENTER_CONFIGURATION]  = {{0,                          MODE_INSTANTIATED | MODE_STEP_COMPLETE | MODE_EVENT},
                                   BOTH},
    [CALL_EXIT_CONFIGURATION]   = {{0,                          MODE_CONFIGURATION | MODE_RECONFIGURATION}, BOTH},
    [CALL_ACTIVATE_PARTITION]   = {{0,                          MODE_CLOCK_ACTIVATION},     BOTH},
    [CALL_DO_STEP]              = {{MODE_STEP_COMPLETE,         MODE_STEP_COMPLETE},        CS},
    [CALL_CANCEL_STEP]          = {{MODE_STEP_IN_PROGRESS,      0},                         BOTH},
    [CALL_GET_STATUS]           = {{FMI2_STATUS,                0},                         CS},
    [CALL_INPUT_DERIVATIVES]    = {{SETTABLE,                   0},                         CS},
    [CALL_OUTPUT_DERIVATIVES]   = {{FMI2_INITIALIZED,           MODE_STEP_COMPLETE | MODE_TERMINATED}, CS},
    /* FMI 3.0: only from eventMode, which a co-simulation instance never enters (hasEventMode false) */
    [CALL_ENTER_STEP_MODE]      = {{0,                          MODE_EVENT},                CS},
    /* FMI 2.0 also in eventMode (section 3.2.3; fmi-standard issue #275: a host may enter it again) */
    [CALL_ENTER_EVENT_MODE]     = {{MODE_EVENT | MODE_CONTINUOUS, MODE_CONTINUOUS},         ME},
    [CALL_UPDATE_DISCRETE_STATES] = {{MODE_EVENT,               MODE_EVENT},                ME},
    [CALL_ENTER_CONTINUOUS_TIME] = {{MODE_EVENT,                MODE_EVENT},                ME},
    [CALL_COMPLETED_STEP]       = {{MODE_CONTINUOUS,            MODE_CONTINUOUS},           ME},
    [CALL_SET_TIME]             = {{MODE_EVENT | MODE_CONTINUOUS, MODE_EVENT | MODE_CONTINUOUS}, ME},
    [CALL_SET_STATES]           = {{MODE_CONTINUOUS,            MODE_CONTINUOUS},           ME},
    /* not in FMI 2.0's initialization mode (section 3.2.3, as the Reference-FMUs: the derivatives
       are initial unknowns there, read by fmi2GetReal); FMI 3.0 allows them there */
    [CALL_GET_DERIVATIVES]      = {{MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED, ME_READABLE}, ME},
    [CALL_GET_STATES]           = {{ME_READABLE,                ME_READABLE},               ME},
    [CALL_GET_NOMINALS]         = {{MODE_INSTANTIATED | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED,
                                    ME_READABLE},                                           ME},
    /* structural: answered in every state, the error state included */
    [CALL_GET_NUMBER_OF]        = {{0,                          FMI3_ALL},                  ME},
};

/* -- the two flavours ------------------------------------------------------------------ */

static const FmiState FMI2_STATES[] = {
    {MODE_INSTANTIATED, "instantiated"}, {MODE_INITIALIZATION, "initializationMode"},
    {MODE_STEP_COMPLETE, "stepComplete"}, {MODE_STEP_IN_PROGRESS, "stepInProgress"},
    {MODE_STEP_FAILED, "stepFailed"}, {MODE_EVENT, "eventMode"}, {MODE_CONTINUOUS, "continuousTimeMode"},
    {MODE_TERMINATED, "terminated"}, {MODE_ERROR, "error"}};
static const char *const FMI2_KIND_TEXT[] = {"a tunable Real parameter", "a fixed Real parameter",
                                             "a String parameter", "a Real output", "a Real local variable",
                                             "(time)", "a Real input"};
/* FMI 3.0's stepMode is MODE_STEP_COMPLETE. */
static const FmiState FMI3_STATES[] = {
    {MODE_INSTANTIATED, "instantiated"}, {MODE_CONFIGURATION, "configurationMode"},
    {MODE_INITIALIZATION, "initializationMode"}, {MODE_EVENT, "eventMode"},
    {MODE_CONTINUOUS, "continuousTimeMode"}, {MODE_STEP_COMPLETE, "stepMode"},
    {MODE_STEP_DISCARDED, "stepDiscarded"}, {MODE_RECONFIGURATION, "reconfigurationMode"},
    {MODE_INTERMEDIATE_UPDATE, "intermediateUpdateMode"}, {MODE_CLOCK_ACTIVATION, "clockActivationMode"},
    {MODE_TERMINATED, "terminated"}, {MODE_ERROR, "error"}};
/* The variable kinds, and the independent variable (FMI 3.0 requires one: causality="independent"). */
static const char *const FMI3_KIND_TEXT[] = {"a tunable Float64 parameter", "a fixed Float64 parameter",
                                             "a String parameter", "a Float64 output", "a Float64 local variable",
                                             "the independent variable (Float64)", "a Float64 input"};

/* The marks of the layers' serialized FMU states (saved_state.c) differ: one layer's state is
   refused by the other. */
const FmiLayer FMI2_LAYER = {
    .column = 0, .prefix = "fmi2", .states = FMI2_STATES, .n_states = sizeof FMI2_STATES / sizeof *FMI2_STATES,
    .after_error = "; after a failed fmi2ExitInitializationMode, fmi2DoStep or model-exchange call, call fmi2Reset, "
                   "fmi2SetFMUstate or fmi2FreeInstance",
    .real = "Real", .kind_text = FMI2_KIND_TEXT, .count_expected = "this FMU has", .token = "GUID", .has_time = 0,
    .magic = "FBSTATE"};
const FmiLayer FMI3_LAYER = {
    .column = 1, .prefix = "fmi3", .states = FMI3_STATES, .n_states = sizeof FMI3_STATES / sizeof *FMI3_STATES,
    .after_error = "; after a failed fmi3ExitInitializationMode, fmi3DoStep or model-exchange call, call fmi3Reset, "
                   "fmi3SetFMUState or fmi3FreeInstance",
    .real = "Float64", .kind_text = FMI3_KIND_TEXT, .count_expected = "expected", .token = "instantiation token",
    .has_time = 1, .magic = "FBSTAT3"};

static const char *state_name(const FmiLayer *layer, int mode)
{
    for (size_t i = 0; i < layer->n_states; i++)
        if (layer->states[i].mode == mode) return layer->states[i].name;
    return "(unknown)";
}

const char *fmi_type_name(int model_exchange) { return model_exchange ? "model exchange" : "co-simulation"; }

/* 1 when the instance is of the type `function` belongs to (BOTH, CS or ME); else logs it. */
static int of_type(ModelInstance *m, const char *function, int type)
{
    if (type == BOTH || m->model_exchange == type) return 1;
    model_log(m, MODEL_ERROR, "logStatusError", "%s is a %s function; this instance was instantiated for %s", function,
              fmi_type_name(type), fmi_type_name(m->model_exchange));
    return 0;
}

int fmi_allowed(ModelInstance *m, const FmiLayer *layer, FmiCall call, const char *function)
{
    const int states = FMI_CALLS[call].states[layer->column];
    char list[300];
    size_t used = 0;
    if (!m) return 0;
    if (m->state.mode & states) return of_type(m, function, FMI_CALLS[call].type);
    list[0] = '\0';
    for (size_t i = 0; i < layer->n_states; i++)
        if ((states & layer->states[i].mode) && used < sizeof list)
            used += snprintf(list + used, sizeof list - used, "%s%s", used ? ", " : "", layer->states[i].name);
    model_log(m, MODEL_ERROR, "logStatusError", "%s is not allowed in state %s (only in: %s)%s", function,
              state_name(layer, m->state.mode), list, m->state.mode == MODE_ERROR ? layer->after_error : "");
    return 0;
}

int fmi_present(ModelInstance *m, const char *function, const void *p, const char *name, size_t n)
{
    if (p) return 1;
    if (n > 0)
        model_log(m, MODEL_ERROR, "logStatusError", "%s: argument %s is NULL but its length is %u", function, name,
                  (unsigned)n);
    else
        model_log(m, MODEL_ERROR, "logStatusError", "%s: argument %s is NULL", function, name);
    return 0;
}

int fmi_count_is(ModelInstance *m, const FmiLayer *layer, const char *function, size_t n, size_t expected,
                 const char *what)
{
    if (n == expected) return 1;
    model_log(m, MODEL_ERROR, "logStatusError", "%s: %u %s given; %s %u", function, (unsigned)n, what,
              layer->count_expected, (unsigned)expected);
    return 0;
}

/* -- variables ----------------------------------------------------------------------- */

static int is_time(const FmiLayer *layer, unsigned int vr) { return layer->has_time && vr == FMU_N_VARIABLES; }
static int kind_of(const FmiLayer *layer, unsigned int vr) { return is_time(layer, vr) ? KIND_TIME : KINDS[vr]; }

/* 1 when every vr[i] is a variable of one of `kinds` (KIND bits); else logs the first that is
   not and returns 0.  Checked before any value is read or written: a refused call changes nothing. */
static int check_refs(ModelInstance *m, const FmiLayer *layer, const char *function, const unsigned int vr[],
                      size_t nvr, int kinds, const char *expected)
{
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= FMU_N_VARIABLES && !is_time(layer, vr[i])) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: unknown value reference %u", function, (unsigned)vr[i]);
            return 0;
        }
        if (!(kinds & KIND(kind_of(layer, vr[i])))) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: %s (value reference %u) is %s; expected %s", function,
                      is_time(layer, vr[i]) ? "time" : NAMES[vr[i]], (unsigned)vr[i],
                      layer->kind_text[kind_of(layer, vr[i])], expected);
            return 0;
        }
    }
    return 1;
}

/* Fixed parameters (and the String integrator) can be set only before initialization ends; in
   continuousTimeMode only inputs (a tunable parameter changes in event mode, as FMI says). */
static int settable_now(ModelInstance *m, const FmiLayer *layer, const char *function, const unsigned int vr[],
                        size_t nvr)
{
    if (m->state.mode == MODE_CONTINUOUS) {
        for (size_t i = 0; i < nvr; i++)
            if (KINDS[vr[i]] != KIND_INPUT) {
                model_log(m, MODEL_ERROR, "logStatusError", "%s: %s is a parameter; in state %s only inputs can be "
                          "set (a tunable parameter changes in eventMode)", function, NAMES[vr[i]],
                          state_name(layer, m->state.mode));
                return 0;
            }
        return 1;
    }
    if (m->state.mode != MODE_STEP_COMPLETE && m->state.mode != MODE_EVENT) return 1;
    for (size_t i = 0; i < nvr; i++)
        if (KINDS[vr[i]] == KIND_FIXED || KINDS[vr[i]] == KIND_STRING) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: %s is a fixed parameter; it can only be set before "
                      "%sExitInitializationMode (the instance is in state %s)", function, NAMES[vr[i]], layer->prefix,
                      state_name(layer, m->state.mode));
            return 0;
        }
    return 1;
}

/* The model time: the start time in initialization mode, then the co-simulation's time or the
   time the model-exchange host set. */
static double model_time(const ModelInstance *m)
{
    if (m->state.mode == MODE_INITIALIZATION) return m->state.start_time;
    return m->model_exchange ? m->state.me_t : m->state.t;
}

/* The output groups (FMU_GROUP_* bits) vr[] reads: computed on first read (model_preview_outputs). */
static int groups_read(const FmiLayer *layer, const unsigned int vr[], size_t nvr)
{
    int groups = 0;
    for (size_t i = 0; i < nvr; i++)
        if (!is_time(layer, vr[i])) groups |= READ_COMPUTED[vr[i]];
    return groups;
}

ModelStatus fmi_get_float64(ModelInstance *m, const FmiLayer *layer, const char *function, const unsigned int vr[],
                            size_t nvr, double value[])
{
    char expected[40];
    snprintf(expected, sizeof expected, "a %s", layer->real);
    if (!check_refs(m, layer, function, vr, nvr, KIND(KIND_TUNABLE) | KIND(KIND_FIXED) | KIND(KIND_OUTPUT) |
                    KIND(KIND_LOCAL) | KIND(KIND_TIME) | KIND(KIND_INPUT), expected))
        return MODEL_ERROR;
    const int groups = nvr > 0 ? groups_read(layer, vr, nvr) & m->state.outputs_pending : 0;
    const int before_start = m->state.mode == MODE_INSTANTIATED || m->state.mode == MODE_INITIALIZATION;
    if (model_few_outputs(m, groups, nvr)) {
        for (size_t i = 0; i < nvr; i++)
            if (!is_time(layer, vr[i])) model_output_one(m, vr[i]);
    } else if (nvr > 0 && (before_start || groups)) {
        model_preview_outputs(m, groups);      /* before the start: what the start values give */
        if (!before_start && (m->state.outputs_pending & groups)) return MODEL_ERROR;  /* logged */
    }
    for (size_t i = 0; i < nvr; i++) value[i] = is_time(layer, vr[i]) ? model_time(m) : m->state.values[vr[i]];
    return MODEL_OK;
}

ModelStatus fmi_set_float64(ModelInstance *m, const FmiLayer *layer, const char *function, const unsigned int vr[],
                            size_t nvr, const double value[])
{
    char expected[40];
    snprintf(expected, sizeof expected, "a %s parameter or input", layer->real);
    if (!check_refs(m, layer, function, vr, nvr, KIND(KIND_TUNABLE) | KIND(KIND_FIXED) | KIND(KIND_INPUT), expected)
        || !settable_now(m, layer, function, vr, nvr) || model_non_finite_values(m, function, vr, value, nvr))
        return MODEL_ERROR;
    int inputs = 0;
    for (size_t i = 0; i < nvr; i++) {      /* parameters: checked, and applied, at the next step or event */
        if (KINDS[vr[i]] == KIND_INPUT) inputs = 1;
        m->state.values[vr[i]] = value[i];
    }
    if (inputs) model_inputs_set(m, vr, nvr);
    return MODEL_OK;
}

ModelStatus fmi_get_string(ModelInstance *m, const FmiLayer *layer, const char *function, const unsigned int vr[],
                           size_t nvr, const char *value[])
{
    if (!check_refs(m, layer, function, vr, nvr, KIND(KIND_STRING), "a String")) return MODEL_ERROR;
    for (size_t i = 0; i < nvr; i++) value[i] = INTEGRATORS[m->state.integrator];
    return MODEL_OK;
}

static int integrator_index(const char *name)
{
    for (int k = 0; k < FMU_N_INTEGRATORS; k++)
        if (name && strcmp(name, INTEGRATORS[k]) == 0) return k;
    return -1;
}

ModelStatus fmi_set_string(ModelInstance *m, const FmiLayer *layer, const char *function, const unsigned int vr[],
                           size_t nvr, const char *const value[])
{
    if (!check_refs(m, layer, function, vr, nvr, KIND(KIND_STRING), "a String")
        || !settable_now(m, layer, function, vr, nvr))
        return MODEL_ERROR;
    for (size_t i = 0; i < nvr; i++)
        if (integrator_index(value[i]) < 0) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: %s '%s': integrator = '%s': must be one of %s, %s",
                      function, MECH_NAME, m->instance_name, value[i] ? value[i] : "(null)", INTEGRATORS[0],
                      INTEGRATORS[1]);
            return MODEL_ERROR;
        }
    for (size_t i = 0; i < nvr; i++) m->state.integrator = integrator_index(value[i]);
    return MODEL_OK;
}

ModelStatus fmi_no_variables(ModelInstance *m, const char *function, const unsigned int vr[], size_t nvr,
                             const char *type)
{
    if (nvr == 0) return MODEL_OK;
    if (type)
        model_log(m, MODEL_ERROR, "logStatusError", "%s: unknown value reference %u (this FMU has no %s variables)",
                  function, (unsigned)vr[0], type);
    else
        model_log(m, MODEL_ERROR, "logStatusError", "%s: unknown value reference %u (this FMU has no variables of "
                  "that type)", function, (unsigned)vr[0]);
    return MODEL_ERROR;
}

/* -- inquiry and life cycle ------------------------------------------------------------ */

int fmi_named(ModelInstance *probe, const char *function)
{
    if (probe->instance_name && probe->instance_name[0]) return 1;
    model_log(probe, MODEL_ERROR, "logStatusError", "%s: the instance name must not be empty", function);
    return 0;
}

ModelInstance *fmi_create(ModelInstance *probe, const FmiLayer *layer, const char *function, const char *token,
                          size_t size, int logging_on, int model_exchange)
{
    const char *name = probe->instance_name ? probe->instance_name : "";
    if (!token || strcmp(token, FMU_GUID) != 0) {
        model_log(probe, MODEL_ERROR, "logStatusError", "%s: %s '%s' does not match this binary's '%s' (a model "
                  "description from another build?)", function, layer->token, token ? token : "(null)", FMU_GUID);
        return NULL;
    }
    ModelInstance *m = (ModelInstance *)model_allocate(probe, size);
    char *copy = (char *)model_allocate(probe, strlen(name) + 1);
    if (!m || !copy) {
        model_release(probe, m);
        model_release(probe, copy);
        model_log(probe, MODEL_ERROR, "logStatusError", "%s: out of memory", function);
        return NULL;
    }
    m->host = probe->host;
    m->environment = probe->environment;
    m->instance_name = strcpy(copy, name);
    m->logging_on = logging_on ? 1 : 0;
    m->model_exchange = model_exchange;
    model_reset(m);
    return m;
}

void fmi_free_instance(ModelInstance *m)
{
    if (!m) return;
    model_release(m, m->instance_name);
    m->instance_name = NULL;
    model_release(m, m);
}

ModelStatus fmi_set_debug_logging(ModelInstance *m, const char *function, int logging_on, size_t n,
                                  const char *const categories[])
{
    static const char *const known[] = {"logStatusWarning", "logStatusDiscard", "logStatusError",
                                        "logStatusFatal", "logAll"};
    for (size_t i = 0; i < n; i++) {
        int found = 0;
        for (size_t k = 0; k < sizeof known / sizeof *known; k++)
            if (categories[i] && strcmp(categories[i], known[k]) == 0) found = 1;
        if (!found) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: unknown log category '%s'", function,
                      categories[i] ? categories[i] : "(null)");
            return MODEL_ERROR;
        }
    }
    m->logging_on = logging_on ? 1 : 0;
    return MODEL_OK;
}

ModelStatus fmi_setup_experiment(ModelInstance *m, const char *function, double start, int stop_defined, double stop)
{
    if (!isfinite(start) || (stop_defined && !(stop >= start))) {
        model_log(m, MODEL_ERROR, "logStatusError", "%s: need a finite start time and a stop time not before it "
                  "(got start %g s, stop %g s)", function, start, stop);
        return MODEL_ERROR;
    }
    m->state.start_time = start;
    m->state.stop_time = stop_defined ? stop : INFINITY;
    return MODEL_OK;
}

ModelStatus fmi_exit_initialization(ModelInstance *m)
{
    if (model_initialize(m) != MODEL_OK) {   /* model_initialize logged why */
        m->state.mode = MODE_ERROR;
        return MODEL_ERROR;
    }
    m->state.mode = m->model_exchange ? MODE_EVENT : MODE_STEP_COMPLETE;
    return MODEL_OK;
}

ModelStatus fmi_terminate(ModelInstance *m)
{
    const ModelState *s = &m->state;
    m->state.mode = MODE_TERMINATED;
    /* the integration's statistics (with logging on: a host that wants to know how hard it was) */
    model_log(m, MODEL_OK, "logAll", "statistics at t = %.9g s: %lu right-hand-side evaluations (%lu on the full "
              "system), %lu by continuation from the last accepted state, %lu at trial points not reached (their "
              "steps rejected); %lu Newton-Raphson iterations, %lu integrator starts, %lu re-partitions; at most %lu "
              "right-hand-side evaluations in one communication step (max_evaluations = %.17g)", s->t,
              s->rhs_evaluations, s->full_evaluations, s->continuations, s->failed_evaluations, s->newton_iterations,
              s->starts, s->repartitions, s->most_step_evaluations, s->values[VR_max_evaluations]);
    return MODEL_OK;
}

/* -- FMU state ----------------------------------------------------------------------- */

ModelStatus fmi_get_fmu_state(ModelInstance *m, const char *function, void **state)
{
    if (!*state) {
        *state = model_allocate(m, sizeof(SavedState));
        if (!*state) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: out of memory", function);
            return MODEL_ERROR;
        }
    }
    memcpy(&((SavedState *)*state)->state, &m->state, sizeof(ModelState));
    ((SavedState *)*state)->model_exchange = m->model_exchange;
    return MODEL_OK;
}

/* Only a state saved by an instance of the same type (its mode is of that type's state machine). */
ModelStatus fmi_set_fmu_state(ModelInstance *m, const char *function, const void *state)
{
    const SavedState *saved = (const SavedState *)state;
    char why[MODEL_MESSAGE];
    if (saved->model_exchange != m->model_exchange) {
        model_log(m, MODEL_ERROR, "logStatusError", "%s: the FMU state was saved by a %s instance; this instance was "
                  "instantiated for %s", function, fmi_type_name(saved->model_exchange),
                  fmi_type_name(m->model_exchange));
        return MODEL_ERROR;
    }
    if (model_check_state(&saved->state, saved->model_exchange, why, sizeof why)) {    /* a corrupted state */
        model_log(m, MODEL_ERROR, "logStatusError", "%s: the FMU state is refused: its %s", function, why);
        return MODEL_ERROR;
    }
    memcpy(&m->state, &saved->state, sizeof(ModelState));
    return MODEL_OK;
}

ModelStatus fmi_free_fmu_state(ModelInstance *m, void **state)
{
    model_release(m, *state);   /* *state == NULL: nothing to free */
    *state = NULL;
    return MODEL_OK;
}

ModelStatus fmi_serialized_size(size_t *size)
{
    *size = model_serialized_size();
    return MODEL_OK;
}

ModelStatus fmi_serialize(ModelInstance *m, const FmiLayer *layer, const char *function, const void *state,
                          unsigned char *bytes, size_t size)
{
    if (size < model_serialized_size()) {
        model_log(m, MODEL_ERROR, "logStatusError", "%s: need %u bytes (got %u)", function,
                  (unsigned)model_serialized_size(), (unsigned)size);
        return MODEL_ERROR;
    }
    model_serialize((const SavedState *)state, layer->magic, bytes);
    return MODEL_OK;
}

ModelStatus fmi_deserialize(ModelInstance *m, const FmiLayer *layer, const char *function,
                            const unsigned char *bytes, size_t size, void **state)
{
    SavedState read;
    char why[MODEL_MESSAGE];
    const int problem = model_deserialize(bytes, size, layer->magic, &read, why, sizeof why);
    if (problem == MODEL_WRONG_SIZE) {
        model_log(m, MODEL_ERROR, "logStatusError", "%s: expected %u bytes, got %u", function,
                  (unsigned)model_serialized_size(), (unsigned)size);
        return MODEL_ERROR;
    }
    if (problem == MODEL_INVALID) {     /* the instance is unchanged, still usable */
        model_log(m, MODEL_ERROR, "logStatusError", "%s: the state is refused: its %s", function, why);
        return MODEL_ERROR;
    }
    if (problem) {
        model_log(m, MODEL_ERROR, "logStatusError", "%s: not a state of this FMU (%s %s)", function, layer->token,
                  FMU_GUID);
        return MODEL_ERROR;
    }
    if (!*state) {
        *state = model_allocate(m, sizeof(SavedState));
        if (!*state) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: out of memory", function);
            return MODEL_ERROR;
        }
    }
    *(SavedState *)*state = read;
    return MODEL_OK;
}

/* -- directional derivatives, a step ----------------------------------------------------- */

/* Every value reference is checked before anything is computed: a refused call changes nothing.  In
   initialization mode it runs on a copy and a failure leaves the instance there (the host may still
   correct the start values); elsewhere a failure leaves the error state. */
ModelStatus fmi_directional(ModelInstance *m, const char *function, const unsigned int unknowns[], size_t n_unknowns,
                            const unsigned int knowns[], size_t n_knowns, const double seed[], double sensitivity[])
{
    Directional d;
    double probe;
    model_me_directional_start(&d);
    for (size_t i = 0; i < n_knowns; i++)
        if (model_me_seed(m, function, &d, knowns[i], seed[i]) != MODEL_OK) return MODEL_ERROR;
    for (size_t i = 0; i < n_unknowns; i++)
        if (model_me_sensitivity(m, function, &d, unknowns[i], &probe) != MODEL_OK) return MODEL_ERROR;
    if (model_me_directional(m, &d) != MODEL_OK) {      /* logged why */
        if (m->state.mode != MODE_INITIALIZATION) m->state.mode = MODE_ERROR;
        return MODEL_ERROR;
    }
    for (size_t i = 0; i < n_unknowns; i++) model_me_sensitivity(m, function, &d, unknowns[i], &sensitivity[i]);
    return MODEL_OK;
}

/* Each check logs why. */
ModelStatus fmi_do_step(ModelInstance *m, const char *function, double current_time, double step)
{
    if (model_bad_step(m, function, current_time, step) || model_past_stop_time(m, function, current_time, step)
        || model_do_step(m, current_time, step) != MODEL_OK) {
        m->state.mode = MODE_ERROR;
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

/* -- model exchange ------------------------------------------------------------------ */

/* The continuous states are the file's independent coordinates, their rates and the drivers' work
   (dae.h), in the order of FMU_STATE_VRS; the FMU has no event indicators and no time events: a
   parameter set in event mode is applied by the event update (re-assembly keeping the states). */

static ModelStatus failed(ModelInstance *m)
{
    m->state.mode = MODE_ERROR;
    return MODEL_ERROR;
}

ModelStatus fmi_update_discrete_states(ModelInstance *m)
{
    return model_me_event_update(m) == MODEL_OK ? MODEL_OK : failed(m);      /* logged why */
}

ModelStatus fmi_enter_continuous_time(ModelInstance *m)
{
    m->state.mode = MODE_CONTINUOUS;
    return MODEL_OK;
}

ModelStatus fmi_completed_step(ModelInstance *m)
{
    return model_me_completed_step(m) == MODEL_OK ? MODEL_OK : failed(m);
}

ModelStatus fmi_set_time(ModelInstance *m, const char *function, double time)
{
    if (!isfinite(time)) {
        model_log(m, MODEL_ERROR, "logStatusError", "%s: the time must be finite (got %g)", function, time);
        return MODEL_ERROR;
    }
    model_me_set_time(m, time);
    return MODEL_OK;
}

ModelStatus fmi_set_states(ModelInstance *m, const FmiLayer *layer, const char *function, const double x[], size_t nx)
{
    if (!fmi_count_is(m, layer, function, nx, FMU_N_STATES, "states") || model_non_finite_states(m, function, x, nx))
        return MODEL_ERROR;
    model_me_set_states(m, x);
    return MODEL_OK;
}

/* In initialization mode, the values the start values give (model_preview_outputs: all of them,
   or none when the start values are invalid or cannot be assembled, which exiting initialization
   mode then reports). */
static ModelStatus from_preview(ModelInstance *m, const int *vrs, double value[], size_t n)
{
    model_preview_outputs(m, FMU_GROUP_STATES);
    for (size_t i = 0; i < n; i++) value[i] = m->state.values[vrs[i]];
    return MODEL_OK;
}

ModelStatus fmi_get_states(ModelInstance *m, const FmiLayer *layer, const char *function, double x[], size_t nx)
{
    if (!fmi_count_is(m, layer, function, nx, FMU_N_STATES, "states")) return MODEL_ERROR;
    if (m->state.mode == MODE_INITIALIZATION) return from_preview(m, STATE_VRS, x, nx);
    model_me_get_states(m, x);
    return MODEL_OK;
}

ModelStatus fmi_get_derivatives(ModelInstance *m, const FmiLayer *layer, const char *function, double dx[], size_t nx)
{
    if (!fmi_count_is(m, layer, function, nx, FMU_N_STATES, "derivatives")) return MODEL_ERROR;
    if (m->state.mode == MODE_INITIALIZATION) return from_preview(m, DERIVATIVE_VRS, dx, nx);
    return model_me_derivatives(m, dx) == MODEL_OK ? MODEL_OK : failed(m);
}

ModelStatus fmi_get_nominals(ModelInstance *m, const FmiLayer *layer, const char *function, double x[], size_t nx)
{
    if (!fmi_count_is(m, layer, function, nx, FMU_N_STATES, "nominals")) return MODEL_ERROR;
    for (size_t i = 0; i < nx; i++) x[i] = 1.0;
    return MODEL_OK;
}
