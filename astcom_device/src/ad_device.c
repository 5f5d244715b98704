/* The endpoint without I/O: registry, message register, sessions and commands (§3–§5, §7). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "ad_internal.h"

#define CLIENT_LABEL "ASTCom-1 client"
#define SERVER_LABEL "ASTCom-1 server"
#define MAX_PROTOCOL_ERRORS 8
#define MAX_SEQ 0x7fffffffffffffffull

static const char *const ROLE_NAMES[] = {"none", "observer", "operator"};

void ad_config_defaults(ad_config *c)
{
    memset(c, 0, sizeof *c);
    c->name = "astcom-device";
    c->loop_rate_hz = 1000.0;
    c->max_frame_bytes = 1u << 20;
    c->max_depth = 16;
    c->max_array_len = 100000;
    c->max_str_bytes = 1u << 16;
    c->max_messages = 4096;
    c->max_names_per_message = 1024;
    c->max_streams_per_client = 64;
    c->max_clients = 32;
    c->max_pending = 8;
    c->max_pending_frame_bytes = 4096;
    c->max_pending_frames = 16;
    c->auth_timeout_s = 10.0;
    c->queue_packets = 256;
    c->ring_ticks = 2048;
    c->max_reply_bytes = 256u << 10;
    c->max_samplers = 64;
    c->max_pending_calls = 8;
    c->flush_interval_s = 0.02;
    /* password attempts: the reference endpoint's ThrottlePolicy (§10) */
    c->auth_first_delay_s = 0.25;
    c->auth_max_delay_s = 30.0;
    c->auth_lockout_failures = 20;
    c->auth_lockout_s = 300.0;
    c->auth_forget_s = 900.0;
    c->auth_rate_per_s = 5.0;
    c->auth_burst = 10;
    c->auth_max_hold_s = 5.0;
    c->auth_max_addresses = 64;
}

/* ---- arena ------------------------------------------------------------------------------ */
typedef struct layout {
    size_t vrt, traced, ring, sessions, msg_pool, samplers, scratch, stage, argbuf, addrs, total;
    uint32_t row_bytes, n_traced, stage_bytes, msg_pool_bytes, argbuf_bytes, n_sessions, n_addrs;
} layout;

static size_t up8(size_t n) { return (n + 7u) & ~(size_t)7u; }

static void plan(const ad_config *c, const ad_var *vars, size_t nv, size_t nf, layout *L)
{
    size_t off = up8(sizeof(ad_device));
    uint32_t row = 0, nt = 0, stage = 64;
    for (size_t i = 0; i < nv; i++) {
        ad_type t;
        if (ad_parse_type(vars[i].type, strlen(vars[i].type), &t)) continue;
        if (vars[i].traced && t.base <= 10 && t.ndim == 0) { row += t.c_size; nt++; }
        stage += (uint32_t)up8(t.base == AD_T_STR ? vars[i].capacity : t.c_size);
    }
    L->row_bytes = (uint32_t)up8(row);
    L->n_traced = nt;
    L->n_sessions = c->max_clients + c->max_pending;
    if (L->n_sessions > AD_MAX_SESSIONS) L->n_sessions = AD_MAX_SESSIONS;
    L->stage_bytes = (uint32_t)up8(stage);
    /* a message record: id, holders, count and its variable indices */
    uint32_t names = c->max_names_per_message < 64 ? 64 : c->max_names_per_message;
    L->msg_pool_bytes = (uint32_t)up8((size_t)c->max_messages * 24u + (size_t)names * 2u * 8u);
    if (L->msg_pool_bytes > (c->max_messages * 24u + c->max_messages * names * 2u))
        L->msg_pool_bytes = (uint32_t)up8(c->max_messages * 24u + c->max_messages * names * 2u);
    L->argbuf_bytes = (uint32_t)up8(c->max_arg_bytes ? c->max_arg_bytes
                                    : c->max_frame_bytes < 65536 ? c->max_frame_bytes * 2u
                                    : c->max_frame_bytes);
    L->vrt = off; off += up8(nv * sizeof(ad_var_rt));
    (void)nf; /* signatures are parsed when a function is called: no table in RAM */
    L->traced = off; off += up8(nt * sizeof(uint16_t));
    L->ring = off; off += (size_t)L->row_bytes * c->ring_ticks;
    L->sessions = off; off += up8(L->n_sessions * sizeof(ad_session));
    L->msg_pool = off; off += L->msg_pool_bytes;
    L->samplers = off; off += up8(c->max_samplers * sizeof(ad_sampler));
    L->scratch = off; off += up8(c->max_reply_bytes);
    L->stage = off; off += L->stage_bytes;
    L->argbuf = off; off += L->argbuf_bytes;
    L->n_addrs = ad_throttle_entries(c, L->n_sessions);
    L->addrs = off; off += up8(L->n_addrs * sizeof(ad_addr_state));
    L->total = off;
}

size_t ad_arena_bytes(const ad_config *cfg, const ad_var *vars, size_t n_vars,
                      const ad_fn *fns, size_t n_fns)
{
    layout L;
    (void)fns;
    plan(cfg, vars, n_vars, n_fns, &L);
    return L.total;
}

static int valid_name(const char *n)
{
    /* dotted identifiers: [A-Za-z_][A-Za-z0-9_]* joined by '.' */
    int start = 1;
    if (!*n) return 0;
    for (; *n; n++) {
        char c = *n;
        int alpha = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_';
        int digit = c >= '0' && c <= '9';
        if (c == '.') { if (start) return 0; start = 1; continue; }
        if (start && !alpha) return 0;
        if (!alpha && !digit) return 0;
        start = 0;
    }
    return !start;
}

/* A function's signature text, read one argument at a time when it is called (no table of
 * parsed signatures in RAM): "(name:type,name:type)->type"; types may hold commas inside
 * [] or {}. */
typedef struct sig_it {
    const char *p, *close;
} sig_it;

/* Check the whole signature; count its arguments and parse its return type. 0 or -1. */
static int sig_begin(const char *sig, sig_it *it, ad_type *ret, uint8_t *n_args);

/* The next argument into `a`: 1, or 0 after the last, or -1 when malformed. */
static int sig_next(sig_it *it, ad_arg *a)
{
    if (it->p >= it->close) return 0;
    const char *colon = memchr(it->p, ':', (size_t)(it->close - it->p));
    if (!colon) return -1;
    const char *q = colon + 1;
    int depth = 0;
    while (q < it->close && !(depth == 0 && *q == ',')) {
        if (*q == '[' || *q == '{') depth++;
        else if (*q == ']' || *q == '}') depth--;
        q++;
    }
    a->name = it->p;
    a->name_len = (uint32_t)(colon - it->p);
    a->type_text = colon + 1;
    a->type_len = (uint32_t)(q - colon - 1);
    if (ad_parse_type(a->type_text, a->type_len, &a->type) || a->type.base == AD_T_NONE
            || a->type.base == AD_T_STRUCT || a->type.base == AD_T_BYTES)
        return -1;
    if (a->type.base == AD_T_STR) a->type.c_size = 0;
    it->p = q < it->close ? q + 1 : q;
    return 1;
}

static int sig_begin(const char *sig, sig_it *it, ad_type *ret, uint8_t *n_args)
{
    const char *p = sig, *close;
    int depth = 0;
    if (*p != '(') return -1;
    p++;
    for (close = p; *close; close++) {
        if (*close == '[' || *close == '{') depth++;
        else if (*close == ']' || *close == '}') depth--;
        else if (*close == ')' && depth == 0) break;
    }
    if (*close != ')' || strncmp(close, ")->", 3)) return -1;
    const char *rtext = close + 3;
    if (ad_parse_type(rtext, strlen(rtext), ret) || ret->ndim == AD_VARLEN
            || ret->base == AD_T_STRUCT || ret->base == AD_T_BYTES)
        return -1;
    sig_it count = {p, close};
    ad_arg a;
    int rc;
    *n_args = 0;
    while ((rc = sig_next(&count, &a)) == 1)
        if (++*n_args > AD_MAX_ARGS) return -1;
    if (rc < 0) return -1;
    it->p = p;
    it->close = close;
    return 0;
}

ad_device *ad_init(void *arena, size_t arena_bytes, const ad_config *cfg, const ad_var *vars,
                   size_t n_vars, const ad_fn *fns, size_t n_fns, char *why, size_t why_len)
{
    layout L;
    uint8_t *base = (uint8_t *)arena;
    uint16_t probe = 1;
    if (*(uint8_t *)&probe != 1) { ad_snprintf(why, why_len, "a big-endian host is not supported"); return NULL; }
    if (!arena || ((uintptr_t)arena & 7u)) { ad_snprintf(why, why_len, "the arena must be 8-byte aligned"); return NULL; }
    if (cfg->loop_rate_hz <= 0 || cfg->ring_ticks < 2 || cfg->max_reply_bytes < 256
            || cfg->max_depth < 2 || cfg->max_frame_bytes < 64) {
        ad_snprintf(why, why_len, "configuration out of range (loop_rate_hz > 0, ring_ticks >= 2, "
                 "max_reply_bytes >= 256, max_depth >= 2, max_frame_bytes >= 64)");
        return NULL;
    }
    if (!(cfg->auth_first_delay_s > 0 && cfg->auth_max_delay_s > 0 && cfg->auth_lockout_s > 0
          && cfg->auth_forget_s > 0 && cfg->auth_rate_per_s > 0 && cfg->auth_max_hold_s > 0
          && cfg->auth_lockout_failures >= 1 && cfg->auth_burst >= 1)) {
        ad_snprintf(why, why_len, "password throttle out of range (auth_*_s and auth_rate_per_s "
                 "> 0, auth_lockout_failures and auth_burst >= 1)");
        return NULL;
    }
    plan(cfg, vars, n_vars, n_fns, &L);
    if (arena_bytes < L.total) {
        ad_snprintf(why, why_len, "the arena holds %zu bytes; this configuration needs %zu",
                 arena_bytes, L.total);
        return NULL;
    }
    memset(arena, 0, L.total);
    ad_device *dev = (ad_device *)arena;
    dev->cfg = *cfg;
    dev->vars = vars;
    dev->n_vars = (uint32_t)n_vars;
    dev->fns = fns;
    dev->n_fns = (uint32_t)n_fns;
    dev->vrt = (ad_var_rt *)(base + L.vrt);
    dev->traced = (uint16_t *)(base + L.traced);
    dev->ring = base + L.ring;
    dev->row_bytes = L.row_bytes;
    dev->sessions = (ad_session *)(base + L.sessions);
    dev->n_sessions = L.n_sessions;
    dev->msg_pool = base + L.msg_pool;
    dev->msg_pool_bytes = L.msg_pool_bytes;
    dev->samplers = (ad_sampler *)(base + L.samplers);
    dev->scratch = base + L.scratch;
    dev->stage = base + L.stage;
    dev->stage_bytes = L.stage_bytes;
    dev->argbuf = base + L.argbuf;
    dev->argbuf_bytes = L.argbuf_bytes;
    ad_throttle_init(&dev->throttle, cfg, (ad_addr_state *)(base + L.addrs), L.n_addrs);
    dev->tick_us = 1e6 / cfg->loop_rate_hz;
    dev->next_msg = 1;
    dev->next_client_id = 1;
    uint32_t col = 0, off = 0;
    for (size_t i = 0; i < n_vars; i++) {
        const ad_var *v = &vars[i];
        ad_var_rt *rt = &dev->vrt[i];
        ad_type t;
        if (!v->name || !valid_name(v->name)) { ad_snprintf(why, why_len, "invalid name '%s': expected dotted identifiers such as axis.az.position", v->name ? v->name : "(null)"); return NULL; }
        if (!v->type || ad_parse_type(v->type, strlen(v->type), &t) || (t.base >= AD_T_BYTES && t.base != AD_T_STRUCT)) { ad_snprintf(why, why_len, "%s: unknown or unsupported type '%s'", v->name, v->type ? v->type : "(null)"); return NULL; }
        if (t.ndim == AD_VARLEN) { ad_snprintf(why, why_len, "%s: a variable cannot be of variable length (%s)", v->name, v->type); return NULL; }
        if (t.base == AD_T_STR) {
            if (v->capacity < 1) { ad_snprintf(why, why_len, "%s: a str variable needs its buffer capacity", v->name); return NULL; }
            t.c_size = v->capacity;
        }
        if (!v->ptr) { ad_snprintf(why, why_len, "%s: no storage (ptr)", v->name); return NULL; }
        if ((v->has_min || v->has_max) && (t.base == 0 || t.base > 10)) { ad_snprintf(why, why_len, "%s: only numeric variables take min/max, not %s", v->name, v->type); return NULL; }
        if (v->has_min && v->has_max && v->min > v->max) { ad_snprintf(why, why_len, "%s: min %g is above max %g", v->name, v->min, v->max); return NULL; }
        rt->base = t.base;
        rt->ndim = t.ndim;
        rt->count = t.count;
        rt->c_size = t.c_size;
        rt->trace_col = -1;
        if (v->traced) {
            if (t.base > 10 || t.ndim) { ad_snprintf(why, why_len, "%s: only numeric scalars can be traced, not %s", v->name, v->type); return NULL; }
            rt->trace_col = (int16_t)col;
            rt->ring_offset = off;
            dev->traced[col++] = (uint16_t)i;
            off += t.c_size;
        }
        for (size_t j = 0; j < i; j++)
            if (!strcmp(vars[j].name, v->name)) { ad_snprintf(why, why_len, "'%s' is already registered", v->name); return NULL; }
    }
    dev->n_traced = col;
    for (size_t i = 0; i < n_fns; i++) {
        if (!fns[i].name || !valid_name(fns[i].name) || !fns[i].fn) { ad_snprintf(why, why_len, "function %zu: invalid name or no callback", i); return NULL; }
        sig_it it;
        ad_type ret;
        uint8_t n_args;
        if (!fns[i].signature || sig_begin(fns[i].signature, &it, &ret, &n_args)) { ad_snprintf(why, why_len, "%s: bad signature '%s'; expected (name:type,...)->type", fns[i].name, fns[i].signature ? fns[i].signature : "(null)"); return NULL; }
        for (size_t j = 0; j < n_vars; j++)
            if (!strcmp(vars[j].name, fns[i].name)) { ad_snprintf(why, why_len, "'%s' is already registered", fns[i].name); return NULL; }
        for (size_t j = 0; j < i; j++)
            if (!strcmp(fns[j].name, fns[i].name)) { ad_snprintf(why, why_len, "'%s' is already registered", fns[i].name); return NULL; }
    }
    return dev;
}

const ad_config *ad_device_config(const ad_device *dev) { return &dev->cfg; }

/* ---- sending ---------------------------------------------------------------------------- */
void ad_send_frame(ad_device *dev, ad_session *s, const ad_wr *w)
{
    (void)dev;
    s->sink.send(s->sink.ctx, dev->scratch, w->used, 0);
}

static void begin(ad_device *dev, ad_wr *w)
{
    ad_wr_init(w, dev->scratch, dev->cfg.max_reply_bytes);
}

static void send_error_raw(ad_device *dev, ad_sink sink, int has_seq, uint64_t seq, int code,
                           const char *message)
{
    ad_wr w;
    size_t n = strlen(message);
    begin(dev, &w);
    ad_wr_array(&w, 3);
    ad_wr_str(&w, "ERR");
    if (has_seq) ad_wr_uint(&w, seq); else ad_wr_nil(&w);
    ad_wr_map(&w, 2);
    ad_wr_str(&w, "code");
    ad_wr_uint(&w, (uint64_t)code);
    ad_wr_str(&w, "message");
    /* the reason, cut to what the scratch holds beside the frame's 40 other bytes */
    size_t most = dev->cfg.max_reply_bytes - 48u;
    if (most > 1024) most = 1024;
    while (n > most) { n--; while (n && ((uint8_t)message[n] & 0xc0) == 0x80) n--; } /* whole UTF-8 */
    ad_wr_strn(&w, message, (uint32_t)n);
    sink.send(sink.ctx, dev->scratch, w.used, 0);
}

static void close_session(ad_session *s, int code, const char *reason)
{
    if (!s->wants_close) {
        s->wants_close = 1;
        s->close_code = code;
        size_t n = strlen(reason);
        if (n >= sizeof s->close_reason) n = sizeof s->close_reason - 1;
        memcpy(s->close_reason, reason, n);
        s->close_reason[n] = 0;
    }
    s->state = AD_CLOSED;
}

static void fail(ad_device *dev, ad_session *s, int has_seq, uint64_t seq, int code,
                 const char *message, int close)
{
    send_error_raw(dev, s->sink, has_seq, seq, code, message);
    if (close) close_session(s, code, message);
}

/* ---- sessions --------------------------------------------------------------------------- */
static void counts(const ad_device *dev, uint32_t *authed, uint32_t *pending)
{
    *authed = *pending = 0;
    for (uint32_t i = 0; i < dev->n_sessions; i++) {
        const ad_session *s = &dev->sessions[i];
        if (!s->used || s->state == AD_CLOSED) continue;
        if (s->role == AD_ROLE_NONE) (*pending)++; else (*authed)++;
    }
}

static const char *admit_refusal(const ad_device *dev, char *buf, size_t len)
{
    uint32_t a, p;
    counts(dev, &a, &p);
    if (a >= dev->cfg.max_clients) {
        ad_snprintf(buf, len, "too many clients: this endpoint accepts at most %u", dev->cfg.max_clients);
        return buf;
    }
    return NULL;
}

/* The throttle's key: the peer's text without what follows its last ':' (the port), as
 * the reference endpoint does; bytes that are not printable ASCII become '?'. */
static void peer_address(const char *peer, char out[AD_ADDR_BYTES])
{
    size_t n = peer ? strlen(peer) : 0;
    for (size_t k = n; k > 0; k--)
        if (peer[k - 1] == ':') { if (k > 1) n = k - 1; break; }
    if (n > AD_ADDR_BYTES - 1) n = AD_ADDR_BYTES - 1;
    for (size_t k = 0; k < n; k++) {
        char c = peer[k];
        out[k] = c >= 0x20 && c < 0x7f ? c : '?';
    }
    out[n] = 0;
}

ad_session *ad_open(ad_device *dev, ad_sink sink, const char *peer, int64_t now_us)
{
    char why[200];
    uint32_t a, p;
    const char *refusal = admit_refusal(dev, why, sizeof why);
    counts(dev, &a, &p);
    if (!refusal && p >= dev->cfg.max_pending) {
        ad_snprintf(why, sizeof why, "too many connections waiting to authenticate: this endpoint "
                 "accepts at most %u (each has %g s); retry shortly", dev->cfg.max_pending,
                 dev->cfg.auth_timeout_s);
        refusal = why;
    }
    ad_session *s = NULL;
    for (uint32_t i = 0; !refusal && i < dev->n_sessions; i++)
        if (!dev->sessions[i].used) { s = &dev->sessions[i]; s->slot = (uint8_t)i; break; }
    if (!refusal && !s) {
        ad_snprintf(why, sizeof why, "too many connections: this device has %u connection slots",
                 dev->n_sessions);
        refusal = why;
    }
    if (refusal) {
        send_error_raw(dev, sink, 0, 0, 429, refusal);
        return NULL;
    }
    uint8_t slot = s->slot;
    memset(s, 0, sizeof *s);
    s->slot = slot;
    s->used = 1;
    s->state = AD_AWAIT_HELLO;
    s->sink = sink;
    s->opened_us = now_us;
    s->id = dev->next_client_id++;
    peer_address(peer, s->addr);
    return s;
}

int ad_wants_close(const ad_session *s, int *code, const char **reason)
{
    if (!s->wants_close) return 0;
    if (code) *code = s->close_code;
    if (reason) *reason = s->close_reason;
    return 1;
}

int ad_can_receive(const ad_device *dev, const ad_session *s)
{
    return s->used && !s->wants_close && !s->call_pending && !s->auth_held
           && s->sink.room(s->sink.ctx) >= dev->cfg.max_reply_bytes;
}

/* ---- the message register -------------------------------------------------------------- */
#define REC_HEAD 16u /* id u32, n u16, pad u16, holders u64 */

static uint32_t rec_bytes(uint16_t n) { return (uint32_t)up8(REC_HEAD + 2u * n); }

static void rec_view(uint8_t *rec, ad_msg *m)
{
    memcpy(&m->id, rec, 4);
    memcpy(&m->n, rec + 4, 2);
    memcpy(&m->holders, rec + 8, 8);
    m->idx = (const uint16_t *)(rec + REC_HEAD);
    m->rec = rec;
}

int ad_msg_find(ad_device *dev, uint32_t id, ad_msg *out)
{
    uint32_t off = 0;
    while (off < dev->msg_pool_used) {
        rec_view(dev->msg_pool + off, out);
        if (out->id == id) return 0;
        off += rec_bytes(out->n);
    }
    return -1;
}

static void msg_set_holders(ad_msg *m, uint64_t holders)
{
    m->holders = holders;
    memcpy(m->rec + 8, &holders, 8);
}

static void msg_free(ad_device *dev, ad_msg *m)
{
    uint32_t size = rec_bytes(m->n);
    uint32_t off = (uint32_t)(m->rec - dev->msg_pool);
    memmove(m->rec, m->rec + size, dev->msg_pool_used - off - size);
    dev->msg_pool_used -= size;
    dev->n_messages--;
}

/* Let go of message `id` for session s: its stream stops; the last holder frees it. */
static void msg_release(ad_device *dev, ad_session *s, uint32_t id)
{
    ad_msg m;
    if (ad_msg_find(dev, id, &m)) return;
    uint64_t bit = 1ull << s->slot;
    if (!(m.holders & bit)) return;
    ad_stream_drop_message(dev, s, id);
    if (ad_msg_find(dev, id, &m)) return;
    msg_set_holders(&m, m.holders & ~bit);
    if (!m.holders) msg_free(dev, &m);
}

void ad_close(ad_device *dev, ad_session *s)
{
    if (!s || !s->used) return;
    ad_stream_drop_session(dev, s);
    uint64_t bit = 1ull << s->slot;
    uint32_t off = 0;
    while (off < dev->msg_pool_used) {
        ad_msg m;
        rec_view(dev->msg_pool + off, &m);
        if (m.holders & bit) {
            msg_set_holders(&m, m.holders & ~bit);
            if (!m.holders) { msg_free(dev, &m); continue; }
        }
        off += rec_bytes(m.n);
    }
    if (s->call_pending && dev->pending_calls) dev->pending_calls--;
    if (s->auth_held) ad_throttle_cancelled(&dev->throttle, s->auth_addr); /* never answered */
    s->auth_held = 0;
    dev->dropped_closed += s->dropped_samples;
    s->used = 0;
    s->state = AD_CLOSED;
}

/* ---- lookups ------------------------------------------------------------------------------ */
static int find_var(const ad_device *dev, const char *name, uint32_t len)
{
    for (uint32_t i = 0; i < dev->n_vars; i++)
        if (strlen(dev->vars[i].name) == len && !memcmp(dev->vars[i].name, name, len)) return (int)i;
    return -1;
}

static int find_fn(const ad_device *dev, const char *name, uint32_t len)
{
    for (uint32_t i = 0; i < dev->n_fns; i++)
        if (strlen(dev->fns[i].name) == len && !memcmp(dev->fns[i].name, name, len)) return (int)i;
    return -1;
}

static uint32_t edit_distance(const char *a, uint32_t la, const char *b)
{
    uint32_t lb = (uint32_t)strlen(b), row[65];
    if (la > 64 || lb > 64) return 99;
    for (uint32_t j = 0; j <= lb; j++) row[j] = j;
    for (uint32_t i = 1; i <= la; i++) {
        uint32_t prev = row[0];
        row[0] = i;
        for (uint32_t j = 1; j <= lb; j++) {
            uint32_t cur = row[j];
            uint32_t best = prev + (a[i - 1] != b[j - 1]);
            if (row[j] + 1 < best) best = row[j] + 1;
            if (row[j - 1] + 1 < best) best = row[j - 1] + 1;
            row[j] = best;
            prev = cur;
        }
    }
    return row[lb];
}

/* "; did you mean a, b?" for names close to the unknown one (as the Python endpoint). */
static void hint(const ad_device *dev, const char *name, uint32_t len, int want_fn, char *out,
                 size_t out_len)
{
    size_t used = 0;
    int n = 0;
    uint32_t limit = len / 4 + 1;
    out[0] = 0;
    uint32_t total = want_fn ? dev->n_fns : dev->n_vars;
    for (uint32_t i = 0; i < total && n < 3; i++) {
        const char *c = want_fn ? dev->fns[i].name : dev->vars[i].name;
        if (edit_distance(name, len, c) <= limit) {
            used += (size_t)ad_snprintf(out + used, out_len - used, "%s%s", n ? ", " : "; did you mean ", c);
            if (used >= out_len) break;
            n++;
        }
    }
    if (n && used + 1 < out_len) { out[used] = '?'; out[used + 1] = 0; }
}

/* 404 for an unknown variable (want_fn 0) or function (1): the other kind of the same name,
 * or the names close to it. Not inlined: its hint buffer would otherwise sit in the stack
 * frame of every request. */
AD_NOINLINE static int unknown_name(const ad_device *dev, const char *name, uint32_t len,
                                    int want_fn, char *why, size_t wl)
{
    char h[160];
    int shown = (int)(len > 80 ? 80 : len);
    if (want_fn ? find_var(dev, name, len) >= 0 : find_fn(dev, name, len) >= 0) {
        ad_snprintf(why, wl, want_fn ? "'%.*s' is a variable, not a function: READ, WRITE or stream it"
                                     : "'%.*s' is a function, not a variable: call it with INVOKE",
                     shown, name);
        return 404;
    }
    hint(dev, name, len, want_fn, h, sizeof h);
    ad_snprintf(why, wl, "no %s named '%.*s'%s", want_fn ? "function" : "variable", shown, name, h);
    return 404;
}

/* ---- request parsing ---------------------------------------------------------------------- */
enum { F_STR = 1, F_BIN = 2, F_INT = 4, F_NUM = 8, F_LIST = 16, F_NIL = 32 };

typedef struct field {
    const char *name;
    uint8_t accept;   /* F_* mask */
    uint8_t required;
    uint8_t present;
    ad_val v;         /* the value head; lists keep a reader positioned at their items */
    ad_rd items;
} field;

static const char *type_words(uint8_t accept)
{
    if (accept & F_LIST) return "list";
    if (accept & F_BIN) return "bytes";
    if (accept & F_NUM) return "int/float";
    if (accept & F_INT) return "int";
    if (accept & F_STR) return (accept & F_NIL) ? "str/NoneType" : "str";
    return "?";
}

static const char *val_type(const ad_val *v)
{
    static const char *const N[] = {"NoneType", "bool", "int", "int", "float", "str", "bytes",
                                    "list", "dict", "ExtType"};
    return v->t <= AD_VT_EXT ? N[v->t] : "?";
}

/* Read the args map; 0, or 400 with why. */
static int parse_args(ad_rd *rd, const ad_val *map, const char *op, field *f, int nf, char *why,
                      size_t wl)
{
    for (uint32_t k = 0; k < map->n; k++) {
        ad_val key, v;
        ad_rd_next(rd, &key);
        ad_rd at = *rd;
        ad_rd_next(rd, &v);
        int matched = -1;
        if (key.t == AD_VT_STR)
            for (int i = 0; i < nf; i++)
                if (strlen(f[i].name) == key.n && !memcmp(f[i].name, key.p, key.n)) matched = i;
        if (matched >= 0) {
            f[matched].present = 1;
            f[matched].v = v;
            f[matched].items = *rd;
            (void)at;
        }
        ad_rd_skip_items(rd, &v);
    }
    for (int i = 0; i < nf; i++) {
        ad_val *v = &f[i].v;
        if (!f[i].present || (v->t == AD_VT_NIL && !f[i].required)) {
            if (f[i].required) { ad_snprintf(why, wl, "%s: missing field '%s'", op, f[i].name); return 400; }
            f[i].present = 0;
            continue;
        }
        uint8_t a = f[i].accept;
        int ok = (v->t == AD_VT_STR && (a & F_STR)) || (v->t == AD_VT_BIN && (a & F_BIN))
                 || ((v->t == AD_VT_UINT || v->t == AD_VT_INT) && (a & (F_INT | F_NUM)))
                 || (v->t == AD_VT_FLOAT && (a & F_NUM)) || (v->t == AD_VT_ARRAY && (a & F_LIST))
                 || (v->t == AD_VT_NIL && (a & F_NIL));
        if (!ok) {
            ad_snprintf(why, wl, "%s: field '%s' must be %s, got %s", op, f[i].name, type_words(a),
                     val_type(v));
            return 400;
        }
    }
    return 0;
}

static int64_t field_int(const field *f)
{
    return f->v.t == AD_VT_UINT ? (f->v.u > (uint64_t)INT64_MAX ? INT64_MAX : (int64_t)f->v.u) : f->v.i;
}

/* ---- replies ------------------------------------------------------------------------------- */
static void ok_head(ad_wr *w, uint64_t seq, uint32_t n_keys)
{
    ad_wr_array(w, 3);
    ad_wr_str(w, "OK");
    ad_wr_uint(w, seq);
    ad_wr_map(w, n_keys);
}

static int finish(ad_device *dev, ad_session *s, ad_wr *w, uint64_t seq, char *why, size_t wl)
{
    if (w->overflow) {
        ad_snprintf(why, wl, "the reply takes %zu bytes; this device builds frames of at most %u "
                 "bytes (use a LIST prefix or a shorter message)", w->used, dev->cfg.max_reply_bytes);
        return 413;
    }
    (void)seq;
    ad_send_frame(dev, s, w);
    return 0;
}

void ad_var_type(const ad_device *dev, uint32_t i, ad_type *out)
{
    const ad_var_rt *rt = &dev->vrt[i];
    if (rt->ndim > 1) {
        ad_parse_type(dev->vars[i].type, strlen(dev->vars[i].type), out);
    } else {
        memset(out, 0, sizeof *out);
        out->base = rt->base;
        out->ndim = rt->ndim;
        out->shape[0] = rt->count;
        out->count = rt->count;
    }
    out->c_size = rt->c_size;
}

static void read_value_locked(ad_device *dev, uint32_t idx, ad_wr *w)
{
    ad_type t;
    ad_var_type(dev, idx, &t);
    ad_write_value(w, &t, dev->vars[idx].type, dev->vars[idx].ptr);
}

/* ---- commands ----------------------------------------------------------------------------- */
typedef struct req {
    const char *op;
    uint64_t seq;
    ad_rd rd;       /* positioned at the args map's items */
    ad_val args;    /* the args map head */
} req;

static void write_list(const ad_device *dev, ad_wr *w, uint64_t seq, const char *pre,
                       uint32_t plen)
{
    uint32_t n = 0;
    for (uint32_t i = 0; i < dev->n_vars; i++) n += !strncmp(dev->vars[i].name, pre, plen) || !plen;
    for (uint32_t i = 0; i < dev->n_fns; i++) n += !strncmp(dev->fns[i].name, pre, plen) || !plen;
    ok_head(w, seq, 1);
    ad_wr_str(w, "entries");
    ad_wr_array(w, n);
    for (uint32_t i = 0; i < dev->n_vars; i++) {
        const ad_var *v = &dev->vars[i];
        if (plen && strncmp(v->name, pre, plen)) continue;
        ad_wr_map(w, 6u + v->has_min + v->has_max);
        ad_wr_str(w, "name"); ad_wr_str(w, v->name);
        ad_wr_str(w, "type"); ad_wr_str(w, v->type);
        ad_wr_str(w, "kind"); ad_wr_str(w, v->kind == AD_PARAMETER ? "parameter" : "signal");
        ad_wr_str(w, "access"); ad_wr_str(w, v->access == AD_RW ? "rw" : "r");
        ad_wr_str(w, "unit"); ad_wr_str(w, v->unit ? v->unit : "");
        ad_wr_str(w, "doc"); ad_wr_str(w, v->doc ? v->doc : "");
        if (v->has_min) { ad_wr_str(w, "min"); ad_wr_f64(w, v->min); }
        if (v->has_max) { ad_wr_str(w, "max"); ad_wr_f64(w, v->max); }
    }
    for (uint32_t i = 0; i < dev->n_fns; i++) {
        const ad_fn *fn = &dev->fns[i];
        if (plen && strncmp(fn->name, pre, plen)) continue;
        ad_wr_map(w, 6);
        ad_wr_str(w, "name"); ad_wr_str(w, fn->name);
        ad_wr_str(w, "type"); ad_wr_str(w, fn->signature);
        ad_wr_str(w, "kind"); ad_wr_str(w, "function");
        ad_wr_str(w, "access"); ad_wr_str(w, "x");
        ad_wr_str(w, "unit"); ad_wr_str(w, "");
        ad_wr_str(w, "doc"); ad_wr_str(w, fn->doc ? fn->doc : "");
    }
}

static void spill_to_sink(void *ctx, const uint8_t *bytes, size_t n)
{
    const ad_sink *sink = (const ad_sink *)ctx;
    sink->part(sink->ctx, bytes, n);
}

/* LIST grows with the registry: a reply larger than the scratch goes out in parts when the
 * transport takes parts (the framed link, TCP), else it is refused (413, use a prefix). */
static int cmd_list(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    field f[] = {{"prefix", F_STR, 0, 0, {0}, {0}}};
    int rc = parse_args(&r->rd, &r->args, r->op, f, 1, why, wl);
    if (rc) return rc;
    const char *pre = f[0].present ? (const char *)f[0].v.p : "";
    uint32_t plen = f[0].present ? f[0].v.n : 0;
    ad_wr w;
    begin(dev, &w);
    write_list(dev, &w, r->seq, pre, plen);
    if (!w.overflow || !s->sink.begin || s->sink.begin(s->sink.ctx, w.used))
        return finish(dev, s, &w, r->seq, why, wl); /* whole, or 413 */
    ad_wr_init_spill(&w, dev->scratch, dev->cfg.max_reply_bytes, spill_to_sink, &s->sink);
    write_list(dev, &w, r->seq, pre, plen);
    ad_wr_flush(&w);
    s->sink.end(s->sink.ctx);
    return 0;
}

static int cmd_define(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    field f[] = {{"names", F_LIST, 1, 0, {0}, {0}}};
    int rc = parse_args(&r->rd, &r->args, r->op, f, 1, why, wl);
    if (rc) return rc;
    uint32_t n = f[0].v.n;
    if (!n) { ad_snprintf(why, wl, "DEFINE: field 'names' must be a non-empty array of names"); return 400; }
    /* names are checked as strings first (400), then the limit (413), then looked up (404) */
    ad_rd it = f[0].items;
    for (uint32_t k = 0; k < n; k++) {
        ad_val v;
        ad_rd_next(&it, &v);
        if (v.t != AD_VT_STR) { ad_snprintf(why, wl, "DEFINE: every entry of 'names' must be a string"); return 400; }
        ad_rd_skip_items(&it, &v);
    }
    if (n > dev->cfg.max_names_per_message) {
        ad_snprintf(why, wl, "DEFINE of %u names; at most %u per message", n, dev->cfg.max_names_per_message);
        return 413;
    }
    uint32_t need = rec_bytes((uint16_t)n);
    if (n > 0xffff) { ad_snprintf(why, wl, "DEFINE of %u names; at most 65535", n); return 413; }
    /* build the record at the end of the pool; it becomes the message if new */
    if (dev->msg_pool_used + need > dev->msg_pool_bytes) {
        /* a message of the same names may still exist: the lookup below needs no room */
        need = 0;
    }
    uint16_t stack_idx[64];
    uint16_t *idx = need ? (uint16_t *)(dev->msg_pool + dev->msg_pool_used + REC_HEAD)
                         : (n <= 64 ? stack_idx : NULL);
    if (!idx) { ad_snprintf(why, wl, "the register is full (%u bytes); UNDEFINE some first", dev->msg_pool_bytes); return 429; }
    it = f[0].items;
    for (uint32_t k = 0; k < n; k++) {
        ad_val v;
        ad_rd_next(&it, &v);
        int i = find_var(dev, (const char *)v.p, v.n);
        if (i < 0) return unknown_name(dev, (const char *)v.p, v.n, 0, why, wl);
        idx[k] = (uint16_t)i;
    }
    /* the same list already registered: the same ID */
    uint32_t off = 0;
    ad_msg m;
    int found = 0;
    while (off < dev->msg_pool_used) {
        rec_view(dev->msg_pool + off, &m);
        if (m.n == n && !memcmp(m.idx, idx, 2u * n)) { found = 1; break; }
        off += rec_bytes(m.n);
    }
    if (!found) {
        if (dev->n_messages >= dev->cfg.max_messages) {
            ad_snprintf(why, wl, "the register holds %u messages; UNDEFINE some first", dev->cfg.max_messages);
            return 429;
        }
        if (!need) { ad_snprintf(why, wl, "the register is full (%u bytes); UNDEFINE some first", dev->msg_pool_bytes); return 429; }
        uint8_t *rec = dev->msg_pool + dev->msg_pool_used;
        uint32_t id = dev->next_msg++;
        uint16_t n16 = (uint16_t)n;
        uint64_t zero = 0;
        memcpy(rec, &id, 4);
        memcpy(rec + 4, &n16, 2);
        memset(rec + 6, 0, 2);
        memcpy(rec + 8, &zero, 8);
        dev->msg_pool_used += rec_bytes(n16);
        dev->n_messages++;
        rec_view(rec, &m);
    }
    msg_set_holders(&m, m.holders | (1ull << s->slot));
    ad_wr w;
    begin(dev, &w);
    ok_head(&w, r->seq, 2);
    ad_wr_str(&w, "msg"); ad_wr_uint(&w, m.id);
    ad_wr_str(&w, "types"); ad_wr_array(&w, m.n);
    for (uint32_t k = 0; k < m.n; k++) ad_wr_str(&w, dev->vars[m.idx[k]].type);
    return finish(dev, s, &w, r->seq, why, wl);
}

static int own_message(ad_device *dev, ad_session *s, int64_t id, ad_msg *m, char *why, size_t wl)
{
    if (id < 0 || id > 0xffffffffll || ad_msg_find(dev, (uint32_t)id, m) || !(m->holders & (1ull << s->slot))) {
        ad_snprintf(why, wl, "message %lld is not defined on this connection; DEFINE it first", (long long)id);
        return 404;
    }
    return 0;
}

static int cmd_msg_only(ad_device *dev, ad_session *s, req *r, ad_msg *m, int64_t *id, char *why,
                        size_t wl)
{
    field f[] = {{"msg", F_INT, 1, 0, {0}, {0}}};
    int rc = parse_args(&r->rd, &r->args, r->op, f, 1, why, wl);
    if (rc) return rc;
    *id = field_int(&f[0]);
    return m ? own_message(dev, s, *id, m, why, wl) : 0;
}

static int cmd_undefine(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    ad_msg m;
    int64_t id;
    int rc = cmd_msg_only(dev, s, r, &m, &id, why, wl);
    if (rc) return rc;
    msg_release(dev, s, (uint32_t)id);
    ad_wr w;
    begin(dev, &w);
    ok_head(&w, r->seq, 0);
    return finish(dev, s, &w, r->seq, why, wl);
}

static int cmd_read(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    ad_msg m;
    int64_t id, tick, t_us;
    int rc = cmd_msg_only(dev, s, r, &m, &id, why, wl);
    if (rc) return rc;
    ad_wr w;
    begin(dev, &w);
    ok_head(&w, r->seq, 3);
    ad_port_lock();
    ad_last_tick(dev, &tick, &t_us);
    ad_wr_str(&w, "tick"); ad_wr_int(&w, tick);
    ad_wr_str(&w, "t_us"); ad_wr_int(&w, t_us);
    ad_wr_str(&w, "values"); ad_wr_array(&w, m.n);
    for (uint32_t k = 0; k < m.n; k++) read_value_locked(dev, m.idx[k], &w);
    ad_port_unlock();
    return finish(dev, s, &w, r->seq, why, wl);
}

static void fmt_bound(char *out, size_t n, double v, const char *unit)
{
    ad_snprintf(out, n, "%g%s%s", v, unit && *unit ? " " : "", unit ? unit : "");
}

static int check_range(const ad_var *v, const ad_type *t, const void *value, char *why, size_t wl)
{
    if (!v->has_min && !v->has_max) return 0;
    const char *unit = v->unit ? v->unit : "";
    const char *sp = *unit ? " " : "";
    uint32_t isz = ad_scalar_size(t->base);
    for (uint32_t k = 0; k < t->count; k++) {
        double x = ad_load_f64(t->base, (const uint8_t *)value + (size_t)k * isz);
        int low = v->has_min && !(x >= v->min);
        int high = v->has_max && !(x <= v->max);
        if (isnan(x)) { low = v->has_min; high = !low; }
        if (low || high) {
            char lo[48], hi[48];
            if (v->has_min) ad_snprintf(lo, sizeof lo, "%g", v->min); else ad_snprintf(lo, sizeof lo, "-∞");
            if (v->has_max) ad_snprintf(hi, sizeof hi, "%g", v->max); else ad_snprintf(hi, sizeof hi, "∞");
            char bad[48], bound[64];
            ad_snprintf(bad, sizeof bad, "%g", x);
            fmt_bound(bound, sizeof bound, low ? v->min : v->max, unit);
            ad_snprintf(why, wl, "%s = %s%s%s is %s its %s %s; allowed %s..%s%s%s", v->name, bad, sp,
                     unit, low ? "below" : "above", low ? "minimum" : "maximum", bound, lo, hi,
                     sp, unit);
            return 422;
        }
    }
    return 0;
}

static int cmd_write(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    field f[] = {{"msg", F_INT, 1, 0, {0}, {0}}, {"values", F_LIST, 1, 0, {0}, {0}}};
    int rc = parse_args(&r->rd, &r->args, r->op, f, 2, why, wl);
    if (rc) return rc;
    ad_msg m;
    int64_t id = field_int(&f[0]);
    rc = own_message(dev, s, id, &m, why, wl);
    if (rc) return rc;
    if (f[1].v.n != m.n) {
        ad_snprintf(why, wl, "WRITE of message %lld: %u values for %u variables", (long long)id,
                 f[1].v.n, m.n);
        return 422;
    }
    for (uint32_t k = 0; k < m.n; k++) {
        const ad_var *v = &dev->vars[m.idx[k]];
        if (v->access != AD_RW) {
            ad_snprintf(why, wl, "%s is read-only (kind %s, access r)", v->name,
                     v->kind == AD_PARAMETER ? "parameter" : "signal");
            return 405;
        }
    }
    /* coerce every value into the stage, check every range, then apply all of them */
    ad_rd it = f[1].items;
    uint32_t off = 0;
    for (uint32_t k = 0; k < m.n; k++) {
        const ad_var *v = &dev->vars[m.idx[k]];
        ad_type type;
        ad_var_type(dev, m.idx[k], &type);
        const ad_type *t = &type;
        if (off + up8(t->c_size) > dev->stage_bytes) {
            ad_snprintf(why, wl, "WRITE of message %lld is larger than this device stages", (long long)id);
            return 413;
        }
        rc = ad_coerce(&it, t, v->type, dev->stage + off, v->name, why, wl);
        if (rc) return rc;
        rc = check_range(v, t, dev->stage + off, why, wl);
        if (rc) return rc;
        if (v->check) {
            char reason[160] = "";
            if (v->check(v, dev->stage + off, reason, sizeof reason)) {
                ad_snprintf(why, wl, "%s: the device refused the value: %s", v->name, reason);
                return 422;
            }
        }
        off += (uint32_t)up8(t->c_size);
    }
    int64_t tick, t_us;
    ad_port_lock();
    off = 0;
    for (uint32_t k = 0; k < m.n; k++) {
        uint32_t size = dev->vrt[m.idx[k]].c_size;
        memcpy(dev->vars[m.idx[k]].ptr, dev->stage + off, size);
        off += (uint32_t)up8(size);
    }
    ad_last_tick(dev, &tick, &t_us);
    ad_port_unlock();
    ad_wr w;
    begin(dev, &w);
    ok_head(&w, r->seq, 1);
    ad_wr_str(&w, "tick"); ad_wr_int(&w, tick);
    return finish(dev, s, &w, r->seq, why, wl);
}

/* ---- INVOKE ------------------------------------------------------------------------------- */
static int coerce_arg(ad_device *dev, ad_rd *rd, const ad_fn *fn, const ad_arg *a,
                      ad_argval *out, char *why, size_t wl)
{
    char where[120];
    ad_snprintf(where, sizeof where, "%s(%.*s)", fn->name, (int)a->name_len, a->name);
    const ad_type *t = &a->type;
    if (t->base == AD_T_STR) {
        ad_val v;
        ad_rd_next(rd, &v);
        if (v.t != AD_VT_STR) {
            ad_snprintf(why, wl, "%s: expected str, got %s", where, val_type(&v));
            ad_rd_skip_items(rd, &v);
            return 422;
        }
        out->form = 3;
        out->data = v.p;
        out->len = v.n;
        return 0;
    }
    if (t->ndim == 0) {
        uint8_t tmp[8];
        int rc = ad_coerce(rd, t, "", tmp, where, why, wl);
        if (rc) return rc;
        out->form = 0;
        out->dtype = t->base;
        if (t->base >= 9) out->v.f = ad_load_f64(t->base, tmp);
        else if (t->base == 8) memcpy(&out->v.u, tmp, 8);
        else out->v.i = ad_load_i64(t->base, tmp);
        return 0;
    }
    /* arrays: an ext 1 of the declared dtype is used in place; anything else is coerced
     * element by element into the argument buffer */
    ad_rd peek = *rd;
    ad_val v;
    ad_rd_next(&peek, &v);
    uint32_t count = t->ndim == AD_VARLEN ? 0 : t->count;
    if (v.t == AD_VT_EXT && v.ext_type == AD_EXT_NDARRAY) {
        ad_ndarray arr;
        ad_parse_ndarray(v.p, v.n, &arr);
        if (t->ndim == AD_VARLEN && arr.ndim != 1) {
            ad_snprintf(why, wl, "%s: expected a 1-D array %.*s, got %u dimensions", where,
                     (int)a->type_len, a->type_text, arr.ndim);
            return 422;
        }
        if (arr.dtype == t->base && (t->ndim == AD_VARLEN || arr.count == t->count)) {
            *rd = peek;
            out->form = 1;
            out->dtype = arr.dtype;
            out->len = arr.count;
            out->data = arr.data;
            return 0;
        }
        count = arr.count;
    } else if (v.t == AD_VT_ARRAY && t->ndim == AD_VARLEN) {
        count = v.n;
        /* a 1-D array: every element a number */
    } else if (v.t != AD_VT_ARRAY) {
        ad_snprintf(why, wl, "%s: expected an array %.*s, got %s", where, (int)a->type_len,
                 a->type_text, val_type(&v));
        ad_rd_skip_items(rd, &v);
        return 422;
    }
    uint32_t isz = ad_scalar_size(t->base);
    uint64_t bytes = (uint64_t)count * isz;
    if (dev->argbuf_used + bytes > dev->argbuf_bytes) {
        ad_snprintf(why, wl, "%s: %u elements do not fit this device's argument buffer (%u bytes)",
                 where, count, dev->argbuf_bytes);
        return 413;
    }
    ad_type tt = *t;
    if (tt.ndim == AD_VARLEN) { tt.ndim = 1; tt.shape[0] = count; tt.count = count; }
    tt.c_size = (uint32_t)bytes;
    uint8_t *dst = dev->argbuf + dev->argbuf_used;
    int rc = ad_coerce(rd, &tt, "", dst, where, why, wl);
    if (rc) return rc;
    dev->argbuf_used += (uint32_t)up8((size_t)bytes);
    out->form = 2;
    out->dtype = t->base;
    out->len = count;
    out->data = dst;
    return 0;
}

static void write_result(ad_wr *w, ad_call *c)
{
    if (!c->has_result || c->ret.base == AD_T_NONE) { ad_wr_nil(w); return; }
    switch (c->result_kind) {
    case 1: ad_wr_f64(w, c->result.f); break;
    case 2: ad_wr_int(w, c->result.i); break;
    case 3: ad_wr_uint(w, c->result.u); break;
    case 4: ad_wr_bool(w, (int)c->result.u); break;
    case 5: ad_wr_strn(w, (const char *)c->result_ptr, c->result_len); break;
    case 6: {
        uint32_t shape[1] = {c->result_len};
        ad_wr_ext(w, AD_EXT_NDARRAY, ad_ndarray_head_bytes(1) + 8u * c->result_len);
        ad_wr_ndarray_head(w, 10, 1, shape);
        ad_wr_raw(w, c->result_ptr, 8u * c->result_len);
        break;
    }
    default: ad_wr_nil(w); break;
    }
}

/* the declared return type decides; a mismatch is the device's bug: ERR 500 */
static const char *return_type(const ad_fn *fn)
{
    const char *p = fn->signature;
    while (*p && !(p[0] == ')' && p[1] == '-' && p[2] == '>')) p++;
    return *p ? p + 3 : p;
}

static int check_result(ad_call *c, char *why, size_t wl)
{
    const ad_type *t = &c->ret;
    if (t->base == AD_T_NONE) return 0;
    if (!c->has_result) {
        ad_snprintf(why, wl, "%s returned no value; its declared type is %s", c->fn->name,
                 return_type(c->fn));
        return 500;
    }
    int ok;
    if (t->ndim) ok = c->result_kind == 6 && t->base == 10 && c->result_len == t->count;
    else if (t->base == AD_T_STR) ok = c->result_kind == 5;
    else if (t->base == 0) ok = c->result_kind == 4;
    else if (t->base >= 9) ok = c->result_kind == 1;
    else ok = c->result_kind == 2 || c->result_kind == 3;
    if (!ok) {
        ad_snprintf(why, wl, "%s returned a value that does not match its declared type %s",
                 c->fn->name, return_type(c->fn));
        return 500;
    }
    return 0;
}

static int reply_call(ad_device *dev, ad_session *s, ad_call *c, char *why, size_t wl)
{
    int rc = check_result(c, why, wl);
    if (rc) return rc;
    ad_wr w;
    begin(dev, &w);
    ok_head(&w, c->seq, 1);
    ad_wr_str(&w, "value");
    write_result(&w, c);
    return finish(dev, s, &w, c->seq, why, wl);
}

static int run_call(ad_device *dev, ad_session *s, ad_call *c, int rc, char *why, size_t wl)
{
    if (rc == AD_PENDING && c->resume) {
        if (dev->pending_calls >= dev->cfg.max_pending_calls) {
            ad_snprintf(why, wl, "too many calls waiting at once: at most %u", dev->cfg.max_pending_calls);
            return 429;
        }
        dev->pending_calls++;
        s->call_pending = 1;
        return -1; /* answered later, from ad_poll */
    }
    if (rc != AD_OK) {
        ad_snprintf(why, wl, "%s failed: %s", c->fn->name, c->fail[0] ? c->fail : "the device function failed");
        return 500;
    }
    return reply_call(dev, s, c, why, wl);
}

static int cmd_invoke(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    field f[] = {{"name", F_STR, 1, 0, {0}, {0}}, {"args", F_LIST, 0, 0, {0}, {0}}};
    int rc = parse_args(&r->rd, &r->args, r->op, f, 2, why, wl);
    if (rc) return rc;
    const char *name = (const char *)f[0].v.p;
    uint32_t nlen = f[0].v.n;
    int i = find_fn(dev, name, nlen);
    if (i < 0) return unknown_name(dev, name, nlen, 1, why, wl);
    const ad_fn *fn = &dev->fns[i];
    sig_it sig;
    ad_type ret;
    uint8_t n_args;
    sig_begin(fn->signature, &sig, &ret, &n_args); /* checked at ad_init */
    uint32_t given = f[1].present ? f[1].v.n : 0;
    if (given != n_args) {
        ad_snprintf(why, wl, "%s takes %u arguments %s, got %u", fn->name, n_args, fn->signature, given);
        return 422;
    }
    ad_call *c = &s->call;
    memset(c, 0, sizeof *c);
    c->dev = dev;
    c->session = s;
    c->fn = fn;
    c->n_args = n_args;
    c->ret = ret;
    c->seq = r->seq;
    dev->argbuf_used = 0;
    ad_rd it = f[1].items;
    for (uint32_t k = 0; k < n_args; k++) {
        ad_arg a;
        sig_next(&sig, &a);
        rc = coerce_arg(dev, &it, fn, &a, &c->args[k], why, wl);
        if (rc) return rc;
    }
    ad_port_lock();
    rc = fn->fn(c, fn->user);
    ad_port_unlock();
    return run_call(dev, s, c, rc, why, wl);
}

static void poll_calls(ad_device *dev, int64_t now_us)
{
    char why[400];
    for (uint32_t i = 0; i < dev->n_sessions; i++) {
        ad_session *s = &dev->sessions[i];
        if (!s->used || !s->call_pending) continue;
        ad_call *c = &s->call;
        ad_port_lock();
        int rc = c->resume(c, c->fn->user, now_us);
        ad_port_unlock();
        if (rc == AD_PENDING) continue;
        s->call_pending = 0;
        dev->pending_calls--;
        int code = rc == AD_OK ? reply_call(dev, s, c, why, sizeof why) : 0;
        if (rc != AD_OK) {
            ad_snprintf(why, sizeof why, "%s failed: %s", c->fn->name, c->fail[0] ? c->fail : "the device function failed");
            code = 500;
        }
        if (code) send_error_raw(dev, s->sink, 1, c->seq, code, why);
    }
}

/* ---- STREAM, PING, STATS --------------------------------------------------------------------- */
static int cmd_stream_start(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    field f[] = {{"msg", F_INT, 1, 0, {0}, {0}}, {"rate_hz", F_NUM, 1, 0, {0}, {0}}};
    int rc = parse_args(&r->rd, &r->args, r->op, f, 2, why, wl);
    if (rc) return rc;
    ad_msg m;
    int64_t id = field_int(&f[0]);
    rc = own_message(dev, s, id, &m, why, wl);
    if (rc) return rc;
    double rate = f[1].v.t == AD_VT_FLOAT ? f[1].v.f
                : f[1].v.t == AD_VT_UINT ? (double)f[1].v.u : (double)f[1].v.i;
    ad_wr w;
    begin(dev, &w);
    rc = ad_stream_start(dev, s, (uint32_t)id, rate, &w, r->seq, why, wl);
    if (rc) return rc;
    return finish(dev, s, &w, r->seq, why, wl);
}

static int cmd_stream_stop(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    int64_t id;
    int rc = cmd_msg_only(dev, s, r, NULL, &id, why, wl);
    if (rc) return rc;
    if (id < 0 || id > 0xffffffffll || ad_stream_stop(dev, s, (uint32_t)id)) {
        ad_snprintf(why, wl, "no stream of message %lld runs on this connection", (long long)id);
        return 404;
    }
    ad_wr w;
    begin(dev, &w);
    ok_head(&w, r->seq, 0);
    return finish(dev, s, &w, r->seq, why, wl);
}

static int cmd_ping(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    int64_t tick, t_us;
    ad_port_lock();
    ad_last_tick(dev, &tick, &t_us);
    ad_port_unlock();
    ad_wr w;
    begin(dev, &w);
    ok_head(&w, r->seq, 3);
    ad_wr_str(&w, "t_us"); ad_wr_timestamp(&w, ad_port_wall_us());
    ad_wr_str(&w, "tick"); ad_wr_int(&w, tick);
    ad_wr_str(&w, "tick_t_us");
    if (tick >= 0) ad_wr_int(&w, t_us); else ad_wr_nil(&w);
    return finish(dev, s, &w, r->seq, why, wl);
}

void ad_get_stats(const ad_device *dev, ad_stats *o)
{
    memset(o, 0, sizeof *o);
    int64_t tick, t_us;
    counts(dev, &o->clients, &o->pending);
    o->clients += o->pending;
    for (uint32_t i = 0; i < dev->n_sessions; i++)
        if (dev->sessions[i].used) {
            o->streams += dev->sessions[i].n_streams;
            o->dropped_samples += dev->sessions[i].dropped_samples;
        }
    for (uint32_t i = 0; i < dev->cfg.max_samplers; i++) o->samplers += dev->samplers[i].used;
    o->messages = dev->n_messages;
    ad_port_lock();
    ad_last_tick((ad_device *)dev, &tick, &t_us);
    ad_port_unlock();
    o->tick = (uint64_t)tick;
    o->t_us = t_us;
    o->dropped_samples += dev->dropped_closed;
    o->ring_lost_samples = dev->ring_lost;
    o->auth_checked = dev->throttle.checked;
    o->auth_refused = dev->throttle.refused;
    o->auth_failures = dev->throttle.failures;
    o->auth_addresses = ad_throttle_tracked(&dev->throttle, dev->now_us);
}

/* packets go to the transport at once: its buffer is the queue */
static uint64_t queued(const ad_session *c)
{
    return c->sink.queued ? c->sink.queued(c->sink.ctx) : 0;
}

static int cmd_stats(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    ad_stats st;
    ad_get_stats(dev, &st);
    uint32_t n = 0;
    for (uint32_t i = 0; i < dev->n_sessions; i++) n += dev->sessions[i].used && dev->sessions[i].state != AD_CLOSED;
    ad_wr w;
    begin(dev, &w);
    ok_head(&w, r->seq, 10);
    ad_wr_str(&w, "clients"); ad_wr_uint(&w, st.clients);
    ad_wr_str(&w, "pending"); ad_wr_uint(&w, st.pending);
    ad_wr_str(&w, "streams"); ad_wr_uint(&w, st.streams);
    ad_wr_str(&w, "sampling_groups"); ad_wr_uint(&w, st.samplers);
    ad_wr_str(&w, "messages"); ad_wr_uint(&w, st.messages);
    ad_wr_str(&w, "tick"); ad_wr_int(&w, (int64_t)st.tick);
    ad_wr_str(&w, "t_us"); ad_wr_int(&w, st.t_us);
    ad_wr_str(&w, "dropped_samples"); ad_wr_uint(&w, st.dropped_samples);
    ad_wr_str(&w, "queue_depths"); ad_wr_map(&w, n);
    for (uint32_t i = 0; i < dev->n_sessions; i++) {
        const ad_session *c = &dev->sessions[i];
        if (!c->used || c->state == AD_CLOSED) continue;
        char id[16];
        ad_snprintf(id, sizeof id, "%u", c->id);
        ad_wr_str(&w, id);
        ad_wr_uint(&w, queued(c));
    }
    ad_wr_str(&w, "per_client"); ad_wr_array(&w, n);
    for (uint32_t i = 0; i < dev->n_sessions; i++) {
        const ad_session *c = &dev->sessions[i];
        if (!c->used || c->state == AD_CLOSED) continue;
        ad_wr_map(&w, 7);
        ad_wr_str(&w, "id"); ad_wr_uint(&w, c->id);
        ad_wr_str(&w, "name"); ad_wr_str(&w, c->name);
        ad_wr_str(&w, "role"); ad_wr_str(&w, ROLE_NAMES[c->role]);
        ad_wr_str(&w, "streams"); ad_wr_uint(&w, c->n_streams);
        ad_wr_str(&w, "queue_depth"); ad_wr_uint(&w, queued(c));
        ad_wr_str(&w, "dropped_samples"); ad_wr_uint(&w, c->dropped_samples);
        ad_wr_str(&w, "dropped_packets"); ad_wr_uint(&w, c->dropped_packets);
    }
    return finish(dev, s, &w, r->seq, why, wl);
}

/* ---- HELLO, AUTH, BYE --------------------------------------------------------------------- */
static int auth_required(const ad_device *dev)
{
    return dev->cfg.operator_password || dev->cfg.observer_password;
}

static void hello_reply(ad_device *dev, ad_session *s, uint64_t seq)
{
    const ad_config *c = &dev->cfg;
    ad_wr w;
    begin(dev, &w);
    ok_head(&w, seq, 7);
    ad_wr_str(&w, "version"); ad_wr_str(&w, AD_VERSION);
    ad_wr_str(&w, "server"); ad_wr_str(&w, c->name);
    ad_wr_str(&w, "auth");
    if (auth_required(dev)) ad_wr_str(&w, "hmac-sha256"); else ad_wr_nil(&w);
    ad_wr_str(&w, "nonce"); ad_wr_bin(&w, s->nonce, auth_required(dev) ? 32 : 0);
    ad_wr_str(&w, "role");
    if (s->role) ad_wr_str(&w, ROLE_NAMES[s->role]); else ad_wr_nil(&w);
    ad_wr_str(&w, "loop_rate_hz"); ad_wr_f64(&w, c->loop_rate_hz);
    ad_wr_str(&w, "limits"); ad_wr_map(&w, 13);
    ad_wr_str(&w, "max_frame_bytes"); ad_wr_uint(&w, c->max_frame_bytes);
    ad_wr_str(&w, "max_depth"); ad_wr_uint(&w, c->max_depth);
    ad_wr_str(&w, "max_array_len"); ad_wr_uint(&w, c->max_array_len);
    ad_wr_str(&w, "max_str_bytes"); ad_wr_uint(&w, c->max_str_bytes);
    ad_wr_str(&w, "max_messages"); ad_wr_uint(&w, c->max_messages);
    ad_wr_str(&w, "max_names_per_message"); ad_wr_uint(&w, c->max_names_per_message);
    ad_wr_str(&w, "max_streams_per_client"); ad_wr_uint(&w, c->max_streams_per_client);
    ad_wr_str(&w, "auth_timeout_s"); ad_wr_f64(&w, c->auth_timeout_s);
    ad_wr_str(&w, "queue_packets"); ad_wr_uint(&w, c->queue_packets);
    ad_wr_str(&w, "max_clients"); ad_wr_uint(&w, c->max_clients);
    ad_wr_str(&w, "max_pending"); ad_wr_uint(&w, c->max_pending);
    ad_wr_str(&w, "max_pending_frame_bytes"); ad_wr_uint(&w, c->max_pending_frame_bytes);
    ad_wr_str(&w, "max_pending_frames"); ad_wr_uint(&w, c->max_pending_frames);
    ad_send_frame(dev, s, &w);
}

static int cmd_hello(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    field f[] = {{"version", F_STR, 1, 0, {0}, {0}}, {"client", F_STR, 0, 0, {0}, {0}}};
    int rc = parse_args(&r->rd, &r->args, r->op, f, 2, why, wl);
    if (rc) return rc;
    const char *v = (const char *)f[0].v.p;
    uint32_t n = f[0].v.n, major = 0;
    while (major < n && v[major] != '.') major++;
    if (major != 1 || v[0] != '1') {
        ad_snprintf(why, wl, "protocol version '%.*s' is not supported; this endpoint speaks %s",
                 (int)(n > 40 ? 40 : n), v, AD_VERSION);
        return 426;
    }
    if (f[1].present) {
        uint32_t cn = f[1].v.n > 64 ? 64 : f[1].v.n;
        /* keep whole UTF-8 characters */
        while (cn && cn < f[1].v.n && (f[1].v.p[cn] & 0xc0) == 0x80) cn--;
        memcpy(s->name, f[1].v.p, cn);
        s->name[cn] = 0;
    }
    if (!auth_required(dev)) {
        char buf[160];
        const char *refusal = admit_refusal(dev, buf, sizeof buf);
        if (refusal) { ad_snprintf(why, wl, "%s", refusal); return 429; }
        s->role = AD_ROLE_OPERATOR;
        s->state = AD_READY;
    } else {
        if (ad_port_random(s->nonce, 32)) { ad_snprintf(why, wl, "no random source"); return 500; }
        s->state = AD_AWAIT_AUTH;
    }
    hello_reply(dev, s, r->seq);
    return 0;
}

/* Answer a held AUTH (its turn has come) and report its outcome to the throttle; `why`
 * is the caller's buffer (the MCU's stack is small). */
AD_NOINLINE static void answer_auth(ad_device *dev, ad_session *s, int64_t now_us, char *why, size_t wl)
{
    s->auth_held = 0;
    if (s->auth_granted == AD_ROLE_NONE) {
        ad_auth_failure f;
        ad_throttle_failed(&dev->throttle, s->auth_addr, now_us, &f);
        fail(dev, s, 1, s->auth_seq, 401, "authentication failed: wrong password", 1);
        if (dev->cfg.on_auth_failure) dev->cfg.on_auth_failure(dev->cfg.auth_user, s->addr, &f);
        return;
    }
    const char *refusal = admit_refusal(dev, why, wl);
    if (refusal) { /* no client slot: not a guess */
        ad_throttle_cancelled(&dev->throttle, s->auth_addr);
        fail(dev, s, 1, s->auth_seq, 429, refusal, 1);
        return;
    }
    ad_throttle_succeeded(&dev->throttle, s->auth_addr);
    s->role = s->auth_granted;
    s->state = AD_READY;
    ad_wr w;
    begin(dev, &w);
    ok_head(&w, s->auth_seq, 2);
    ad_wr_str(&w, "role"); ad_wr_str(&w, ROLE_NAMES[s->role]);
    ad_wr_str(&w, "proof"); ad_wr_bin(&w, s->nonce, 32);
    ad_send_frame(dev, s, &w);
}

/* Ask the throttle (in a frame of its own, gone before the HMAC's deep stack): nonzero and
 * the refusal in why[] when the attempt is refused unchecked; else its entry and turn. */
AD_NOINLINE static int reserve_auth(ad_device *dev, ad_session *s, char *why, size_t wl)
{
    ad_verdict v = ad_throttle_reserve(&dev->throttle, s->addr, dev->now_us);
    if (v.refused) {
        s->state = AD_CLOSED;
        ad_throttle_message(&v, s->addr, why, wl);
        return 1;
    }
    s->auth_addr = v.entry;
    s->auth_due_us = dev->now_us + v.wait_us;
    return 0;
}

static int cmd_auth(ad_device *dev, ad_session *s, req *r, char *why, size_t wl)
{
    field f[] = {{"cnonce", F_BIN, 1, 0, {0}, {0}}, {"mac", F_BIN, 1, 0, {0}, {0}},
                 {"role", F_STR | F_NIL, 0, 0, {0}, {0}}};
    int rc = parse_args(&r->rd, &r->args, r->op, f, 3, why, wl);
    if (rc) return rc;
    uint32_t cn = f[0].v.n;
    if (cn < 16 || cn > 256) { ad_snprintf(why, wl, "AUTH: cnonce must hold 16..256 bytes"); return 400; }
    int requested = AD_ROLE_OPERATOR;
    if (f[2].present && f[2].v.t == AD_VT_STR) {
        if (f[2].v.n == 8 && !memcmp(f[2].v.p, "observer", 8)) requested = AD_ROLE_OBSERVER;
        else if (f[2].v.n == 8 && !memcmp(f[2].v.p, "operator", 8)) requested = AD_ROLE_OPERATOR;
        else {
            ad_snprintf(why, wl, "AUTH: unknown role '%.*s'; expected observer or operator",
                     (int)(f[2].v.n > 32 ? 32 : f[2].v.n), (const char *)f[2].v.p);
            return 400;
        }
    }
    /* Throttled (§10): refused unchecked, or checked now and answered at its turn (the
     * session reads nothing meanwhile); the outcome counts when the answer goes out. */
    if (reserve_auth(dev, s, why, wl)) return 429;
    /* every role's MAC is computed and compared, so the time does not say which came close */
    const char *passwords[3] = {NULL, dev->cfg.observer_password, dev->cfg.operator_password};
    int granted = AD_ROLE_NONE;
    uint8_t proof[32];
    for (int role = AD_ROLE_OBSERVER; role <= AD_ROLE_OPERATOR; role++) {
        uint8_t mac[32];
        if (!passwords[role]) continue;
        if (ad_hmac(passwords[role], CLIENT_LABEL, s->nonce, 32, f[0].v.p, cn, mac)) continue;
        if (f[1].v.n == 32 && ad_equal_ct(mac, f[1].v.p, 32)) {
            granted = role;
            ad_hmac(passwords[role], SERVER_LABEL, s->nonce, 32, f[0].v.p, cn, proof);
        }
    }
    if (granted > requested) granted = requested;
    s->auth_held = 1;
    s->auth_granted = (uint8_t)granted;
    s->auth_seq = r->seq;
    if (granted != AD_ROLE_NONE) memcpy(s->nonce, proof, 32); /* the nonce is spent */
    if (s->auth_due_us <= dev->now_us) answer_auth(dev, s, dev->now_us, why, wl);
    return 0;
}

/* ---- dispatch ----------------------------------------------------------------------------- */
typedef int (*cmd_fn)(ad_device *, ad_session *, req *, char *, size_t);
typedef struct command {
    const char *op;
    uint8_t role;
    uint8_t allowed;   /* bit per state: AWAIT_HELLO, AWAIT_AUTH, READY */
    cmd_fn run;
} command;

#define S_HELLO 1u
#define S_AUTH 2u
#define S_READY 4u

/* Rules (§5): HELLO first, then AUTH (skipped when authentication is off), then the
 * rest; PING and BYE at any time. A command outside its states gets 409. */
static const command COMMANDS[] = {
    {"HELLO", AD_ROLE_NONE, S_HELLO, cmd_hello},
    {"AUTH", AD_ROLE_NONE, S_AUTH, cmd_auth},
    {"LIST", AD_ROLE_OBSERVER, S_READY, cmd_list},
    {"DEFINE", AD_ROLE_OBSERVER, S_READY, cmd_define},
    {"UNDEFINE", AD_ROLE_OBSERVER, S_READY, cmd_undefine},
    {"READ", AD_ROLE_OBSERVER, S_READY, cmd_read},
    {"WRITE", AD_ROLE_OPERATOR, S_READY, cmd_write},
    {"INVOKE", AD_ROLE_OPERATOR, S_READY, cmd_invoke},
    {"STREAM_START", AD_ROLE_OBSERVER, S_READY, cmd_stream_start},
    {"STREAM_STOP", AD_ROLE_OBSERVER, S_READY, cmd_stream_stop},
    {"PING", AD_ROLE_NONE, S_HELLO | S_AUTH | S_READY, cmd_ping},
    {"STATS", AD_ROLE_OBSERVER, S_READY, cmd_stats},
    {"BYE", AD_ROLE_NONE, S_HELLO | S_AUTH | S_READY, NULL},
};
#define N_COMMANDS (sizeof COMMANDS / sizeof COMMANDS[0])

void ad_refuse(ad_device *dev, ad_session *s, int code, const char *why)
{
    if (s->used && !s->wants_close) fail(dev, s, 0, 0, code, why, 1);
}

/* Before AUTH, a peer gets almost nothing (§8): small frames, and few of them. */
static int pre_auth(const ad_device *dev, const ad_session *s)
{
    return auth_required(dev) && s->role == AD_ROLE_NONE;
}

uint32_t ad_frame_limit(const ad_device *dev, const ad_session *s)
{
    uint32_t small = dev->cfg.max_pending_frame_bytes;
    return pre_auth(dev, s) && small < dev->cfg.max_frame_bytes ? small : dev->cfg.max_frame_bytes;
}

void ad_refuse_oversize(ad_device *dev, ad_session *s, uint64_t announced)
{
    char why[160];
    ad_snprintf(why, sizeof why, "frame of %llu bytes announced; the limit is %u bytes%s",
             (unsigned long long)announced, ad_frame_limit(dev, s),
             pre_auth(dev, s) ? " before authentication" : "");
    fail(dev, s, 0, 0, 413, why, 1);
}

void ad_receive(ad_device *dev, ad_session *s, const uint8_t *frame, size_t len, int64_t now_us)
{
    char why[AD_WHY_BYTES];
    ad_limits lim = {dev->cfg.max_frame_bytes, dev->cfg.max_depth, dev->cfg.max_array_len,
                     dev->cfg.max_str_bytes};
    dev->now_us = now_us;
    if (!s->used || s->state == AD_CLOSED || s->wants_close) return;
    if (s->auth_held) {
        /* a transport that reads while ad_can_receive() says no (a link without a park):
         * the held AUTH is dropped unanswered rather than hold the link */
        ad_throttle_cancelled(&dev->throttle, s->auth_addr);
        s->auth_held = 0;
        fail(dev, s, 0, 0, 429, "a frame before the AUTH was answered", 1);
        return;
    }
    int has_seq = 0;
    uint64_t seq = 0;
    if (pre_auth(dev, s)) {
        if (len > ad_frame_limit(dev, s)) { ad_refuse_oversize(dev, s, len); return; }
        if (++s->frames_before_auth > dev->cfg.max_pending_frames) {
            ad_snprintf(why, sizeof why, "more than %u frames before authenticating",
                        dev->cfg.max_pending_frames);
            fail(dev, s, 0, 0, 429, why, 1);
            return;
        }
    }
    int code = ad_validate(frame, len, &lim, why, sizeof why);
    if (code == 413) { fail(dev, s, 0, 0, 413, why, 1); return; }
    req r;
    memset(&r, 0, sizeof r);
    const command *cmd = NULL;
    if (!code) {
        ad_rd rd;
        ad_val top, op, sq;
        ad_rd_init(&rd, frame, len);
        ad_rd_next(&rd, &top);
        if (top.t == AD_VT_ARRAY && top.n == 3) {
            ad_rd_next(&rd, &op);
            ad_rd_skip_items(&rd, &op);
            ad_rd_next(&rd, &sq);
            if (sq.t == AD_VT_UINT && sq.u <= MAX_SEQ) { has_seq = 1; seq = sq.u; }
            ad_rd_skip_items(&rd, &sq);
            ad_rd_next(&rd, &r.args);
            r.rd = rd;
            if (!has_seq) {
                code = 400;
                ad_snprintf(why, sizeof why, "request seq must be an unsigned integer below 2**63");
            } else {
                for (size_t i = 0; op.t == AD_VT_STR && i < N_COMMANDS; i++)
                    if (strlen(COMMANDS[i].op) == op.n && !memcmp(COMMANDS[i].op, op.p, op.n))
                        cmd = &COMMANDS[i];
                if (!cmd) {
                    code = 400;
                    if (op.t == AD_VT_STR)
                        ad_snprintf(why, sizeof why, "unknown command '%.*s'; expected one of HELLO AUTH LIST "
                                 "DEFINE UNDEFINE READ WRITE INVOKE STREAM_START STREAM_STOP PING STATS BYE",
                                 (int)(op.n > 40 ? 40 : op.n), (const char *)op.p);
                    else
                        ad_snprintf(why, sizeof why, "unknown command of type %s; expected one of HELLO AUTH "
                                 "LIST DEFINE UNDEFINE READ WRITE INVOKE STREAM_START STREAM_STOP PING STATS BYE",
                                 val_type(&op));
                } else if (r.args.t != AD_VT_MAP) {
                    code = 400;
                    ad_snprintf(why, sizeof why, "%s: args must be a map", cmd->op);
                }
            }
        } else {
            code = 400;
            ad_snprintf(why, sizeof why, "a request frame is the array [OP, seq, args]");
        }
    }
    if (!code) {
        uint8_t bit = (uint8_t)(1u << s->state);
        if (!(cmd->allowed & bit)) {
            code = 409;
            if (s->state == AD_READY)
                ad_snprintf(why, sizeof why, "%s is not allowed after the handshake", cmd->op);
            else
                ad_snprintf(why, sizeof why, "%s is not allowed before %s", cmd->op,
                         s->state == AD_AWAIT_HELLO ? "HELLO" : "AUTH");
        } else if (s->role < cmd->role) {
            code = 403;
            ad_snprintf(why, sizeof why, "%s needs the %s role; this connection is %s", cmd->op,
                     ROLE_NAMES[cmd->role], ROLE_NAMES[s->role]);
        }
    }
    if (code == 400 || code == 409) {
        s->protocol_errors++;
        int fatal = s->role == AD_ROLE_NONE || s->protocol_errors >= MAX_PROTOCOL_ERRORS;
        fail(dev, s, has_seq, seq, code, why, fatal);
        return;
    }
    if (code) { fail(dev, s, has_seq, seq, code, why, 0); return; }
    if (!cmd->run) { /* BYE */
        ad_wr w;
        begin(dev, &w);
        ok_head(&w, seq, 0);
        ad_send_frame(dev, s, &w);
        close_session(s, 1000, "bye");
        return;
    }
    r.op = cmd->op;
    r.seq = seq;
    code = cmd->run(dev, s, &r, why, sizeof why);
    if (code <= 0) return; /* answered (or deferred) */
    if (code == 400 || code == 409) {
        s->protocol_errors++;
        int fatal = s->role == AD_ROLE_NONE || s->protocol_errors >= MAX_PROTOCOL_ERRORS;
        fail(dev, s, has_seq, seq, code, why, fatal);
        return;
    }
    /* 401, 426 and a refused admission close; the rest leave the connection open */
    int closes = code == 401 || code == 426 || (code == 429 && s->state == AD_CLOSED)
                 || (code == 429 && s->role == AD_ROLE_NONE) || s->state == AD_CLOSED;
    fail(dev, s, 1, seq, code, why, closes);
}

void ad_poll(ad_device *dev, int64_t now_us)
{
    char why[160];
    int64_t limit_us = (int64_t)(dev->cfg.auth_timeout_s * 1e6);
    dev->now_us = now_us;
    for (uint32_t i = 0; i < dev->n_sessions; i++) {
        ad_session *s = &dev->sessions[i];
        if (!s->used || s->wants_close || s->state == AD_READY || s->state == AD_CLOSED) continue;
        int64_t deadline_us = s->opened_us + limit_us;
        if (s->auth_held && s->auth_due_us <= now_us && s->auth_due_us < deadline_us) {
            answer_auth(dev, s, now_us, why, sizeof why);
        } else if (now_us >= deadline_us) {
            if (s->auth_held) ad_throttle_cancelled(&dev->throttle, s->auth_addr);
            s->auth_held = 0;
            ad_snprintf(why, sizeof why, "not authenticated within %g s", dev->cfg.auth_timeout_s);
            fail(dev, s, 0, 0, 408, why, 1);
        }
    }
    poll_calls(dev, now_us);
    ad_stream_poll(dev);
}

int64_t ad_poll_delay_us(const ad_device *dev, int64_t now_us, int64_t max_us)
{
    int64_t delay = max_us;
    if (dev->pending_calls) return delay < 1000 ? delay : 1000;
    int64_t limit_us = (int64_t)(dev->cfg.auth_timeout_s * 1e6);
    for (uint32_t i = 0; i < dev->n_sessions; i++) {
        const ad_session *s = &dev->sessions[i];
        if (!s->used || s->wants_close || s->state == AD_READY || s->state == AD_CLOSED) continue;
        int64_t left = s->opened_us + limit_us - now_us;
        if (s->auth_held && s->auth_due_us - now_us < left) left = s->auth_due_us - now_us;
        if (left < delay) delay = left;
    }
    int64_t streams = ad_stream_delay_us((ad_device *)dev);
    if (streams < delay) delay = streams;
    return delay > 0 ? delay : 0;
}

/* ---- function call API ---------------------------------------------------------------------- */
uint32_t ad_arg_count(const ad_call *c) { return c->n_args; }
double ad_arg_f64(const ad_call *c, uint32_t i)
{
    const ad_argval *a = &c->args[i];
    return a->dtype >= 9 ? a->v.f : a->dtype == 8 ? (double)a->v.u : (double)a->v.i;
}
int64_t ad_arg_i64(const ad_call *c, uint32_t i)
{
    const ad_argval *a = &c->args[i];
    return a->dtype >= 9 ? (int64_t)a->v.f : a->dtype == 8 ? (int64_t)a->v.u : a->v.i;
}
uint64_t ad_arg_u64(const ad_call *c, uint32_t i)
{
    const ad_argval *a = &c->args[i];
    return a->dtype == 8 ? a->v.u : (uint64_t)ad_arg_i64(c, i);
}
int ad_arg_bool(const ad_call *c, uint32_t i) { return c->args[i].v.i != 0; }
const char *ad_arg_str(const ad_call *c, uint32_t i, uint32_t *len)
{
    if (len) *len = c->args[i].len;
    return (const char *)c->args[i].data;
}
uint32_t ad_arg_len(const ad_call *c, uint32_t i) { return c->args[i].len; }
double ad_arg_elem_f64(const ad_call *c, uint32_t i, uint32_t k)
{
    const ad_argval *a = &c->args[i];
    return k < a->len ? ad_load_f64(a->dtype, a->data + (size_t)k * AD_DTYPE_SIZE[a->dtype]) : 0.0;
}
int64_t ad_arg_elem_i64(const ad_call *c, uint32_t i, uint32_t k)
{
    const ad_argval *a = &c->args[i];
    return k < a->len ? ad_load_i64(a->dtype, a->data + (size_t)k * AD_DTYPE_SIZE[a->dtype]) : 0;
}
void ad_return_f64(ad_call *c, double v) { c->has_result = 1; c->result_kind = 1; c->result.f = v; }
void ad_return_i64(ad_call *c, int64_t v) { c->has_result = 1; c->result_kind = 2; c->result.i = v; }
void ad_return_u64(ad_call *c, uint64_t v) { c->has_result = 1; c->result_kind = 3; c->result.u = v; }
void ad_return_bool(ad_call *c, int v) { c->has_result = 1; c->result_kind = 4; c->result.u = v != 0; }
void ad_return_str(ad_call *c, const char *s)
{
    c->has_result = 1;
    c->result_kind = 5;
    c->result_ptr = s;
    c->result_len = (uint32_t)strlen(s);
}
void ad_return_f64_array(ad_call *c, const double *v, uint32_t n)
{
    c->has_result = 1;
    c->result_kind = 6;
    c->result_ptr = v;
    c->result_len = n;
}
int ad_fail(ad_call *c, const char *message)
{
    ad_snprintf(c->fail, sizeof c->fail, "%s", message);
    return AD_FAILED;
}
int ad_defer(ad_call *c, ad_resume_fn resume)
{
    c->resume = resume;
    return AD_PENDING;
}
void *ad_call_state(ad_call *c) { return c->state; }
const char *ad_call_client(const ad_call *c) { return c->session->name; }
