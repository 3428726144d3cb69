/* A strict FMI 2.0 co-simulation host: it dlopens an FMU binary and calls every exported
   fmi2* function
     1. in every state of the co-simulation state machine the FMU can reach (instantiated,
        initializationMode, stepComplete, terminated, and error, reached both by a failed
        fmi2ExitInitializationMode and by a failed fmi2DoStep), with valid arguments;
     2. with a NULL instance;
     3. with NULL pointer or array arguments (array lengths > 0), in a state that allows the call;
   plus a few sequences: unknown value references, a refused fmi2SetReal changing nothing,
   recovery by fmi2Reset and fmi2SetFMUstate, fmi2Instantiate's refusals, and a short healthy
   run with a parameter change replayed from a saved FMU state.

   What it requires (the FMI 2.0 standard, as the Modelica Reference-FMUs implement it):
   - a call the state machine does not allow returns fmi2Error, logs a message naming the
     function and the instance's state, and changes nothing (checked by a probe call after it);
   - a NULL instance gives fmi2Error and no crash; a NULL argument gives fmi2Error and a message;
   - the status returned is the worst status logged during the call (an OK call logs no
     warning or error); a status inquiry the FMU has no value for gives fmi2Discard (FMI 2.0,
     section 2.1.3);
   - every block the FMU allocates through allocateMemory is given back through freeMemory;
   - stricter than the Reference-FMUs, as the native FourBar FMU promises: in the error state no
     value can be read (fmi2GetXXX, fmi2GetFMUstate and the output derivatives are refused).

   usage: fmi2_strict_host [--in-process] LIBRARY GUID VR_TUNABLE VR_OUTPUT VR_STRING
     VR_TUNABLE: a tunable Real parameter that must be positive (set to -1 to make
     initialization and a step fail); VR_OUTPUT: a Real output; VR_STRING: a fixed String
     parameter.  Each case runs in a forked child, so a crash is reported as a failed case;
     --in-process runs them in one process (for valgrind).
   Prints "FAIL ..." for each failed check and a summary line; exit status 0 when everything
   holds, 1 when a check failed, 2 for a usage or loading error.
   tests/test_fmu_native_strict.py builds and runs it. */
#define _POSIX_C_SOURCE 200809L   /* fork, waitpid, dlopen */
#include <dlfcn.h>
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
    X(GetRealStatus) X(GetIntegerStatus) X(GetBooleanStatus) X(GetStringStatus)
#define DECLARE(name) fmi2##name##TYPE *name;
static struct { FMI2_FUNCTIONS(DECLARE) } F;

/* -- the state machine (FMI 2.0, section 4.2.4) --------------------------------------- */
enum {
    INSTANTIATED = 1, INITIALIZATION = 2, STEP_COMPLETE = 4, STEP_IN_PROGRESS = 8, STEP_FAILED = 16,
    TERMINATED = 32, ERROR = 64
};
#define ANY (INSTANTIATED | INITIALIZATION | STEP_COMPLETE | STEP_IN_PROGRESS | STEP_FAILED | TERMINATED | ERROR)
#define INITIALIZED (STEP_COMPLETE | STEP_FAILED | TERMINATED)
#define READ (INITIALIZATION | INITIALIZED)          /* no reading in the error state */
#define WRITE (INSTANTIATED | INITIALIZATION | STEP_COMPLETE)
#define STATUS (STEP_COMPLETE | STEP_IN_PROGRESS | STEP_FAILED | TERMINATED)

/* The states this host drives a fresh instance into, and the word the FMU must use for each. */
typedef struct { const char *label; int state; const char *word; } Reached;
enum { R_INSTANTIATED, R_INITIALIZATION, R_STEP_COMPLETE, R_TERMINATED, R_FAILED_INIT, R_FAILED_STEP, N_REACHED };
static const Reached REACHED[N_REACHED] = {
    {"instantiated", INSTANTIATED, "state instantiated"},
    {"initializationMode", INITIALIZATION, "state initializationMode"},
    {"stepComplete", STEP_COMPLETE, "state stepComplete"},
    {"terminated", TERMINATED, "state terminated"},
    {"error after a failed fmi2ExitInitializationMode", ERROR, "state error"},
    {"error after a failed fmi2DoStep", ERROR, "state error"}};

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

/* -- fixtures -------------------------------------------------------------------------- */
static const char *GUID;
static fmi2ValueReference VR_TUNABLE, VR_OUTPUT, VR_STRING;
static fmi2Real TUNABLE_START;                      /* read from the FMU */
static char STRING_START[256];
static fmi2Component DONOR;                          /* a healthy instance whose state the cases use */
static fmi2FMUstate DONOR_STATE;
static fmi2Byte *SERIAL;
static size_t SERIAL_SIZE;

static fmi2Component instantiate(void)
{
    return F.Instantiate("strict", fmi2CoSimulation, GUID, "", &CALLBACKS, fmi2False, fmi2False);
}

/* A fresh instance in REACHED[r]; NULL (and a failure) if the FMU does not get there. */
static fmi2Component make(int r)
{
    const fmi2Real bad = -1.0;
    fmi2Component c = instantiate();
    int ok = c != NULL;
    if (!c) fail("fmi2Instantiate returned NULL (log: %s)", LOG.text);
    if (ok && r == R_FAILED_INIT)
        ok = expect("fmi2SetReal(tunable = -1)", F.SetReal(c, &VR_TUNABLE, 1, &bad), fmi2OK, 1, NULL, NULL);
    if (ok && r != R_INSTANTIATED)
        ok = expect("fmi2SetupExperiment", F.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, 10.0), fmi2OK, 1,
                    NULL, NULL)
             && expect("fmi2EnterInitializationMode", F.EnterInitializationMode(c), fmi2OK, 1, NULL, NULL);
    if (ok && r == R_FAILED_INIT)
        ok = expect("fmi2ExitInitializationMode with tunable = -1", F.ExitInitializationMode(c), fmi2Error, 1,
                    NULL, NULL) || 1;
    else if (ok && r >= R_STEP_COMPLETE)
        ok = expect("fmi2ExitInitializationMode", F.ExitInitializationMode(c), fmi2OK, 1, NULL, NULL);
    if (ok && r == R_TERMINATED) ok = expect("fmi2Terminate", F.Terminate(c), fmi2OK, 1, NULL, NULL);
    if (ok && r == R_FAILED_STEP)
        ok = expect("fmi2SetReal(tunable = -1)", F.SetReal(c, &VR_TUNABLE, 1, &bad), fmi2OK, 1, NULL, NULL)
             && (expect("fmi2DoStep with tunable = -1", F.DoStep(c, 0.0, 0.01, fmi2True), fmi2Error, 1, NULL, NULL)
                 || 1);
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
    fmi2Real v;
    switch (r) {
    case R_INSTANTIATED:
        expect("probe fmi2EnterInitializationMode", F.EnterInitializationMode(c), fmi2OK, 1, NULL, NULL);
        break;
    case R_INITIALIZATION:
        expect("probe fmi2ExitInitializationMode", F.ExitInitializationMode(c), fmi2OK, 1, NULL, NULL);
        break;
    case R_STEP_COMPLETE:
        expect("probe fmi2DoStep", F.DoStep(c, 0.0, 0.01, fmi2True), fmi2OK, 1, NULL, NULL);
        break;
    case R_TERMINATED:
        expect("probe fmi2GetReal", F.GetReal(c, &VR_OUTPUT, 1, &v), fmi2OK, 1, NULL, NULL);
        expect("probe fmi2DoStep", F.DoStep(c, 0.0, 0.01, fmi2True), fmi2Error, 1, NULL, NULL);
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

/* Each function: the states it is allowed in, and its status there with the arguments above:
   fmi2Error for what the FMU does not provide (directional derivatives), fmi2Discard for a
   status it does not have (an asynchronous fmi2DoStep's, any Integer status; FMI 2.0, 2.1.3). */
typedef struct { const char *name; int allowed; fmi2Status there; Call call; } Entry;
#define E(name, allowed, there) {"fmi2" #name, allowed, there, call_##name}
static const Entry TABLE[] = {
    E(SetDebugLogging, ANY, fmi2OK),
    E(SetupExperiment, INSTANTIATED, fmi2OK),
    E(EnterInitializationMode, INSTANTIATED, fmi2OK),
    E(ExitInitializationMode, INITIALIZATION, fmi2OK),
    E(Terminate, STEP_COMPLETE | STEP_FAILED, fmi2OK),
    E(Reset, ANY, fmi2OK),
    E(GetReal, READ, fmi2OK),
    E(GetInteger, READ, fmi2OK),
    E(GetBoolean, READ, fmi2OK),
    E(GetString, READ, fmi2OK),
    E(SetReal, WRITE, fmi2OK),                      /* a tunable parameter */
    E(SetInteger, WRITE, fmi2OK),
    E(SetBoolean, WRITE, fmi2OK),
    E(SetString, INSTANTIATED | INITIALIZATION, fmi2OK),   /* a fixed parameter */
    E(GetFMUstate, ANY & ~ERROR, fmi2OK),
    E(SetFMUstate, ANY, fmi2OK),                    /* FMI 2.0's way out of the error state */
    E(FreeFMUstate, ANY, fmi2OK),
    E(SerializedFMUstateSize, ANY, fmi2OK),
    E(SerializeFMUstate, ANY, fmi2OK),
    E(DeSerializeFMUstate, ANY, fmi2OK),
    E(GetDirectionalDerivative, READ, fmi2Error),
    E(SetRealInputDerivatives, WRITE, fmi2OK),
    E(GetRealOutputDerivatives, INITIALIZED, fmi2OK),
    E(DoStep, STEP_COMPLETE, fmi2OK),
    E(CancelStep, STEP_IN_PROGRESS, fmi2Error),
    E(GetStatus, STATUS, fmi2Discard),
    E(GetRealStatus, STATUS, fmi2OK),
    E(GetIntegerStatus, STATUS, fmi2Discard),
    E(GetBooleanStatus, STATUS, fmi2OK),
    E(GetStringStatus, STATUS, fmi2Discard),
};
#define N_TABLE (sizeof TABLE / sizeof *TABLE)

static void case_state(const void *arg)
{
    const int index = *(const int *)arg;
    const Entry *e = &TABLE[index % N_TABLE];
    const int r = index / (int)N_TABLE;
    fmi2Component c = make(r);
    if (!c) return;
    if (e->allowed & REACHED[r].state) {
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

static void case_bad_step_arguments(const void *arg)
{
    fmi2Component c = make(R_STEP_COMPLETE);
    (void)arg;
    if (!c) return;
    expect("fmi2DoStep(h = 0)", F.DoStep(c, 0.0, 0.0, fmi2True), fmi2Error, 1, "fmi2DoStep", NULL);
    expect("fmi2GetReal after a failed fmi2DoStep", call_GetReal(c), fmi2Error, 1, "fmi2GetReal", "state error");
    F.FreeInstance(c);
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

/* One case: in a forked child unless --in-process (a crash is then a failure, not the end of
   the run); in both, every block the FMU allocated during the case must be freed by it. */
static void run(const char *label, void (*fn)(const void *), const void *arg)
{
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

static int setup_donor(void)
{
    fmi2String s = NULL;
    int ok = (DONOR = make(R_INITIALIZATION)) != NULL;
    ok = ok && expect("donor fmi2GetReal", F.GetReal(DONOR, &VR_TUNABLE, 1, &TUNABLE_START), fmi2OK, 1, NULL, NULL)
         && expect("donor fmi2GetString", F.GetString(DONOR, &VR_STRING, 1, &s), fmi2OK, 1, NULL, NULL)
         && s && strlen(s) < sizeof STRING_START
         && expect("donor fmi2ExitInitializationMode", F.ExitInitializationMode(DONOR), fmi2OK, 1, NULL, NULL)
         && expect("donor fmi2GetFMUstate", F.GetFMUstate(DONOR, &DONOR_STATE), fmi2OK, 1, NULL, NULL)
         && expect("donor fmi2SerializedFMUstateSize", F.SerializedFMUstateSize(DONOR, DONOR_STATE, &SERIAL_SIZE),
                   fmi2OK, 1, NULL, NULL);
    if (ok) {
        strcpy(STRING_START, s);
        SERIAL = malloc(SERIAL_SIZE);
        ok = expect("donor fmi2SerializeFMUstate", F.SerializeFMUstate(DONOR, DONOR_STATE, SERIAL, SERIAL_SIZE),
                    fmi2OK, 1, NULL, NULL);
    }
    return ok;
}

int main(int argc, char **argv)
{
    int first = 1;
    if (argc > 1 && strcmp(argv[1], "--in-process") == 0) { ISOLATE = 0; first = 2; }
    if (argc - first != 5) {
        fprintf(stderr, "usage: %s [--in-process] LIBRARY GUID VR_TUNABLE VR_OUTPUT VR_STRING\n", argv[0]);
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
    if (!setup_donor()) { fprintf(stderr, "cannot bring an instance to stepComplete: see the FAIL lines\n"); return 2; }

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
    run("fmi2DoStep with a zero step", case_bad_step_arguments, NULL);
    run("fmi2Instantiate's refusals", case_instantiate_refusals, NULL);
    run("a healthy run with a parameter change, saved and replayed", case_run, NULL);

    CASE = "teardown";
    F.FreeFMUstate(DONOR, &DONOR_STATE);
    F.FreeInstance(DONOR);
    free(SERIAL);
    if (ALLOCS != FREES) fail("%ld block(s) allocated through allocateMemory were never freed", ALLOCS - FREES);
    dlclose(library);
    printf("fmi2_strict_host: %d cases, %d failed check(s)\n", CASES, FAILURES);
    return FAILURES ? 1 : 0;
}
