/*
 * aiofl_params.c
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
 */
#include <math.h>

#include "aiofl_controller.h"

#if !defined(AIOFL_LAYOUT) || AIOFL_LAYOUT != 0x33a0f391UL
#error these parameters are for another controller (prefix, precision, rho, Ts, options)
#endif

const aiofl_params aiofl_default_params = {
    .b0 = 49.99843033265063,
    .u_min = -HUGE_VAL,
    .u_max = HUGE_VAL,
    .u0 = 0.0,
    .eso_dphi = {
        {0.0, 0.001, 5e-07},
        {0.0, 0.0, 0.001},
        {0.0, 0.0, 0.0}},
    .eso_gamma = {2.4999215166325314e-05, 0.049998430332650626, 0.0},
    .eso_k = {0.0, 0.0, 0.0},
    .eso_l = {0.32826949069004596, 43.412094700518274, 1916.4788771407357},
    .pf_c = {1099.4642748015735, 66.3163411174523},
    .pf_dphi = {
        {-0.0005377298385633528, 0.0009673855355767386},
        {-1.0636058363264105, -0.06469119900795964}},
    .sef_gain = {1099.4642748015735, 66.3163411174523}
};
