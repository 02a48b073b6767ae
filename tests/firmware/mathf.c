/* The float libm functions an exported controller may call (expf, logf, tanhf, sinf, cosf),
   written once for the host and the targets: linked ahead of the C library (glibc on the
   host, newlib on the Cortex-M), they make a design that calls them compute the same bits
   on both sides (the two libraries need not round alike; see loop.c).  Only + - * / and
   integer operations on the float's bits, -ffp-contract=off: IEEE single everywhere.
   Accurate to a few ulp (expf, logf, sinf, cosf) and ~1e-6 relative (tanhf): enough for a
   closed loop; not a replacement for libm.  sqrtf and fabsf are left to the library and
   the compiler (correctly rounded on every IEEE target).  sincosf too: gcc merges sinf(x)
   and cosf(x) of one x into a call of it. */
#include <math.h>
#include <stdint.h>
#include <string.h>

static float from_bits(uint32_t b)
{
    float f;
    memcpy(&f, &b, sizeof f);
    return f;
}

static uint32_t to_bits(float f)
{
    uint32_t b;
    memcpy(&b, &f, sizeof b);
    return b;
}

/* 2^k for -252 <= k <= 254, as a product of two normal powers */
static float pow2i(int k)
{
    if (k < -126) return from_bits((uint32_t)(k + 126 + 127) << 23) * from_bits(1u << 23);
    if (k > 127) return from_bits((uint32_t)(k - 127 + 127) << 23) * from_bits(0x7F000000u);
    return from_bits((uint32_t)(k + 127) << 23);
}

float expf(float x)
{
    float kf, r, p;
    int k;
    if (x != x) return x;
    if (x > 88.7228394f) return from_bits(0x7F800000u); /* +inf */
    if (x < -103.972084f) return 0.0f;
    kf = x * 1.44269502f;
    k = (int)(kf + (kf >= 0.0f ? 0.5f : -0.5f));
    r = (x - (float)k * 0.693145752f) - (float)k * 1.42860677e-6f; /* ln 2 = hi + lo */
    p = 1.0f + r * (1.0f + r * (0.5f + r * (1.66666672e-1f + r * (4.16666679e-2f +
                      r * (8.33333377e-3f + r * (1.38888892e-3f + r * 1.98412701e-4f))))));
    return p * pow2i(k);
}

float logf(float x)
{
    uint32_t b = to_bits(x);
    int e;
    float m, f, s, s2;
    if (x != x || x < 0.0f) return from_bits(0x7FC00000u); /* NaN */
    if (x == 0.0f) return -from_bits(0x7F800000u);
    if (b >= 0x7F800000u) return x; /* +inf */
    e = 0;
    if (b < 0x00800000u) { /* subnormal */
        x *= 16777216.0f;
        b = to_bits(x);
        e = -24;
    }
    e += (int)(b >> 23) - 127;
    m = from_bits((b & 0x007FFFFFu) | 0x3F800000u); /* [1, 2) */
    if (m > 1.41421354f) {
        m *= 0.5f;
        e += 1;
    }
    f = m - 1.0f;
    s = f / (2.0f + f);
    s2 = s * s;
    return (float)e * 0.693147182f +
           2.0f * s * (1.0f + s2 * (3.33333343e-1f + s2 * (2.0e-1f + s2 * (1.42857149e-1f +
                                   s2 * (1.11111112e-1f + s2 * 9.09090936e-2f)))));
}

float tanhf(float x)
{
    float a = x < 0.0f ? -x : x, t, y;
    if (x != x) return x;
    if (a > 9.0f) {
        y = 1.0f;
    } else if (a < 0.125f) {
        float a2 = a * a;
        y = a * (1.0f + a2 * (-3.33333343e-1f + a2 * (1.33333340e-1f + a2 * -5.39682545e-2f)));
    } else {
        t = expf(2.0f * a);
        y = (t - 1.0f) / (t + 1.0f);
    }
    return x < 0.0f ? -y : y;
}

/* sin on [-pi/2, pi/2] after a Cody-Waite reduction to [-pi, pi] and a fold (as loop.c) */
float sinf(float x)
{
    float kf = x * 0.159154943f, r, r2;
    int k;
    if (x != x || x - x != 0.0f) return from_bits(0x7FC00000u); /* NaN, inf */
    kf = kf + (kf >= 0.0f ? 0.5f : -0.5f);
    k = (kf > 8388608.0f || kf < -8388608.0f) ? 0 : (int)kf;
    r = (x - (float)k * 6.28125f) - (float)k * 1.93530717e-3f;
    if (r > 1.57079637f)
        r = 3.14159274f - r;
    else if (r < -1.57079637f)
        r = -3.14159274f - r;
    r2 = r * r;
    return r * (1.0f + r2 * (-1.66666672e-1f + r2 * (8.33333377e-3f + r2 * (-1.98412701e-4f +
                                      r2 * (2.75573188e-6f + r2 * -2.50521083e-8f)))));
}

float cosf(float x) { return sinf(x + 1.57079637f); }

void sincosf(float x, float *s, float *c);
void sincosf(float x, float *s, float *c)
{
    *s = sinf(x);
    *c = cosf(x);
}
