/* FMI 3.0 co-simulation and model exchange interface of a mechanism's native FMU (any mechanism: model.h).
 * (In its own folder, fmu_src/native/fmi3/; the FMU's sources/ is flat: it includes model.h beside it.)
 *
 * The second thin layer over model.h, beside fmi2Functions.c and built the same way (one of the
 * two goes into a binary): it checks each call, maps value references to the model's variables,
 * and implements the FMU state functions as copies of the instance's pointer-free ModelState.
 * No global or static mutable data: instances are independent.  Scheduled Execution is not
 * offered (fmi3InstantiateScheduledExecution returns NULL with a message).
 *
 * The rules every entry point follows are fmi2Functions.c's, with FMI 3.0's state machines:
 * - ENTER, first: a NULL instance is refused with fmi3Error (no logger can be reached through
 *   it); a call that the state machine of the instance's type (co-simulation: instantiated,
 *   initializationMode, stepMode, terminated; model exchange: instantiated, initializationMode,
 *   eventMode, continuousTimeMode, terminated; both: error) does not allow in the instance's
 *   state is refused with fmi3Error and a message naming the function, the state and the states
 *   the call is allowed in.  CS_ONLY / ME_ONLY then refuse a call of the other type.
 * - REQUIRE: a NULL pointer argument the call would use is refused with fmi3Error and a message;
 *   nValues must equal nValueReferences (every variable is a scalar).
 * - A refused call changes nothing.  fmi3ExitInitializationMode, fmi3DoStep,
 *   fmi3UpdateDiscreteStates and a failed model-exchange evaluation returning fmi3Error leave the
 *   instance in the error state, where no value can be read: only fmi3Reset, fmi3FreeInstance,
 *   fmi3SetFMUState (a state saved before the failure by an instance of the same type), the other
 *   FMU-state bookkeeping calls and fmi3SetDebugLogging are accepted.
 * - The status a call returns is the worst status it logged.
 * - The FMU has Float64 variables (the Real ones of variables.h, and the independent variable
 *   `time`, value reference FMU_N_VARIABLES) and one String (`integrator`); every value reference
 *   of another type (Float32, the integers, Boolean, Binary, Clock) is refused as unknown.
 * Every message goes through the host's logMessage callback (FMI 3.0 passes no instance name:
 * messages start with it).  Memory is the C library's (FMI 3.0 has no memory callbacks).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi3Functions.h"
#include "model.h"

static const int KINDS[FMU_N_VARIABLES] = FMU_VARIABLE_KINDS;
static const char *const NAMES[FMU_N_VARIABLES] = FMU_VARIABLE_NAMES;
static const char *const INTEGRATORS[FMU_N_INTEGRATORS] = FMU_INTEGRATOR_NAMES;
static const int READ_COMPUTED[FMU_N_VARIABLES] = FMU_READ_COMPUTED;
enum { KIND_TUNABLE = 0, KIND_FIXED = 1, KIND_STRING = 2, KIND_OUTPUT = 3, KIND_LOCAL = 4, KIND_TIME = 5 };
static const char *const KIND_TEXT[] = {"a tunable Float64 parameter", "a fixed Float64 parameter", "a String parameter",
                                        "a Float64 output", "a Float64 local variable",
                                        "the independent variable (Float64)"};
#define KIND(k) (1 << (k))
/* The independent variable: FMI 3.0 requires one (causality="independent"). */
#define VR_TIME FMU_N_VARIABLES

/* -- the FMI 3.0 state machines (co-simulation and model exchange) --------------------- */

/* The states this FMU never enters, named because functions are defined for them only:
   fmi3DoStep is synchronous and never discards (stepDiscarded), there are no structural
   parameters (configurationMode, reconfigurationMode), no intermediate update and no clocks
   (intermediateUpdateMode, clockActivationMode).  MODE_STEP_COMPLETE is FMI 3.0's stepMode. */
#define MODE_STEP_DISCARDED 64
#define MODE_CONFIGURATION 512
#define MODE_RECONFIGURATION 1024
#define MODE_INTERMEDIATE_UPDATE 2048
#define MODE_CLOCK_ACTIVATION 4096

static const struct { int mode; const char *name; } STATES[] = {
    {MODE_INSTANTIATED, "instantiated"}, {MODE_CONFIGURATION, "configurationMode"},
    {MODE_INITIALIZATION, "initializationMode"}, {MODE_EVENT, "eventMode"},
    {MODE_CONTINUOUS, "continuousTimeMode"}, {MODE_STEP_COMPLETE, "stepMode"},
    {MODE_STEP_DISCARDED, "stepDiscarded"}, {MODE_RECONFIGURATION, "reconfigurationMode"},
    {MODE_INTERMEDIATE_UPDATE, "intermediateUpdateMode"}, {MODE_CLOCK_ACTIVATION, "clockActivationMode"},
    {MODE_TERMINATED, "terminated"}, {MODE_ERROR, "error"}};
#define N_STATES (sizeof STATES / sizeof *STATES)

/* Where each group of calls is allowed (FMI 3.0, sections 3.2 and 4.2, as the Reference-FMUs'
   masks, except that no value can be read in the error state and, as in fmi2Functions.c, none in
   instantiated).  An instance is in the states of its type only. */
#define ALL_STATES (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_EVENT | MODE_CONTINUOUS | \
                    MODE_TERMINATED | MODE_ERROR)
#define READABLE (MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)
/* fmi3Get{VariableType}: also in instantiated (FMI 3.0, 2.3.2; unlike FMI 2.0, whose getters
   start in initialization mode): the start values, and the outputs and states they give */
#define GETTABLE (MODE_INSTANTIATED | READABLE)
/* fmi3SetXXX: parameters only (the FMU has no inputs), so not in continuousTimeMode */
#define SETTABLE (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_EVENT)
#define ME_READABLE (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)

/* What the layer keeps of the host: FMI 3.0 gives a logger only.  ModelInstance.host points here. */
typedef struct {
    fmi3LogMessageCallback log_message;
} Host;

/* An instance: the model's, and the host it was given (one allocation, freed together). */
typedef struct {
    ModelInstance model;
    Host host;
} Instance;

/* The mark of this layer's serialized FMU states (saved_state.c): the FMI 2.0 layer's differs. */
static const char STATE_MAGIC[8] = "FBSTAT3";

/* Every message goes through the host's logger: errors and warnings always, information
   (status OK) only with logging on. */
void model_log(ModelInstance *m, ModelStatus status, const char *category, const char *fmt, ...)
{
    char text[1024];
    int used;
    va_list args;
    const Host *host = m ? (const Host *)m->host : NULL;
    if (!host || !host->log_message) return;
    if (status == MODEL_OK && !m->logging_on) return;
    used = snprintf(text, sizeof text, "%s: ", m->instance_name ? m->instance_name : "");
    if (used < 0 || (size_t)used >= sizeof text) used = 0;
    va_start(args, fmt);
    vsnprintf(text + used, sizeof text - (size_t)used, fmt, args);
    va_end(args);
    host->log_message(m->environment, (fmi3Status)status, category, text);
}

static const char *state_name(int mode)
{
    for (size_t i = 0; i < N_STATES; i++)
        if (STATES[i].mode == mode) return STATES[i].name;
    return "(unknown)";
}

/* 1 when `function` may be called in the instance's state; else logs why and returns 0. */
static int allowed(ModelInstance *m, const char *function, int states)
{
    char list[300];
    size_t used = 0;
    if (!m) return 0;
    if (m->state.mode & states) return 1;
    list[0] = '\0';
    for (size_t i = 0; i < N_STATES; i++)
        if ((states & STATES[i].mode) && used < sizeof list)
            used += snprintf(list + used, sizeof list - used, "%s%s", used ? ", " : "", STATES[i].name);
    model_log(m, MODEL_ERROR, "logStatusError", "%s is not allowed in state %s (only in: %s)%s", function,
              state_name(m->state.mode), list, m->state.mode == MODE_ERROR ?
              "; after a failed fmi3ExitInitializationMode, fmi3DoStep or model-exchange call, call fmi3Reset, "
              "fmi3SetFMUState or fmi3FreeInstance" : "");
    return 0;
}

#define ENTER(states) \
    ModelInstance *const m = (ModelInstance *)instance; \
    if (!allowed(m, __func__, (states))) return fmi3Error

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

static const char *type_name(int model_exchange) { return model_exchange ? "model exchange" : "co-simulation"; }

static int of_type(ModelInstance *m, const char *function, int model_exchange)
{
    if (m->model_exchange == model_exchange) return 1;
    model_log(m, MODEL_ERROR, "logStatusError", "%s is a %s function; this instance was instantiated for %s", function,
              type_name(model_exchange), type_name(m->model_exchange));
    return 0;
}

#define CS_ONLY if (!of_type(m, __func__, 0)) return fmi3Error
#define ME_ONLY if (!of_type(m, __func__, 1)) return fmi3Error
#define REQUIRE(p) if (!present(m, __func__, (const void *)(p), #p, 0)) return fmi3Error
#define REQUIRE_ARRAY(p, n) if ((n) > 0 && !present(m, __func__, (const void *)(p), #p, (n))) return fmi3Error

static int count_is(ModelInstance *m, const char *function, size_t n, size_t expected, const char *what)
{
    if (n == expected) return 1;
    model_log(m, MODEL_ERROR, "logStatusError", "%s: %u %s given; expected %u", function, (unsigned)n, what,
              (unsigned)expected);
    return 0;
}

/* Every variable is a scalar: one value per value reference. */
#define SCALARS(nvr, nValues) \
    if (!count_is(m, __func__, (nValues), (nvr), "values for as many scalar value references")) return fmi3Error

static int kind_of(fmi3ValueReference vr) { return vr == VR_TIME ? KIND_TIME : KINDS[vr]; }
static const char *name_of(fmi3ValueReference vr) { return vr == VR_TIME ? "time" : NAMES[vr]; }

/* 1 when every vr[i] is a variable of one of `kinds`; else logs the first that is not. */
static int check_refs(ModelInstance *m, const char *function, const fmi3ValueReference vr[], size_t nvr, int kinds,
                      const char *expected)
{
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] > VR_TIME) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: unknown value reference %u", function, (unsigned)vr[i]);
            return 0;
        }
        if (!(kinds & KIND(kind_of(vr[i])))) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: %s (value reference %u) is %s; expected %s", function,
                      name_of(vr[i]), (unsigned)vr[i], KIND_TEXT[kind_of(vr[i])], expected);
            return 0;
        }
    }
    return 1;
}

/* Fixed parameters (and the String integrator) can be set only before initialization ends. */
static int settable_now(ModelInstance *m, const char *function, const fmi3ValueReference vr[], size_t nvr)
{
    if (m->state.mode != MODE_STEP_COMPLETE && m->state.mode != MODE_EVENT) return 1;
    for (size_t i = 0; i < nvr; i++)
        if (KINDS[vr[i]] == KIND_FIXED || KINDS[vr[i]] == KIND_STRING) {
            model_log(m, MODEL_ERROR, "logStatusError", "%s: %s is a fixed parameter; it can only be set before "
                      "fmi3ExitInitializationMode (the instance is in state %s)", function, NAMES[vr[i]],
                      state_name(m->state.mode));
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

/* -- inquiry ------------------------------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
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
            model_log(m, MODEL_ERROR, "logStatusError", "fmi3SetDebugLogging: unknown log category '%s'",
                      categories[i] ? categories[i] : "(null)");
            return fmi3Error;
        }
    }
    m->logging_on = loggingOn ? 1 : 0;
    return fmi3OK;
}

/* -- life cycle ---------------------------------------------------------------------- */

/* A new instance, or NULL after logging why (the token names another build, an empty name). */
static fmi3Instance instantiate(const char *function, fmi3String instanceName, fmi3String instantiationToken,
                                fmi3Boolean loggingOn, fmi3InstanceEnvironment environment,
                                fmi3LogMessageCallback logMessage, int model_exchange)
{
    Instance probe;
    const char *name = instanceName ? instanceName : "";
    memset(&probe, 0, sizeof probe);
    probe.host.log_message = logMessage;
    probe.model.host = &probe.host;
    probe.model.environment = environment;
    probe.model.instance_name = (char *)name;
    if (!instanceName || !instanceName[0]) {
        model_log(&probe.model, MODEL_ERROR, "logStatusError", "%s: the instance name must not be empty", function);
        return NULL;
    }
    if (!instantiationToken || strcmp(instantiationToken, FMU_GUID) != 0) {
        model_log(&probe.model, MODEL_ERROR, "logStatusError", "%s: instantiation token '%s' does not match this "
                  "binary's '%s' (a model description from another build?)", function,
                  instantiationToken ? instantiationToken : "(null)", FMU_GUID);
        return NULL;
    }
    Instance *created = (Instance *)calloc(1, sizeof(Instance));
    char *copy = (char *)malloc(strlen(name) + 1);
    if (!created || !copy) {
        free(created);
        free(copy);
        model_log(&probe.model, MODEL_ERROR, "logStatusError", "%s: out of memory", function);
        return NULL;
    }
    created->host.log_message = logMessage;
    ModelInstance *m = &created->model;
    m->host = &created->host;
    m->environment = environment;
    m->instance_name = strcpy(copy, name);
    m->logging_on = loggingOn ? 1 : 0;
    m->model_exchange = model_exchange;
    model_reset(m);
    return created;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)resourcePath;
    (void)visible;
    return instantiate(__func__, instanceName, instantiationToken, loggingOn, instanceEnvironment, logMessage, 1);
}

/* Event mode is not offered in co-simulation (hasEventMode is false: the FMU has no events) and
   neither is intermediate update (providesIntermediateUpdate is false); earlyReturnAllowed is
   accepted, fmi3DoStep never returns early. */
fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)resourcePath;
    (void)visible;
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    if (eventModeUsed || nRequiredIntermediateVariables > 0) {
        Instance probe;
        memset(&probe, 0, sizeof probe);
        probe.host.log_message = logMessage;
        probe.model.host = &probe.host;
        probe.model.environment = instanceEnvironment;
        probe.model.instance_name = (char *)(instanceName ? instanceName : "");
        model_log(&probe.model, MODEL_ERROR, "logStatusError", "%s: %s", __func__, eventModeUsed ?
                  "eventModeUsed must be false: this FMU has no event mode in co-simulation (hasEventMode is false)" :
                  "this FMU provides no intermediate update (providesIntermediateUpdate is false): "
                  "nRequiredIntermediateVariables must be 0");
        return NULL;
    }
    return instantiate(__func__, instanceName, instantiationToken, loggingOn, instanceEnvironment, logMessage, 0);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    Instance probe;
    (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    memset(&probe, 0, sizeof probe);
    probe.host.log_message = logMessage;
    probe.model.host = &probe.host;
    probe.model.environment = instanceEnvironment;
    probe.model.instance_name = (char *)(instanceName ? instanceName : "");
    model_log(&probe.model, MODEL_ERROR, "logStatusError", "fmi3InstantiateScheduledExecution: this FMU offers "
              "Co-Simulation and Model Exchange, not Scheduled Execution");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    Instance *created = (Instance *)instance;    /* allowed in every state; NULL is ignored */
    if (!created) return;
    free(created->model.instance_name);
    free(created);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    ENTER(MODE_INSTANTIATED);
    (void)toleranceDefined;   /* the integrator's tolerances are the rtol and atol parameters */
    (void)tolerance;
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi3EnterInitializationMode: need a finite start time and a "
                  "stop time not before it (got start %g s, stop %g s)", startTime, stopTime);
        return fmi3Error;
    }
    m->state.start_time = startTime;
    m->state.stop_time = stopTimeDefined ? stopTime : INFINITY;
    m->state.mode = MODE_INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    ENTER(MODE_INITIALIZATION);
    if (model_initialize(m) != MODEL_OK) {   /* model_initialize logged why */
        m->state.mode = MODE_ERROR;
        return fmi3Error;
    }
    m->state.mode = m->model_exchange ? MODE_EVENT : MODE_STEP_COMPLETE;
    return fmi3OK;
}

/* Model exchange: from continuousTimeMode only (FMI 3.0, 3.2.1; FMI 2.0's layer also accepts it
   in eventMode, after that standard's errata).  A co-simulation instance never enters event mode
   (hasEventMode false). */
fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    ENTER(MODE_CONTINUOUS);
    ME_ONLY;
    m->state.mode = MODE_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    ENTER(MODE_STEP_COMPLETE | MODE_EVENT | MODE_CONTINUOUS);
    m->state.mode = MODE_TERMINATED;
    model_log(m, MODEL_OK, "logAll", "statistics at t = %.9g s: %lu right-hand-side evaluations (%lu on the full system), %lu by "
              "continuation from the last accepted state, %lu at trial points not reached (their steps "
              "rejected); %lu Newton-Raphson iterations, %lu integrator starts, %lu re-partitions; at most %lu "
              "right-hand-side evaluations in one communication step (max_evaluations = %.17g)", m->state.t,
              m->state.rhs_evaluations, m->state.full_evaluations, m->state.continuations,
              m->state.failed_evaluations, m->state.newton_iterations, m->state.starts, m->state.repartitions,
              m->state.most_step_evaluations, m->state.values[VR_max_evaluations]);
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    ENTER(ALL_STATES);
    model_reset(m);
    return fmi3OK;
}

/* -- variables ----------------------------------------------------------------------- */

static int groups_read(const fmi3ValueReference vr[], size_t nvr)
{
    int groups = 0;
    for (size_t i = 0; i < nvr; i++)
        if (vr[i] != VR_TIME) groups |= READ_COMPUTED[vr[i]];
    return groups;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues)
{
    ENTER(GETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValues);
    SCALARS(nValueReferences, nValues);
    if (!check_refs(m, __func__, valueReferences, nValueReferences, KIND(KIND_TUNABLE) | KIND(KIND_FIXED) |
                    KIND(KIND_OUTPUT) | KIND(KIND_LOCAL) | KIND(KIND_TIME), "a Float64"))
        return fmi3Error;
    const int groups = nValueReferences > 0 ? groups_read(valueReferences, nValueReferences) &
                                              m->state.outputs_pending : 0;
    const int before_start = m->state.mode == MODE_INSTANTIATED || m->state.mode == MODE_INITIALIZATION;
    if (model_few_outputs(m, groups, nValueReferences)) {
        for (size_t i = 0; i < nValueReferences; i++)
            if (valueReferences[i] != VR_TIME) model_output_one(m, valueReferences[i]);
    } else if (nValueReferences > 0 && (before_start || groups)) {
        model_preview_outputs(m, groups);      /* before the start: what the start values give */
        if (!before_start && (m->state.outputs_pending & groups)) return fmi3Error;  /* logged */
    }
    for (size_t i = 0; i < nValueReferences; i++)
        values[i] = valueReferences[i] == VR_TIME ? model_time(m) : m->state.values[valueReferences[i]];
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues)
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValues);
    SCALARS(nValueReferences, nValues);
    if (!check_refs(m, __func__, valueReferences, nValueReferences, KIND(KIND_TUNABLE) | KIND(KIND_FIXED),
                    "a Float64 parameter")
        || !settable_now(m, __func__, valueReferences, nValueReferences)
        || model_non_finite_values(m, __func__, valueReferences, values, nValueReferences))
        return fmi3Error;
    for (size_t i = 0; i < nValueReferences; i++)        /* checked, and applied, at the next doStep or event update */
        m->state.values[valueReferences[i]] = values[i];
    return fmi3OK;
}

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         fmi3String values[], size_t nValues)
{
    ENTER(GETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValues);
    SCALARS(nValueReferences, nValues);
    if (!check_refs(m, __func__, valueReferences, nValueReferences, KIND(KIND_STRING), "a String")) return fmi3Error;
    for (size_t i = 0; i < nValueReferences; i++) values[i] = INTEGRATORS[m->state.integrator];
    return fmi3OK;
}

static int integrator_index(const char *name)
{
    for (int k = 0; k < FMU_N_INTEGRATORS; k++)
        if (name && strcmp(name, INTEGRATORS[k]) == 0) return k;
    return -1;
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const fmi3String values[], size_t nValues)
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValues);
    SCALARS(nValueReferences, nValues);
    if (!check_refs(m, __func__, valueReferences, nValueReferences, KIND(KIND_STRING), "a String")
        || !settable_now(m, __func__, valueReferences, nValueReferences))
        return fmi3Error;
    for (size_t i = 0; i < nValueReferences; i++)
        if (integrator_index(values[i]) < 0) {
            model_log(m, MODEL_ERROR, "logStatusError", "fmi3SetString: %s '%s': integrator = '%s': must be one "
                      "of %s, %s", MECH_NAME, m->instance_name, values[i] ? values[i] : "(null)", INTEGRATORS[0],
                      INTEGRATORS[1]);
            return fmi3Error;
        }
    for (size_t i = 0; i < nValueReferences; i++) m->state.integrator = integrator_index(values[i]);
    return fmi3OK;
}

/* The types this FMU has no variables of: every value reference is unknown. */
static fmi3Status no_variables(ModelInstance *m, const char *function, const fmi3ValueReference vr[], size_t nvr,
                               const char *type)
{
    if (nvr == 0) return fmi3OK;
    model_log(m, MODEL_ERROR, "logStatusError", "%s: unknown value reference %u (this FMU has no %s variables)",
              function, (unsigned)vr[0], type);
    return fmi3Error;
}

#define NO_VARIABLES_GET(NAME, CTYPE, TYPE) \
fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences, \
                CTYPE values[], size_t nValues) \
{ \
    ENTER(GETTABLE); \
    REQUIRE_ARRAY(valueReferences, nValueReferences); \
    REQUIRE_ARRAY(values, nValues); \
    return no_variables(m, __func__, valueReferences, nValueReferences, TYPE); \
}
#define NO_VARIABLES_SET(NAME, CTYPE, TYPE) \
fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences, \
                const CTYPE values[], size_t nValues) \
{ \
    ENTER(SETTABLE); \
    REQUIRE_ARRAY(valueReferences, nValueReferences); \
    REQUIRE_ARRAY(values, nValues); \
    return no_variables(m, __func__, valueReferences, nValueReferences, TYPE); \
}

NO_VARIABLES_GET(fmi3GetFloat32, fmi3Float32, "Float32")
NO_VARIABLES_GET(fmi3GetInt8, fmi3Int8, "Int8")
NO_VARIABLES_GET(fmi3GetUInt8, fmi3UInt8, "UInt8")
NO_VARIABLES_GET(fmi3GetInt16, fmi3Int16, "Int16")
NO_VARIABLES_GET(fmi3GetUInt16, fmi3UInt16, "UInt16")
NO_VARIABLES_GET(fmi3GetInt32, fmi3Int32, "Int32")
NO_VARIABLES_GET(fmi3GetUInt32, fmi3UInt32, "UInt32")
NO_VARIABLES_GET(fmi3GetInt64, fmi3Int64, "Int64")
NO_VARIABLES_GET(fmi3GetUInt64, fmi3UInt64, "UInt64")
NO_VARIABLES_GET(fmi3GetBoolean, fmi3Boolean, "Boolean")
NO_VARIABLES_SET(fmi3SetFloat32, fmi3Float32, "Float32")
NO_VARIABLES_SET(fmi3SetInt8, fmi3Int8, "Int8")
NO_VARIABLES_SET(fmi3SetUInt8, fmi3UInt8, "UInt8")
NO_VARIABLES_SET(fmi3SetInt16, fmi3Int16, "Int16")
NO_VARIABLES_SET(fmi3SetUInt16, fmi3UInt16, "UInt16")
NO_VARIABLES_SET(fmi3SetInt32, fmi3Int32, "Int32")
NO_VARIABLES_SET(fmi3SetUInt32, fmi3UInt32, "UInt32")
NO_VARIABLES_SET(fmi3SetInt64, fmi3Int64, "Int64")
NO_VARIABLES_SET(fmi3SetUInt64, fmi3UInt64, "UInt64")
NO_VARIABLES_SET(fmi3SetBoolean, fmi3Boolean, "Boolean")

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    ENTER(GETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(valueSizes, nValues);
    REQUIRE_ARRAY(values, nValues);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Binary");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(valueSizes, nValues);
    REQUIRE_ARRAY(values, nValues);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Binary");
}

/* -- clocks: the FMU has none ---------------------------------------------------------- */

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[])
{
    ENTER(READABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValueReferences);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[])
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValueReferences);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    ENTER(READABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(intervals, nValueReferences);
    REQUIRE_ARRAY(qualifiers, nValueReferences);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    ENTER(READABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(counters, nValueReferences);
    REQUIRE_ARRAY(resolutions, nValueReferences);
    REQUIRE_ARRAY(qualifiers, nValueReferences);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    ENTER(READABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(shifts, nValueReferences);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    ENTER(READABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(counters, nValueReferences);
    REQUIRE_ARRAY(resolutions, nValueReferences);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(intervals, nValueReferences);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(counters, nValueReferences);
    REQUIRE_ARRAY(resolutions, nValueReferences);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(shifts, nValueReferences);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    ENTER(SETTABLE);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(counters, nValueReferences);
    REQUIRE_ARRAY(resolutions, nValueReferences);
    return no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

/* Scheduled Execution only: in clockActivationMode, which this FMU never enters. */
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    ENTER(MODE_CLOCK_ACTIVATION);
    (void)m; (void)clockReference; (void)activationTime;
    return fmi3Error;
}

/* -- what the FMU does not provide ----------------------------------------------------- */

static fmi3Status not_provided(ModelInstance *m, const char *function, const char *why)
{
    model_log(m, MODEL_ERROR, "logStatusError", "%s: not provided (%s)", function, why);
    return fmi3Error;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    ENTER(ALL_STATES & ~MODE_ERROR);
    (void)valueReference;
    REQUIRE(nDependencies);
    return not_provided(m, __func__, "providesPerElementDependencies is false: the dependencies are "
                        "modelDescription.xml's <ModelStructure>");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    ENTER(ALL_STATES & ~MODE_ERROR);
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    return not_provided(m, __func__, "providesPerElementDependencies is false: the dependencies are "
                        "modelDescription.xml's <ModelStructure>");
}

/* Model exchange only: the states' derivatives or outputs (unknowns) along a direction of the
   states (knowns, seed), exact (model.h: model_me_directional; in initializationMode at the state
   the start values give, the states' start parameters also accepted as knowns, and a failure
   leaves the instance in initializationMode).  In co-simulation the FMU has no inputs (providesDirectionalDerivatives
   is false there).  Every value reference is checked before anything is computed. */
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    Directional d;
    double probe;
    ENTER(READABLE);
    if (!m->model_exchange)
        return not_provided(m, __func__, "in co-simulation: providesDirectionalDerivatives is false there, the FMU "
                            "has no inputs");
    REQUIRE_ARRAY(unknowns, nUnknowns);
    REQUIRE_ARRAY(knowns, nKnowns);
    REQUIRE_ARRAY(seed, nSeed);
    REQUIRE_ARRAY(sensitivity, nSensitivity);
    if (!count_is(m, __func__, nSeed, nKnowns, "seeds (one per known: every variable is a scalar)")) return fmi3Error;
    if (!count_is(m, __func__, nSensitivity, nUnknowns, "sensitivities (one per unknown: every variable is a scalar)"))
        return fmi3Error;
    model_me_directional_start(&d);
    for (size_t i = 0; i < nKnowns; i++)
        if (model_me_seed(m, __func__, &d, knowns[i], seed[i]) != MODEL_OK) return fmi3Error;
    for (size_t i = 0; i < nUnknowns; i++)
        if (model_me_sensitivity(m, __func__, &d, unknowns[i], &probe) != MODEL_OK) return fmi3Error;
    if (model_me_directional(m, &d) != MODEL_OK) {      /* logged why */
        /* in initialization mode it ran on a copy: the host may still correct the start values */
        if (m->state.mode != MODE_INITIALIZATION) m->state.mode = MODE_ERROR;
        return fmi3Error;
    }
    for (size_t i = 0; i < nUnknowns; i++) model_me_sensitivity(m, __func__, &d, unknowns[i], &sensitivity[i]);
    return fmi3OK;
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    ENTER(READABLE);
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    return not_provided(m, __func__, "providesAdjointDerivatives is false");
}

/* The FMU has no structural parameters: configuration mode is never entered. */
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    ENTER(MODE_INSTANTIATED | MODE_STEP_COMPLETE | MODE_EVENT);
    return not_provided(m, __func__, "this FMU has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    ENTER(MODE_CONFIGURATION | MODE_RECONFIGURATION);
    (void)m;
    return fmi3Error;
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    ENTER(ALL_STATES & ~MODE_ERROR);
    return not_provided(m, __func__, "providesEvaluateDiscreteStates is false: the FMU has no discrete states");
}

/* -- FMU state ----------------------------------------------------------------------- */

/* Not in the error state: a state saved there could only restore the failure. */
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    ENTER(ALL_STATES & ~MODE_ERROR);
    REQUIRE(FMUState);
    if (!*FMUState) {
        *FMUState = calloc(1, sizeof(SavedState));
        if (!*FMUState) {
            model_log(m, MODEL_ERROR, "logStatusError", "fmi3GetFMUState: out of memory");
            return fmi3Error;
        }
    }
    memcpy(&((SavedState *)*FMUState)->state, &m->state, sizeof(ModelState));
    ((SavedState *)*FMUState)->model_exchange = m->model_exchange;
    return fmi3OK;
}

/* Also in the error state: the way to continue after a failure.  Only a state saved by an
   instance of the same type (its mode is of that type's state machine). */
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    ENTER(ALL_STATES);
    REQUIRE(FMUState);
    const SavedState *saved = (const SavedState *)FMUState;
    if (saved->model_exchange != m->model_exchange) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi3SetFMUState: the FMU state was saved by a %s instance; "
                  "this instance was instantiated for %s", type_name(saved->model_exchange),
                  type_name(m->model_exchange));
        return fmi3Error;
    }
    char why[MODEL_MESSAGE];
    if (model_check_state(&saved->state, saved->model_exchange, why, sizeof why)) {    /* a corrupted state */
        model_log(m, MODEL_ERROR, "logStatusError", "fmi3SetFMUState: the FMU state is refused: its %s", why);
        return fmi3Error;
    }
    memcpy(&m->state, &saved->state, sizeof(ModelState));
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    ENTER(ALL_STATES);
    REQUIRE(FMUState);
    free(*FMUState);   /* *FMUState == NULL: nothing to free */
    *FMUState = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    ENTER(ALL_STATES);
    REQUIRE(FMUState);
    REQUIRE(size);
    *size = model_serialized_size();
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    ENTER(ALL_STATES);
    REQUIRE(FMUState);
    REQUIRE(serializedState);
    if (size < model_serialized_size()) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi3SerializeFMUState: need %u bytes (got %u)",
                  (unsigned)model_serialized_size(), (unsigned)size);
        return fmi3Error;
    }
    model_serialize((const SavedState *)FMUState, STATE_MAGIC, (unsigned char *)serializedState);
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    SavedState read;
    ENTER(ALL_STATES);
    REQUIRE(serializedState);
    REQUIRE(FMUState);
    char why[MODEL_MESSAGE];
    const int problem = model_deserialize((const unsigned char *)serializedState, size, STATE_MAGIC, &read, why,
                                          sizeof why);
    if (problem == MODEL_WRONG_SIZE) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi3DeserializeFMUState: expected %u bytes, got %u",
                  (unsigned)model_serialized_size(), (unsigned)size);
        return fmi3Error;
    }
    if (problem == MODEL_INVALID) {     /* the instance is unchanged, still usable */
        model_log(m, MODEL_ERROR, "logStatusError", "fmi3DeserializeFMUState: the state is refused: its %s", why);
        return fmi3Error;
    }
    if (problem) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi3DeserializeFMUState: not a state of this FMU (instantiation token %s)",
                  FMU_GUID);
        return fmi3Error;
    }
    if (!*FMUState) {
        *FMUState = calloc(1, sizeof(SavedState));
        if (!*FMUState) {
            model_log(m, MODEL_ERROR, "logStatusError", "fmi3DeserializeFMUState: out of memory");
            return fmi3Error;
        }
    }
    *(SavedState *)*FMUState = read;
    return fmi3OK;
}

/* -- co-simulation ------------------------------------------------------------------- */

/* Only from eventMode, which a co-simulation instance of this FMU never enters (hasEventMode false). */
fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    ENTER(MODE_EVENT);
    CS_ONLY;
    return fmi3Error;      /* unreachable: an instance in eventMode is a model-exchange one */
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    ENTER(MODE_STEP_COMPLETE | MODE_TERMINATED);
    CS_ONLY;
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(orders, nValueReferences);
    REQUIRE_ARRAY(values, nValues);
    SCALARS(nValueReferences, nValues);
    if (nValueReferences == 0) return fmi3OK;
    return not_provided(m, __func__, "maxOutputDerivativeOrder is 0");
}

/* A failed step, a step size that is not positive and a step past a defined stop time leave the
   instance in the error state; NULL output pointers are refused changing nothing (as every
   refused call).  The step is synchronous and complete: no event, no early return, the simulation
   never asked to end. */
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    ENTER(MODE_STEP_COMPLETE);
    CS_ONLY;
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE(eventHandlingNeeded);
    REQUIRE(terminateSimulation);
    REQUIRE(earlyReturn);
    REQUIRE(lastSuccessfulTime);
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = m->state.t;
    if (model_bad_step(m, __func__, currentCommunicationPoint, communicationStepSize)) {   /* logged why */
        m->state.mode = MODE_ERROR;
        return fmi3Error;
    }
    if (model_past_stop_time(m, __func__, currentCommunicationPoint, communicationStepSize)) {   /* logged */
        m->state.mode = MODE_ERROR;
        return fmi3Error;
    }
    if (model_do_step(m, currentCommunicationPoint, communicationStepSize) != MODEL_OK) {   /* logged why */
        m->state.mode = MODE_ERROR;
        return fmi3Error;
    }
    *lastSuccessfulTime = m->state.t;
    return fmi3OK;
}

/* -- model exchange ------------------------------------------------------------------ */

/* As fmi2Functions.c: the continuous states are the file's independent coordinates, their rates
   and the drivers' work, in the order of FMU_STATE_VRS; no event indicators, no time events; a
   parameter set in event mode is applied by fmi3UpdateDiscreteStates (re-assembly keeping the
   states).  An evaluation that fails leaves the instance in the error state. */

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    ENTER(MODE_EVENT);
    ME_ONLY;
    REQUIRE(discreteStatesNeedUpdate);
    REQUIRE(terminateSimulation);
    REQUIRE(nominalsOfContinuousStatesChanged);
    REQUIRE(valuesOfContinuousStatesChanged);
    REQUIRE(nextEventTimeDefined);
    REQUIRE(nextEventTime);
    if (model_me_event_update(m) != MODEL_OK) {      /* logged why */
        m->state.mode = MODE_ERROR;
        return fmi3Error;
    }
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;   /* a re-assembly keeps the states */
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    ENTER(MODE_EVENT);
    ME_ONLY;
    m->state.mode = MODE_CONTINUOUS;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    ENTER(MODE_CONTINUOUS);
    ME_ONLY;
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE(enterEventMode);
    REQUIRE(terminateSimulation);
    if (model_me_completed_step(m) != MODEL_OK) {
        m->state.mode = MODE_ERROR;
        return fmi3Error;
    }
    *enterEventMode = fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    ENTER(MODE_EVENT | MODE_CONTINUOUS);
    ME_ONLY;
    if (!isfinite(time)) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi3SetTime: the time must be finite (got %g)", time);
        return fmi3Error;
    }
    model_me_set_time(m, time);
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    ENTER(MODE_CONTINUOUS);
    ME_ONLY;
    REQUIRE_ARRAY(continuousStates, nContinuousStates);
    if (!count_is(m, __func__, nContinuousStates, FMU_N_STATES, "states")) return fmi3Error;
    if (model_non_finite_states(m, __func__, continuousStates, nContinuousStates)) return fmi3Error;
    model_me_set_states(m, continuousStates);
    return fmi3OK;
}

/* In initialization mode, the values the start values give (model_preview_outputs: all of them,
   or none when the start values are invalid or cannot be assembled, which
   fmi3ExitInitializationMode then reports). */
static fmi3Status from_preview(ModelInstance *m, const int *vrs, fmi3Float64 value[], size_t n)
{
    model_preview_outputs(m, FMU_GROUP_STATES);
    for (size_t i = 0; i < n; i++) value[i] = m->state.values[vrs[i]];
    return fmi3OK;
}

/* FMI 3.0 (as the Reference-FMUs) allows the derivatives in initializationMode too. */
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    static const int DERIVATIVE_VRS[] = FMU_DERIVATIVE_VRS;
    ENTER(ME_READABLE);
    ME_ONLY;
    REQUIRE_ARRAY(derivatives, nContinuousStates);
    if (!count_is(m, __func__, nContinuousStates, FMU_N_STATES, "derivatives")) return fmi3Error;
    if (m->state.mode == MODE_INITIALIZATION) return from_preview(m, DERIVATIVE_VRS, derivatives, nContinuousStates);
    if (model_me_derivatives(m, derivatives) != MODEL_OK) {
        m->state.mode = MODE_ERROR;
        return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    ENTER(ME_READABLE);
    ME_ONLY;
    REQUIRE_ARRAY(eventIndicators, nEventIndicators);
    return count_is(m, __func__, nEventIndicators, 0, "event indicators") ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates)
{
    static const int STATE_VRS[] = FMU_STATE_VRS;
    ENTER(ME_READABLE);
    ME_ONLY;
    REQUIRE_ARRAY(continuousStates, nContinuousStates);
    if (!count_is(m, __func__, nContinuousStates, FMU_N_STATES, "states")) return fmi3Error;
    if (m->state.mode == MODE_INITIALIZATION) return from_preview(m, STATE_VRS, continuousStates, nContinuousStates);
    model_me_get_states(m, continuousStates);
    return fmi3OK;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates)
{
    ENTER(ME_READABLE);
    ME_ONLY;
    REQUIRE_ARRAY(nominals, nContinuousStates);
    if (!count_is(m, __func__, nContinuousStates, FMU_N_STATES, "nominals")) return fmi3Error;
    for (size_t i = 0; i < nContinuousStates; i++) nominals[i] = 1.0;
    return fmi3OK;
}

/* Structural: answered in every state, the error state included. */
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    ENTER(ALL_STATES);
    ME_ONLY;
    REQUIRE(nEventIndicators);
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    ENTER(ALL_STATES);
    ME_ONLY;
    REQUIRE(nContinuousStates);
    *nContinuousStates = FMU_N_STATES;
    return fmi3OK;
}
