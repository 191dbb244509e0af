/*
 * Native CVODE driver of the hitl-formation toolkit (generated/native.py).
 *
 * This file is appended to the C that CasADi generates for
 *   nat_rhs(t, x, p) -> xdot       the closed loop's right-hand side (p: its parameters)
 *   nat_jac(t, x, p) -> J             its Jacobian on the pattern of M = I - gamma J
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

/* Write the Jacobian's pattern into J (SUNMatZero clears it too) and point res[0] at
   its values: the caller then evaluates its generated Jacobian into them. */
static void hitl_jac_prepare(hitl_ctx *c, SUNMatrix J) {
  sunindextype *ptr = SM_INDEXPTRS_S(J), *idx = SM_INDEXVALS_S(J);
  for (casadi_int j = 0; j <= c->nx; ++j) ptr[j] = (sunindextype)c->jcol[j];
  for (casadi_int k = 0; k < c->jnnz; ++k) idx[k] = (sunindextype)c->jrow[k];
  c->res[0] = SM_DATA_S(J);
  c->n_jac++;
}

/* The whole-loop driver's CVODE: work arrays, the Jacobian's and the LU's patterns, a
   SUNSparseMatrix and the custom direct linear solver. Returns 0, or -1 with c->msg. */
static int hitl_native_create(hitl_ctx *c, hitl_cvode *s, int nx, const casadi_int *sz,
                              casadi_int **lucol, casadi_int **lurow, const char *log_path) {
  const casadi_int *jac_sp = nat_jac_sparsity_out(0);
  casadi_int lunnz;
  memset(s, 0, sizeof *s);
  if (hitl_ctx_alloc(c, nx, sz)) return -1;
  c->jnnz = hitl_pattern(jac_sp, &c->jcol, &c->jrow);
  lunnz = hitl_pattern(nat_lu_factor_sparsity_out(0), lucol, lurow);
  c->lu = (casadi_real *)calloc((size_t)(lunnz > 0 ? lunnz : 0) + 1, sizeof(casadi_real));
  c->piv = (casadi_real *)calloc((size_t)nx + 1, sizeof(casadi_real));
  if (!c->lu || !c->piv || c->jnnz < 0 || lunnz < 0) {
    hitl_msg(c, "out of memory");
    return -1;
  }
  if (jac_sp[0] != nx || jac_sp[1] != nx) {
    hitl_msg(c, "nx does not match the generated Jacobian");
    return -1;
  }
  if (hitl_sundials_create(c, s, nx, log_path)) return -1;
  s->A = SUNSparseMatrix(nx, nx, c->jnnz, CSC_MAT, s->ctx);
  if (!s->A) {
    hitl_msg(c, "CVODE could not allocate its memory");
    return -1;
  }
  hitl_ls_attach(s, c, hitl_ls_setup, hitl_ls_solve);
  return 0;
}

static int hitl_rhs(sunrealtype t, N_Vector y, N_Vector ydot, void *data) {
  hitl_ctx *c = (hitl_ctx *)data;
  casadi_real tt = t;
  casadi_real *out = N_VGetArrayPointer(ydot);
  c->arg[0] = &tt;
  c->arg[1] = N_VGetArrayPointer(y);
  c->arg[2] = c->p;
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
  casadi_real tt = t;
  hitl_jac_prepare(c, J);
  c->arg[0] = &tt;
  c->arg[1] = N_VGetArrayPointer(y);
  c->arg[2] = c->p;
  (void)fy; (void)t1; (void)t2; (void)t3;
  return nat_jac(c->arg, c->res, c->iw, c->w, 0) ? -1 : 0;
}

/*
 * Integrate from x0 at o->t_out[0] and store the state at every output time in
 * r->x_out (row-major x_out[k * nx + i]; CVODE's interpolant between its steps, as
 * CVODES through CasADi). The run restarts (CVodeReInit) at every breakpoint; it stops
 * exactly there and at the horizon (CVodeSetStopTime), never stepping beyond. The
 * options' t_out and breaks are generated.schedule.schedule's targets and restart
 * times (hitl_cvode_outputs). Returns r->filled: the rows of x_out filled (>= 1), or -1
 * if CVODE could not be set up; r->flag is CVODE's last flag (< 0 on a failure) and
 * r->msg its name and message.
 */
CASADI_SYMBOL_EXPORT int hitl_native_run(int nx, const double *x0, const hitl_options *o,
                                         hitl_result *r) {
  hitl_ctx c;
  hitl_cvode s;
  casadi_int sz[4] = {0, 0, 0, 0}, *lucol = NULL, *lurow = NULL;
  int ok, filled;

  memset(&c, 0, sizeof c);
  hitl_result_start(r);
  c.msg = r->msg;
  c.msglen = HITL_MSG_LEN;
  c.p = o->p;
  if (o->np != (int)nat_rhs_sparsity_in(2)[0] || (o->np > 0 && !o->p)) {
    snprintf(r->msg, HITL_MSG_LEN, "HITL_BAD_PARAMETERS: %d parameters given, the library takes %d",
             o->np, (int)nat_rhs_sparsity_in(2)[0]);
    r->flag = -1;
    return -1;
  }
  hitl_work_size(nat_rhs_work, sz);
  hitl_work_size(nat_jac_work, sz);
  hitl_work_size(nat_lu_factor_work, sz);
  hitl_work_size(nat_lu_solve_work, sz);
  ok = hitl_native_create(&c, &s, nx, sz, &lucol, &lurow, o->log_path) == 0;
  filled = hitl_cvode_run(&c, &s, ok, &c, hitl_rhs, hitl_jac, x0, o, r);
  hitl_cvode_free(&c, &s);
  free(lucol), free(lurow);
  return filled;
}
