/*
 * Graph-ordered CVODE driver of the hitl-formation toolkit (generated/dag.py): the whole
 * closed loop in one CVODE run, with its right-hand side and its Newton systems
 * evaluated follower by follower along a topological order of the (acyclic) graph.
 *
 * Appended (after common.c) to the C that CasADi generates for
 *   dag_rhs(t, xb, nb, cpl, prm, gf) -> (xbdot, jets)  one follower's block
 *                                                      (symbolic/cascade.py)
 *   dag_jac(t, xb, nb, cpl, prm, gf) -> (jets, K)      the same jets and the block's
 *                                                      Jacobian K = d(xbdot, jets)/d(xb, nb)
 *   dag_faults(t) -> values                            every distinct fault expression
 * with xb = (eta0, s_i) and jets = C0 (eta_i, eta_i', eta_i'') (3n); nb = sum_j
 * (L+B)_ij jets_j.
 *
 * Right-hand side: one pass over the followers in order; each block reads the jets the
 * followers it hears computed earlier in the same pass (exact, nothing interpolated).
 * The sum over blocks is the whole closed loop's right-hand side.
 *
 * Newton systems (I - gamma J) x = b: J is block lower triangular in this order (a
 * follower depends on itself, the leader and, through nb, on followers before it), so
 * they are solved exactly by block forward substitution: the leader's block, then for
 * each follower (I - gamma A_ss) x_i = b_i + gamma (A_s0 x_0 + B_s dnb_i), with dnb_i the
 * sum of the directional jets dj_j = C_0 x_0 + C_s x_j + E dnb_j of the followers it
 * hears. Only the diagonal blocks are factorised (dense LU with partial pivoting,
 * SUNDIALS' SUNDlsMat_denseGETRF): cost linear in N, no fill-in. The Jacobian lives in
 * a custom SUNMatrix holding the K blocks and the scalar that CVODE's
 * SUNMatScaleAddI(-gamma) applies, so CVODE reuses a Jacobian across set-ups exactly
 * as with the native driver.
 */

/* declared in SUNDIALS' sundials/sundials_dense.h (not vendored); in sundials_core */
SUNDIALS_EXPORT sunindextype SUNDlsMat_denseGETRF(sunrealtype **a, sunindextype m,
                                                  sunindextype n, sunindextype *p);
SUNDIALS_EXPORT void SUNDlsMat_denseGETRS(sunrealtype **a, sunindextype n, sunindextype *p,
                                          sunrealtype *b);

/* The Jacobian: a hitl_kmat (common.c) of N blocks K_i, k x k, column-major */

typedef struct {
  hitl_ctx base; /* first member */
  int N, m, na, n, n3, k, npar;
  const int *order, *up_ptr, *up_idx, *fidx;
  const double *up_w, *cpl, *prm;
  double *fvals, *gf, *nb, *xb, *xbdot, *jets; /* jets: N x n3 */
  double *lu, **cols, *djets, *r, *dnb;        /* linear solver */
  sunindextype *piv;
} hitl_dag;

/* nb of follower i (3n) from a per-follower array of jets (N x n3) */
static void hitl_dag_gather(const hitl_dag *d, int i, const double *J, double *nb) {
  for (int k = 0; k < d->n3; ++k) nb[k] = 0.0;
  for (int q = d->up_ptr[i]; q < d->up_ptr[i + 1]; ++q) {
    const double *jj = J + (size_t)d->up_idx[q] * d->n3;
    double w = d->up_w[q];
    for (int k = 0; k < d->n3; ++k) nb[k] += w * jj[k];
  }
}

/* One pass over the followers at (t, y): ydot (if not NULL) and/or the Jacobian blocks
   K (if not NULL; N x k x k). */
static int hitl_dag_pass(hitl_dag *d, double t, const double *y, double *ydot, double *K) {
  hitl_ctx *c = &d->base;
  casadi_real tt = t;
  int m = d->m, na = d->na, n = d->n;
  c->arg[0] = &tt;
  c->res[0] = d->fvals;
  if (dag_faults(c->arg, c->res, c->iw, c->w, 0)) return -1;
  for (int oi = 0; oi < d->N; ++oi) {
    int i = d->order[oi];
    const int *fi = d->fidx + (size_t)(1 + n) * i;
    hitl_dag_gather(d, i, d->jets, d->nb);
    memcpy(d->xb, y, sizeof(double) * (size_t)m);
    memcpy(d->xb + m, y + m + (size_t)na * i, sizeof(double) * (size_t)na);
    for (int r = 0; r <= n; ++r) d->gf[r] = d->fvals[fi[r]];
    c->arg[0] = &tt;
    c->arg[1] = d->xb;
    c->arg[2] = d->nb;
    c->arg[3] = d->cpl + 2 * (size_t)i;
    c->arg[4] = d->prm + (size_t)d->npar * i;
    c->arg[5] = d->gf;
    if (ydot) {
      c->res[0] = d->xbdot;
      c->res[1] = d->jets + (size_t)d->n3 * i;
      if (dag_rhs(c->arg, c->res, c->iw, c->w, 0)) return -1;
      if (oi == 0) memcpy(ydot, d->xbdot, sizeof(double) * (size_t)m);
      memcpy(ydot + m + (size_t)na * i, d->xbdot + m, sizeof(double) * (size_t)na);
    } else {
      c->res[0] = d->jets + (size_t)d->n3 * i;
      c->res[1] = K + (size_t)d->k * d->k * i;
      if (dag_jac(c->arg, c->res, c->iw, c->w, 0)) return -1;
    }
  }
  return 0;
}

static int hitl_dag_rhs(sunrealtype t, N_Vector y, N_Vector ydot, void *data) {
  hitl_dag *d = (hitl_dag *)data;
  casadi_real *out = N_VGetArrayPointer(ydot);
  d->base.n_rhs++;
  if (hitl_dag_pass(d, t, N_VGetArrayPointer(y), out, NULL)) return -1;
  for (int i = 0; i < d->base.nx; ++i)
    if (!isfinite(out[i])) return 1; /* recoverable: CVODE retries with a smaller step */
  return 0;
}

static int hitl_dag_jac(sunrealtype t, N_Vector y, N_Vector fy, SUNMatrix J, void *data,
                        N_Vector t1, N_Vector t2, N_Vector t3) {
  hitl_dag *d = (hitl_dag *)data;
  hitl_kmat *M = HITL_KMAT(J);
  (void)fy; (void)t1; (void)t2; (void)t3;
  d->base.n_jac++;
  M->c = 1.0;
  M->shifted = 0;
  return hitl_dag_pass(d, t, N_VGetArrayPointer(y), NULL, M->K) ? -1 : 0;
}

/* Factorise the diagonal blocks of M = I + c J: the leader's (first follower's block,
   rows and columns 0..m-1) and every follower's A_ss. */
static int hitl_dag_ls_setup(SUNLinearSolver S, SUNMatrix A) {
  hitl_dag *d = (hitl_dag *)S->content;
  hitl_kmat *M = HITL_KMAT(A);
  int m = d->m, na = d->na, k = d->k;
  double c = M->c;
  if (!M->shifted) return -1; /* CVODE always hands over I - gamma J */
  d->base.n_fac++;
  for (int b = 0; b <= d->N; ++b) {
    /* block b < N: follower order[b]'s A_ss; b = N: the leader */
    int i = b < d->N ? d->order[b] : d->order[0];
    int sz = b < d->N ? na : m, off = b < d->N ? m : 0;
    const double *K = M->K + (size_t)k * k * i;
    double *L = d->lu + (size_t)na * na * b;
    double **cols = d->cols + (size_t)na * b;
    for (int col = 0; col < sz; ++col) {
      cols[col] = L + (size_t)sz * col;
      for (int row = 0; row < sz; ++row)
        cols[col][row] = c * K[(size_t)(off + col) * k + off + row] + (row == col ? 1.0 : 0.0);
    }
    if (SUNDlsMat_denseGETRF(cols, sz, sz, d->piv + (size_t)na * b) != 0) {
      d->base.n_piv_fail++;
      return SUNLS_LUFACT_FAIL; /* recoverable: CVODE retries with a smaller step */
    }
  }
  return 0;
}

/* x = M^{-1} b by block forward substitution along the order */
static int hitl_dag_ls_solve(SUNLinearSolver S, SUNMatrix A, N_Vector xv, N_Vector bv,
                             sunrealtype tol) {
  hitl_dag *d = (hitl_dag *)S->content;
  hitl_kmat *M = HITL_KMAT(A);
  int m = d->m, na = d->na, k = d->k, n3 = d->n3, N = d->N;
  double c = M->c, *x = N_VGetArrayPointer(xv);
  const double *b = N_VGetArrayPointer(bv);
  (void)tol;
  if (x != b) memcpy(x, b, sizeof(double) * (size_t)d->base.nx);
  SUNDlsMat_denseGETRS(d->cols + (size_t)na * N, m, d->piv + (size_t)na * N, x); /* leader */
  for (int oi = 0; oi < N; ++oi) {
    int i = d->order[oi];
    const double *K = M->K + (size_t)k * k * i;
    double *xi = x + m + (size_t)na * i, *dj = d->djets + (size_t)n3 * i;
    hitl_dag_gather(d, i, d->djets, d->dnb);
    /* (I + c A_ss) x_i = b_i - c (A_s0 x_0 + B_s dnb) */
    for (int row = 0; row < na; ++row) {
      double acc = 0.0;
      for (int col = 0; col < m; ++col) acc += K[(size_t)col * k + m + row] * x[col];
      for (int col = 0; col < n3; ++col) acc += K[(size_t)(m + na + col) * k + m + row] * d->dnb[col];
      xi[row] -= c * acc;
    }
    SUNDlsMat_denseGETRS(d->cols + (size_t)na * oi, na, d->piv + (size_t)na * oi, xi);
    /* its directional jets: C_0 x_0 + C_s x_i + E dnb */
    for (int row = 0; row < n3; ++row) {
      int r = m + na + row;
      double acc = 0.0;
      for (int col = 0; col < m; ++col) acc += K[(size_t)col * k + r] * x[col];
      for (int col = 0; col < na; ++col) acc += K[(size_t)(m + col) * k + r] * xi[col];
      for (int col = 0; col < n3; ++col) acc += K[(size_t)(m + na + col) * k + r] * d->dnb[col];
      dj[row] = acc;
    }
  }
  return 0;
}

/* Everything a run needs: sizes, problem arrays, work arrays, CVODE, the block
   matrix and the linear solver; SUNDIALS' messages to log_path (NULL: dropped).
   Returns 0, or -1 with d->base.msg set. */
static int hitl_dag_init(hitl_dag *d, hitl_cvode *s, const hitl_dag_problem *p, char *msg,
                         int msglen, const char *log_path) {
  hitl_ctx *c = &d->base;
  casadi_int sz[4] = {0, 0, 0, 0};
  int N = p->N, m = p->m, na = p->na, n = p->n, npar = p->npar;
  int nx = m + N * na;
  memset(d, 0, sizeof *d);
  memset(s, 0, sizeof *s);
  c->msg = msg;
  c->msglen = msglen;
  if (msglen > 0) msg[0] = '\0';
  d->N = N, d->m = m, d->na = na, d->n = n, d->n3 = 3 * n, d->k = m + na + 3 * n;
  d->npar = npar, d->order = p->order, d->up_ptr = p->up_ptr, d->up_idx = p->up_idx;
  d->up_w = p->up_w, d->cpl = p->cpl, d->prm = p->prm, d->fidx = p->fidx;
  if (dag_rhs_sparsity_in(1)[0] != m + na || dag_rhs_sparsity_in(2)[0] != 3 * n ||
      dag_rhs_sparsity_in(4)[0] != npar || dag_jac_sparsity_out(1)[0] != d->k) {
    hitl_msg(c, "block sizes do not match the generated block");
    return -1;
  }
  hitl_work_size(dag_rhs_work, sz);
  hitl_work_size(dag_jac_work, sz);
  hitl_work_size(dag_faults_work, sz);
  if (hitl_ctx_alloc(c, nx, sz)) return -1;
  d->fvals = (double *)calloc((size_t)dag_faults_sparsity_out(0)[0] + 1, sizeof(double));
  d->gf = (double *)calloc((size_t)n + 1, sizeof(double));
  d->nb = (double *)calloc((size_t)d->n3 + 1, sizeof(double));
  d->xb = (double *)calloc((size_t)(m + na), sizeof(double));
  d->xbdot = (double *)calloc((size_t)(m + na), sizeof(double));
  d->jets = (double *)calloc((size_t)N * d->n3 + 1, sizeof(double));
  d->djets = (double *)calloc((size_t)N * d->n3 + 1, sizeof(double));
  d->dnb = (double *)calloc((size_t)d->n3 + 1, sizeof(double));
  d->lu = (double *)calloc((size_t)(N + 1) * na * na, sizeof(double));
  d->cols = (double **)calloc((size_t)(N + 1) * na, sizeof(double *));
  d->piv = (sunindextype *)calloc((size_t)(N + 1) * na, sizeof(sunindextype));
  if (!d->fvals || !d->gf || !d->nb || !d->xb || !d->xbdot || !d->jets || !d->djets ||
      !d->dnb || !d->lu || !d->cols || !d->piv) {
    hitl_msg(c, "out of memory");
    return -1;
  }
  if (hitl_sundials_create(c, s, nx, log_path)) return -1;
  s->A = hitl_kmat_new((long)N * d->k * d->k, s->ctx);
  if (!s->A) {
    hitl_msg(c, "out of memory");
    return -1;
  }
  hitl_ls_attach(s, d, hitl_dag_ls_setup, hitl_dag_ls_solve);
  return 0;
}

static void hitl_dag_free(hitl_dag *d, hitl_cvode *s) {
  free(d->fvals), free(d->gf), free(d->nb), free(d->xb), free(d->xbdot), free(d->jets);
  free(d->djets), free(d->dnb), free(d->lu), free(d->cols), free(d->piv);
  hitl_cvode_free(&d->base, s);
}

/*
 * Integrate the whole closed loop (nx = m + N*na states of the problem p, hitl_native.h)
 * from x0 at o->t_out[0] and store the state at every output time in r->x_out
 * (row-major); options and result as the whole-loop driver's (hitl_native_run).
 * Returns r->filled: the rows filled (>= 1), or -1 if CVODE could not be set up.
 */
CASADI_SYMBOL_EXPORT int hitl_dag_run(const hitl_dag_problem *p, const double *x0,
                                      const hitl_options *o, hitl_result *r) {
  hitl_dag d;
  hitl_cvode s;
  int ok, filled;
  hitl_result_start(r);
  ok = hitl_dag_init(&d, &s, p, r->msg, HITL_MSG_LEN, o->log_path) == 0;
  filled = hitl_cvode_run(&d.base, &s, ok, &d, hitl_dag_rhs, hitl_dag_jac, x0, o, r);
  hitl_dag_free(&d, &s);
  return filled;
}

/*
 * For tests (tests/test_dag.py): at (t, x), the right-hand side (xdot, nx) and the
 * solution of (I - gamma J) sol = b, exactly as a run evaluates and solves them.
 * Returns 0, or -1 with msg set.
 */
CASADI_SYMBOL_EXPORT int hitl_dag_probe(const hitl_dag_problem *p, double t, const double *x,
                                        double gamma, const double *b, double *xdot, double *sol,
                                        char *msg, int msglen) {
  hitl_dag d;
  hitl_cvode s;
  int nx = p->m + p->N * p->na, ret = -1;
  N_Vector bv = NULL, xv = NULL;
  if (hitl_dag_init(&d, &s, p, msg, msglen, NULL)) goto done;
  bv = N_VNew_Serial(nx, s.ctx);
  xv = N_VNew_Serial(nx, s.ctx);
  if (!bv || !xv) goto done;
  memcpy(N_VGetArrayPointer(s.y), x, (size_t)nx * sizeof(double));
  memcpy(N_VGetArrayPointer(bv), b, (size_t)nx * sizeof(double));
  if (hitl_dag_pass(&d, t, x, xdot, NULL)) goto done;
  if (hitl_dag_jac(t, s.y, NULL, s.A, &d, NULL, NULL, NULL)) goto done;
  if (SUNMatScaleAddI(-gamma, s.A) || hitl_dag_ls_setup(s.LS, s.A) ||
      hitl_dag_ls_solve(s.LS, s.A, xv, bv, 0.0))
    goto done;
  memcpy(sol, N_VGetArrayPointer(xv), (size_t)nx * sizeof(double));
  ret = 0;

done:
  if (bv) N_VDestroy(bv);
  if (xv) N_VDestroy(xv);
  hitl_dag_free(&d, &s);
  return ret;
}
