/* ad_snprintf: the small formatter of the library's texts (astcom_device.h).
 *
 * Why not the C library's snprintf: on a Cortex-M4, newlib's float printf (with its dtoa
 * and big-number helpers) costs about 9 KiB of flash, and newlib-nano's integer printf
 * has neither %zu nor %lld. Error texts need only a few conversions, done here with no
 * allocation: %s %.*s %c %d %u %x %02x %ld %lu %lld %llu %zu %g %.Ng %.Nf %%. Digits
 * are computed in double arithmetic, not exactly as printf's big-number conversion: the
 * last digit shown may differ by one where the number lies within a rounding error of a
 * half (0.15 shown with one decimal), and %.17g is good to about 15 digits. These are
 * texts for people; tests/fmt_check.c measures the differences against the C library.
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <string.h>

#include "ad_internal.h"

typedef struct out {
    char *p;
    size_t cap, len;   /* len counts every byte, also those beyond cap */
} out;

static void put(out *o, char c)
{
    if (o->len + 1 < o->cap) o->p[o->len] = c;
    o->len++;
}

static void puts_n(out *o, const char *s, size_t n)
{
    for (size_t i = 0; i < n; i++) put(o, s[i]);
}

static void put_u64(out *o, uint64_t v, unsigned base, int width, char pad)
{
    char d[24];
    int n = 0;
    do {
        unsigned k = (unsigned)(v % base);
        d[n++] = (char)(k < 10 ? '0' + k : 'a' + k - 10);
        v /= base;
    } while (v);
    while (width-- > n) put(o, pad);
    while (n) put(o, d[--n]);
}

static void put_i64(out *o, int64_t v, int width)
{
    if (v < 0) {
        put(o, '-');
        put_u64(o, (uint64_t)(-(v + 1)) + 1, 10, width - 1, ' ');
    } else {
        put_u64(o, (uint64_t)v, 10, width, ' ');
    }
}

static double pow10i(int e)
{
    /* exact powers up to 1e22, then steps of 1e22: a few roundings at most */
    static const double P[23] = {1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11,
                                 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21,
                                 1e22};
    unsigned k = (unsigned)(e < 0 ? -e : e);
    double r = 1.0;
    while (k > 22) { r *= 1e22; k -= 22; }
    r *= P[k];
    return e < 0 ? 1.0 / r : r;
}

/* Round a non-negative double to an integer, an exact half to even (as printf does for
 * the numbers a double holds exactly, such as 0.25 or 2.5). */
static uint64_t round_even(double v)
{
    double f = floor(v);
    uint64_t m = (uint64_t)f;
    double frac = v - f;
    if (frac > 0.5 || (frac == 0.5 && (m & 1u))) m++;
    return m;
}

/* x * 10^k without overflowing the power for the smallest numbers */
static double scale10(double x, int k)
{
    return k > 300 ? x * pow10i(300) * pow10i(k - 300) : x * pow10i(k);
}

/* The `prec` significant digits of x > 0 (finite) and its decimal exponent. */
static int digits_of(double x, int prec, char *d, int *exp10)
{
    int e2;
    frexp(x, &e2);
    int e = (int)floor((e2 - 1) * 0.30102999566398120);      /* log10(x), maybe 1 too low */
    double scaled = scale10(x, prec - 1 - e);
    while (scaled >= pow10i(prec)) { e++; scaled = scale10(x, prec - 1 - e); }
    while (scaled < pow10i(prec - 1)) { e--; scaled = scale10(x, prec - 1 - e); }
    uint64_t m = round_even(scaled);
    if (m >= (uint64_t)pow10i(prec)) { m /= 10; e++; }          /* 9.99.. rounded up */
    for (int i = prec - 1; i >= 0; i--) { d[i] = (char)('0' + m % 10); m /= 10; }
    *exp10 = e;
    return prec;
}

static int special(out *o, double x)
{
    if (isnan(x)) { puts_n(o, "nan", 3); return 1; }
    if (isinf(x)) { if (x < 0) put(o, '-'); puts_n(o, "inf", 3); return 1; }
    return 0;
}

static void put_g(out *o, double x, int prec)
{
    if (special(o, x)) return;
    if (prec <= 0) prec = 1;
    if (prec > 17) prec = 17;
    if (signbit(x)) { put(o, '-'); x = -x; }
    if (x == 0.0) { put(o, '0'); return; }
    char d[17];
    int e;
    digits_of(x, prec, d, &e);
    int n = prec;
    while (n > 1 && d[n - 1] == '0') n--;                       /* %g drops trailing zeros */
    if (e < -4 || e >= prec) {                                  /* d.ddde+XX */
        put(o, d[0]);
        if (n > 1) { put(o, '.'); puts_n(o, d + 1, (size_t)n - 1); }
        put(o, 'e');
        put(o, e < 0 ? '-' : '+');
        put_u64(o, (uint64_t)(e < 0 ? -e : e), 10, 2, '0');
    } else if (e >= 0) {                                        /* ddd.ddd */
        for (int i = 0; i <= e; i++) put(o, i < n ? d[i] : '0');
        if (n > e + 1) { put(o, '.'); puts_n(o, d + e + 1, (size_t)(n - e - 1)); }
    } else {                                                    /* 0.000ddd */
        puts_n(o, "0.", 2);
        for (int i = 0; i < -e - 1; i++) put(o, '0');
        puts_n(o, d, (size_t)n);
    }
}

static void put_f(out *o, double x, int prec)
{
    if (special(o, x)) return;
    if (prec > 9) prec = 9;
    if (signbit(x)) { put(o, '-'); x = -x; }
    if (x >= 1e15) { put_g(o, x, 17); return; }
    double scale = pow10i(prec);
    uint64_t m = round_even(x * scale), unit = (uint64_t)scale;
    put_u64(o, m / unit, 10, 0, ' ');
    if (prec) {
        put(o, '.');
        put_u64(o, m % unit, 10, prec, '0');
    }
}

int ad_vsnprintf(char *buf, size_t cap, const char *fmt, va_list ap)
{
    out o = {buf, cap, 0};
    for (const char *f = fmt; *f; f++) {
        if (*f != '%') { put(&o, *f); continue; }
        f++;
        char pad = ' ';
        int width = 0, prec = -1, lng = 0;
        if (*f == '0') { pad = '0'; f++; }
        while (*f >= '0' && *f <= '9') width = width * 10 + (*f++ - '0');
        if (*f == '.') {
            f++;
            if (*f == '*') { prec = va_arg(ap, int); f++; }
            else for (prec = 0; *f >= '0' && *f <= '9'; f++) prec = prec * 10 + (*f - '0');
        }
        while (*f == 'l') { lng++; f++; }
        if (*f == 'z') { lng = 3; f++; }
        switch (*f) {
        case 's': {
            const char *s = va_arg(ap, const char *);
            if (!s) s = "(null)";
            size_t n = 0;
            while ((prec < 0 || n < (size_t)prec) && s[n]) n++;
            while (width-- > (int)n) put(&o, ' ');
            puts_n(&o, s, n);
            break;
        }
        case 'c': put(&o, (char)va_arg(ap, int)); break;
        case 'd': case 'i':
            put_i64(&o, lng >= 2 ? va_arg(ap, long long) : lng ? va_arg(ap, long) : va_arg(ap, int),
                    width);
            break;
        case 'u': case 'x': {
            uint64_t v = lng == 3 ? va_arg(ap, size_t) : lng >= 2 ? va_arg(ap, unsigned long long)
                       : lng ? va_arg(ap, unsigned long) : va_arg(ap, unsigned);
            put_u64(&o, v, *f == 'x' ? 16u : 10u, width, pad);
            break;
        }
        case 'g': put_g(&o, va_arg(ap, double), prec < 0 ? 6 : prec); break;
        case 'f': put_f(&o, va_arg(ap, double), prec < 0 ? 6 : prec); break;
        case '%': put(&o, '%'); break;
        default: /* an unknown conversion is shown as written */
            put(&o, '%');
            if (!*f) { f--; break; }
            put(&o, *f);
        }
    }
    if (cap) buf[o.len < cap ? o.len : cap - 1] = 0;
    return (int)o.len;
}

int ad_snprintf(char *buf, size_t cap, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int n = ad_vsnprintf(buf, cap, fmt, ap);
    va_end(ap);
    return n;
}
