/*
 * aiofl_controller.h
 *
 * identified-ladrc: LADRC controller, sampled, by aiofl 0.1.0.
 *
 * ESO linear, differentiator linear, state error feedback linear; rho = 2, n_feedback = 2, arithmetic: double.
 *
 * Parameters (aiofl column names, as in the TOML config):
 *   law.b0 = 49.99843033265063
 *   law.u_max = inf
 *   law.u_min = -inf
 *   eso.omega0 = 132.6326822349046
 *   eso.alpha1 = 3.0
 *   eso.alpha2 = 3.0
 *   eso.alpha3 = 1.0
 *   td.omega = 33.15817055872615
 *   sef.omega_c = 33.15817055872615
 *
 * Discretisation:
 *   sample time Ts = 0.001 s, computation delay 0 sample(s)
 *   ESO: exact ZOH discretisation, current-observer form (Miklosovic, Radke & Gao 2006), poles z = exp(s_i Ts)
 *   TD: linear prefilter, exact ZOH discretisation
 *   SEF, law and saturation: the continuous formulas at each sample
 *   quantisation: y_quantum = 0.00153398, u_quantum = 0
 *
 * Config: id/first.toml
 * first LADRC from the log: rho 2, b0 50, omega0 132.6, omega_c 33.16
 *
 * Use: aiofl_init(&s, &aiofl_default_params, y0) once with the first measurement y0
 * (bumpless: the ESO at (y0, 0, ..., 0, -b0 u0), the differentiator at rest at y0,
 * so the first u is u0 = p->u0, eso.u0; or aiofl_start(&s, &p, y0, AIOFL_START_ZERO
 * / _OUTPUT); aiofl_start_at takes over a command u0 now holding the plant); then
 * at every sample
 * t_k = k*AIOFL_TS: u = aiofl_step(&s, &p, r, y) with y the measurement at t_k and
 * r[0..rho] = r, r', ..., r^(rho) at t_k (only r[0] is read: the controller has a differentiator).
 * Apply u at once and hold it until the next sample (zero-order hold).
 * aiofl_reset(&s, &p, y) restarts bumplessly mid-run.  Switch parameter instances
 * (aiofl export --params-only) only at a sample boundary.
 * A y or r that is not finite or beyond +-AIOFL_SIGNAL_MAX (1e30), or an update that
 * overflows, is a fault: u is held at its last value and aiofl_fault(&s) is 1 until
 * the next start (aiofl_init / aiofl_start / aiofl_reset).
 */
#ifndef AIOFL_CONTROLLER_H
#define AIOFL_CONTROLLER_H

#include <math.h>

/* the design's structure (generated) */
#define AIOFL_REAL_IS_FLOAT 0
#define AIOFL_RHO 2
#define AIOFL_NFB 2
#define AIOFL_NTD 2
#define AIOFL_ESO_IMPROVED 0
#define AIOFL_ESO_MODEL 0
#define AIOFL_N_PLANT_P 0
#define AIOFL_TD 3
#define AIOFL_TD_FHAN 0
#define AIOFL_SEF 0
#define AIOFL_DELAY 0
#define AIOFL_KDELAY 0
#define AIOFL_TS 0.001 /* sample time [s] */
#define AIOFL_U_MIN (-HUGE_VAL) /* law.u_min of the default parameters */
#define AIOFL_U_MAX (HUGE_VAL) /* law.u_max */
#define AIOFL_LAYOUT 0x33a0f391UL /* prefix, precision, rho, Ts, options */

/* ---- the exported API (hand-written part of the header, src/aiofl/export/templates) ---- */

/* AIOFL_REAL_IS_FLOAT: the controller's arithmetic.  The measurement and the reference
   enter as aiofl_signal, double even in a float build (they are subtracted from the
   previous sample's in that type, so the controller only sees small differences); define
   AIOFL_SIGNAL_IS_FLOAT to take them as float (cheaper without a double FPU, but then y is
   quantised to 24 bits before the observer sees it). */
#if AIOFL_REAL_IS_FLOAT
typedef float aiofl_real;
#else
typedef double aiofl_real;
#endif
#if defined(AIOFL_SIGNAL_IS_FLOAT) && AIOFL_REAL_IS_FLOAT
typedef float aiofl_signal;
#else
typedef double aiofl_signal;
#endif

#define AIOFL_TD_EXACT 0
#define AIOFL_TD_HAN 1
#define AIOFL_TD_IMPROVED 2
#define AIOFL_TD_LINEAR 3
#define AIOFL_SEF_LINEAR 0
#define AIOFL_SEF_NONLINEAR 1
#define AIOFL_SEF_IMPROVED 2

/* The fault policy (the same in aiofl.DiscreteController and the FMU): a measurement y, or a
   reference value the step reads, that is not finite or beyond +-AIOFL_SIGNAL_MAX, or an
   update that would make the command or the state non-finite, is a fault: aiofl_step
   returns the last command it returned (p->u0 after a start) and aiofl_fault(s) is 1 (a
   faulted input changes nothing; after an update that overflowed the state is not used
   again); every later sample is ignored, the command held, until the next
   aiofl_start / aiofl_init / aiofl_reset (a start at a y0 that is not usable is a fault
   too, except AIOFL_START_ZERO, which ignores y0).  Compile without -ffinite-math-only
   (part of -ffast-math), which lets the compiler drop these checks. */
#define AIOFL_SIGNAL_MAX 1e30

/* start modes of aiofl_start */
#define AIOFL_START_BUMPLESS 0 /* ESO at (y0, 0, ..., 0), differentiator at rest at y0 */
#define AIOFL_START_ZERO 1     /* everything at 0, y0 unused (eso.init = zero) */
#define AIOFL_START_OUTPUT 2   /* ESO at (y0, 0, ..., 0), differentiator at rest at 0 */

/* Every design parameter the step reads.  aiofl_default_params is the exported design;
   aiofl export --params-only writes other instances of this struct (same AIOFL_LAYOUT). */
typedef struct {
    aiofl_real b0;    /* law.b0 */
    aiofl_real u_min; /* actuator range [u_min, u_max] (+-HUGE_VAL when open) */
    aiofl_real u_max;
    aiofl_real u0;    /* eso.u0: the command held at a start at y0 (bumpless / output) */
    /* ESO, delta form: xhat = p + L phi(e);  p+ = xhat + (DPHI xhat + GAMMA u + K phi) */
    aiofl_real eso_dphi[AIOFL_RHO + 1][AIOFL_RHO + 1]; /* PHI - I, upper triangular */
    aiofl_real eso_gamma[AIOFL_RHO + 1];
    aiofl_real eso_k[AIOFL_RHO + 1];
    aiofl_real eso_l[AIOFL_RHO + 1];
#if AIOFL_ESO_IMPROVED
    aiofl_real k_alpha, k_beta, g_alpha, g_beta; /* INLESO injection, eq. (19) */
#endif
#if AIOFL_TD == AIOFL_TD_HAN
    aiofl_real td_r;  /* td.R */
    aiofl_real td_h0; /* fhan's filter factor h0 [s] (AIOFL_TD_FHAN) */
#elif AIOFL_TD == AIOFL_TD_IMPROVED
    aiofl_real itd_rho;      /* td.rho */
    aiofl_real itd_b_over_c; /* b/c */
    aiofl_real itd_gain;     /* (1 - a)/c */
#elif AIOFL_TD == AIOFL_TD_LINEAR
    aiofl_real pf_c[AIOFL_RHO];                /* coefficients of (s + omega)^rho */
    aiofl_real pf_dphi[AIOFL_RHO][AIOFL_RHO];  /* prefilter ZOH, PHI - I */
#endif
#if AIOFL_SEF == AIOFL_SEF_NONLINEAR
    aiofl_real sef_k[AIOFL_NFB], sef_alpha[AIOFL_NFB], sef_delta[AIOFL_NFB];
    aiofl_real sef_slope[AIOFL_NFB]; /* delta^(alpha - 1) */
#elif AIOFL_SEF == AIOFL_SEF_IMPROVED
    aiofl_real sef_k[AIOFL_NFB], sef_kb[AIOFL_NFB], sef_mu[AIOFL_NFB], sef_alpha[AIOFL_NFB];
    aiofl_real sef_v_limit;
#else
    aiofl_real sef_gain[AIOFL_NFB]; /* binomial(rho, i-1) omega_c^(rho-i+1) */
#endif
#if AIOFL_ESO_MODEL
    aiofl_real plant_p[AIOFL_N_PLANT_P]; /* the nominal model's parameters */
#endif
} aiofl_params;

/* The controller's memory, in offset coordinates (see aiofl_controller.c). */
typedef struct {
    aiofl_signal y_prev;            /* the previous measurement */
    aiofl_real p[AIOFL_RHO + 1];    /* ESO prediction; p[0] holds p_1 - y_prev */
    aiofl_real xhat[AIOFL_RHO + 1]; /* ESO estimate at the last sample; xhat[0] holds xhat_1 - y */
#if AIOFL_TD != AIOFL_TD_EXACT
    aiofl_signal r_prev;            /* the previous reference */
    aiofl_real td[AIOFL_NTD];       /* differentiator, next sample; td[0] holds r_1 - r_prev */
#endif
#if AIOFL_DELAY
    aiofl_real u_prev; /* the command applied over the current interval */
#endif
#if AIOFL_KDELAY /* a known measurement delay of AIOFL_KDELAY samples (eso.delay) */
    aiofl_real u_old[AIOFL_DELAY + AIOFL_KDELAY]; /* u_(k-1), u_(k-2), ...: the ESO's input */
    aiofl_signal r_old[AIOFL_KDELAY][AIOFL_RHO + 1]; /* the last references, newest first */
    int r_full; /* 1 once r_old holds references */
#endif
    aiofl_real u_held; /* the last command returned (held after a fault) */
    int fault;         /* 1 after a fault, until the next start */
} aiofl_state;

extern const aiofl_params aiofl_default_params;

void aiofl_start(aiofl_state *s, const aiofl_params *p, aiofl_signal y0, int mode);
/* a start that takes over the command u0 now holding the plant (a manual or another
   controller's; aiofl_start uses the design's p->u0): the ESO's extended state at -b0 u0 */
void aiofl_start_at(aiofl_state *s, const aiofl_params *p, aiofl_signal y0, aiofl_real u0,
                    int mode);
void aiofl_init(aiofl_state *s, const aiofl_params *p, aiofl_signal y0);
void aiofl_reset(aiofl_state *s, const aiofl_params *p, aiofl_signal y0);
aiofl_real aiofl_step(aiofl_state *s, const aiofl_params *p, const aiofl_signal *r, aiofl_signal y);
int aiofl_fault(const aiofl_state *s);

#endif /* AIOFL_CONTROLLER_H */
