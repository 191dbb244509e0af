/*
 * The per-agent native driver (generated/agents.py; the design: docs/performance.md, 'The
 * graph as data'): one CVODE run whose right-hand side and Newton systems are evaluated
 * agent by agent from per-model kernels, with the graph, N, the pinning, the gauge signs,
 * every switching time and the links' fade as runtime data.
 *
 * Appended (after common.c) to the C that CasADi generates for ONE follower model
 * (generated/agent_kernels.py):
 *   ag_jet0, ag_jet1, ag_jet2 (t, xb, nb, cpl, prm) -> C0 eta_i, C0 eta_i', C0 eta_i''
 *   ag_rhs (t, xb, nb, cpl, prm) -> (xbdot, jets)
 *   ag_jac (t, xb, nb, cpl, prm) -> (jets, K),  K = d(xbdot, jets)/d(xb, nb): its
 *                                     structural nonzeros (column-compressed)
 *   ag_nfac (c, K) -> (P, pivots)        D = I + c A_ss factorised without pivoting, packed
 *                                         with what a solve reads (c A_s0, c B_s, C_0, C_s, E)
 *   ag_nsol (P, x0, s, b) -> (x, dj)     x = D^{-1} (b - c (A_s0 x0 + B_s s)),
 *                                         dj = C_0 x0 + C_s x + E s
 *   ag_gmat (P) -> (G, H)                G = E - c C_s D^{-1} B_s, H = -c D^{-1} B_s
 * with xb = (eta0, s_i), nb = sum_j (L+B)_ij jets_j (3n) and its two time derivatives,
 * and cpl = (l_ii, a_i0 h_i) with their first two time derivatives (6). The driver gets
 * one table of kernel pointers per follower model (hitl_agent_kernels): followers of
 * different models, each from its own library, run in one CVODE run.
 *
 * Right-hand side: one pass per jet level over all agents (level l reads the levels < l
 * of the neighbour sums), then the rates; on an acyclic topology one sweep along its order.
 *
 * Newton systems (I + c J) x = b (c = -gamma): the leader first; eliminating agent i's
 * states (D_i x_i = b_i - c (A_s0 x_0 + B_s dnb_i)) leaves the jets system
 *   dj_i - G_i sum_j w_ij dj_j = r_i,   r_i = C_0 x_0 + C_s D_i^{-1} (b_i - c A_s0 x_0),
 * solved by HITL_AG_FORWARD (block forward substitution through the states, acyclic
 * topologies only), HITL_AG_DENSE (LU with partial pivoting, small N) or HITL_AG_GMRES
 * (restarted, right-preconditioned: hitl_ag_precond); HITL_AG_AUTO takes FORWARD on an
 * acyclic topology and GMRES otherwise. Then x_i = y_i + H_i dnb_i.
 *
 * Links that fade (graph.link_fade = T > 0): time is cut into segments at every switch
 * s_k and s_k + T; on each, W(t) = sum_k c_k(t) W_k over the active topologies
 * (hitl_ag_weights) on the union of their patterns, whose order and acyclic flag the
 * solver choice reads. Neighbour sums take the weights' rates (hitl_ag_edge_level) and
 * the Newton systems the exact linearisation at the Jacobian's time: dnb_i = sum_j Wb_ij
 * dj_j, Wb = [[w, 0, 0], [w', w, 0], [w'', 2w', w]] (x I_n).
 */
#ifdef _OPENMP
#include <omp.h>
#endif

enum { HITL_AG_AUTO = 0, HITL_AG_FORWARD = 1, HITL_AG_DENSE = 2, HITL_AG_GMRES = 3 };

typedef int (*hitl_fn)(const casadi_real **, casadi_real **, casadi_int *, casadi_real *, int);
typedef int (*hitl_work_fn)(casadi_int *, casadi_int *, casadi_int *, casadi_int *);

/* One follower model's kernels (in generated/agent_kernels.py's KERNELS order) and their
   work sizes: pointers into its library (generated/agents.py) */
enum { AG_JET0, AG_RHS = 3, AG_JAC, AG_NFAC, AG_NSOL, AG_GMAT, AG_NKERNELS };
typedef struct {
  hitl_fn fn[AG_NKERNELS];
  hitl_work_fn work[AG_NKERNELS];
} hitl_agent_kernels;

/* The problem: sizes, kernels, per-agent data and the graph's topologies as CSR */
typedef struct {
  int N, m, na, n, npar, nmodels;
  const hitl_agent_kernels *kern; /* nmodels */
  const int *model;               /* N: kernel table of each follower */
  const double *prm;    /* N x npar, agent-major */
  int ntop;             /* segments (one topology each when links switch raw) */
  const double *t_switch; /* ntop - 1 start times of segments 1.. */
  const int *ptr;       /* ntop x (N + 1): CSR row pointers into idx (absolute) */
  const int *idx;       /* followers each one hears (a segment's: its topologies' union) */
  const double *w;      /* per active topology: (L + B)_ij on its segment's pattern */
  const double *cpl;    /* per active topology: N x 2 (l_ii, a_i0 h_i) */
  const int *order;     /* ntop x N: topological order (cycles broken), grouped by depth */
  const int *acyclic;   /* ntop flags (of the union pattern) */
  int solver;           /* HITL_AG_* */
  int nthreads;         /* <= 0: OpenMP's default */
  const int *koff;      /* N + 1: agent i's nonzeros of K at koff[i] .. koff[i+1] */
  const int *poff;      /* N + 1: agent i's packed factorisation P at poff[i] .. poff[i+1] */
  const int *lead_nz;   /* m x m (column-major): the leader block's nonzero in agent 0's
                           K, or -1 where it is structurally zero */
  const int *depth;     /* ntop x N: each follower's wave */
  const int *act_ptr;   /* ntop + 1: segment s's active topologies act_ptr[s] .. [s+1] */
  const int *act_top;   /* per active: its topology k of the graph (0 .. ngraph - 1) */
  const int *w_off;     /* per active: its weight of edge q at w[w_off[a] + q - ptr_s[0]] */
  int ngraph;           /* the graph's topologies */
  const double *t_graph; /* ngraph: their start times s_k (s_0 = 0) */
  double fade;          /* T (graph.link_fade): the links' fade time, 0 = raw */
} hitl_agents_problem;

/* One follower's sizes, compiled in (generated/agent_kernels.py; hitl_ag_init checks them)
   so that the small per-agent loops unroll. 0: read at run time. */
#ifndef HITL_AG_N_OUT
#define HITL_AG_N_OUT 0
#endif
#ifndef HITL_AG_N_STATE
#define HITL_AG_N_STATE 0
#endif
#ifndef HITL_AG_N_LEADER
#define HITL_AG_N_LEADER 0
#endif
#define AG_N(d) (HITL_AG_N_OUT ? HITL_AG_N_OUT : (d)->n)
#define AG_N3(d) (3 * AG_N(d))
#define AG_NA(d) (HITL_AG_N_STATE ? HITL_AG_N_STATE : (d)->na)
#define AG_M(d) (HITL_AG_N_LEADER ? HITL_AG_N_LEADER : (d)->m)

/* one thread's work arrays for the kernels and its agent's inputs */
typedef struct {
  const casadi_real **arg;
  casadi_real **res;
  casadi_int *iw;
  casadi_real *w;
  double *xb, *xbdot, *jscr, *col;
  casadi_real t; /* the kernels' time argument */
} hitl_agwork;

/* The graph's weights at one time on one segment's pattern: W(t) = sum_k c_k(t) W_k and
   its first two time derivatives (eq. (6)'s L + B and a0 h, faded) */
typedef struct {
  int seg, fade; /* segment (-1: none yet); fade: more than one topology active */
  double t;      /* the time they hold at */
  double *w[3];  /* w, w', w'' of edge q at [q - base] */
  int base;      /* the segment's ptr[0] */
  double *cpl;   /* N x 6: (l_ii, a_i0 h_i) and their first and second derivatives */
} hitl_ag_wts;

typedef struct {
  hitl_cvode s; /* CVODE, its messages and counters */
  const hitl_agents_problem *p;
  int N, m, na, n, n3, nthreads;
  double *jets, *nb; /* N x n3 */
  hitl_agwork *wk;           /* nthreads */
  /* linear solver */
  double *lu;    /* p->poff[N]: each agent's P (ag_nfac) at p->poff[i] */
  double *lul;   /* m x m: the leader's dense LU */
  int *piv;      /* m: the leader's row swaps */
  double *G;     /* N x n3 x n3 (column-major) */
  double *Hm;    /* N x na x n3 (column-major): -c D_i^{-1} B_s */
  double *ps;    /* N x n3: the level-by-level preconditioner's partial neighbour sums */
  double *zero;  /* n3 zeros: the neighbour sums of ag_nsol when only D_i^{-1} is wanted */
  double *y;     /* N x na */
  double *dj, *dnb, *rj; /* N x n3 */
  double *S;     /* dense jets system (n3 N)^2, HITL_AG_DENSE */
  int *Spiv;
  int ls_top, ls_mode;
  double *V, *H, *cs, *sn, *g, *z; /* GMRES */
  long *done, epoch; /* hitl_ag_sweep's flags: the last level each agent finished */
  double *mem;       /* the block every double array above is carved from */
  long n_krylov;
  hitl_ag_wts wr, wl; /* the weights of the right-hand side (at t) and of the Newton
                         systems (at the Jacobian's time t_jac) */
  const hitl_ag_wts *W; /* the ones in use: wr in a pass, wl in the linear solver */
  double t_jac;
} hitl_ag;

static int hitl_ag_threads(const hitl_ag *d) { return d->nthreads; }

/* the calling thread's kernel work arrays */
static hitl_agwork *hitl_ag_wk(hitl_ag *d) {
#ifdef _OPENMP
  return d->wk + omp_get_thread_num();
#else
  return d->wk;
#endif
}

/* kernel `which` of agent i's model on wk's arguments and results: 0, or non-zero */
static int hitl_ag_call(const hitl_ag *d, hitl_agwork *wk, int i, int which) {
  return d->p->kern[d->p->model[i]].fn[which](wk->arg, wk->res, wk->iw, wk->w, 0);
}

/* agent i's ag_nsol on its packed factorisation (b is copied first: x may be where b was) */
static int hitl_ag_nsol(hitl_ag *d, hitl_agwork *wk, int i, const double *x0,
                        const double *s, const double *b, double *x, double *dj) {
  memcpy(wk->xb, b, sizeof(double) * (size_t)AG_NA(d));
  wk->arg[0] = d->lu + d->p->poff[i];
  wk->arg[1] = x0;
  wk->arg[2] = s;
  wk->arg[3] = wk->xb;
  wk->res[0] = x;
  wk->res[1] = dj;
  return hitl_ag_call(d, wk, i, AG_NSOL);
}

static int hitl_ag_topology(const hitl_agents_problem *p, double t) {
  int top = 0;
  while (top < p->ntop - 1 && t >= p->t_switch[top]) top++;
  return top;
}

/* sigma_k of the graph's topology k at t and its two derivatives (the quintic C^2 fade
   of core/graph.py fade_jets; sigma_0 = 1, sigma_K = 0) */
static void hitl_ag_sigma(const hitl_agents_problem *p, int k, double t, double s[3]) {
  s[0] = k == 0 ? 1.0 : 0.0, s[1] = s[2] = 0.0;
  if (k <= 0 || k >= p->ngraph) return;
  double T = p->fade, x = (t - p->t_graph[k]) / T;
  x = x < 0.0 ? 0.0 : x > 1.0 ? 1.0 : x;
  s[0] = x * x * x * (10.0 - 15.0 * x + 6.0 * x * x);
  s[1] = 30.0 * x * x * (1.0 - x) * (1.0 - x) / T;
  s[2] = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x) / (T * T);
}

/* W = the weights on segment seg at t: W(t) = W_0 + sum_k sigma_k (W_k - W_{k-1}) =
   sum_k c_k W_k with c_k = sigma_k - sigma_{k+1}, over the segment's active topologies,
   and the rates W', W'' that eq. (6)'s oracle derivatives take (product rule) */
static void hitl_ag_weights(hitl_ag *d, hitl_ag_wts *W, int seg, double t) {
  const hitl_agents_problem *p = d->p;
  int N = d->N, a0 = p->act_ptr[seg], na = p->act_ptr[seg + 1] - a0;
  if (W->seg == seg && (na == 1 || W->t == t)) return; /* one topology: constant */
  const int *ptr = p->ptr + (size_t)seg * (N + 1);
  int base = ptr[0], nnz = ptr[N] - base;
  W->seg = seg, W->t = t, W->fade = na > 1, W->base = base;
  for (int l = 0; l < 3; ++l) memset(W->w[l], 0, sizeof(double) * (size_t)nnz);
  memset(W->cpl, 0, sizeof(double) * (size_t)N * 6);
  for (int a = a0; a < a0 + na; ++a) {
    double c[3] = {1.0, 0.0, 0.0};
    if (na > 1) {
      double s0[3], s1[3];
      hitl_ag_sigma(p, p->act_top[a], t, s0);
      hitl_ag_sigma(p, p->act_top[a] + 1, t, s1);
      for (int l = 0; l < 3; ++l) c[l] = s0[l] - s1[l];
    }
    const double *wa = p->w + p->w_off[a], *ca = p->cpl + (size_t)a * N * 2;
    for (int l = 0; l < 3; ++l) {
      if (c[l] == 0.0) continue;
      for (int q = 0; q < nnz; ++q) W->w[l][q] += c[l] * wa[q];
      for (int i = 0; i < N; ++i) {
        W->cpl[(size_t)6 * i + 2 * l] += c[l] * ca[2 * i];
        W->cpl[(size_t)6 * i + 2 * l + 1] += c[l] * ca[2 * i + 1];
      }
    }
  }
}

/* the level-l neighbour sum of edge q's jets zj added to s, with the weights in use
   (d->W): level l is the l-th derivative of sum_j w_ij C0 eta_j, so during a fade it takes
   the lower levels of zj with the weights' rates (eq. (6), product rule): nb_1 = sum w J_1
   + w' J_0, nb_2 = sum w J_2 + 2 w' J_1 + w'' J_0 */
static void hitl_ag_edge_level(const hitl_ag *d, int q, int l, const double *zj, double *s) {
  const hitl_ag_wts *W = d->W;
  int n = AG_N(d);
  double w = W->w[0][q - W->base];
  for (int r = l * n; r < (l + 1) * n; ++r) s[r] += w * zj[r];
  if (!W->fade || l == 0) return;
  double w1 = W->w[1][q - W->base], w2 = W->w[2][q - W->base];
  for (int r = 0; r < n; ++r)
    s[l * n + r] += (l == 1 ? w1 * zj[r] : 2.0 * w1 * zj[n + r] + w2 * zj[r]);
}

/* nb_i (levels lo..hi-1, n each) from the agents' jets J (N x n3) on segment top */
static void hitl_ag_gather(const hitl_ag *d, int top, int i, const double *J, double *nb,
                           int lo, int hi) {
  const int *ptr = d->p->ptr + (size_t)top * (d->N + 1);
  for (int r = lo * AG_N(d); r < hi * AG_N(d); ++r) nb[r] = 0.0;
  for (int q = ptr[i]; q < ptr[i + 1]; ++q)
    for (int l = lo; l < hi; ++l)
      hitl_ag_edge_level(d, q, l, J + (size_t)d->p->idx[q] * AG_N3(d), nb);
}

/* agent i's kernel inputs in work wk: xb = (eta0, s_i) */
static void hitl_ag_inputs(hitl_ag *d, hitl_agwork *wk, int i, const double *y, double t) {
  wk->t = t;
  memcpy(wk->xb, y, sizeof(double) * (size_t)AG_M(d));
  memcpy(wk->xb + AG_M(d), y + AG_M(d) + (size_t)AG_NA(d) * i,
         sizeof(double) * (size_t)AG_NA(d));
  wk->arg[0] = &wk->t;
  wk->arg[1] = wk->xb;
  wk->arg[2] = d->nb + (size_t)AG_N3(d) * i;
  wk->arg[3] = d->W->cpl + (size_t)6 * i; /* the weights in use, at the pass's t */
  wk->arg[4] = d->p->prm + (size_t)d->p->npar * i;
}

/* What one agent computes at one level of a sweep (hitl_ag_sweep): 0, or non-zero */
typedef int (*hitl_ag_step_fn)(hitl_ag *d, hitl_agwork *wk, int top, int i, int lev,
                               void *ctx);

#ifndef HITL_AG_SWEEP_CHUNK
#define HITL_AG_SWEEP_CHUNK 16 /* consecutive positions of the order one thread takes */
#endif
#ifndef HITL_AG_SWEEP_MIN
#define HITL_AG_SWEEP_MIN 64 /* fewer agents: one thread (a region costs more) */
#endif

/* wait until agent j's flag reaches need (acquire: what j wrote before is visible) */
static void hitl_ag_wait(const long *done, int j, long need) {
  while (__atomic_load_n(done + j, __ATOMIC_ACQUIRE) < need) {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
  }
}

/* One sweep over the agents of topology top, `levels` times, level-major, in its order
   (grouped by depth): agent i's level l reads its neighbours' level l where they are of
   lower depth and their level l - 1 otherwise. With threads, one OpenMP region in which
   the order is dealt out in chunks and each agent waits on its neighbours' flags
   (docs/performance.md, item Threads: why it cannot deadlock); nbrows (N x n3, or NULL):
   what a step reads of its neighbours, prefetched with their flags one item ahead.
   Returns 0 or -1. */
static int hitl_ag_sweep(hitl_ag *d, int top, int levels, hitl_ag_step_fn f, void *ctx,
                         const double *nbrows) {
  const hitl_agents_problem *p = d->p;
  const int *ord = p->order + (size_t)top * d->N;
  int N = d->N, fail = 0;
  if (hitl_ag_threads(d) <= 1 || N < HITL_AG_SWEEP_MIN) {
    for (int l = 0; l < levels; ++l)
      for (int oi = 0; oi < N; ++oi)
        if (f(d, d->wk, top, ord[oi], l, ctx)) fail = 1;
    return fail ? -1 : 0;
  }
#ifdef _OPENMP
  const int *ptr = p->ptr + (size_t)top * (N + 1);
  const int *dep = p->depth + (size_t)top * N;
  long ep = d->epoch, *done = d->done;
  d->epoch += levels;
#pragma omp parallel num_threads(hitl_ag_threads(d)) reduction(| : fail)
  {
    int nt = omp_get_num_threads(), th = omp_get_thread_num();
    hitl_agwork *wk = d->wk + th;
    for (int l = 0; l < levels; ++l)
      for (int c0 = th * HITL_AG_SWEEP_CHUNK; c0 < N; c0 += nt * HITL_AG_SWEEP_CHUNK)
        for (int oi = c0; oi < c0 + HITL_AG_SWEEP_CHUNK && oi < N; ++oi) {
          int i = ord[oi];
          { /* the next item's neighbours: their flags and rows, written by other threads */
            int on = oi + 1 < c0 + HITL_AG_SWEEP_CHUNK ? oi + 1 : c0 + nt * HITL_AG_SWEEP_CHUNK;
            if (on < N) {
              int inx = ord[on];
              for (int q = ptr[inx]; q < ptr[inx + 1]; ++q) {
                __builtin_prefetch(done + p->idx[q]);
                if (nbrows) __builtin_prefetch(nbrows + (size_t)AG_N3(d) * p->idx[q]);
              }
            }
          }
          for (int q = ptr[i]; q < ptr[i + 1]; ++q) {
            int j = p->idx[q];
            hitl_ag_wait(done, j, ep + l + (dep[j] < dep[i]));
          }
          if (f(d, wk, top, i, l, ctx)) fail |= 1;
          __atomic_store_n(done + i, ep + l + 1, __ATOMIC_RELEASE); /* also on failure */
        }
  }
#endif
  return fail ? -1 : 0;
}

typedef struct {
  double t;
  const double *y;
  double *ydot, *K;
} hitl_ag_at;

/* agent i's rates into ydot or its Jacobian block into K (the other NULL), its jets into
   jets (its inputs set by hitl_ag_inputs); 0, or non-zero */
static int hitl_ag_eval(hitl_ag *d, hitl_agwork *wk, int i, double *jets, double *ydot,
                        double *K) {
  if (K) {
    wk->res[0] = jets;
    wk->res[1] = K + d->p->koff[i];
    return hitl_ag_call(d, wk, i, AG_JAC);
  }
  wk->res[0] = wk->xbdot;
  wk->res[1] = jets;
  if (hitl_ag_call(d, wk, i, AG_RHS)) return 1;
  if (i == 0) memcpy(ydot, wk->xbdot, sizeof(double) * (size_t)AG_M(d));
  memcpy(ydot + AG_M(d) + (size_t)AG_NA(d) * i, wk->xbdot + AG_M(d),
         sizeof(double) * (size_t)AG_NA(d));
  return 0;
}

/* agent i of the one-pass sweep of an acyclic topology: its neighbour sums (complete),
   then its rates or its Jacobian block, which give its jets too */
static int hitl_ag_wave_step(hitl_ag *d, hitl_agwork *wk, int top, int i, int lev,
                             void *ctx) {
  const hitl_ag_at *a = (const hitl_ag_at *)ctx;
  double *jets = d->jets + (size_t)AG_N3(d) * i;
  (void)lev;
  hitl_ag_gather(d, top, i, d->jets, d->nb + (size_t)AG_N3(d) * i, 0, 3);
  hitl_ag_inputs(d, wk, i, a->y, a->t);
  return hitl_ag_eval(d, wk, i, jets, a->ydot, a->K);
}

/* The passes at (t, y): jets and neighbour sums of every level, then ydot or the Jacobian
   blocks K (at p->koff; the other NULL). Returns 0 or -1. */
static int hitl_ag_pass(hitl_ag *d, double t, const double *y, double *ydot, double *K,
                        int *top_out) {
  const hitl_agents_problem *p = d->p;
  int N = d->N, n3 = AG_N3(d), fail = 0;
  int top = hitl_ag_topology(p, t);
  if (top_out) *top_out = top;
  hitl_ag_weights(d, &d->wr, top, t);
  d->W = &d->wr;
  if (p->acyclic[top]) { /* one sweep along its order */
    hitl_ag_at a = {t, y, ydot, K};
    return hitl_ag_sweep(d, top, 1, hitl_ag_wave_step, &a, d->jets);
  }
  memset(d->nb, 0, sizeof(double) * (size_t)N * n3);
  for (int lev = 0;; ++lev) { /* the jets level by level, then the rates or K */
#pragma omp parallel for schedule(static) num_threads(hitl_ag_threads(d)) if(hitl_ag_threads(d) > 1) reduction(| : fail)
    for (int i = 0; i < N; ++i) {
      hitl_agwork *wk = hitl_ag_wk(d);
      hitl_ag_inputs(d, wk, i, y, t);
      if (lev == 3) {
        if (hitl_ag_eval(d, wk, i, wk->jscr, ydot, K)) fail |= 1;
        continue;
      }
      wk->res[0] = d->jets + (size_t)n3 * i + (size_t)lev * AG_N(d);
      if (hitl_ag_call(d, wk, i, AG_JET0 + lev)) fail |= 1;
    }
    if (fail || lev == 3) return fail ? -1 : 0;
#pragma omp parallel for schedule(static) num_threads(hitl_ag_threads(d)) if(hitl_ag_threads(d) > 1)
    for (int i = 0; i < N; ++i)
      hitl_ag_gather(d, top, i, d->jets, d->nb + (size_t)n3 * i, lev, lev + 1);
  }
}

static int hitl_ag_rhs(sunrealtype t, N_Vector y, N_Vector ydot, void *data) {
  hitl_ag *d = (hitl_ag *)data;
  casadi_real *out = N_VGetArrayPointer(ydot);
  if (hitl_ag_pass(d, t, N_VGetArrayPointer(y), out, NULL, NULL)) return -1;
  for (int i = 0; i < d->s.nx; ++i)
    if (!isfinite(out[i])) return 1; /* recoverable: CVODE retries with a smaller step */
  return 0;
}

static int hitl_ag_jac(sunrealtype t, N_Vector y, N_Vector fy, SUNMatrix J, void *data,
                       N_Vector t1, N_Vector t2, N_Vector t3) {
  hitl_ag *d = (hitl_ag *)data;
  hitl_kmat *M = HITL_KMAT(J);
  (void)fy; (void)t1; (void)t2; (void)t3;
  hitl_kmat_zero(J);
  d->t_jac = t; /* the Newton systems couple the agents with the weights at t */
  return hitl_ag_pass(d, t, N_VGetArrayPointer(y), NULL, M->K, &M->top) ? -1 : 0;
}

/* ---------------------------------------------------------------- small dense algebra */
/* LU with partial pivoting of the n x n column-major a (in place); 0, or -1 if singular */
static int hitl_lu(double *a, int n, int *piv) {
  for (int j = 0; j < n; ++j) {
    int pr = j;
    double best = fabs(a[(size_t)j * n + j]);
    for (int r = j + 1; r < n; ++r) {
      double v = fabs(a[(size_t)j * n + r]);
      if (v > best) best = v, pr = r;
    }
    piv[j] = pr;
    if (!(best > 0.0) || !isfinite(best)) return -1;
    if (pr != j)
      for (int col = 0; col < n; ++col) {
        double tmp = a[(size_t)col * n + j];
        a[(size_t)col * n + j] = a[(size_t)col * n + pr];
        a[(size_t)col * n + pr] = tmp;
      }
    double inv = 1.0 / a[(size_t)j * n + j];
    for (int r = j + 1; r < n; ++r) a[(size_t)j * n + r] *= inv;
    for (int col = j + 1; col < n; ++col) {
      double f = a[(size_t)col * n + j];
      if (f != 0.0)
        for (int r = j + 1; r < n; ++r) a[(size_t)col * n + r] -= f * a[(size_t)j * n + r];
    }
  }
  return 0;
}

/* solve (LU) x = b in place with hitl_lu's factors */
static void hitl_lu_solve(const double *a, int n, const int *piv, double *b) {
  for (int j = 0; j < n; ++j) /* the row swaps (whole rows, as LAPACK's getrf), then L */
    if (piv[j] != j) {
      double tmp = b[j];
      b[j] = b[piv[j]];
      b[piv[j]] = tmp;
    }
  for (int j = 0; j < n; ++j)
    for (int r = j + 1; r < n; ++r) b[r] -= a[(size_t)j * n + r] * b[j];
  for (int j = n - 1; j >= 0; --j) {
    b[j] /= a[(size_t)j * n + j];
    for (int r = 0; r < j; ++r) b[r] -= a[(size_t)j * n + r] * b[j];
  }
}

/* ---------------------------------------------------------------- linear solver */
/* the solver of the jets system on topology top (HITL_AG_AUTO resolved) */
static int hitl_ag_mode(const hitl_ag *d, int top) {
  int s = d->p->solver;
  if (s == HITL_AG_AUTO) return d->p->acyclic[top] ? HITL_AG_FORWARD : HITL_AG_GMRES;
  return s;
}

/* out_i = u_i + sign G_i sum_j w_ij v_j: the jets system's product (sign -1, u = v) or a
   step of its forward substitution (sign +1) */
static void hitl_ag_gs(const hitl_ag *d, int top, int i, const double *v, const double *u,
                       double *out, double sign) {
  int n3 = AG_N3(d);
  double s[64];
  const double *G = d->G + (size_t)n3 * n3 * i;
  hitl_ag_gather(d, top, i, v, s, 0, 3);
  for (int r = 0; r < n3; ++r) {
    double acc = u[(size_t)n3 * i + r];
    for (int q = 0; q < n3; ++q) acc += sign * G[(size_t)q * n3 + r] * s[q];
    out[(size_t)n3 * i + r] = acc;
  }
}

/* y = A_jets v: (A v)_i = v_i - G_i sum_j w_ij v_j */
static void hitl_ag_apply(hitl_ag *d, int top, const double *v, double *out) {
#pragma omp parallel for schedule(static) num_threads(hitl_ag_threads(d)) if(hitl_ag_threads(d) > 1)
  for (int i = 0; i < d->N; ++i) hitl_ag_gs(d, top, i, v, v, out, -1.0);
}

/* agent i of P^{-1} u on an acyclic topology: z_i = u_i + G_i sum_j w_ij z_j */
typedef struct {
  const double *u;
  double *z;
} hitl_ag_uz;

static int hitl_ag_forward_step(hitl_ag *d, hitl_agwork *wk, int top, int i, int lev,
                                void *ctx) {
  const hitl_ag_uz *a = (const hitl_ag_uz *)ctx;
  (void)wk, (void)lev;
  hitl_ag_gs(d, top, i, a->z, a->u, a->z, 1.0);
  return 0;
}

/* agent i's level l of the level-by-level preconditioner: its partial neighbour sums
   ps_i gain level l from the neighbours of lower depth and level l - 1 from the others
   (which sweep l - 1 had not reached), then z_i's level-l rows from levels <= l */
static int hitl_ag_levels_step(hitl_ag *d, hitl_agwork *wk, int top, int i, int l,
                               void *ctx) {
  const hitl_agents_problem *p = d->p;
  const hitl_ag_uz *a = (const hitl_ag_uz *)ctx;
  const int *ptr = p->ptr + (size_t)top * (d->N + 1);
  const int *dep = p->depth + (size_t)top * d->N;
  int n = AG_N(d), n3 = AG_N3(d), lo = l * n, hi = lo + n;
  double *s = d->ps + (size_t)n3 * i; /* levels < l - 1 complete from earlier sweeps */
  const double *G = d->G + (size_t)n3 * n3 * i;
  (void)wk;
  for (int r = lo; r < hi; ++r) s[r] = 0.0;
  for (int q = ptr[i]; q < ptr[i + 1]; ++q) {
    int j = p->idx[q];
    const double *zj = a->z + (size_t)n3 * j;
    if (dep[j] < dep[i])
      hitl_ag_edge_level(d, q, l, zj, s);
    else if (l > 0)
      hitl_ag_edge_level(d, q, l - 1, zj, s);
  }
  for (int r = lo; r < hi; ++r) {
    double acc = a->u[(size_t)n3 * i + r];
    for (int q = 0; q < hi; ++q) acc += G[(size_t)q * n3 + r] * s[q];
    a->z[(size_t)n3 * i + r] = acc;
  }
  return 0;
}

static double hitl_dot(const double *a, const double *b, long n) {
  double s = 0.0;
  for (long i = 0; i < n; ++i) s += a[i] * b[i];
  return s;
}

/* GMRES's preconditioner z = P^{-1} u: on an acyclic topology forward substitution along
   its order (exact); on a cycle level by level, which drops only couplings of G_i's
   -c C_s D_i^{-1} B_s part, vanishing with the step (docs/performance.md) */
static void hitl_ag_precond(hitl_ag *d, int top, const double *u, double *z) {
  hitl_ag_uz a = {u, z};
  if (d->p->acyclic[top]) hitl_ag_sweep(d, top, 1, hitl_ag_forward_step, &a, z);
  else hitl_ag_sweep(d, top, 3, hitl_ag_levels_step, &a, z);
}

#define HITL_GMRES_KRYLOV 30    /* restart length */
#define HITL_GMRES_TOL 1e-14     /* relative residual reached at every solve */
#define HITL_GMRES_FLOOR 1e-10   /* ... or this, where a restart no longer halves it */
#define HITL_GMRES_MAX_ITER 300  /* iterations per solve before it fails (CVODE retries) */

/* Restarted right-preconditioned GMRES on the jets system: x from rhs (x: initial guess
   0). Returns 0, or -1 if the residual did not reach HITL_GMRES_TOL * |rhs| (or
   stagnated above HITL_GMRES_FLOOR * |rhs|) in HITL_GMRES_MAX_ITER. */
static int hitl_ag_gmres(hitl_ag *d, int top, const double *rhs, double *x) {
  long n = (long)d->N * AG_N3(d);
  int kr = HITL_GMRES_KRYLOV, it = 0;
  double beta0 = sqrt(hitl_dot(rhs, rhs, n)), tol = HITL_GMRES_TOL * beta0;
  double *V = d->V, *H = d->H, *z = d->z;
  memset(x, 0, sizeof(double) * (size_t)n);
  if (beta0 == 0.0) return 0;
  double *r = d->rj; /* residual */
  memcpy(r, rhs, sizeof(double) * (size_t)n);
  double beta_prev = HUGE_VAL;
  while (it < HITL_GMRES_MAX_ITER) {
    double beta = sqrt(hitl_dot(r, r, n));
    if (beta <= tol) return 0;
    /* a restart that no longer halves the true residual has reached rounding: accept it
       where that is within HITL_GMRES_FLOOR of the right-hand side */
    if (beta > 0.5 * beta_prev && beta <= HITL_GMRES_FLOOR * beta0) return 0;
    beta_prev = beta;
    for (long q = 0; q < n; ++q) V[q] = r[q] / beta;
    for (int q = 0; q <= kr; ++q) d->g[q] = 0.0;
    d->g[0] = beta;
    int j = 0;
    for (; j < kr && it < HITL_GMRES_MAX_ITER; ++j, ++it) {
      double *vj = V + (size_t)n * j, *w = V + (size_t)n * (j + 1);
      hitl_ag_precond(d, top, vj, z);
      hitl_ag_apply(d, top, z, w);
      for (int q = 0; q <= j; ++q) { /* modified Gram-Schmidt */
        double h = hitl_dot(w, V + (size_t)n * q, n);
        H[(size_t)j * (kr + 1) + q] = h;
        for (long e = 0; e < n; ++e) w[e] -= h * V[(size_t)n * q + e];
      }
      double hn = sqrt(hitl_dot(w, w, n));
      H[(size_t)j * (kr + 1) + j + 1] = hn;
      if (hn > 0.0)
        for (long e = 0; e < n; ++e) w[e] /= hn;
      double *hc = H + (size_t)j * (kr + 1);
      for (int q = 0; q < j; ++q) { /* earlier rotations */
        double a = hc[q], b = hc[q + 1];
        hc[q] = d->cs[q] * a + d->sn[q] * b;
        hc[q + 1] = -d->sn[q] * a + d->cs[q] * b;
      }
      double den = hypot(hc[j], hc[j + 1]);
      d->cs[j] = den > 0 ? hc[j] / den : 1.0;
      d->sn[j] = den > 0 ? hc[j + 1] / den : 0.0;
      hc[j] = den;
      hc[j + 1] = 0.0;
      d->g[j + 1] = -d->sn[j] * d->g[j];
      d->g[j] = d->cs[j] * d->g[j];
      d->n_krylov++;
      if (fabs(d->g[j + 1]) <= tol) {
        ++j, ++it;
        break;
      }
    }
    /* y = H^{-1} g (upper triangular j x j), x += P^{-1} V y */
    for (int q = j - 1; q >= 0; --q) {
      double acc = d->g[q];
      for (int e = q + 1; e < j; ++e) acc -= H[(size_t)e * (kr + 1) + q] * d->g[e];
      d->g[q] = acc / H[(size_t)q * (kr + 1) + q];
    }
    memset(r, 0, sizeof(double) * (size_t)n);
    for (int q = 0; q < j; ++q)
      for (long e = 0; e < n; ++e) r[e] += d->g[q] * V[(size_t)n * q + e];
    hitl_ag_precond(d, top, r, z);
    for (long e = 0; e < n; ++e) x[e] += z[e];
    /* true residual */
    hitl_ag_apply(d, top, x, r);
    for (long e = 0; e < n; ++e) r[e] = rhs[e] - r[e];
  }
  return sqrt(hitl_dot(r, r, n)) <= tol ? 0 : -1;
}

/* agent i of the forward substitution through the states: D_i x_i = b_i - c (A_s0 x_0 +
   B_s dnb_i), then dj_i = C_0 x_0 + C_s x_i + E dnb_i (x holds b on entry, the leader
   solved) */
static int hitl_ag_forward_x_step(hitl_ag *d, hitl_agwork *wk, int top, int i, int lev,
                                  void *ctx) {
  double *x = (double *)ctx, s[64];
  double *xi = x + AG_M(d) + (size_t)AG_NA(d) * i;
  (void)lev;
  hitl_ag_gather(d, top, i, d->dj, s, 0, 3);
  return hitl_ag_nsol(d, wk, i, x, s, xi, xi, d->dj + (size_t)AG_N3(d) * i);
}

/* Set-up of M = I + c J: the leader's block factorised (dense, pivoting), every agent's
   D_i by its model's ag_nfac (pivots below HITL_PIVOT_MIN fail the set-up) and,
   unless the solve substitutes through the states, G_i by ag_gmat; HITL_AG_DENSE also
   factorises the jets system. */
static int hitl_ag_ls_setup(SUNLinearSolver S, SUNMatrix A) {
  hitl_ag *d = (hitl_ag *)S->content;
  hitl_kmat *M = HITL_KMAT(A);
  int m = AG_M(d), na = AG_NA(d), n3 = AG_N3(d), N = d->N, fail = 0;
  double c = M->c;
  if (!M->shifted) return -1; /* CVODE always hands over I - gamma J */
  d->s.n_fac++;
  hitl_ag_weights(d, &d->wl, M->top, d->t_jac);
  d->W = &d->wl;
  d->ls_top = M->top;
  d->ls_mode = hitl_ag_mode(d, M->top);
  { /* the leader: rows and columns 0..m-1 of agent 0's block */
    double *L = d->lul;
    for (int col = 0; col < m; ++col)
      for (int row = 0; row < m; ++row) {
        int nz = d->p->lead_nz[(size_t)col * m + row];
        L[(size_t)col * m + row] = (nz >= 0 ? c * M->K[nz] : 0.0) + (row == col ? 1.0 : 0.0);
      }
    if (hitl_lu(L, m, d->piv)) fail = 1;
  }
#pragma omp parallel for schedule(static) num_threads(hitl_ag_threads(d)) if(hitl_ag_threads(d) > 1) reduction(| : fail)
  for (int i = 0; i < N; ++i) {
    hitl_agwork *wk = hitl_ag_wk(d);
    const double *K = M->K + d->p->koff[i];
    double *P = d->lu + d->p->poff[i];
    wk->arg[0] = &c;
    wk->arg[1] = K;
    wk->res[0] = P;
    wk->res[1] = wk->col; /* the pivots */
    if (hitl_ag_call(d, wk, i, AG_NFAC)) fail |= 1;
    for (int r = 0; r < na; ++r)
      if (!(fabs(wk->col[r]) > HITL_PIVOT_MIN)) fail |= 1; /* also catches NaN */
    /* after a failure the set-up fails; FORWARD: the solve substitutes through x */
    if (fail || d->ls_mode == HITL_AG_FORWARD) continue;
    wk->arg[0] = P;
    wk->res[0] = d->G + (size_t)n3 * n3 * i;
    wk->res[1] = d->Hm + (size_t)na * n3 * i;
    if (hitl_ag_call(d, wk, i, AG_GMAT)) fail |= 1;
  }
  if (fail) {
    d->s.n_piv_fail++;
    return SUNLS_LUFACT_FAIL; /* recoverable: CVODE retries with a smaller step */
  }
  if (d->ls_mode == HITL_AG_FORWARD && !d->p->acyclic[M->top]) return -1; /* forward substitution on a cycle: unrecoverable */
  if (d->ls_mode == HITL_AG_DENSE) {
    long nj = (long)N * n3;
    const int *ptr = d->p->ptr + (size_t)M->top * (N + 1);
    memset(d->S, 0, sizeof(double) * (size_t)nj * nj);
    for (long e = 0; e < nj; ++e) d->S[(size_t)e * nj + e] = 1.0;
    const hitl_ag_wts *W = d->W;
    int n = AG_N(d);
    for (int i = 0; i < N; ++i) {
      const double *G = d->G + (size_t)n3 * n3 * i;
      for (int q = ptr[i]; q < ptr[i + 1]; ++q) {
        int j = d->p->idx[q];
        double wq[3] = {W->w[0][q - W->base], 0.0, 0.0};
        if (W->fade) wq[1] = W->w[1][q - W->base], wq[2] = W->w[2][q - W->base];
        /* dnb_i's level a takes dj_j's level b <= a with binom(a, b) w^(a-b) */
        for (int b = 0; b < 3; ++b)
          for (int lv = b; lv < 3; ++lv) {
            double f = (lv - b == 1 && lv == 2 ? 2.0 : 1.0) * wq[lv - b];
            if (f == 0.0) continue;
            for (int r = 0; r < n; ++r)
              for (int row = 0; row < n3; ++row)
                d->S[(size_t)(n3 * j + b * n + r) * nj + n3 * i + row] -=
                    f * G[(size_t)(lv * n + r) * n3 + row];
          }
      }
    }
    if (hitl_lu(d->S, (int)nj, d->Spiv)) {
      d->s.n_piv_fail++;
      return SUNLS_LUFACT_FAIL;
    }
  }
  return 0;
}

/* x = M^{-1} b */
static int hitl_ag_ls_solve(SUNLinearSolver S, SUNMatrix A, N_Vector xv, N_Vector bv,
                            sunrealtype tol) {
  hitl_ag *d = (hitl_ag *)S->content;
  int m = AG_M(d), na = AG_NA(d), n3 = AG_N3(d), N = d->N, top = d->ls_top;
  double *x = N_VGetArrayPointer(xv);
  const double *b = N_VGetArrayPointer(bv);
  (void)A, (void)tol; /* the factorisations of the set-up are all a solve reads */
  d->W = &d->wl;
  if (x != b) memcpy(x, b, sizeof(double) * (size_t)d->s.nx);
  hitl_lu_solve(d->lul, m, d->piv, x); /* leader */
  if (d->ls_mode == HITL_AG_FORWARD) /* along the order of an acyclic topology */
    return hitl_ag_sweep(d, top, 1, hitl_ag_forward_x_step, x, d->dj);
  /* y_i = D_i^{-1} (b_i - c A_s0 x_0), r_i = C_0 x_0 + C_s y_i: ag_nsol with s = 0 */
  int fail = 0;
#pragma omp parallel for schedule(static) num_threads(hitl_ag_threads(d)) if(hitl_ag_threads(d) > 1) reduction(| : fail)
  for (int i = 0; i < N; ++i)
    if (hitl_ag_nsol(d, hitl_ag_wk(d), i, x, d->zero, x + m + (size_t)na * i,
                     d->y + (size_t)na * i, d->rj + (size_t)n3 * i))
      fail |= 1;
  if (fail) return -1;
  if (d->ls_mode == HITL_AG_DENSE) {
    memcpy(d->dj, d->rj, sizeof(double) * (size_t)N * n3);
    hitl_lu_solve(d->S, N * n3, d->Spiv, d->dj);
  } else {
    double *rhs = d->dnb; /* the GMRES residual uses rj: keep the right-hand side apart */
    memcpy(rhs, d->rj, sizeof(double) * (size_t)N * n3);
    if (hitl_ag_gmres(d, top, rhs, d->dj)) return SUNLS_CONV_FAIL; /* recoverable */
  }
  /* x_i = D_i^{-1} (b_i - c (A_s0 x_0 + B_s dnb_i)) = y_i + H_i dnb_i */
#pragma omp parallel for schedule(static) num_threads(hitl_ag_threads(d)) if(hitl_ag_threads(d) > 1)
  for (int i = 0; i < N; ++i) {
    double s[64];
    const double *Hi = d->Hm + (size_t)na * n3 * i, *yi = d->y + (size_t)na * i;
    double *xi = x + m + (size_t)na * i;
    hitl_ag_gather(d, top, i, d->dj, s, 0, 3);
    for (int r = 0; r < na; ++r) xi[r] = yi[r];
    for (int q = 0; q < n3; ++q)
      for (int r = 0; r < na; ++r) xi[r] += Hi[(size_t)q * na + r] * s[q];
  }
  return 0;
}

/* ---------------------------------------------------------------- set-up */
/* each thread's work arrays; w (CasADi's) is followed by xb, xbdot (m + na), jscr (3n + 1)
   and col (m + na + 3n + 1) */
static int hitl_ag_work_alloc(hitl_ag *d, const casadi_int *sz) {
  size_t nw = (size_t)sz[3] + 1, nb = (size_t)(d->m + d->na), n3 = (size_t)d->n3 + 1;
  d->wk = (hitl_agwork *)calloc((size_t)d->nthreads, sizeof(hitl_agwork));
  if (!d->wk) return -1;
  for (int q = 0; q < d->nthreads; ++q) {
    hitl_agwork *wk = d->wk + q;
    wk->arg = (const casadi_real **)calloc((size_t)sz[0] + 1, sizeof(casadi_real *));
    wk->res = (casadi_real **)calloc((size_t)sz[1] + 1, sizeof(casadi_real *));
    wk->iw = (casadi_int *)calloc((size_t)sz[2] + 1, sizeof(casadi_int));
    wk->w = (casadi_real *)calloc(nw + 3 * nb + 2 * n3, sizeof(casadi_real));
    if (!wk->arg || !wk->res || !wk->iw || !wk->w) return -1;
    wk->xb = wk->w + nw, wk->xbdot = wk->xb + nb, wk->jscr = wk->xbdot + nb;
    wk->col = wk->jscr + n3;
  }
  return 0;
}

static int hitl_ag_init(hitl_ag *d, const hitl_agents_problem *p, char *msg, int msglen,
                        const char *log_path) {
  hitl_cvode *s = &d->s;
  casadi_int sz[4] = {0, 0, 0, 0};
  int N = p->N, m = p->m, na = p->na, n = p->n;
  int nx = m + N * na;
  long nj = (long)N * 3 * n;
  memset(d, 0, sizeof *d);
  s->msg = msg;
  s->msglen = msglen;
  if (msglen > 0) msg[0] = '\0';
  d->p = p;
  d->N = N, d->m = m, d->na = na, d->n = n, d->n3 = 3 * n;
#ifdef _OPENMP
  d->nthreads = p->nthreads > 0 ? p->nthreads : omp_get_max_threads();
#else
  d->nthreads = 1;
#endif
  if ((HITL_AG_N_OUT && n != HITL_AG_N_OUT) || (HITL_AG_N_STATE && na != HITL_AG_N_STATE) ||
      (HITL_AG_N_LEADER && m != HITL_AG_N_LEADER)) {
    hitl_msg(s, "the problem's sizes (m, na, n) differ from those the driver was compiled for");
    return -1;
  }
  if (d->n3 > 64) {
    hitl_msg(s, "more than 21 output coordinates per follower");
    return -1;
  }
  if (p->solver == HITL_AG_DENSE && nj > 6000) {
    hitl_msg(s, "the dense jets solver is for 3nN <= 6000 (use gmres)");
    return -1;
  }
  for (int q = 0; q < p->nmodels; ++q)
    for (int f = 0; f < AG_NKERNELS; ++f) hitl_work_size(p->kern[q].work[f], sz);
  s->nx = nx;
  int maxnnz = 0, kr = HITL_GMRES_KRYLOV;
  for (int sg = 0; sg < p->ntop; ++sg) {
    int nz = p->ptr[(size_t)sg * (N + 1) + N] - p->ptr[(size_t)sg * (N + 1)];
    if (nz > maxnnz) maxnnz = nz;
  }
  struct {
    double **a;
    size_t n;
  } arr[] = {
      {&d->jets, nj}, {&d->nb, nj}, {&d->dj, nj}, {&d->dnb, nj}, {&d->rj, nj}, {&d->z, nj},
      {&d->ps, nj}, {&d->lu, p->poff[N]}, {&d->lul, m * m}, {&d->zero, d->n3},
      {&d->G, nj * d->n3}, {&d->Hm, (size_t)N * na * d->n3}, {&d->y, (size_t)N * na},
      {&d->V, nj * (kr + 1)}, {&d->H, (kr + 1) * (kr + 1)}, {&d->cs, kr}, {&d->sn, kr},
      {&d->g, kr + 1}, {&d->S, p->solver == HITL_AG_DENSE ? nj * nj : 0},
      {&d->wr.w[0], maxnnz}, {&d->wr.w[1], maxnnz}, {&d->wr.w[2], maxnnz},
      {&d->wl.w[0], maxnnz}, {&d->wl.w[1], maxnnz}, {&d->wl.w[2], maxnnz},
      {&d->wr.cpl, N * 6}, {&d->wl.cpl, N * 6}, {&s->K, p->koff[N]}};
  size_t total = 0, narr = sizeof arr / sizeof arr[0];
  for (size_t q = 0; q < narr; ++q) total += arr[q].n + 1;
  d->mem = (double *)calloc(total, sizeof(double));
  for (size_t q = 0, off = 0; d->mem && q < narr; ++q) {
    *arr[q].a = d->mem + off;
    off += arr[q].n + 1;
  }
  d->wr.seg = d->wl.seg = -1;
  d->W = &d->wr;
  d->piv = (int *)calloc((size_t)m + 1, sizeof(int));
  d->Spiv = (int *)calloc((size_t)nj + 1, sizeof(int));
  d->done = (long *)calloc((size_t)N + 1, sizeof(long));
  if (!d->mem || !d->piv || !d->Spiv || !d->done || hitl_ag_work_alloc(d, sz)) {
    hitl_msg(s, "out of memory");
    return -1;
  }
  if (hitl_sundials_create(s, log_path)) return -1;
  s->A = hitl_kmat_new(s->K, s->ctx);
  if (!s->A) {
    hitl_msg(s, "out of memory");
    return -1;
  }
  s->LS->content = d; /* the driver's linear solver: direct, custom, freed empty */
  s->LS->ops->gettype = hitl_ls_type;
  s->LS->ops->setup = hitl_ag_ls_setup;
  s->LS->ops->solve = hitl_ag_ls_solve;
  s->LS->ops->free = hitl_ls_free;
  return 0;
}

static void hitl_ag_free(hitl_ag *d) {
  for (int q = 0; d->wk && q < d->nthreads; ++q)
    free(d->wk[q].arg), free(d->wk[q].res), free(d->wk[q].iw), free(d->wk[q].w);
  hitl_cvode_free(&d->s);
  free(d->wk), free(d->mem), free(d->piv), free(d->Spiv), free(d->done);
}

/* 1 if compiled with OpenMP (threads over the agents), else 0 */
CASADI_SYMBOL_EXPORT int hitl_agents_openmp(void) {
#ifdef _OPENMP
  return 1;
#else
  return 0;
#endif
}

CASADI_SYMBOL_EXPORT long hitl_agents_problem_size(void) {
  return (long)sizeof(hitl_agents_problem);
}

/*
 * Integrate the closed loop (nx = m + N*na) from x0 at o->t_out[0] (hitl_native.h's
 * options and result). krylov_iters: GMRES iterations (or NULL).
 * Returns r->filled, or -1 if CVODE could not be set up.
 */
CASADI_SYMBOL_EXPORT int hitl_agents_run(const hitl_agents_problem *p, const double *x0,
                                         const hitl_options *o, hitl_result *r,
                                         long *krylov_iters) {
  hitl_ag d;
  int ok, filled;
  hitl_result_start(r);
  ok = hitl_ag_init(&d, p, r->msg, HITL_MSG_LEN, o->log_path) == 0;
  filled = hitl_cvode_run(&d.s, ok, &d, hitl_ag_rhs, hitl_ag_jac, x0, o, r);
  if (krylov_iters) *krylov_iters = d.n_krylov;
  hitl_ag_free(&d);
  return filled;
}

/*
 * For tests: at (t, x), the right-hand side (xdot) and the solution of
 * (I - gamma J) sol = b, exactly as a run evaluates and solves them. Returns 0, or -1
 * with msg set.
 */
CASADI_SYMBOL_EXPORT int hitl_agents_probe(const hitl_agents_problem *p, double t,
                                           const double *x, double gamma, const double *b,
                                           double *xdot, double *sol, char *msg, int msglen) {
  hitl_ag d;
  hitl_cvode *s = &d.s;
  int nx = p->m + p->N * p->na, ret = -1;
  N_Vector bv = NULL, xv = NULL;
  if (hitl_ag_init(&d, p, msg, msglen, NULL)) goto done;
  bv = N_VNew_Serial(nx, s->ctx);
  xv = N_VNew_Serial(nx, s->ctx);
  if (!bv || !xv) goto done;
  memcpy(N_VGetArrayPointer(s->y), x, (size_t)nx * sizeof(double));
  memcpy(N_VGetArrayPointer(bv), b, (size_t)nx * sizeof(double));
  if (hitl_ag_pass(&d, t, x, xdot, NULL, NULL)) goto done;
  if (hitl_ag_jac(t, s->y, NULL, s->A, &d, NULL, NULL, NULL)) goto done;
  if (SUNMatScaleAddI(-gamma, s->A) || hitl_ag_ls_setup(s->LS, s->A) ||
      hitl_ag_ls_solve(s->LS, s->A, xv, bv, 0.0)) {
    hitl_msg(s, "linear solve failed");
    goto done;
  }
  memcpy(sol, N_VGetArrayPointer(xv), (size_t)nx * sizeof(double));
  ret = 0;

done:
  if (bv) N_VDestroy(bv);
  if (xv) N_VDestroy(xv);
  hitl_ag_free(&d);
  return ret;
}
