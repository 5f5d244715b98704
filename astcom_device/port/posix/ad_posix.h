/* The POSIX host layer: a real-time tick thread, a TCP server and a framed serial link,
 * pumped by one poll() loop. Memory: the device's arena (ad_arena_bytes), and per TCP
 * connection a receive buffer and a send ring that start at 4 KiB and 16 KiB and grow
 * to what the connection needs, up to max_frame_bytes + 4 and 2 × max_reply_bytes +
 * tx_extra_bytes; freed when it leaves. At most max_clients + max_pending + 1
 * connections hold a slot at once, and as many more may linger (2 s, 1 MiB at most) while
 * their peers read the last frames (the TCP close is not a reset). The tick thread runs
 * late ticks back to back; more than 2 s behind, it gives them up (counted). */
#ifndef AD_POSIX_H
#define AD_POSIX_H

#include <stdint.h>

#include "astcom_device.h"

typedef struct ad_posix_opts {
    const char *tcp;          /* "HOST:PORT" to listen on (port 0: any free port), or NULL */
    const char *serial;       /* a tty or pty path for the framed link, or NULL */
    uint32_t link_channels;   /* channels of the framed link */
    double duration_s;        /* stop after this long (0: until SIGINT/SIGTERM) */
    uint32_t tx_extra_bytes;  /* per TCP connection, beyond two replies */
    const char *stats_path;   /* write the loop's lateness figures here as JSON at exit */
    double warmup_s;          /* the lateness figures leave out the first warmup_s */
    int rt_priority;          /* > 0: the tick thread runs SCHED_FIFO at this priority */
} ad_posix_opts;

/* Compute one tick (called with the critical section held); return its mount time. */
typedef int64_t (*ad_step_fn)(uint64_t tick);

/* Run until stopped. Prints "listening on tcp://HOST:PORT" and/or "link on PATH" to stdout.
 * Returns 0, or 1 when a transport cannot be set up (the reason on stderr). */
int ad_posix_run(ad_device *dev, const ad_posix_opts *opts, ad_step_fn step);
int64_t ad_posix_wall_us(void);

#endif
