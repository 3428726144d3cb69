/* What every model behind the FMI layers checks and says the same way (model_api.h): a failure
 * logged with the model's and instance's names, numbers written as Python's repr writes them, times
 * on the FMU's 1 ns grid, and the checks of the parameters, of a communication step and of values a
 * host sets.  Compiled into the mechanisms' FMUs (model.c) and the components' (block/block.c): they
 * depend only on the generated tables (equations.h, variables.h) and ModelState's values and
 * stop_time, not on the model.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "model.h"

static const int KINDS[FMU_N_VARIABLES] = FMU_VARIABLE_KINDS;
static const char *const NAMES[FMU_N_VARIABLES] = FMU_VARIABLE_NAMES;
static const int POSITIVE[FMU_N_VARIABLES] = FMU_POSITIVE;
static const double MINIMUM[FMU_N_VARIABLES] = FMU_MINIMUM;
static const double MAXIMUM[FMU_N_VARIABLES] = FMU_MAXIMUM;
static const char *const UNITS[FMU_N_VARIABLES] = FMU_MESSAGE_UNITS;
static const int STATE_VRS[] = FMU_STATE_VRS;
enum { KIND_TUNABLE = 0, KIND_FIXED = 1 };      /* FMU_VARIABLE_KINDS' parameters */

ModelStatus model_fail(ModelInstance *m, const char *fmt, ...)
{
    char text[2 * MODEL_MESSAGE];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    model_log(m, MODEL_ERROR, "logStatusError", "%s '%s': %s", MECH_NAME, m->instance_name, text);
    return MODEL_ERROR;
}

/* A double as Python's repr writes it: the shortest of %.15g, %.16g, %.17g that reads back as
   the same value, with ".0" on whole numbers (so messages read the same from both FMUs). */
const char *model_real_text(char *buf, size_t n, double v)
{
    if (isnan(v)) {                      /* Python has one NaN: 'nan', whatever its sign bit */
        snprintf(buf, n, "nan");
        return buf;
    }
    snprintf(buf, n, "%.15g", v);
    if (isfinite(v) && strtod(buf, NULL) != v) snprintf(buf, n, "%.16g", v);
    if (isfinite(v) && strtod(buf, NULL) != v) snprintf(buf, n, "%.17g", v);
    if (isfinite(v) && !strpbrk(buf, ".e")) strncat(buf, ".0", n - strlen(buf) - 1);
    return buf;
}

double model_snap_time(double t)
{
    return nearbyint(t * 1e9) / 1e9;    /* round half to even, as Python's round() */
}

int model_check_parameters(const ModelState *s, char *out, size_t n)
{
    char num[40], low[40], high[40];
    size_t used = 0;
    int count = 0;
    out[0] = '\0';
#define ADD(...) do { if (used < n) used += snprintf(out + used, n - used, "%s", count++ ? "; " : ""); \
                      if (used < n) used += snprintf(out + used, n - used, __VA_ARGS__); } while (0)
    for (int vr = 0; vr < FMU_N_VARIABLES; vr++) {
        if (KINDS[vr] != KIND_TUNABLE && KINDS[vr] != KIND_FIXED) continue;
        const double v = s->values[vr];
        const char *gap = UNITS[vr][0] ? " " : "";
        if (POSITIVE[vr] && !(isfinite(v) && v > 0.0))
            ADD("%s = %s%s%s: must be a finite positive number", NAMES[vr], model_real_text(num, sizeof num, v), gap,
                UNITS[vr]);
        else if (!isfinite(v))
            ADD("%s = %s: must be finite", NAMES[vr], model_real_text(num, sizeof num, v));
        else if (v < MINIMUM[vr] || v > MAXIMUM[vr])
            ADD("%s = %s%s%s: must be within [%s, %s]", NAMES[vr], model_real_text(num, sizeof num, v), gap, UNITS[vr],
                isfinite(MINIMUM[vr]) ? model_real_text(low, sizeof low, MINIMUM[vr]) : "-inf",
                isfinite(MAXIMUM[vr]) ? model_real_text(high, sizeof high, MAXIMUM[vr]) : "inf");
    }
#undef ADD
    return count;
}

int model_past_stop_time(ModelInstance *m, const char *function, double current_time, double step)
{
    const ModelState *s = &m->state;
    if (!(model_snap_time(current_time + step) > model_snap_time(s->stop_time))) return 0;
    model_fail(m, "%s: a step from t = %.9g s to %.9g s goes past the stop time %.9g s the host defined at "
               "initialization", function, current_time, current_time + step, s->stop_time);
    return 1;
}

int model_bad_step(ModelInstance *m, const char *function, double current_time, double step)
{
    char a[40], b[40];
    if (!isfinite(current_time)) {
        model_fail(m, "%s: the current communication point must be finite (got %s s)", function,
                   model_real_text(a, sizeof a, current_time));
        return 1;
    }
    if (!isfinite(step) || !(step > 0.0) || !isfinite(current_time + step)) {
        model_fail(m, "%s: the communication step size must be a finite positive number of seconds (got %s s at "
                   "t = %s s)", function, model_real_text(a, sizeof a, step),
                   model_real_text(b, sizeof b, current_time));
        return 1;
    }
    if (!(model_snap_time(current_time + step) > model_snap_time(current_time))) {
        model_fail(m, "%s: a step of %s s from t = %s s cannot advance the time: the FMU's communication times "
                   "are whole nanoseconds (give a step of at least 1e-9 s)", function,
                   model_real_text(a, sizeof a, step), model_real_text(b, sizeof b, current_time));
        return 1;
    }
    return 0;
}

int model_non_finite_values(ModelInstance *m, const char *function, const unsigned int *vr, const double *value,
                            size_t n)
{
    char a[40];
    for (size_t i = 0; i < n; i++)
        if (!isfinite(value[i])) {
            model_fail(m, "%s: %s = %s: must be finite (nothing was set)", function,
                       vr[i] < FMU_N_VARIABLES ? NAMES[vr[i]] : "?", model_real_text(a, sizeof a, value[i]));
            return 1;
        }
    return 0;
}

int model_non_finite_states(ModelInstance *m, const char *function, const double *x, size_t n)
{
    char a[40];
    const size_t n_states = FMU_N_STATES;   /* a variable: it may be 0 (no always-false comparison) */
    for (size_t i = 0; i < n && i < n_states; i++)
        if (!isfinite(x[i])) {
            model_fail(m, "%s: the continuous state %s = %s: must be finite (nothing was set)", function,
                       NAMES[STATE_VRS[i]], model_real_text(a, sizeof a, x[i]));
            return 1;
        }
    return 0;
}
