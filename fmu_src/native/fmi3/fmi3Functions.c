/* FMI 3.0 co-simulation and model exchange interface of a mechanism's native FMU (any mechanism: model.h).
 * (In its own folder, fmu_src/native/fmi3/; the FMU's sources/ is flat: it includes model.h beside it.)
 *
 * The second thin layer over model.h and fmi_layer.h (what it shares with fmi2Functions.c; the
 * entry points both standards define alike are fmi_calls.h's), built the same way (one of the two
 * goes into a binary): it checks each call against the state table,
 * maps value references to the model's variables, and implements the FMU state functions as
 * copies of the instance's pointer-free ModelState.
 * No global or static mutable data: instances are independent.  Scheduled Execution is not
 * offered (fmi3InstantiateScheduledExecution returns NULL with a message).
 *
 * The rules every entry point follows are fmi2Functions.c's, with FMI 3.0's state machines:
 * - ENTER, first: a NULL instance is refused with fmi3Error (no logger can be reached through
 *   it); a call that the state machine of the instance's type (co-simulation: instantiated,
 *   initializationMode, stepMode, terminated; model exchange: instantiated, initializationMode,
 *   eventMode, continuousTimeMode, terminated; both: error; the table of fmi_layer.c) does not
 *   allow in the instance's state is refused with fmi3Error and a message naming the function,
 *   the state and the states the call is allowed in; so is a call of the other type.
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
#define FMI_VERSION 3
#include "fmi_calls.h"      /* the entry points both standards define alike, and the layer's names */

/* What the layer keeps of the host: FMI 3.0 gives a logger only.  ModelInstance.host points here. */
typedef struct {
    fmi3LogMessageCallback log_message;
} Host;

/* An instance: the model's, and the host it was given (one allocation, freed together). */
typedef struct {
    ModelInstance model;
    Host host;
} Instance;

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

/* Memory is the C library's (FMI 3.0 has no memory callbacks). */
void *model_allocate(const ModelInstance *m, size_t size)
{
    (void)m;
    return calloc(1, size);
}

void model_release(const ModelInstance *m, void *p)
{
    (void)m;
    free(p);   /* p == NULL: nothing to free */
}

/* Every variable is a scalar: one value per value reference. */
#define SCALARS(nvr, nValues) \
    if (!fmi_count_is(m, &LAYER, __func__, (nValues), (nvr), "values for as many scalar value references")) \
        return fmi3Error

/* -- inquiry ------------------------------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

/* -- life cycle ---------------------------------------------------------------------- */

/* The instance being made, to log through before it exists. */
static ModelInstance *make_probe(Instance *probe, fmi3String instanceName, fmi3InstanceEnvironment environment,
                                 fmi3LogMessageCallback logMessage)
{
    memset(probe, 0, sizeof *probe);
    probe->host.log_message = logMessage;
    probe->model.host = &probe->host;
    probe->model.environment = environment;
    probe->model.instance_name = (char *)(instanceName ? instanceName : "");
    return &probe->model;
}

/* A new instance, or NULL after logging why (the token names another build, an empty name). */
static fmi3Instance instantiate(const char *function, fmi3String instanceName, fmi3String instantiationToken,
                                fmi3Boolean loggingOn, fmi3InstanceEnvironment environment,
                                fmi3LogMessageCallback logMessage, int model_exchange)
{
    Instance probe;
    make_probe(&probe, instanceName, environment, logMessage);
    if (!fmi_named(&probe.model, function)) return NULL;
    Instance *created = (Instance *)fmi_create(&probe.model, &LAYER, function, instantiationToken, sizeof(Instance),
                                               loggingOn, model_exchange);
    if (!created) return NULL;
    created->host = probe.host;
    created->model.host = &created->host;
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
        model_log(make_probe(&probe, instanceName, instanceEnvironment, logMessage), MODEL_ERROR, "logStatusError",
                  "%s: %s", __func__, eventModeUsed ?
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
    model_log(make_probe(&probe, instanceName, instanceEnvironment, logMessage), MODEL_ERROR, "logStatusError",
              "fmi3InstantiateScheduledExecution: this FMU offers Co-Simulation and Model Exchange, not Scheduled "
              "Execution");
    return NULL;
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    ENTER(CALL_ENTER_INITIALIZATION);
    (void)toleranceDefined;   /* the integrator's tolerances are the rtol and atol parameters */
    (void)tolerance;
    if (fmi_setup_experiment(m, __func__, startTime, stopTimeDefined, stopTime) != MODEL_OK) return fmi3Error;
    m->state.mode = MODE_INITIALIZATION;
    return fmi3OK;
}

/* -- variables ----------------------------------------------------------------------- */

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues)
{
    ENTER(CALL_GET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValues);
    SCALARS(nValueReferences, nValues);
    return (fmi3Status)fmi_get_float64(m, &LAYER, __func__, valueReferences, nValueReferences, values);
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues)
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValues);
    SCALARS(nValueReferences, nValues);
    return (fmi3Status)fmi_set_float64(m, &LAYER, __func__, valueReferences, nValueReferences, values);
}

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         fmi3String values[], size_t nValues)
{
    ENTER(CALL_GET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValues);
    SCALARS(nValueReferences, nValues);
    return (fmi3Status)fmi_get_string(m, &LAYER, __func__, valueReferences, nValueReferences, values);
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const fmi3String values[], size_t nValues)
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValues);
    SCALARS(nValueReferences, nValues);
    return (fmi3Status)fmi_set_string(m, &LAYER, __func__, valueReferences, nValueReferences, values);
}

/* The types this FMU has no variables of: every value reference is unknown. */
#define NO_VARIABLES_GET(NAME, CTYPE, TYPE) \
fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences, \
                CTYPE values[], size_t nValues) \
{ \
    ENTER(CALL_GET); \
    REQUIRE_ARRAY(valueReferences, nValueReferences); \
    REQUIRE_ARRAY(values, nValues); \
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, TYPE); \
}
#define NO_VARIABLES_SET(NAME, CTYPE, TYPE) \
fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences, \
                const CTYPE values[], size_t nValues) \
{ \
    ENTER(CALL_SET); \
    REQUIRE_ARRAY(valueReferences, nValueReferences); \
    REQUIRE_ARRAY(values, nValues); \
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, TYPE); \
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
    ENTER(CALL_GET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(valueSizes, nValues);
    REQUIRE_ARRAY(values, nValues);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Binary");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(valueSizes, nValues);
    REQUIRE_ARRAY(values, nValues);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Binary");
}

/* -- clocks: the FMU has none ---------------------------------------------------------- */

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[])
{
    ENTER(CALL_GET_DEFINED);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValueReferences);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[])
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(values, nValueReferences);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    ENTER(CALL_GET_DEFINED);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(intervals, nValueReferences);
    REQUIRE_ARRAY(qualifiers, nValueReferences);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    ENTER(CALL_GET_DEFINED);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(counters, nValueReferences);
    REQUIRE_ARRAY(resolutions, nValueReferences);
    REQUIRE_ARRAY(qualifiers, nValueReferences);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    ENTER(CALL_GET_DEFINED);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(shifts, nValueReferences);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    ENTER(CALL_GET_DEFINED);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(counters, nValueReferences);
    REQUIRE_ARRAY(resolutions, nValueReferences);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(intervals, nValueReferences);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(counters, nValueReferences);
    REQUIRE_ARRAY(resolutions, nValueReferences);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(shifts, nValueReferences);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    ENTER(CALL_SET);
    REQUIRE_ARRAY(valueReferences, nValueReferences);
    REQUIRE_ARRAY(counters, nValueReferences);
    REQUIRE_ARRAY(resolutions, nValueReferences);
    return (fmi3Status)fmi_no_variables(m, __func__, valueReferences, nValueReferences, "Clock");
}

/* Scheduled Execution only: in clockActivationMode, which this FMU never enters. */
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    ENTER(CALL_ACTIVATE_PARTITION);
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
    ENTER(CALL_NOT_IN_ERROR);
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
    ENTER(CALL_NOT_IN_ERROR);
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    return not_provided(m, __func__, "providesPerElementDependencies is false: the dependencies are "
                        "modelDescription.xml's <ModelStructure>");
}

/* Model exchange only: the states' derivatives or outputs (unknowns) along a direction of the
   states (knowns, seed), exact (model.h: model_me_directional; in initializationMode at the state
   the start values give, the states' start parameters also accepted as knowns, and a failure
   leaves the instance in initializationMode).  Not in co-simulation (providesDirectionalDerivatives
   is false there).  Every value reference is checked before anything is computed. */
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    ENTER(CALL_GET_DEFINED);
    if (!m->model_exchange)
        return not_provided(m, __func__, "in co-simulation: providesDirectionalDerivatives is false there");
    REQUIRE_ARRAY(unknowns, nUnknowns);
    REQUIRE_ARRAY(knowns, nKnowns);
    REQUIRE_ARRAY(seed, nSeed);
    REQUIRE_ARRAY(sensitivity, nSensitivity);
    if (!fmi_count_is(m, &LAYER, __func__, nSeed, nKnowns, "seeds (one per known: every variable is a scalar)")
        || !fmi_count_is(m, &LAYER, __func__, nSensitivity, nUnknowns,
                         "sensitivities (one per unknown: every variable is a scalar)"))
        return fmi3Error;
    return (fmi3Status)fmi_directional(m, __func__, unknowns, nUnknowns, knowns, nKnowns, seed, sensitivity);
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    ENTER(CALL_GET_DEFINED);
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    return not_provided(m, __func__, "providesAdjointDerivatives is false");
}

/* The FMU has no structural parameters: configuration mode is never entered. */
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    ENTER(CALL_ENTER_CONFIGURATION);
    return not_provided(m, __func__, "this FMU has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    ENTER(CALL_EXIT_CONFIGURATION);
    (void)m;
    return fmi3Error;
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    ENTER(CALL_NOT_IN_ERROR);
    return not_provided(m, __func__, "providesEvaluateDiscreteStates is false: the FMU has no discrete states");
}

/* -- co-simulation ------------------------------------------------------------------- */

/* Only from eventMode, which a co-simulation instance of this FMU never enters (hasEventMode false). */
fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    ENTER(CALL_ENTER_STEP_MODE);
    return fmi3Error;      /* unreachable: an instance in eventMode is a model-exchange one */
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    ENTER(CALL_OUTPUT_DERIVATIVES);
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
    ENTER(CALL_DO_STEP);
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE(eventHandlingNeeded);
    REQUIRE(terminateSimulation);
    REQUIRE(earlyReturn);
    REQUIRE(lastSuccessfulTime);
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = m->state.t;
    if (fmi_do_step(m, __func__, currentCommunicationPoint, communicationStepSize) != MODEL_OK) return fmi3Error;
    *lastSuccessfulTime = m->state.t;
    return fmi3OK;
}

/* -- model exchange ------------------------------------------------------------------ */

/* The rest of model exchange is fmi_calls.h's. */
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    ENTER(CALL_UPDATE_DISCRETE_STATES);
    REQUIRE(discreteStatesNeedUpdate);
    REQUIRE(terminateSimulation);
    REQUIRE(nominalsOfContinuousStatesChanged);
    REQUIRE(valuesOfContinuousStatesChanged);
    REQUIRE(nextEventTimeDefined);
    REQUIRE(nextEventTime);
    if (fmi_update_discrete_states(m) != MODEL_OK) return fmi3Error;      /* logged why */
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;   /* a re-assembly keeps the states */
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
}

/* Structural: answered in every state, the error state included. */
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    ENTER(CALL_GET_NUMBER_OF);
    REQUIRE(nEventIndicators);
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    ENTER(CALL_GET_NUMBER_OF);
    REQUIRE(nContinuousStates);
    *nContinuousStates = FMU_N_STATES;
    return fmi3OK;
}
