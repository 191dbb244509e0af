/*
 * The native driver's calling convention: a run takes one options struct and fills one
 * result struct, mirrored in generated/native.py (tests/test_solver_interface.py compares
 * every offset; every library reports its sizes, hitl_struct_size). Plain C types only.
 */
#ifndef HITL_NATIVE_H
#define HITL_NATIVE_H

/* length of the result's message buffer (with its terminating NUL) */
#define HITL_MSG_LEN 1024

/* What a run is asked to do: tolerances, steps, output and restart times. t_out and
   breaks are generated.schedule.schedule's targets and restart times. */
typedef struct {
  double rtol;
  double atol;
  long max_steps;       /* steps allowed between two output times (CVodeSetMaxNumSteps) */
  int nt;               /* number of output times */
  const double *t_out;  /* nt output times, t_out[0] the start */
  int nb;               /* number of restart times */
  const double *breaks; /* nb restart times, strictly inside (t_out[0], t_out[nt-1]) */
  const char *log_path; /* SUNDIALS' warnings and errors appended here (NULL: dropped) */
} hitl_options;

/* What a run returns: the output rows, CVODE's counters, its last flag and message, and
   the state CVODE held when it returned. */
typedef struct {
  double *x_out;           /* caller's nt x nx buffer, row-major (x_out[k * nx + i]) */
  double *x_stop;          /* caller's nx buffer (NULL: not wanted): the state at t_stop */
  int filled;              /* rows of x_out filled (>= 1), or -1 if CVODE could not start */
  int flag;                /* CVODE's last flag (< 0 on a failure) */
  double t_reached;        /* t_out[filled - 1] */
  double t_stop;           /* where CVODE stood when it returned: on a failure its last
                              internal step (past t_reached), else the horizon */
  double last_step;        /* the last step size taken */
  long steps;
  long rhs_evals;
  long jac_evals;
  long lin_setups;
  long error_test_fails;
  long newton_iters;
  long newton_fails;
  long lu_factorizations;  /* set-ups of the driver's linear solver */
  long pivot_failures;     /* set-ups refused for a small pivot or a singular block */
  long restarts;           /* CVodeReInit at breakpoints */
  char msg[HITL_MSG_LEN];  /* "FLAG_NAME: SUNDIALS message" on a failure */
} hitl_result;

/* which argument of hitl_struct_size */
enum { HITL_OPTIONS_SIZE, HITL_RESULT_SIZE };

#endif
