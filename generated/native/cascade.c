/*
 * Cascade CVODE driver of the hitl-formation toolkit (generated/cascade.py): the
 * closed loop follower by follower, along a topological order of an acyclic graph.
 *
 * Appended (after common.c) to the C that CasADi generates for
 *   cas_rhs(t, xb, nb, cpl, prm, gf) -> (xbdot, jets)   one follower's block
 *                                                       (symbolic/cascade.py)
 *   cas_jac(t, xb, nb, cpl, prm, gf) -> J               its Jacobian on the pattern of
 *                                                       M = I - gamma J
 *   nat_lu_factor / nat_lu_solve                        sparse LU of M (common.c)
 *   cas_faults(t) -> values                             every distinct fault expression
 *
 * Each follower is integrated over the whole horizon by CVODE (BDF) with its own
 * steps. Its input nb(t) = sum_j (L+B)_ij (C0 eta_j, its 1st and 2nd derivative) comes
 * from the followers it hears, integrated before it: at every accepted step each
 * follower stores its jets (C0 eta, C0 eta', C0 eta'', C0 eta''') and a listener
 * evaluates nb(t) by cubic Hermite interpolation of each jet level with the next one
 * as its derivative. Breakpoints split the horizon into segments that every follower
 * ends and restarts at exactly, so no interpolation crosses a discontinuity. A
 * follower's stored jets are freed once every follower that hears it is done.
 */

/* extra stats after the common ones (generated/cascade.py: STATS) */
enum { HITL_C_JETS = HITL_NSTATS, HITL_C_MAX_AGENT_STEPS, HITL_C_PEAK_NODES, HITL_C_FAILED,
       HITL_C_NSTATS };

/* one follower's jets at its accepted steps */
typedef struct {
  double *data;    /* rows (t, jets[4n]) */
  long count, cap; /* rows stored / allocated */
  long *seg;       /* seg[s]: first row of segment s; seg[nseg] = count once closed */
  int nseg;        /* segments opened */
  int remaining;   /* listeners not yet integrated */
} hitl_track;

typedef struct {
  hitl_ctx base; /* first member: the linear solver's content is a hitl_ctx */
  int n, row;    /* outputs per follower; doubles per stored row (1 + 4n) */
  int seg;       /* current segment */
  int nup;       /* followers heard by the current one */
  const int *up;
  const double *upw;
  long *cursor; /* per heard follower: row where the last lookup ended */
  hitl_track *tracks;
  const double *cpl, *prm;
  const int *fidx;
  double *fvals, *gf, *nb, *jets;
  long n_jets, live_rows, peak_rows;
} hitl_cascade;

/* nb(t) (3n) from the tracks of the followers heard, and gf(t) from the faults */
static int hitl_cascade_inputs(hitl_cascade *cc, double t) {
  hitl_ctx *c = &cc->base;
  casadi_real tt = t;
  int n = cc->n, row = cc->row;
  c->arg[0] = &tt;
  c->res[0] = cc->fvals;
  if (cas_faults(c->arg, c->res, c->iw, c->w, 0)) return -1;
  for (int r = 0; r <= n; ++r) cc->gf[r] = cc->fvals[cc->fidx[r]];
  for (int k = 0; k < 3 * n; ++k) cc->nb[k] = 0.0;
  for (int q = 0; q < cc->nup; ++q) {
    const hitl_track *tr = &cc->tracks[cc->up[q]];
    int sg = cc->seg < tr->nseg ? cc->seg : tr->nseg - 1;
    long lo = tr->seg[sg], hi = (sg + 1 < tr->nseg ? tr->seg[sg + 1] : tr->count) - 1;
    long a = cc->cursor[q];
    const double *D = tr->data;
    double w = cc->upw[q];
    if (hi <= lo) { /* one row: constant */
      for (int k = 0; k < 3 * n; ++k) cc->nb[k] += w * D[lo * row + 1 + k];
      continue;
    }
    if (a < lo || a >= hi) a = lo;
    while (a + 1 < hi && D[(a + 1) * row] < t) a++;
    while (a > lo && D[a * row] > t) a--;
    cc->cursor[q] = a;
    {
      const double *y0 = D + a * row, *y1 = D + (a + 1) * row;
      double h = y1[0] - y0[0];
      double s = h > 0 ? (t - y0[0]) / h : 0.0;
      if (s < 0) s = 0; /* CVODE never asks outside a segment; guard round-off */
      if (s > 1) s = 1;
      {
        double s2 = s * s, s3 = s2 * s;
        double h00 = 2 * s3 - 3 * s2 + 1, h10 = s3 - 2 * s2 + s;
        double h01 = -2 * s3 + 3 * s2, h11 = s3 - s2;
        for (int lev = 0; lev < 3; ++lev)
          for (int r = 0; r < n; ++r) {
            int v = 1 + lev * n + r, d = v + n; /* value and its derivative */
            cc->nb[lev * n + r] +=
                w * (h00 * y0[v] + h10 * h * y0[d] + h01 * y1[v] + h11 * h * y1[d]);
          }
      }
    }
  }
  return 0;
}

/* the block at (t, y): xbdot and/or jets (a NULL output is skipped) */
static int hitl_cascade_eval(hitl_cascade *cc, double t, const double *y, double *xbdot,
                             double *jets) {
  hitl_ctx *c = &cc->base;
  casadi_real tt = t;
  if (hitl_cascade_inputs(cc, t)) return -1;
  c->arg[0] = &tt;
  c->arg[1] = y;
  c->arg[2] = cc->nb;
  c->arg[3] = cc->cpl;
  c->arg[4] = cc->prm;
  c->arg[5] = cc->gf;
  c->res[0] = xbdot;
  c->res[1] = jets;
  return cas_rhs(c->arg, c->res, c->iw, c->w, 0) ? -1 : 0;
}

static int hitl_cascade_rhs(sunrealtype t, N_Vector y, N_Vector ydot, void *data) {
  hitl_cascade *cc = (hitl_cascade *)data;
  casadi_real *out = N_VGetArrayPointer(ydot);
  cc->base.n_rhs++;
  if (hitl_cascade_eval(cc, t, N_VGetArrayPointer(y), out, NULL)) return -1;
  for (int i = 0; i < cc->base.nx; ++i)
    if (!isfinite(out[i])) return 1; /* recoverable: CVODE retries with a smaller step */
  return 0;
}

static int hitl_cascade_jac(sunrealtype t, N_Vector y, N_Vector fy, SUNMatrix J, void *data,
                            N_Vector t1, N_Vector t2, N_Vector t3) {
  hitl_cascade *cc = (hitl_cascade *)data;
  hitl_ctx *c = &cc->base;
  casadi_real tt = t;
  (void)fy; (void)t1; (void)t2; (void)t3;
  if (hitl_cascade_inputs(cc, t)) return -1;
  hitl_jac_prepare(c, J);
  c->arg[0] = &tt;
  c->arg[1] = N_VGetArrayPointer(y);
  c->arg[2] = cc->nb;
  c->arg[3] = cc->cpl;
  c->arg[4] = cc->prm;
  c->arg[5] = cc->gf;
  return cas_jac(c->arg, c->res, c->iw, c->w, 0) ? -1 : 0;
}

/* store the jets of follower i at (t, y) as a new row of its track */
static int hitl_track_push(hitl_cascade *cc, hitl_track *tr, double t, const double *y) {
  if (tr->count == tr->cap) {
    long cap = tr->cap ? 2 * tr->cap : 1024;
    double *d = (double *)realloc(tr->data, sizeof(double) * (size_t)(cap * cc->row));
    if (!d) return -1;
    tr->data = d;
    tr->cap = cap;
  }
  cc->n_jets++;
  if (hitl_cascade_eval(cc, t, y, NULL, cc->jets)) return -1;
  tr->data[tr->count * cc->row] = t;
  memcpy(tr->data + tr->count * cc->row + 1, cc->jets, sizeof(double) * (size_t)(4 * cc->n));
  tr->count++;
  if (++cc->live_rows > cc->peak_rows) cc->peak_rows = cc->live_rows;
  return 0;
}

static void hitl_track_free(hitl_cascade *cc, hitl_track *tr) {
  cc->live_rows -= tr->count;
  free(tr->data), free(tr->seg);
  tr->data = NULL, tr->seg = NULL, tr->count = tr->cap = 0;
}

/*
 * Integrate N followers, block size nxb = m + na, in the given order. order[N]: a
 * topological order; up_ptr[N+1], up_idx, up_w: CSR of the followers each one hears
 * and the weights (L+B)_ij; cpl[N*2], prm[N*npar] (agent-major), fidx[N*(1+n)]: the
 * block's constant inputs; x0[nx] with nx = m + N*na: the whole closed loop's initial
 * state; t_out[nt], breaks[nb] (inside (t_out[0], t_out[nt-1]), increasing).
 * x_out (nt*nx, row-major) receives the whole state at every output time: follower i's
 * block from its own run, the leader's from the first follower's. agent_steps[N]:
 * CVODE's steps per follower. Returns the number of rows filled: nt, or, if a
 * follower's integration fails, the rows every follower reached (the failing one's;
 * later followers stop there); -1 if CVODE could not be set up or run out of memory
 * (msg says which). stats[HITL_C_FAILED]
 * is the failing follower (0-based) or -1.
 */
CASADI_SYMBOL_EXPORT int hitl_cascade_run(int N, int m, int na, int n, const int *order,
                                          const int *up_ptr, const int *up_idx,
                                          const double *up_w, const double *cpl,
                                          int npar, const double *prm, const int *fidx,
                                          const double *x0, int nt, const double *t_out,
                                          int nb, const double *breaks, double rtol,
                                          double atol, long max_steps, double *x_out,
                                          double *stats, double *agent_steps, char *msg,
                                          int msglen) {
  hitl_cascade cc;
  hitl_ctx *c = &cc.base;
  hitl_cvode s;
  casadi_int sz[4] = {0, 0, 0, 0};
  casadi_int nf = cas_faults_sparsity_out(0)[0];
  int nxb = m + na, nx = m + N * na, nt_eff = nt, flag = 0, inited = 0, failed = -1;
  int status = -1, fail_flag = 0; /* -1 until every follower has been run */
  long acc[7] = {0, 0, 0, 0, 0, 0, 0}, max_agent_steps = 0;
  double h_last = 0;
  N_Vector ytmp = NULL;

  memset(&cc, 0, sizeof cc);
  memset(&s, 0, sizeof s);
  for (int i = 0; i < HITL_C_NSTATS; ++i) stats[i] = 0.0;
  for (int i = 0; i < N; ++i) agent_steps[i] = 0.0;
  stats[HITL_C_FAILED] = -1;
  c->msg = msg;
  c->msglen = msglen;
  if (msglen > 0) msg[0] = '\0';
  cc.n = n;
  cc.row = 1 + 4 * n;
  hitl_work_size(cas_rhs_work, sz);
  hitl_work_size(cas_jac_work, sz);
  hitl_work_size(cas_faults_work, sz);
  hitl_work_size(nat_lu_factor_work, sz);
  hitl_work_size(nat_lu_solve_work, sz);
  if (cas_rhs_sparsity_in(1)[0] != nxb || cas_rhs_sparsity_in(2)[0] != 3 * n ||
      cas_rhs_sparsity_in(4)[0] != npar) {
    hitl_msg(c, "block sizes do not match the generated cascade block");
    return -1;
  }
  cc.tracks = (hitl_track *)calloc((size_t)N, sizeof(hitl_track));
  cc.cursor = (long *)calloc((size_t)(up_ptr[N] + 1), sizeof(long));
  cc.fvals = (double *)calloc((size_t)nf + 1, sizeof(double));
  cc.gf = (double *)calloc((size_t)n + 1, sizeof(double));
  cc.nb = (double *)calloc((size_t)(3 * n), sizeof(double));
  cc.jets = (double *)calloc((size_t)(4 * n), sizeof(double));
  if (!cc.tracks || !cc.cursor || !cc.fvals || !cc.gf || !cc.nb || !cc.jets) {
    hitl_msg(c, "out of memory");
    goto done;
  }
  for (int q = 0; q < up_ptr[N]; ++q) cc.tracks[up_idx[q]].remaining++;
  if (hitl_cvode_create(c, &s, nxb, sz, cas_jac_sparsity_out(0), nat_lu_factor_sparsity_out(0)))
    goto done;
  ytmp = N_VNew_Serial(nxb, s.ctx);
  if (!ytmp) {
    hitl_msg(c, "out of memory");
    goto done;
  }
  memcpy(x_out, x0, (size_t)nx * sizeof(double));

  for (int oi = 0; oi < N; ++oi) {
    int i = order[oi], ib = 0, k = 1;
    hitl_track *tr = &cc.tracks[i];
    double *y = N_VGetArrayPointer(s.y), t = t_out[0], t_end = t_out[nt_eff - 1];
    double tstop_set = NAN;
    long steps_out = 0, steps0 = acc[0];
    cc.up = up_idx + up_ptr[i];
    cc.upw = up_w + up_ptr[i];
    cc.nup = up_ptr[i + 1] - up_ptr[i];
    for (int q = 0; q < cc.nup; ++q) cc.cursor[q] = 0;
    cc.cpl = cpl + 2 * i;
    cc.prm = prm + (size_t)npar * i;
    cc.fidx = fidx + (size_t)(1 + n) * i;
    cc.seg = 0;
    tr->seg = (long *)calloc((size_t)nb + 2, sizeof(long));
    if (!tr->seg) {
      hitl_msg(c, "out of memory");
      goto done;
    }
    tr->nseg = 1;
    memcpy(y, x0, (size_t)m * sizeof(double));
    memcpy(y + m, x0 + m + (size_t)na * i, (size_t)na * sizeof(double));
    if (!inited) {
      if (CVodeInit(s.mem, hitl_cascade_rhs, t, s.y) ||
          hitl_cvode_options(&s, &cc, rtol, atol, hitl_cascade_jac))
        goto done;
      inited = 1;
    } else if (CVodeReInit(s.mem, t, s.y)) {
      goto done;
    }
    if (hitl_track_push(&cc, tr, t, y)) goto fail_eval;
    while (ib < nb && breaks[ib] <= t) ib++;
    while (k < nt_eff) {
      double stop = ib < nb && breaks[ib] < t_end ? breaks[ib] : t_end;
      if (stop != tstop_set) {
        CVodeSetStopTime(s.mem, stop);
        tstop_set = stop;
      }
      flag = CVode(s.mem, stop, s.y, &t, CV_ONE_STEP);
      if (flag >= 0 && ++steps_out > max_steps) {
        flag = CV_TOO_MUCH_WORK;
        hitl_msg(c, "more than max_steps steps between two output times");
      }
      if (flag < 0) break;
      while (k < nt_eff && t_out[k] <= t) { /* outputs inside the step just taken */
        double *row = x_out + (size_t)k * nx;
        if (CVodeGetDky(s.mem, t_out[k], 0, ytmp)) {
          flag = CV_ILL_INPUT;
          break;
        }
        if (oi == 0) memcpy(row, N_VGetArrayPointer(ytmp), (size_t)m * sizeof(double));
        memcpy(row + m + (size_t)na * i, N_VGetArrayPointer(ytmp) + m,
               (size_t)na * sizeof(double));
        k++;
        steps_out = 0;
      }
      if (flag < 0) break;
      if (hitl_track_push(&cc, tr, t, y)) goto fail_eval;
      if (t >= stop) {
        tstop_set = NAN; /* CVODE forgets a stop time once reached */
        if (stop < t_end) { /* a breakpoint: new segment, restart from the state reached */
          hitl_add_counters(s.mem, acc);
          if (CVodeReInit(s.mem, t, s.y)) goto done;
          stats[HITL_RESTARTS] += 1;
          ib++;
          tr->seg[tr->nseg++] = tr->count;
          cc.seg++;
          if (hitl_track_push(&cc, tr, t, y)) goto fail_eval;
        }
      }
    }
    hitl_add_counters(s.mem, acc);
    CVodeGetLastStep(s.mem, &h_last);
    agent_steps[i] = (double)(acc[0] - steps0);
    if (acc[0] - steps0 > max_agent_steps) max_agent_steps = acc[0] - steps0;
    if (flag < 0) { /* later followers stop where this one did */
      if (failed < 0) {
        failed = i;
        fail_flag = flag;
        hitl_flag_message(c, flag);
      }
      nt_eff = k;
      flag = 0;
    }
    for (int q = 0; q < cc.nup; ++q) /* free what no one will read again */
      if (--cc.tracks[cc.up[q]].remaining == 0) hitl_track_free(&cc, &cc.tracks[cc.up[q]]);
    if (tr->remaining == 0) hitl_track_free(&cc, tr);
    continue;
  fail_eval:
    hitl_msg(c, "the block could not be evaluated (out of memory or a generated-code error)");
    goto done;
  }
  status = nt_eff;

done:
  hitl_stats(c, acc, h_last, fail_flag, stats);
  stats[HITL_C_JETS] = (double)cc.n_jets;
  stats[HITL_C_MAX_AGENT_STEPS] = (double)max_agent_steps;
  stats[HITL_C_PEAK_NODES] = (double)cc.peak_rows;
  stats[HITL_C_FAILED] = failed;
  stats[HITL_T_REACHED] = status >= 1 ? t_out[status - 1] : t_out[0];
  if (cc.tracks)
    for (int i = 0; i < N; ++i) hitl_track_free(&cc, &cc.tracks[i]);
  free(cc.tracks), free(cc.cursor), free(cc.fvals), free(cc.gf), free(cc.nb), free(cc.jets);
  if (ytmp) N_VDestroy(ytmp);
  hitl_cvode_free(c, &s);
  return status;
}
