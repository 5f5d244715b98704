/*
 * astcom_device: ASTCom inside a controller, in C99.
 *
 * The design, in the spirit of libcanard: the library holds no socket, no thread and
 * no heap. The application declares its variables and functions in static tables
 * (ad_var, ad_fn), hands the library one block of memory (the arena) at init, calls
 * ad_tick() from its control loop after every tick, and pumps bytes between its
 * transports and the library from its communication loop:
 *
 *     control loop (ISR or RT thread)          communication loop (main loop / thread)
 *     ------------------------------           ---------------------------------------
 *     compute the tick                         s = ad_open(dev, sink, peer) a peer arrived
 *     ad_tick(dev, tick, t_us)  O(traced)      ad_receive(dev, s, frame, n) a whole frame
 *                                              ad_poll(dev, now_us)         streams, timeouts
 *                                              ad_close(dev, s)             the peer left
 *
 * ad_tick() copies the traced signals into a ring and never allocates, never blocks on
 * I/O and costs O(number of traced signals). Everything else runs on the
 * communication side. Frames out of the library go to a sink (ad_sink) that the
 * transport supplies: a TCP connection, or a channel of the framed serial link
 * (ad_link.h). The host layer provides only a clock, byte-stream I/O (in its
 * transports) and a critical section (ad_port_lock/ad_port_unlock, below).
 *
 * Every error is a negative code or an ERR frame to the peer; nothing here aborts.
 * The wire protocol is docs/astcom-protocol.md; this library's own manual is
 * docs/astcom-device.md.
 */
#ifndef ASTCOM_DEVICE_H
#define ASTCOM_DEVICE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define AD_VERSION "1.0"

/* ---- the host layer: what the application must supply ------------------------------- */

/* Enter/leave the critical section shared by ad_tick() and the communication side
 * (an interrupt mask on an MCU, a mutex on a POSIX host). The library holds it only for
 * O(1) work or for copying the values of one request. */
void ad_port_lock(void);
void ad_port_unlock(void);
/* Fill `n` bytes with unpredictable bytes (server nonces). Return 0 on success. */
int ad_port_random(uint8_t *out, size_t n);
/* The host's wall clock (UTC, µs since 1970): PING's t_us. */
int64_t ad_port_wall_us(void);

/* ---- registry: static tables ---------------------------------------------------------- */

enum ad_kind { AD_SIGNAL = 0, AD_PARAMETER = 1 };
enum ad_access { AD_R = 0, AD_RW = 1 };

struct ad_var;
/* Optional check before a WRITE applies `value` (the new value, in the variable's C
 * layout). Return 0 to accept; otherwise write a reason into why[why_len] (ERR 422). */
typedef int (*ad_check_fn)(const struct ad_var *var, const void *value, char *why,
                           size_t why_len);

/* One variable. `ptr` points to its storage in the C layout of its type: bool as
 * uint8_t, iN/uN/f32/f64 as the C types, fixed arrays contiguous in C order, str as a
 * NUL-terminated char buffer of `capacity` bytes, a struct {a:f64,b:i32} as a C struct
 * of those members in that order (natural alignment). Only numeric scalars may be
 * traced (sampled every tick). */
typedef struct ad_var {
    const char *name;       /* dotted identifiers: "axis.az.position" */
    const char *type;       /* ASTCom type text: "f64", "f64[3]", "str", "{lat:f64,lon:f64}" */
    uint8_t kind;           /* AD_SIGNAL or AD_PARAMETER */
    uint8_t access;         /* AD_R or AD_RW */
    uint8_t traced;         /* 1: sampled into the ring at every tick */
    uint8_t has_min, has_max;
    double min, max;        /* inclusive range a WRITE must respect (unit below) */
    const char *unit;
    const char *doc;
    void *ptr;
    uint32_t capacity;      /* str: bytes of the buffer, NUL included */
    ad_check_fn check;      /* optional */
} ad_var;

typedef struct ad_call ad_call;
/* A device function. Read the arguments with ad_arg_*, answer with ad_return_* and
 * return AD_OK, or return ad_fail(call, "why") (ERR 500 "name failed: why"). A function
 * that must wait (without blocking the loop) calls ad_defer() and returns AD_PENDING;
 * the library then calls `resume` from ad_poll() until it returns AD_OK or an error. */
typedef int (*ad_fn_cb)(ad_call *call, void *user);
typedef struct ad_fn {
    const char *name;
    const char *signature;  /* "(t_us:i64[],az_rad:f64[])->u32", "()->none" */
    ad_fn_cb fn;
    void *user;
    const char *doc;
} ad_fn;

/* ---- configuration and memory --------------------------------------------------------- */

/* What a wrong password cost its address (on_auth_failure). */
typedef struct ad_auth_failure {
    uint32_t failures;  /* consecutive failures from the address, this one included */
    double locked_s;    /* > 0: this failure locked the address out for so long */
    uint32_t refused;   /* attempts from the address refused unchecked since its last failure */
} ad_auth_failure;

typedef struct ad_config {
    const char *name;              /* HELLO's server name */
    double loop_rate_hz;           /* the control loop's rate */
    const char *operator_password; /* NULL: no operator password */
    const char *observer_password; /* NULL: none; both NULL: authentication off */
    /* limits announced in HELLO (docs/astcom-protocol.md §8) */
    uint32_t max_frame_bytes, max_depth, max_array_len, max_str_bytes;
    uint32_t max_messages, max_names_per_message, max_streams_per_client;
    uint32_t max_clients, max_pending;
    /* before AUTH succeeds (with authentication on): frames of at most this size, and at
     * most this many of them (the next is ERR 429 and a close) */
    uint32_t max_pending_frame_bytes, max_pending_frames;
    double auth_timeout_s;
    uint32_t queue_packets;        /* announced; the sink's room decides what is dropped */
    /* device-side sizes */
    uint32_t ring_ticks;           /* trace ring depth in ticks (20 ms at 10 kHz: 200) */
    uint32_t max_reply_bytes;      /* largest frame the library builds (the scratch) */
    uint32_t max_samplers;         /* (message, rate) sampling groups over all clients */
    uint32_t max_pending_calls;    /* deferred INVOKEs at once (ERR 429 beyond) */
    double flush_interval_s;       /* samples per packet ~ this much time (0.02) */
    uint32_t max_arg_bytes;        /* array arguments sent as msgpack arrays (0: 2 frames) */
    /* Password attempts (docs/astcom-protocol.md §10; the reference endpoint's
     * astcom_client/throttle.py), per peer address and over the whole device: the n-th
     * consecutive failure from an address puts auth_first_delay_s × 2^(n-1) (at most
     * auth_max_delay_s) before its next check; the auth_lockout_failures-th locks it out for
     * auth_lockout_s; a right password forgets it, so does auth_forget_s of quiet. Over all
     * addresses at most auth_rate_per_s checks a second after a burst of auth_burst. An
     * AUTH is held (its answer, not the loop) until its turn, at most auth_max_hold_s;
     * one that would wait longer, or comes from a locked-out address, is answered ERR 429
     * unchecked. The table remembers auth_max_addresses addresses (at least max_pending + 1;
     * the least recently seen go first). */
    double auth_first_delay_s, auth_max_delay_s, auth_lockout_s, auth_forget_s;
    double auth_rate_per_s, auth_max_hold_s;
    uint32_t auth_lockout_failures, auth_burst, auth_max_addresses;
    /* Called for every wrong password (the application logs it), with what it cost the
     * address; NULL: not reported (ad_get_stats still counts them). */
    void (*on_auth_failure)(void *user, const char *address, const ad_auth_failure *f);
    void *auth_user;
} ad_config;


/* Fill `cfg` with the defaults of the spec (and of the Python endpoint) for a host. */
void ad_config_defaults(ad_config *cfg);

typedef struct ad_device ad_device;

/* Bytes the arena needs for `cfg` with these tables. */
size_t ad_arena_bytes(const ad_config *cfg, const ad_var *vars, size_t n_vars,
                      const ad_fn *fns, size_t n_fns);
/* Build a device in `arena` (ad_arena_bytes of it, 8-byte aligned). Returns the
 * device, or NULL and a reason in why[why_len] (bad type text, duplicate name, a
 * traced non-scalar, a range on a non-number, arena too small). Nothing is allocated
 * afterwards. */
ad_device *ad_init(void *arena, size_t arena_bytes, const ad_config *cfg,
                   const ad_var *vars, size_t n_vars, const ad_fn *fns, size_t n_fns,
                   char *why, size_t why_len);

/* The configuration the device runs with (a copy of the one given to ad_init). */
const ad_config *ad_device_config(const ad_device *dev);

/* ---- the control side ------------------------------------------------------------------ */

/* Record that tick `tick` (mount time `t_us`) is computed: copy the traced signals into
 * the ring. Call with the critical section NOT held; it takes it for one store.
 * Consecutive ticks whose times follow the loop rate form one segment; a jump in either
 * opens a new one (no stream packet spans it). */
void ad_tick(ad_device *dev, uint64_t tick, int64_t t_us);

/* ---- the communication side ----------------------------------------------------------- */

/* Where the frames of one connection go. `room` says how many frame bytes can be taken
 * now without waiting (stream packets beyond it are dropped and counted); `send`
 * takes one whole frame and must take it (buffer or wait) unless `droppable`, in which
 * case it may refuse (return nonzero: the packet is counted as dropped). */
typedef struct ad_sink {
    size_t (*room)(void *ctx);
    int (*send)(void *ctx, const uint8_t *frame, size_t len, int droppable);
    void *ctx;
    /* Optional (NULL: not offered): a reply of `len` bytes in parts, for replies larger
     * than max_reply_bytes (a whole LIST on a device with a small scratch). begin() returns
     * 0 when it takes the frame (it then must take every part: buffer or wait), else the
     * reply is refused with ERR 413; part() gets the bytes in order; end() closes it. */
    int (*begin)(void *ctx, size_t len);
    void (*part)(void *ctx, const uint8_t *bytes, size_t n);
    void (*end)(void *ctx);
    /* Optional: the stream packets this connection's transport holds, not yet sent (STATS
     * queue_depths); NULL: reported as 0. */
    size_t (*queued)(void *ctx);
} ad_sink;

typedef struct ad_session ad_session;

/* A peer connected from `peer` (its address as text, "host:port" or "[v6]:port": what
 * follows the last ':' is left out; password attempts are throttled per address; "" or
 * NULL: an address of its own shared by every peer without one). Returns its session, or
 * NULL when refused (the ERR 429 frame has then been sent to `sink`; close the transport).
 * `now_us` (the communication side's monotonic clock, as for ad_receive and ad_poll)
 * starts its auth timeout. */
ad_session *ad_open(ad_device *dev, ad_sink sink, const char *peer, int64_t now_us);
/* One whole frame from the peer (the transport cut it out of its byte stream). */
void ad_receive(ad_device *dev, ad_session *s, const uint8_t *frame, size_t len,
                int64_t now_us);
/* A frame the transport had to refuse before it was whole (its length prefix was over
 * max_frame_bytes): ERR 413 and close. */
void ad_refuse_oversize(ad_device *dev, ad_session *s, uint64_t announced);
/* Streams, auth timeouts and deferred calls. Call often (every ms or so), or when
 * ad_poll_delay_us() says. */
void ad_poll(ad_device *dev, int64_t now_us);
/* How long (µs) the communication loop may sleep before ad_poll() has work: until the
 * next stream packet is due, the next auth timeout, at most `max_us`; 1 ms while a
 * deferred call runs. A loop that sleeps this long (waking early for I/O) does what one
 * that polls every millisecond does, with far fewer wake-ups. */
int64_t ad_poll_delay_us(const ad_device *dev, int64_t now_us, int64_t max_us);
/* True when the library wants the transport closed (after BYE or an error that
 * closes); `code`/`reason` say why (reason may be ""). The frames before are sent. */
int ad_wants_close(const ad_session *s, int *code, const char **reason);
/* The peer is gone: free its session, its streams and its messages. */
void ad_close(ad_device *dev, ad_session *s);
/* Stop reading from a peer whose sink cannot take a reply now (back-pressure), whose
 * deferred call runs, or whose AUTH is held (§10). */
int ad_can_receive(const ad_device *dev, const ad_session *s);
/* The largest frame the peer may send now (smaller before it has authenticated): a
 * transport that reads a length first refuses a larger one with ad_refuse_oversize(). */
uint32_t ad_frame_limit(const ad_device *dev, const ad_session *s);

/* ---- function calls ------------------------------------------------------------------- */

enum { AD_OK = 0, AD_PENDING = 1, AD_FAILED = -1 };

uint32_t ad_arg_count(const ad_call *call);
double ad_arg_f64(const ad_call *call, uint32_t i);
int64_t ad_arg_i64(const ad_call *call, uint32_t i);
uint64_t ad_arg_u64(const ad_call *call, uint32_t i);
int ad_arg_bool(const ad_call *call, uint32_t i);
const char *ad_arg_str(const ad_call *call, uint32_t i, uint32_t *len);
/* A variable-length or fixed array argument: its element count and elements. */
uint32_t ad_arg_len(const ad_call *call, uint32_t i);
double ad_arg_elem_f64(const ad_call *call, uint32_t i, uint32_t k);
int64_t ad_arg_elem_i64(const ad_call *call, uint32_t i, uint32_t k);

void ad_return_f64(ad_call *call, double v);
void ad_return_i64(ad_call *call, int64_t v);
void ad_return_u64(ad_call *call, uint64_t v);
void ad_return_bool(ad_call *call, int v);
void ad_return_str(ad_call *call, const char *s);
void ad_return_f64_array(ad_call *call, const double *v, uint32_t n);
int ad_fail(ad_call *call, const char *message);
/* Wait without blocking: `resume(call, user, now_us)` is called from ad_poll() until it
 * returns AD_OK (after ad_return_*) or fails. `state` keeps up to AD_CALL_STATE_BYTES
 * bytes for it. The arguments (ad_arg_*) are valid in the first call only: copy what
 * resume needs into the state. The connection's later requests wait for the answer (over
 * the framed link, only that channel's). */
#define AD_CALL_STATE_BYTES 32
typedef int (*ad_resume_fn)(ad_call *call, void *user, int64_t now_us);
int ad_defer(ad_call *call, ad_resume_fn resume);
void *ad_call_state(ad_call *call);
/* Who asked: the session's client name and role ("observer"/"operator"). */
const char *ad_call_client(const ad_call *call);

/* ---- texts ------------------------------------------------------------------------------- */

/* snprintf for the library's and an application's texts, without the C library's float
 * printf (9 KiB of flash on a Cortex-M4): %s %.*s %c %d %u %x %02x, the l, ll and z
 * lengths, %g %.Ng (up to 17 digits) %.Nf (up to 9 decimals) and %%. Returns the length
 * the whole text needs, as snprintf does; `buf` always ends with a NUL when cap > 0. */
#if defined(__GNUC__) && !defined(AD_NO_FORMAT_CHECK)
/* checked against printf's rules by the host builds; on a Cortex-M4, whose uint32_t is an
 * unsigned long of the same size, the firmware build defines AD_NO_FORMAT_CHECK */
__attribute__((format(printf, 3, 4)))
#endif
int ad_snprintf(char *buf, size_t cap, const char *fmt, ...);

/* ---- figures ---------------------------------------------------------------------------- */

typedef struct ad_stats {
    uint32_t clients, pending, streams, samplers, messages;
    uint64_t tick;
    int64_t t_us;
    uint64_t dropped_samples;     /* all clients since start */
    uint64_t ring_lost_samples;   /* lost because the ring was overrun */
    /* password attempts since start: checked, refused unchecked (ERR 429), wrong */
    uint64_t auth_checked, auth_refused, auth_failures;
    uint32_t auth_addresses;      /* addresses the throttle remembers now */
} ad_stats;
void ad_get_stats(const ad_device *dev, ad_stats *out);

#ifdef __cplusplus
}
#endif
#endif /* ASTCOM_DEVICE_H */
