/* FMI 2.0 co-simulation and model exchange interface of a mechanism's native FMU (any mechanism: model.h).
 *
 * A thin layer over model.h and fmi_layer.h (what it shares with the FMI 3.0 layer; the entry
 * points both standards define alike are fmi_calls.h's): it checks each call against the state
 * table, maps value references to the model's variables, and implements the FMU state functions
 * as copies of the instance's pointer-free ModelState.  No global or static mutable data:
 * instances are independent.
 *
 * The rules every entry point follows (tests/native_host/fmi2_strict_host.c checks them all):
 * - ENTER, first: a NULL instance is refused with fmi2Error (no logger can be reached through
 *   it); a call that the FMI 2.0 state machine of the instance's type (co-simulation or model
 *   exchange: the table of fmi_layer.c) does not allow in the instance's state is refused with
 *   fmi2Error and a message naming the function, the state and the states the call is allowed
 *   in; so is a call of the other type (with a message saying so).
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
#define FMI_VERSION 2
#include "fmi_calls.h"      /* the entry points both standards define alike, and the layer's names */

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

void *model_allocate(const ModelInstance *m, size_t size)
{
    if (m && callbacks(m) && callbacks(m)->allocateMemory) return callbacks(m)->allocateMemory(1, size);
    return calloc(1, size);
}

void model_release(const ModelInstance *m, void *p)
{
    if (!p) return;
    if (m && callbacks(m) && callbacks(m)->freeMemory) callbacks(m)->freeMemory(p);
    else free(p);
}

/* -- inquiry ------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

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
    if (!fmi_named(&probe, __func__)) return NULL;
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        model_log(&probe, MODEL_ERROR, "logStatusError", "fmi2Instantiate: unknown fmuType %d (fmi2ModelExchange %d "
                  "or fmi2CoSimulation %d)", (int)fmuType, (int)fmi2ModelExchange, (int)fmi2CoSimulation);
        return NULL;
    }
    return fmi_create(&probe, &LAYER, __func__, fmuGUID, sizeof(ModelInstance), loggingOn,
                      fmuType == fmi2ModelExchange);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    ENTER(CALL_ENTER_INITIALIZATION);
    (void)toleranceDefined;   /* the integrator's tolerances are the rtol and atol parameters */
    (void)tolerance;
    return (fmi2Status)fmi_setup_experiment(m, __func__, startTime, stopTimeDefined, stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    ENTER(CALL_ENTER_INITIALIZATION);
    m->state.mode = MODE_INITIALIZATION;
    return fmi2OK;
}

/* -- variables ----------------------------------------------------------------------- */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    ENTER(CALL_GET);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return (fmi2Status)fmi_get_float64(m, &LAYER, __func__, vr, nvr, value);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return (fmi2Status)fmi_set_float64(m, &LAYER, __func__, vr, nvr, value);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    ENTER(CALL_GET);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return (fmi2Status)fmi_get_string(m, &LAYER, __func__, vr, nvr, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return (fmi2Status)fmi_set_string(m, &LAYER, __func__, vr, nvr, value);
}

/* The FMU has no Integer or Boolean variables: every value reference of those types is unknown. */
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    ENTER(CALL_GET);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return (fmi2Status)fmi_no_variables(m, __func__, vr, nvr, NULL);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return (fmi2Status)fmi_no_variables(m, __func__, vr, nvr, NULL);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    ENTER(CALL_GET);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return (fmi2Status)fmi_no_variables(m, __func__, vr, nvr, NULL);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(value, nvr);
    return (fmi2Status)fmi_no_variables(m, __func__, vr, nvr, NULL);
}

/* -- directional derivatives ------------------------------------------------------------ */

/* Model exchange only: the states' derivatives or outputs (vUnknown_ref) along a direction of the
   states and inputs (vKnown_ref, dvKnown), exact (model.h: model_me_directional).  Not in
   co-simulation (providesDirectionalDerivative is false there: its outputs are those of the
   step's end).  In initialization mode: at the state the start values give, the states' start
   parameters also accepted as knowns (the states are initial unknowns there); a failure there
   leaves the instance in initialization mode (fmi_directional). */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    ENTER(CALL_GET_DEFINED);
    if (!m->model_exchange) {
        model_log(m, MODEL_ERROR, "logStatusError", "fmi2GetDirectionalDerivative: not provided in co-simulation "
                  "(providesDirectionalDerivative is false there)");
        return fmi2Error;
    }
    REQUIRE_ARRAY(vUnknown_ref, nUnknown);
    REQUIRE_ARRAY(vKnown_ref, nKnown);
    REQUIRE_ARRAY(dvKnown, nKnown);
    REQUIRE_ARRAY(dvUnknown, nUnknown);
    return (fmi2Status)fmi_directional(m, __func__, vUnknown_ref, nUnknown, vKnown_ref, nKnown, dvKnown, dvUnknown);
}

/* -- co-simulation ------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    ENTER(CALL_INPUT_DERIVATIVES);
    REQUIRE_ARRAY(vr, nvr);
    REQUIRE_ARRAY(order, nvr);
    REQUIRE_ARRAY(value, nvr);
    if (nvr == 0) return fmi2OK;
    int orders[64];
    for (size_t start = 0; start < nvr; start += 64) {        /* fmi2Integer is int: copied in chunks */
        const size_t n = nvr - start < 64 ? nvr - start : 64;
        for (size_t i = 0; i < n; i++) orders[i] = (int)order[start + i];
        if (model_set_input_derivatives(m, __func__, vr + start, n, orders, value + start) != MODEL_OK)
            return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    ENTER(CALL_OUTPUT_DERIVATIVES);
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
    ENTER(CALL_DO_STEP);
    (void)noSetFMUStatePriorToCurrentPoint;
    return (fmi2Status)fmi_do_step(m, __func__, currentCommunicationPoint, communicationStepSize);
}

/* Only allowed in stepInProgress, which this FMU never enters (fmi2DoStep never returns
   fmi2Pending): ENTER always refuses it, naming the instance's state. */
fmi2Status fmi2CancelStep(fmi2Component c)
{
    ENTER(CALL_CANCEL_STEP);
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
    ENTER(CALL_GET_STATUS);
    REQUIRE(value);
    return no_status(m, __func__, s);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    ENTER(CALL_GET_STATUS);
    REQUIRE(value);
    if (s != fmi2LastSuccessfulTime) return no_status(m, __func__, s);
    *value = m->state.t;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    ENTER(CALL_GET_STATUS);
    REQUIRE(value);
    return no_status(m, __func__, s);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    ENTER(CALL_GET_STATUS);
    REQUIRE(value);
    if (s != fmi2Terminated) return no_status(m, __func__, s);
    *value = fmi2False;   /* the slave never asks to end the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    ENTER(CALL_GET_STATUS);
    REQUIRE(value);
    return no_status(m, __func__, s);
}

/* -- model exchange ------------------------------------------------------------------ */

/* The rest of model exchange is fmi_calls.h's. */
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *fmi2eventInfo)
{
    ENTER(CALL_UPDATE_DISCRETE_STATES);
    REQUIRE(fmi2eventInfo);
    if (fmi_update_discrete_states(m) != MODEL_OK) return fmi2Error;      /* logged why */
    fmi2eventInfo->newDiscreteStatesNeeded = fmi2False;
    fmi2eventInfo->terminateSimulation = fmi2False;
    fmi2eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    fmi2eventInfo->valuesOfContinuousStatesChanged = fmi2False;   /* a re-assembly keeps the states */
    fmi2eventInfo->nextEventTimeDefined = fmi2False;
    fmi2eventInfo->nextEventTime = 0.0;
    return fmi2OK;
}

