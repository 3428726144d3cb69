/* A strict FMI 2.0 host for an FMU that offers co-simulation and model exchange in one binary:
   it dlopens the binary and calls every exported fmi2* function (both types')
     1. in every state the FMU can reach, with valid arguments: of the co-simulation state
        machine (section 4.2.4: instantiated, initializationMode, stepComplete, terminated, and
        error, reached both by a failed fmi2ExitInitializationMode and by a failed fmi2DoStep)
        on a co-simulation instance, and of the model-exchange one (section 3.2.3:
        instantiated, initializationMode, eventMode, continuousTimeMode, terminated, and error,
        reached both by a failed fmi2ExitInitializationMode and by a failed
        fmi2NewDiscreteStates) on a model-exchange instance;
     2. with a NULL instance;
     3. with NULL pointer or array arguments (array lengths > 0), in a state that allows the call;
   plus a few sequences: unknown value references, a refused fmi2SetReal changing nothing,
   recovery by fmi2Reset and fmi2SetFMUstate, fmi2Instantiate's refusals, an FMU state of one
   type refused by an instance of the other, wrong state and event-indicator counts, and two
   short healthy runs: co-simulation with a parameter change replayed from a saved FMU state;
   model exchange with explicit Euler steps, an event that changes the parameter, and a replay;
   steps that cannot be taken (0, < 0, inf, NaN, under 1 ns, a non-finite time), non-finite
   parameter values, states of no physical size (+-1e308), and crafted FMU states: a valid
   serialized state with each of a few integers at every 4-byte offset, each of a few doubles at
   every 8-byte offset, and random bytes at random places, each refused or survived (run under
   -fsanitize=address,undefined by tests/test_fmu_bounds.py).

   What it requires (the FMI 2.0 standard, as the Modelica Reference-FMUs implement it):
   - a call the state machine does not allow returns fmi2Error, logs a message naming the
     function and the instance's state, and changes nothing (checked by a probe call after it);
     so does a function of the other type (a co-simulation function on a model-exchange
     instance, or the other way round), whose message names the function and either the state
     or the instance's type ("instantiated for model exchange");
   - a NULL instance gives fmi2Error and no crash; a NULL argument gives fmi2Error and a message;
   - the status returned is the worst status logged during the call (an OK call logs no
     warning or error); a status inquiry the FMU has no value for gives fmi2Discard (FMI 2.0,
     section 2.1.3);
   - every block the FMU allocates through allocateMemory is given back through freeMemory;
   - stricter than the Reference-FMUs, as the native FourBar FMU promises: in the error state no
     value can be read (fmi2GetXXX, fmi2GetFMUstate and the output derivatives are refused).

   usage: fmi2_strict_host [--in-process] [--only TEXT] LIBRARY GUID VR_TUNABLE VR_OUTPUT VR_STRING N_STATES
     VR_TUNABLE: a tunable Real parameter that must be positive (set to -1 to make
     initialization, a step and an event update fail); VR_OUTPUT: a Real output; VR_STRING: a
     fixed String parameter; N_STATES: the number of continuous states (the model description's
     <Derivatives> unknowns; 1 to MAX_STATES).  Each case runs in a forked child, so a crash is
     reported as a failed case;
     --in-process runs them in one process (for valgrind); --only runs the cases whose label
     contains TEXT (tests/test_fmu_bounds.py: the crafted states under the sanitizers).
   Prints "FAIL ..." for each failed check and a summary line; exit status 0 when everything
   holds, 1 when a check failed, 2 for a usage or loading error.
   tests/test_fmu_native_strict.py builds and runs it. */
#define _POSIX_C_SOURCE 200809L   /* fork, waitpid, dlopen */
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>
#include "fmi2FunctionTypes.h"

/* -- the FMU's functions ------------------------------------------------------------- */
#define FMI2_FUNCTIONS(X) \
    X(GetTypesPlatform) X(GetVersion) X(SetDebugLogging) X(Instantiate) X(FreeInstance) \
    X(SetupExperiment) X(EnterInitializationMode) X(ExitInitializationMode) X(Terminate) X(Reset) \
    X(GetReal) X(GetInteger) X(GetBoolean) X(GetString) X(SetReal) X(SetInteger) X(SetBoolean) \
    X(SetString) X(GetFMUstate) X(SetFMUstate) X(FreeFMUstate) X(SerializedFMUstateSize) \
    X(SerializeFMUstate) X(DeSerializeFMUstate) X(GetDirectionalDerivative) \
    X(SetRealInputDerivatives) X(GetRealOutputDerivatives) X(DoStep) X(CancelStep) X(GetStatus) \
    X(GetRealStatus) X(GetIntegerStatus) X(GetBooleanStatus) X(GetStringStatus) \
    X(EnterEventMode) X(NewDiscreteStates) X(EnterContinuousTimeMode) X(CompletedIntegratorStep) X(SetTime) \
    X(SetContinuousStates) X(GetDerivatives) X(GetEventIndicators) X(GetContinuousStates) \
    X(GetNominalsOfContinuousStates)
#define DECLARE(name) fmi2##name##TYPE *name;
static struct { FMI2_FUNCTIONS(DECLARE) } F;

/* -- the state machines (FMI 2.0, sections 4.2.4 and 3.2.3) ----------------------------- */
/* The states of both; a co-simulation instance reaches stepComplete (never stepInProgress nor
   stepFailed: fmi2DoStep is synchronous), a model-exchange instance eventMode and
   continuousTimeMode; the others are common. */
enum {
    INSTANTIATED = 1, INITIALIZATION = 2, STEP_COMPLETE = 4, STEP_IN_PROGRESS = 8, STEP_FAILED = 16,
    TERMINATED = 32, ERROR = 64, EVENT = 128, CONTINUOUS = 256
};
#define ANY (INSTANTIATED | INITIALIZATION | STEP_COMPLETE | STEP_IN_PROGRESS | STEP_FAILED | TERMINATED | ERROR | \
             EVENT | CONTINUOUS)
#define INITIALIZED (STEP_COMPLETE | STEP_FAILED | EVENT | CONTINUOUS | TERMINATED)
#define READ (INITIALIZATION | INITIALIZED)          /* no reading in the error state */
/* parameters (the FMU has no inputs): not in continuousTimeMode, where only inputs may be set */
#define WRITE (INSTANTIATED | INITIALIZATION | STEP_COMPLETE | EVENT)
#define STATUS (STEP_COMPLETE | STEP_IN_PROGRESS | STEP_FAILED | TERMINATED)
#define ME_READ (INITIALIZATION | EVENT | CONTINUOUS | TERMINATED)   /* states, event indicators */

/* An instance's type, and the type a function belongs to (BOTH: the common functions). */
enum { CS = 0, ME = 1, BOTH = 2 };
static const char *const TYPE_WORDS[2] = {"instantiated for co-simulation", "instantiated for model exchange"};

/* The states this host drives a fresh instance into, the word the FMU must use for each, and the
   instance's type. */
typedef struct { const char *label; int state; const char *word; int type; } Reached;
enum {
    R_INSTANTIATED, R_INITIALIZATION, R_STEP_COMPLETE, R_TERMINATED, R_FAILED_INIT, R_FAILED_STEP,
    R_ME_INSTANTIATED, R_ME_INITIALIZATION, R_EVENT, R_CONTINUOUS, R_ME_TERMINATED, R_ME_FAILED_INIT,
    R_FAILED_EVENT, N_REACHED
};
static const Reached REACHED[N_REACHED] = {
    {"instantiated", INSTANTIATED, "state instantiated", CS},
    {"initializationMode", INITIALIZATION, "state initializationMode", CS},
    {"stepComplete", STEP_COMPLETE, "state stepComplete", CS},
    {"terminated", TERMINATED, "state terminated", CS},
    {"error after a failed fmi2ExitInitializationMode", ERROR, "state error", CS},
    {"error after a failed fmi2DoStep", ERROR, "state error", CS},
    {"instantiated (model exchange)", INSTANTIATED, "state instantiated", ME},
    {"initializationMode (model exchange)", INITIALIZATION, "state initializationMode", ME},
    {"eventMode", EVENT, "state eventMode", ME},
    {"continuousTimeMode", CONTINUOUS, "state continuousTimeMode", ME},
    {"terminated (model exchange)", TERMINATED, "state terminated", ME},
    {"error after a failed fmi2ExitInitializationMode (model exchange)", ERROR, "state error", ME},
    {"error after a failed fmi2NewDiscreteStates", ERROR, "state error", ME}};

/* -- what the FMU logs and allocates --------------------------------------------------- */
static int ENV_TAG;                                  /* its address is the component environment */
static struct { int count; fmi2Status worst; int bad_arguments; char text[8192]; } LOG;
static long ALLOCS, FREES;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    char line[2048];
    va_list args;
    va_start(args, message);
    vsnprintf(line, sizeof line, message ? message : "(null)", args);
    va_end(args);
    if (env != &ENV_TAG || !name || !category) LOG.bad_arguments++;
    if (LOG.count == 0 || status > LOG.worst) LOG.worst = status;
    LOG.count++;
    size_t used = strlen(LOG.text);
    snprintf(LOG.text + used, sizeof LOG.text - used, "%s[%d] %s", used ? " | " : "", (int)status, line);
}

static void *allocate_memory(size_t n, size_t size)
{
    ALLOCS++;
    return calloc(n, size);
}

static void free_memory(void *p)
{
    if (p) FREES++;
    free(p);
}

static fmi2CallbackFunctions CALLBACKS = {logger, allocate_memory, free_memory, NULL, &ENV_TAG};

/* -- checks ---------------------------------------------------------------------------- */
static int FAILURES, CASES;
static const char *CASE = "";                        /* what is being checked, for FAIL lines */

static void fail(const char *fmt, ...)
{
    va_list args;
    printf("FAIL %s: ", CASE);
    va_start(args, fmt);
    vprintf(fmt, args);
    va_end(args);
    printf("\n");
    FAILURES++;
}

static const char *status_name(fmi2Status s)
{
    static const char *const names[] = {"fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal",
                                        "fmi2Pending"};
    return (unsigned)s < 6 ? names[s] : "(not an fmi2Status)";
}

static void clear_log(void) { memset(&LOG, 0, sizeof LOG); }

/* `got` must be `want`; with an instance, the log must agree with the status and contain
   `says1` and `says2` (when not NULL).  Clears the log for the next call. */
static int expect(const char *call, fmi2Status got, fmi2Status want, int instance, const char *says1,
                  const char *says2)
{
    int ok = 1;
    if (got != want) {
        fail("%s returned %s, expected %s (log: %s)", call, status_name(got), status_name(want), LOG.text);
        ok = 0;
    } else if (instance) {
        if (LOG.bad_arguments) { fail("%s: the logger got a wrong environment or a NULL name/category", call); ok = 0; }
        if (got != fmi2OK && (LOG.count == 0 || LOG.worst != got)) {
            fail("%s returned %s but logged %s (log: %s)", call, status_name(got),
                 LOG.count ? status_name(LOG.worst) : "nothing", LOG.text);
            ok = 0;
        }
        if (got == fmi2OK && LOG.count && LOG.worst != fmi2OK) {
            fail("%s returned fmi2OK but logged %s (log: %s)", call, status_name(LOG.worst), LOG.text);
            ok = 0;
        }
        for (int i = 0; i < 2; i++) {
            const char *says = i ? says2 : says1;
            if (got != fmi2OK && says && !strstr(LOG.text, says)) {
                fail("%s: the message does not say '%s' (log: %s)", call, says, LOG.text);
                ok = 0;
            }
        }
    }
    clear_log();
    return ok;
}

/* A refusal: fmi2Error, the log as expect() requires it, naming `name` and `word1` or `word2`
   (a function of the other type may be refused by the state machine or by the type check). */
static int expect_refused(const char *call, fmi2Status got, const char *name, const char *word1,
                          const char *word2)
{
    char text[sizeof LOG.text];
    strcpy(text, LOG.text);
    int ok = expect(call, got, fmi2Error, 1, name, NULL);
    if (ok && !strstr(text, word1) && !(word2 && strstr(text, word2))) {
        fail("%s: the message says neither '%s' nor '%s' (log: %s)", call, word1, word2 ? word2 : "", text);
        ok = 0;
    }
    return ok;
}

/* -- fixtures -------------------------------------------------------------------------- */
#define MAX_STATES 64
static const char *GUID;
static fmi2ValueReference VR_TUNABLE, VR_OUTPUT, VR_STRING;
static int NX;                                       /* number of continuous states (command line) */
static fmi2Real TUNABLE_START;                      /* read from the FMU */
static char STRING_START[256];
static fmi2Real X_START[MAX_STATES];                 /* the continuous states after initialization */
/* A healthy instance of each type whose saved state the cases use. */
typedef struct { fmi2Component c; fmi2FMUstate state; fmi2Byte *serial; size_t size; } Donor;
static Donor DONORS[2];
static int TYPE;                                     /* of the instance the current case made */
#define DONOR (DONORS[TYPE].c)
#define DONOR_STATE (DONORS[TYPE].state)
#define SERIAL (DONORS[TYPE].serial)
#define SERIAL_SIZE (DONORS[TYPE].size)

static fmi2Component instantiate(int type)
{
    return F.Instantiate("strict", type == ME ? fmi2ModelExchange : fmi2CoSimulation, GUID, "", &CALLBACKS,
                         fmi2False, fmi2False);
}

/* A fresh instance in REACHED[r]; NULL (and a failure) if the FMU does not get there.  Sets TYPE. */
static fmi2Component make(int r)
{
    const fmi2Real bad = -1.0;
    const int state = REACHED[r].state;
    const int failed_init = r == R_FAILED_INIT || r == R_ME_FAILED_INIT;
    fmi2EventInfo info;
    TYPE = REACHED[r].type;
    fmi2Component c = instantiate(TYPE);
    int ok = c != NULL;
    if (!c) fail("fmi2Instantiate returned NULL (log: %s)", LOG.text);
    if (ok && failed_init)
        ok = expect("fmi2SetReal(tunable = -1)", F.SetReal(c, &VR_TUNABLE, 1, &bad), fmi2OK, 1, NULL, NULL);
    if (ok && state != INSTANTIATED)
        ok = expect("fmi2SetupExperiment", F.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, 10.0), fmi2OK, 1,
                    NULL, NULL)
             && expect("fmi2EnterInitializationMode", F.EnterInitializationMode(c), fmi2OK, 1, NULL, NULL);
    if (ok && failed_init)
        ok = expect("fmi2ExitInitializationMode with tunable = -1", F.ExitInitializationMode(c), fmi2Error, 1,
                    NULL, NULL) || 1;
    else if (ok && state != INSTANTIATED && state != INITIALIZATION)
        ok = expect("fmi2ExitInitializationMode", F.ExitInitializationMode(c), fmi2OK, 1, NULL, NULL);
    if (ok && (r == R_CONTINUOUS || r == R_ME_TERMINATED))
        ok = expect("fmi2NewDiscreteStates", F.NewDiscreteStates(c, &info), fmi2OK, 1, NULL, NULL)
             && expect("fmi2EnterContinuousTimeMode", F.EnterContinuousTimeMode(c), fmi2OK, 1, NULL, NULL);
    if (ok && (r == R_TERMINATED || r == R_ME_TERMINATED))
        ok = expect("fmi2Terminate", F.Terminate(c), fmi2OK, 1, NULL, NULL);
    if (ok && r == R_FAILED_STEP)
        ok = expect("fmi2SetReal(tunable = -1)", F.SetReal(c, &VR_TUNABLE, 1, &bad), fmi2OK, 1, NULL, NULL)
             && (expect("fmi2DoStep with tunable = -1", F.DoStep(c, 0.0, 0.01, fmi2True), fmi2Error, 1, NULL, NULL)
                 || 1);
    if (ok && r == R_FAILED_EVENT)
        ok = expect("fmi2SetReal(tunable = -1) in eventMode", F.SetReal(c, &VR_TUNABLE, 1, &bad), fmi2OK, 1, NULL,
                    NULL)
             && (expect("fmi2NewDiscreteStates with tunable = -1", F.NewDiscreteStates(c, &info), fmi2Error, 1,
                        NULL, NULL) || 1);
    if (!ok && c) {
        F.FreeInstance(c);
        c = NULL;
    }
    clear_log();
    return c;
}

/* A call that succeeds only in the state `r` leaves: proves a refused call changed nothing. */
static void probe(fmi2Component c, int r)
{
    fmi2Real v, x[MAX_STATES];
    fmi2Boolean enter, terminate;
    switch (r) {
    case R_INSTANTIATED:
    case R_ME_INSTANTIATED:
        expect("probe fmi2EnterInitializationMode", F.EnterInitializationMode(c), fmi2OK, 1, NULL, NULL);
        break;
    case R_INITIALIZATION:
    case R_ME_INITIALIZATION:
        expect("probe fmi2ExitInitializationMode", F.ExitInitializationMode(c), fmi2OK, 1, NULL, NULL);
        break;
    case R_STEP_COMPLETE:
        expect("probe fmi2DoStep", F.DoStep(c, 0.0, 0.01, fmi2True), fmi2OK, 1, NULL, NULL);
        break;
    case R_TERMINATED:
        expect("probe fmi2GetReal", F.GetReal(c, &VR_OUTPUT, 1, &v), fmi2OK, 1, NULL, NULL);
        expect("probe fmi2DoStep", F.DoStep(c, 0.0, 0.01, fmi2True), fmi2Error, 1, NULL, NULL);
        break;
    case R_EVENT:
        expect("probe fmi2EnterContinuousTimeMode", F.EnterContinuousTimeMode(c), fmi2OK, 1, NULL, NULL);
        break;
    case R_CONTINUOUS:
        expect("probe fmi2CompletedIntegratorStep", F.CompletedIntegratorStep(c, fmi2True, &enter, &terminate),
               fmi2OK, 1, NULL, NULL);
        break;
    case R_ME_TERMINATED:   /* readable (not instantiated, not error), not initializationMode, not event/continuous */
        expect("probe fmi2GetReal", F.GetReal(c, &VR_OUTPUT, 1, &v), fmi2OK, 1, NULL, NULL);
        expect("probe fmi2GetNominalsOfContinuousStates", F.GetNominalsOfContinuousStates(c, x, (size_t)NX), fmi2OK,
               1, NULL, NULL);
        expect("probe fmi2SetTime", F.SetTime(c, 0.0), fmi2Error, 1, NULL, NULL);
        break;
    default:
        expect("probe fmi2GetReal", F.GetReal(c, &VR_OUTPUT, 1, &v), fmi2Error, 1, NULL, NULL);
        break;
    }
}

/* -- every function with valid arguments ------------------------------------------------ */
typedef fmi2Status (*Call)(fmi2Component c);

static fmi2Status call_SetDebugLogging(fmi2Component c) { return F.SetDebugLogging(c, fmi2False, 0, NULL); }
static fmi2Status call_SetupExperiment(fmi2Component c)
{
    return F.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, 10.0);
}
static fmi2Status call_EnterInitializationMode(fmi2Component c) { return F.EnterInitializationMode(c); }
static fmi2Status call_ExitInitializationMode(fmi2Component c) { return F.ExitInitializationMode(c); }
static fmi2Status call_Terminate(fmi2Component c) { return F.Terminate(c); }
static fmi2Status call_Reset(fmi2Component c) { return F.Reset(c); }
static fmi2Status call_GetReal(fmi2Component c)
{
    fmi2Real v;
    return F.GetReal(c, &VR_OUTPUT, 1, &v);
}
static fmi2Status call_GetInteger(fmi2Component c) { return F.GetInteger(c, NULL, 0, NULL); }
static fmi2Status call_GetBoolean(fmi2Component c) { return F.GetBoolean(c, NULL, 0, NULL); }
static fmi2Status call_GetString(fmi2Component c)
{
    fmi2String v;
    return F.GetString(c, &VR_STRING, 1, &v);
}
static fmi2Status call_SetReal(fmi2Component c) { return F.SetReal(c, &VR_TUNABLE, 1, &TUNABLE_START); }
static fmi2Status call_SetInteger(fmi2Component c) { return F.SetInteger(c, NULL, 0, NULL); }
static fmi2Status call_SetBoolean(fmi2Component c) { return F.SetBoolean(c, NULL, 0, NULL); }
static fmi2Status call_SetString(fmi2Component c)
{
    fmi2String v = STRING_START;
    return F.SetString(c, &VR_STRING, 1, &v);
}
static fmi2Status call_GetFMUstate(fmi2Component c)
{
    fmi2FMUstate s = NULL;
    fmi2Status status = F.GetFMUstate(c, &s);
    if (s) F.FreeFMUstate(DONOR, &s);
    return status;
}
static fmi2Status call_SetFMUstate(fmi2Component c) { return F.SetFMUstate(c, DONOR_STATE); }
static fmi2Status call_FreeFMUstate(fmi2Component c)
{
    fmi2FMUstate s = NULL;
    F.DeSerializeFMUstate(DONOR, SERIAL, SERIAL_SIZE, &s);
    fmi2Status status = F.FreeFMUstate(c, &s);
    if (s) F.FreeFMUstate(DONOR, &s);
    return status;
}
static fmi2Status call_SerializedFMUstateSize(fmi2Component c)
{
    size_t size;
    return F.SerializedFMUstateSize(c, DONOR_STATE, &size);
}
static fmi2Status call_SerializeFMUstate(fmi2Component c)
{
    fmi2Byte *buffer = malloc(SERIAL_SIZE);
    fmi2Status status = F.SerializeFMUstate(c, DONOR_STATE, buffer, SERIAL_SIZE);
    free(buffer);
    return status;
}
static fmi2Status call_DeSerializeFMUstate(fmi2Component c)
{
    fmi2FMUstate s = NULL;
    fmi2Status status = F.DeSerializeFMUstate(c, SERIAL, SERIAL_SIZE, &s);
    if (s) F.FreeFMUstate(DONOR, &s);
    return status;
}
static fmi2Status call_GetDirectionalDerivative(fmi2Component c)
{
    const fmi2Real seed = 1.0;
    fmi2Real out;
    return F.GetDirectionalDerivative(c, &VR_OUTPUT, 1, &VR_TUNABLE, 1, &seed, &out);
}
static fmi2Status call_SetRealInputDerivatives(fmi2Component c)
{
    return F.SetRealInputDerivatives(c, NULL, 0, NULL, NULL);
}
static fmi2Status call_GetRealOutputDerivatives(fmi2Component c)
{
    return F.GetRealOutputDerivatives(c, NULL, 0, NULL, NULL);
}
static fmi2Status call_DoStep(fmi2Component c) { return F.DoStep(c, 0.0, 0.01, fmi2True); }
static fmi2Status call_CancelStep(fmi2Component c) { return F.CancelStep(c); }
static fmi2Status call_GetStatus(fmi2Component c)
{
    fmi2Status v;
    return F.GetStatus(c, fmi2DoStepStatus, &v);
}
static fmi2Status call_GetRealStatus(fmi2Component c)
{
    fmi2Real v;
    return F.GetRealStatus(c, fmi2LastSuccessfulTime, &v);
}
static fmi2Status call_GetIntegerStatus(fmi2Component c)
{
    fmi2Integer v;
    return F.GetIntegerStatus(c, fmi2DoStepStatus, &v);
}
static fmi2Status call_GetBooleanStatus(fmi2Component c)
{
    fmi2Boolean v;
    return F.GetBooleanStatus(c, fmi2Terminated, &v);
}
static fmi2Status call_GetStringStatus(fmi2Component c)
{
    fmi2String v;
    return F.GetStringStatus(c, fmi2PendingStatus, &v);
}

static fmi2Status call_EnterEventMode(fmi2Component c) { return F.EnterEventMode(c); }
static fmi2Status call_NewDiscreteStates(fmi2Component c)
{
    fmi2EventInfo info;
    return F.NewDiscreteStates(c, &info);
}
static fmi2Status call_EnterContinuousTimeMode(fmi2Component c) { return F.EnterContinuousTimeMode(c); }
static fmi2Status call_CompletedIntegratorStep(fmi2Component c)
{
    fmi2Boolean enter, terminate;
    return F.CompletedIntegratorStep(c, fmi2True, &enter, &terminate);
}
static fmi2Status call_SetTime(fmi2Component c) { return F.SetTime(c, 0.0); }
static fmi2Status call_SetContinuousStates(fmi2Component c) { return F.SetContinuousStates(c, X_START, (size_t)NX); }
static fmi2Status call_GetDerivatives(fmi2Component c)
{
    fmi2Real dx[MAX_STATES];
    return F.GetDerivatives(c, dx, (size_t)NX);
}
static fmi2Status call_GetEventIndicators(fmi2Component c) { return F.GetEventIndicators(c, NULL, 0); }
static fmi2Status call_GetContinuousStates(fmi2Component c)
{
    fmi2Real x[MAX_STATES];
    return F.GetContinuousStates(c, x, (size_t)NX);
}
static fmi2Status call_GetNominalsOfContinuousStates(fmi2Component c)
{
    fmi2Real nominal[MAX_STATES];
    return F.GetNominalsOfContinuousStates(c, nominal, (size_t)NX);
}

/* Each function: its type, the states it is allowed in, and its status there with the arguments
   above: fmi2Error for what the FMU does not provide (directional derivatives), fmi2Discard for
   a status it does not have (an asynchronous fmi2DoStep's, any Integer status; FMI 2.0, 2.1.3).
   On an instance of the other type a function is refused in every state.  As the Reference-FMUs,
   except that no value can be read in the error state (fmi2GetXXX, fmi2GetFMUstate, the
   derivatives, states, event indicators and nominals). */
typedef struct { const char *name; int type; int allowed; fmi2Status there; Call call; } Entry;
#define E(name, type, allowed, there) {"fmi2" #name, type, allowed, there, call_##name}
static const Entry TABLE[] = {
    E(SetDebugLogging, BOTH, ANY, fmi2OK),
    E(SetupExperiment, BOTH, INSTANTIATED, fmi2OK),
    E(EnterInitializationMode, BOTH, INSTANTIATED, fmi2OK),
    E(ExitInitializationMode, BOTH, INITIALIZATION, fmi2OK),
    E(Terminate, BOTH, STEP_COMPLETE | STEP_FAILED | EVENT | CONTINUOUS, fmi2OK),
    E(Reset, BOTH, ANY, fmi2OK),
    E(GetReal, BOTH, READ, fmi2OK),
    E(GetInteger, BOTH, READ, fmi2OK),
    E(GetBoolean, BOTH, READ, fmi2OK),
    E(GetString, BOTH, READ, fmi2OK),
    E(SetReal, BOTH, WRITE, fmi2OK),                      /* a tunable parameter */
    E(SetInteger, BOTH, WRITE, fmi2OK),
    E(SetBoolean, BOTH, WRITE, fmi2OK),
    E(SetString, BOTH, INSTANTIATED | INITIALIZATION, fmi2OK),   /* a fixed parameter */
    E(GetFMUstate, BOTH, ANY & ~ERROR, fmi2OK),
    E(SetFMUstate, BOTH, ANY, fmi2OK),                    /* FMI 2.0's way out of the error state */
    E(FreeFMUstate, BOTH, ANY, fmi2OK),
    E(SerializedFMUstateSize, BOTH, ANY, fmi2OK),
    E(SerializeFMUstate, BOTH, ANY, fmi2OK),
    E(DeSerializeFMUstate, BOTH, ANY, fmi2OK),
    E(GetDirectionalDerivative, BOTH, READ, fmi2Error),
    E(SetRealInputDerivatives, CS, WRITE, fmi2OK),
    E(GetRealOutputDerivatives, CS, INITIALIZED, fmi2OK),
    E(DoStep, CS, STEP_COMPLETE, fmi2OK),
    E(CancelStep, CS, STEP_IN_PROGRESS, fmi2Error),
    E(GetStatus, CS, STATUS, fmi2Discard),
    E(GetRealStatus, CS, STATUS, fmi2OK),
    E(GetIntegerStatus, CS, STATUS, fmi2Discard),
    E(GetBooleanStatus, CS, STATUS, fmi2OK),
    E(GetStringStatus, CS, STATUS, fmi2Discard),
    E(EnterEventMode, ME, EVENT | CONTINUOUS, fmi2OK),    /* again in eventMode too (fmi-standard #275) */
    E(NewDiscreteStates, ME, EVENT, fmi2OK),
    E(EnterContinuousTimeMode, ME, EVENT, fmi2OK),
    E(CompletedIntegratorStep, ME, CONTINUOUS, fmi2OK),
    E(SetTime, ME, EVENT | CONTINUOUS, fmi2OK),
    E(SetContinuousStates, ME, CONTINUOUS, fmi2OK),
    E(GetDerivatives, ME, EVENT | CONTINUOUS | TERMINATED, fmi2OK),   /* initializationMode: by fmi2GetReal */
    E(GetEventIndicators, ME, ME_READ, fmi2OK),
    E(GetContinuousStates, ME, ME_READ, fmi2OK),
    E(GetNominalsOfContinuousStates, ME, INSTANTIATED | EVENT | CONTINUOUS | TERMINATED, fmi2OK),
};
#define N_TABLE (sizeof TABLE / sizeof *TABLE)

static void case_state(const void *arg)
{
    const int index = *(const int *)arg;
    const Entry *e = &TABLE[index % N_TABLE];
    const int r = index / (int)N_TABLE;
    fmi2Component c = make(r);
    if (!c) return;
    if (e->type != BOTH && e->type != REACHED[r].type) {
        if (expect_refused(e->name, e->call(c), e->name, REACHED[r].word, TYPE_WORDS[REACHED[r].type])) probe(c, r);
    } else if (e->allowed & REACHED[r].state) {
        expect(e->name, e->call(c), e->there, 1, e->there == fmi2OK ? NULL : e->name, NULL);
    } else if (expect(e->name, e->call(c), fmi2Error, 1, e->name, REACHED[r].word)) {
        probe(c, r);
    }
    F.FreeInstance(c);
}

/* -- a NULL instance -------------------------------------------------------------------- */
static void case_null_instance(const void *arg)
{
    const Entry *e = &TABLE[*(const int *)arg];
    expect(e->name, e->call(NULL), fmi2Error, 0, NULL, NULL);
}

static void case_null_instance_lifecycle(const void *arg)
{
    (void)arg;
    F.FreeInstance(NULL);                            /* must simply return */
    if (strcmp(F.GetVersion(), "2.0") != 0) fail("fmi2GetVersion returned '%s'", F.GetVersion());
    if (strcmp(F.GetTypesPlatform(), "default") != 0) fail("fmi2GetTypesPlatform returned '%s'", F.GetTypesPlatform());
}

/* -- NULL arguments --------------------------------------------------------------------- */
static fmi2Real REAL_BUFFER[1];
static fmi2Integer INT_BUFFER[1];
static fmi2Boolean BOOL_BUFFER[1];
static fmi2String STRING_BUFFER[1];
static const fmi2ValueReference NO_SUCH_VR = 999999;

static fmi2Status n_SetDebugLogging(fmi2Component c) { return F.SetDebugLogging(c, fmi2True, 1, NULL); }
static fmi2Status n_SetDebugLogging_item(fmi2Component c)
{
    const fmi2String categories[1] = {NULL};
    return F.SetDebugLogging(c, fmi2True, 1, categories);
}
static fmi2Status n_GetReal_vr(fmi2Component c) { return F.GetReal(c, NULL, 1, REAL_BUFFER); }
static fmi2Status n_GetReal_value(fmi2Component c) { return F.GetReal(c, &VR_OUTPUT, 1, NULL); }
static fmi2Status n_GetInteger_vr(fmi2Component c) { return F.GetInteger(c, NULL, 1, INT_BUFFER); }
static fmi2Status n_GetInteger_value(fmi2Component c) { return F.GetInteger(c, &NO_SUCH_VR, 1, NULL); }
static fmi2Status n_GetBoolean_vr(fmi2Component c) { return F.GetBoolean(c, NULL, 1, BOOL_BUFFER); }
static fmi2Status n_GetBoolean_value(fmi2Component c) { return F.GetBoolean(c, &NO_SUCH_VR, 1, NULL); }
static fmi2Status n_GetString_vr(fmi2Component c) { return F.GetString(c, NULL, 1, STRING_BUFFER); }
static fmi2Status n_GetString_value(fmi2Component c) { return F.GetString(c, &VR_STRING, 1, NULL); }
static fmi2Status n_SetReal_vr(fmi2Component c) { return F.SetReal(c, NULL, 1, &TUNABLE_START); }
static fmi2Status n_SetReal_value(fmi2Component c) { return F.SetReal(c, &VR_TUNABLE, 1, NULL); }
static fmi2Status n_SetInteger_vr(fmi2Component c) { return F.SetInteger(c, NULL, 1, INT_BUFFER); }
static fmi2Status n_SetInteger_value(fmi2Component c) { return F.SetInteger(c, &NO_SUCH_VR, 1, NULL); }
static fmi2Status n_SetBoolean_vr(fmi2Component c) { return F.SetBoolean(c, NULL, 1, BOOL_BUFFER); }
static fmi2Status n_SetBoolean_value(fmi2Component c) { return F.SetBoolean(c, &NO_SUCH_VR, 1, NULL); }
static fmi2Status n_SetString_vr(fmi2Component c)
{
    fmi2String v = STRING_START;
    return F.SetString(c, NULL, 1, &v);
}
static fmi2Status n_SetString_value(fmi2Component c) { return F.SetString(c, &VR_STRING, 1, NULL); }
static fmi2Status n_SetString_item(fmi2Component c)
{
    const fmi2String v = NULL;
    return F.SetString(c, &VR_STRING, 1, &v);
}
static fmi2Status n_GetFMUstate(fmi2Component c) { return F.GetFMUstate(c, NULL); }
static fmi2Status n_SetFMUstate(fmi2Component c) { return F.SetFMUstate(c, NULL); }
static fmi2Status n_FreeFMUstate(fmi2Component c) { return F.FreeFMUstate(c, NULL); }
static fmi2Status n_SerializedFMUstateSize_state(fmi2Component c)
{
    size_t size;
    return F.SerializedFMUstateSize(c, NULL, &size);
}
static fmi2Status n_SerializedFMUstateSize_size(fmi2Component c)
{
    return F.SerializedFMUstateSize(c, DONOR_STATE, NULL);
}
static fmi2Status n_SerializeFMUstate_state(fmi2Component c)
{
    fmi2Byte buffer[8];
    return F.SerializeFMUstate(c, NULL, buffer, sizeof buffer);
}
static fmi2Status n_SerializeFMUstate_buffer(fmi2Component c)
{
    return F.SerializeFMUstate(c, DONOR_STATE, NULL, SERIAL_SIZE);
}
static fmi2Status n_DeSerializeFMUstate_buffer(fmi2Component c)
{
    fmi2FMUstate s = NULL;
    fmi2Status status = F.DeSerializeFMUstate(c, NULL, SERIAL_SIZE, &s);
    if (s) F.FreeFMUstate(DONOR, &s);
    return status;
}
static fmi2Status n_DeSerializeFMUstate_state(fmi2Component c)
{
    return F.DeSerializeFMUstate(c, SERIAL, SERIAL_SIZE, NULL);
}
static fmi2Status n_GetDirectionalDerivative(fmi2Component c)
{
    return F.GetDirectionalDerivative(c, NULL, 1, NULL, 1, NULL, NULL);
}
static fmi2Status n_SetRealInputDerivatives(fmi2Component c)
{
    return F.SetRealInputDerivatives(c, NULL, 1, NULL, NULL);
}
static fmi2Status n_GetRealOutputDerivatives(fmi2Component c)
{
    return F.GetRealOutputDerivatives(c, NULL, 1, NULL, NULL);
}
static fmi2Status n_GetStatus(fmi2Component c) { return F.GetStatus(c, fmi2DoStepStatus, NULL); }
static fmi2Status n_GetRealStatus(fmi2Component c) { return F.GetRealStatus(c, fmi2LastSuccessfulTime, NULL); }
static fmi2Status n_GetIntegerStatus(fmi2Component c) { return F.GetIntegerStatus(c, fmi2DoStepStatus, NULL); }
static fmi2Status n_GetBooleanStatus(fmi2Component c) { return F.GetBooleanStatus(c, fmi2Terminated, NULL); }
static fmi2Status n_GetStringStatus(fmi2Component c) { return F.GetStringStatus(c, fmi2PendingStatus, NULL); }
static fmi2Status n_NewDiscreteStates(fmi2Component c) { return F.NewDiscreteStates(c, NULL); }
static fmi2Status n_CompletedIntegratorStep_enter(fmi2Component c)
{
    fmi2Boolean terminate;
    return F.CompletedIntegratorStep(c, fmi2True, NULL, &terminate);
}
static fmi2Status n_CompletedIntegratorStep_terminate(fmi2Component c)
{
    fmi2Boolean enter;
    return F.CompletedIntegratorStep(c, fmi2True, &enter, NULL);
}
static fmi2Status n_SetContinuousStates(fmi2Component c) { return F.SetContinuousStates(c, NULL, (size_t)NX); }
static fmi2Status n_GetDerivatives(fmi2Component c) { return F.GetDerivatives(c, NULL, (size_t)NX); }
static fmi2Status n_GetEventIndicators(fmi2Component c) { return F.GetEventIndicators(c, NULL, 1); }
static fmi2Status n_GetContinuousStates(fmi2Component c) { return F.GetContinuousStates(c, NULL, (size_t)NX); }
static fmi2Status n_GetNominalsOfContinuousStates(fmi2Component c)
{
    return F.GetNominalsOfContinuousStates(c, NULL, (size_t)NX);
}

/* Each NULL argument, in a state where the call is allowed; the message must name the function. */
typedef struct { const char *name; const char *argument; int r; Call call; } NullEntry;
#define N(fn, arg, r, suffix) {"fmi2" #fn, arg, r, n_##fn##suffix}
static const NullEntry NULLS[] = {
    N(SetDebugLogging, "categories", R_INSTANTIATED, ),
    N(SetDebugLogging, "categories[0]", R_INSTANTIATED, _item),
    N(GetReal, "vr", R_STEP_COMPLETE, _vr), N(GetReal, "value", R_STEP_COMPLETE, _value),
    N(GetInteger, "vr", R_STEP_COMPLETE, _vr), N(GetInteger, "value", R_STEP_COMPLETE, _value),
    N(GetBoolean, "vr", R_STEP_COMPLETE, _vr), N(GetBoolean, "value", R_STEP_COMPLETE, _value),
    N(GetString, "vr", R_STEP_COMPLETE, _vr), N(GetString, "value", R_STEP_COMPLETE, _value),
    N(SetReal, "vr", R_INSTANTIATED, _vr), N(SetReal, "value", R_INSTANTIATED, _value),
    N(SetInteger, "vr", R_INSTANTIATED, _vr), N(SetInteger, "value", R_INSTANTIATED, _value),
    N(SetBoolean, "vr", R_INSTANTIATED, _vr), N(SetBoolean, "value", R_INSTANTIATED, _value),
    N(SetString, "vr", R_INSTANTIATED, _vr), N(SetString, "value", R_INSTANTIATED, _value),
    N(SetString, "value[0]", R_INSTANTIATED, _item),
    N(GetFMUstate, "FMUstate", R_STEP_COMPLETE, ), N(SetFMUstate, "FMUstate", R_STEP_COMPLETE, ),
    N(FreeFMUstate, "FMUstate", R_STEP_COMPLETE, ),
    N(SerializedFMUstateSize, "FMUstate", R_STEP_COMPLETE, _state),
    N(SerializedFMUstateSize, "size", R_STEP_COMPLETE, _size),
    N(SerializeFMUstate, "FMUstate", R_STEP_COMPLETE, _state),
    N(SerializeFMUstate, "serializedState", R_STEP_COMPLETE, _buffer),
    N(DeSerializeFMUstate, "serializedState", R_STEP_COMPLETE, _buffer),
    N(DeSerializeFMUstate, "FMUstate", R_STEP_COMPLETE, _state),
    N(GetDirectionalDerivative, "all", R_STEP_COMPLETE, ),
    N(SetRealInputDerivatives, "vr, order, value", R_STEP_COMPLETE, ),
    N(GetRealOutputDerivatives, "vr, order, value", R_STEP_COMPLETE, ),
    N(GetStatus, "value", R_STEP_COMPLETE, ), N(GetRealStatus, "value", R_STEP_COMPLETE, ),
    N(GetIntegerStatus, "value", R_STEP_COMPLETE, ), N(GetBooleanStatus, "value", R_STEP_COMPLETE, ),
    N(GetStringStatus, "value", R_STEP_COMPLETE, ),
    N(NewDiscreteStates, "fmi2eventInfo", R_EVENT, ),
    N(CompletedIntegratorStep, "enterEventMode", R_CONTINUOUS, _enter),
    N(CompletedIntegratorStep, "terminateSimulation", R_CONTINUOUS, _terminate),
    N(SetContinuousStates, "x", R_CONTINUOUS, ), N(GetDerivatives, "derivatives", R_CONTINUOUS, ),
    N(GetEventIndicators, "eventIndicators", R_CONTINUOUS, ), N(GetContinuousStates, "x", R_CONTINUOUS, ),
    N(GetNominalsOfContinuousStates, "x_nominal", R_CONTINUOUS, ),
};
#define N_NULLS (sizeof NULLS / sizeof *NULLS)

static void case_null_argument(const void *arg)
{
    const NullEntry *e = &NULLS[*(const int *)arg];
    fmi2Component c = make(e->r);
    if (!c) return;
    expect(e->name, e->call(c), fmi2Error, 1, e->name, NULL);
    F.FreeInstance(c);
    expect(e->name, e->call(NULL), fmi2Error, 0, NULL, NULL);   /* and with no instance either */
}

/* -- sequences -------------------------------------------------------------------------- */
static void case_unknown_references(const void *arg)
{
    fmi2Real v;
    fmi2String s;
    fmi2Component c = make(R_STEP_COMPLETE);
    (void)arg;
    if (!c) return;
    expect("fmi2GetReal(unknown vr)", F.GetReal(c, &NO_SUCH_VR, 1, &v), fmi2Error, 1, "fmi2GetReal", NULL);
    expect("fmi2GetReal(String vr)", F.GetReal(c, &VR_STRING, 1, &v), fmi2Error, 1, "fmi2GetReal", NULL);
    expect("fmi2GetString(Real vr)", F.GetString(c, &VR_OUTPUT, 1, &s), fmi2Error, 1, "fmi2GetString", NULL);
    expect("fmi2SetReal(output)", F.SetReal(c, &VR_OUTPUT, 1, &TUNABLE_START), fmi2Error, 1, "fmi2SetReal", NULL);
    expect("fmi2GetInteger(unknown vr)", F.GetInteger(c, &NO_SUCH_VR, 1, INT_BUFFER), fmi2Error, 1,
           "fmi2GetInteger", NULL);
    expect("fmi2GetReal(nvr = 0, NULL arrays)", F.GetReal(c, NULL, 0, NULL), fmi2OK, 1, NULL, NULL);
    expect("fmi2SetReal(nvr = 0, NULL arrays)", F.SetReal(c, NULL, 0, NULL), fmi2OK, 1, NULL, NULL);
    F.FreeInstance(c);
}

static void case_refused_set_changes_nothing(const void *arg)
{
    const fmi2ValueReference vrs[2] = {VR_TUNABLE, NO_SUCH_VR};
    const fmi2Real values[2] = {2.0 * TUNABLE_START + 1.0, 1.0};
    fmi2Real v = 0.0;
    fmi2Component c = make(R_INITIALIZATION);
    (void)arg;
    if (!c) return;
    expect("fmi2SetReal(tunable, unknown vr)", F.SetReal(c, vrs, 2, values), fmi2Error, 1, "fmi2SetReal", NULL);
    expect("fmi2GetReal(tunable)", F.GetReal(c, &VR_TUNABLE, 1, &v), fmi2OK, 1, NULL, NULL);
    if (v != TUNABLE_START)
        fail("a refused fmi2SetReal changed the tunable parameter to %g (was %g)", v, TUNABLE_START);
    F.FreeInstance(c);
}

static void case_reset_after_failed_init(const void *arg)
{
    fmi2Real v;
    fmi2Component c = make(R_FAILED_INIT);
    (void)arg;
    if (!c) return;
    expect("fmi2Reset", F.Reset(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2SetupExperiment", call_SetupExperiment(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2EnterInitializationMode", F.EnterInitializationMode(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2ExitInitializationMode", F.ExitInitializationMode(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2DoStep", F.DoStep(c, 0.0, 0.01, fmi2True), fmi2OK, 1, NULL, NULL);
    expect("fmi2GetReal", F.GetReal(c, &VR_OUTPUT, 1, &v), fmi2OK, 1, NULL, NULL);
    F.FreeInstance(c);
}

static void case_set_state_after_failed_step(const void *arg)
{
    fmi2Real v;
    fmi2Component c = make(R_FAILED_STEP);
    (void)arg;
    if (!c) return;
    expect("fmi2SetFMUstate", F.SetFMUstate(c, DONOR_STATE), fmi2OK, 1, NULL, NULL);
    expect("fmi2DoStep", F.DoStep(c, 0.0, 0.01, fmi2True), fmi2OK, 1, NULL, NULL);
    expect("fmi2GetReal", F.GetReal(c, &VR_OUTPUT, 1, &v), fmi2OK, 1, NULL, NULL);
    F.FreeInstance(c);
}

/* Communication steps that cannot be taken as given: each refused with fmi2Error and a message,
   never fmi2OK without advancing (the FMU's times are whole nanoseconds). */
static void case_bad_step_arguments(const void *arg)
{
    static const struct { const char *label; double t, h; const char *says; } BAD[] = {
        {"fmi2DoStep(h = 0)", 0.0, 0.0, "step size"}, {"fmi2DoStep(h = -0.01)", 0.0, -0.01, "step size"},
        {"fmi2DoStep(h = inf)", 0.0, INFINITY, "step size"}, {"fmi2DoStep(h = -inf)", 0.0, -INFINITY, "step size"},
        {"fmi2DoStep(h = NaN)", 0.0, NAN, "step size"}, {"fmi2DoStep(h = 1e-12)", 0.0, 1e-12, "cannot advance"},
        {"fmi2DoStep(h = 4e-10)", 0.0, 4e-10, "cannot advance"},
        {"fmi2DoStep(t = inf)", INFINITY, 0.01, "communication point"},
        {"fmi2DoStep(t = NaN)", NAN, 0.01, "communication point"}};
    fmi2Real t = -1.0;
    (void)arg;
    for (size_t i = 0; i < sizeof BAD / sizeof *BAD; i++) {
        fmi2Component c = make(R_STEP_COMPLETE);
        if (!c) return;
        expect(BAD[i].label, F.DoStep(c, BAD[i].t, BAD[i].h, fmi2True), fmi2Error, 1, "fmi2DoStep", BAD[i].says);
        expect("fmi2GetReal after a failed fmi2DoStep", call_GetReal(c), fmi2Error, 1, "fmi2GetReal", "state error");
        F.FreeInstance(c);
    }
    fmi2Component c = make(R_STEP_COMPLETE);        /* the shortest step that advances: 1 ns */
    if (!c) return;
    expect("fmi2DoStep(h = 1e-9)", F.DoStep(c, 0.0, 1e-9, fmi2True), fmi2OK, 1, NULL, NULL);
    expect("fmi2GetRealStatus(fmi2LastSuccessfulTime)", F.GetRealStatus(c, fmi2LastSuccessfulTime, &t), fmi2OK, 1,
           NULL, NULL);
    if (!(t > 0.0)) fail("fmi2DoStep(h = 1e-9) returned fmi2OK but the time is %g", t);
    F.FreeInstance(c);
}

/* A parameter value that is not finite is refused by fmi2SetReal, naming why, changing nothing. */
static void case_non_finite_values(const void *arg)
{
    static const double VALUES[] = {NAN, INFINITY, -INFINITY};
    fmi2Real v = 0.0;
    (void)arg;
    fmi2Component c = make(R_INITIALIZATION);
    if (!c) return;
    for (size_t i = 0; i < sizeof VALUES / sizeof *VALUES; i++)
        expect("fmi2SetReal(tunable = a non-finite value)", F.SetReal(c, &VR_TUNABLE, 1, &VALUES[i]), fmi2Error, 1,
               "fmi2SetReal", "must be finite");
    expect("fmi2GetReal(tunable)", F.GetReal(c, &VR_TUNABLE, 1, &v), fmi2OK, 1, NULL, NULL);
    if (v != TUNABLE_START) fail("a refused fmi2SetReal changed the tunable parameter to %g (was %g)", v, TUNABLE_START);
    F.FreeInstance(c);
}

static int all_finite(const fmi2Real *x, int n);

/* Model exchange at finite states of no physical size (1e308, -1e308, ...): the derivatives are
   either refused (fmi2Error, the instance in the error state) or finite; never NaN with fmi2OK. */
static void case_huge_states(const void *arg)
{
    fmi2Real x[MAX_STATES], dx[MAX_STATES];
    (void)arg;
    fmi2Component c = make(R_CONTINUOUS);
    if (!c) return;
    for (int i = 0; i < NX; i++) x[i] = i % 2 ? -1e308 : 1e308;
    expect("fmi2SetContinuousStates(+-1e308)", F.SetContinuousStates(c, x, (size_t)NX), fmi2OK, 1, NULL, NULL);
    const fmi2Status status = F.GetDerivatives(c, dx, (size_t)NX);
    if (status == fmi2OK) {
        if (!all_finite(dx, NX)) fail("fmi2GetDerivatives at states +-1e308 returned fmi2OK with a non-finite value");
        clear_log();
    } else {
        expect("fmi2GetDerivatives at states +-1e308", status, fmi2Error, 1, "not finite", NULL);
    }
    F.FreeInstance(c);
}

/* -- crafted FMU states ------------------------------------------------------------------ */
/* A serialized FMU state of the donor with its bytes changed: at every 4-byte offset each of a few
   integers (out-of-range indices, a mode of 12345, -1), at every 8-byte offset each of a few
   doubles (NaN, inf, -1e308); then random bytes at random places (a fixed seed).  Each must be
   refused with fmi2Error and a message, or, accepted (a field no check needs), survive being used:
   fmi2SetFMUstate, the output, the String parameter, a step, the states and derivatives.  No
   crash and, under -fsanitize=address,undefined, no report: the harness exits non-zero on one.
   The instance that deserializes stays usable: it steps after the sweep. */
static unsigned long RANDOM = 36;
static unsigned long next_random(void)
{
    RANDOM = RANDOM * 6364136223846793005UL + 1442695040888963407UL;
    return RANDOM >> 33;
}

static int CRAFTED_REFUSED, CRAFTED_ACCEPTED;

/* One crafted state, deserialized by `reader` (a healthy instance of the donor's type) and, when
   accepted, set into and used by `user`. */
static void try_crafted(fmi2Component reader, fmi2Component user, const fmi2Byte *bytes)
{
    fmi2FMUstate state = NULL;
    fmi2Real v, x[MAX_STATES], dx[MAX_STATES];
    fmi2String s;
    const fmi2Status status = F.DeSerializeFMUstate(reader, bytes, SERIAL_SIZE, &state);
    if (status != fmi2OK) {
        CRAFTED_REFUSED++;
        expect("fmi2DeSerializeFMUstate(crafted)", status, fmi2Error, 1, "fmi2DeSerializeFMUstate", NULL);
        return;
    }
    CRAFTED_ACCEPTED++;
    clear_log();
    if (F.SetFMUstate(user, state) == fmi2OK) {
        F.GetReal(user, &VR_OUTPUT, 1, &v);
        F.GetString(user, &VR_STRING, 1, &s);
        if (TYPE == CS) {
            F.DoStep(user, 0.0, 0.01, fmi2True);
            F.GetReal(user, &VR_OUTPUT, 1, &v);
        } else {
            F.GetContinuousStates(user, x, (size_t)NX);
            F.EnterContinuousTimeMode(user);
            F.GetDerivatives(user, dx, (size_t)NX);
        }
    }
    clear_log();
    F.FreeFMUstate(reader, &state);
}

static void case_crafted_states(const void *arg)
{
    static const int INTS[] = {-1, 12345, 100000000, 7};
    static const double DOUBLES[] = {NAN, INFINITY, -1e308};
    const int type = *(const int *)arg;
    fmi2Component reader = make(type == ME ? R_EVENT : R_STEP_COMPLETE);
    fmi2Component user = make(type == ME ? R_EVENT : R_STEP_COMPLETE);
    fmi2Byte *bytes = malloc(SERIAL_SIZE);
    fmi2Real v;
    CRAFTED_REFUSED = CRAFTED_ACCEPTED = 0;
    if (!reader || !user || !bytes) goto done;
    for (size_t at = 0; at + sizeof(int) <= SERIAL_SIZE; at += sizeof(int))
        for (size_t k = 0; k < sizeof INTS / sizeof *INTS; k++) {
            memcpy(bytes, SERIAL, SERIAL_SIZE);
            memcpy(bytes + at, &INTS[k], sizeof(int));
            try_crafted(reader, user, bytes);
        }
    for (size_t at = 0; at + sizeof(double) <= SERIAL_SIZE; at += sizeof(double))
        for (size_t k = 0; k < sizeof DOUBLES / sizeof *DOUBLES; k++) {
            memcpy(bytes, SERIAL, SERIAL_SIZE);
            memcpy(bytes + at, &DOUBLES[k], sizeof(double));
            try_crafted(reader, user, bytes);
        }
    for (int trial = 0; trial < 3000; trial++) {
        memcpy(bytes, SERIAL, SERIAL_SIZE);
        for (int n = 1 + (int)(next_random() % 8); n > 0; n--) bytes[next_random() % SERIAL_SIZE] = (fmi2Byte)next_random();
        try_crafted(reader, user, bytes);
    }
    if (CRAFTED_REFUSED == 0) fail("no crafted state was refused (%d accepted)", CRAFTED_ACCEPTED);
    printf("crafted states (%s): %d refused, %d accepted\n", type == ME ? "model exchange" : "co-simulation",
           CRAFTED_REFUSED, CRAFTED_ACCEPTED);
    /* the reader is still usable */
    if (type == CS)
        expect("fmi2DoStep after the crafted states", F.DoStep(reader, 0.0, 0.01, fmi2True), fmi2OK, 1, NULL, NULL);
    expect("fmi2GetReal after the crafted states", F.GetReal(reader, &VR_OUTPUT, 1, &v), fmi2OK, 1, NULL, NULL);
done:
    free(bytes);
    if (reader) F.FreeInstance(reader);
    if (user) F.FreeInstance(user);
}

/* Steps `from` .. `to` - 1 of 0.01 s, the tunable parameter raised by 10 % before step 50;
   the output after each step into rows[k]. */
static void steps(fmi2Component c, int from, int to, fmi2Real rows[])
{
    const fmi2Real changed = 1.1 * TUNABLE_START;
    for (int k = from; k < to; k++) {
        if (k == 50) expect("fmi2SetReal(tunable)", F.SetReal(c, &VR_TUNABLE, 1, &changed), fmi2OK, 1, NULL, NULL);
        expect("fmi2DoStep", F.DoStep(c, k * 0.01, 0.01, fmi2True), fmi2OK, 1, NULL, NULL);
        expect("fmi2GetReal", F.GetReal(c, &VR_OUTPUT, 1, &rows[k]), fmi2OK, 1, NULL, NULL);
    }
}

/* A short healthy run through the model's code paths (the parameter change re-assembles and
   restarts the integrator), then a replay of its second half from a saved FMU state, which
   must give the same numbers; valgrind thus sees the numerics too. */
static void case_run(const void *arg)
{
    fmi2Real first[100], replay[100], t = -1.0;
    fmi2FMUstate saved = NULL;
    fmi2Component c = make(R_STEP_COMPLETE);
    (void)arg;
    if (!c) return;
    steps(c, 0, 50, first);
    expect("fmi2GetFMUstate at t = 0.5 s", F.GetFMUstate(c, &saved), fmi2OK, 1, NULL, NULL);
    steps(c, 50, 100, first);
    expect("fmi2GetRealStatus(fmi2LastSuccessfulTime)", F.GetRealStatus(c, fmi2LastSuccessfulTime, &t), fmi2OK, 1,
           NULL, NULL);
    if (!(t > 0.999 && t < 1.001)) fail("fmi2LastSuccessfulTime is %g s after 100 steps of 0.01 s", t);
    if (saved && expect("fmi2SetFMUstate(t = 0.5 s)", F.SetFMUstate(c, saved), fmi2OK, 1, NULL, NULL)) {
        steps(c, 50, 100, replay);
        for (int k = 50; k < 100; k++)
            if (!(replay[k] == first[k])) {
                fail("after step %d the replay from the saved state gave %.17g, the run %.17g", k + 1, replay[k],
                     first[k]);
                break;
            }
    }
    if (saved) F.FreeFMUstate(c, &saved);
    F.FreeInstance(c);
}

/* -- model exchange sequences ------------------------------------------------------------ */
/* An FMU state saved by an instance of one type, given to an instance of the other: refused (its
   mode is of the other state machine), and the instance is where it was. */
static void case_state_of_the_other_type(const void *arg)
{
    (void)arg;
    fmi2Component c = make(R_STEP_COMPLETE);
    if (c) {
        if (expect_refused("fmi2SetFMUstate(a model-exchange state)", F.SetFMUstate(c, DONORS[ME].state),
                           "fmi2SetFMUstate", "model exchange", NULL))
            probe(c, R_STEP_COMPLETE);
        F.FreeInstance(c);
    }
    c = make(R_CONTINUOUS);
    if (c) {
        if (expect_refused("fmi2SetFMUstate(a co-simulation state)", F.SetFMUstate(c, DONORS[CS].state),
                           "fmi2SetFMUstate", "co-simulation", NULL))
            probe(c, R_CONTINUOUS);
        F.FreeInstance(c);
    }
    /* the type survives serialization */
    c = make(R_CONTINUOUS);
    if (c) {
        fmi2FMUstate s = NULL;
        if (expect("fmi2DeSerializeFMUstate(a co-simulation state)",
                   F.DeSerializeFMUstate(c, DONORS[CS].serial, DONORS[CS].size, &s), fmi2OK, 1, NULL, NULL)
            && expect_refused("fmi2SetFMUstate(a deserialized co-simulation state)", F.SetFMUstate(c, s),
                              "fmi2SetFMUstate", "co-simulation", NULL))
            probe(c, R_CONTINUOUS);
        if (s) F.FreeFMUstate(c, &s);
        F.FreeInstance(c);
    }
}

static int same_states(const fmi2Real *a, const fmi2Real *b) { return memcmp(a, b, (size_t)NX * sizeof *a) == 0; }

static int all_finite(const fmi2Real *x, int n)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(x[i])) return 0;
    return 1;
}

/* Wrong counts (nx other than the FMU's, ni other than 0), non-finite time and states: each refused
   with a message naming the function, nothing written, nothing changed. */
static void case_wrong_counts(const void *arg)
{
    enum { SENTINEL = 12345 };
    fmi2Real x[MAX_STATES + 1], before[MAX_STATES], buffer[MAX_STATES + 1];
    fmi2Boolean enter, terminate;
    char has[64];
    (void)arg;
    fmi2Component c = make(R_CONTINUOUS);
    if (!c) return;
    snprintf(has, sizeof has, "this FMU has %d", NX);
    expect("fmi2GetContinuousStates", F.GetContinuousStates(c, before, (size_t)NX), fmi2OK, 1, NULL, NULL);
    for (int i = 0; i <= MAX_STATES; i++) buffer[i] = SENTINEL;
    memcpy(x, before, (size_t)NX * sizeof *x);
    x[NX] = 1.0;
    expect("fmi2SetContinuousStates(nx + 1)", F.SetContinuousStates(c, x, (size_t)NX + 1), fmi2Error, 1,
           "fmi2SetContinuousStates", has);
    expect("fmi2SetContinuousStates(nx - 1)", F.SetContinuousStates(c, x, (size_t)NX - 1), fmi2Error, 1,
           "fmi2SetContinuousStates", has);
    expect("fmi2GetDerivatives(nx + 1)", F.GetDerivatives(c, buffer, (size_t)NX + 1), fmi2Error, 1,
           "fmi2GetDerivatives", has);
    expect("fmi2GetDerivatives(NULL, 0)", F.GetDerivatives(c, NULL, 0), fmi2Error, 1, "fmi2GetDerivatives", has);
    expect("fmi2GetContinuousStates(nx - 1)", F.GetContinuousStates(c, buffer, (size_t)NX - 1), fmi2Error, 1,
           "fmi2GetContinuousStates", has);
    expect("fmi2GetNominalsOfContinuousStates(nx + 1)", F.GetNominalsOfContinuousStates(c, buffer, (size_t)NX + 1),
           fmi2Error, 1, "fmi2GetNominalsOfContinuousStates", has);
    expect("fmi2GetEventIndicators(ni = 1)", F.GetEventIndicators(c, buffer, 1), fmi2Error, 1,
           "fmi2GetEventIndicators", "this FMU has 0");
    for (int i = 0; i <= MAX_STATES; i++)
        if (buffer[i] != SENTINEL) {
            fail("a refused call wrote %g into element %d of its output array", buffer[i], i);
            break;
        }
    expect("fmi2SetTime(NaN)", F.SetTime(c, NAN), fmi2Error, 1, "fmi2SetTime", NULL);
    expect("fmi2SetTime(inf)", F.SetTime(c, INFINITY), fmi2Error, 1, "fmi2SetTime", NULL);
    memcpy(x, before, (size_t)NX * sizeof *x);
    x[NX - 1] = NAN;
    expect("fmi2SetContinuousStates(a NaN)", F.SetContinuousStates(c, x, (size_t)NX), fmi2Error, 1,
           "fmi2SetContinuousStates", NULL);
    expect("fmi2GetContinuousStates", F.GetContinuousStates(c, x, (size_t)NX), fmi2OK, 1, NULL, NULL);
    if (!same_states(x, before)) fail("refused calls changed the continuous states");
    expect("fmi2CompletedIntegratorStep", F.CompletedIntegratorStep(c, fmi2True, &enter, &terminate), fmi2OK, 1,
           NULL, NULL);
    F.FreeInstance(c);
}

/* Out of the error state a failed fmi2NewDiscreteStates leaves: by fmi2SetFMUstate (a state saved
   in eventMode, before the failure), then by fmi2Reset and a new initialization. */
static void case_recover_after_failed_event(const void *arg)
{
    fmi2EventInfo info;
    fmi2Real dx[MAX_STATES];
    (void)arg;
    fmi2Component c = make(R_FAILED_EVENT);
    if (!c) return;
    expect("fmi2GetDerivatives in state error", F.GetDerivatives(c, dx, (size_t)NX), fmi2Error, 1,
           "fmi2GetDerivatives", "state error");
    expect("fmi2SetFMUstate", F.SetFMUstate(c, DONORS[ME].state), fmi2OK, 1, NULL, NULL);
    expect("fmi2NewDiscreteStates", F.NewDiscreteStates(c, &info), fmi2OK, 1, NULL, NULL);
    expect("fmi2EnterContinuousTimeMode", F.EnterContinuousTimeMode(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2GetDerivatives", F.GetDerivatives(c, dx, (size_t)NX), fmi2OK, 1, NULL, NULL);
    if (!all_finite(dx, NX)) fail("the derivatives after fmi2SetFMUstate are not finite");
    expect("fmi2Reset", F.Reset(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2SetupExperiment", call_SetupExperiment(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2EnterInitializationMode", F.EnterInitializationMode(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2ExitInitializationMode", F.ExitInitializationMode(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2NewDiscreteStates", F.NewDiscreteStates(c, &info), fmi2OK, 1, NULL, NULL);
    expect("fmi2EnterContinuousTimeMode", F.EnterContinuousTimeMode(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2GetDerivatives", F.GetDerivatives(c, dx, (size_t)NX), fmi2OK, 1, NULL, NULL);
    F.FreeInstance(c);
}

/* The event update's answer: nothing more to do, the states kept. */
static void check_event_info(const char *when, const fmi2EventInfo *info)
{
    if (info->newDiscreteStatesNeeded || info->terminateSimulation || info->nominalsOfContinuousStatesChanged
        || info->valuesOfContinuousStatesChanged || info->nextEventTimeDefined)
        fail("fmi2NewDiscreteStates %s: newDiscreteStatesNeeded %d, terminateSimulation %d, "
             "nominalsOfContinuousStatesChanged %d, valuesOfContinuousStatesChanged %d, nextEventTimeDefined %d "
             "(expected all false: no event indicators, no time events, a re-assembly keeps the states)", when,
             info->newDiscreteStatesNeeded, info->terminateSimulation, info->nominalsOfContinuousStatesChanged,
             info->valuesOfContinuousStatesChanged, info->nextEventTimeDefined);
}

#define ME_STEP 1e-3          /* s: the explicit Euler step */
#define ME_STEPS 40

/* Explicit Euler steps `from` .. `to` - 1 of ME_STEP from x (updated): at each, the derivatives
   at (t, x), then x + h dx set at t + h and the step completed; the states after each step into
   rows[k], the output into out[k]. */
static void euler(fmi2Component c, int from, int to, fmi2Real *x, fmi2Real rows[][MAX_STATES], fmi2Real out[])
{
    fmi2Real dx[MAX_STATES];
    fmi2Boolean enter = fmi2True, terminate = fmi2True;
    for (int k = from; k < to; k++) {
        const int ok = expect("fmi2SetTime", F.SetTime(c, k * ME_STEP), fmi2OK, 1, NULL, NULL)
                       && expect("fmi2SetContinuousStates", F.SetContinuousStates(c, x, (size_t)NX), fmi2OK, 1,
                                 NULL, NULL)
                       && expect("fmi2GetDerivatives", F.GetDerivatives(c, dx, (size_t)NX), fmi2OK, 1, NULL, NULL);
        if (!ok) return;
        if (!all_finite(dx, NX)) { fail("step %d: the derivatives are not finite", k); return; }
        for (int i = 0; i < NX; i++) x[i] += ME_STEP * dx[i];
        expect("fmi2SetTime", F.SetTime(c, (k + 1) * ME_STEP), fmi2OK, 1, NULL, NULL);
        expect("fmi2SetContinuousStates", F.SetContinuousStates(c, x, (size_t)NX), fmi2OK, 1, NULL, NULL);
        expect("fmi2CompletedIntegratorStep", F.CompletedIntegratorStep(c, fmi2False, &enter, &terminate), fmi2OK,
               1, NULL, NULL);
        if (enter || terminate)
            fail("step %d: fmi2CompletedIntegratorStep asked for %s", k, enter ? "an event" : "the end");
        expect("fmi2GetReal(output)", F.GetReal(c, &VR_OUTPUT, 1, &out[k]), fmi2OK, 1, NULL, NULL);
        if (!isfinite(out[k])) fail("step %d: the output is %g", k, out[k]);
        memcpy(rows[k], x, (size_t)NX * sizeof *x);
    }
}

/* A short healthy model-exchange run: the event iteration after initialization, explicit Euler
   steps, an FMU state saved in continuousTimeMode and the second half replayed from it (the same
   numbers), then an event that changes the tunable parameter (the states kept), more steps, and
   fmi2Terminate.  Valgrind thus sees model exchange's numerics too. */
static void case_model_exchange_run(const void *arg)
{
    static fmi2Real rows[2 * ME_STEPS][MAX_STATES], replay[2 * ME_STEPS][MAX_STATES];
    fmi2Real out[2 * ME_STEPS], out_replay[2 * ME_STEPS], x[MAX_STATES], x_saved[MAX_STATES], after[MAX_STATES];
    fmi2Real nominal[MAX_STATES], dx[MAX_STATES], v = 0.0;
    const fmi2Real changed = 1.1 * TUNABLE_START;
    fmi2EventInfo info;
    fmi2FMUstate saved = NULL;
    const int half = ME_STEPS / 2;
    (void)arg;
    fmi2Component c = make(R_EVENT);
    if (!c) return;
    memset(&info, 0xff, sizeof info);
    expect("fmi2NewDiscreteStates", F.NewDiscreteStates(c, &info), fmi2OK, 1, NULL, NULL);
    check_event_info("after initialization", &info);
    expect("fmi2EnterContinuousTimeMode", F.EnterContinuousTimeMode(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2GetEventIndicators(ni = 0)", F.GetEventIndicators(c, NULL, 0), fmi2OK, 1, NULL, NULL);
    expect("fmi2GetNominalsOfContinuousStates", F.GetNominalsOfContinuousStates(c, nominal, (size_t)NX), fmi2OK, 1,
           NULL, NULL);
    for (int i = 0; i < NX; i++)
        if (!(nominal[i] > 0.0 && isfinite(nominal[i]))) fail("nominal of state %d is %g", i, nominal[i]);
    expect("fmi2GetContinuousStates", F.GetContinuousStates(c, x, (size_t)NX), fmi2OK, 1, NULL, NULL);
    if (!same_states(x, X_START)) fail("the states after initialization differ from the donor's");

    euler(c, 0, half, x, rows, out);
    memcpy(x_saved, x, sizeof x_saved);
    expect("fmi2GetFMUstate in continuousTimeMode", F.GetFMUstate(c, &saved), fmi2OK, 1, NULL, NULL);
    euler(c, half, ME_STEPS, x, rows, out);
    if (saved && expect("fmi2SetFMUstate(saved in continuousTimeMode)", F.SetFMUstate(c, saved), fmi2OK, 1, NULL,
                        NULL)) {
        memcpy(x, x_saved, sizeof x);
        euler(c, half, ME_STEPS, x, replay, out_replay);   /* in continuousTimeMode again, or these fail */
        for (int k = half; k < ME_STEPS; k++)
            if (!same_states(replay[k], rows[k]) || !(out_replay[k] == out[k])) {
                fail("after step %d the replay from the saved state gave other states or output (%.17g, the run "
                     "%.17g)", k + 1, out_replay[k], out[k]);
                break;
            }
    }
    if (saved) F.FreeFMUstate(c, &saved);

    /* the event: the tunable parameter changes, the states do not */
    expect("fmi2EnterEventMode", F.EnterEventMode(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2SetTime in eventMode", F.SetTime(c, ME_STEPS * ME_STEP), fmi2OK, 1, NULL, NULL);
    expect("fmi2SetReal(tunable + 10 %) in eventMode", F.SetReal(c, &VR_TUNABLE, 1, &changed), fmi2OK, 1, NULL,
           NULL);
    memset(&info, 0xff, sizeof info);
    expect("fmi2NewDiscreteStates(tunable changed)", F.NewDiscreteStates(c, &info), fmi2OK, 1, NULL, NULL);
    check_event_info("after the parameter change", &info);
    expect("fmi2GetContinuousStates after the event", F.GetContinuousStates(c, after, (size_t)NX), fmi2OK, 1, NULL,
           NULL);
    if (!same_states(after, x)) fail("the event changed the continuous states (valuesOfContinuousStatesChanged false)");
    expect("fmi2GetReal(tunable)", F.GetReal(c, &VR_TUNABLE, 1, &v), fmi2OK, 1, NULL, NULL);
    if (v != changed) fail("the tunable parameter reads %.17g after the event, set %.17g", v, changed);
    expect("fmi2EnterContinuousTimeMode", F.EnterContinuousTimeMode(c), fmi2OK, 1, NULL, NULL);
    euler(c, ME_STEPS, 2 * ME_STEPS, x, rows, out);
    expect("fmi2Terminate", F.Terminate(c), fmi2OK, 1, NULL, NULL);
    expect("fmi2GetDerivatives in state terminated", F.GetDerivatives(c, dx, (size_t)NX), fmi2OK, 1, NULL, NULL);
    if (!all_finite(dx, NX)) fail("the derivatives in state terminated are not finite");
    expect("fmi2GetReal in state terminated", F.GetReal(c, &VR_OUTPUT, 1, &v), fmi2OK, 1, NULL, NULL);
    if (!(v == out[2 * ME_STEPS - 1])) fail("the output in state terminated is %.17g, after the last step %.17g", v,
                                            out[2 * ME_STEPS - 1]);
    F.FreeInstance(c);
}

static void case_instantiate_refusals(const void *arg)
{
    fmi2CallbackFunctions no_logger = CALLBACKS, half = CALLBACKS;
    fmi2Component c;
    (void)arg;
    no_logger.logger = NULL;
    half.freeMemory = NULL;
    if ((c = F.Instantiate("strict", fmi2CoSimulation, GUID, "", NULL, fmi2False, fmi2False)))
        { fail("fmi2Instantiate without callbacks returned an instance"); F.FreeInstance(c); }
    if ((c = F.Instantiate("strict", fmi2CoSimulation, GUID, "", &no_logger, fmi2False, fmi2False)))
        { fail("fmi2Instantiate without a logger returned an instance"); F.FreeInstance(c); }
    struct { const char *what, *name, *guid; fmi2Type type; fmi2CallbackFunctions *cb; const char *says; } bad[] = {
        {"another GUID", "strict", "{00000000-0000-0000-0000-000000000000}", fmi2CoSimulation, &CALLBACKS, "GUID"},
        {"a NULL GUID", "strict", NULL, fmi2CoSimulation, &CALLBACKS, "GUID"},
        {"an unknown fmuType", "strict", GUID, (fmi2Type)7, &CALLBACKS, "fmuType"},
        {"a NULL instance name", NULL, GUID, fmi2CoSimulation, &CALLBACKS, "name"},
        {"an empty instance name", "", GUID, fmi2CoSimulation, &CALLBACKS, "name"},
        {"allocateMemory without freeMemory", "strict", GUID, fmi2CoSimulation, &half, "freeMemory"}};
    for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
        clear_log();
        c = F.Instantiate(bad[i].name, bad[i].type, bad[i].guid, "", bad[i].cb, fmi2False, fmi2False);
        if (c) {
            fail("fmi2Instantiate with %s returned an instance", bad[i].what);
            F.FreeInstance(c);
        } else if (LOG.count == 0 || LOG.worst != fmi2Error || !strstr(LOG.text, bad[i].says)) {
            fail("fmi2Instantiate with %s: expected an error message saying '%s' (log: %s)", bad[i].what,
                 bad[i].says, LOG.text);
        }
    }
    clear_log();
}

/* -- running the cases ------------------------------------------------------------------ */
static int ISOLATE = 1;
static const char *ONLY;                             /* --only: run the cases whose label contains it */

/* One case: in a forked child unless --in-process (a crash is then a failure, not the end of
   the run); in both, every block the FMU allocated during the case must be freed by it. */
static void run(const char *label, void (*fn)(const void *), const void *arg)
{
    if (ONLY && !strstr(label, ONLY)) return;
    CASES++;
    CASE = label;
    if (ISOLATE) {
        fflush(stdout);
        pid_t pid = fork();
        if (pid == 0) {
            FAILURES = 0;
            ISOLATE = 0;
            run(label, fn, arg);
            fflush(stdout);
            _exit(FAILURES > 100 ? 100 : FAILURES);
        }
        int status = 0;
        if (pid < 0 || waitpid(pid, &status, 0) < 0) {
            fail("cannot fork");
        } else if (WIFSIGNALED(status)) {
            fail("crashed (signal %d)", WTERMSIG(status));
        } else {
            FAILURES += WEXITSTATUS(status);
        }
        return;
    }
    const long held = ALLOCS - FREES;
    clear_log();
    fn(arg);
    if (ALLOCS - FREES != held)
        fail("%ld block(s) allocated through allocateMemory were not freed", ALLOCS - FREES - held);
}

/* The donor of `type`: a healthy instance just past initialization (stepComplete or eventMode),
   its FMU state saved and serialized; the CS donor reads the start values, the ME donor the states. */
static int setup_donor(int type)
{
    Donor *d = &DONORS[type];
    fmi2String s = NULL;
    d->c = make(type == ME ? R_ME_INITIALIZATION : R_INITIALIZATION);
    int ok = d->c != NULL;
    if (ok && type == CS) {
        ok = expect("donor fmi2GetReal", F.GetReal(d->c, &VR_TUNABLE, 1, &TUNABLE_START), fmi2OK, 1, NULL, NULL)
             && expect("donor fmi2GetString", F.GetString(d->c, &VR_STRING, 1, &s), fmi2OK, 1, NULL, NULL)
             && s && strlen(s) < sizeof STRING_START;
        if (ok) strcpy(STRING_START, s);
    }
    ok = ok && expect("donor fmi2ExitInitializationMode", F.ExitInitializationMode(d->c), fmi2OK, 1, NULL, NULL)
         && (type == CS || expect("donor fmi2GetContinuousStates", F.GetContinuousStates(d->c, X_START, (size_t)NX),
                                  fmi2OK, 1, NULL, NULL))
         && expect("donor fmi2GetFMUstate", F.GetFMUstate(d->c, &d->state), fmi2OK, 1, NULL, NULL)
         && expect("donor fmi2SerializedFMUstateSize", F.SerializedFMUstateSize(d->c, d->state, &d->size), fmi2OK, 1,
                   NULL, NULL);
    if (ok) {
        d->serial = malloc(d->size);
        ok = d->serial && expect("donor fmi2SerializeFMUstate", F.SerializeFMUstate(d->c, d->state, d->serial,
                                                                                    d->size), fmi2OK, 1, NULL, NULL);
    }
    return ok;
}

int main(int argc, char **argv)
{
    int first = 1;
    for (;;) {
        if (argc > first && strcmp(argv[first], "--in-process") == 0) { ISOLATE = 0; first++; continue; }
        if (argc > first + 1 && strcmp(argv[first], "--only") == 0) { ONLY = argv[first + 1]; first += 2; continue; }
        break;
    }
    if (argc - first != 6) {
        fprintf(stderr, "usage: %s [--in-process] [--only TEXT] LIBRARY GUID VR_TUNABLE VR_OUTPUT VR_STRING N_STATES\n",
                argv[0]);
        return 2;
    }
    NX = atoi(argv[first + 5]);
    if (NX < 1 || NX > MAX_STATES) {
        fprintf(stderr, "N_STATES must be 1 to %d (got '%s')\n", MAX_STATES, argv[first + 5]);
        return 2;
    }
    void *library = dlopen(argv[first], RTLD_NOW | RTLD_LOCAL);
    if (!library) { fprintf(stderr, "cannot load %s: %s\n", argv[first], dlerror()); return 2; }
#define LOAD(name) \
    if (!(*(void **)&F.name = dlsym(library, "fmi2" #name))) { \
        fprintf(stderr, "%s exports no fmi2" #name "\n", argv[first]); \
        return 2; \
    }
    FMI2_FUNCTIONS(LOAD)
    GUID = argv[first + 1];
    VR_TUNABLE = (fmi2ValueReference)strtoul(argv[first + 2], NULL, 10);
    VR_OUTPUT = (fmi2ValueReference)strtoul(argv[first + 3], NULL, 10);
    VR_STRING = (fmi2ValueReference)strtoul(argv[first + 4], NULL, 10);
    setvbuf(stdout, NULL, _IOLBF, 0);
    CASE = "setup";
    if (!setup_donor(CS) || !setup_donor(ME)) {
        fprintf(stderr, "cannot bring an instance to stepComplete or eventMode: see the FAIL lines\n");
        return 2;
    }

    static int index[N_REACHED * N_TABLE];
    static char labels[N_REACHED * N_TABLE + N_TABLE + N_NULLS][160];
    int k = 0;
    for (int r = 0; r < N_REACHED; r++)
        for (size_t i = 0; i < N_TABLE; i++, k++) {
            index[k] = k;
            snprintf(labels[k], sizeof labels[k], "%s in state %s", TABLE[i].name, REACHED[r].label);
            run(labels[k], case_state, &index[k]);
        }
    for (size_t i = 0; i < N_TABLE; i++, k++) {
        snprintf(labels[k], sizeof labels[k], "%s with a NULL instance", TABLE[i].name);
        run(labels[k], case_null_instance, &index[i]);
    }
    run("fmi2FreeInstance(NULL), fmi2GetVersion, fmi2GetTypesPlatform", case_null_instance_lifecycle, NULL);
    for (size_t i = 0; i < N_NULLS; i++, k++) {
        snprintf(labels[k], sizeof labels[k], "%s with NULL %s", NULLS[i].name, NULLS[i].argument);
        run(labels[k], case_null_argument, &index[i]);
    }
    run("unknown and mistyped value references", case_unknown_references, NULL);
    run("a refused fmi2SetReal changes nothing", case_refused_set_changes_nothing, NULL);
    run("fmi2Reset after a failed fmi2ExitInitializationMode", case_reset_after_failed_init, NULL);
    run("fmi2SetFMUstate after a failed fmi2DoStep", case_set_state_after_failed_step, NULL);
    run("fmi2DoStep with steps that cannot be taken (0, < 0, inf, NaN, < 1 ns) and a non-finite time",
        case_bad_step_arguments, NULL);
    run("fmi2SetReal with non-finite values", case_non_finite_values, NULL);
    run("model exchange at states +-1e308", case_huge_states, NULL);
    static const int TYPES[2] = {CS, ME};
    run("crafted FMU states (co-simulation)", case_crafted_states, &TYPES[CS]);
    run("crafted FMU states (model exchange)", case_crafted_states, &TYPES[ME]);
    run("fmi2Instantiate's refusals", case_instantiate_refusals, NULL);
    run("a healthy run with a parameter change, saved and replayed", case_run, NULL);
    run("an FMU state of the other type", case_state_of_the_other_type, NULL);
    run("wrong state and event-indicator counts, non-finite time and states", case_wrong_counts, NULL);
    run("fmi2SetFMUstate and fmi2Reset after a failed fmi2NewDiscreteStates", case_recover_after_failed_event, NULL);
    run("a healthy model-exchange run: Euler steps, saved and replayed, an event changing a parameter",
        case_model_exchange_run, NULL);

    CASE = "teardown";
    for (int type = CS; type <= ME; type++) {
        F.FreeFMUstate(DONORS[type].c, &DONORS[type].state);
        F.FreeInstance(DONORS[type].c);
        free(DONORS[type].serial);
    }
    if (ALLOCS != FREES) fail("%ld block(s) allocated through allocateMemory were never freed", ALLOCS - FREES);
    dlclose(library);
    printf("fmi2_strict_host: %d cases, %d failed check(s)\n", CASES, FAILURES);
    return FAILURES ? 1 : 0;
}
