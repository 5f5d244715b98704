/* The POSIX host layer (ad_posix.h). */
#define _GNU_SOURCE
#include "ad_posix.h"

#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/socket.h>
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
static volatile sig_atomic_t STOP;
static struct {
    ad_device *dev;
    ad_step_fn step;
    double rate_hz;
    uint64_t hist[LATE_BINS];
    uint64_t ticks, late_max_ns;
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
        uint64_t us = (uint64_t)late / 1000u;
        T.hist[us < LATE_BINS - 1 ? us : LATE_BINS - 1]++;
        if ((uint64_t)late > T.late_max_ns) T.late_max_ns = (uint64_t)late;
        T.ticks++;
        ad_port_lock();
        int64_t t_us = T.step(tick);
        ad_port_unlock();
        ad_tick(T.dev, tick, t_us);
        tick++;
        next += period_ns;
        /* a loop more than 100 ms behind gives those ticks up rather than racing */
        if (mono_ns() - next > 100000000) {
            int64_t skip = (mono_ns() - next) / period_ns;
            next += skip * period_ns;
            tick += (uint64_t)skip;
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
               "\"ring_lost_samples\": %llu}\n",
            (unsigned long long)T.ticks, percentile(0.5), percentile(0.99), percentile(0.999),
            (double)T.late_max_ns / 1000.0, (unsigned long long)st.dropped_samples,
            (unsigned long long)st.ring_lost_samples);
    fclose(f);
}

/* ---- TCP connections ------------------------------------------------------------------------- */
typedef struct conn {
    int fd;
    ad_session *s;
    uint8_t *rx;
    size_t rx_cap, rx_len;
    uint8_t *tx;
    size_t tx_cap, tx_head, tx_tail;
    int closing;           /* no more reading: flush, then close */
    int64_t closing_since;
    struct conn *next;
} conn;

static size_t conn_room(void *ctx)
{
    conn *c = (conn *)ctx;
    size_t f = c->tx_cap - (c->tx_head - c->tx_tail);
    return f > 4 ? f - 4 : 0;
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

static int conn_send(void *ctx, const uint8_t *frame, size_t len, int droppable)
{
    conn *c = (conn *)ctx;
    if (conn_room(c) < len) {
        if (!droppable) c->closing = 1; /* cannot happen while the reserve is kept */
        return -1;
    }
    uint8_t head[4] = {(uint8_t)(len >> 24), (uint8_t)(len >> 16), (uint8_t)(len >> 8), (uint8_t)len};
    tx_put(c, head, 4);
    tx_put(c, frame, len);
    return 0;
}

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
    }
    return 0;
}

static void parse_frames(ad_device *dev, conn *c, uint32_t max_frame, int64_t now_us)
{
    size_t off = 0;
    while (!c->closing && c->s && c->rx_len - off >= 4) {
        uint8_t *p = c->rx + off;
        uint32_t size = (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
        if (size > max_frame) {
            ad_refuse_oversize(dev, c->s, size);
            c->closing = 1;
            break;
        }
        if (c->rx_len - off - 4 < size) break;
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
static void link_drain(void *io)
{
    ad_link *l = (ad_link *)io;
    uint8_t buf[4096];
    struct pollfd p = {LINK_FD, POLLOUT, 0};
    if (poll(&p, 1, 1000) <= 0) return;
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
    pthread_t th;
    pthread_attr_t attr;
    pthread_attr_init(&attr);
    if (pthread_create(&th, &attr, tick_thread, NULL)) { fprintf(stderr, "cannot start the tick thread\n"); return 1; }
    int64_t t_end = o->duration_s > 0 ? mono_ns() + (int64_t)(o->duration_s * 1e9) : 0;
    struct pollfd *pf = calloc(max_conns + 2, sizeof *pf);
    conn **pc = calloc(max_conns + 2, sizeof *pc);

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
            pf[n].events = (short)((!c->closing && c->s && ad_can_receive(dev, c->s) ? POLLIN : 0)
                                   | (c->tx_head != c->tx_tail ? POLLOUT : 0));
            pc[n - base] = c;
            n++;
        }
        poll(pf, (nfds_t)n, 1);
        int64_t now_us = mono_ns() / 1000;
        if (li >= 0 && (pf[li].revents & POLLIN)) {
            int fd = accept4(lfd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
            if (fd >= 0) {
                int one = 1;
                setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
                conn *c = calloc(1, sizeof *c);
                c->fd = fd;
                c->rx_cap = (size_t)cfg->max_frame_bytes + 4;
                c->rx = malloc(c->rx_cap);
                c->tx_cap = 2 * (size_t)cfg->max_reply_bytes + (o->tx_extra_bytes ? o->tx_extra_bytes : (4u << 20));
                c->tx = malloc(c->tx_cap);
                ad_sink sink = {conn_room, conn_send, c};
                c->s = ad_open(dev, sink, now_us);
                if (!c->s) { c->closing = 1; c->closing_since = now_us; }
                c->next = conns;
                conns = c;
                n_conns++;
            }
        }
        for (int i = base; i < n; i++) {
            conn *c = pc[i - base];
            if (pf[i].revents & (POLLIN | POLLHUP | POLLERR)) {
                if (!c->closing && c->rx_len < c->rx_cap) {
                    ssize_t r = recv(c->fd, c->rx + c->rx_len, c->rx_cap - c->rx_len, MSG_DONTWAIT);
                    if (r > 0) c->rx_len += (size_t)r;
                    else if (r == 0 || (errno != EAGAIN && errno != EINTR)) { c->closing = 2; }
                } else if (pf[i].revents & (POLLHUP | POLLERR)) {
                    c->closing = 2;
                }
            }
            if (c->s && c->closing != 2) parse_frames(dev, c, cfg->max_frame_bytes, now_us);
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
            if (c->s && !c->closing && c->rx_len >= 4) parse_frames(dev, c, cfg->max_frame_bytes, now_us);
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
            if (c->s && !c->closing && ad_wants_close(c->s, &code, &reason)) { c->closing = 1; c->closing_since = now_us; }
            if (conn_flush(c)) c->closing = 2;
            int done = c->closing == 2 || (c->closing == 1 && (c->tx_head == c->tx_tail || now_us - c->closing_since > 2000000));
            if (done) {
                *pp = c->next;
                if (c->closing == 1) shutdown(c->fd, SHUT_RDWR);
                conn_free(dev, c);
                n_conns--;
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
