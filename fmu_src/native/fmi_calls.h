/* The entry points FMI 2.0 and FMI 3.0 define alike (the same arguments, the same rules, the same
 * work), written once for both layers: fmi2Functions.c and fmi3/fmi3Functions.c each define
 * FMI_VERSION (2 or 3), include their standard's header and fmi_layer.h, then this file.  What
 * differs between the standards here is a name: of a function, a type, or an argument that a
 * message names (FMI_PICK: the FMI 2.0 one, the FMI 3.0 one).  Every entry point checks its call
 * against the state table first (ENTER, fmi_layer.h).
 */
#ifndef FMI_CALLS_H
#define FMI_CALLS_H

#include "fmi_layer.h"

#if FMI_VERSION == 2
#define FMI_PICK(fmi2, fmi3) fmi2
#elif FMI_VERSION == 3
#define FMI_PICK(fmi2, fmi3) fmi3
#else
#error FMI_VERSION must be 2 or 3
#endif

#define LAYER                FMI_PICK(FMI2_LAYER, FMI3_LAYER)
#define LAYER_INSTANCE       FMI_PICK(c, instance)
#define LAYER_ERROR          FMI_PICK(fmi2Error, fmi3Error)
#define LayerInstance        FMI_PICK(fmi2Component, fmi3Instance)
#define LayerStatus          FMI_PICK(fmi2Status, fmi3Status)
#define LayerBoolean         FMI_PICK(fmi2Boolean, fmi3Boolean)
#define LayerString          FMI_PICK(fmi2String, fmi3String)
#define LayerFloat64         FMI_PICK(fmi2Real, fmi3Float64)
#define LayerByte            FMI_PICK(fmi2Byte, fmi3Byte)
#define LayerFMUState        FMI_PICK(fmi2FMUstate, fmi3FMUState)
#define LAYER_FALSE          FMI_PICK(fmi2False, fmi3False)

#define SET_DEBUG_LOGGING    FMI_PICK(fmi2SetDebugLogging, fmi3SetDebugLogging)
#define FREE_INSTANCE        FMI_PICK(fmi2FreeInstance, fmi3FreeInstance)
#define EXIT_INITIALIZATION  FMI_PICK(fmi2ExitInitializationMode, fmi3ExitInitializationMode)
#define TERMINATE            FMI_PICK(fmi2Terminate, fmi3Terminate)
#define RESET                FMI_PICK(fmi2Reset, fmi3Reset)
#define GET_FMU_STATE        FMI_PICK(fmi2GetFMUstate, fmi3GetFMUState)
#define SET_FMU_STATE        FMI_PICK(fmi2SetFMUstate, fmi3SetFMUState)
#define FREE_FMU_STATE       FMI_PICK(fmi2FreeFMUstate, fmi3FreeFMUState)
#define SERIALIZED_SIZE      FMI_PICK(fmi2SerializedFMUstateSize, fmi3SerializedFMUStateSize)
#define SERIALIZE            FMI_PICK(fmi2SerializeFMUstate, fmi3SerializeFMUState)
#define DESERIALIZE          FMI_PICK(fmi2DeSerializeFMUstate, fmi3DeserializeFMUState)
#define ENTER_EVENT_MODE     FMI_PICK(fmi2EnterEventMode, fmi3EnterEventMode)
#define ENTER_CONTINUOUS     FMI_PICK(fmi2EnterContinuousTimeMode, fmi3EnterContinuousTimeMode)
#define COMPLETED_STEP       FMI_PICK(fmi2CompletedIntegratorStep, fmi3CompletedIntegratorStep)
#define SET_TIME             FMI_PICK(fmi2SetTime, fmi3SetTime)
#define SET_STATES           FMI_PICK(fmi2SetContinuousStates, fmi3SetContinuousStates)
#define GET_DERIVATIVES      FMI_PICK(fmi2GetDerivatives, fmi3GetContinuousStateDerivatives)
#define GET_EVENT_INDICATORS FMI_PICK(fmi2GetEventIndicators, fmi3GetEventIndicators)
#define GET_STATES           FMI_PICK(fmi2GetContinuousStates, fmi3GetContinuousStates)
#define GET_NOMINALS         FMI_PICK(fmi2GetNominalsOfContinuousStates, fmi3GetNominalsOfContinuousStates)
/* The arguments whose names differ, as messages name them. */
#define FMU_STATE_ARG        FMI_PICK("FMUstate", "FMUState")
#define STATES_ARG           FMI_PICK("x", "continuousStates")
#define NOMINALS_ARG         FMI_PICK("x_nominal", "nominals")

#define REQUIRE_NAMED(p, name) if (!fmi_present(m, __func__, (const void *)(p), (name), 0)) return LAYER_ERROR
#define REQUIRE_ARRAY_NAMED(p, n, name) \
    if ((n) > 0 && !fmi_present(m, __func__, (const void *)(p), (name), (n))) return LAYER_ERROR

/* -- inquiry and life cycle ------------------------------------------------------------ */

LayerStatus SET_DEBUG_LOGGING(LayerInstance LAYER_INSTANCE, LayerBoolean loggingOn, size_t nCategories,
                              const LayerString categories[])
{
    ENTER(CALL_ANY_STATE);
    REQUIRE_ARRAY(categories, nCategories);
    return (LayerStatus)fmi_set_debug_logging(m, __func__, loggingOn, nCategories, categories);
}

void FREE_INSTANCE(LayerInstance LAYER_INSTANCE)
{
    fmi_free_instance((ModelInstance *)LAYER_INSTANCE);   /* allowed in every state; NULL is ignored */
}

LayerStatus EXIT_INITIALIZATION(LayerInstance LAYER_INSTANCE)
{
    ENTER(CALL_EXIT_INITIALIZATION);
    return (LayerStatus)fmi_exit_initialization(m);
}

LayerStatus TERMINATE(LayerInstance LAYER_INSTANCE)
{
    ENTER(CALL_TERMINATE);
    return (LayerStatus)fmi_terminate(m);
}

LayerStatus RESET(LayerInstance LAYER_INSTANCE)
{
    ENTER(CALL_ANY_STATE);
    model_reset(m);
    return (LayerStatus)MODEL_OK;
}

/* -- FMU state ----------------------------------------------------------------------- */

/* Not in the error state: a state saved there could only restore the failure. */
LayerStatus GET_FMU_STATE(LayerInstance LAYER_INSTANCE, LayerFMUState *FMUState)
{
    ENTER(CALL_NOT_IN_ERROR);
    REQUIRE_NAMED(FMUState, FMU_STATE_ARG);
    return (LayerStatus)fmi_get_fmu_state(m, __func__, FMUState);
}

/* Also in the error state: the way to continue after a failure.  Only a state saved by an
   instance of the same type (its mode is of that type's state machine). */
LayerStatus SET_FMU_STATE(LayerInstance LAYER_INSTANCE, LayerFMUState FMUState)
{
    ENTER(CALL_ANY_STATE);
    REQUIRE_NAMED(FMUState, FMU_STATE_ARG);
    return (LayerStatus)fmi_set_fmu_state(m, __func__, FMUState);
}

LayerStatus FREE_FMU_STATE(LayerInstance LAYER_INSTANCE, LayerFMUState *FMUState)
{
    ENTER(CALL_ANY_STATE);
    REQUIRE_NAMED(FMUState, FMU_STATE_ARG);
    return (LayerStatus)fmi_free_fmu_state(m, FMUState);   /* *FMUState == NULL: nothing to free */
}

LayerStatus SERIALIZED_SIZE(LayerInstance LAYER_INSTANCE, LayerFMUState FMUState, size_t *size)
{
    ENTER(CALL_ANY_STATE);
    REQUIRE_NAMED(FMUState, FMU_STATE_ARG);
    REQUIRE(size);
    return (LayerStatus)fmi_serialized_size(size);
}

LayerStatus SERIALIZE(LayerInstance LAYER_INSTANCE, LayerFMUState FMUState, LayerByte serializedState[], size_t size)
{
    ENTER(CALL_ANY_STATE);
    REQUIRE_NAMED(FMUState, FMU_STATE_ARG);
    REQUIRE(serializedState);
    return (LayerStatus)fmi_serialize(m, &LAYER, __func__, FMUState, (unsigned char *)serializedState, size);
}

LayerStatus DESERIALIZE(LayerInstance LAYER_INSTANCE, const LayerByte serializedState[], size_t size,
                        LayerFMUState *FMUState)
{
    ENTER(CALL_ANY_STATE);
    REQUIRE(serializedState);
    REQUIRE_NAMED(FMUState, FMU_STATE_ARG);
    return (LayerStatus)fmi_deserialize(m, &LAYER, __func__, (const unsigned char *)serializedState, size, FMUState);
}

/* -- model exchange ------------------------------------------------------------------ */

/* fmi_layer.h: the continuous states, and the error state an evaluation that fails (the loop
   cannot be closed at the states the host set) leaves the instance in.  Event mode: FMI 2.0 also
   from eventMode, FMI 3.0 from continuousTimeMode only (the table); a co-simulation instance never
   enters it (FMI 3.0: hasEventMode false). */
LayerStatus ENTER_EVENT_MODE(LayerInstance LAYER_INSTANCE)
{
    ENTER(CALL_ENTER_EVENT_MODE);
    m->state.mode = MODE_EVENT;
    return (LayerStatus)MODEL_OK;
}

LayerStatus ENTER_CONTINUOUS(LayerInstance LAYER_INSTANCE)
{
    ENTER(CALL_ENTER_CONTINUOUS_TIME);
    return (LayerStatus)fmi_enter_continuous_time(m);
}

LayerStatus COMPLETED_STEP(LayerInstance LAYER_INSTANCE, LayerBoolean noSetFMUStatePriorToCurrentPoint,
                           LayerBoolean *enterEventMode, LayerBoolean *terminateSimulation)
{
    ENTER(CALL_COMPLETED_STEP);
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE(enterEventMode);
    REQUIRE(terminateSimulation);
    if (fmi_completed_step(m) != MODEL_OK) return LAYER_ERROR;
    *enterEventMode = LAYER_FALSE;
    *terminateSimulation = LAYER_FALSE;
    return (LayerStatus)MODEL_OK;
}

LayerStatus SET_TIME(LayerInstance LAYER_INSTANCE, LayerFloat64 time)
{
    ENTER(CALL_SET_TIME);
    return (LayerStatus)fmi_set_time(m, __func__, time);
}

LayerStatus SET_STATES(LayerInstance LAYER_INSTANCE, const LayerFloat64 x[], size_t nx)
{
    ENTER(CALL_SET_STATES);
    REQUIRE_ARRAY_NAMED(x, nx, STATES_ARG);
    return (LayerStatus)fmi_set_states(m, &LAYER, __func__, x, nx);
}

/* Not in FMI 2.0's initialization mode; FMI 3.0 (as the Reference-FMUs) allows the derivatives
   there too: the values the start values give (the table; fmi_get_derivatives). */
LayerStatus GET_DERIVATIVES(LayerInstance LAYER_INSTANCE, LayerFloat64 derivatives[], size_t nx)
{
    ENTER(CALL_GET_DERIVATIVES);
    REQUIRE_ARRAY(derivatives, nx);
    return (LayerStatus)fmi_get_derivatives(m, &LAYER, __func__, derivatives, nx);
}

LayerStatus GET_EVENT_INDICATORS(LayerInstance LAYER_INSTANCE, LayerFloat64 eventIndicators[], size_t ni)
{
    ENTER(CALL_GET_STATES);
    REQUIRE_ARRAY(eventIndicators, ni);
    return fmi_count_is(m, &LAYER, __func__, ni, 0, "event indicators") ? (LayerStatus)MODEL_OK : LAYER_ERROR;
}

LayerStatus GET_STATES(LayerInstance LAYER_INSTANCE, LayerFloat64 x[], size_t nx)
{
    ENTER(CALL_GET_STATES);
    REQUIRE_ARRAY_NAMED(x, nx, STATES_ARG);
    return (LayerStatus)fmi_get_states(m, &LAYER, __func__, x, nx);
}

LayerStatus GET_NOMINALS(LayerInstance LAYER_INSTANCE, LayerFloat64 x_nominal[], size_t nx)
{
    ENTER(CALL_GET_NOMINALS);
    REQUIRE_ARRAY_NAMED(x_nominal, nx, NOMINALS_ARG);
    return (LayerStatus)fmi_get_nominals(m, &LAYER, __func__, x_nominal, nx);
}

#endif
