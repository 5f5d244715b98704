/* The POSIX host layer (ad_posix.h). */
#define _GNU_SOURCE
#include "ad_posix.h"

#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <arpa/inet.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "ad_link.h"

/* ---- the host layer of astcom_device.h ------------------------------------------------- */
static pthread_mutex_t LOCK = PTHREAD_MUTEX_INITIALIZER;
void ad_port_lock(void) { pthread_mutex_lock(&LOCK); }
void ad_port_unlock(void) { pthread_mutex_unlock(&LOCK); }

int ad_port_random(uint8_t *out, size_t n)
{
    size_t got = 0;
    while (got < n) {
        ssize_t r = getrandom(out + got, n - got, 0);
        if (r < 0) { if (errno == EINTR) continue; return -1; }
        got += (size_t)r;
    }
    return 0;
}

int64_t ad_posix_wall_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}
int64_t ad_port_wall_us(void) { return ad_posix_wall_us(); }

static int64_t mono_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

/* ---- the tick thread ---------------------------------------------------------------------- */
#define LATE_BINS 20001 /* 0..20 ms in µs, the last bin holds everything later */
#define SKIP_AFTER_NS 2000000000LL
static volatile sig_atomic_t STOP;
static struct {
    ad_device *dev;
    ad_step_fn step;
    double rate_hz;
    uint64_t hist[LATE_BINS];
    uint64_t ticks, late_max_ns, skipped;
    int64_t count_from_ns;  /* ticks due before this (monotonic) are not counted */
} T;

static void *tick_thread(void *arg)
{
    (void)arg;
    int64_t period_ns = (int64_t)(1e9 / T.rate_hz);
    int64_t start = mono_ns(), next = start;
    uint64_t tick = 0;
    while (!STOP) {
        struct timespec ts = {(time_t)(next / 1000000000), (long)(next % 1000000000)};
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR && !STOP) {}
        int64_t late = mono_ns() - next;
        if (late < 0) late = 0;
        if (next >= T.count_from_ns) {
            uint64_t us = (uint64_t)late / 1000u;
            T.hist[us < LATE_BINS - 1 ? us : LATE_BINS - 1]++;
            if ((uint64_t)late > T.late_max_ns) T.late_max_ns = (uint64_t)late;
            T.ticks++;
        }
        ad_port_lock();
        int64_t t_us = T.step(tick);
        ad_port_unlock();
        ad_tick(T.dev, tick, t_us);
        tick++;
        next += period_ns;
        /* A late loop catches up (its ticks run back to back at their own times, so no
         * tick and no sample is missing after the host took the CPU away for a while);
         * only a loop more than SKIP_AFTER_NS behind, a host that cannot keep the rate,
         * gives those ticks up (the tick numbers jump, a new clock segment; counted). */
        if (mono_ns() - next > SKIP_AFTER_NS) {
            int64_t skip = (mono_ns() - next) / period_ns;
            next += skip * period_ns;
            tick += (uint64_t)skip;
            T.skipped += (uint64_t)skip;
        }
    }
    return NULL;
}

static double percentile(double q)
{
    uint64_t want = (uint64_t)(q * (double)T.ticks), seen = 0;
    for (int i = 0; i < LATE_BINS; i++) {
        seen += T.hist[i];
        if (seen > want) return i;
    }
    return LATE_BINS - 1;
}

static void write_stats(const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f) return;
    ad_stats st;
    ad_get_stats(T.dev, &st);
    fprintf(f, "{\"ticks\": %llu, \"late_p50_us\": %.0f, \"late_p99_us\": %.0f, "
               "\"late_p999_us\": %.0f, \"late_max_us\": %.1f, \"dropped_samples\": %llu, "
               "\"ring_lost_samples\": %llu, \"skipped_ticks\": %llu}\n",
            (unsigned long long)T.ticks, percentile(0.5), percentile(0.99), percentile(0.999),
            (double)T.late_max_ns / 1000.0, (unsigned long long)st.dropped_samples,
            (unsigned long long)st.ring_lost_samples, (unsigned long long)T.skipped);
    fclose(f);
}

/* ---- TCP connections ------------------------------------------------------------------------- */
/* A connection's end: no more requests are read (C_FLUSH) while the frames already built
 * (the last reply, the ERR that says why) are sent; then our side shuts down (FIN) and
 * what the peer still sends is read and thrown away until it closes too (C_LINGER).
 * Closing a socket whose receive queue holds unread bytes makes the kernel send a RST,
 * and a RST makes the peer's kernel discard the replies it has not read yet: the peer
 * would never see why it was cut off. Each phase lasts at most CLOSE_WAIT_US. */
enum { C_OPEN, C_FLUSH, C_DEAD, C_LINGER };
#define CLOSE_WAIT_US 2000000
#define LINGER_BYTES (1u << 20)

typedef struct conn {
    int fd;
    ad_session *s;
    uint8_t *rx;
    size_t rx_cap, rx_len, rx_limit;   /* rx grows to the frame a header announces */
    uint8_t *tx;
    size_t tx_cap, tx_head, tx_tail, tx_limit; /* the send ring grows up to tx_limit */
    size_t frames, data_frames; /* frames in the ring, of them stream packets (STATS) */
    size_t frame_end;           /* where the frame at the tail ends */
    int frame_is_data;
    int closing;           /* C_OPEN, C_FLUSH, C_DEAD or C_LINGER */
    int64_t closing_since; /* µs (monotonic) when the phase began */
    int lingered;          /* counted in n_linger instead of n_conns */
    struct conn *next;
} conn;

static void begin_close(conn *c)
{
    if (c->closing == C_OPEN) {
        c->closing = C_FLUSH;
        c->closing_since = mono_ns() / 1000;
    }
}

/* Buffers start small and grow to what the connection uses, up to their limits: a peer
 * that connects and says little (or only garbage) costs a few KiB, not the limits. */
#define RX_START 4096u
#define TX_START 16384u

static size_t conn_room(void *ctx)
{
    conn *c = (conn *)ctx;
    size_t f = c->tx_limit - (c->tx_head - c->tx_tail);
    return f > 4 ? f - 4 : 0;
}

/* Make the send ring hold `need` more bytes (its contents moved to the start). */
static int tx_grow(conn *c, size_t need)
{
    size_t used = c->tx_head - c->tx_tail, cap = c->tx_cap;
    if (cap - used >= need) return 0;
    while (cap - used < need) cap *= 2;
    if (cap > c->tx_limit) cap = c->tx_limit;
    if (cap - used < need) return -1;
    uint8_t *t = malloc(cap);
    if (!t) return -1;
    for (size_t i = 0; i < used;) {
        size_t at = (c->tx_tail + i) % c->tx_cap, run = c->tx_cap - at;
        if (run > used - i) run = used - i;
        memcpy(t + i, c->tx + at, run);
        i += run;
    }
    free(c->tx);
    c->tx = t;
    c->tx_cap = cap;
    c->frame_end -= c->tx_tail;
    c->tx_tail = 0;
    c->tx_head = used;
    return 0;
}

static void tx_put(conn *c, const uint8_t *p, size_t n)
{
    for (size_t i = 0; i < n;) {
        size_t at = c->tx_head % c->tx_cap, run = c->tx_cap - at;
        if (run > n - i) run = n - i;
        memcpy(c->tx + at, p + i, run);
        c->tx_head += run;
        i += run;
    }
}

/* ---- counting the frames in the ring: their length prefixes mark where each ends -------- */
static void tx_peek(const conn *c, size_t at, uint8_t *out, size_t n)
{
    for (size_t i = 0; i < n; i++) out[i] = c->tx[(at + i) % c->tx_cap];
}

static int is_data(const uint8_t *frame_head) /* an array of 9 starting with "DATA" */
{
    return frame_head[0] == 0x99 && frame_head[1] == 0xa4;
}

static void frame_queued(conn *c, size_t len, int data)
{
    if (!c->frames) {
        c->frame_end = c->tx_head + 4 + len;
        c->frame_is_data = data;
    }
    c->frames++;
    c->data_frames += data != 0;
}

static void frames_sent(conn *c)
{
    while (c->frames && c->tx_tail >= c->frame_end) {
        c->frames--;
        c->data_frames -= c->frame_is_data != 0;
        if (!c->frames) break;
        uint8_t h[6];
        tx_peek(c, c->frame_end, h, 6);
        size_t len = (size_t)h[0] << 24 | (size_t)h[1] << 16 | (size_t)h[2] << 8 | h[3];
        c->frame_is_data = len >= 2 && is_data(h + 4);
        c->frame_end += 4 + len;
    }
}

static size_t conn_queued(void *ctx) { return ((conn *)ctx)->data_frames; }

static int conn_send(void *ctx, const uint8_t *frame, size_t len, int droppable)
{
    conn *c = (conn *)ctx;
    if (conn_room(c) < len || tx_grow(c, len + 4)) {
        if (!droppable) begin_close(c); /* cannot happen while the reserve is kept */
        return -1;
    }
    frame_queued(c, len, len >= 2 && is_data(frame));
    uint8_t head[4] = {(uint8_t)(len >> 24), (uint8_t)(len >> 16), (uint8_t)(len >> 8), (uint8_t)len};
    size_t sent = 0;
    if (c->tx_head == c->tx_tail && c->closing != C_LINGER) {
        /* nothing waits: straight to the socket, no copy into the ring unless it is full */
        struct iovec iov[2] = {{head, 4}, {(void *)frame, len}};
        struct msghdr mh;
        memset(&mh, 0, sizeof mh);
        mh.msg_iov = iov;
        mh.msg_iovlen = 2;
        ssize_t w = sendmsg(c->fd, &mh, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (w > 0) sent = (size_t)w;
        if (sent == len + 4) {
            c->tx_head += sent; /* as if it went through the ring */
            c->tx_tail += sent;
            frames_sent(c);
            return 0;
        }
    }
    tx_put(c, head, 4);
    tx_put(c, frame, len);
    c->tx_tail += sent;
    frames_sent(c);
    return 0;
}

/* a reply in parts (a LIST larger than the library's scratch): its length first, room for
 * all of it now (the send ring grows to its limit), then the parts as they come */
static int conn_begin(void *ctx, size_t len)
{
    conn *c = (conn *)ctx;
    if (conn_room(c) < len + 4 || len > UINT32_MAX || tx_grow(c, len + 4)) return -1;
    frame_queued(c, len, 0);
    uint8_t head[4] = {(uint8_t)(len >> 24), (uint8_t)(len >> 16), (uint8_t)(len >> 8), (uint8_t)len};
    tx_put(c, head, 4);
    return 0;
}

static void conn_part(void *ctx, const uint8_t *bytes, size_t n) { tx_put((conn *)ctx, bytes, n); }
static void conn_end(void *ctx) { (void)ctx; }

static int conn_flush(conn *c)
{
    while (c->tx_tail < c->tx_head) {
        size_t at = c->tx_tail % c->tx_cap, run = c->tx_cap - at, avail = c->tx_head - c->tx_tail;
        if (run > avail) run = avail;
        ssize_t w = send(c->fd, c->tx + at, run, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (w < 0) {
            if (errno == EAGAIN || errno == EWOULDBLOCK) return 0;
            if (errno == EINTR) continue;
            return -1;
        }
        c->tx_tail += (size_t)w;
        frames_sent(c);
    }
    return 0;
}

static conn *conn_new(int fd, const ad_config *cfg, const ad_posix_opts *o)
{
    conn *c = calloc(1, sizeof *c);
    if (!c) return NULL;
    c->fd = fd;
    c->rx_limit = (size_t)cfg->max_frame_bytes + 4;
    c->rx_cap = c->rx_limit < RX_START ? c->rx_limit : RX_START;
    c->tx_limit = 2 * (size_t)cfg->max_reply_bytes + (o->tx_extra_bytes ? o->tx_extra_bytes : (4u << 20));
    c->tx_cap = c->tx_limit < TX_START ? c->tx_limit : TX_START;
    c->rx = malloc(c->rx_cap);
    c->tx = malloc(c->tx_cap);
    if (!c->rx || !c->tx) {
        free(c->rx);
        free(c->tx);
        free(c);
        return NULL;
    }
    return c;
}

/* "a.b.c.d:port" or "[v6]:port": password attempts are throttled per address (§10) */
static void peer_text(const struct sockaddr_storage *sa, socklen_t len, char *out, size_t cap)
{
    char host[INET6_ADDRSTRLEN] = "?";
    unsigned port = 0;
    if (sa->ss_family == AF_INET && len >= (socklen_t)sizeof(struct sockaddr_in)) {
        const struct sockaddr_in *a = (const struct sockaddr_in *)sa;
        inet_ntop(AF_INET, &a->sin_addr, host, sizeof host);
        port = ntohs(a->sin_port);
        snprintf(out, cap, "%s:%u", host, port);
    } else if (sa->ss_family == AF_INET6 && len >= (socklen_t)sizeof(struct sockaddr_in6)) {
        const struct sockaddr_in6 *a = (const struct sockaddr_in6 *)sa;
        inet_ntop(AF_INET6, &a->sin6_addr, host, sizeof host);
        port = ntohs(a->sin6_port);
        snprintf(out, cap, "[%s]:%u", host, port);
    } else {
        snprintf(out, cap, "?");
    }
}

static void parse_frames(ad_device *dev, conn *c, int64_t now_us)
{
    size_t off = 0;
    while (!c->closing && c->s && c->rx_len - off >= 4) {
        uint8_t *p = c->rx + off;
        uint32_t size = (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
        if (size > ad_frame_limit(dev, c->s)) {
            ad_refuse_oversize(dev, c->s, size);
            begin_close(c);
            break;
        }
        if (c->rx_len - off - 4 < size) {
            if (4 + (size_t)size > c->rx_cap) { /* make room for the whole frame */
                memmove(c->rx, c->rx + off, c->rx_len - off);
                c->rx_len -= off;
                off = 0;
                uint8_t *r = realloc(c->rx, 4 + (size_t)size);
                if (!r) { c->closing = C_DEAD; return; }
                c->rx = r;
                c->rx_cap = 4 + (size_t)size;
            }
            break;
        }
        if (!ad_can_receive(dev, c->s)) break;
        ad_receive(dev, c->s, p + 4, size, now_us);
        off += 4 + (size_t)size;
    }
    if (off) {
        memmove(c->rx, c->rx + off, c->rx_len - off);
        c->rx_len -= off;
    }
}

static int listen_tcp(const char *spec, char *url, size_t url_len)
{
    char host[256];
    const char *colon = strrchr(spec, ':');
    if (!colon || (size_t)(colon - spec) >= sizeof host) return -1;
    memcpy(host, spec, (size_t)(colon - spec));
    host[colon - spec] = 0;
    struct addrinfo hints, *ai;
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_INET;
    hints.ai_socktype = SOCK_STREAM;
    hints.ai_flags = AI_PASSIVE;
    if (getaddrinfo(host, colon + 1, &hints, &ai)) return -1;
    int fd = socket(ai->ai_family, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    int one = 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (fd < 0 || bind(fd, ai->ai_addr, ai->ai_addrlen) || listen(fd, 64)) {
        freeaddrinfo(ai);
        if (fd >= 0) close(fd);
        return -1;
    }
    freeaddrinfo(ai);
    struct sockaddr_in sa;
    socklen_t sl = sizeof sa;
    getsockname(fd, (struct sockaddr *)&sa, &sl);
    snprintf(url, url_len, "tcp://%s:%u", host, (unsigned)ntohs(sa.sin_port));
    return fd;
}

/* ---- the framed link ---------------------------------------------------------------------------- */
static int LINK_FD = -1;
/* The link's reply must wait for the wire: wait for the reader (the Relay) up to 10 s,
 * while it is there; a closed other end (POLLHUP, EIO) is a wire that is gone. */
static void link_drain(void *io)
{
    ad_link *l = (ad_link *)io;
    uint8_t buf[4096];
    struct pollfd p = {LINK_FD, POLLOUT, 0};
    for (int waited = 0; waited < 100; waited++) {
        int r = poll(&p, 1, 100);
        if (r < 0 && errno != EINTR) return;
        if (p.revents & (POLLERR | POLLNVAL)) return;
        if (r > 0 && (p.revents & POLLOUT)) break;
        if (STOP) return;
    }
    size_t n = ad_link_take(l, buf, sizeof buf);
    size_t done = 0;
    while (done < n) {
        ssize_t w = write(LINK_FD, buf + done, n - done);
        if (w < 0) {
            if (errno == EINTR) continue;
            if (errno == EAGAIN) { poll(&p, 1, 100); continue; }
            return;
        }
        done += (size_t)w;
    }
}

static int open_serial(const char *path)
{
    int fd = open(path, O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) return -1;
    struct termios t;
    if (!tcgetattr(fd, &t)) {
        cfmakeraw(&t);
        cfsetspeed(&t, B921600);
        tcsetattr(fd, TCSANOW, &t);
    }
    return fd;
}

static void on_signal(int sig) { (void)sig; STOP = 1; }

static void conn_free(ad_device *dev, conn *c)
{
    if (c->s) ad_close(dev, c->s);
    close(c->fd);
    free(c->rx);
    free(c->tx);
    free(c);
}

int ad_posix_run(ad_device *dev, const ad_posix_opts *o, ad_step_fn step)
{
    const ad_config *cfg = ad_device_config(dev);
    char url[300];
    int lfd = -1;
    conn *conns = NULL;
    ad_link *link = NULL;
    void *link_mem = NULL;
    uint8_t link_in[8192];
    size_t link_in_len = 0, link_in_off = 0;
    uint32_t n_conns = 0, max_conns = cfg->max_clients + cfg->max_pending + 1;

    signal(SIGPIPE, SIG_IGN);
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    if (o->tcp) {
        lfd = listen_tcp(o->tcp, url, sizeof url);
        if (lfd < 0) { fprintf(stderr, "cannot listen on %s: %s\n", o->tcp, strerror(errno)); return 1; }
        printf("listening on %s\n", url);
    }
    if (o->serial) {
        LINK_FD = open_serial(o->serial);
        if (LINK_FD < 0) { fprintf(stderr, "cannot open the link %s: %s\n", o->serial, strerror(errno)); return 1; }
        uint32_t ch = o->link_channels ? o->link_channels : 16;
        size_t bytes = ad_link_bytes(cfg->max_frame_bytes, cfg->max_reply_bytes, ch);
        if (posix_memalign(&link_mem, 8, (bytes + 7) & ~(size_t)7)) link_mem = NULL;
        link = link_mem ? ad_link_init(link_mem, bytes, dev, cfg->max_frame_bytes,
                                       cfg->max_reply_bytes, ch, link_drain, NULL) : NULL;
        if (!link) { fprintf(stderr, "cannot set the link up (%zu bytes)\n", bytes); return 1; }
        /* the drain callback needs the link itself */
        link = ad_link_init(link_mem, bytes, dev, cfg->max_frame_bytes, cfg->max_reply_bytes, ch,
                            link_drain, link_mem);
        ad_link_hello(link);
        printf("link on %s\n", o->serial);
    }
    fflush(stdout);

    T.dev = dev;
    T.step = step;
    T.rate_hz = cfg->loop_rate_hz;
    T.count_from_ns = mono_ns() + (int64_t)(o->warmup_s * 1e9);
    pthread_t th;
    pthread_attr_t attr;
    pthread_attr_init(&attr);
    if (o->rt_priority > 0) {
        /* a controller's loop: SCHED_FIFO, above every ordinary process of the host */
        struct sched_param sp = {.sched_priority = o->rt_priority};
        pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED);
        pthread_attr_setschedpolicy(&attr, SCHED_FIFO);
        pthread_attr_setschedparam(&attr, &sp);
    }
    int err = pthread_create(&th, &attr, tick_thread, NULL);
    if (err) {
        fprintf(stderr, "cannot start the tick thread%s: %s\n",
                o->rt_priority > 0 ? " at SCHED_FIFO priority (needs CAP_SYS_NICE or an rtprio limit)" : "",
                strerror(err));
        return 1;
    }
    int64_t t_end = o->duration_s > 0 ? mono_ns() + (int64_t)(o->duration_s * 1e9) : 0;
    /* lingering connections do not hold a slot; at most max_conns of them at once */
    uint32_t n_linger = 0;
    struct pollfd *pf = calloc(2 * (size_t)max_conns + 2, sizeof *pf);
    conn **pc = calloc(2 * (size_t)max_conns + 2, sizeof *pc);

    while (!STOP && (!t_end || mono_ns() < t_end)) {
        int n = 0, li = -1, ki = -1;
        if (lfd >= 0) { pf[n].fd = lfd; pf[n].events = n_conns < max_conns ? POLLIN : 0; li = n++; }
        if (link) {
            pf[n].fd = LINK_FD;
            pf[n].events = (short)((link_in_off == link_in_len ? POLLIN : 0) | (ad_link_pending(link) ? POLLOUT : 0));
            ki = n++;
        }
        int base = n;
        for (conn *c = conns; c; c = c->next) {
            pf[n].fd = c->fd;
            pf[n].events = (short)((c->closing == C_LINGER
                                    || (c->closing == C_OPEN && c->s && ad_can_receive(dev, c->s)) ? POLLIN : 0)
                                   | (c->tx_head != c->tx_tail ? POLLOUT : 0));
            pc[n - base] = c;
            n++;
        }
        /* sleep until a stream packet or an auth timeout is due (or I/O), 1..50 ms; a
         * link waiting for room, or a deferred call, wakes every millisecond */
        int64_t delay_us = ad_poll_delay_us(dev, mono_ns() / 1000, 50000);
        int wait_ms = (int)((delay_us + 999) / 1000);
        if (wait_ms < 1 || (link && (link_in_off < link_in_len || !ad_link_can_feed(link)))) wait_ms = 1;
        poll(pf, (nfds_t)n, wait_ms);
        int64_t now_us = mono_ns() / 1000;
        if (li >= 0 && (pf[li].revents & POLLIN)) {
            struct sockaddr_storage sa;
            socklen_t sa_len = sizeof sa;
            int fd = accept4(lfd, (struct sockaddr *)&sa, &sa_len, SOCK_NONBLOCK | SOCK_CLOEXEC);
            if (fd >= 0) {
                char peer[INET6_ADDRSTRLEN + 16];
                peer_text(&sa, sa_len, peer, sizeof peer);
                int one = 1;
                setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
                conn *c = conn_new(fd, cfg, o);
                if (!c) {
                    close(fd); /* out of memory: refuse this one */
                } else {
                    ad_sink sink = {conn_room, conn_send, c, conn_begin, conn_part, conn_end,
                                    conn_queued};
                    c->s = ad_open(dev, sink, peer, now_us);
                    if (!c->s) begin_close(c);
                    c->next = conns;
                    conns = c;
                    n_conns++;
                }
            }
        }
        for (int i = base; i < n; i++) {
            conn *c = pc[i - base];
            if (c->closing == C_LINGER) {
                if (pf[i].revents & (POLLIN | POLLHUP | POLLERR)) {
                    uint8_t sink[4096];
                    ssize_t r = recv(c->fd, sink, sizeof sink, MSG_DONTWAIT);
                    if (r == 0 || (r < 0 && errno != EAGAIN && errno != EINTR)) c->closing = C_DEAD;
                    /* frames in flight, not a flood: beyond LINGER_BYTES it is not read on */
                    if (r > 0 && (c->rx_len += (size_t)r) > LINGER_BYTES) c->closing = C_DEAD;
                }
                continue;
            }
            if (pf[i].revents & (POLLIN | POLLHUP | POLLERR)) {
                if (c->closing == C_OPEN && c->rx_len < c->rx_cap) {
                    ssize_t r = recv(c->fd, c->rx + c->rx_len, c->rx_cap - c->rx_len, MSG_DONTWAIT);
                    if (r > 0) c->rx_len += (size_t)r;
                    else if (r == 0 || (errno != EAGAIN && errno != EINTR)) c->closing = C_DEAD;
                } else if (pf[i].revents & (POLLHUP | POLLERR)) {
                    c->closing = C_DEAD;
                }
            }
            if (c->s && c->closing != C_DEAD) parse_frames(dev, c, now_us);
        }
        if (link && ki >= 0) {
            if (pf[ki].revents & POLLIN) {
                ssize_t r = read(LINK_FD, link_in, sizeof link_in);
                if (r > 0) { link_in_len = (size_t)r; link_in_off = 0; }
            }
            if (link_in_off < link_in_len)
                link_in_off += ad_link_feed(link, link_in + link_in_off, link_in_len - link_in_off, now_us);
        }
        ad_poll(dev, now_us);
        for (conn *c = conns; c; c = c->next) {
            /* frames left in rx while a call was pending or the sink was full */
            if (c->s && c->closing == C_OPEN && c->rx_len >= 4) parse_frames(dev, c, now_us);
        }
        if (link) {
            ad_link_service(link);
            if (ad_link_pending(link)) link_drain(link);
        }
        conn **pp = &conns;
        while (*pp) {
            conn *c = *pp;
            int code;
            const char *reason;
            if (c->s && c->closing == C_OPEN && ad_wants_close(c->s, &code, &reason)) begin_close(c);
            if (c->closing != C_LINGER && conn_flush(c)) c->closing = C_DEAD;
            int late = c->closing != C_OPEN && now_us - c->closing_since > CLOSE_WAIT_US;
            if (c->closing == C_FLUSH && (c->tx_head == c->tx_tail || late)) {
                c->closing = C_DEAD;
                if (!late && n_linger < max_conns && !shutdown(c->fd, SHUT_WR)) {
                    /* the session is over and its slot free; the socket lingers */
                    if (c->s) { ad_close(dev, c->s); c->s = NULL; }
                    c->closing = C_LINGER;
                    c->closing_since = now_us;
                    c->lingered = 1;
                    c->rx_len = 0; /* from now on: the bytes dropped */
                    n_conns--;
                    n_linger++;
                }
            }
            if (c->closing == C_LINGER && late) c->closing = C_DEAD;
            if (c->closing == C_DEAD) {
                *pp = c->next;
                if (c->lingered) n_linger--; else n_conns--;
                conn_free(dev, c);
                continue;
            }
            pp = &c->next;
        }
    }
    STOP = 1;
    pthread_join(th, NULL);
    while (conns) { conn *c = conns; conns = c->next; conn_free(dev, c); }
    if (o->stats_path) write_stats(o->stats_path);
    free(pf);
    free(pc);
    free(link_mem);
    if (lfd >= 0) close(lfd);
    return 0;
}
