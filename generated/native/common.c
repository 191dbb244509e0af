/*
 * The SUNDIALS side of the native CVODE driver (generated/native/README.md), prepended to
 * agents.c after the generated C of the follower kernels.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cvodes/cvodes.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_linearsolver.h>
#include <sundials/sundials_version.h>
#include <sunmatrix/sunmatrix_sparse.h>

#include "hitl_native.h"

/* a pivot below this (or not finite) makes the setup fail recoverably */
#define HITL_PIVOT_MIN 1e-13

/* CVODE with everything it needs and what a run reports: one per run, re-initialised at
   breakpoints */
typedef struct {
  SUNContext ctx;
  N_Vector y;
  SUNMatrix A;
  SUNLinearSolver LS;
  void *mem;
  double *K; /* the Jacobian's storage, shared by its matrices (hitl_kmat; the driver's) */
  FILE *log; /* SUNDIALS' messages (hitl_log_msg), or NULL: dropped */
  int nx;
  long n_fac, n_piv_fail; /* set-ups of the driver's linear solver, and those refused */
  char *msg;              /* the last message (msglen bytes) */
  int msglen;
} hitl_cvode;

static void hitl_msg(hitl_cvode *c, const char *text) {
  if (c->msg && c->msglen > 0) {
    strncpy(c->msg, text, (size_t)c->msglen - 1);
    c->msg[c->msglen - 1] = '\0';
  }
}

static void hitl_err_handler(int line, const char *func, const char *file, const char *msg,
                             SUNErrCode code, void *data, SUNContext ctx) {
  /* keep SUNDIALS' last message instead of printing it */
  hitl_msg((hitl_cvode *)data, msg ? msg : "SUNDIALS error");
  (void)line; (void)func; (void)file; (void)code; (void)ctx;
}

static void hitl_work_size(int (*work)(casadi_int *, casadi_int *, casadi_int *, casadi_int *),
                           casadi_int *sz) {
  casadi_int a, r, i, w;
  work(&a, &r, &i, &w);
  if (a > sz[0]) sz[0] = a;
  if (r > sz[1]) sz[1] = r;
  if (i > sz[2]) sz[2] = i;
  if (w > sz[3]) sz[3] = w;
}

/* CVODE's counters since the last (re)initialisation, added to the result's */
static void hitl_add_counters(void *mem, hitl_result *r) {
  long v;
  CVodeGetNumSteps(mem, &v), r->steps += v;
  CVodeGetNumRhsEvals(mem, &v), r->rhs_evals += v;
  CVodeGetNumJacEvals(mem, &v), r->jac_evals += v;
  CVodeGetNumLinSolvSetups(mem, &v), r->lin_setups += v;
  CVodeGetNumErrTestFails(mem, &v), r->error_test_fails += v;
  CVodeGetNumNonlinSolvIters(mem, &v), r->newton_iters += v;
  CVodeGetNumNonlinSolvConvFails(mem, &v), r->newton_fails += v;
}

/* SUNDIALS' logger queue function: one line per message, "[WARNING][CVode] text
   (cvode.c:1234)", appended to the run's log (content: its FILE *, or NULL) instead of
   the terminal. The scope's directories (SUNDIALS' build paths) are left out. */
static SUNErrCode hitl_log_msg(SUNLogger logger, SUNLogLevel lvl, const char *prefix, int rank,
                               const char *scope, const char *label, const char *payload,
                               void *content) {
  static const char *level[] = {"NONE", "ERROR", "WARNING", "INFO", "DEBUG"};
  FILE *f = (FILE *)content;
  const char *base = scope ? scope : "", *slash;
  (void)logger; (void)prefix; (void)rank;
  if (!f) return SUN_SUCCESS;
  if ((slash = strrchr(base, '/')) != NULL) base = slash + 1;
  fprintf(f, "[%s][%s] ", lvl >= 1 && lvl <= 4 ? level[lvl] : "LOG", label ? label : "");
  for (const char *q = payload ? payload : ""; *q; ++q) fputc(*q == '\n' ? ' ' : *q, f);
  fprintf(f, " (%s)\n", base);
  return SUN_SUCCESS;
}

static SUNErrCode hitl_log_flush(SUNLogger logger, SUNLogLevel lvl, void *content) {
  (void)logger; (void)lvl;
  if (content) fflush((FILE *)content);
  return SUN_SUCCESS;
}

/* The SUNDIALS context, the state vector, an empty linear solver (the driver sets its
   content and operations) and CVODE (BDF) for s->nx states. The driver creates the
   matrix s->A. SUNDIALS' warnings and errors go to the file log_path (appended; NULL or
   "": dropped), never to the terminal; the last error also to s->msg. Returns 0, or -1
   with s->msg set. */
static int hitl_sundials_create(hitl_cvode *s, const char *log_path) {
  SUNLogger logger = NULL;
  if (SUNContext_Create(SUN_COMM_NULL, &s->ctx) != SUN_SUCCESS) {
    s->ctx = NULL;
    hitl_msg(s, "SUNContext_Create failed");
    return -1;
  }
  if (log_path && *log_path) s->log = fopen(log_path, "a");
  if (SUNContext_GetLogger(s->ctx, &logger) == SUN_SUCCESS && logger)
    SUNLogger_SetQueueAndFlushMsgFns(logger, hitl_log_msg, hitl_log_flush, s->log);
  SUNContext_ClearErrHandlers(s->ctx);
  SUNContext_PushErrHandler(s->ctx, SUNLogErrHandlerFn, NULL); /* errors into the log */
  SUNContext_PushErrHandler(s->ctx, hitl_err_handler, s);
  s->y = N_VNew_Serial(s->nx, s->ctx);
  s->LS = SUNLinSolNewEmpty(s->ctx);
  s->mem = CVodeCreate(CV_BDF, s->ctx);
  if (!s->y || !s->LS || !s->mem) {
    hitl_msg(s, "CVODE could not allocate its memory");
    return -1;
  }
  return 0;
}

/* From CVodeInit's state at t_out[0], integrate to every t_out[k] and store the state
   there (row-major x_out[k * nx + i]; CVODE's interpolant between its steps). CVODE
   restarts (CVodeReInit) at every breakpoint; it stops exactly there and at the horizon
   (CVodeSetStopTime), never stepping beyond. t_out and breaks are the targets and restart
   times of generated.schedule.schedule, so CVODE is never asked for a time it already
   stands at (CV_TOO_CLOSE). Returns the rows filled (>= 1); *flag is CVODE's last flag
   (< 0 on a failure). */
static int hitl_cvode_outputs(hitl_cvode *s, int nx, const hitl_options *o, hitl_result *r,
                              int *flag) {
  int filled = 1, ib = 0, nt = o->nt, nb = o->nb;
  const double *t_out = o->t_out, *breaks = o->breaks;
  double t = t_out[0], tstop_set = NAN;
  *flag = 0;
  while (ib < nb && breaks[ib] <= t) ib++;
  for (int k = 1; k < nt; ++k) {
    double tout = t_out[k];
    while (t < tout) {
      /* CVODE may step past output times (it interpolates there) but never past the
         next breakpoint or the horizon: the stop time */
      double stop = ib < nb ? breaks[ib] : t_out[nt - 1];
      if (stop != tstop_set) {
        CVodeSetStopTime(s->mem, stop);
        tstop_set = stop;
      }
      *flag = CVode(s->mem, tout < stop ? tout : stop, s->y, &t, CV_NORMAL);
      r->t_stop = t; /* on a failure CVODE returns its last internal step's state in y */
      if (*flag < 0) return filled;
      if (t >= stop) {
        tstop_set = NAN; /* CVODE forgets a stop time once reached */
        if (ib < nb) {   /* a breakpoint: restart from the state reached */
          hitl_add_counters(s->mem, r);
          *flag = CVodeReInit(s->mem, t, s->y);
          if (*flag < 0) return filled;
          r->restarts += 1;
          ib++;
        }
      }
    }
    memcpy(r->x_out + (size_t)k * nx, N_VGetArrayPointer(s->y), (size_t)nx * sizeof(double));
    filled = k + 1;
  }
  return filled;
}

/* the driver's linear solver: direct, custom (its content and operations: agents.c) */
static SUNLinearSolver_Type hitl_ls_type(SUNLinearSolver S) {
  (void)S;
  return SUNLINEARSOLVER_DIRECT;
}

static SUNErrCode hitl_ls_free(SUNLinearSolver S) {
  if (S) SUNLinSolFreeEmpty(S);
  return SUN_SUCCESS;
}

/* CVODE's options after CVodeInit: user data, tolerances, linear solver, Jacobian.
   J is evaluated afresh at every set-up of the Newton matrix, as CasADi's cvodes does
   (CVODE's default keeps one for up to 51 steps): the closed loop's right-hand side has
   kinks (the ghat projection, |chi|, the torque limit) across which J changes by orders
   of magnitude, and Newton iterates from a J of the far side pass the convergence test
   with the step's derivative history wrong (tests/data/startup-projection-kink.toml was
   lost so, docs/simulation.md). */
static int hitl_cvode_options(hitl_cvode *s, void *data, const hitl_options *o,
                              CVLsJacFn jac) {
  return CVodeSetUserData(s->mem, data) || CVodeSStolerances(s->mem, o->rtol, o->atol) ||
         CVodeSetLinearSolver(s->mem, s->LS, s->A) || CVodeSetJacFn(s->mem, jac) ||
         CVodeSetJacEvalFrequency(s->mem, 1) || CVodeSetMaxNumSteps(s->mem, o->max_steps);
}

/* A driver's result before the run: zero counters, an empty message, x_out kept */
static void hitl_result_start(hitl_result *r) {
  double *x_out = r->x_out, *x_stop = r->x_stop;
  memset(r, 0, sizeof *r);
  r->x_out = x_out;
  r->x_stop = x_stop;
  r->filled = -1;
}

/* CVODE's flag name and the last SUNDIALS message, as "NAME: message", into c->msg */
static void hitl_flag_message(hitl_cvode *c, int flag) {
  char *name = CVodeGetReturnFlagName(flag);
  char text[640];
  snprintf(text, sizeof text, "%s: %s", name ? name : "CV_UNKNOWN", c->msg ? c->msg : "");
  hitl_msg(c, text);
  free(name);
}

/* A whole run on a created CVODE (ok: the driver's set-up succeeded): from x0 at
   t_out[0] through every output time (hitl_cvode_outputs), then CVODE's counters, the
   last flag and its message into the result (reset by hitl_result_start first). Returns
   the rows of x_out filled (>= 1), or -1 if CVODE could not be started. */
static int hitl_cvode_run(hitl_cvode *s, int ok, void *data, CVRhsFn rhs, CVLsJacFn jac,
                          const double *x0, const hitl_options *o, hitl_result *r) {
  int nx = s->nx, filled = -1, flag = 0;
  sunrealtype h = 0;
  if (ok) {
    memcpy(N_VGetArrayPointer(s->y), x0, (size_t)nx * sizeof(double));
    memcpy(r->x_out, x0, (size_t)nx * sizeof(double));
    r->t_stop = o->t_out[0];
    if (!CVodeInit(s->mem, rhs, o->t_out[0], s->y) &&
        !hitl_cvode_options(s, data, o, jac)) /* else: msg set by the error handler */
      filled = hitl_cvode_outputs(s, nx, o, r, &flag);
    if (filled >= 1 && r->x_stop)
      memcpy(r->x_stop, N_VGetArrayPointer(s->y), (size_t)nx * sizeof(double));
  }
  if (s->mem) {
    hitl_add_counters(s->mem, r);
    CVodeGetLastStep(s->mem, &h);
  }
  r->last_step = h;
  r->lu_factorizations = s->n_fac;
  r->pivot_failures = s->n_piv_fail;
  r->flag = flag;
  r->filled = filled;
  r->t_reached = filled >= 1 ? o->t_out[filled - 1] : o->t_out[0];
  if (flag < 0) hitl_flag_message(s, flag);
  return filled;
}

static void hitl_cvode_free(hitl_cvode *s) {
  if (s->mem) CVodeFree(&s->mem);
  if (s->LS) SUNLinSolFree(s->LS);
  if (s->A) SUNMatDestroy(s->A);
  if (s->y) N_VDestroy(s->y);
  if (s->ctx) SUNContext_Free(&s->ctx);
  if (s->log) fclose(s->log), s->log = NULL;
}

/* ------------------------------------------------- the per-follower block matrix */
/* The Jacobian of the per-agent driver (agents.c): one block K_i per follower, representing
   c J (+ I once shifted). Its matrices share K (hitl_cvode.K; docs/performance.md, item
   Storage: why that is safe) and keep the shift c and top, the topology K was evaluated on. */
typedef struct {
  double *K;
  double c;
  int shifted, top;
} hitl_kmat;

#define HITL_KMAT(A) ((hitl_kmat *)(A)->content)

static SUNMatrix_ID hitl_kmat_id(SUNMatrix A) {
  (void)A;
  return SUNMATRIX_CUSTOM;
}

static SUNMatrix hitl_kmat_new(double *K, SUNContext ctx);

static SUNMatrix hitl_kmat_clone(SUNMatrix A) {
  return hitl_kmat_new(HITL_KMAT(A)->K, A->sunctx);
}

static void hitl_kmat_destroy(SUNMatrix A) {
  if (!A) return;
  free(A->content);
  A->content = NULL;
  SUNMatFreeEmpty(A);
}

/* the Jacobian evaluation that follows writes every entry of K: only the shift resets */
static SUNErrCode hitl_kmat_zero(SUNMatrix A) {
  hitl_kmat *m = HITL_KMAT(A);
  m->c = 1.0;
  m->shifted = 0;
  return SUN_SUCCESS;
}

static SUNErrCode hitl_kmat_copy(SUNMatrix A, SUNMatrix B) {
  hitl_kmat *a = HITL_KMAT(A), *b = HITL_KMAT(B);
  b->c = a->c;
  b->shifted = a->shifted;
  b->top = a->top;
  return SUN_SUCCESS;
}

/* A = c A + I: CVODE calls it once on a fresh copy of the Jacobian */
static SUNErrCode hitl_kmat_scaleaddi(sunrealtype c, SUNMatrix A) {
  hitl_kmat *m = HITL_KMAT(A);
  if (m->shifted) return SUN_ERR_NOT_IMPLEMENTED;
  m->c *= c;
  m->shifted = 1;
  return SUN_SUCCESS;
}

/* A block matrix on the storage K, or NULL when out of memory */
static SUNMatrix hitl_kmat_new(double *K, SUNContext ctx) {
  SUNMatrix A = SUNMatNewEmpty(ctx);
  hitl_kmat *m = A ? (hitl_kmat *)calloc(1, sizeof *m) : NULL;
  if (!m) {
    if (A) SUNMatFreeEmpty(A);
    return NULL;
  }
  m->K = K;
  m->c = 1.0;
  A->content = m;
  A->ops->getid = hitl_kmat_id;
  A->ops->clone = hitl_kmat_clone;
  A->ops->destroy = hitl_kmat_destroy;
  A->ops->zero = hitl_kmat_zero;
  A->ops->copy = hitl_kmat_copy;
  A->ops->scaleaddi = hitl_kmat_scaleaddi;
  return A;
}

/* sizeof of the structs of hitl_native.h as compiled here (which: HITL_*_SIZE), or -1:
   the loader compares them with its ctypes mirror before any call */
CASADI_SYMBOL_EXPORT long hitl_struct_size(int which) {
  switch (which) {
    case HITL_OPTIONS_SIZE: return (long)sizeof(hitl_options);
    case HITL_RESULT_SIZE: return (long)sizeof(hitl_result);
    default: return -1;
  }
}

/* Does the SUNDIALS we run against match the headers we were compiled with? */
CASADI_SYMBOL_EXPORT int hitl_native_check(char *msg, int msglen) {
  char version[64] = "";
  SUNContext ctx = NULL;
  int ok = 1;
  if (SUNDIALSGetVersion(version, (int)sizeof version) != SUN_SUCCESS ||
      strcmp(version, SUNDIALS_VERSION) != 0) {
    snprintf(msg, (size_t)msglen, "SUNDIALS library is %s, headers are %s", version,
             SUNDIALS_VERSION);
    return 0;
  }
  if (SUNContext_Create(SUN_COMM_NULL, &ctx) != SUN_SUCCESS) {
    snprintf(msg, (size_t)msglen, "SUNContext_Create failed");
    return 0;
  }
  /* the index type: a 3x5 matrix with 7 nonzeros must read back as such */
  SUNMatrix A = SUNSparseMatrix(3, 5, 7, CSC_MAT, ctx);
  if (!A || SM_ROWS_S(A) != 3 || SM_COLUMNS_S(A) != 5 || SM_NNZ_S(A) != 7) {
    snprintf(msg, (size_t)msglen,
             "SUNDIALS index type differs from the headers' (sizeof(sunindextype) = %d)",
             (int)sizeof(sunindextype));
    ok = 0;
  }
  if (A) SUNMatDestroy(A);
  SUNContext_Free(&ctx);
  return ok;
}

