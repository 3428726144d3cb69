/* FMI 2.0 co-simulation interface of the native FourBar FMU.
 *
 * A thin layer over model.h: it checks each call against the FMI 2.0 state machine, maps
 * value references to the model's variables, and implements the FMU state functions as
 * copies of the instance's pointer-free ModelState.  Every message goes through the host's
 * logger callback.  No global or static mutable data: instances are independent.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "model.h"

static const int KINDS[FB_N_VARIABLES] = FB_VARIABLE_KINDS;
static const char *const NAMES[FB_N_VARIABLES] = FB_VARIABLE_NAMES;
static const char *const INTEGRATORS[FB_N_INTEGRATORS] = FB_INTEGRATOR_NAMES;
enum { KIND_TUNABLE = 0, KIND_FIXED = 1, KIND_STRING = 2, KIND_OUTPUT = 3 };

#define ANY_MODE (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_STEP_FAILED | \
                  MODE_TERMINATED | MODE_ERROR)
#define GET_MODES (MODE_INITIALIZATION | MODE_STEP_COMPLETE | MODE_STEP_FAILED | MODE_TERMINATED | MODE_ERROR)
#define SET_MODES (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP_COMPLETE)

/* Serialized FMU state: this header, then the ModelState's bytes. */
typedef struct {
    char magic[8];
    unsigned int state_size;
    char guid[48];
} StateHeader;
static const char STATE_MAGIC[8] = "FBSTATE";

/* Every message goes through the host's logger: errors and warnings always, information
   (status OK) only with logging on.  The text is formatted here and passed as "%s". */
void model_log(ModelInstance *m, fmi2Status status, const char *category, const char *fmt, ...)
{
    char text[1024];
    va_list args;
    if (!m->functions || !m->functions->logger) return;
    if (status == fmi2OK && !m->logging_on) return;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    m->functions->logger(m->environment, m->instance_name, status, category, "%s", text);
}

static const char *mode_name(ModelMode mode)
{
    switch (mode) {
    case MODE_INSTANTIATED: return "instantiated";
    case MODE_INITIALIZATION: return "initialization mode";
    case MODE_STEP_COMPLETE: return "step mode";
    case MODE_STEP_FAILED: return "step failed";
    case MODE_TERMINATED: return "terminated";
    default: return "error";
    }
}

/* 1 when `function` may be called in the instance's mode, else logs why and returns 0. */
static int allowed(ModelInstance *m, const char *function, int modes)
{
    if (!m) return 0;
    if (m->state.mode & modes) return 1;
    model_log(m, fmi2Error, "logStatusError", "%s is not allowed in %s", function, mode_name(m->state.mode));
    return 0;
}

static void *allocate(const ModelInstance *m, size_t size)
{
    if (m && m->functions && m->functions->allocateMemory) return m->functions->allocateMemory(1, size);
    return calloc(1, size);
}

static void release(const ModelInstance *m, void *p)
{
    if (!p) return;
    if (m && m->functions && m->functions->freeMemory) m->functions->freeMemory(p);
    else free(p);
}

static int check_vr(ModelInstance *m, const char *function, fmi2ValueReference vr)
{
    if (vr < FB_N_VARIABLES) return 1;
    model_log(m, fmi2Error, "logStatusError", "%s: unknown value reference %u", function, (unsigned)vr);
    return 0;
}

/* -- inquiry ------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    static const char *const known[] = {"logStatusWarning", "logStatusDiscard", "logStatusError",
                                        "logStatusFatal", "logAll"};
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2SetDebugLogging", ANY_MODE)) return fmi2Error;
    for (size_t i = 0; i < nCategories; i++) {
        int found = 0;
        for (size_t k = 0; k < sizeof known / sizeof *known; k++)
            if (categories[i] && strcmp(categories[i], known[k]) == 0) found = 1;
        if (!found) {
            model_log(m, fmi2Error, "logStatusError", "fmi2SetDebugLogging: unknown log category '%s'",
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
    probe.functions = functions;
    probe.environment = functions ? functions->componentEnvironment : NULL;
    probe.instance_name = (char *)name;
    if (!functions || !functions->logger) return NULL;
    if (!instanceName || !instanceName[0]) {
        model_log(&probe, fmi2Error, "logStatusError", "fmi2Instantiate: the instance name must not be empty");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        model_log(&probe, fmi2Error, "logStatusError", "fmi2Instantiate: %s is a co-simulation FMU only",
                  FB_MODEL_IDENTIFIER);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, FB_GUID) != 0) {
        model_log(&probe, fmi2Error, "logStatusError", "fmi2Instantiate: GUID '%s' does not match this binary's "
                  "'%s' (a model description from another build?)", fmuGUID ? fmuGUID : "(null)", FB_GUID);
        return NULL;
    }
    ModelInstance *m = (ModelInstance *)allocate(&probe, sizeof(ModelInstance));
    if (!m) return NULL;
    m->functions = functions;
    m->environment = functions->componentEnvironment;
    m->instance_name = (char *)allocate(&probe, strlen(name) + 1);
    if (!m->instance_name) { release(&probe, m); return NULL; }
    strcpy(m->instance_name, name);
    m->logging_on = loggingOn ? 1 : 0;
    model_reset(m);
    return m;
}

void fmi2FreeInstance(fmi2Component c)
{
    ModelInstance *m = (ModelInstance *)c;
    if (!m) return;
    release(m, m->instance_name);
    m->instance_name = NULL;
    release(m, m);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    ModelInstance *m = (ModelInstance *)c;
    (void)toleranceDefined;   /* the integrator's tolerances are the rtol and atol parameters */
    (void)tolerance;
    if (!allowed(m, "fmi2SetupExperiment", MODE_INSTANTIATED)) return fmi2Error;
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        model_log(m, fmi2Error, "logStatusError", "fmi2SetupExperiment: need a finite start time and a stop "
                  "time not before it (got start %g s, stop %g s)", startTime, stopTime);
        return fmi2Error;
    }
    m->state.start_time = startTime;
    m->state.stop_time = stopTimeDefined ? stopTime : INFINITY;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2EnterInitializationMode", MODE_INSTANTIATED)) return fmi2Error;
    m->state.mode = MODE_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2ExitInitializationMode", MODE_INITIALIZATION)) return fmi2Error;
    if (model_initialize(m) != fmi2OK) {
        m->state.mode = MODE_ERROR;
        return fmi2Error;
    }
    m->state.mode = MODE_STEP_COMPLETE;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2Terminate", MODE_STEP_COMPLETE | MODE_STEP_FAILED)) return fmi2Error;
    m->state.mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2Reset", ANY_MODE)) return fmi2Error;
    model_reset(m);
    return fmi2OK;
}

/* -- variables ----------------------------------------------------------------------- */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2GetReal", GET_MODES)) return fmi2Error;
    if (m->state.mode == MODE_INITIALIZATION) model_preview_outputs(m);
    for (size_t i = 0; i < nvr; i++) {
        if (!check_vr(m, "fmi2GetReal", vr[i])) return fmi2Error;
        if (KINDS[vr[i]] == KIND_STRING) {
            model_log(m, fmi2Error, "logStatusError", "fmi2GetReal: %s is a String", NAMES[vr[i]]);
            return fmi2Error;
        }
        value[i] = m->state.values[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2SetReal", SET_MODES)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (!check_vr(m, "fmi2SetReal", vr[i])) return fmi2Error;
        const int kind = KINDS[vr[i]];
        if (kind == KIND_OUTPUT || kind == KIND_STRING) {
            model_log(m, fmi2Error, "logStatusError", "fmi2SetReal: %s is %s and cannot be set", NAMES[vr[i]],
                      kind == KIND_OUTPUT ? "an output" : "a String");
            return fmi2Error;
        }
        if (kind == KIND_FIXED && m->state.mode == MODE_STEP_COMPLETE) {
            model_log(m, fmi2Error, "logStatusError", "fmi2SetReal: %s is a fixed parameter; it can only be set "
                      "before fmi2ExitInitializationMode", NAMES[vr[i]]);
            return fmi2Error;
        }
        m->state.values[vr[i]] = value[i];   /* checked, and applied, at the next doStep */
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2GetString", GET_MODES)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (!check_vr(m, "fmi2GetString", vr[i])) return fmi2Error;
        if (KINDS[vr[i]] != KIND_STRING) {
            model_log(m, fmi2Error, "logStatusError", "fmi2GetString: %s is not a String", NAMES[vr[i]]);
            return fmi2Error;
        }
        value[i] = INTEGRATORS[m->state.integrator];
    }
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2SetString", MODE_INSTANTIATED | MODE_INITIALIZATION)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (!check_vr(m, "fmi2SetString", vr[i])) return fmi2Error;
        if (KINDS[vr[i]] != KIND_STRING) {
            model_log(m, fmi2Error, "logStatusError", "fmi2SetString: %s is not a String", NAMES[vr[i]]);
            return fmi2Error;
        }
        int found = -1;
        for (int k = 0; k < FB_N_INTEGRATORS; k++)
            if (value[i] && strcmp(value[i], INTEGRATORS[k]) == 0) found = k;
        if (found < 0) {
            model_log(m, fmi2Error, "logStatusError", "FourBar '%s': integrator = '%s': must be one of %s, %s",
                      m->instance_name, value[i] ? value[i] : "(null)", INTEGRATORS[0], INTEGRATORS[1]);
            return fmi2Error;
        }
        m->state.integrator = found;
    }
    return fmi2OK;
}

static fmi2Status no_such_type(ModelInstance *m, const char *function, size_t nvr)
{
    if (nvr == 0) return fmi2OK;
    model_log(m, fmi2Error, "logStatusError", "%s: this FMU has no variables of that type", function);
    return fmi2Error;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    (void)vr; (void)value;
    return no_such_type((ModelInstance *)c, "fmi2GetInteger", nvr);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    (void)vr; (void)value;
    return no_such_type((ModelInstance *)c, "fmi2SetInteger", nvr);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    (void)vr; (void)value;
    return no_such_type((ModelInstance *)c, "fmi2GetBoolean", nvr);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    (void)vr; (void)value;
    return no_such_type((ModelInstance *)c, "fmi2SetBoolean", nvr);
}

/* -- FMU state ----------------------------------------------------------------------- */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2GetFMUstate", ANY_MODE)) return fmi2Error;
    if (!*FMUstate) {
        *FMUstate = allocate(m, sizeof(ModelState));
        if (!*FMUstate) {
            model_log(m, fmi2Error, "logStatusError", "fmi2GetFMUstate: out of memory");
            return fmi2Error;
        }
    }
    memcpy(*FMUstate, &m->state, sizeof(ModelState));
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    ModelInstance *m = (ModelInstance *)c;
    if (!allowed(m, "fmi2SetFMUstate", ANY_MODE)) return fmi2Error;
    if (!FMUstate) {
        model_log(m, fmi2Error, "logStatusError", "fmi2SetFMUstate: no state given");
        return fmi2Error;
    }
    memcpy(&m->state, FMUstate, sizeof(ModelState));
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    ModelInstance *m = (ModelInstance *)c;
    if (!m) return fmi2Error;
    if (FMUstate && *FMUstate) {
        release(m, *FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    (void)FMUstate;
    if (!allowed((ModelInstance *)c, "fmi2SerializedFMUstateSize", ANY_MODE)) return fmi2Error;
    *size = sizeof(StateHeader) + sizeof(ModelState);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    ModelInstance *m = (ModelInstance *)c;
    StateHeader header;
    if (!allowed(m, "fmi2SerializeFMUstate", ANY_MODE)) return fmi2Error;
    if (!FMUstate || size < sizeof header + sizeof(ModelState)) {
        model_log(m, fmi2Error, "logStatusError", "fmi2SerializeFMUstate: need a state and %u bytes (got %u)",
                  (unsigned)(sizeof header + sizeof(ModelState)), (unsigned)size);
        return fmi2Error;
    }
    memset(&header, 0, sizeof header);
    memcpy(header.magic, STATE_MAGIC, sizeof header.magic);
    header.state_size = (unsigned int)sizeof(ModelState);
    strncpy(header.guid, FB_GUID, sizeof header.guid - 1);
    memcpy(serializedState, &header, sizeof header);
    memcpy(serializedState + sizeof header, FMUstate, sizeof(ModelState));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    ModelInstance *m = (ModelInstance *)c;
    StateHeader header;
    if (!allowed(m, "fmi2DeSerializeFMUstate", ANY_MODE)) return fmi2Error;
    if (size != sizeof header + sizeof(ModelState)) {
        model_log(m, fmi2Error, "logStatusError", "fmi2DeSerializeFMUstate: expected %u bytes, got %u",
                  (unsigned)(sizeof header + sizeof(ModelState)), (unsigned)size);
        return fmi2Error;
    }
    memcpy(&header, serializedState, sizeof header);
    if (memcmp(header.magic, STATE_MAGIC, sizeof header.magic) != 0 || header.state_size != sizeof(ModelState)
        || strncmp(header.guid, FB_GUID, sizeof header.guid) != 0) {
        model_log(m, fmi2Error, "logStatusError", "fmi2DeSerializeFMUstate: not a state of this FMU (GUID %s)",
                  FB_GUID);
        return fmi2Error;
    }
    if (!*FMUstate) {
        *FMUstate = allocate(m, sizeof(ModelState));
        if (!*FMUstate) return fmi2Error;
    }
    memcpy(*FMUstate, serializedState + sizeof header, sizeof(ModelState));
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    model_log((ModelInstance *)c, fmi2Error, "logStatusError",
              "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative is false)");
    return fmi2Error;
}

/* -- co-simulation ------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr; (void)order; (void)value;
    return no_such_type((ModelInstance *)c, "fmi2SetRealInputDerivatives (the FMU has no inputs)", nvr);
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)order; (void)value;
    if (nvr == 0) return fmi2OK;
    model_log((ModelInstance *)c, fmi2Error, "logStatusError",
              "fmi2GetRealOutputDerivatives: not provided (maxOutputDerivativeOrder is 0)");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    ModelInstance *m = (ModelInstance *)c;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(m, "fmi2DoStep", MODE_STEP_COMPLETE)) return fmi2Error;
    if (!(communicationStepSize > 0.0) || !isfinite(currentCommunicationPoint)) {
        model_log(m, fmi2Error, "logStatusError", "fmi2DoStep: the step size must be positive (got %g s at t = %g s)",
                  communicationStepSize, currentCommunicationPoint);
        return fmi2Error;
    }
    if (model_do_step(m, currentCommunicationPoint, communicationStepSize) != fmi2OK) {
        m->state.mode = MODE_ERROR;
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    model_log((ModelInstance *)c, fmi2Error, "logStatusError",
              "fmi2CancelStep: doStep never returns fmi2Pending, so there is no step to cancel");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s; (void)value;
    model_log((ModelInstance *)c, fmi2Error, "logStatusError", "fmi2GetStatus: doStep is never asynchronous");
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    ModelInstance *m = (ModelInstance *)c;
    if (!m) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = m->state.t;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    ModelInstance *m = (ModelInstance *)c;
    if (!m) return fmi2Error;
    if (s == fmi2Terminated) {
        *value = fmi2False;   /* the slave never asks to end the simulation */
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
