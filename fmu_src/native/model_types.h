/* What a model's ModelState is made of before the model defines it (model.h, block/model.h): the
 * longest message, the statuses the model's functions return and log, and the FMI state machines'
 * states.  model_api.h, included after ModelState, declares what the FMI layers call.
 */
#ifndef MODEL_TYPES_H
#define MODEL_TYPES_H

#define MODEL_MESSAGE 512   /* longest message of one failure */

/* What the model's functions return and log: the values of ModelStatus and fmi3Status. */
typedef enum { MODEL_OK = 0, MODEL_WARNING = 1, MODEL_DISCARD = 2, MODEL_ERROR = 3, MODEL_FATAL = 4 } ModelStatus;

/* Co-simulation: instantiated, initialization, stepComplete (stepFailed is never entered), terminated,
   error; Model Exchange: instantiated, initialization, eventMode, continuousTimeMode, terminated, error. */
typedef enum {
    MODE_INSTANTIATED = 1, MODE_INITIALIZATION = 2, MODE_STEP_COMPLETE = 4,
    MODE_STEP_FAILED = 8, MODE_TERMINATED = 16, MODE_ERROR = 32,
    MODE_EVENT = 128, MODE_CONTINUOUS = 256
} ModelMode;

#endif
