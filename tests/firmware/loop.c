/* Closed loop of an exported aiofl controller (float build) and the single-link
   flexible-joint manipulator (SLFJM, eq. 15), the plant stepped by RK4 in float: the same
   source runs on the host (cc -DHOST) and on a Cortex-M under qemu (semihosting output).

   Bit-identical on both sides by construction: float arithmetic only (IEEE single on x86-64
   SSE and on the Cortex-M4's FPv4 / libgcc's soft-float), -ffp-contract=off on both, and no
   libm in the plant or the reference: sin and cos are the polynomial psin() below (newlib's
   sinf and glibc's sinf are not guaranteed to round alike).  The controller itself calls
   no libm function for linear (LADRC) designs; a design whose export calls expf, logf,
   tanhf, sinf... (LESO, INLESO, model-assisted) may part from the host's by their rounding.

   Output, one "name 0x<IEEE-754 bits>" line per value (hex: exact, no float formatting in
   the firmware): itae, isu, y_end, u samples; on the target also the SysTick counts of a
   timed run of N_COUNT controller steps and of the same loop around a trivial function
   (instructions per step under qemu -icount shift=0, see tests/test_cortex_m.py).

   -DRECORD: also print y at every sample ("y_<k> 0x..."); -DREPLAY: the plant is not
   stepped, y(t_k) is read from "replay.h" (static const float Y_REC[N_STEPS], a recorded run):
   the controller makes the same calls as in the closed loop, and an instruction trace of
   the run holds little but the controller (benchmarks/bench_mcu.py). */
#include <stdint.h>
#include <string.h>

#include "aiofl_controller.h"
#ifdef REPLAY
#include "replay.h"
#endif

/* the export's API (docs/guide/export.md, "Firmware-ready C"), default prefix and parameters */
typedef aiofl_signal ctrl_signal;
#define CTRL_INIT(s, y0) aiofl_init((s), &aiofl_default_params, (y0))
#define CTRL_STEP(s, r, y) aiofl_step((s), &aiofl_default_params, (r), (y))

#ifdef HOST
#include <stdio.h>
static void sh_write0(const char *text) { fputs(text, stdout); }
#else
#include "semihost.h"
#endif

#ifndef N_STEPS
#define N_STEPS 5000 /* 5 s at Ts = 1 ms */
#endif
#ifndef N_SUB
#define N_SUB 5 /* RK4 sub-steps per sample, the command held */
#endif
#ifndef N_COUNT
#define N_COUNT 2000 /* steps of the timed run (target only) */
#endif
#ifndef REF_A
#define REF_A 0.785398163f /* scenario 1: r = 0.785 sin 2t */
#endif
#ifndef REF_W
#define REF_W 2.0f
#endif
#ifndef SCALE_JL
#define SCALE_JL 1.0f /* load inertia factor (scenario 2: 1.4) */
#endif

#define TS ((float)AIOFL_TS)

/* SLFJM parameters (aiofl.plants.builtin.SLFJM_PARAMS) */
#define K_S 1.61f
#define J_H 0.0021f
#define M_L 0.403f
#define G_R (-9.81f)
#define H_L 0.06f
#define K_M 0.00767f
#define K_G 70.0f
#define J_L (0.0059f * SCALE_JL)
#define R_M 2.6f

/* sin on [-pi, pi] after a Cody-Waite reduction, Taylor to x^11 on [-pi/2, pi/2]
   (|error| < 1e-7): the same float operations on every target */
static float psin(float x)
{
    float kf = x * 0.159154943f, r, r2;
    int k = (int)(kf + (kf >= 0.0f ? 0.5f : -0.5f));
    r = (x - (float)k * 6.28125f) - (float)k * 1.93530717e-3f; /* 2 pi = 6.28125 + 1.935e-3 */
    if (r > 1.57079637f)
        r = 3.14159274f - r;
    else if (r < -1.57079637f)
        r = -3.14159274f - r;
    r2 = r * r;
    return r * (1.0f + r2 * (-1.66666672e-1f +
                             r2 * (8.33333377e-3f +
                                   r2 * (-1.98412701e-4f + r2 * (2.75573188e-6f + r2 * -2.50521083e-8f)))));
}

#ifndef REPLAY
static void rhs(const float *x, float u, float *dx)
{
    const float damp = K_M * K_M * K_G * K_G / (R_M * J_H), b = K_M * K_G / (R_M * J_H);
    dx[0] = x[2];
    dx[1] = x[3];
    dx[2] = K_S / J_H * x[1] - damp * x[2] + b * u;
    dx[3] = -K_S / J_H * x[1] - K_S / J_L * x[1] + damp * x[2] + M_L * G_R * H_L / J_L * psin(x[0] + x[1]) - b * u;
}

static void rk4(float *x, float u, float h)
{
    float k1[4], k2[4], k3[4], k4[4], t[4];
    int i;
    rhs(x, u, k1);
    for (i = 0; i < 4; ++i) t[i] = x[i] + 0.5f * h * k1[i];
    rhs(t, u, k2);
    for (i = 0; i < 4; ++i) t[i] = x[i] + 0.5f * h * k2[i];
    rhs(t, u, k3);
    for (i = 0; i < 4; ++i) t[i] = x[i] + h * k3[i];
    rhs(t, u, k4);
    for (i = 0; i < 4; ++i) x[i] = x[i] + h / 6.0f * (k1[i] + 2.0f * k2[i] + 2.0f * k3[i] + k4[i]);
}
#endif

/* r, r', ..., r^(rho) of REF_A sin(REF_W t) */
static void reference(float t, ctrl_signal *r)
{
    float s = psin(REF_W * t), c = psin(REF_W * t + 1.57079637f), a = REF_A;
    int k;
    for (k = 0; k <= AIOFL_RHO; ++k) {
        r[k] = (ctrl_signal)((k % 4 == 0) ? a * s : (k % 4 == 1) ? a * c : (k % 4 == 2) ? -a * s : -a * c);
        a *= REF_W;
    }
}

static void put(const char *name, float value)
{
    static const char hex[] = "0123456789abcdef";
    char line[48];
    uint32_t bits;
    size_t n = strlen(name);
    int i;
    memcpy(&bits, &value, sizeof bits);
    memcpy(line, name, n);
    line[n++] = ' ';
    line[n++] = '0';
    line[n++] = 'x';
    for (i = 7; i >= 0; --i) line[n++] = hex[(bits >> (4 * i)) & 0xFu];
    line[n++] = '\n';
    line[n] = '\0';
    sh_write0(line);
}

/* put() with the name prefix followed by the decimal k */
static void put_k(const char *prefix, int k, float value)
{
    char name[24];
    int n = 0, d = 1000000;
    while (prefix[n] != '\0' && n < 8) {
        name[n] = prefix[n];
        ++n;
    }
    for (; d > 1; d /= 10)
        if (k >= d) break;
    for (; d > 0; d /= 10) name[n++] = (char)('0' + (k / d) % 10);
    name[n] = '\0';
    put(name, value);
}

#ifndef HOST
#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)

/* the timed loop's empty twin: the same call, arguments and accumulation */
__attribute__((noipa)) static aiofl_real trivial(aiofl_state *s, const aiofl_params *p,
                                                 const ctrl_signal *r, ctrl_signal y)
{
    __asm__ volatile("" ::"r"(s), "r"(p), "r"(r), "m"(y) : "memory");
    return (aiofl_real)0;
}

static void count(void)
{
    static ctrl_signal rs[64][AIOFL_RHO + 1], ys[64];
    aiofl_state s;
    volatile aiofl_real sink;
    aiofl_real acc;
    uint32_t t0, t1, t2;
    int j;
    for (j = 0; j < 64; ++j) {
        reference((float)j * TS, rs[j]);
        ys[j] = (ctrl_signal)(0.95f * (float)rs[j][0] + 1e-4f);
    }
    CTRL_INIT(&s, ys[0]);
    SYST_RVR = 0x00FFFFFFu;
    SYST_CVR = 0u;
    SYST_CSR = 5u; /* enabled, processor clock, no interrupt */
    acc = 0.0f;
    t0 = SYST_CVR;
    for (j = 0; j < N_COUNT; ++j) acc += CTRL_STEP(&s, rs[j & 63], ys[j & 63]);
    t1 = SYST_CVR;
    for (j = 0; j < N_COUNT; ++j) acc += trivial(&s, &aiofl_default_params, rs[j & 63], ys[j & 63]);
    t2 = SYST_CVR;
    sink = acc;
    (void)sink;
    put("ticks_step", (float)((t0 - t1) & 0x00FFFFFFu));
    put("ticks_base", (float)((t1 - t2) & 0x00FFFFFFu));
    put("n_count", (float)N_COUNT);
}
#endif

int main(void)
{
    aiofl_state s;
    ctrl_signal r[AIOFL_RHO + 1];
    float x[4] = {0.0f, 0.0f, 0.0f, 0.0f}, itae = 0.0f, isu = 0.0f, y = 0.0f;
    const float h = TS / (float)N_SUB;
    int k, i;
    for (k = 0; k < N_STEPS; ++k) {
        const float t = (float)k * TS;
        float u, e;
#ifdef REPLAY
        y = Y_REC[k];
#else
        y = x[0] + x[1];
#endif
        reference(t, r);
        if (k == 0) CTRL_INIT(&s, (ctrl_signal)y);
        u = (float)CTRL_STEP(&s, r, (ctrl_signal)y);
        e = (float)r[0] - y;
        itae += t * (e < 0.0f ? -e : e) * TS;
        isu += u * u * TS;
#ifdef RECORD
        put_k("y_", k, y);
#endif
        if (k == 0 || k == 1 || k == 2 || k == 10 || k == 100 || k == 1000 || k == N_STEPS - 1) {
            put_k("u_", k, u);
        }
#ifndef REPLAY
        for (i = 0; i < N_SUB; ++i) rk4(x, u, h);
#else
        (void)i;
        (void)h;
        (void)x;
#endif
    }
    put("itae", itae);
    put("isu", isu);
    put("y_end", y);
#ifndef HOST
    count();
#endif
    sh_write0("done\n");
    return 0;
}
