/* The framed link (ad_link.h): COBS + CRC-32 frames carrying one session per channel. */
#include <stdio.h>
#include <string.h>

#include "ad_link.h"
#include "ad_internal.h"

/* CRC-32 (IEEE 802.3, reflected), nibble table: 64 bytes of flash, two lookups a byte. */
static const uint32_t CRC_NIBBLE[16] = {
    0x00000000u, 0x1db71064u, 0x3b6e20c8u, 0x26d930acu, 0x76dc4190u, 0x6b6b51f4u,
    0x4db26158u, 0x5005713cu, 0xedb88320u, 0xf00f9344u, 0xd6d6a3e8u, 0xcb61b38cu,
    0x9b64c2b0u, 0x86d3d2d4u, 0xa00ae278u, 0xbdbdf21cu};

uint32_t ad_crc32(uint32_t crc, const uint8_t *p, size_t n)
{
    crc = ~crc;
    while (n--) {
        crc ^= *p++;
        crc = (crc >> 4) ^ CRC_NIBBLE[crc & 15u];
        crc = (crc >> 4) ^ CRC_NIBBLE[crc & 15u];
    }
    return ~crc;
}

typedef struct chan_ctx {
    ad_link *link;
    uint8_t id;
} chan_ctx;

struct ad_link {
    ad_device *dev;
    uint32_t max_frame, max_reply, channels;
    uint8_t *rx;           /* COBS bytes of the frame being received */
    size_t rx_cap, rx_len;
    int rx_skip;           /* discarding up to the next 0x00 */
    int held;              /* rx holds a decoded frame a channel cannot take yet */
    size_t held_len;
    uint8_t *park;         /* frames of channels that wait (a deferred call): [chan][len u32][frame] */
    size_t park_cap, park_len;
    uint8_t *tx;
    size_t tx_cap, tx_head, tx_tail;   /* ring of encoded bytes */
    /* the frame being COBS-encoded into the ring: its open block's code byte (a 0x00
     * placeholder until the block ends) at code_at; nothing from there on may be sent */
    struct { size_t code_at; uint8_t code, open, broken; uint32_t crc; } enc;
    ad_session **chan;     /* [channels + 1] */
    chan_ctx *ctx;         /* [channels + 1] */
    ad_link_drain_fn drain;
    void *io;
    int64_t now_us;
    ad_link_stats st;
};

static size_t cobs_max(size_t n) { return n + n / 254u + 2u; } /* code bytes and the 0x00 */
/* The send ring holds AD_LINK_TX_FRAMES frames of max_reply_bytes: a stream packet is
 * queued whole or dropped; a reply, or a LIST in parts, waits for the wire (drain) and may
 * be larger than the ring. A host keeps two (one on the wire while the next is built); a
 * small MCU sets 1 and drains synchronously. */
#ifndef AD_LINK_TX_FRAMES
#define AD_LINK_TX_FRAMES 2u
#endif
/* A channel that cannot take a request yet (a deferred call runs there) would hold the
 * link's input, every other channel's requests with it, and the relay's PINGs (a call
 * longer than its 3 s timeout would lose the link). Its frames are parked instead, in
 * order, in room for AD_LINK_PARK_FRAMES frames of max_frame_bytes; a channel that
 * overflows the park is closed with ERR 429. A small MCU may set 0: then the link waits
 * for the call (keep its calls short). */
#ifndef AD_LINK_PARK_FRAMES
#define AD_LINK_PARK_FRAMES 2u
#endif
#define PARK_HEAD 5u
static size_t up8(size_t n) { return (n + 7u) & ~(size_t)7u; }

size_t ad_link_bytes(uint32_t max_frame, uint32_t max_reply, uint32_t channels)
{
    size_t frame_in = (size_t)max_frame + 6u, frame_out = (size_t)max_reply + 6u;
    return up8(sizeof(ad_link)) + up8(cobs_max(frame_in)) + up8(AD_LINK_TX_FRAMES * cobs_max(frame_out) + 64u)
           + up8(AD_LINK_PARK_FRAMES * ((size_t)max_frame + PARK_HEAD))
           + up8((channels + 1u) * sizeof(ad_session *))
           + up8((channels + 1u) * sizeof(chan_ctx));
}

static size_t tx_used(const ad_link *l) { return l->tx_head - l->tx_tail; }
static size_t tx_free(const ad_link *l) { return l->tx_cap - tx_used(l); }

static void tx_put(ad_link *l, uint8_t b)
{
    l->tx[l->tx_head % l->tx_cap] = b;
    l->tx_head++;
}

/* Room for `need` more bytes in the ring: wait for the wire (drain) unless `droppable`.
 * Only the bytes before an open frame's code byte can be sent, so a ring larger than one
 * COBS block (255 bytes) always makes progress. */
static int tx_wait(ad_link *l, size_t need, int droppable)
{
    while (tx_free(l) < need) {
        if (droppable || !l->drain) return -1;
        size_t before = tx_used(l);
        l->drain(l->io);
        if (tx_used(l) == before) return -1; /* the wire is gone */
    }
    return 0;
}

/* ---- the COBS encoder: a frame is begun, fed, ended; it may be larger than the ring ---- */
static void enc_begin(ad_link *l, uint8_t chan, uint8_t kind);

static void enc_byte(ad_link *l, uint8_t b)
{
    if (l->enc.broken || tx_wait(l, 2, 0)) { l->enc.broken = 1; return; }
    if (b) {
        tx_put(l, b);
        l->enc.code++;
    }
    if (!b || l->enc.code == 0xff) {
        l->tx[l->enc.code_at % l->tx_cap] = l->enc.code;
        l->enc.code_at = l->tx_head;
        l->enc.code = 1;
        tx_put(l, 0);
    }
}

static void enc_bytes(ad_link *l, const uint8_t *p, size_t n)
{
    l->enc.crc = ad_crc32(l->enc.crc, p, n);
    for (size_t i = 0; i < n; i++) enc_byte(l, p[i]);
}

static void enc_begin(ad_link *l, uint8_t chan, uint8_t kind)
{
    uint8_t head[2] = {chan, kind};
    l->enc.open = 1;
    l->enc.broken = 0;
    l->enc.crc = 0;
    l->enc.code = 1;
    l->enc.code_at = l->tx_head;
    tx_put(l, 0); /* the first block's code byte (the caller made room) */
    enc_bytes(l, head, 2);
}

static void enc_end(ad_link *l)
{
    uint8_t tail[4];
    uint32_t crc = l->enc.crc;
    for (int k = 0; k < 4; k++) tail[k] = (uint8_t)(crc >> (8 * k));
    for (int k = 0; k < 4; k++) enc_byte(l, tail[k]);
    if (!l->enc.broken && !tx_wait(l, 1, 0)) {
        l->tx[l->enc.code_at % l->tx_cap] = l->enc.code;
        tx_put(l, 0);
        l->st.frames_out++;
    }
    /* a broken frame (the wire went away mid-frame) keeps its 0x00 placeholder: the
     * receiver sees a frame end there, and drops the damaged frame (CRC) */
    l->enc.open = 0;
}

/* Send one link frame; `droppable` frames go whole or not at all, others wait for room. */
static int send_link(ad_link *l, uint8_t chan, uint8_t kind, const uint8_t *body, size_t n,
                     int droppable)
{
    if (tx_wait(l, droppable ? cobs_max(n + 6u) + 1u : 1u, droppable)) return -1;
    enc_begin(l, chan, kind);
    enc_bytes(l, body, n);
    enc_end(l);
    return l->enc.broken ? -1 : 0;
}

/* A reply in parts (ad_sink.begin/part/end): LIST larger than the library's scratch. */
static int sink_begin(void *ctx, size_t len)
{
    chan_ctx *c = (chan_ctx *)ctx;
    (void)len;
    if (tx_wait(c->link, 1, 0)) return -1;
    enc_begin(c->link, c->id, AD_LINK_DATA);
    return 0;
}

static void sink_part(void *ctx, const uint8_t *bytes, size_t n)
{
    chan_ctx *c = (chan_ctx *)ctx;
    enc_bytes(c->link, bytes, n);
}

static void sink_end(void *ctx)
{
    chan_ctx *c = (chan_ctx *)ctx;
    enc_end(c->link);
}

static size_t sink_room(void *ctx)
{
    chan_ctx *c = (chan_ctx *)ctx;
    size_t f = tx_free(c->link);
    size_t over = 8u + f / 254u;
    /* replies wait for the wire (drain) instead of needing room kept free for them, so the
     * reserve the library keeps for a reply is granted here */
    return (f > over ? f - over : 0) + c->link->max_reply;
}

static int sink_send(void *ctx, const uint8_t *frame, size_t len, int droppable)
{
    chan_ctx *c = (chan_ctx *)ctx;
    return send_link(c->link, c->id, AD_LINK_DATA, frame, len, droppable);
}

ad_link *ad_link_init(void *mem, size_t mem_bytes, ad_device *dev, uint32_t max_frame,
                      uint32_t max_reply, uint32_t channels, ad_link_drain_fn drain, void *io)
{
    if (channels > AD_LINK_MAX_CHANNELS || mem_bytes < ad_link_bytes(max_frame, max_reply, channels)
            || ((uintptr_t)mem & 7u))
        return NULL;
    uint8_t *p = (uint8_t *)mem;
    memset(mem, 0, ad_link_bytes(max_frame, max_reply, channels));
    ad_link *l = (ad_link *)p;
    size_t frame_in = (size_t)max_frame + 6u, frame_out = (size_t)max_reply + 6u;
    p += up8(sizeof(ad_link));
    l->rx = p; l->rx_cap = cobs_max(frame_in); p += up8(l->rx_cap);
    l->tx = p; l->tx_cap = AD_LINK_TX_FRAMES * cobs_max(frame_out) + 64u; p += up8(l->tx_cap);
    l->park = p; l->park_cap = AD_LINK_PARK_FRAMES * ((size_t)max_frame + PARK_HEAD); p += up8(l->park_cap);
    l->chan = (ad_session **)p; p += up8((channels + 1u) * sizeof(ad_session *));
    l->ctx = (chan_ctx *)p;
    l->dev = dev;
    l->max_frame = max_frame;
    l->max_reply = max_reply;
    l->channels = channels;
    l->drain = drain;
    l->io = io;
    for (uint32_t c = 0; c <= channels; c++) { l->ctx[c].link = l; l->ctx[c].id = (uint8_t)c; }
    return l;
}

/* Announce the device; `token` is the relay HELLO's being answered (0 at boot), so the
 * relay can tell its answer from a device that rebooted. */
static void say_hello(ad_link *l, const uint8_t token[4])
{
    uint8_t body[11];
    body[0] = AD_LINK_VERSION;
    body[1] = (uint8_t)l->channels;
    body[2] = (uint8_t)(l->channels >> 8);
    for (int k = 0; k < 4; k++) body[3 + k] = (uint8_t)(l->max_frame >> (8 * k));
    memcpy(body + 7, token, 4);
    send_link(l, 0, AD_LINK_HELLO, body, sizeof body, 0);
}

void ad_link_hello(ad_link *l)
{
    static const uint8_t boot[4] = {0, 0, 0, 0};
    say_hello(l, boot);
}

/* ---- parked frames ---------------------------------------------------------------------- */
static uint32_t park_rec_len(const uint8_t *rec)
{
    return (uint32_t)rec[1] | (uint32_t)rec[2] << 8 | (uint32_t)rec[3] << 16 | (uint32_t)rec[4] << 24;
}

static int chan_parked(const ad_link *l, uint8_t chan)
{
    for (size_t off = 0; off < l->park_len; off += PARK_HEAD + park_rec_len(l->park + off))
        if (l->park[off] == chan) return 1;
    return 0;
}

static int park(ad_link *l, uint8_t chan, const uint8_t *body, size_t n)
{
    if (l->park_len + PARK_HEAD + n > l->park_cap) return -1;
    uint8_t *rec = l->park + l->park_len;
    rec[0] = chan;
    for (int k = 0; k < 4; k++) rec[1 + k] = (uint8_t)(n >> (8 * k));
    memcpy(rec + PARK_HEAD, body, n);
    l->park_len += PARK_HEAD + n;
    return 0;
}

static void unpark_at(ad_link *l, size_t off)
{
    size_t size = PARK_HEAD + park_rec_len(l->park + off);
    memmove(l->park + off, l->park + off + size, l->park_len - off - size);
    l->park_len -= size;
}

/* Hand each channel its parked frames, in order, while it can take them. */
static void unpark(ad_link *l)
{
    uint8_t waiting[32] = {0}; /* channels whose earlier frame still waits: keep their order */
    size_t off = 0;
    while (off < l->park_len) {
        uint8_t chan = l->park[off];
        ad_session *s = l->chan[chan];
        if (!s) { unpark_at(l, off); continue; } /* the channel closed meanwhile */
        if (!(waiting[chan >> 3] & (1u << (chan & 7)))
                && (ad_can_receive(l->dev, s) || ad_wants_close(s, NULL, NULL))) {
            ad_receive(l->dev, s, l->park + off + PARK_HEAD, park_rec_len(l->park + off), l->now_us);
            unpark_at(l, off);
            continue;
        }
        waiting[chan >> 3] |= (uint8_t)(1u << (chan & 7));
        off += PARK_HEAD + park_rec_len(l->park + off);
    }
}

static void close_channel(ad_link *l, uint8_t chan, int code, const char *reason, int tell)
{
    for (size_t off = 0; off < l->park_len;) { /* its parked frames go with it */
        if (l->park[off] == chan) unpark_at(l, off);
        else off += PARK_HEAD + park_rec_len(l->park + off);
    }
    if (l->chan[chan]) {
        ad_close(l->dev, l->chan[chan]);
        l->chan[chan] = NULL;
    }
    if (tell) {
        uint8_t body[2 + 120];
        size_t n = strlen(reason);
        if (n > 120) n = 120;
        body[0] = (uint8_t)code;
        body[1] = (uint8_t)(code >> 8);
        memcpy(body + 2, reason, n);
        send_link(l, chan, AD_LINK_CLOSE, body, 2 + n, 0);
    }
}

/* Act on one decoded link frame; returns 0, or 1 when it must wait (held). */
/* A client arrived on `chan`; `body` is its address as the relay saw it. In a frame of its
 * own, kept off the link's deeper paths (the MCU's stack is small). */
AD_NOINLINE static void open_channel(ad_link *l, uint8_t chan, const uint8_t *body, size_t len)
{
    close_channel(l, chan, 1001, "", 0);
    /* queue_depths: 0 here; a relayed client's packets wait in the Relay's queue */
    ad_sink sink = {sink_room, sink_send, &l->ctx[chan], sink_begin, sink_part, sink_end, NULL};
    char peer[65];
    size_t peer_len = len < sizeof peer - 1 ? len : sizeof peer - 1;
    memcpy(peer, body, peer_len);
    peer[peer_len] = 0;
    l->chan[chan] = ad_open(l->dev, sink, peer, l->now_us);
    if (!l->chan[chan]) close_channel(l, chan, 429, "refused", 1);
}

static int dispatch(ad_link *l, uint8_t *f, size_t n)
{
    uint8_t chan = f[0], kind = f[1];
    uint8_t *body = f + 2;
    size_t len = n - 6;
    if (chan > l->channels) { l->st.framing_errors++; return 0; }
    switch (kind) {
    case AD_LINK_HELLO: {
        /* the relay (re)started: every channel it knew is gone */
        uint8_t token[4] = {0, 0, 0, 0};
        if (len >= 11) memcpy(token, body + 7, 4);
        for (uint32_t c = 1; c <= l->channels; c++) close_channel(l, (uint8_t)c, 1001, "", 0);
        say_hello(l, token);
        break;
    }
    case AD_LINK_PING:
        send_link(l, 0, AD_LINK_PONG, body, len > 8 ? 8 : len, 0);
        break;
    case AD_LINK_OPEN:
        if (chan) open_channel(l, chan, body, len);
        break;
    case AD_LINK_CLOSE:
        if (chan) close_channel(l, chan, 1000, "", 1); /* the answer frees the channel */
        break;
    case AD_LINK_DATA: {
        ad_session *s = chan ? l->chan[chan] : NULL;
        if (!s) break; /* a late frame of a closed channel */
        if ((!ad_can_receive(l->dev, s) && !ad_wants_close(s, NULL, NULL)) || chan_parked(l, chan)) {
            if (!park(l, chan, body, len)) break; /* the other channels go on */
            if (!l->park_cap && s->auth_held) {
                /* an unauthenticated peer must not hold the link for its held AUTH (§10):
                 * the device drops that AUTH and closes the channel */
                ad_receive(l->dev, s, body, len, l->now_us);
                break;
            }
            if (!l->park_cap) return 1;           /* no park (a small MCU): the link waits */
            /* a client that sends more than the park holds while its call runs is cut off,
             * rather than let it hold the link (and every other client) */
            ad_refuse(l->dev, s, 429, "too many requests wait behind a call on this connection");
            break;
        }
        ad_receive(l->dev, s, body, len, l->now_us);
        break;
    }
    default:
        l->st.framing_errors++;
    }
    return 0;
}

/* COBS-decode rx in place; returns the plain length or 0 when malformed. */
static size_t cobs_decode(uint8_t *p, size_t n)
{
    size_t in = 0, out = 0;
    while (in < n) {
        uint8_t code = p[in++];
        if (!code || in + code - 1 > n) return 0;
        for (uint8_t k = 1; k < code; k++) {
            if (!p[in]) return 0;
            p[out++] = p[in++];
        }
        if (code != 0xff && in < n) p[out++] = 0;
    }
    return out;
}

static void complete(ad_link *l)
{
    size_t n = cobs_decode(l->rx, l->rx_len);
    l->rx_len = 0;
    if (n < 6) { l->st.framing_errors++; return; }
    uint32_t crc = ad_crc32(0, l->rx, n - 4);
    uint32_t got = (uint32_t)l->rx[n - 4] | (uint32_t)l->rx[n - 3] << 8
                   | (uint32_t)l->rx[n - 2] << 16 | (uint32_t)l->rx[n - 1] << 24;
    if (crc != got) { l->st.crc_errors++; return; }
    l->st.frames_in++;
    if (dispatch(l, l->rx, n)) { l->held = 1; l->held_len = n; }
}

size_t ad_link_feed(ad_link *l, const uint8_t *bytes, size_t n, int64_t now_us)
{
    l->now_us = now_us;
    size_t i;
    for (i = 0; i < n && !l->held; i++) {
        uint8_t b = bytes[i];
        if (b == 0) {
            if (l->rx_skip) { l->rx_skip = 0; l->rx_len = 0; continue; }
            if (l->rx_len) complete(l);
            continue;
        }
        if (l->rx_skip) continue;
        if (l->rx_len == l->rx_cap) { l->rx_skip = 1; l->st.oversize++; continue; }
        l->rx[l->rx_len++] = b;
    }
    return i;
}

int ad_link_can_feed(const ad_link *l) { return !l->held; }

void ad_link_service(ad_link *l)
{
    unpark(l);
    if (l->held && !dispatch(l, l->rx, l->held_len)) l->held = 0;
    for (uint32_t c = 1; c <= l->channels; c++) {
        int code;
        const char *reason;
        if (l->chan[c] && ad_wants_close(l->chan[c], &code, &reason))
            close_channel(l, (uint8_t)c, code, reason, 1);
    }
}

size_t ad_link_take(ad_link *l, uint8_t *out, size_t max)
{
    size_t n = 0, end = l->enc.open ? l->enc.code_at : l->tx_head; /* not the open block */
    while (n < max && l->tx_tail < end) {
        size_t at = l->tx_tail % l->tx_cap;
        size_t run = l->tx_cap - at;
        size_t avail = end - l->tx_tail;
        if (run > avail) run = avail;
        if (run > max - n) run = max - n;
        memcpy(out + n, l->tx + at, run);
        n += run;
        l->tx_tail += run;
    }
    return n;
}

size_t ad_link_pending(const ad_link *l) { return tx_used(l); }

void ad_link_get_stats(const ad_link *l, ad_link_stats *out) { *out = l->st; }
