/* The example controller on a POSIX host: TCP and/or a framed serial link.
 *
 *   astcom-example [--tcp HOST:PORT] [--serial PATH] [--rate HZ] [--password P]
 *                  [--observer-password P] [--extra N] [--duration S] [--stats FILE]
 *                  [--warmup S] [--rt-priority N]
 *                  [--LIMIT VALUE ...]
 *
 * Limits: --max-clients --max-pending --auth-timeout --max-frame-bytes --max-depth
 * --max-array-len --max-str-bytes --max-messages --max-names --max-streams
 * --ring-ticks --max-reply-bytes --link-channels. Password attempts (§10): --auth-first-delay
 * --auth-max-delay --auth-lockout-failures --auth-lockout --auth-forget --auth-rate
 * --auth-burst --auth-max-hold --auth-addresses. ASTCOM_PASSWORD sets --password.
 * Every wrong password is logged on stderr: "auth: wrong password from ADDRESS (...)".
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ad_posix.h"
#include "example_controller.h"

static void usage(void)
{
    fputs("usage: astcom-example [--tcp HOST:PORT] [--serial PATH] [--rate HZ] [--password P]\n"
          "       [--observer-password P] [--extra N] [--duration S] [--stats FILE] [--warmup S]\n"
          "       [--rt-priority N]\n"
          "       [--max-clients N] [--max-pending N] [--auth-timeout S] [--max-frame-bytes N]\n"
          "       [--max-pending-frame-bytes N] [--max-pending-frames N]\n"
          "       [--max-depth N] [--max-array-len N] [--max-str-bytes N] [--max-messages N]\n"
          "       [--max-names N] [--max-streams N] [--ring-ticks N] [--max-reply-bytes N]\n"
          "       [--link-channels N]\n"
          "       [--auth-first-delay S] [--auth-max-delay S] [--auth-lockout-failures N]\n"
          "       [--auth-lockout S] [--auth-forget S] [--auth-rate PER_S] [--auth-burst N]\n"
          "       [--auth-max-hold S] [--auth-addresses N]\n"
          "Serves the example controller (the Python example device's names plus a two-axis\n"
          "trajectory follower) over ASTCom: TCP, and/or the framed link on a tty/pty for\n"
          "`astcom relay`. Without a password authentication is off (loopback tests only).\n"
          "--stats FILE writes the tick loop's lateness (p50/p99/p99.9/max, the first\n"
          "--warmup S seconds left out), dropped and skipped counts as JSON at exit.\n"
          "--rt-priority N runs the tick thread SCHED_FIFO at priority N (1..99), as a\n"
          "controller's loop should run on Linux (needs CAP_SYS_NICE or an rtprio limit).\n"
          "Password attempts are throttled per address and overall (docs/astcom-protocol.md\n"
          "§10; defaults 0.25 s doubling to 30 s, 20 failures lock out for 300 s, 5/s after\n"
          "a burst of 10, held at most 5 s, 64 addresses remembered); each wrong password\n"
          "is logged on stderr as 'auth: wrong password from ADDRESS (N in a row...)'.\n",
          stderr);
}

static unsigned long number(const char *opt, const char *v)
{
    char *end;
    unsigned long n = strtoul(v, &end, 10);
    if (!*v || *end) { fprintf(stderr, "%s: expected a whole number, got '%s'\n", opt, v); exit(2); }
    return n;
}

static double seconds(const char *opt, const char *v)
{
    char *end;
    double x = strtod(v, &end);
    if (!*v || *end || !(x > 0)) { fprintf(stderr, "%s: expected a number > 0, got '%s'\n", opt, v); exit(2); }
    return x;
}

/* The device's log of wrong passwords (the Python endpoint's on_auth_failure warning). */
static void log_auth_failure(void *user, const char *address, const ad_auth_failure *f)
{
    (void)user;
    fprintf(stderr, "auth: wrong password from %s (%u in a row", address, (unsigned)f->failures);
    if (f->locked_s > 0) fprintf(stderr, "; locked out for %g s", f->locked_s);
    if (f->refused) fprintf(stderr, "; %u refused unchecked before", (unsigned)f->refused);
    fputs(")\n", stderr);
    fflush(stderr);
}

int main(int argc, char **argv)
{
    ad_config cfg;
    ad_posix_opts o;
    unsigned extra = 0;
    ad_config_defaults(&cfg);
    memset(&o, 0, sizeof o);
    cfg.name = "example";
    cfg.on_auth_failure = log_auth_failure;
    cfg.operator_password = getenv("ASTCOM_PASSWORD");
    if (cfg.operator_password && !*cfg.operator_password) cfg.operator_password = NULL;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) { usage(); return 0; }
        if (!v) { fprintf(stderr, "%s needs a value\n", a); usage(); return 2; }
        i++;
        if (!strcmp(a, "--tcp")) o.tcp = v;
        else if (!strcmp(a, "--serial")) o.serial = v;
        else if (!strcmp(a, "--rate")) cfg.loop_rate_hz = atof(v);
        else if (!strcmp(a, "--password")) cfg.operator_password = *v ? v : NULL;
        else if (!strcmp(a, "--observer-password")) cfg.observer_password = *v ? v : NULL;
        else if (!strcmp(a, "--extra")) extra = (unsigned)number(a, v);
        else if (!strcmp(a, "--duration")) o.duration_s = atof(v);
        else if (!strcmp(a, "--stats")) o.stats_path = v;
        else if (!strcmp(a, "--warmup")) o.warmup_s = atof(v);
        else if (!strcmp(a, "--rt-priority")) o.rt_priority = (int)number(a, v);
        else if (!strcmp(a, "--max-clients")) cfg.max_clients = (uint32_t)number(a, v);
        else if (!strcmp(a, "--max-pending")) cfg.max_pending = (uint32_t)number(a, v);
        else if (!strcmp(a, "--max-pending-frame-bytes")) cfg.max_pending_frame_bytes = (uint32_t)number(a, v);
        else if (!strcmp(a, "--max-pending-frames")) cfg.max_pending_frames = (uint32_t)number(a, v);
        else if (!strcmp(a, "--auth-timeout")) cfg.auth_timeout_s = atof(v);
        else if (!strcmp(a, "--max-frame-bytes")) cfg.max_frame_bytes = (uint32_t)number(a, v);
        else if (!strcmp(a, "--max-depth")) cfg.max_depth = (uint32_t)number(a, v);
        else if (!strcmp(a, "--max-array-len")) cfg.max_array_len = (uint32_t)number(a, v);
        else if (!strcmp(a, "--max-str-bytes")) cfg.max_str_bytes = (uint32_t)number(a, v);
        else if (!strcmp(a, "--max-messages")) cfg.max_messages = (uint32_t)number(a, v);
        else if (!strcmp(a, "--max-names")) cfg.max_names_per_message = (uint32_t)number(a, v);
        else if (!strcmp(a, "--max-streams")) cfg.max_streams_per_client = (uint32_t)number(a, v);
        else if (!strcmp(a, "--ring-ticks")) cfg.ring_ticks = (uint32_t)number(a, v);
        else if (!strcmp(a, "--max-reply-bytes")) cfg.max_reply_bytes = (uint32_t)number(a, v);
        else if (!strcmp(a, "--link-channels")) o.link_channels = (uint32_t)number(a, v);
        else if (!strcmp(a, "--auth-first-delay")) cfg.auth_first_delay_s = seconds(a, v);
        else if (!strcmp(a, "--auth-max-delay")) cfg.auth_max_delay_s = seconds(a, v);
        else if (!strcmp(a, "--auth-lockout-failures")) cfg.auth_lockout_failures = (uint32_t)number(a, v);
        else if (!strcmp(a, "--auth-lockout")) cfg.auth_lockout_s = seconds(a, v);
        else if (!strcmp(a, "--auth-forget")) cfg.auth_forget_s = seconds(a, v);
        else if (!strcmp(a, "--auth-rate")) cfg.auth_rate_per_s = seconds(a, v);
        else if (!strcmp(a, "--auth-burst")) cfg.auth_burst = (uint32_t)number(a, v);
        else if (!strcmp(a, "--auth-max-hold")) cfg.auth_max_hold_s = seconds(a, v);
        else if (!strcmp(a, "--auth-addresses")) cfg.auth_max_addresses = (uint32_t)number(a, v);
        else { fprintf(stderr, "unknown option %s\n", a); usage(); return 2; }
    }
    if (!o.tcp && !o.serial) { fputs("give --tcp HOST:PORT and/or --serial PATH\n", stderr); usage(); return 2; }
    if (!(cfg.loop_rate_hz > 0 && cfg.loop_rate_hz <= 100000)) { fputs("--rate must be in (0, 100000] Hz\n", stderr); return 2; }
    /* the ring keeps at least 0.2 s of ticks on a host (the MCU build states its own) */
    if (cfg.ring_ticks < cfg.loop_rate_hz / 5) cfg.ring_ticks = (uint32_t)(cfg.loop_rate_hz / 5);
    ex_init(cfg.loop_rate_hz, ad_posix_wall_us(), ad_posix_wall_us);
    size_t nv, nf;
    const ad_var *vars = ex_vars(extra, &nv);
    const ad_fn *fns = ex_fns(&nf);
    size_t bytes = ad_arena_bytes(&cfg, vars, nv, fns, nf);
    void *arena = NULL;
    if (posix_memalign(&arena, 8, (bytes + 7) & ~(size_t)7)) arena = NULL;
    char why[300];
    ad_device *dev = arena ? ad_init(arena, bytes, &cfg, vars, nv, fns, nf, why, sizeof why) : NULL;
    if (!dev) { fprintf(stderr, "cannot build the device: %s\n", arena ? why : "out of memory"); return 1; }
    int rc = ad_posix_run(dev, &o, ex_step);
    free(arena);
    return rc;
}
