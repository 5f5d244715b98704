/* The library's own structures (not part of the API). */
#ifndef AD_INTERNAL_H
#define AD_INTERNAL_H

#include <stdint.h>

#include "astcom_device.h"
#include "ad_codec.h"

/* element kinds beyond the numeric dtype codes 0..10 of §2.1 */
#define AD_T_STR 11
#define AD_T_BYTES 12
#define AD_T_STRUCT 13
#define AD_T_NONE 14
#define AD_VARLEN 0xff         /* ndim of "f64[]" */
#define AD_MAX_SEGMENTS 8      /* clock segments remembered by the ring */
#define AD_MAX_SESSIONS 64     /* holders and subscribers are 64-bit masks */
#ifndef AD_ADDR_BYTES
#define AD_ADDR_BYTES 48       /* a peer's address, NUL included ("[IPv6]": 47) */
#endif

/* A parsed type: a scalar, a fixed array (ndim 1..4), a variable array, or a struct
 * (its fields are read from the type text when needed: ad_struct_next). */
typedef struct ad_type {
    uint8_t base;       /* 0..10 numeric, AD_T_STR, AD_T_BYTES, AD_T_STRUCT, AD_T_NONE */
    uint8_t ndim;       /* 0 scalar, 1..4 fixed, AD_VARLEN */
    uint32_t shape[4];
    uint32_t count;     /* elements of a fixed array, 1 for a scalar */
    uint32_t c_size;    /* bytes of the C storage (str: capacity) */
} ad_type;

int ad_parse_type(const char *text, size_t len, ad_type *out);
uint32_t ad_scalar_size(uint8_t base);
/* Iterate the fields of a struct type text; returns 0 while there is a field. */
typedef struct ad_struct_it {
    const char *p, *end;
    uint32_t offset;    /* of the field just returned, in the C struct */
    uint32_t align;     /* largest member alignment so far */
} ad_struct_it;
void ad_struct_begin(ad_struct_it *it, const char *type_text);
int ad_struct_next(ad_struct_it *it, const char **name, uint32_t *name_len, uint8_t *base);

/* Coerce one msgpack value into the C layout of `t` (dst, t->c_size bytes).
 * 0, or 422 with a message naming `where`. Arrays accept ext 1 or nested msgpack arrays. */
int ad_coerce(ad_rd *rd, const ad_type *t, const char *type_text, void *dst,
              const char *where, char *why, size_t why_len);
/* Write a value stored in the C layout of `t` as its wire form. */
void ad_write_value(ad_wr *w, const ad_type *t, const char *type_text, const void *src);
/* Load element k of a numeric array stored as `base` as a double / int64. */
double ad_load_f64(uint8_t base, const void *p);
int64_t ad_load_i64(uint8_t base, const void *p);

/* What the library keeps of each variable (16 bytes): its type's kind and sizes; the shape
 * of a fixed array of more than one dimension is read again from the type text. */
typedef struct ad_var_rt {
    uint8_t base, ndim;     /* as ad_type */
    int16_t trace_col;      /* index among traced signals, -1 if not traced */
    uint32_t count, c_size; /* elements; bytes of its C storage (str: the capacity) */
    uint32_t ring_offset;   /* byte offset in a ring row */
} ad_var_rt;

typedef struct ad_arg {
    ad_type type;
    const char *name;
    uint32_t name_len;
    const char *type_text;
    uint32_t type_len;
} ad_arg;

#define AD_MAX_ARGS 8

/* Keep a function's locals out of its callers' frames (the MCU's stack is small). */
#if defined(__GNUC__)
#define AD_NOINLINE __attribute__((noinline))
#else
#define AD_NOINLINE
#endif

/* The buffer of a request's error text (an MCU build may make it smaller: longer texts
 * are cut) */
#ifndef AD_WHY_BYTES
#define AD_WHY_BYTES 600
#endif

/* A function call in progress: decoded arguments and the result to send. */
typedef struct ad_argval {
    uint8_t form;           /* 0 scalar, 1 ext-1 view, 2 copied array, 3 str */
    uint8_t dtype;          /* element dtype of a view or copy */
    uint32_t len;
    const uint8_t *data;
    union { double f; int64_t i; uint64_t u; } v;
} ad_argval;

struct ad_call {
    ad_device *dev;
    ad_session *session;
    const ad_fn *fn;
    uint8_t n_args;
    ad_type ret;            /* the declared return type */
    ad_argval args[AD_MAX_ARGS];
    uint64_t seq;
    uint8_t has_result, result_kind;  /* 0 none, 1 f64, 2 i64, 3 u64, 4 bool, 5 str, 6 f64[] */
    union { double f; int64_t i; uint64_t u; } result;
    const void *result_ptr;
    uint32_t result_len;
    char fail[160];
    ad_resume_fn resume;
    uint8_t state[AD_CALL_STATE_BYTES];
};

enum ad_state { AD_AWAIT_HELLO, AD_AWAIT_AUTH, AD_READY, AD_CLOSED };
enum ad_role { AD_ROLE_NONE, AD_ROLE_OBSERVER, AD_ROLE_OPERATOR };

struct ad_session {
    uint8_t used, state, role, call_pending;
    uint8_t slot;
    uint8_t auth_held;        /* an AUTH checked and held until auth_due_us (§10) */
    uint8_t auth_granted;     /* its outcome: the role, AD_ROLE_NONE for a wrong password */
    uint16_t auth_addr;       /* its address's entry in the throttle table */
    uint32_t id;
    int close_code;
    int wants_close;
    char close_reason[128];
    ad_sink sink;
    int64_t opened_us;
    int64_t auth_due_us;
    uint64_t auth_seq;
    uint8_t nonce[32];        /* HELLO's nonce; after the check, the held AUTH's proof */
    char addr[AD_ADDR_BYTES]; /* the peer's address without its port (ad_open) */
    char name[65];
    uint32_t protocol_errors;
    uint32_t frames_before_auth;
    uint32_t n_streams;
    uint64_t dropped_samples, dropped_packets;
    ad_call call;
};

/* Password attempts per address and overall (§10), the rules of the reference endpoint's
 * astcom_client/throttle.py in a fixed table (ad_throttle.c). Times are the
 * communication side's now_us. */
typedef struct ad_addr_state {
    char addr[AD_ADDR_BYTES];   /* "" : a free entry */
    uint16_t failures;          /* consecutive wrong passwords */
    uint16_t pending;           /* attempts reserved and not yet reported */
    uint32_t refused;           /* refused unchecked since the last failure */
    int64_t next_us;            /* the next attempt is not checked before this */
    int64_t locked_until_us;
    int64_t seen_us;
} ad_addr_state;

typedef struct ad_throttle {
    ad_addr_state *table;
    uint32_t n;                 /* entries of the table */
    int64_t first_delay_us, max_delay_us, lockout_us, forget_us, interval_us, max_hold_us;
    uint32_t lockout_failures, burst;
    int64_t tat_us;             /* the overall limit's theoretical arrival time */
    uint64_t checked, refused, failures;
} ad_throttle;

enum { AD_WHY_NONE = 0, AD_WHY_ADDRESS = 1, AD_WHY_LOCKED = 2, AD_WHY_OVERALL = 3 };
typedef struct ad_verdict {
    int64_t wait_us;
    uint8_t refused, reason;    /* reason: AD_WHY_* */
    uint16_t entry;             /* the address's entry (when not refused) */
} ad_verdict;

/* The table's entries for `cfg` (at least max_pending + 1, so an entry whose attempt is
 * pending is never the one evicted). */
uint32_t ad_throttle_entries(const ad_config *cfg, uint32_t n_sessions);
void ad_throttle_init(ad_throttle *t, const ad_config *cfg, ad_addr_state *table, uint32_t n);
ad_verdict ad_throttle_reserve(ad_throttle *t, const char *addr, int64_t now_us);
void ad_throttle_failed(ad_throttle *t, uint16_t entry, int64_t now_us, ad_auth_failure *out);
void ad_throttle_succeeded(ad_throttle *t, uint16_t entry);
void ad_throttle_cancelled(ad_throttle *t, uint16_t entry);
uint32_t ad_throttle_tracked(const ad_throttle *t, int64_t now_us);
/* "... not checked; try again in N s" for a refused verdict */
void ad_throttle_message(const ad_verdict *v, const char *addr, char *out, size_t len);

typedef struct ad_segment {
    uint64_t row0;     /* first ring row of the segment */
    uint64_t tick0;
    int64_t t0_us;
} ad_segment;

typedef struct ad_sampler {
    uint8_t used;
    uint32_t msg;
    uint64_t k;
    uint32_t spp;
    uint64_t seq;
    uint64_t next_tick;       /* next tick to sample (on the k-grid) */
    uint64_t subscribers;     /* session slot mask */
    double period_us;
} ad_sampler;

struct ad_device {
    ad_config cfg;
    const ad_var *vars;
    ad_var_rt *vrt;
    uint32_t n_vars;
    const ad_fn *fns;
    uint32_t n_fns;
    double tick_us;
    /* the ring: written by ad_tick, read by ad_poll */
    uint8_t *ring;
    uint32_t row_bytes, n_traced;
    uint16_t *traced;             /* var index of each trace column */
    volatile uint64_t head;       /* rows written */
    ad_segment seg[AD_MAX_SEGMENTS];
    volatile uint32_t n_seg;      /* segments opened (index = n_seg - 1 mod AD_MAX_SEGMENTS) */
    /* communication side */
    ad_session *sessions;
    uint32_t n_sessions;
    uint32_t next_client_id;
    uint8_t *msg_pool;            /* [id u32][holders u64][n u16][pad][idx u16 × n] records */
    uint32_t msg_pool_bytes, msg_pool_used, n_messages, next_msg;
    ad_sampler *samplers;
    uint8_t *scratch;             /* frames are built here */
    uint8_t *stage;               /* WRITE values, checked before any is applied */
    uint32_t stage_bytes;
    uint8_t *argbuf;              /* call arguments given as msgpack arrays */
    uint32_t argbuf_bytes, argbuf_used;
    uint32_t pending_calls;
    uint64_t dropped_closed, ring_lost;
    ad_throttle throttle;         /* password attempts (ad_throttle.c) */
    int64_t now_us;               /* the communication side's clock at its last call */
};

/* The whole type of variable `i`. */
void ad_var_type(const ad_device *dev, uint32_t i, ad_type *out);

/* messages */
typedef struct ad_msg {
    uint32_t id;
    uint64_t holders;
    uint16_t n;
    const uint16_t *idx;
    uint8_t *rec;
} ad_msg;
int ad_msg_find(ad_device *dev, uint32_t id, ad_msg *out);

/* streams (ad_stream.c) */
void ad_stream_poll(ad_device *dev);
/* µs until the first sampler has a whole packet in the ring (INT64_MAX: no stream) */
int64_t ad_stream_delay_us(ad_device *dev);
void ad_stream_drop_session(ad_device *dev, ad_session *s);
void ad_stream_drop_message(ad_device *dev, ad_session *s, uint32_t msg);
int ad_stream_start(ad_device *dev, ad_session *s, uint32_t msg, double rate_hz, ad_wr *w,
                    uint64_t seq, char *why, size_t why_len);
int ad_stream_stop(ad_device *dev, ad_session *s, uint32_t msg);
void ad_last_tick(ad_device *dev, int64_t *tick, int64_t *t_us);
int64_t ad_round_half_up(double x);

/* ERR nil `code` with `why`, then the session closes (a transport's refusal) */
void ad_refuse(ad_device *dev, ad_session *s, int code, const char *why);

/* sending (ad_device.c) */
void ad_send_frame(ad_device *dev, ad_session *s, const ad_wr *w);

/* auth (ad_auth.c) */
int ad_hmac(const char *password, const char *label, const uint8_t *sn, size_t sn_len,
            const uint8_t *cn, size_t cn_len, uint8_t out[32]);
int ad_equal_ct(const uint8_t *a, const uint8_t *b, size_t n);

#endif
