/* Password attempts throttled per address and overall (§10): the rules of the reference
 * endpoint (astcom_client/throttle.py) in a fixed table, without I/O or a clock.
 *
 * cmd_auth() asks ad_throttle_reserve() before it checks a password and holds the answer
 * for the verdict's wait; the outcome is reported with failed/succeeded/cancelled when the
 * answer goes out (ad_device.c). The caller passes the time, so the rules do not depend on
 * how fast the host is. Differences from the reference, for bounded memory: the table has
 * a fixed number of entries (the least recently seen address goes first, but never one
 * with an attempt still held: the table is at least max_pending + 1 long), and an address
 * is kept as at most AD_ADDR_BYTES - 1 bytes of text. */
#include <string.h>

#include "ad_internal.h"

static int64_t us(double s) { return (int64_t)(s * 1e6 + 0.5); }

uint32_t ad_throttle_entries(const ad_config *cfg, uint32_t n_sessions)
{
    uint32_t least = (cfg->max_pending < n_sessions ? cfg->max_pending : n_sessions) + 1u;
    uint32_t n = cfg->auth_max_addresses > least ? cfg->auth_max_addresses : least;
    return n > 65535u ? 65535u : n;
}

void ad_throttle_init(ad_throttle *t, const ad_config *c, ad_addr_state *table, uint32_t n)
{
    memset(t, 0, sizeof *t);
    t->table = table;
    t->n = n;
    t->first_delay_us = us(c->auth_first_delay_s);
    t->max_delay_us = us(c->auth_max_delay_s);
    t->lockout_us = us(c->auth_lockout_s);
    t->forget_us = us(c->auth_forget_s);
    t->interval_us = us(1.0 / c->auth_rate_per_s);
    t->max_hold_us = us(c->auth_max_hold_s);
    t->lockout_failures = c->auth_lockout_failures;
    t->burst = c->auth_burst;
}

/* The wait before the next check after `failures` consecutive failures. */
static int64_t delay_us(const ad_throttle *t, uint32_t failures)
{
    if (!failures) return 0;
    int64_t d = t->first_delay_us;
    for (uint32_t k = 1; k < failures && d < t->max_delay_us; k++) d *= 2;
    return d < t->max_delay_us ? d : t->max_delay_us;
}

/* The entry of `addr`, remembered from now on (stale ones forgotten first); -1 when every
 * entry holds an attempt (cannot happen with the table ad_throttle_entries() sizes). */
static int state(ad_throttle *t, const char *addr, int64_t now_us)
{
    int found = -1, free_at = -1, oldest = -1;
    for (uint32_t i = 0; i < t->n; i++) {
        ad_addr_state *e = &t->table[i];
        if (e->addr[0] && now_us - e->seen_us >= t->forget_us && now_us >= e->locked_until_us
                && !e->pending)
            memset(e, 0, sizeof *e); /* quiet for forget_us: forgotten */
        if (!e->addr[0]) { if (free_at < 0) free_at = (int)i; continue; }
        if (!strncmp(e->addr, addr, AD_ADDR_BYTES - 1)) found = (int)i;
        else if (!e->pending && (oldest < 0 || e->seen_us < t->table[oldest].seen_us)) oldest = (int)i;
    }
    if (found < 0) {
        found = free_at >= 0 ? free_at : oldest; /* full: the least recently seen goes */
        if (found < 0) return -1;
        ad_addr_state *e = &t->table[found];
        memset(e, 0, sizeof *e);
        size_t n = strlen(addr);
        if (n > AD_ADDR_BYTES - 1) n = AD_ADDR_BYTES - 1;
        memcpy(e->addr, addr, n);
        if (!n) e->addr[0] = '?'; /* a peer without an address */
    }
    t->table[found].seen_us = now_us;
    return found;
}

static ad_verdict refuse(ad_throttle *t, ad_addr_state *e, int64_t wait_us, uint8_t reason)
{
    ad_verdict v = {wait_us, 1, reason, 0};
    if (e) e->refused++;
    t->refused++;
    return v;
}

ad_verdict ad_throttle_reserve(ad_throttle *t, const char *addr, int64_t now_us)
{
    int i = state(t, addr ? addr : "", now_us);
    if (i < 0) return refuse(t, NULL, t->max_hold_us, AD_WHY_OVERALL);
    ad_addr_state *e = &t->table[i];
    if (now_us < e->locked_until_us)
        return refuse(t, e, e->locked_until_us - now_us, AD_WHY_LOCKED);
    int64_t overall_us = t->tat_us - (int64_t)(t->burst - 1u) * t->interval_us;
    if (overall_us < now_us) overall_us = now_us;
    int64_t at_us = overall_us > e->next_us ? overall_us : e->next_us;
    if (at_us - now_us > t->max_hold_us)
        return refuse(t, e, at_us - now_us,
                      e->next_us >= overall_us ? AD_WHY_ADDRESS : AD_WHY_OVERALL);
    t->tat_us = (t->tat_us > at_us ? t->tat_us : at_us) + t->interval_us;
    e->pending++;
    /* the next attempt from this address waits as if this one fails (it is forgotten if
     * it does not) */
    e->next_us = at_us + delay_us(t, (uint32_t)e->failures + e->pending);
    t->checked++;
    ad_verdict v = {at_us - now_us, 0,
                    at_us > overall_us ? AD_WHY_ADDRESS : at_us > now_us ? AD_WHY_OVERALL : AD_WHY_NONE,
                    (uint16_t)i};
    return v;
}

void ad_throttle_failed(ad_throttle *t, uint16_t entry, int64_t now_us, ad_auth_failure *out)
{
    ad_addr_state *e = &t->table[entry];
    if (e->pending) e->pending--;
    if (e->failures < 0xffff) e->failures++;
    e->seen_us = now_us;
    t->failures++;
    out->failures = e->failures;
    out->refused = e->refused;
    out->locked_s = 0;
    e->refused = 0;
    if (e->failures >= t->lockout_failures) {
        e->failures = 0; /* after the lockout: afresh */
        e->locked_until_us = now_us + t->lockout_us;
        if (e->next_us < e->locked_until_us) e->next_us = e->locked_until_us;
        out->locked_s = (double)t->lockout_us / 1e6;
    }
}

void ad_throttle_succeeded(ad_throttle *t, uint16_t entry)
{
    ad_addr_state *e = &t->table[entry];
    if (e->pending > 1) { /* a right password forgets the address; others still wait */
        uint16_t pending = (uint16_t)(e->pending - 1);
        char addr[AD_ADDR_BYTES];
        int64_t seen = e->seen_us;
        memcpy(addr, e->addr, sizeof addr);
        memset(e, 0, sizeof *e);
        memcpy(e->addr, addr, sizeof addr);
        e->pending = pending;
        e->seen_us = seen;
        return;
    }
    memset(e, 0, sizeof *e);
}

void ad_throttle_cancelled(ad_throttle *t, uint16_t entry)
{
    if (t->table[entry].pending) t->table[entry].pending--;
}

uint32_t ad_throttle_tracked(const ad_throttle *t, int64_t now_us)
{
    uint32_t n = 0;
    (void)now_us;
    for (uint32_t i = 0; i < t->n; i++) n += t->table[i].addr[0] != 0;
    return n;
}

void ad_throttle_message(const ad_verdict *v, const char *addr, char *out, size_t len)
{
    double wait_s = (double)v->wait_us / 1e6;
    if (v->reason == AD_WHY_LOCKED)
        ad_snprintf(out, len, "%s is locked out after too many wrong passwords: not checked; "
                    "try again in %.0f s", addr, wait_s);
    else if (v->reason == AD_WHY_ADDRESS)
        ad_snprintf(out, len, "too many wrong passwords from %s: not checked; try again in %.0f s",
                    addr, wait_s);
    else
        ad_snprintf(out, len, "too many login attempts on this server: not checked; "
                    "try again in %.0f s", wait_s);
}
