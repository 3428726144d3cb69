/* Explicit Runge-Kutta integration with error control and dense output, for small systems.
 *
 * The algorithm is scipy.integrate's RungeKutta/DOP853/RK45 (scipy/integrate/_ivp/rk.py),
 * step for step: the same initial-step selection (Hairer, Norsett and Wanner, Sec. II.4),
 * the same error norms (RMS; DOP853's combination of its 5th- and 3rd-order estimators),
 * the same step-size factor (safety 0.9, between 0.2 and 10, no growth right after a
 * rejection) and the same dense output.  The tableaus are generated from scipy's published
 * coefficients (rk_tableaus.h).  So the native FMU and the pythonfmu FMU take the same steps
 * up to floating-point summation order.
 *
 * The solver state is a plain struct without pointers: copying it copies the integrator
 * (fmi2GetFMUstate relies on that).
 */
#ifndef RK_H
#define RK_H

#include "equations.h"

/* State dimension: the independent coordinates, their rates and each work output (at least 1:
   C99 has no empty arrays; a mechanism with nothing to integrate carries one constant zero).  A
   model whose equations.h defines RK_N (a component's: fmu_src/native/block/) keeps its own. */
#ifndef RK_N
#define RK_N MECH_ALLOC(2 * MECH_K + MECH_N_WORKS)
#endif
#define RK_MAX_STAGES 16         /* DOP853 with its three extra dense-output stages */
#define RK_MAX_DENSE 7           /* DOP853's interpolator power */

typedef enum { RK_KIND_EMBEDDED = 0, RK_KIND_DOP853 = 1 } RKKind;

typedef struct {
    const char *name;
    RKKind kind;
    int n_stages;                /* stages of a step (without the FSAL stage) */
    int n_stages_extended;       /* stages incl. the extra dense-output ones (DOP853) */
    int order;
    int error_estimator_order;
    int n_dense;                 /* RK45: columns of P; DOP853: interpolator power */
    const double *A;             /* n_stages_extended x n_stages_extended, row-major */
    const double *B;             /* n_stages */
    const double *C;             /* n_stages_extended */
    const double *E;             /* n_stages + 1: the error estimator (DOP853: E5) */
    const double *E3;            /* DOP853's 3rd-order estimator, else NULL */
    const double *P;             /* RK45: (n_stages + 1) x n_dense; DOP853: D, (n_dense - 3) x n_stages_extended */
} RKTableau;


/* Right-hand side: f = dy/dt at (t, y).  Returns RK_FUNCTION_OK; RK_FUNCTION_REJECT when f cannot be
   evaluated at this trial point (the step that needs it is rejected as scipy rejects a step whose
   f is infinite: error norm inf, step size times MIN_FACTOR); or RK_FUNCTION_ERROR to abort. */
enum { RK_FUNCTION_OK = 0, RK_FUNCTION_REJECT = 1, RK_FUNCTION_ERROR = 2 };
typedef int (*RKFunction)(void *context, double t, const double *y, double *f);

typedef enum { RK_RUNNING = 0, RK_FINISHED = 1, RK_FAILED = 2 } RKStatus;

typedef struct {
    int method;                  /* index into rk_tableau() */
    double t, t_old, t_bound;
    double y[RK_N], y_old[RK_N], f[RK_N];
    double h_abs, h_previous;
    double rtol, atol;
    double K[RK_MAX_STAGES][RK_N];
    double dense[RK_MAX_DENSE][RK_N];   /* F (DOP853) or Q^T (RK45) of the last step */
    int dense_ready;
    int has_step;                /* a step has been taken since the start */
    RKStatus status;
    unsigned long nfev;
    unsigned long rejected_by_function;   /* attempts rejected because f could not be evaluated */
} RKSolver;

/* Results of rk_start / rk_step. */
typedef enum { RK_OK = 0, RK_ERROR_RHS = 1, RK_ERROR_STEP_TOO_SMALL = 2, RK_ERROR_FINISHED = 3 } RKResult;

const RKTableau *rk_tableau(int method);     /* 0 DOP853, 1 RK45; NULL otherwise */

/* Start at (t0, y0); first_step <= 0 selects the initial step as scipy does. */
RKResult rk_start(RKSolver *s, int method, RKFunction fun, void *ctx, double t0, const double *y0,
                  double t_bound, double rtol, double atol, double first_step);

/* One accepted step (rejected attempts included).  An attempt whose function returns
   RK_FUNCTION_REJECT at one of its stages is rejected at once, and the step size is multiplied by
   MIN_FACTOR (0.2): what scipy's error control does with the infinite derivative dae.py returns
   there (the stages after it, evaluated at infinite or NaN states, change nothing).  Only a step
   size below 10 ulp of t fails the step (RK_ERROR_STEP_TOO_SMALL). */
RKResult rk_step(RKSolver *s, RKFunction fun, void *ctx);

/* y at t within the last accepted step [t_old, t], from the dense output.  A dense-output stage
   whose function returns RK_FUNCTION_REJECT is taken as infinite (scipy's interpolant then
   holds inf or NaN): y is then not finite. */
RKResult rk_dense(RKSolver *s, RKFunction fun, void *ctx, double t, double *y);

#endif
