/* A plain FMI 2.0 co-simulation host that builds for Linux (gcc, dlopen) and for Windows
   (mingw-w64, LoadLibrary; run under wine here): it loads a native FMU's extracted binary and
   runs the paper's Case 2 (L2 1.0 -> 1.1 m at t = 10 s) at rtol = atol = 1e-12, writing
   x2..y4 after every 0.01 s step as CSV.  tests/test_fmu_windows.py builds it both ways and
   compares the Windows DLL's run with the Linux library's.

   usage: portable_host LIBRARY GUID VR_L2 VR_RTOL VR_ATOL VR_X2 OUT.csv
   (x2..y4 are six consecutive value references from VR_X2) */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _WIN32
#include <windows.h>
#define LOAD(path) ((void *)LoadLibraryA(path))
#define SYMBOL(lib, name) ((void *)GetProcAddress((HMODULE)(lib), name))
#else
#include <dlfcn.h>
#define LOAD(path) dlopen(path, RTLD_NOW | RTLD_LOCAL)
#define SYMBOL(lib, name) dlsym(lib, name)
#endif
#include "fmi2FunctionTypes.h"

static void log_message(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                        fmi2String message, ...)
{
    va_list args;
    (void)env;
    (void)category;
    if (status == fmi2OK) return;
    fprintf(stderr, "[%s %d] ", name ? name : "?", (int)status);
    va_start(args, message);
    vfprintf(stderr, message, args);
    va_end(args);
    fprintf(stderr, "\n");
}

#define GET(type, name) type *name = (type *)SYMBOL(lib, #name); \
    if (!name) { fprintf(stderr, "missing %s\n", #name); return 1; }

int main(int argc, char **argv)
{
    if (argc != 8) {
        fprintf(stderr, "usage: %s LIBRARY GUID VR_L2 VR_RTOL VR_ATOL VR_X2 OUT.csv\n", argv[0]);
        return 2;
    }
    void *lib = LOAD(argv[1]);
    if (!lib) { fprintf(stderr, "cannot load %s\n", argv[1]); return 1; }
    GET(fmi2InstantiateTYPE, fmi2Instantiate)
    GET(fmi2SetupExperimentTYPE, fmi2SetupExperiment)
    GET(fmi2EnterInitializationModeTYPE, fmi2EnterInitializationMode)
    GET(fmi2ExitInitializationModeTYPE, fmi2ExitInitializationMode)
    GET(fmi2SetRealTYPE, fmi2SetReal)
    GET(fmi2GetRealTYPE, fmi2GetReal)
    GET(fmi2DoStepTYPE, fmi2DoStep)
    GET(fmi2TerminateTYPE, fmi2Terminate)
    GET(fmi2FreeInstanceTYPE, fmi2FreeInstance)
    const fmi2ValueReference l2 = (fmi2ValueReference)atoi(argv[3]);
    const fmi2ValueReference tols[2] = {(fmi2ValueReference)atoi(argv[4]), (fmi2ValueReference)atoi(argv[5])};
    fmi2ValueReference out[6];
    for (int i = 0; i < 6; i++) out[i] = (fmi2ValueReference)(atoi(argv[6]) + i);
    fmi2CallbackFunctions callbacks = {log_message, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("portable", fmi2CoSimulation, argv[2], "", &callbacks, fmi2False, fmi2False);
    if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 1; }
    const double tight[2] = {1e-12, 1e-12}, l2_new = 1.1;
    double v[6];
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, 20.0) > fmi2Warning
        || fmi2EnterInitializationMode(c) > fmi2Warning || fmi2SetReal(c, tols, 2, tight) > fmi2Warning
        || fmi2ExitInitializationMode(c) > fmi2Warning) {
        fprintf(stderr, "initialization failed\n");
        return 1;
    }
    FILE *csv = fopen(argv[7], "w");
    if (!csv) { fprintf(stderr, "cannot write %s\n", argv[7]); return 1; }
    fprintf(csv, "time,x2,y2,x3,y3,x4,y4\n");
    for (int n = 0; n <= 2000; n++) {
        fmi2GetReal(c, out, 6, v);
        fprintf(csv, "%.2f,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", n * 0.01, v[0], v[1], v[2], v[3], v[4], v[5]);
        if (n == 2000) break;
        if (n == 1000 && fmi2SetReal(c, &l2, 1, &l2_new) > fmi2Warning) return 1;    /* at t = 10.00 s */
        if (fmi2DoStep(c, n * 0.01, 0.01, fmi2True) > fmi2Warning) { fprintf(stderr, "step %d failed\n", n); return 1; }
    }
    fclose(csv);
    fmi2Terminate(c);
    fmi2FreeInstance(c);
    printf("ok\n");
    return 0;
}
