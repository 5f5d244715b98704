/* The trace ring and the stream samplers (§6).
 *
 * ad_tick() (control side) copies the traced signals of one tick into row `head % N` of
 * the ring, then publishes head + 1 under the critical section; that is all it does.
 * The communication side builds DATA packets straight from the ring: a sampler
 * (message, k) waits until the ring holds `samples_per_packet` of its grid ticks, then
 * encodes them once and hands the frame to every subscriber's sink. Rows the ring
 * overwrote before a sampler got to them are lost: the sampler skips them, counts them
 * (STATS dropped_samples of each subscriber) and advances its packet seq as if the
 * packets had been made, so a client's loss detection (seq jump) sees them.
 *
 * Clock segments: consecutive ticks whose mount times follow the loop rate form one
 * segment; sample times come from the segment's first tick and time by the spec's
 * rounding rule. A packet never spans two segments.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "ad_internal.h"

int64_t ad_round_half_up(double x)
{
    double f = floor(x);
    return (int64_t)f + (x - f >= 0.5);
}

static const ad_segment *seg_at(const ad_device *dev, uint32_t k)
{
    return &dev->seg[k % AD_MAX_SEGMENTS];
}

void ad_tick(ad_device *dev, uint64_t tick, int64_t t_us)
{
    uint64_t h = dev->head;
    uint8_t *row = dev->ring + (size_t)(h % dev->cfg.ring_ticks) * dev->row_bytes;
    for (uint32_t c = 0; c < dev->n_traced; c++) {
        uint16_t i = dev->traced[c];
        const ad_var_rt *rt = &dev->vrt[i];
        memcpy(row + rt->ring_offset, dev->vars[i].ptr, rt->c_size);
    }
    int new_seg = 1;
    if (dev->n_seg) {
        const ad_segment *s = seg_at(dev, dev->n_seg - 1);
        uint64_t last = s->tick0 + (h - 1 - s->row0);
        new_seg = tick != last + 1
                  || t_us != s->t0_us + ad_round_half_up((double)(tick - s->tick0) * dev->tick_us);
    }
    ad_port_lock();
    if (new_seg) {
        ad_segment *s = &dev->seg[dev->n_seg % AD_MAX_SEGMENTS];
        s->row0 = h;
        s->tick0 = tick;
        s->t0_us = t_us;
        dev->n_seg++;
    }
    dev->head = h + 1;
    ad_port_unlock();
}

/* Call with the critical section held. */
void ad_last_tick(ad_device *dev, int64_t *tick, int64_t *t_us)
{
    if (!dev->head || !dev->n_seg) { *tick = -1; *t_us = 0; return; }
    const ad_segment *s = seg_at(dev, dev->n_seg - 1);
    uint64_t t = s->tick0 + (dev->head - 1 - s->row0);
    *tick = (int64_t)t;
    *t_us = s->t0_us + ad_round_half_up((double)(t - s->tick0) * dev->tick_us);
}

/* ---- layout of a message's stream ------------------------------------------------------- */
typedef struct col_group {
    uint8_t dtype;
    uint32_t n_cols;
} col_group;

static uint32_t message_groups(const ad_device *dev, const ad_msg *m, col_group *g, uint32_t max_g)
{
    uint32_t n = 0;
    for (uint32_t k = 0; k < m->n; k++) {
        const ad_var_rt *t = &dev->vrt[m->idx[k]];
        uint32_t j;
        for (j = 0; j < n && g[j].dtype != t->base; j++) {}
        if (j == n) {
            if (n == max_g) return n;
            g[n].dtype = t->base;
            g[n].n_cols = 0;
            n++;
        }
        g[j].n_cols += t->count;
    }
    return n;
}

static void write_layout(ad_wr *w, const ad_device *dev, const ad_msg *m)
{
    col_group g[11];
    uint32_t ng = message_groups(dev, m, g, 11), total = 0;
    for (uint32_t j = 0; j < ng; j++) total += g[j].n_cols;
    ad_wr_str(w, "columns");
    ad_wr_array(w, total);
    char name[160];
    for (uint32_t k = 0; k < m->n; k++) {
        const ad_var *v = &dev->vars[m->idx[k]];
        const ad_var_rt *t = &dev->vrt[m->idx[k]];
        if (!t->ndim) { ad_wr_str(w, v->name); continue; }
        for (uint32_t e = 0; e < t->count; e++) {
            ad_snprintf(name, sizeof name, "%s[%u]", v->name, e);
            ad_wr_str(w, name);
        }
    }
    static const char *const DT[] = {"bool", "i8", "i16", "i32", "i64", "u8", "u16", "u32",
                                      "u64", "f32", "f64"};
    ad_wr_str(w, "dtypes");
    ad_wr_array(w, ng);
    for (uint32_t j = 0; j < ng; j++) ad_wr_str(w, DT[g[j].dtype]);
    ad_wr_str(w, "groups");
    ad_wr_array(w, ng);
    for (uint32_t j = 0; j < ng; j++) {
        ad_wr_array(w, g[j].n_cols);
        uint32_t col = 0;
        for (uint32_t k = 0; k < m->n; k++) {
            const ad_var_rt *t = &dev->vrt[m->idx[k]];
            for (uint32_t e = 0; e < t->count; e++, col++)
                if (t->base == g[j].dtype) ad_wr_uint(w, col);
        }
    }
}

/* ---- STREAM_START / STREAM_STOP ------------------------------------------------------------ */
static ad_sampler *find_sub(ad_device *dev, const ad_session *s, uint32_t msg)
{
    for (uint32_t i = 0; i < dev->cfg.max_samplers; i++) {
        ad_sampler *sp = &dev->samplers[i];
        if (sp->used && sp->msg == msg && (sp->subscribers >> s->slot) & 1u) return sp;
    }
    return NULL;
}

static void unsubscribe(ad_device *dev, ad_session *s, ad_sampler *sp)
{
    (void)dev;
    sp->subscribers &= ~(1ull << s->slot);
    if (s->n_streams) s->n_streams--;
    if (!sp->subscribers) sp->used = 0;
}

int ad_stream_start(ad_device *dev, ad_session *s, uint32_t msg, double rate, ad_wr *w,
                    uint64_t seq, char *why, size_t wl)
{
    ad_msg m;
    ad_msg_find(dev, msg, &m);
    size_t used = 0;
    why[0] = 0;
    for (uint32_t k = 0; k < m.n; k++) {
        const ad_var_rt *t = &dev->vrt[m.idx[k]];
        if (t->base <= 10 && t->ndim != AD_VARLEN) continue;
        used += (size_t)ad_snprintf(why + used, used < wl ? wl - used : 0, "%s%s (%s)",
                                 used ? ", " : "cannot stream ", dev->vars[m.idx[k]].name,
                                 dev->vars[m.idx[k]].type);
    }
    if (used) {
        if (used < wl) ad_snprintf(why + used, wl - used, ": streams carry numeric scalars and "
                                "fixed-size numeric arrays");
        return 422;
    }
    double loop = dev->cfg.loop_rate_hz, lowest = loop / 4294967296.0;
    if (!(rate >= lowest && rate <= loop * (1 + 1e-9))) {
        ad_snprintf(why, wl, "rate_hz %g out of range: expected %.6g <= rate_hz <= %g: at most the "
                 "device loop rate (every tick), at least one sample every 2^32 ticks", rate,
                 lowest, loop);
        return 422;
    }
    ad_sampler *old = find_sub(dev, s, msg);
    if (!old && s->n_streams >= dev->cfg.max_streams_per_client) {
        ad_snprintf(why, wl, "this connection already runs %u streams (the maximum)", s->n_streams);
        return 429;
    }
    /* k = round(loop / rate), ties to even, as Python's round() */
    double q = loop / rate, fl = floor(q);
    uint64_t k = (uint64_t)fl;
    if (q - fl > 0.5 || (q - fl == 0.5 && (k & 1u))) k++;
    if (k < 1) k = 1;
    col_group g[11];
    uint32_t ng = message_groups(dev, &m, g, 11), cols = 0, row_bytes = 0;
    for (uint32_t j = 0; j < ng; j++) { cols += g[j].n_cols; row_bytes += g[j].n_cols * AD_DTYPE_SIZE[g[j].dtype]; }
    ad_sampler *sp = NULL;
    for (uint32_t i = 0; i < dev->cfg.max_samplers; i++)
        if (dev->samplers[i].used && dev->samplers[i].msg == msg && dev->samplers[i].k == k)
            sp = &dev->samplers[i];
    if (!sp) {
        for (uint32_t i = 0; !sp && i < dev->cfg.max_samplers; i++)
            if (!dev->samplers[i].used && &dev->samplers[i] != old) sp = &dev->samplers[i];
        if (!sp && old && old->subscribers == (1ull << s->slot)) sp = old; /* re-rate in place */
        if (!sp) {
            ad_snprintf(why, wl, "this device samples at most %u (message, rate) groups at once",
                     dev->cfg.max_samplers);
            return 429;
        }
        if (sp == old) { unsubscribe(dev, s, old); old = NULL; }
        memset(sp, 0, sizeof *sp);
        sp->used = 1;
        sp->msg = msg;
        sp->k = k;
        sp->period_us = (double)k * 1e6 / loop;
        /* samples per packet: about flush_interval_s worth, and what fits one frame */
        double want = loop / (double)k * dev->cfg.flush_interval_s;
        uint64_t spp = (uint64_t)ad_round_half_up(want);
        uint32_t overhead = 96 + ng * (8 + 40);
        uint64_t fit = row_bytes ? (dev->cfg.max_reply_bytes - overhead) / row_bytes : spp;
        uint64_t by_len = cols ? dev->cfg.max_array_len / cols : spp;
        /* a packet spans at most half the ring: the other half is the time the
         * communication side has to build it before its first row is overwritten (a
         * 20-ms ring with 20-ms packets would leave none) */
        uint64_t by_ring = dev->cfg.ring_ticks / 2u / k;
        if (spp > fit) spp = fit;
        if (spp > by_len) spp = by_len;
        if (spp > by_ring) spp = by_ring;
        if (spp < 1) spp = 1;
        sp->spp = (uint32_t)spp;
        int64_t tick, t_us;
        ad_port_lock();
        ad_last_tick(dev, &tick, &t_us);
        ad_port_unlock();
        uint64_t after = tick < 0 ? 0 : (uint64_t)tick + 1;
        sp->next_tick = (after + k - 1) / k * k;
    }
    if (old && old != sp) unsubscribe(dev, s, old);
    if (!((sp->subscribers >> s->slot) & 1u)) {
        sp->subscribers |= 1ull << s->slot;
        s->n_streams++;
    }
    ad_wr_array(w, 3);
    ad_wr_str(w, "OK");
    ad_wr_uint(w, seq);
    ad_wr_map(w, 8);
    ad_wr_str(w, "msg"); ad_wr_uint(w, msg);
    ad_wr_str(w, "rate_hz"); ad_wr_f64(w, loop / (double)k);
    ad_wr_str(w, "period_ticks"); ad_wr_uint(w, k);
    ad_wr_str(w, "period_us"); ad_wr_f64(w, sp->period_us);
    ad_wr_str(w, "samples_per_packet"); ad_wr_uint(w, sp->spp);
    write_layout(w, dev, &m);
    return 0;
}

int ad_stream_stop(ad_device *dev, ad_session *s, uint32_t msg)
{
    ad_sampler *sp = find_sub(dev, s, msg);
    if (!sp) return -1;
    unsubscribe(dev, s, sp);
    return 0;
}

void ad_stream_drop_message(ad_device *dev, ad_session *s, uint32_t msg)
{
    ad_stream_stop(dev, s, msg);
}

void ad_stream_drop_session(ad_device *dev, ad_session *s)
{
    for (uint32_t i = 0; i < dev->cfg.max_samplers; i++) {
        ad_sampler *sp = &dev->samplers[i];
        if (sp->used && (sp->subscribers >> s->slot) & 1u) unsubscribe(dev, s, sp);
    }
}

/* ---- building packets ---------------------------------------------------------------------- */
typedef struct ring_view {
    uint64_t head;
    uint32_t n_seg;
    ad_segment seg[AD_MAX_SEGMENTS];
} ring_view;

static uint64_t grid_count(uint64_t from, uint64_t to, uint64_t k)
{
    /* grid ticks (multiples of k) in [from, to) */
    if (to <= from) return 0;
    uint64_t a = (from + k - 1) / k, b = (to + k - 1) / k;
    return b - a;
}

/* Find the first row still in the ring whose tick is >= want_tick. `gone` counts the
 * grid ticks >= want_tick that were in the ring but were overwritten before now. */
static int locate(const ring_view *v, uint64_t oldest, uint64_t want_tick, uint64_t k,
                  uint64_t *row_out, const ad_segment **seg_out, uint64_t *seg_end,
                  uint64_t *gone)
{
    uint32_t first = v->n_seg > AD_MAX_SEGMENTS ? v->n_seg - AD_MAX_SEGMENTS : 0;
    *gone = 0;
    for (uint32_t i = first; i < v->n_seg; i++) {
        const ad_segment *s = &v->seg[i % AD_MAX_SEGMENTS];
        uint64_t end = i + 1 < v->n_seg ? v->seg[(i + 1) % AD_MAX_SEGMENTS].row0 : v->head;
        if (end <= s->row0) continue;
        uint64_t last_tick = s->tick0 + (end - 1 - s->row0);
        if (last_tick < want_tick) continue;
        uint64_t from_tick = want_tick > s->tick0 ? want_tick : s->tick0;
        uint64_t start = s->row0 > oldest ? s->row0 : oldest;
        if (start >= end) { *gone += grid_count(from_tick, last_tick + 1, k); continue; }
        uint64_t start_tick = s->tick0 + (start - s->row0);
        if (start_tick > from_tick) *gone += grid_count(from_tick, start_tick, k);
        *row_out = s->row0 + ((from_tick > start_tick ? from_tick : start_tick) - s->tick0);
        *seg_out = s;
        *seg_end = end;
        return 0;
    }
    return -1;
}

static void encode_packet(ad_device *dev, ad_sampler *sp, const ad_msg *m, const ad_segment *seg,
                          uint64_t row, uint64_t first_tick, uint32_t n, ad_wr *w)
{
    col_group g[11];
    uint32_t ng = message_groups(dev, m, g, 11);
    int64_t first_t_us = seg->t0_us + ad_round_half_up((double)(first_tick - seg->tick0) * dev->tick_us);
    ad_wr_array(w, 9);
    ad_wr_str(w, "DATA");
    ad_wr_uint(w, sp->msg);
    ad_wr_uint(w, sp->seq);
    ad_wr_uint(w, first_tick);
    ad_wr_int(w, first_t_us);
    ad_wr_f64(w, sp->period_us);
    ad_wr_uint(w, sp->k);
    ad_wr_uint(w, n);
    ad_wr_array(w, ng);
    for (uint32_t j = 0; j < ng; j++) {
        uint32_t isz = AD_DTYPE_SIZE[g[j].dtype];
        uint32_t shape[2] = {n, g[j].n_cols};
        ad_wr_ext(w, AD_EXT_NDARRAY, ad_ndarray_head_bytes(2) + n * g[j].n_cols * isz);
        ad_wr_ndarray_head(w, g[j].dtype, 2, shape);
        for (uint32_t i = 0; i < n; i++) {
            uint64_t r = row + (uint64_t)i * sp->k;
            const uint8_t *ring_row = dev->ring + (size_t)(r % dev->cfg.ring_ticks) * dev->row_bytes;
            /* columns that lie side by side in the ring row are copied in one run */
            const uint8_t *run = NULL;
            uint32_t run_len = 0;
            for (uint32_t k = 0; k < m->n; k++) {
                const ad_var_rt *rt = &dev->vrt[m->idx[k]];
                if (rt->base != g[j].dtype) continue;
                if (rt->trace_col >= 0) {
                    const uint8_t *p = ring_row + rt->ring_offset;
                    if (run && run + run_len == p) { run_len += isz; continue; }
                    if (run) ad_wr_raw(w, run, run_len);
                    run = p;
                    run_len = isz;
                } else {
                    if (run) { ad_wr_raw(w, run, run_len); run = NULL; }
                    /* parameters and untraced signals: their value now (end of the block) */
                    ad_port_lock();
                    ad_wr_raw(w, dev->vars[m->idx[k]].ptr, rt->count * isz);
                    ad_port_unlock();
                }
            }
            if (run) ad_wr_raw(w, run, run_len);
        }
    }
}

static void deliver(ad_device *dev, ad_sampler *sp, const ad_wr *w, uint32_t n)
{
    for (uint32_t i = 0; i < dev->n_sessions; i++) {
        ad_session *s = &dev->sessions[i];
        if (!((sp->subscribers >> i) & 1u) || !s->used || s->wants_close) continue;
        /* keep room for the largest reply: a stream never starves the replies */
        int dropped = s->sink.room(s->sink.ctx) < w->used + dev->cfg.max_reply_bytes
                      || s->sink.send(s->sink.ctx, dev->scratch, w->used, 1);
        if (dropped) {
            s->dropped_packets++;
            s->dropped_samples += n;
        }
    }
}

static void lost(ad_device *dev, ad_sampler *sp, uint64_t samples)
{
    if (!samples) return;
    dev->ring_lost += samples;
    for (uint32_t i = 0; i < dev->n_sessions; i++)
        if ((sp->subscribers >> i) & 1u) dev->sessions[i].dropped_samples += samples;
    sp->seq += (samples + sp->spp - 1) / sp->spp;
}

static void poll_sampler(ad_device *dev, ad_sampler *sp, const ring_view *v)
{
    ad_msg m;
    if (ad_msg_find(dev, sp->msg, &m)) { sp->used = 0; return; }
    uint64_t n_rows = dev->cfg.ring_ticks;
    for (int guard = 0; guard < 64; guard++) {
        /* rows older than head - N + 1 may be overwritten while we read them */
        uint64_t oldest = v->head > n_rows - 1 ? v->head - (n_rows - 1) : 0;
        uint64_t row, end, gone;
        const ad_segment *seg;
        if (locate(v, oldest, sp->next_tick, sp->k, &row, &seg, &end, &gone)) return;
        lost(dev, sp, gone);
        uint64_t tick = seg->tick0 + (row - seg->row0);
        uint64_t grid = (tick + sp->k - 1) / sp->k * sp->k;
        row += grid - tick;
        tick = grid;
        sp->next_tick = tick;
        if (row >= end) { if (end == v->head) return; continue; }
        uint64_t avail = (end - 1 - row) / sp->k + 1;
        uint32_t n = sp->spp;
        if (avail < n) {
            if (end == v->head) return; /* more of this segment is to come */
            n = (uint32_t)avail;        /* the segment ended: a short packet, no gap spanned */
        }
        ad_wr w;
        ad_wr_init(&w, dev->scratch, dev->cfg.max_reply_bytes);
        encode_packet(dev, sp, &m, seg, row, tick, n, &w);
        /* was any row overwritten while we copied it? */
        uint64_t head_now;
        ad_port_lock();
        head_now = dev->head;
        ad_port_unlock();
        uint64_t safe_from = head_now > n_rows - 1 ? head_now - (n_rows - 1) : 0;
        if (row < safe_from || w.overflow) {
            lost(dev, sp, n);
        } else {
            deliver(dev, sp, &w, n);
            sp->seq++;
        }
        sp->next_tick = tick + (uint64_t)n * sp->k;
    }
}

int64_t ad_stream_delay_us(ad_device *dev)
{
    int64_t tick, t_us, best = INT64_MAX;
    ad_port_lock();
    ad_last_tick(dev, &tick, &t_us);
    ad_port_unlock();
    for (uint32_t i = 0; i < dev->cfg.max_samplers; i++) {
        const ad_sampler *sp = &dev->samplers[i];
        if (!sp->used) continue;
        /* its packet is whole when the tick of its last sample is in the ring */
        double last = (double)sp->next_tick + (double)(sp->spp - 1u) * (double)sp->k;
        double ticks = last - (double)tick;
        int64_t us = ticks <= 0 ? 0 : (int64_t)(ticks * dev->tick_us);
        if (us < best) best = us;
    }
    return best;
}

void ad_stream_poll(ad_device *dev)
{
    ring_view v;
    int any = 0;
    for (uint32_t i = 0; i < dev->cfg.max_samplers; i++) any |= dev->samplers[i].used;
    if (!any) return;
    ad_port_lock();
    v.head = dev->head;
    v.n_seg = dev->n_seg;
    memcpy(v.seg, dev->seg, sizeof v.seg);
    ad_port_unlock();
    for (uint32_t i = 0; i < dev->cfg.max_samplers; i++)
        if (dev->samplers[i].used) poll_sampler(dev, &dev->samplers[i], &v);
}
