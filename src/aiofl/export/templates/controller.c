/*
 * The sampled AIOFL / ADRC controller (hand-written; aiofl export copies it with the
 * prefix applied and a generated header of the options, constants and parameter struct).
 * Options (from the header): AIOFL_ESO_IMPROVED (INLESO injection), AIOFL_ESO_MODEL
 * (model-assisted), AIOFL_TD (exact / han / improved / linear), AIOFL_TD_FHAN, AIOFL_SEF
 * (linear / nonlinear / improved), AIOFL_DELAY (one-sample computation delay), AIOFL_KDELAY
 * (a known measurement delay in samples: the ESO is fed the command that much older and the
 * reference is delayed as much, aligned with the measurement).
 *
 * One sample, the engine's update (aiofl.engine.kernel.sampled._tpl_ctrl_step):
 *   ESO correction   xhat = p + L phi(e),            e = y - p_1
 *   control          e_i = r_i - xhat_i, v = SEF(e), u = v - xhat_(rho+1)/b0 (law 14),
 *                    clamped to [u_min, u_max]
 *   ESO prediction   p+ = xhat + ((PHI - I) xhat + GAMMA u + K phi)
 *   differentiator   advanced to the next sample.
 *
 * Offset coordinates (why float holds): y and r arrive as aiofl_signal (double unless
 * AIOFL_SIGNAL_IS_FLOAT), and only their changes since the previous sample, y - y_prev and
 * r - r_prev, and r_prev - y are formed in that type and rounded to aiofl_real.  The ESO's
 * first state is kept as p_1 - y_prev and xhat_1 - y, the differentiator's first state as
 * r_1 - r_prev.  Every aiofl_real quantity is then a small difference: no float ever holds
 * y (~1) next to its 1e-7 changes, so neither rounding y to 24 bits (a quantiser the
 * high-gain observer amplifies by ~1/Ts^rho) nor the cancellation in r_1 - xhat_1 enters.
 * Cost: three subtractions in aiofl_signal per sample.
 */
#include <math.h>

#include "aiofl_controller.h"

#if AIOFL_REAL_IS_FLOAT
#define AIOFL_K(x) x##f /* a constant of the controller's type */
#define AIOFL_FABS fabsf
#define AIOFL_SQRT sqrtf
#define AIOFL_EXP expf
#define AIOFL_LOG logf
#define AIOFL_TANH tanhf
#else
#define AIOFL_K(x) x
#define AIOFL_FABS fabs
#define AIOFL_SQRT sqrt
#define AIOFL_EXP exp
#define AIOFL_LOG log
#define AIOFL_TANH tanh
#endif
#define AIOFL_NEED_SIGN (AIOFL_TD == AIOFL_TD_HAN || AIOFL_SEF != AIOFL_SEF_LINEAR || AIOFL_ESO_IMPROVED)
#define AIOFL_NEED_POW (AIOFL_SEF == AIOFL_SEF_IMPROVED || AIOFL_ESO_IMPROVED)

/* 1 if x is finite (not-a-number and +-inf fail the comparison).  Compile without -ffinite-math-only
   (part of -ffast-math): it lets the compiler assume every value finite and drop the checks
   of the fault policy. */
static int aiofl_finite(aiofl_real x)
{
#if AIOFL_REAL_IS_FLOAT
    return fabsf(x) < HUGE_VALF;
#else
    return fabs(x) < HUGE_VAL;
#endif
}

/* 1 if a measurement or reference value is usable: finite and |v| <= AIOFL_SIGNAL_MAX */
static int aiofl_usable(aiofl_signal v)
{
#if defined(AIOFL_SIGNAL_IS_FLOAT) && AIOFL_REAL_IS_FLOAT
    return fabsf(v) <= (float)AIOFL_SIGNAL_MAX;
#else
    return fabs(v) <= AIOFL_SIGNAL_MAX;
#endif
}

#if AIOFL_NEED_SIGN
static aiofl_real aiofl_sign(aiofl_real x)
{
    return x > AIOFL_K(0.0) ? AIOFL_K(1.0) : (x < AIOFL_K(0.0) ? AIOFL_K(-1.0) : AIOFL_K(0.0));
}
#endif

#if AIOFL_NEED_POW
/* |e|^a as exp(a log|e|), x = |e| >= 0; 0^a = 0 for a > 0 */
static aiofl_real aiofl_abspow(aiofl_real x, aiofl_real a)
{
    if (a == AIOFL_K(1.0)) return x;
    if (a == AIOFL_K(0.0)) return AIOFL_K(1.0);
    return AIOFL_EXP(a * AIOFL_LOG(x));
}
#endif

#if AIOFL_ESO_IMPROVED
/* the INLESO's error injection g(e) = k_a |e|^g_a sign(e) + k_b |e|^g_b e, eq. (19) */
static aiofl_real aiofl_inleso(const aiofl_params *p, aiofl_real e)
{
    aiofl_real ae = AIOFL_FABS(e);
    aiofl_real g = p->k_alpha * aiofl_abspow(ae, p->g_alpha) * aiofl_sign(e);
    if (p->k_beta != AIOFL_K(0.0)) g += p->k_beta * aiofl_abspow(ae, p->g_beta) * e;
    return g;
}
#endif

#if AIOFL_SEF == AIOFL_SEF_NONLINEAR
/* Han's fal, eq. (17): e delta^(alpha-1) for |e| <= delta, |e|^alpha sign(e) beyond */
static aiofl_real aiofl_fal(aiofl_real e, aiofl_real alpha, aiofl_real delta, aiofl_real slope)
{
    aiofl_real ae = AIOFL_FABS(e);
    if (ae <= delta) return e * slope;
    if (alpha == AIOFL_K(1.0)) return e;
    return AIOFL_EXP(alpha * AIOFL_LOG(ae)) * aiofl_sign(e);
}
#elif AIOFL_SEF == AIOFL_SEF_IMPROVED
/* one term of the INLSEF, eq. (20): (k1 + k2/(1 + exp(mu e^2))) |e|^alpha sign(e) */
static aiofl_real aiofl_inlsef_term(aiofl_real e, aiofl_real k1, aiofl_real k2, aiofl_real mu,
                                    aiofl_real alpha)
{
    aiofl_real gain = k1;
    if (k2 != AIOFL_K(0.0)) gain += k2 / (AIOFL_K(1.0) + AIOFL_EXP(mu * e * e));
    return gain * aiofl_abspow(AIOFL_FABS(e), alpha) * aiofl_sign(e);
}
#endif

#if AIOFL_TD == AIOFL_TD_HAN && AIOFL_TD_FHAN
/* Han's time-optimal synthesis function fhan(x1, x2, r, h) (Han 2009) */
static aiofl_real aiofl_fhan(aiofl_real x1, aiofl_real x2, aiofl_real r, aiofl_real h)
{
    aiofl_real d = r * h;
    aiofl_real d0 = h * d;
    aiofl_real y = x1 + h * x2;
    aiofl_real ay = AIOFL_FABS(y);
    aiofl_real a;
    if (ay > d0)
        a = x2 + AIOFL_K(0.5) * (AIOFL_SQRT(d * d + AIOFL_K(8.0) * r * ay) - d) * aiofl_sign(y);
    else
        a = x2 + y / h;
    if (AIOFL_FABS(a) > d) return -r * aiofl_sign(a);
    return -r * a / d;
}
#endif

#if AIOFL_ESO_MODEL
#include "aiofl_model.h" /* static void aiofl_nominal_model(p, xi, &alpha, &beta) */
#endif

void aiofl_start_at(aiofl_state *s, const aiofl_params *p, aiofl_signal y0, aiofl_real u0,
                    int mode)
{
    int i;
    /* the ESO's prediction (y0, 0, ..., 0, -b0 u0), or 0: p[0] holds p_1 - y_prev = 0 */
    for (i = 0; i <= AIOFL_RHO; ++i) {
        s->p[i] = AIOFL_K(0.0);
        s->xhat[i] = AIOFL_K(0.0);
    }
    if (mode == AIOFL_START_ZERO) u0 = AIOFL_K(0.0);
#if AIOFL_ESO_MODEL
    (void)p;
    u0 = AIOFL_K(0.0); /* the model-assisted observer starts at its model's holding input */
#else
    s->p[AIOFL_RHO] = -p->b0 * u0;
    s->xhat[AIOFL_RHO] = s->p[AIOFL_RHO];
#endif
    s->y_prev = mode == AIOFL_START_ZERO ? 0 : y0;
#if AIOFL_TD != AIOFL_TD_EXACT
    for (i = 0; i < AIOFL_NTD; ++i) s->td[i] = AIOFL_K(0.0);
    /* the differentiator at rest at y0 (bumpless) or at 0: r_1 = r_prev, r_2.. = 0 */
    s->r_prev = mode == AIOFL_START_BUMPLESS ? y0 : 0;
#endif
#if AIOFL_DELAY
    s->u_prev = u0;
#endif
#if AIOFL_KDELAY
    for (i = 0; i < AIOFL_DELAY + AIOFL_KDELAY; ++i) s->u_old[i] = u0;
    s->r_full = 0;
#endif
    s->u_held = u0;
    s->fault = mode != AIOFL_START_ZERO && (!aiofl_usable(y0) || !aiofl_finite(u0));
}

void aiofl_start(aiofl_state *s, const aiofl_params *p, aiofl_signal y0, int mode)
{
    aiofl_start_at(s, p, y0, p->u0, mode);
}

int aiofl_fault(const aiofl_state *s)
{
    return s->fault;
}

void aiofl_init(aiofl_state *s, const aiofl_params *p, aiofl_signal y0)
{
    aiofl_start(s, p, y0, AIOFL_START_BUMPLESS);
}

void aiofl_reset(aiofl_state *s, const aiofl_params *p, aiofl_signal y0)
{
    aiofl_start(s, p, y0, AIOFL_START_BUMPLESS);
}

aiofl_real aiofl_step(aiofl_state *s, const aiofl_params *p, const aiofl_signal *r, aiofl_signal y)
{
    int i, j, ok;
    aiofl_real e, phi, dx1, v, u, um, acc, err[AIOFL_NFB];
#if AIOFL_TD != AIOFL_TD_EXACT
    aiofl_real x1; /* r_1 - r at t_k */
#endif
#if AIOFL_TD == AIOFL_TD_LINEAR
    aiofl_real next[AIOFL_RHO];
#elif AIOFL_TD == AIOFL_TD_HAN || AIOFL_TD == AIOFL_TD_IMPROVED
    const aiofl_real ts = (aiofl_real)AIOFL_TS;
    aiofl_real r2, d2;
#endif
#if AIOFL_SEF == AIOFL_SEF_LINEAR /* feed-forward r_1^(rho): exact, the prefilter's, or 0 */
#if AIOFL_TD == AIOFL_TD_EXACT
    aiofl_real rff = (aiofl_real)r[AIOFL_RHO];
#else
    aiofl_real rff = AIOFL_K(0.0);
#endif
#endif
#if AIOFL_ESO_MODEL
    aiofl_real a_hat, b_hat, xi[AIOFL_RHO];
#endif
#if AIOFL_KDELAY
    aiofl_signal r_then[AIOFL_RHO + 1];
#endif

    /* the fault policy (aiofl_controller.h): unusable inputs change nothing */
    if (s->fault) return s->u_held;
    ok = aiofl_usable(y);
#if AIOFL_TD == AIOFL_TD_EXACT
    for (i = 0; i <= AIOFL_RHO; ++i) ok = ok && aiofl_usable(r[i]);
#else
    ok = ok && aiofl_usable(r[0]);
#endif
    if (!ok) {
        s->fault = 1;
        return s->u_held;
    }
#if AIOFL_KDELAY /* the reference AIOFL_KDELAY samples old, aligned with the measurement */
    if (!s->r_full) {
        for (j = 0; j < AIOFL_KDELAY; ++j)
            for (i = 0; i <= AIOFL_RHO; ++i) s->r_old[j][i] = AIOFL_TD == AIOFL_TD_EXACT || !i ? r[i] : 0;
        s->r_full = 1;
    }
    for (i = 0; i <= AIOFL_RHO; ++i) {
        r_then[i] = s->r_old[AIOFL_KDELAY - 1][i];
        for (j = AIOFL_KDELAY - 1; j > 0; --j) s->r_old[j][i] = s->r_old[j - 1][i];
        s->r_old[0][i] = AIOFL_TD == AIOFL_TD_EXACT || !i ? r[i] : 0;
    }
    r = r_then;
#if AIOFL_SEF == AIOFL_SEF_LINEAR && AIOFL_TD == AIOFL_TD_EXACT
    rff = (aiofl_real)r[AIOFL_RHO]; /* the feed-forward of the delayed reference */
#endif
#endif

    /* ESO correction, e = y - p_1 = (y - y_prev) - (p_1 - y_prev) */
    e = (aiofl_real)(y - s->y_prev) - s->p[0];
#if AIOFL_ESO_IMPROVED
    phi = aiofl_inleso(p, e);
#else
    phi = e;
#endif
    dx1 = p->eso_l[0] * phi - e; /* xhat_1 - y */
    s->xhat[0] = dx1;
    for (i = 1; i <= AIOFL_RHO; ++i) s->xhat[i] = s->p[i] + p->eso_l[i] * phi;

    /* errors e_i = r_i - xhat_i; e_1 = (r_1 - y) - (xhat_1 - y) from small numbers */
#if AIOFL_TD == AIOFL_TD_EXACT
    err[0] = (aiofl_real)(r[0] - y) - dx1;
    for (i = 1; i < AIOFL_NFB; ++i) err[i] = (aiofl_real)r[i] - s->xhat[i];
#else
    x1 = s->td[0] - (aiofl_real)(r[0] - s->r_prev);
    err[0] = (aiofl_real)(s->r_prev - y) + s->td[0] - dx1;
    for (i = 1; i < AIOFL_NFB; ++i) err[i] = s->td[i] - s->xhat[i];
#endif
#if AIOFL_TD == AIOFL_TD_LINEAR && AIOFL_SEF == AIOFL_SEF_LINEAR /* prefilter's r_1^(rho) */
    rff = -p->pf_c[0] * x1;
    for (i = 1; i < AIOFL_RHO; ++i) rff -= p->pf_c[i] * s->td[i];
#endif

#if AIOFL_ESO_MODEL /* the nominal model at the corrected estimate: (alpha, beta)(PHI^-1(xhat)) */
    xi[0] = (aiofl_real)(y + (aiofl_signal)dx1);
    for (i = 1; i < AIOFL_RHO; ++i) xi[i] = s->xhat[i];
    aiofl_nominal_model(p, xi, &a_hat, &b_hat);
#endif

    /* state error feedback */
#if AIOFL_SEF == AIOFL_SEF_NONLINEAR /* v = sum k_i fal(e_i), eq. (17) */
    v = AIOFL_K(0.0);
    for (i = 0; i < AIOFL_NFB; ++i)
        v += p->sef_k[i] * aiofl_fal(err[i], p->sef_alpha[i], p->sef_delta[i], p->sef_slope[i]);
#elif AIOFL_SEF == AIOFL_SEF_IMPROVED /* v = v_lim tanh(sum terms / v_lim), eq. (20) */
    acc = AIOFL_K(0.0);
    for (i = 0; i < AIOFL_NFB; ++i)
        acc += aiofl_inlsef_term(err[i], p->sef_k[i], p->sef_kb[i], p->sef_mu[i], p->sef_alpha[i]);
    v = p->sef_v_limit * AIOFL_TANH(acc / p->sef_v_limit);
#else /* v = (sum k_i e_i + r^(rho)) / b0 */
    acc = AIOFL_K(0.0);
    for (i = 0; i < AIOFL_NFB; ++i) acc += p->sef_gain[i] * err[i];
    v = (acc + rff) / p->b0;
#endif

#if AIOFL_ESO_MODEL /* model-assisted law: u = (b0 v - alpha - xhat_(rho+1))/beta */
    u = (p->b0 * v - a_hat - s->xhat[AIOFL_RHO]) / b_hat;
#else /* law (14) */
    u = v - s->xhat[AIOFL_RHO] / p->b0;
#endif
    if (u > p->u_max) u = p->u_max;
    if (u < p->u_min) u = p->u_min;

    /* ESO prediction, delta form (PHI - I upper triangular, its first column 0):
       p_1+ - y = (xhat_1 - y) + delta_1,  p_i+ = xhat_i + delta_i */
#if AIOFL_KDELAY /* the command applied over the interval the measurements span */
    um = s->u_old[AIOFL_DELAY + AIOFL_KDELAY - 1];
    for (j = AIOFL_DELAY + AIOFL_KDELAY - 1; j > 0; --j) s->u_old[j] = s->u_old[j - 1];
    s->u_old[0] = u;
#elif AIOFL_DELAY
    um = s->u_prev;
    s->u_prev = u;
#else
    um = u;
#endif
#if AIOFL_ESO_MODEL
    um = (a_hat + b_hat * um) / p->b0; /* GAMMA holds b0: the model's input */
#endif
    for (i = 0; i <= AIOFL_RHO; ++i) {
        acc = p->eso_gamma[i] * um + p->eso_k[i] * phi;
        for (j = i > 0 ? i : 1; j <= AIOFL_RHO; ++j) acc += p->eso_dphi[i][j] * s->xhat[j];
        s->p[i] = (i == 0 ? dx1 : s->xhat[i]) + acc;
    }
    s->y_prev = y;

    /* the differentiator to t_(k+1), its first state relative to r_k */
#if AIOFL_TD == AIOFL_TD_HAN
    r2 = s->td[1];
#if AIOFL_TD_FHAN /* Han's discrete TD: r1+ = r1 + Ts r2, r2+ = r2 + Ts fhan(r1 - r, r2, R, h0) */
    d2 = aiofl_fhan(x1, r2, p->td_r, p->td_h0);
#else /* forward Euler on Han's TD, eq. (18) */
    d2 = -p->td_r * aiofl_sign(x1 + r2 * AIOFL_FABS(r2) / (AIOFL_K(2.0) * p->td_r));
#endif
    s->td[0] = x1 + ts * r2;
    s->td[1] = r2 + ts * d2;
#elif AIOFL_TD == AIOFL_TD_IMPROVED /* forward Euler on the ITD, eq. (21) */
    r2 = s->td[1];
    d2 = -p->itd_rho * p->itd_rho *
             AIOFL_TANH(p->itd_b_over_c * x1 + (p->itd_b_over_c - p->itd_gain) * (aiofl_real)r[0]) -
         p->itd_rho * r2;
    s->td[0] = x1 + ts * r2;
    s->td[1] = r2 + ts * d2;
#elif AIOFL_TD == AIOFL_TD_LINEAR /* prefilter, exact ZOH: r_i+ = r_i + ((PHI - I) r + GAMMA r)_i,
                                     GAMMA = -(PHI - I) e_1 (unit DC gain) */
    for (i = 0; i < AIOFL_RHO; ++i) {
        acc = p->pf_dphi[i][0] * x1;
        for (j = 1; j < AIOFL_RHO; ++j) acc += p->pf_dphi[i][j] * s->td[j];
        next[i] = (i == 0 ? x1 : s->td[i]) + acc;
    }
    for (i = 0; i < AIOFL_RHO; ++i) s->td[i] = next[i];
#endif
#if AIOFL_TD != AIOFL_TD_EXACT
    s->r_prev = r[0];
#endif
    /* an update that overflowed: a fault (the state is not used again until a start, which
       rewrites it; no copy to undo it, to keep the stack small) */
    ok = aiofl_finite(u);
    for (i = 0; i <= AIOFL_RHO; ++i) ok = ok && aiofl_finite(s->p[i]) && aiofl_finite(s->xhat[i]);
#if AIOFL_TD != AIOFL_TD_EXACT
    for (i = 0; i < AIOFL_NTD; ++i) ok = ok && aiofl_finite(s->td[i]);
#endif
    if (!ok) {
        s->fault = 1;
        return s->u_held;
    }
    s->u_held = u;
    return u;
}
