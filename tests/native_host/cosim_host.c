/* A non-Python FMI host: libcosim's C API (libcosimc.so, shipped in the libcosimpy wheel)
   runs FourBar.fmu or FourBarNative.fmu for Case 2 and writes x2..y4 after every 0.01 s
   step as CSV.  Value references from modelDescription.xml (the same in both FMUs):
   L2 = 1, x2..y4 = 13..18.  tests/test_fmu_native_host.py builds and runs it. */
#include <dlfcn.h>
#include <stdint.h>
#include <stdlib.h>
#include <stdio.h>
typedef struct cosim_execution_s cosim_execution;
typedef struct cosim_slave_s cosim_slave;
typedef struct cosim_observer_s cosim_observer;
typedef struct cosim_manipulator_s cosim_manipulator;
cosim_execution* cosim_execution_create(int64_t start_ns, int64_t step_ns);
cosim_slave* cosim_local_slave_create(const char* fmu_path, const char* instance_name);
int cosim_execution_add_slave(cosim_execution*, cosim_slave*);
int cosim_execution_step(cosim_execution*, int64_t num_steps);
cosim_observer* cosim_last_value_observer_create(void);
int cosim_execution_add_observer(cosim_execution*, cosim_observer*);
cosim_manipulator* cosim_override_manipulator_create(void);
int cosim_execution_add_manipulator(cosim_execution*, cosim_manipulator*);
int cosim_manipulator_slave_set_real(cosim_manipulator*, int, const uint32_t*, size_t, const double*);
int cosim_observer_slave_get_real(cosim_observer*, int, const uint32_t*, size_t, double*);
const char* cosim_last_error_message(void);
int cosim_execution_destroy(cosim_execution*);
int cosim_local_slave_destroy(cosim_slave*);
int cosim_observer_destroy(cosim_observer*);
int cosim_manipulator_destroy(cosim_manipulator*);
void cosim_log_set_output_level(int);

int main(int argc, char** argv)
{
    if (argc != 3) { fprintf(stderr, "usage: %s FourBar.fmu out.csv\n", argv[0]); return 2; }
    /* Optional: load libpython globally and start the interpreter here, before the FMU is
       loaded. Then no LD_PRELOAD is needed, and pythonfmu, finding Python initialised,
       leaves it alone at exit (its own Py_Finalize at exit crashes once scipy is loaded). */
    const char* libpython = getenv("HOST_LIBPYTHON");
    if (libpython) {
        void* py = dlopen(libpython, RTLD_NOW | RTLD_GLOBAL);
        if (!py) { fprintf(stderr, "%s\n", dlerror()); return 1; }
        ((void (*)(void))dlsym(py, "Py_Initialize"))();
        ((void* (*)(void))dlsym(py, "PyEval_SaveThread"))();   /* release the GIL for the FMU's threads */
    }
    cosim_log_set_output_level(3);                                   /* warnings and worse */
    cosim_execution* ex = cosim_execution_create(0, 10000000);       /* 0.01 s step */
    cosim_slave* fmu = cosim_local_slave_create(argv[1], "fourbar");
    int idx = fmu ? cosim_execution_add_slave(ex, fmu) : -1;
    if (idx < 0) { fprintf(stderr, "cannot load %s: %s\n", argv[1], cosim_last_error_message()); return 1; }
    cosim_observer* obs = cosim_last_value_observer_create();
    cosim_execution_add_observer(ex, obs);
    cosim_manipulator* man = cosim_override_manipulator_create();
    cosim_execution_add_manipulator(ex, man);
    const uint32_t out[6] = {13, 14, 15, 16, 17, 18}, L2 = 1;
    const double L2_new = 1.1;
    FILE* csv = fopen(argv[2], "w");
    fprintf(csv, "time,x2,y2,x3,y3,x4,y4\n");
    double v[6];
    for (int n = 0; n < 10000; ++n) {
        if (n == 1000) cosim_manipulator_slave_set_real(man, idx, &L2, 1, &L2_new);   /* at t = 10.00 s */
        if (cosim_execution_step(ex, 1) != 0) { fprintf(stderr, "step %d: %s\n", n, cosim_last_error_message()); return 1; }
        cosim_observer_slave_get_real(obs, idx, out, 6, v);
        fprintf(csv, "%.2f,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", (n + 1) * 0.01, v[0], v[1], v[2], v[3], v[4], v[5]);
    }
    fclose(csv);
    printf("t = 100 s: x2 = %.15g, y2 = %.15g\n", v[0], v[1]);
    fflush(stdout);
    /* Destroying the objects also removes libcosim's extracted copy of the FMU. */
    cosim_execution_destroy(ex);
    cosim_local_slave_destroy(fmu);
    cosim_observer_destroy(obs);
    cosim_manipulator_destroy(man);
    return 0;
}
