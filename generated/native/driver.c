/*
 * Native CVODE driver of the hitl-formation toolkit (generated/native.py).
 *
 * This file is appended to the C that CasADi generates for
 *   nat_rhs(t, x) -> xdot          the closed loop's right-hand side
 *   nat_jac(t, x) -> J             its Jacobian on the pattern of M = I - gamma J
 *   nat_lu_factor(M) -> (LU, piv)  sparse LU without pivoting (generated/sparse_lu.py)
 *   nat_lu_solve(LU, b) -> x
 * and compiled with it into one shared library, linked against SUNDIALS 7.9 (CVODE,
 * from the scikit-sundae wheel; headers vendored in generated/native/include). The
 * whole integration runs here: Python calls hitl_native_run once per run.
 *
 * CVODE: BDF, Newton iteration, matrix-based linear solver interface with a
 * SUNSparseMatrix (CSC, the CasADi pattern) and a custom direct SUNLinearSolver whose
 * setup factorises M with nat_lu_factor and whose solve calls nat_lu_solve. CVODE
 * decides when to re-evaluate J (it keeps a saved copy and rebuilds M from it when
 * only gamma changed), which CasADi's CVODES interface does not do.
 *
 * Only CVODE functions are called (the CVODES header declares the same ones; a
 * CVODES-only call would fail to link).
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

/* stats[] layout, read by generated/native.py (STATS) */
enum {
  HITL_STEPS, HITL_RHS_EVALS, HITL_JAC_EVALS, HITL_LIN_SETUPS, HITL_ERR_TEST_FAILS,
  HITL_NEWTON_ITERS, HITL_NEWTON_FAILS, HITL_LAST_STEP, HITL_LU_FACTOR, HITL_PIVOT_FAILS,
  HITL_RESTARTS, HITL_FLAG, HITL_T_REACHED, HITL_NSTATS
};

/* a pivot below this (or not finite) makes the setup fail recoverably */
#define HITL_PIVOT_MIN 1e-13

typedef struct {
  const casadi_real **arg;
  casadi_real **res;
  casadi_int *iw;
  casadi_real *w;
  casadi_real *lu, *piv;
  casadi_int *jcol, *jrow; /* CCS of nat_jac's output: colind[nx+1], row[nnz] */
  casadi_int jnnz;
  int nx;
  long n_rhs, n_jac, n_fac, n_piv_fail;
  char *msg;
  int msglen;
} hitl_ctx;

static void hitl_msg(hitl_ctx *c, const char *text) {
  if (c->msg && c->msglen > 0) {
    strncpy(c->msg, text, (size_t)c->msglen - 1);
    c->msg[c->msglen - 1] = '\0';
  }
}

static void hitl_err_handler(int line, const char *func, const char *file, const char *msg,
                             SUNErrCode code, void *data, SUNContext ctx) {
  /* keep SUNDIALS' last message instead of printing it */
  hitl_msg((hitl_ctx *)data, msg ? msg : "SUNDIALS error");
  (void)line; (void)func; (void)file; (void)code; (void)ctx;
}

/* Expand a CasADi sparsity (nrow, ncol, colind..., row... or the dense shorthand
   nrow, ncol, 1) into allocated colind/row arrays; returns nnz or -1. */
static casadi_int hitl_pattern(const casadi_int *sp, casadi_int **colind, casadi_int **row) {
  casadi_int nr = sp[0], nc = sp[1], nnz;
  int dense = sp[2] == 1;
  nnz = dense ? nr * nc : sp[2 + nc];
  *colind = (casadi_int *)malloc(sizeof(casadi_int) * (size_t)(nc + 1));
  *row = (casadi_int *)malloc(sizeof(casadi_int) * (size_t)(nnz + 1));
  if (!*colind || !*row) return -1;
  for (casadi_int j = 0; j <= nc; ++j) (*colind)[j] = dense ? j * nr : sp[2 + j];
  for (casadi_int k = 0; k < nnz; ++k) (*row)[k] = dense ? k % nr : sp[3 + nc + k];
  return nnz;
}

static int hitl_rhs(sunrealtype t, N_Vector y, N_Vector ydot, void *data) {
  hitl_ctx *c = (hitl_ctx *)data;
  casadi_real tt = t;
  casadi_real *out = N_VGetArrayPointer(ydot);
  c->arg[0] = &tt;
  c->arg[1] = N_VGetArrayPointer(y);
  c->res[0] = out;
  c->n_rhs++;
  if (nat_rhs(c->arg, c->res, c->iw, c->w, 0)) return -1;
  for (int i = 0; i < c->nx; ++i)
    if (!isfinite(out[i])) return 1; /* recoverable: CVODE retries with a smaller step */
  return 0;
}

static int hitl_jac(sunrealtype t, N_Vector y, N_Vector fy, SUNMatrix J, void *data,
                    N_Vector t1, N_Vector t2, N_Vector t3) {
  hitl_ctx *c = (hitl_ctx *)data;
  sunindextype *ptr = SM_INDEXPTRS_S(J), *idx = SM_INDEXVALS_S(J);
  casadi_real tt = t;
  /* SUNMatZero clears the pattern too: write it every time */
  for (casadi_int j = 0; j <= c->nx; ++j) ptr[j] = (sunindextype)c->jcol[j];
  for (casadi_int k = 0; k < c->jnnz; ++k) idx[k] = (sunindextype)c->jrow[k];
  c->arg[0] = &tt;
  c->arg[1] = N_VGetArrayPointer(y);
  c->res[0] = SM_DATA_S(J);
  c->n_jac++;
  (void)fy; (void)t1; (void)t2; (void)t3;
  return nat_jac(c->arg, c->res, c->iw, c->w, 0) ? -1 : 0;
}

static SUNLinearSolver_Type hitl_ls_type(SUNLinearSolver S) {
  (void)S;
  return SUNLINEARSOLVER_DIRECT;
}

static int hitl_ls_setup(SUNLinearSolver S, SUNMatrix M) {
  hitl_ctx *c = (hitl_ctx *)S->content;
  if (SM_INDEXPTRS_S(M)[c->nx] != c->jnnz)
    return -1; /* M lost the pattern (cannot happen with a full diagonal) */
  c->arg[0] = SM_DATA_S(M);
  c->res[0] = c->lu;
  c->res[1] = c->piv;
  c->n_fac++;
  if (nat_lu_factor(c->arg, c->res, c->iw, c->w, 0)) return -1;
  for (int i = 0; i < c->nx; ++i)
    if (!(fabs(c->piv[i]) > HITL_PIVOT_MIN)) {
      c->n_piv_fail++;
      return SUNLS_RECOV_FAILURE;
    }
  return 0;
}

static int hitl_ls_solve(SUNLinearSolver S, SUNMatrix M, N_Vector x, N_Vector b, sunrealtype tol) {
  hitl_ctx *c = (hitl_ctx *)S->content;
  c->arg[0] = c->lu;
  c->arg[1] = N_VGetArrayPointer(b);
  c->res[0] = N_VGetArrayPointer(x);
  (void)M; (void)tol;
  return nat_lu_solve(c->arg, c->res, c->iw, c->w, 0) ? -1 : 0;
}

static SUNErrCode hitl_ls_free(SUNLinearSolver S) {
  if (S) SUNLinSolFreeEmpty(S);
  return SUN_SUCCESS;
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

/* CVODE's counters since the last (re)initialisation, added to acc[0..6]: steps, RHS,
   Jacobians, linear-solver set-ups, error-test failures, Newton iterations, Newton
   convergence failures */
static void hitl_add_counters(void *mem, long *acc) {
  long v;
  CVodeGetNumSteps(mem, &v), acc[0] += v;
  CVodeGetNumRhsEvals(mem, &v), acc[1] += v;
  CVodeGetNumJacEvals(mem, &v), acc[2] += v;
  CVodeGetNumLinSolvSetups(mem, &v), acc[3] += v;
  CVodeGetNumErrTestFails(mem, &v), acc[4] += v;
  CVodeGetNumNonlinSolvIters(mem, &v), acc[5] += v;
  CVodeGetNumNonlinSolvConvFails(mem, &v), acc[6] += v;
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

/*
 * Integrate from x0 at t_out[0] and store the state at every t_out[k] (row-major
 * x_out[k * nx + i]; CVODE's interpolant between its steps, as CVODES through
 * CasADi). The run restarts (CVodeReInit) at every breakpoint strictly inside
 * (t_out[0], t_out[nt-1]]; it stops exactly there and at the horizon
 * (CVodeSetStopTime), never stepping beyond.
 * Returns the number of rows of x_out filled (>= 1), or -1 if CVODE could not be set
 * up; stats[HITL_FLAG] is CVODE's last flag (< 0 on a failure) and msg its name and
 * message.
 */
CASADI_SYMBOL_EXPORT int hitl_native_run(int nx, const double *x0, int nt, const double *t_out,
                                         int nb, const double *breaks, double rtol, double atol,
                                         long max_steps, double *x_out, double *stats, char *msg,
                                         int msglen) {
  hitl_ctx c;
  casadi_int sz[4] = {0, 0, 0, 0};
  SUNContext ctx = NULL;
  N_Vector y = NULL;
  SUNMatrix A = NULL;
  SUNLinearSolver LS = NULL;
  void *mem = NULL;
  casadi_int *lucol = NULL, *lurow = NULL, lunnz;
  int filled = -1, flag = 0, ib = 0;
  long acc[7] = {0, 0, 0, 0, 0, 0, 0};
  double t, tstop_set = NAN;

  memset(&c, 0, sizeof c);
  for (int i = 0; i < HITL_NSTATS; ++i) stats[i] = 0.0;
  c.nx = nx;
  c.msg = msg;
  c.msglen = msglen;
  if (msglen > 0) msg[0] = '\0';
  hitl_work_size(nat_rhs_work, sz);
  hitl_work_size(nat_jac_work, sz);
  hitl_work_size(nat_lu_factor_work, sz);
  hitl_work_size(nat_lu_solve_work, sz);
  c.jnnz = hitl_pattern(nat_jac_sparsity_out(0), &c.jcol, &c.jrow);
  lunnz = hitl_pattern(nat_lu_factor_sparsity_out(0), &lucol, &lurow);
  c.arg = (const casadi_real **)calloc((size_t)sz[0] + 1, sizeof(casadi_real *));
  c.res = (casadi_real **)calloc((size_t)sz[1] + 1, sizeof(casadi_real *));
  c.iw = (casadi_int *)calloc((size_t)sz[2] + 1, sizeof(casadi_int));
  c.w = (casadi_real *)calloc((size_t)sz[3] + 1, sizeof(casadi_real));
  c.lu = (casadi_real *)calloc((size_t)(lunnz > 0 ? lunnz : 0) + 1, sizeof(casadi_real));
  c.piv = (casadi_real *)calloc((size_t)nx + 1, sizeof(casadi_real));
  if (!c.arg || !c.res || !c.iw || !c.w || !c.lu || !c.piv || c.jnnz < 0 || lunnz < 0) {
    hitl_msg(&c, "out of memory");
    goto done;
  }
  if (nat_jac_sparsity_out(0)[0] != nx || nat_jac_sparsity_out(0)[1] != nx) {
    hitl_msg(&c, "nx does not match the generated Jacobian");
    goto done;
  }
  if (SUNContext_Create(SUN_COMM_NULL, &ctx) != SUN_SUCCESS) {
    hitl_msg(&c, "SUNContext_Create failed");
    goto done;
  }
  SUNContext_ClearErrHandlers(ctx);
  SUNContext_PushErrHandler(ctx, hitl_err_handler, &c);
  y = N_VNew_Serial(nx, ctx);
  A = SUNSparseMatrix(nx, nx, c.jnnz, CSC_MAT, ctx);
  LS = SUNLinSolNewEmpty(ctx);
  mem = CVodeCreate(CV_BDF, ctx);
  if (!y || !A || !LS || !mem) {
    hitl_msg(&c, "CVODE could not allocate its memory");
    goto done;
  }
  LS->content = &c;
  LS->ops->gettype = hitl_ls_type;
  LS->ops->setup = hitl_ls_setup;
  LS->ops->solve = hitl_ls_solve;
  LS->ops->free = hitl_ls_free;
  memcpy(N_VGetArrayPointer(y), x0, (size_t)nx * sizeof(double));
  memcpy(x_out, x0, (size_t)nx * sizeof(double));
  t = t_out[0];
  if (CVodeInit(mem, hitl_rhs, t, y) || CVodeSetUserData(mem, &c) ||
      CVodeSStolerances(mem, rtol, atol) || CVodeSetLinearSolver(mem, LS, A) ||
      CVodeSetJacFn(mem, hitl_jac) || CVodeSetMaxNumSteps(mem, max_steps)) {
    goto done; /* msg set by the error handler */
  }
  filled = 1;
  while (ib < nb && breaks[ib] <= t) ib++;
  for (int k = 1; k < nt; ++k) {
    double tout = t_out[k];
    for (;;) {
      /* CVODE may step past output times (it interpolates there) but never past the
         next breakpoint or the horizon: the stop time */
      double stop = ib < nb ? breaks[ib] : t_out[nt - 1];
      if (stop != tstop_set) {
        CVodeSetStopTime(mem, stop);
        tstop_set = stop;
      }
      flag = CVode(mem, tout < stop ? tout : stop, y, &t, CV_NORMAL);
      if (flag < 0) goto done;
      if (t >= stop) {
        tstop_set = NAN; /* CVODE forgets a stop time once reached */
        if (ib < nb) {   /* a breakpoint: restart from the state reached */
          hitl_add_counters(mem, acc);
          if (CVodeReInit(mem, t, y)) goto done;
          stats[HITL_RESTARTS] += 1;
          ib++;
        }
      }
      if (t >= tout) break;
    }
    memcpy(x_out + (size_t)k * nx, N_VGetArrayPointer(y), (size_t)nx * sizeof(double));
    filled = k + 1;
  }

done:
  if (mem) {
    sunrealtype h = 0;
    hitl_add_counters(mem, acc);
    stats[HITL_STEPS] = (double)acc[0];
    stats[HITL_RHS_EVALS] = (double)acc[1];
    stats[HITL_JAC_EVALS] = (double)acc[2];
    stats[HITL_LIN_SETUPS] = (double)acc[3];
    stats[HITL_ERR_TEST_FAILS] = (double)acc[4];
    stats[HITL_NEWTON_ITERS] = (double)acc[5];
    stats[HITL_NEWTON_FAILS] = (double)acc[6];
    CVodeGetLastStep(mem, &h), stats[HITL_LAST_STEP] = h;
  }
  stats[HITL_LU_FACTOR] = (double)c.n_fac;
  stats[HITL_PIVOT_FAILS] = (double)c.n_piv_fail;
  stats[HITL_FLAG] = flag;
  stats[HITL_T_REACHED] = filled >= 1 ? t_out[filled - 1] : t_out[0];
  if (flag < 0) {
    char *name = CVodeGetReturnFlagName(flag);
    char text[640];
    snprintf(text, sizeof text, "%s: %s", name ? name : "CV_UNKNOWN", msg ? msg : "");
    hitl_msg(&c, text);
    free(name);
  }
  if (mem) CVodeFree(&mem);
  if (LS) SUNLinSolFree(LS);
  if (A) SUNMatDestroy(A);
  if (y) N_VDestroy(y);
  if (ctx) SUNContext_Free(&ctx);
  free(c.arg), free(c.res), free(c.iw), free(c.w), free(c.lu), free(c.piv);
  free(c.jcol), free(c.jrow), free(lucol), free(lurow);
  return filled;
}
