/*
 * The framed link: ASTCom over one byte stream (UART, SPI, a pty, a TCP pipe) shared by
 * many clients through the Relay (docs/astcom-protocol.md §11).
 *
 * Each link frame is COBS(chan, kind, body..., crc32 LE) followed by a 0x00 byte; the
 * CRC (IEEE 802.3, as zlib's crc32) covers chan, kind and body. A damaged or oversized
 * frame is skipped up to the next 0x00 and counted; nothing else is lost. Channel c
 * (1..255) is one client's ASTCom connection: the device runs one session per channel,
 * with its own handshake, authentication, messages and streams, exactly as for a TCP
 * connection. Sans I/O: feed received bytes with ad_link_feed(); take bytes to send
 * with ad_link_take(); `drain` is called when a reply must wait for the wire.
 */
#ifndef AD_LINK_H
#define AD_LINK_H

#include <stddef.h>
#include <stdint.h>

#include "astcom_device.h"

#define AD_LINK_VERSION 1
enum ad_link_kind {
    AD_LINK_DATA = 1,   /* an ASTCom frame of channel `chan` (either way) */
    AD_LINK_OPEN = 2,   /* relay -> device: a client arrived on `chan` (body: its address) */
    AD_LINK_CLOSE = 3,  /* either way: `chan` is over; from the device: u16 LE code + reason */
    AD_LINK_HELLO = 4,  /* chan 0: u8 version, u16 LE channels, u32 LE max_frame_bytes,
                           u32 LE token (the relay's; the device echoes it, 0 at boot) */
    AD_LINK_PING = 5,   /* chan 0, relay -> device: u32 token */
    AD_LINK_PONG = 6    /* chan 0, device -> relay: the same token */
};

#define AD_LINK_MAX_CHANNELS 255

typedef struct ad_link ad_link;
typedef void (*ad_link_drain_fn)(void *io);

/* Bytes the link needs for a device whose frames are at most `max_frame_bytes` in and
 * `max_reply_bytes` out, with `channels` channels (<= AD_LINK_MAX_CHANNELS): its receive
 * buffer, its send ring, the park and the channel tables. */
size_t ad_link_bytes(uint32_t max_frame_bytes, uint32_t max_reply_bytes, uint32_t channels);
ad_link *ad_link_init(void *mem, size_t mem_bytes, ad_device *dev, uint32_t max_frame_bytes,
                      uint32_t max_reply_bytes, uint32_t channels, ad_link_drain_fn drain,
                      void *io);
/* Announce the device at boot (a HELLO on channel 0 with token 0); a relay's HELLO is
 * answered by the link itself, with the relay's token. */
void ad_link_hello(ad_link *link);
/* Returns the bytes consumed. A frame for a channel that cannot take it yet (a deferred
 * call runs there) is parked, so the other channels go on, and handed on by
 * ad_link_service(); a channel that overflows the park (AD_LINK_PARK_FRAMES frames) is
 * closed with ERR 429. Built without a park (0, a small MCU), fewer than `n` are consumed
 * instead: feed the rest after ad_link_service(). */
size_t ad_link_feed(ad_link *link, const uint8_t *bytes, size_t n, int64_t now_us);
/* Close the channels the device wants closed (after BYE, errors); call after ad_poll. */
void ad_link_service(ad_link *link);
/* Up to `max` bytes to send; returns how many were copied into `out`. */
size_t ad_link_take(ad_link *link, uint8_t *out, size_t max);
/* Bytes waiting to be sent. */
size_t ad_link_pending(const ad_link *link);
/* True when no received frame waits because a channel cannot take it yet. */
int ad_link_can_feed(const ad_link *link);

typedef struct ad_link_stats {
    uint64_t frames_in, frames_out, crc_errors, framing_errors, oversize;
} ad_link_stats;
void ad_link_get_stats(const ad_link *link, ad_link_stats *out);

/* The CRC of the link (zlib's crc32: reflected 0xEDB88320, init and xorout 0xFFFFFFFF). */
uint32_t ad_crc32(uint32_t crc, const uint8_t *p, size_t n);

#endif
