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
  casadi_real tt = t;
  hitl_jac_prepare(c, J);
  c->arg[0] = &tt;
  c->arg[1] = N_VGetArrayPointer(y);
  (void)fy; (void)t1; (void)t2; (void)t3;
  return nat_jac(c->arg, c->res, c->iw, c->w, 0) ? -1 : 0;
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
  hitl_cvode s;
  casadi_int sz[4] = {0, 0, 0, 0};
  int filled = -1, flag = 0, ib = 0;
  long acc[7] = {0, 0, 0, 0, 0, 0, 0};
  double t, tstop_set = NAN;

  memset(&c, 0, sizeof c);
  for (int i = 0; i < HITL_NSTATS; ++i) stats[i] = 0.0;
  c.msg = msg;
  c.msglen = msglen;
  if (msglen > 0) msg[0] = '\0';
  hitl_work_size(nat_rhs_work, sz);
  hitl_work_size(nat_jac_work, sz);
  hitl_work_size(nat_lu_factor_work, sz);
  hitl_work_size(nat_lu_solve_work, sz);
  if (hitl_cvode_create(&c, &s, nx, sz, nat_jac_sparsity_out(0),
                        nat_lu_factor_sparsity_out(0)))
    goto done;
  memcpy(N_VGetArrayPointer(s.y), x0, (size_t)nx * sizeof(double));
  memcpy(x_out, x0, (size_t)nx * sizeof(double));
  t = t_out[0];
  if (CVodeInit(s.mem, hitl_rhs, t, s.y) || hitl_cvode_options(&s, &c, rtol, atol, hitl_jac) ||
      CVodeSetMaxNumSteps(s.mem, max_steps)) {
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
        CVodeSetStopTime(s.mem, stop);
        tstop_set = stop;
      }
      flag = CVode(s.mem, tout < stop ? tout : stop, s.y, &t, CV_NORMAL);
      if (flag < 0) goto done;
      if (t >= stop) {
        tstop_set = NAN; /* CVODE forgets a stop time once reached */
        if (ib < nb) {   /* a breakpoint: restart from the state reached */
          hitl_add_counters(s.mem, acc);
          if (CVodeReInit(s.mem, t, s.y)) goto done;
          stats[HITL_RESTARTS] += 1;
          ib++;
        }
      }
      if (t >= tout) break;
    }
    memcpy(x_out + (size_t)k * nx, N_VGetArrayPointer(s.y), (size_t)nx * sizeof(double));
    filled = k + 1;
  }

done:
  {
    sunrealtype h = 0;
    if (s.mem) {
      hitl_add_counters(s.mem, acc);
      CVodeGetLastStep(s.mem, &h);
    }
    hitl_stats(&c, acc, h, flag, stats);
  }
  stats[HITL_T_REACHED] = filled >= 1 ? t_out[filled - 1] : t_out[0];
  if (flag < 0) hitl_flag_message(&c, flag);
  hitl_cvode_free(&c, &s);
  return filled;
}
