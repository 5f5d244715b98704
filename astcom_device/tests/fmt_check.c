/* ad_snprintf against the C library's snprintf (the reference) on many numbers: prints
 * one line per disagreement and "checked N" at the end: exact agreement on a list of
 * plain numbers, one unit of the last digit elsewhere, %.17g read back within 1e-14. Built by `make
 * fmt-check` on a host with glibc; run by tests/device_c/test_device_format.py. */
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "astcom_device.h"

static unsigned long checked, bad;

/* Exactly as the C library for the numbers of `fixed` below; for any other number within
 * one unit of the last digit shown (parsed back and compared with the library's). */
static void same(const char *fmt, double x, int exact)
{
    char a[64], b[64];
    ad_snprintf(a, sizeof a, fmt, x);
    snprintf(b, sizeof b, fmt, x);
    checked++;
    if (!strcmp(a, b)) return;
    if (!exact) {
        double pa = strtod(a, NULL), pb = strtod(b, NULL);
        const char *dot = strchr(b, '.'), *ex = strchr(b, 'e');
        int decimals = dot ? (int)((ex ? ex : b + strlen(b)) - dot - 1) : 0;
        double unit = pow(10.0, (ex ? atoi(ex + 1) : 0) - decimals);
        if (fabs(pa - pb) <= 1.01 * unit) return;
    }
    bad++;
    printf("MISMATCH %s %.17g: ours '%s' libc '%s'\n", fmt, x, a, b);
}

static void close17(double x)
{
    char a[64];
    ad_snprintf(a, sizeof a, "%.17g", x);
    double back = strtod(a, NULL);
    checked++;
    if (!(back == x || fabs(back - x) <= 1e-14 * fabs(x)) && !(isnan(x) && isnan(back))) {
        bad++;
        printf("MISMATCH %%.17g %.17g: ours '%s' reads back %.17g\n", x, a, back);
    }
}

static uint64_t state = 88172645463325252ull;
static uint64_t next(void)
{
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    return state;
}

int main(void)
{
    static const double fixed[] = {0.0, -0.0, 1.0, -1.0, 0.5, 0.1, 0.25, 1.5, 2.5, 5.0,
        10.0, 100.0, 1000.0, 5000.0, 1e5, 123456.0, 999999.0, 999999.5, 1e6, 1234567.0, 1e-4,
        1e-5, 0.000123456, 9.9999949e-5, 2.3283064365386963e-07, 4294967296.0, 1e15, 1e16,
        1e21, 1e100, 1e300, 1.7976931348623157e308, 5e-324, 2.2250738585072014e-308, 1e-9,
        3.14159265358979, 1e-300, 86400.0, 0.3, 0.7, 1.0 / 3.0, 2.0 / 3.0, 6.02214076e23};
    const char *fmts[] = {"%g", "%.6g", "%.3g", "%.1f", "%.4f", "%.0f"};
    for (size_t i = 0; i < sizeof fixed / sizeof fixed[0]; i++) {
        for (size_t k = 0; k < 3; k++) { same(fmts[k], fixed[i], 1); same(fmts[k], -fixed[i], 1); }
        if (fabs(fixed[i]) < 1e14)
            for (size_t k = 3; k < 6; k++) { same(fmts[k], fixed[i], 1); same(fmts[k], -fixed[i], 1); }
        close17(fixed[i]);
    }
    same("%.1f", 0.15, 0); /* a near-half: one unit off allowed (ad_fmt.c) */
    same("%g", NAN, 1);
    same("%g", INFINITY, 1);
    same("%g", -INFINITY, 1);
    for (int i = 0; i < 200000; i++) {
        uint64_t bits = next();
        double x;
        memcpy(&x, &bits, 8);
        if (!isfinite(x)) continue;
        same("%g", x, 0);
        close17(x);
        double y = (double)(int64_t)(next() % 2000000001) / pow(10.0, (double)(next() % 12));
        same("%g", y, 0);
        same("%.6g", y, 0);
        if (fabs(y) < 1e9) { same("%.4f", y, 0); same("%.1f", y, 0); }
        close17(y);
    }
    /* integers and texts */
    char a[128], b[128];
    long long v[] = {0, 1, -1, 9223372036854775807LL, -9223372036854775807LL - 1, 4294967296LL};
    for (size_t i = 0; i < sizeof v / sizeof v[0]; i++) {
        ad_snprintf(a, sizeof a, "%lld|%llu|%zu|%u|%d|%02x|%x", v[i], (unsigned long long)v[i],
                    (size_t)v[i], (unsigned)v[i], (int)v[i], (unsigned)(v[i] & 0xff), (unsigned)v[i]);
        snprintf(b, sizeof b, "%lld|%llu|%zu|%u|%d|%02x|%x", v[i], (unsigned long long)v[i],
                 (size_t)v[i], (unsigned)v[i], (int)v[i], (unsigned)(v[i] & 0xff), (unsigned)v[i]);
        checked++;
        if (strcmp(a, b)) { bad++; printf("MISMATCH ints: ours '%s' libc '%s'\n", a, b); }
    }
    ad_snprintf(a, sizeof a, "[%s] [%.*s] [%c] 100%%", "text", 3, "abcdef", 'z');
    snprintf(b, sizeof b, "[%s] [%.*s] [%c] 100%%", "text", 3, "abcdef", 'z');
    checked++;
    if (strcmp(a, b)) { bad++; printf("MISMATCH texts: ours '%s' libc '%s'\n", a, b); }
    /* truncation: the length it needs, a NUL inside the buffer */
    int n = ad_snprintf(a, 5, "%s-%g", "abcdef", 1.5);
    checked++;
    if (n != 10 || strcmp(a, "abcd")) { bad++; printf("MISMATCH truncation: %d '%s'\n", n, a); }
    printf("checked %lu, mismatches %lu\n", checked, bad);
    return bad != 0;
}
