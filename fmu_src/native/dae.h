/* The DAE of any mechanism (equations.h), integrated one communication step at a time: the C
 * twin of fmu_src/mechanism_model/dae.py's MechanismDAE (same algorithm, same tolerances, the
 * same messages).  Every function works on the DAE part of a ModelState (model.h).
 *
 * Results: 0, or DAE_ASSEMBLY (dae.py's AssemblyError: the constraints cannot be solved there)
 * or DAE_INTEGRATION (dae.py's IntegrationError), with the message in s->rhs_message.
 */
#ifndef MECHANISM_DAE_H
#define MECHANISM_DAE_H

#include "model.h"

enum { DAE_OK = 0, DAE_ASSEMBLY = 1, DAE_INTEGRATION = 2 };

/* Newton-Raphson stops once every correction is at most NEWTON_STEP (1 + |q_i|) (dae.py). */
#define DAE_NEWTON_STEP 1e-8
#define DAE_NEWTON_ITERATIONS 25
/* The partition's review (dae.py's REPARTITION_AWAY, REPARTITION_RETURN, REPARTITION_GAIN): the
   velocity ratio of independent coordinates is the largest rate of a dependent coordinate per unit
   rate of the independent ones (positions in units of the mechanism's size, s->length_scale),
   infinite at their dead points.  The declared coordinates are left when theirs exceeds
   DAE_REPARTITION_AWAY ... */
#define DAE_REPARTITION_AWAY 5.0
/* ... and taken back once it is below DAE_REPARTITION_RETURN (hysteresis); other coordinates are left
   when theirs exceeds DAE_REPARTITION_AWAY ... */
#define DAE_REPARTITION_RETURN 2.0
/* ... for the column-pivoted QR's choice, when that choice's ratio is this many times smaller. */
#define DAE_REPARTITION_GAIN 2.0
/* Sub-steps tried, in turn, to follow the assembly branch from the base to a trial stage that
   Newton-Raphson from the predictor does not reach (dae.py's CONTINUATION_STEPS). */
#define DAE_CONTINUATION_STEPS {2, 4, 8, 32}
/* Steps tried, in turn, to follow the branch to other parameters or start values (dae_assemble,
   dae_change_parameters) when Newton-Raphson does not reach them directly (dae.py's FOLLOW_STEPS). */
#define DAE_FOLLOW_STEPS {1, 8, 32, 128}
/* Restarts with the QR's independent coordinates allowed within one communication step when a
   Runge-Kutta step fails because the dependent block went singular inside it. */
#define DAE_RESCUES 2

/* Communication times on the 1 ns grid (dae.py's snap_time; round half to even). */
double dae_snap_time(double t);

/* The drivers' (s_ref, t_ref, v) for a start at time t with parameters p. */
void dae_drive_at(const double *p, double t, double *d);

/* The consistent state at time t with parameters s->p: q[independent] and qd[independent] from
   `guess` and `rates` (n values each), the dependent coordinates on the file's assembly branch
   (followed from the file's guesses at the default parameters and start values; else by
   Newton-Raphson from `guess`).  Sets s->t, s->d, s->q, s->qd, the initial partition and the
   cached M^-1. */
int dae_assemble(ModelState *s, double t, const double *guess, const double *rates);

/* (Re)start the integrator at s->t from the consistent state (first_step <= 0: scipy's choice). */
int dae_start(ModelState *s, double first_step);

/* Integrate to t_end (s) and store the consistent state; may re-partition (and restart).  Once the
   call has made max_evaluations right-hand-side evaluations (rejected attempts and restarts
   included) every further one fails (ModelState's evaluation_limit, checked in the right-hand
   side, so that no loop inside a Runge-Kutta step escapes it): DAE_INTEGRATION, the message
   naming the cap and the time reached (the bound on the work of one doStep). */
int dae_advance(ModelState *s, double t_end, double max_evaluations);

/* Apply new parameters at s->t: re-assembly keeping the declared ([start]) coordinates and their
   rates whatever partition the integrator uses (which it keeps afterwards); only where the declared
   ones cannot carry it (their block singular, or the loop not closing with them held: at a dead
   point of theirs) the coordinates in use instead (dae.py's change_parameters).  The drivers
   continue from where they are; on DAE_ASSEMBLY the state is unchanged.  Does not restart the
   integrator (dae_start). */
int dae_change_parameters(ModelState *s, const double *p);

/* The outputs of a consistent state with parameters p and drivers d, into out (MECH_N_OUTPUTS,
   in output order), in three groups: those of kinds STATE and WORK; the RESIDUAL; those of kind
   FORCE (they need the multipliers: DAE_INTEGRATION with a message when eq. (11) cannot be
   solved there).  tr: cos and sin of q's angles (ModelState's), or NULL to compute them. */
void dae_outputs_state(const double *p, const double *d, double t, const double *q, const double *tr,
                       const double *qd, const double *work, double *out);
/* Output k (its position in output order, of kind STATE or WORK) alone: dae_outputs_state's out[k]
   (tr: ModelState's). */
double dae_output_state_one(const double *p, const double *d, double t, const double *q, const double *tr,
                            const double *qd, const double *work, int k);
/* Model Exchange: the host integrates y = (q[independent], qd[independent], work) of the file's
   partition, which never changes (DAE_N_STATES values, the Runge-Kutta's y without its filler).
   dae_states: y of the current consistent state.  dae_me_start: after assembly or a parameter
   change, the current state becomes the predictor's base (with its accelerations).
   dae_me_evaluate: the consistent state at (t, y) becomes the current one (s->t, q, qd, tr, work)
   and f its derivatives; DAE_ASSEMBLY or DAE_INTEGRATION with the message, the state unchanged.
   dae_me_accept: the current state (the last evaluation) becomes the predictor's base, the old
   base its second point (fmi2CompletedIntegratorStep).  dae_derivatives: f at the current
   consistent state without touching the integrator's bookkeeping (a co-simulation host reading
   der(...) between steps). */
#define DAE_N_STATES (2 * MECH_K + MECH_N_DRIVERS)
void dae_states(const ModelState *s, double *y);
int dae_me_start(ModelState *s);
int dae_me_evaluate(ModelState *s, double t, const double *y, double *f);
void dae_me_accept(ModelState *s);
int dae_derivatives(ModelState *s, double *f);
/* Model Exchange's directional derivatives at the current consistent state: along dy (DAE_N_STATES)
   of the states and du (MECH_N_INPUTS) of the inputs, df of their derivatives (DAE_N_STATES) and dout of the
   outputs (MECH_N_OUTPUTS). */
int dae_directional(ModelState *s, const double *dy, const double *du, double *df, double *dout);
void dae_outputs_residual(const double *p, const double *d, double t, const double *q, const double *qd,
                          double *out);
int dae_outputs_force(const double *p, const double *d, double t, const double *q, const double *qd, double *out,
                      char *message);

#endif
