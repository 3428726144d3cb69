/* Explicit Runge-Kutta driver: scipy's RungeKutta step control in C (see rk.h). */
#include <float.h>
#include <math.h>
#include "rk.h"
#include "rk_tableaus.h"

/* Each tableau's step is compiled on its own (rk_step and rk_dense dispatch on the method), its
   coefficients constants: the compiler unrolls the stage sums and drops their zero terms (DOP853's
   rows are 40 % zeros; in-process over 100 s at 1e-10 the five-bar, 4 states, takes 226.7 -> 212.1
   million instructions, the Watt six-bar, 2 states, 239.9 -> 234.2), the sums bit for bit the same. */
#if defined(__GNUC__)
#define RK_UNROLL _Pragma("GCC unroll 16")
#define RK_INLINE __attribute__((always_inline)) inline
#else
#define RK_UNROLL
#define RK_INLINE inline
#endif

#define SAFETY 0.9
#define MIN_FACTOR 0.2
#define MAX_FACTOR 10.0

const RKTableau *rk_tableau(int method)
{
    switch (method) {
    case 0: return &RK_DOP853;
    case 1: return &RK_RK45;
    default: return 0;
    }
}

/* sum[j] = sum over k < n of coef[k * stride] K[k][j], k ascending (numpy's dot of K's columns with
   a tableau row or column).  A coefficient that is exactly zero is skipped (at compile time: the
   coefficients are constants): adding its product (+-0 for a finite stage) leaves every sum as it
   was.  (A stage that is infinite only comes from prepare_dense's rejected extra stages, whose
   every column of P has a nonzero entry: the interpolant is not finite either way.) */
static RK_INLINE void combine(const RKSolver *s, int n, const double *coef, int stride, double *sum)
{
    for (int j = 0; j < RK_N; j++) sum[j] = 0.0;
    RK_UNROLL
    for (int k = 0; k < n; k++) {
        const double c = coef[k * stride];
        if (c == 0.0) continue;
        for (int j = 0; j < RK_N; j++) sum[j] += s->K[k][j] * c;
    }
}

/* RMS norm of a vector of RK_N entries (scipy's common.norm). */
static double rms(const double *x)
{
    double sum = 0.0;
    for (int j = 0; j < RK_N; j++) sum += x[j] * x[j];
    return sqrt(sum) / sqrt((double)RK_N);
}

/* Hairer, Norsett and Wanner's initial step, as scipy's select_initial_step (max_step = inf). */
static RKResult initial_step(RKSolver *s, const RKTableau *tab, RKFunction fun, void *ctx, double *h)
{
    double interval = fabs(s->t_bound - s->t);
    if (interval == 0.0) { *h = 0.0; return RK_OK; }
    double scale[RK_N], v[RK_N], y1[RK_N], f1[RK_N];
    for (int j = 0; j < RK_N; j++) scale[j] = s->atol + fabs(s->y[j]) * s->rtol;
    for (int j = 0; j < RK_N; j++) v[j] = s->y[j] / scale[j];
    double d0 = rms(v);
    for (int j = 0; j < RK_N; j++) v[j] = s->f[j] / scale[j];
    double d1 = rms(v);
    double h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    if (h0 > interval) h0 = interval;
    for (int j = 0; j < RK_N; j++) y1[j] = s->y[j] + h0 * s->f[j];
    s->nfev++;
    const int r = fun(ctx, s->t + h0, y1, f1);
    if (r == RK_FUNCTION_ERROR) return RK_ERROR_RHS;
    /* f1 infinite (dae.py's failed evaluation) gives scipy d2 = inf, h1 = 0: a first step of 10 ulp */
    double d2 = INFINITY;
    if (r == RK_FUNCTION_OK) {
        for (int j = 0; j < RK_N; j++) v[j] = (f1[j] - s->f[j]) / scale[j];
        d2 = rms(v) / h0;
    }
    double h1;
    if (d1 <= 1e-15 && d2 <= 1e-15) h1 = fmax(1e-6, h0 * 1e-3);
    else h1 = pow(0.01 / fmax(d1, d2), 1.0 / (tab->error_estimator_order + 1));
    double hmin = 100.0 * h0;
    if (h1 < hmin) hmin = h1;
    if (interval < hmin) hmin = interval;
    *h = hmin;
    return RK_OK;
}

RKResult rk_start(RKSolver *s, int method, RKFunction fun, void *ctx, double t0, const double *y0,
                  double t_bound, double rtol, double atol, double first_step)
{
    const RKTableau *tab = rk_tableau(method);
    s->method = method;
    s->t = s->t_old = t0;
    s->t_bound = t_bound;
    for (int j = 0; j < RK_N; j++) s->y[j] = s->y_old[j] = y0[j];
    s->rtol = rtol < 100.0 * DBL_EPSILON ? 100.0 * DBL_EPSILON : rtol;   /* scipy's floor for rtol */
    s->atol = atol;
    s->h_previous = 0.0;
    s->dense_ready = 0;
    s->has_step = 0;
    s->status = RK_RUNNING;
    s->nfev++;
    if (fun(ctx, t0, s->y, s->f) != RK_FUNCTION_OK) return RK_ERROR_RHS;   /* a consistent state: no trial */
    if (first_step > 0.0) {
        double interval = fabs(t_bound - t0);
        s->h_abs = first_step < interval ? first_step : interval;
        return RK_OK;
    }
    return initial_step(s, tab, fun, ctx, &s->h_abs);
}

/* One attempt: stages, the solution at t + h and its derivative (scipy's rk_step).  RK_OK, or the
   function's RK_FUNCTION_REJECT or RK_FUNCTION_ERROR at the first stage that returned one. */
static RK_INLINE int attempt(RKSolver *s, const RKTableau *tab, RKFunction fun, void *ctx, double h,
                   double *y_new, double *f_new)
{
    int r;
    const int n = tab->n_stages, stride = tab->n_stages_extended;
    double dy[RK_N], ys[RK_N];
    for (int j = 0; j < RK_N; j++) s->K[0][j] = s->f[j];
    RK_UNROLL
    for (int st = 1; st < n; st++) {
        combine(s, st, tab->A + st * stride, 1, dy);
        for (int j = 0; j < RK_N; j++) {
            dy[j] *= h;
            ys[j] = s->y[j] + dy[j];
        }
        s->nfev++;
        if ((r = fun(ctx, s->t + tab->C[st] * h, ys, s->K[st])) != RK_FUNCTION_OK) return r;
    }
    combine(s, n, tab->B, 1, dy);
    for (int j = 0; j < RK_N; j++) y_new[j] = s->y[j] + h * dy[j];
    s->nfev++;
    if ((r = fun(ctx, s->t + h, y_new, f_new)) != RK_FUNCTION_OK) return r;
    for (int j = 0; j < RK_N; j++) s->K[n][j] = f_new[j];
    return RK_FUNCTION_OK;
}

static RK_INLINE double error_norm(const RKSolver *s, const RKTableau *tab, double h, const double *scale)
{
    const int n = tab->n_stages;
    if (tab->kind == RK_KIND_DOP853) {
        double e5 = 0.0, e3 = 0.0, sum5[RK_N], sum3[RK_N];
        combine(s, n + 1, tab->E, 1, sum5);
        combine(s, n + 1, tab->E3, 1, sum3);
        for (int j = 0; j < RK_N; j++) {
            const double s5 = sum5[j] / scale[j], s3 = sum3[j] / scale[j];
            e5 += s5 * s5;
            e3 += s3 * s3;
        }
        if (e5 == 0.0 && e3 == 0.0) return 0.0;
        return fabs(h) * e5 / sqrt((e5 + 0.01 * e3) * RK_N);
    }
    double err[RK_N];
    combine(s, n + 1, tab->E, 1, err);
    for (int j = 0; j < RK_N; j++) err[j] = err[j] * h / scale[j];
    return rms(err);
}

static RK_INLINE RKResult step_with(RKSolver *s, const RKTableau *tab, RKFunction fun, void *ctx)
{
    if (s->status != RK_RUNNING) return RK_ERROR_FINISHED;
    if (s->t == s->t_bound) {
        s->t_old = s->t;
        s->status = RK_FINISHED;
        return RK_OK;
    }
    const double t = s->t;
    const double exponent = -1.0 / (tab->error_estimator_order + 1);
    const double min_step = 10.0 * fabs(nextafter(t, INFINITY) - t);
    double h_abs = s->h_abs < min_step ? min_step : s->h_abs;
    double h = 0.0, t_new = t, y_new[RK_N], f_new[RK_N], scale[RK_N];
    int rejected = 0;
    for (;;) {
        if (h_abs < min_step) { s->status = RK_FAILED; return RK_ERROR_STEP_TOO_SMALL; }
        t_new = t + h_abs;
        if (t_new - s->t_bound > 0.0) t_new = s->t_bound;
        h = t_new - t;
        h_abs = fabs(h);
        s->dense_ready = 0;                       /* K is overwritten from here on */
        const int r = attempt(s, tab, fun, ctx, h, y_new, f_new);
        if (r == RK_FUNCTION_REJECT) {            /* scipy: error norm inf or NaN -> MIN_FACTOR */
            s->rejected_by_function++;
            h_abs *= MIN_FACTOR;
            rejected = 1;
            continue;
        }
        if (r != RK_FUNCTION_OK) { s->status = RK_FAILED; return RK_ERROR_RHS; }
        for (int j = 0; j < RK_N; j++) scale[j] = s->atol + fmax(fabs(s->y[j]), fabs(y_new[j])) * s->rtol;
        double en = error_norm(s, tab, h, scale);
        if (en < 1.0) {
            double factor = en == 0.0 ? MAX_FACTOR : fmin(MAX_FACTOR, SAFETY * pow(en, exponent));
            if (rejected) factor = fmin(1.0, factor);
            h_abs *= factor;
            break;
        }
        h_abs *= fmax(MIN_FACTOR, SAFETY * pow(en, exponent));
        rejected = 1;
    }
    s->h_previous = h;
    for (int j = 0; j < RK_N; j++) { s->y_old[j] = s->y[j]; s->y[j] = y_new[j]; s->f[j] = f_new[j]; }
    s->t_old = t;
    s->t = t_new;
    s->h_abs = h_abs;
    s->has_step = 1;
    if (s->t - s->t_bound >= 0.0) s->status = RK_FINISHED;
    return RK_OK;
}

RKResult rk_step(RKSolver *s, RKFunction fun, void *ctx)
{
    return s->method == 0 ? step_with(s, &RK_DOP853, fun, ctx) : step_with(s, &RK_RK45, fun, ctx);
}

/* The interpolant's coefficients for the last step (scipy's _dense_output_impl). */
static RK_INLINE RKResult prepare_dense(RKSolver *s, const RKTableau *tab, RKFunction fun, void *ctx)
{
    const double h = s->h_previous;
    if (tab->kind == RK_KIND_DOP853) {
        const int stride = tab->n_stages_extended;
        double ys[RK_N];
        RK_UNROLL
        for (int st = tab->n_stages + 1; st < tab->n_stages_extended; st++) {
            combine(s, st, tab->A + st * stride, 1, ys);
            for (int j = 0; j < RK_N; j++) ys[j] = s->y_old[j] + ys[j] * h;
            s->nfev++;
            const int r = fun(ctx, s->t_old + tab->C[st] * h, ys, s->K[st]);
            if (r == RK_FUNCTION_ERROR) return RK_ERROR_RHS;
            if (r == RK_FUNCTION_REJECT)        /* scipy's interpolant gets inf (and NaN) from it */
                for (int j = 0; j < RK_N; j++) s->K[st][j] = INFINITY;
        }
        for (int j = 0; j < RK_N; j++) {
            const double f_old = s->K[0][j], delta = s->y[j] - s->y_old[j];
            s->dense[0][j] = delta;
            s->dense[1][j] = h * f_old - delta;
            s->dense[2][j] = 2.0 * delta - h * (s->f[j] + f_old);
        }
        RK_UNROLL
        for (int i = 0; i < tab->n_dense - 3; i++) {
            combine(s, tab->n_stages_extended, tab->P + i * stride, 1, s->dense[3 + i]);
            for (int j = 0; j < RK_N; j++) s->dense[3 + i][j] *= h;
        }
    } else {
        for (int c = 0; c < tab->n_dense; c++) combine(s, tab->n_stages + 1, tab->P + c, tab->n_dense, s->dense[c]);
    }
    s->dense_ready = 1;
    return RK_OK;
}

static RK_INLINE RKResult dense_with(RKSolver *s, const RKTableau *tab, RKFunction fun, void *ctx, double t,
                                    double *y)
{
    if (!s->dense_ready && prepare_dense(s, tab, fun, ctx) != RK_OK) return RK_ERROR_RHS;
    const double h = s->t - s->t_old;
    const double x = (t - s->t_old) / h;
    if (tab->kind == RK_KIND_DOP853) {
        for (int j = 0; j < RK_N; j++) {
            double v = 0.0;
            for (int i = 0; i < tab->n_dense; i++) {
                v += s->dense[tab->n_dense - 1 - i][j];
                v *= (i % 2 == 0) ? x : 1.0 - x;
            }
            y[j] = v + s->y_old[j];
        }
    } else {
        double p[RK_MAX_DENSE], xp = 1.0;
        for (int c = 0; c < tab->n_dense; c++) { xp *= x; p[c] = xp; }
        for (int j = 0; j < RK_N; j++) {
            double sum = 0.0;
            for (int c = 0; c < tab->n_dense; c++) sum += s->dense[c][j] * p[c];
            y[j] = h * sum + s->y_old[j];
        }
    }
    return RK_OK;
}

RKResult rk_dense(RKSolver *s, RKFunction fun, void *ctx, double t, double *y)
{
    return s->method == 0 ? dense_with(s, &RK_DOP853, fun, ctx, t, y) : dense_with(s, &RK_RK45, fun, ctx, t, y);
}
