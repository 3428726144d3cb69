/* FMI 2.0 co-simulation and model exchange interface of a mechanism's native FMU (any mechanism: model.h).
 *
 * A thin layer over model.h: it checks each call, maps value references to the model's
 * variables, and implements the FMU state functions as copies of the instance's pointer-free
 * ModelState.  No global or static mutable data: instances are independent.
 *
 * The rules every entry point follows (tests/native_host/fmi2_strict_host.c checks them all):
 * - ENTER, first: a NULL instance is refused with fmi2Error (no logger can be reached through
 *   it); a call that the FMI 2.0 state machine of the instance's type (co-simulation or model
 *   exchange) does not allow in the instance's state is refused with fmi2Error and a message
 *   naming the function, the state and the states the call is allowed in.  CS_ONLY / ME_ONLY
 *   then refuse a call of the other type (with a message saying so).
 * - REQUIRE: a NULL pointer argument the call would use is refused with fmi2Error and a message.
 * - A refused call changes nothing.  fmi2ExitInitializationMode, fmi2DoStep, fmi2NewDiscreteStates
 *   and a failed model-exchange evaluation returning fmi2Error leave the instance in the error
 *   state, where no value can be read: only fmi2Reset, fmi2FreeInstance, fmi2SetFMUstate (back to
 *   a state saved before the failure, by an instance of the same type), the other FMU-state
 *   bookkeeping calls and fmi2SetDebugLogging are accepted.
 * - The status a call returns is the worst status it logged (fmi2Discard only from the status
 *   inquiries, for a status the FMU does not have).
 * Every message goes through the host's logger callback.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"
#include "model.h"

static const int KINDS[FMU_N_VARIABLES] = FMU_VARIABLE_KINDS;
static const char *const NAMES[FMU_N_VARIABLES] = FMU_VARIABLE_NAMES;
static const char *const INTEGRATORS[FMU_N_INTEGRATORS] = FMU_INTEGRATOR_NAMES;
static const int READ_COMPUTED[FMU_N_VARIABLES] = FMU_READ_COMPUTED;
enum { KIND_TUNABLE = 0, KIND_FIXED = 1, KIND_STRING = 2, KIND_OUTPUT = 3, KIND_LOCAL = 4 };
static const char *const KIND_TEXT[] = {"a tunable Real parameter", "a fixed Real parameter", "a String parameter",
                                        "a Real output", "a Real local variable"};
#define KIND(k) (1 << (k))

/* -- the FMI 2.0 state machines (co-simulation and model exchange) --------------------- */

/* fmi2DoStep is synchronous, so the state stepInProgress is never entered; it is named
   because fmi2CancelStep and the status inquiries are defined for it.  The state fatal is
   never entered either: the FMU shares nothing between instances and never returns fmi2Fatal. */
#define MODE_STEP_IN_PROGRESS 64

static const struct { int mode; const char *name; } STATES[] = {
    {MODE_INSTANTIATED, "instantiated"}, {MODE_INITIALIZATION, "initializationMode"},
    {MODE_STEP_COMPLETE, "stepComplete"}, {MODE_STEP_IN_PROGRESS, "stepInProgress"},
    {MODE_STEP_FAILED, "stepFailed"}, {MODE_EVENT, "eventMode"}, {MODE_CONTINUOUS, "continuousTimeMode"},
    {MODE_TERMINATED, "terminated"}, {MODE_ERROR, "error"}};
#define N_STATES (sizeof STATES / sizeof *STATES)

/* Where each group of calls is allowed (FMI 2.0, sections 3.2.3 and 4.2.4; as the Reference-FMUs,
   except that no value can be read in the error state).  An instance is in the states of its
   type only (co-simulation: stepComplete; model exchange: eventMode, continuousTimeMode). */
#define ALL_STATES (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_STEP_FAILED | \
                    MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED | MODE_ERROR)
#define INITIALIZED (MODE_STEP_COMPLETE | MODE_STEP_FAILED | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)
#define READABLE (MODE_INITIALIZATION | INITIALIZED)                       /* fmi2GetXXX */
/* fmi2SetXXX: parameters (the FMU has no inputs), so not in continuousTimeMode */
#define SETTABLE (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_EVENT)
#define ME_READABLE (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)
#define STATUS_STATES (MODE_STEP_COMPLETE | MODE_STEP_IN_PROGRESS | MODE_STEP_FAILED | MODE_TERMINATED)

/* The mark of this layer's serialized FMU states (saved_state.c): the FMI 3.0 layer's differs. */
static const char STATE_MAGIC[8] = "FBSTATE";

/* Every message goes through the host's logger: errors and warnings always, information
   (status OK) only with logging on.  The text is formatted here and passed as "%s". */
static const fmi2CallbackFunctions *callbacks(const ModelInstance *m)
{
    return (const fmi2CallbackFunctions *)m->host;
}

void model_log(ModelInstance *m, ModelStatus status, const char *category, const char *fmt, ...)
{
    char text[1024];
    va_list args;
    if (!m || !callbacks(m) || !callbacks(m)->logger) return;
    if (status == MODEL_OK && !m->logging_on) return;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    callbacks(m)->logger(m->environment, m->instance_name, (fmi2Status)status, category, "%s", text);
}

static const char *state_name(int mode)
{
    for (size_t i = 0; i < N_STATES; i++)
        if (STATES[i].mode == mode) return STATES[i].name;
    return "(unknown)";
}

/* 1 when `function` may be called in the instance's state; else logs why and returns 0.
   A NULL instance gives 0 without a message: there is no logger to call. */
static int allowed(ModelInstance *m, const char *function, int states)
{
    char list[200];
    size_t used = 0;
    if (!m) return 0;
    if (m->state.mode & states) return 1;
    list[0] = '\0';
    for (size_t i = 0; i < N_STATES; i++)
        if ((states & STATES[i].mode) && used < sizeof list)
            used += snprintf(list + used, sizeof list - used, "%s%s", used ? ", " : "", STATES[i].name);
    model_log(m, MODEL_ERROR, "logStatusError", "%s is not allowed in state %s (only in: %s)%s", function,
              state_name(m->state.mode), list, m->state.mode == MODE_ERROR ?
              "; after a failed fmi2ExitInitializationMode, fmi2DoStep or model-exchange call, call fmi2Reset, fmi2SetFMUstate or "
              "fmi2FreeInstance" : "");
    return 0;
}

/* The first statement of every entry point: names the instance `m` and returns fmi2Error when
   it is NULL or the call is not allowed in its state. */
#define ENTER(states) \
    ModelInstance *const m = (ModelInstance *)c; \
    if (!allowed(m, __func__, (states))) return fmi2Error

/* 1 when `p` is not NULL; else logs which argument is missing and returns 0.  `n` is the
   length of an array argument, 0 for a single pointer (REQUIRE_ARRAY checks only when n > 0). */
static int present(ModelInstance *m, const char *function, const void *p, const char *name, size_t n)
{
    if (p) return 1;
    if (n > 0)
        model_log(m, MODEL_ERROR, "logStatusError", "%s: argument %s is NULL but its length is %u", function, name,
                  (unsigned)n);
    else
        model_log(m, MODEL_ERROR, "logStatusError", "%s: argument %s is NULL", function, name);
    return 0;
}

/* 1 when the instance is of the type `function` belongs to (model_exchange 0 or 1); else logs it. */
static int of_type(ModelInstance *m, const char *function, int model_exchange)
{
    if (m->model_exchange == model_exchange) return 1;
    model_log(m, MODEL_ERROR, "logStatusError", "%s is a %s function; this instance was instantiated for %s", function,
              model_exchange ? "model exchange" : "co-simulation", m->model_exchange ? "model exchange" : "co-simulation");
    return 0;
}

#define CS_ONLY if (!of_type(m, __func__, 0)) return fmi2Error
#define ME_ONLY if (!of_type(m, __func__, 1)) return fmi2Error

#define REQUIRE(p) if (!present(m, __func__, (const void *)(p), #p, 0)) return fmi2Error
#define REQUIRE_ARRAY(p, n) if ((n) > 0 && !present(m, __func__, (const void *)(p), #p, (n))) return fmi2Error

static void *allocate(const ModelInstance *m, size_t size)
{
    if (m && callbacks(m) && callbacks(m)->allocateMemory) return callbacks(m)->allocateMemory(1, size);
    return calloc(1, size);
}

static void release(const ModelInstance *m, void *p)
{
    if (!p) return;
    if (m && callbacks(m) && callbacks(m)->freeMemory) callbacks(m)->freeMemory(p);
    else free(p);
}

/* 1 when every vr[i] is a variable of one of `kinds` (KIND bits); else logs the first that is
   not and returns 0.  Checked before any value is read or written: a refused call changes nothing. */
static int check_refs(ModelInstance *m, const char *function, const fmi2ValueReference vr[], size_t nvr, int kinds,
                      const char *expected)
{
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= FMU_N_VARIABLES) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: unknown value reference %u", function, (unsigned)vr[i]);
            return 0;
        }
        if (!(kinds & KIND(KINDS[vr[i]]))) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: %s (value reference %u) is %s; expected %s", function,
                      NAMES[vr[i]], (unsigned)vr[i], KIND_TEXT[KINDS[vr[i]]], expected);
            return 0;
        }
    }
    return 1;
}

/* Fixed parameters (and the String integrator) can be set only before initialization ends. */
static int settable_now(ModelInstance *m, const char *function, const fmi2ValueReference vr[], size_t nvr)
{
    if (m->state.mode != MODE_STEP_COMPLETE && m->state.mode != MODE_EVENT) return 1;
    for (size_t i = 0; i < nvr; i++)
        if (KINDS[vr[i]] == KIND_FIXED || KINDS[vr[i]] == KIND_STRING) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: %s is a fixed parameter; it can only be set before "
                      "fmi2ExitInitializationMode (the instance is in state %s)", function, NAMES[vr[i]],
                      state_name(m->state.mode));
            return 0;
        }
    return 1;
}

/* -- inquiry ------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    static const char *const known[] = {"logStatusWarning", "logStatusDiscard", "logStatusError",
                                        "logStatusFatal", "logAll"};
    ENTER(ALL_STATES);
    REQUIRE_ARRAY(categories, nCategories);
    for (size_t i = 0; i < nCategories; i++) {
        int found = 0;
        for (size_t k = 0; k < sizeof known / sizeof *known; k++)
            if (categories[i] && strcmp(categories[i], known[k]) == 0) found = 1;
        if (!found) {
            model_log(m, MODEL_ERROR, "logStatusError", "fmi2SetDebugLogging: unknown log category '%s'",
                      categories[i] ? categories[i] : "(null)");
            return fmi2Error;
        }
    }
    m->logging_on = loggingOn ? 1 : 0;
    return fmi2OK;
}

/* -- life cycle ---------------------------------------------------------------------- */

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    ModelInstance probe;
    const char *name = instanceName ? instanceName : "";
    (void)fmuResourceLocation;
    (void)visible;
    memset(&probe, 0, sizeof probe);
    probe.host = functions;
    probe.environment = functions ? functions->componentEnvironment : NULL;
    probe.instance_name = (char *)name;
    if (!functions || !functions->logger) return NULL;
    if (!functions->allocateMemory != !functions->freeMemory) {
        model_log(&probe, MODEL_ERROR, "logStatusError", "fmi2Instantiate: allocateMemory and freeMemory must be "
                  "given together (memory allocated by one must be freed by the other)");
        return NULL;
    }
    if (!instanceName || !instanceName[0]) {
        model_log(&probe, MODEL_ERROR, "logStatusError", "fmi2Instantiate: the instance name must not be empty");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        model_log(&probe, MODEL_ERROR, "logStatusError", "fmi2Instantiate: unknown fmuType %d (fmi2ModelExchange %d "
                  "or fmi2CoSimulation %d)", (int)fmuType, (int)fmi2ModelExchange, (int)fmi2CoSimulation);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, FMU_GUID) != 0) {
        model_log(&probe, MODEL_ERROR, "logStatusError", "fmi2Instantiate: GUID '%s' does not match this binary's "
                  "'%s' (a model description from another build?)", fmuGUID ? fmuGUID : "(null)", FMU_GUID);
        return NULL;
    }
    ModelInstance *m = (ModelInstance *)allocate(&probe, sizeof(ModelInstance));
    char *copy = (char *)allocate(&probe, strlen(name) + 1);
    if (!m || !copy) {
        release(&probe, m);
        release(&probe, copy);
        model_log(&probe, MODEL_ERROR, "logStatusError", "fmi2Instantiate: out of memory");
        return NULL;
    }
    m->host = functions;
    m->environment = functions->componentEnvironment;
    m->instance_name = strcpy(copy, name);
    m->logging_on = loggingOn ? 1 : 0;
    m->model_exchange = fmuType == fmi2ModelExchange;
    model_reset(m);
    return m;
}

void fmi2FreeInstance(fmi2Component c)
{
    ModelInstance *m = (ModelInstance *)c;   /* allowed in every state; NULL is ignored */
    if (!m) return;
    release(m, m->instance_name);
    m->instance_name = NULL;
    release(m, m);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    ENTER(MODE_INSTANTIATED);
    (void)toleranceDefined;   /* the integrator's tolerances are the rtol and atol parameters */
    (void)tolerance;
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi2SetupExperiment: need a finite start time and a stop "
                  "time not before it (got start %g s, stop %g s)", startTime, stopTime);
        return fmi2Error;
    }
    m->state.start_time = startTime;
    m->state.stop_time = stopTimeDefined ? stopTime : INFINITY;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    ENTER(MODE_INSTANTIATED);
    m->state.mode = MODE_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    ENTER(MODE_INITIALIZATION);
    if (model_initialize(m) != MODEL_OK) {   /* model_initialize logged why */
        m->state.mode = MODE_ERROR;
        return fmi2Error;
    }
    m->state.mode = m->model_exchange ? MODE_EVENT : MODE_STEP_COMPLETE;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    ENTER(MODE_STEP_COMPLETE | MODE_STEP_FAILED | MODE_EVENT | MODE_CONTINUOUS);
    m->state.mode = MODE_TERMINATED;
    /* the integration's statistics (with logging on: a host that wants to know how hard it was) */
    model_log(m, MODEL_OK, "logAll", "statistics at t = %.9g s: %lu right-hand-side evaluations (%lu on the full system), %lu by "
              "continuation from the last accepted state, %lu at trial points not reached (their steps "
              "rejected); %lu Newton-Raphson iterations, %lu integrator starts, %lu re-partitions; at most %lu "
              "right-hand-side evaluations in one communication step (max_evaluations = %.17g)", m->state.t,
              m->state.rhs_evaluations, m->state.full_evaluations, m->state.continuations,
              m->state.failed_evaluations, m->state.newton_iterations, m->state.starts, m->state.repartitions,
              m->state.most_step_evaluations, m->state.values[VR_max_evaluations]);
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    ENTER(ALL_STATES);
    model_reset(m);
    return fmi2OK;
}

/* -- variables ----------------------------------------------------------------------- */

/* The output groups (FMU_GROUP_* bits) vr[] reads: computed on first read (model_preview_outputs). */
static int groups_read(const fmi2ValueReference vr[], size_t nvr)
{
    int groups = 0;
    for (size_t i = 0; i < nvr; i++) groups |= READ_COMPUTED[vr[i]];
    return groups;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    ENTER(READABLE);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    if (!check_refs(m, __func__, vr, nvr, KIND(KIND_TUNABLE) | KIND(KIND_FIXED) | KIND(KIND_OUTPUT) | KIND(KIND_LOCAL),
                    "a Real"))
        return fmi2Error;
    const int groups = nvr > 0 ? groups_read(vr, nvr) & m->state.outputs_pending : 0;
    if (model_few_outputs(m, groups, nvr)) {
        for (size_t i = 0; i < nvr; i++) model_output_one(m, vr[i]);
    } else if (nvr > 0 && (m->state.mode == MODE_INITIALIZATION || groups)) {
        model_preview_outputs(m, groups);
        if (m->state.mode != MODE_INITIALIZATION && (m->state.outputs_pending & groups)) return fmi2Error;  /* logged */
    }
    for (size_t i = 0; i < nvr; i++) value[i] = m->state.values[vr[i]];
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    if (!check_refs(m, __func__, vr, nvr, KIND(KIND_TUNABLE) | KIND(KIND_FIXED), "a Real parameter")
        || !settable_now(m, __func__, vr, nvr) || model_non_finite_values(m, __func__, vr, value, nvr))
        return fmi2Error;
    for (size_t i = 0; i < nvr; i++) m->state.values[vr[i]] = value[i];   /* checked, and applied, at the next doStep */
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    ENTER(READABLE);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    if (!check_refs(m, __func__, vr, nvr, KIND(KIND_STRING), "a String")) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = INTEGRATORS[m->state.integrator];
    return fmi2OK;
}

static int integrator_index(const char *name)
{
    for (int k = 0; k < FMU_N_INTEGRATORS; k++)
        if (name && strcmp(name, INTEGRATORS[k]) == 0) return k;
    return -1;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    if (!check_refs(m, __func__, vr, nvr, KIND(KIND_STRING), "a String") || !settable_now(m, __func__, vr, nvr))
        return fmi2Error;
    for (size_t i = 0; i < nvr; i++)
        if (integrator_index(value[i]) < 0) {
            model_log(m, MODEL_ERROR, "logStatusError", "fmi2SetString: %s '%s': integrator = '%s': must be one "
                      "of %s, %s", MECH_NAME, m->instance_name, value[i] ? value[i] : "(null)", INTEGRATORS[0], INTEGRATORS[1]);
            return fmi2Error;
        }
    for (size_t i = 0; i < nvr; i++) m->state.integrator = integrator_index(value[i]);
    return fmi2OK;
}

/* The FMU has no Integer or Boolean variables: every value reference of those types is unknown. */
static fmi2Status no_variables(ModelInstance *m, const char *function, const fmi2ValueReference vr[], size_t nvr)
{
    if (nvr == 0) return fmi2OK;
    model_log(m, MODEL_ERROR, "logStatusError", "%s: unknown value reference %u (this FMU has no variables of "
              "that type)", function, (unsigned)vr[0]);
    return fmi2Error;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    ENTER(READABLE);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return no_variables(m, __func__, vr, nvr);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return no_variables(m, __func__, vr, nvr);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    ENTER(READABLE);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return no_variables(m, __func__, vr, nvr);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return no_variables(m, __func__, vr, nvr);
}

/* -- FMU state ----------------------------------------------------------------------- */

/* Not in the error state: a state saved there could only restore the failure. */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    ENTER(ALL_STATES & ~MODE_ERROR);
    REQUIRE(FMUstate);
    if (!*FMUstate) {
        *FMUstate = allocate(m, sizeof(SavedState));
        if (!*FMUstate) {
            model_log(m, MODEL_ERROR, "logStatusError", "fmi2GetFMUstate: out of memory");
            return fmi2Error;
        }
    }
    memcpy(&((SavedState *)*FMUstate)->state, &m->state, sizeof(ModelState));
    ((SavedState *)*FMUstate)->model_exchange = m->model_exchange;
    return fmi2OK;
}

static const char *type_name(int model_exchange) { return model_exchange ? "model exchange" : "co-simulation"; }

/* Also in the error state: FMI 2.0's way to continue after a failure.  Only a state saved by an
   instance of the same type (its mode is of that type's state machine). */
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    ENTER(ALL_STATES);
    REQUIRE(FMUstate);
    const SavedState *saved = (const SavedState *)FMUstate;
    if (saved->model_exchange != m->model_exchange) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi2SetFMUstate: the FMU state was saved by a %s instance; "
                  "this instance was instantiated for %s", type_name(saved->model_exchange),
                  type_name(m->model_exchange));
        return fmi2Error;
    }
    char why[MODEL_MESSAGE];
    if (model_check_state(&saved->state, saved->model_exchange, why, sizeof why)) {    /* a corrupted state */
        model_log(m, MODEL_ERROR, "logStatusError", "fmi2SetFMUstate: the FMU state is refused: its %s", why);
        return fmi2Error;
    }
    memcpy(&m->state, &saved->state, sizeof(ModelState));
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    ENTER(ALL_STATES);
    REQUIRE(FMUstate);
    release(m, *FMUstate);   /* *FMUstate == NULL: nothing to free (FMI 2.0) */
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    ENTER(ALL_STATES);
    REQUIRE(FMUstate);
    REQUIRE(size);
    *size = model_serialized_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    ENTER(ALL_STATES);
    REQUIRE(FMUstate);
    REQUIRE(serializedState);
    if (size < model_serialized_size()) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi2SerializeFMUstate: need %u bytes (got %u)",
                  (unsigned)model_serialized_size(), (unsigned)size);
        return fmi2Error;
    }
    model_serialize((const SavedState *)FMUstate, STATE_MAGIC, (unsigned char *)serializedState);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    SavedState read;
    ENTER(ALL_STATES);
    REQUIRE(serializedState);
    REQUIRE(FMUstate);
    char why[MODEL_MESSAGE];
    const int problem = model_deserialize((const unsigned char *)serializedState, size, STATE_MAGIC, &read, why,
                                          sizeof why);
    if (problem == MODEL_WRONG_SIZE) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi2DeSerializeFMUstate: expected %u bytes, got %u",
                  (unsigned)model_serialized_size(), (unsigned)size);
        return fmi2Error;
    }
    if (problem == MODEL_INVALID) {     /* the instance is unchanged, still usable */
        model_log(m, MODEL_ERROR, "logStatusError", "fmi2DeSerializeFMUstate: the state is refused: its %s", why);
        return fmi2Error;
    }
    if (problem) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi2DeSerializeFMUstate: not a state of this FMU (GUID %s)",
                  FMU_GUID);
        return fmi2Error;
    }
    if (!*FMUstate) {
        *FMUstate = allocate(m, sizeof(SavedState));
        if (!*FMUstate) {
            model_log(m, MODEL_ERROR, "logStatusError", "fmi2DeSerializeFMUstate: out of memory");
            return fmi2Error;
        }
    }
    *(SavedState *)*FMUstate = read;
    return fmi2OK;
}

/* Model exchange only: the states' derivatives or outputs (vUnknown_ref) along a direction of the
   states (vKnown_ref, dvKnown), exact (model.h: model_me_directional).  In co-simulation the FMU
   has no inputs, so nothing to differentiate with respect to (providesDirectionalDerivative is
   false there).  In initialization mode: at the state the start values give, the states' start
   parameters also accepted as knowns (the states are initial unknowns there); a failure there
   leaves the instance in initialization mode.  The value references are checked before anything
   is computed: a refused call changes nothing. */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    Directional d;
    double probe;
    ENTER(READABLE);
    if (!m->model_exchange) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi2GetDirectionalDerivative: not provided in co-simulation "
                  "(providesDirectionalDerivative is false there: the FMU has no inputs)");
        return fmi2Error;
    }
    REQUIRE_ARRAY(vUnknown_ref, nUnknown);
    REQUIRE_ARRAY(vKnown_ref, nKnown);
    REQUIRE_ARRAY(dvKnown, nKnown);
    REQUIRE_ARRAY(dvUnknown, nUnknown);
    model_me_directional_start(&d);
    for (size_t i = 0; i < nKnown; i++)
        if (model_me_seed(m, __func__, &d, vKnown_ref[i], dvKnown[i]) != MODEL_OK) return fmi2Error;
    for (size_t i = 0; i < nUnknown; i++)
        if (model_me_sensitivity(m, __func__, &d, vUnknown_ref[i], &probe) != MODEL_OK) return fmi2Error;
    if (model_me_directional(m, &d) != MODEL_OK) {      /* logged why */
        /* in initialization mode it ran on a copy: the host may still correct the start values */
        if (m->state.mode != MODE_INITIALIZATION) m->state.mode = MODE_ERROR;
        return fmi2Error;
    }
    for (size_t i = 0; i < nUnknown; i++) model_me_sensitivity(m, __func__, &d, vUnknown_ref[i], &dvUnknown[i]);
    return fmi2OK;
}

/* -- co-simulation ------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    ENTER(SETTABLE);
    CS_ONLY;
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(order, nvr);
    REQUIRE_ARRAY(value, nvr);
    if (nvr == 0) return fmi2OK;
    model_log(m, MODEL_ERROR, "logStatusError", "fmi2SetRealInputDerivatives: the FMU has no inputs "
              "(value reference %u)", (unsigned)vr[0]);
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    ENTER(INITIALIZED);
    CS_ONLY;
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(order, nvr);
    REQUIRE_ARRAY(value, nvr);
    if (nvr == 0) return fmi2OK;
    model_log(m, MODEL_ERROR, "logStatusError",
              "fmi2GetRealOutputDerivatives: not provided (maxOutputDerivativeOrder is 0)");
    return fmi2Error;
}

/* A failure here, bad arguments included, leaves the instance in the error state. */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    ENTER(MODE_STEP_COMPLETE);
    CS_ONLY;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (model_bad_step(m, __func__, currentCommunicationPoint, communicationStepSize)) {   /* logged why */
        m->state.mode = MODE_ERROR;
        return fmi2Error;
    }
    if (model_past_stop_time(m, __func__, currentCommunicationPoint, communicationStepSize)) {   /* logged */
        m->state.mode = MODE_ERROR;
        return fmi2Error;
    }
    if (model_do_step(m, currentCommunicationPoint, communicationStepSize) != MODEL_OK) {   /* logged why */
        m->state.mode = MODE_ERROR;
        return fmi2Error;
    }
    return fmi2OK;
}

/* Only allowed in stepInProgress, which this FMU never enters (fmi2DoStep never returns
   fmi2Pending): ENTER always refuses it, naming the instance's state. */
fmi2Status fmi2CancelStep(fmi2Component c)
{
    ENTER(MODE_STEP_IN_PROGRESS);
    (void)m;
    return fmi2Error;
}

/* A status kind this FMU has no value for: those of an asynchronous fmi2DoStep, and a kind
   asked of a function of another type.  FMI 2.0 (section 2.1.3): "fmi2Discard is returned
   also if the slave is not able to return the required status information"; logged as such. */
static fmi2Status no_status(ModelInstance *m, const char *function, fmi2StatusKind s)
{
    static const char *const kinds[] = {"fmi2DoStepStatus", "fmi2PendingStatus", "fmi2LastSuccessfulTime",
                                        "fmi2Terminated"};
    model_log(m, MODEL_DISCARD, "logStatusDiscard", "%s(%s): no such status: fmi2DoStep never returns fmi2Pending, "
              "so the only status values are fmi2GetRealStatus(fmi2LastSuccessfulTime) and "
              "fmi2GetBooleanStatus(fmi2Terminated)", function,
              (unsigned)s < sizeof kinds / sizeof *kinds ? kinds[s] : "an unknown kind");
    return fmi2Discard;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    ENTER(STATUS_STATES);
    CS_ONLY;
    REQUIRE(value);
    return no_status(m, __func__, s);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    ENTER(STATUS_STATES);
    CS_ONLY;
    REQUIRE(value);
    if (s != fmi2LastSuccessfulTime) return no_status(m, __func__, s);
    *value = m->state.t;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    ENTER(STATUS_STATES);
    CS_ONLY;
    REQUIRE(value);
    return no_status(m, __func__, s);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    ENTER(STATUS_STATES);
    CS_ONLY;
    REQUIRE(value);
    if (s != fmi2Terminated) return no_status(m, __func__, s);
    *value = fmi2False;   /* the slave never asks to end the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    ENTER(STATUS_STATES);
    CS_ONLY;
    REQUIRE(value);
    return no_status(m, __func__, s);
}

/* -- model exchange ------------------------------------------------------------------ */

/* The continuous states are the file's independent coordinates, their rates and the drivers' work
   (dae.h), in the order of FMU_STATE_VRS; the FMU has no event indicators and no time events: a
   parameter set in event mode is applied by fmi2NewDiscreteStates (re-assembly keeping the
   states).  An evaluation that fails (the loop cannot be closed at the states the host set)
   leaves the instance in the error state. */

static int count_is(ModelInstance *m, const char *function, size_t n, size_t expected, const char *what)
{
    if (n == expected) return 1;
    model_log(m, MODEL_ERROR, "logStatusError", "%s: %u %s given; this FMU has %u", function, (unsigned)n, what,
              (unsigned)expected);
    return 0;
}

/* Also in event mode (FMI 2.0, section 3.2.3; fmi-standard issue #275): a host may enter it again. */
fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    ENTER(MODE_EVENT | MODE_CONTINUOUS);
    ME_ONLY;
    m->state.mode = MODE_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *fmi2eventInfo)
{
    ENTER(MODE_EVENT);
    ME_ONLY;
    REQUIRE(fmi2eventInfo);
    if (model_me_event_update(m) != MODEL_OK) {      /* logged why */
        m->state.mode = MODE_ERROR;
        return fmi2Error;
    }
    fmi2eventInfo->newDiscreteStatesNeeded = fmi2False;
    fmi2eventInfo->terminateSimulation = fmi2False;
    fmi2eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    fmi2eventInfo->valuesOfContinuousStatesChanged = fmi2False;   /* a re-assembly keeps the states */
    fmi2eventInfo->nextEventTimeDefined = fmi2False;
    fmi2eventInfo->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    ENTER(MODE_EVENT);
    ME_ONLY;
    m->state.mode = MODE_CONTINUOUS;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    ENTER(MODE_CONTINUOUS);
    ME_ONLY;
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE(enterEventMode);
    REQUIRE(terminateSimulation);
    if (model_me_completed_step(m) != MODEL_OK) {
        m->state.mode = MODE_ERROR;
        return fmi2Error;
    }
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    ENTER(MODE_EVENT | MODE_CONTINUOUS);
    ME_ONLY;
    if (!isfinite(time)) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi2SetTime: the time must be finite (got %g)", time);
        return fmi2Error;
    }
    model_me_set_time(m, time);
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    ENTER(MODE_CONTINUOUS);
    ME_ONLY;
    REQUIRE_ARRAY(x, nx);
    if (!count_is(m, __func__, nx, FMU_N_STATES, "states")) return fmi2Error;
    if (model_non_finite_states(m, __func__, x, nx)) return fmi2Error;
    model_me_set_states(m, x);
    return fmi2OK;
}

/* In initialization mode, the values the start values give (model_preview_outputs: all of them,
   or none when the start values are invalid or cannot be assembled, which
   fmi2ExitInitializationMode then reports). */
static fmi2Status from_preview(ModelInstance *m, const int *vrs, fmi2Real value[], size_t n)
{
    model_preview_outputs(m, FMU_GROUP_STATES);
    for (size_t i = 0; i < n; i++) value[i] = m->state.values[vrs[i]];
    return fmi2OK;
}

/* Not in initialization mode (FMI 2.0, section 3.2.3, as the Reference-FMUs): the derivatives
   are initial unknowns there, read by fmi2GetReal. */
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    ENTER(MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED);
    ME_ONLY;
    REQUIRE_ARRAY(derivatives, nx);
    if (!count_is(m, __func__, nx, FMU_N_STATES, "derivatives")) return fmi2Error;
    if (model_me_derivatives(m, derivatives) != MODEL_OK) {
        m->state.mode = MODE_ERROR;
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    ENTER(ME_READABLE);
    ME_ONLY;
    REQUIRE_ARRAY(eventIndicators, ni);
    return count_is(m, __func__, ni, 0, "event indicators") ? fmi2OK : fmi2Error;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    static const int STATE_VRS[] = FMU_STATE_VRS;
    ENTER(ME_READABLE);
    ME_ONLY;
    REQUIRE_ARRAY(x, nx);
    if (!count_is(m, __func__, nx, FMU_N_STATES, "states")) return fmi2Error;
    if (m->state.mode == MODE_INITIALIZATION) return from_preview(m, STATE_VRS, x, nx);
    model_me_get_states(m, x);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    ENTER(MODE_INSTANTIATED | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED);
    ME_ONLY;
    REQUIRE_ARRAY(x_nominal, nx);
    if (!count_is(m, __func__, nx, FMU_N_STATES, "nominals")) return fmi2Error;
    for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}
