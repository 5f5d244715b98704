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
    uint8_t *tx;
    size_t tx_cap, tx_head, tx_tail;   /* ring of encoded bytes */
    ad_session **chan;     /* [channels + 1] */
    chan_ctx *ctx;         /* [channels + 1] */
    ad_link_drain_fn drain;
    void *io;
    int64_t now_us;
    ad_link_stats st;
};

static size_t cobs_max(size_t n) { return n + n / 254u + 2u; } /* code bytes and the 0x00 */
/* The send ring holds two replies (one being sent while the next is built); a build for a
 * small MCU sets AD_LINK_TX_FRAMES 1 and drains synchronously. */
#ifndef AD_LINK_TX_FRAMES
#define AD_LINK_TX_FRAMES 2u
#endif
static size_t up8(size_t n) { return (n + 7u) & ~(size_t)7u; }

size_t ad_link_bytes(uint32_t max_frame, uint32_t max_reply, uint32_t channels)
{
    size_t frame_in = (size_t)max_frame + 6u, frame_out = (size_t)max_reply + 6u;
    return up8(sizeof(ad_link)) + up8(cobs_max(frame_in)) + up8(AD_LINK_TX_FRAMES * cobs_max(frame_out) + 64u)
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

/* COBS-encode the pieces (chan and kind, body, crc) plus the 0x00 into the ring. */
static void tx_frame(ad_link *l, const uint8_t *head, size_t nh, const uint8_t *body, size_t nb,
                     const uint8_t *tail, size_t nt)
{
    size_t code_at = l->tx_head;
    uint8_t code = 1;
    const uint8_t *parts[3] = {head, body, tail};
    size_t lens[3] = {nh, nb, nt};
    tx_put(l, 0);
    for (int p = 0; p < 3; p++)
        for (size_t i = 0; i < lens[p]; i++) {
            uint8_t b = parts[p][i];
            if (b) {
                tx_put(l, b);
                code++;
            }
            if (!b || code == 0xff) {
                l->tx[code_at % l->tx_cap] = code;
                code_at = l->tx_head;
                code = 1;
                tx_put(l, 0);
            }
        }
    l->tx[code_at % l->tx_cap] = code;
    tx_put(l, 0);
    l->st.frames_out++;
}

/* Send one link frame; `droppable` frames are refused when the ring lacks room. */
static int send_link(ad_link *l, uint8_t chan, uint8_t kind, const uint8_t *body, size_t n,
                     int droppable)
{
    size_t need = cobs_max(n + 6u);
    if (need > l->tx_cap) return -1;
    while (tx_free(l) < need) {
        if (droppable || !l->drain) return -1;
        size_t before = tx_used(l);
        l->drain(l->io);
        if (tx_used(l) == before) return -1; /* the wire is gone */
    }
    uint8_t head[2] = {chan, kind}, tail[4];
    uint32_t crc = ad_crc32(ad_crc32(0, head, 2), body, n);
    for (int k = 0; k < 4; k++) tail[k] = (uint8_t)(crc >> (8 * k));
    tx_frame(l, head, 2, body, n, tail, 4);
    return 0;
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

void ad_link_hello(ad_link *l)
{
    uint8_t body[7];
    body[0] = AD_LINK_VERSION;
    body[1] = (uint8_t)l->channels;
    body[2] = (uint8_t)(l->channels >> 8);
    for (int k = 0; k < 4; k++) body[3 + k] = (uint8_t)(l->max_frame >> (8 * k));
    send_link(l, 0, AD_LINK_HELLO, body, sizeof body, 0);
}

static void close_channel(ad_link *l, uint8_t chan, int code, const char *reason, int tell)
{
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
static int dispatch(ad_link *l, uint8_t *f, size_t n)
{
    uint8_t chan = f[0], kind = f[1];
    uint8_t *body = f + 2;
    size_t len = n - 6;
    if (chan > l->channels) { l->st.framing_errors++; return 0; }
    switch (kind) {
    case AD_LINK_HELLO:
        /* the relay (re)started: every channel it knew is gone */
        for (uint32_t c = 1; c <= l->channels; c++) close_channel(l, (uint8_t)c, 1001, "", 0);
        ad_link_hello(l);
        break;
    case AD_LINK_PING:
        send_link(l, 0, AD_LINK_PONG, body, len > 8 ? 8 : len, 0);
        break;
    case AD_LINK_OPEN: {
        if (!chan) break;
        close_channel(l, chan, 1001, "", 0);
        ad_sink sink = {sink_room, sink_send, &l->ctx[chan]};
        l->chan[chan] = ad_open(l->dev, sink, l->now_us);
        if (!l->chan[chan]) close_channel(l, chan, 429, "refused", 1);
        break;
    }
    case AD_LINK_CLOSE:
        if (chan) close_channel(l, chan, 1000, "", 1); /* the answer frees the channel */
        break;
    case AD_LINK_DATA: {
        ad_session *s = chan ? l->chan[chan] : NULL;
        if (!s) break; /* a late frame of a closed channel */
        if (!ad_can_receive(l->dev, s) && !ad_wants_close(s, NULL, NULL)) return 1;
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
    size_t n = 0;
    while (n < max && l->tx_tail < l->tx_head) {
        size_t at = l->tx_tail % l->tx_cap;
        size_t run = l->tx_cap - at;
        size_t avail = l->tx_head - l->tx_tail;
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
