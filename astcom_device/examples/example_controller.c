/* The example controller (example_controller.h). */
#include "example_controller.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#define PI 3.14159265358979323846
#define ARCSEC_PER_RAD 206264.80624709636
#define DEG (PI / 180.0)

#ifdef EX_MCU
/* the MCU build: no doc texts (flash, and LIST fits a 5 KiB reply); only the sixteen
 * f32 extras are traced (a 20 ms ring of 16 f32 signals at 10 kHz is 12.8 KiB) */
#define DOC(d) ""
#define TRACED 0
#define EXTRA_TYPE "f32"
typedef float extra_t;
#else
#define DOC(d) d
#define TRACED 1
#define EXTRA_TYPE "f64"
typedef double extra_t;
#endif
/* ---- the Python example device's variables (astcom_client/example_device.py) -------- */
static struct {
    double sine, cosine, diff;
    extra_t extra[EX_MAX_EXTRA];
    int64_t counter;
    double amplitude, frequency_hz, offset, pair_a, pair_b;
    double gains[3];
    char label[64];
    struct { double lat_deg, lon_deg; } site;
    double voltage_v;
    char mode[32];
    double current_a;
    uint8_t enabled;
    uint64_t counter_base;
} W;

/* ---- the follower ------------------------------------------------------------------------ */
typedef struct point { int64_t t_us; double pos[2], rate[2]; } point;

typedef struct axis {
    double position, velocity, demand, error_arcsec;
    int64_t state, faults;
    char fault_text[48];
    double rate_limit, accel_limit, ctrl_rate_limit, pos_min, pos_max;
    double target;        /* a slew's goal */
} axis;

static struct {
    axis ax[2];
    int64_t mount_state, tick, mount_us, sync_count;
    int64_t traj_count, traj_free, traj_capacity, underruns, late, pushed;
    point buf[EX_TRAJ_CAPACITY];
    uint32_t head, count;
    int started;           /* traj.start given: following the buffer */
    int64_t armed_second;  /* time.set_utc, applied at the next PPS edge */
    int64_t clock_offset_us;
    double rate_hz, tick_us;
    int64_t start_t_us;
    ex_clock_fn wall_us;
    uint64_t last_tick;
} F;

static void set_state(axis *a, int64_t s) { a->state = s; }

static void update_mount_state(void)
{
    axis *a = &F.ax[0], *e = &F.ax[1];
    int64_t s;
    if (a->state == EX_FAULT || e->state == EX_FAULT) s = EX_FAULT;
    else if (a->state == EX_OFF && e->state == EX_OFF) s = EX_OFF;
    else if (a->state == EX_TRACKING || e->state == EX_TRACKING) s = EX_TRACKING;
    else if (a->state == EX_SLEWING || e->state == EX_SLEWING) s = EX_SLEWING;
    else if (a->state == EX_STOPPING || e->state == EX_STOPPING) s = EX_STOPPING;
    else if (a->state == EX_OFF || e->state == EX_OFF) s = EX_HOLDING;
    else s = EX_HOLDING;
    F.mount_state = s;
    F.traj_count = F.count;
    F.traj_free = EX_TRAJ_CAPACITY - F.count;
}

void ex_init(double rate_hz, int64_t start_t_us, ex_clock_fn wall_us)
{
    memset(&W, 0, sizeof W);
    memset(&F, 0, sizeof F);
    W.amplitude = 1.0;
    W.frequency_hz = 5.0;
    W.gains[0] = 1.0; W.gains[1] = 0.1; W.gains[2] = 0.01;
    ad_snprintf(W.label, sizeof W.label, "example");
    W.site.lat_deg = 45.0;
    W.site.lon_deg = 6.0;
    W.voltage_v = 24.0;
    ad_snprintf(W.mode, sizeof W.mode, "idle");
    W.current_a = 2.5;
    W.enabled = 1;
    F.rate_hz = rate_hz;
    F.tick_us = 1e6 / rate_hz;
    F.start_t_us = start_t_us;
    F.wall_us = wall_us;
    F.traj_capacity = EX_TRAJ_CAPACITY;
    for (int i = 0; i < 2; i++) {
        axis *a = &F.ax[i];
        a->rate_limit = 5.0 * DEG;
        a->accel_limit = 2.0 * DEG;
        a->ctrl_rate_limit = 1.0 * DEG;
        ad_snprintf(a->fault_text, sizeof a->fault_text, "none");
    }
    F.ax[0].pos_min = -270.0 * DEG; F.ax[0].pos_max = 270.0 * DEG;
    F.ax[1].pos_min = 0.0 * DEG; F.ax[1].pos_max = 90.0 * DEG;
    F.ax[1].position = F.ax[1].demand = F.ax[1].target = 85.0 * DEG;
    update_mount_state();
}

/* ---- the tick ------------------------------------------------------------------------------ */
static int64_t mount_time(uint64_t tick)
{
    double x = (double)tick * F.tick_us, f = floor(x);
    return F.start_t_us + F.clock_offset_us + (int64_t)f + (x - f >= 0.5);
}

static void fault(axis *a, int64_t bit, const char *text)
{
    a->faults |= bit;
    ad_snprintf(a->fault_text, sizeof a->fault_text, "%s", text);
    a->velocity = 0.0;
    set_state(a, EX_FAULT);
}

/* Move toward `goal` under the rate and acceleration limits; 1 when arrived. */
static int ramp_to(axis *a, double goal, double dt)
{
    double d = goal - a->position;
    double vmax = a->rate_limit, acc = a->accel_limit;
    double v_des = sqrt(2.0 * acc * fabs(d));
    if (v_des > vmax) v_des = vmax;
    if (d < 0) v_des = -v_des;
    double dv = v_des - a->velocity, step = acc * dt;
    a->velocity += dv > step ? step : dv < -step ? -step : dv;
    double move = a->velocity * dt;
    if (fabs(d) <= fabs(move) || (fabs(d) < 1e-9 && fabs(a->velocity) < acc * dt * 2)) {
        a->position = goal;
        a->velocity = 0.0;
        return 1;
    }
    a->position += move;
    return 0;
}

static int stop_axis(axis *a, double dt)
{
    double step = a->accel_limit * dt;
    if (fabs(a->velocity) <= step) { a->velocity = 0.0; return 1; }
    a->velocity -= a->velocity > 0 ? step : -step;
    a->position += a->velocity * dt;
    return 0;
}

static void hermite(const point *p0, const point *p1, int64_t t_us, int i, double *pos)
{
    double h = (double)(p1->t_us - p0->t_us) * 1e-6;
    double s = (double)(t_us - p0->t_us) * 1e-6 / h;
    double s2 = s * s, s3 = s2 * s;
    *pos = (2 * s3 - 3 * s2 + 1) * p0->pos[i] + (s3 - 2 * s2 + s) * h * p0->rate[i]
           + (-2 * s3 + 3 * s2) * p1->pos[i] + (s3 - s2) * h * p1->rate[i];
}

static void follow(int64_t now_us, double dt)
{
    while (F.count >= 2 && F.buf[(F.head + 1) % EX_TRAJ_CAPACITY].t_us <= now_us) {
        F.head = (F.head + 1) % EX_TRAJ_CAPACITY;
        F.count--;
    }
    const point *p0 = &F.buf[F.head];
    if (!F.count || (F.count == 1 && now_us > p0->t_us)) {
        /* the buffer ran dry: ramp to rest */
        F.underruns++;
        F.count = 0;
        F.started = 0;
        for (int i = 0; i < 2; i++) set_state(&F.ax[i], EX_STOPPING);
        return;
    }
    for (int i = 0; i < 2; i++) {
        axis *a = &F.ax[i];
        double d = a->position;
        if (now_us >= p0->t_us && F.count >= 2)
            hermite(p0, &F.buf[(F.head + 1) % EX_TRAJ_CAPACITY], now_us, i, &d);
        else if (now_us >= p0->t_us)
            d = p0->pos[i];
        if (d < a->pos_min || d > a->pos_max) { fault(a, 4, "position limit"); continue; }
        /* an ideal servo, whose steps are capped at the slew rate */
        double step = d - a->position, cap = a->rate_limit * dt;
        if (step > cap) step = cap;
        if (step < -cap) step = -cap;
        a->velocity = step / dt;
        a->position += step;
        a->demand = d;
        a->error_arcsec = (a->position - d) * ARCSEC_PER_RAD;
    }
}

int64_t ex_step(uint64_t tick)
{
    double dt = 1.0 / F.rate_hz;
    /* the wave generator of the Python example device */
    double phase = 2 * PI * W.frequency_hz * (double)tick / F.rate_hz;
#ifdef EX_MCU /* single precision: the Cortex-M4F's FPU, and no double libm in flash */
    float ph = (float)(phase - 2 * PI * floor(phase / (2 * PI)));
    W.sine = W.amplitude * sinf(ph) + W.offset;
    W.cosine = W.amplitude * cosf(ph);
    for (int i = 0; i < EX_MAX_EXTRA; i++) W.extra[i] = sinf(ph + (float)i);
#else
    W.sine = W.amplitude * sin(phase) + W.offset;
    W.cosine = W.amplitude * cos(phase);
    for (int i = 0; i < EX_MAX_EXTRA; i++) W.extra[i] = (extra_t)sin(phase + i);
#endif
    W.counter = (int64_t)(tick - W.counter_base);
    W.diff = W.pair_a - W.pair_b;
    /* the clock: an armed UTC second is taken at the PPS edge (the host clock's second) */
    int64_t now = mount_time(tick);
    if (F.armed_second) {
        int64_t wall = F.wall_us ? F.wall_us() : now;
        if (wall >= F.armed_second * 1000000) {
            F.clock_offset_us += F.armed_second * 1000000 + (wall - F.armed_second * 1000000) - now;
            F.armed_second = 0;
            F.sync_count++;
            now = mount_time(tick);
        }
    }
    F.tick = (int64_t)tick;
    F.mount_us = now;
    /* the axes */
    if (F.started) follow(now, dt);
    for (int i = 0; i < 2; i++) {
        axis *a = &F.ax[i];
        if (a->state == EX_SLEWING && ramp_to(a, a->target, dt)) set_state(a, EX_HOLDING);
        if (a->state == EX_STOPPING && stop_axis(a, dt)) set_state(a, EX_HOLDING);
        if (a->state != EX_TRACKING) { a->demand = a->position; a->error_arcsec = 0.0; }
    }
    update_mount_state();
    F.last_tick = tick;
    return now;
}

/* ---- functions ------------------------------------------------------------------------------ */
static int fn_counter_reset(ad_call *c, void *u)
{
    (void)u;
    ad_return_i64(c, (int64_t)(F.last_tick + 1 - W.counter_base));
    W.counter_base = F.last_tick + 1;
    return AD_OK;
}

static int fn_add(ad_call *c, void *u)
{
    (void)u;
    ad_return_f64(c, ad_arg_f64(c, 0) + ad_arg_f64(c, 1));
    return AD_OK;
}

static int fn_sum(ad_call *c, void *u)
{
    double s = 0.0;
    (void)u;
    for (uint32_t k = 0; k < ad_arg_len(c, 0); k++) s += ad_arg_elem_f64(c, 0, k);
    ad_return_f64(c, s);
    return AD_OK;
}

static int fn_fail(ad_call *c, void *u)
{
    (void)u;
    return ad_fail(c, "RuntimeError: this function always fails");
}

/* device.wait: answered later, without blocking the loop */
typedef struct wait_state { int64_t until_us; double seconds; int started; } wait_state;
static int resume_wait(ad_call *c, void *u, int64_t now_us)
{
    wait_state *w = (wait_state *)ad_call_state(c);
    (void)u;
    if (!w->started) { w->started = 1; w->until_us += now_us; }
    if (now_us < w->until_us) return AD_PENDING;
    ad_return_f64(c, w->seconds);
    return AD_OK;
}
static int fn_wait(ad_call *c, void *u)
{
    wait_state *w = (wait_state *)ad_call_state(c);
    double s = ad_arg_f64(c, 0);
    (void)u;
    w->seconds = s;
    w->until_us = (int64_t)((s < 0 ? 0 : s > 5 ? 5 : s) * 1e6);
    w->started = 0;
    return ad_defer(c, resume_wait);
}

static int fn_power_on(ad_call *c, void *u)
{
    (void)c; (void)u;
    for (int i = 0; i < 2; i++)
        if (F.ax[i].state == EX_OFF) set_state(&F.ax[i], EX_HOLDING);
    update_mount_state();
    return AD_OK;
}

static int fn_power_off(ad_call *c, void *u)
{
    (void)c; (void)u;
    for (int i = 0; i < 2; i++)
        if (F.ax[i].state != EX_FAULT) { F.ax[i].velocity = 0.0; set_state(&F.ax[i], EX_OFF); }
    F.started = 0;
    update_mount_state();
    return AD_OK;
}

static int fn_stop(ad_call *c, void *u)
{
    (void)c; (void)u;
    for (int i = 0; i < 2; i++) {
        axis *a = &F.ax[i];
        if (a->state == EX_SLEWING || a->state == EX_TRACKING || a->state == EX_MANUAL)
            set_state(a, EX_STOPPING);
    }
    F.started = 0;
    update_mount_state();
    return AD_OK;
}

static int fn_slew(ad_call *c, void *u)
{
    double goal[2] = {ad_arg_f64(c, 0) * DEG, ad_arg_f64(c, 1) * DEG};
    char why[120];
    (void)u;
    for (int i = 0; i < 2; i++) {
        axis *a = &F.ax[i];
        if (a->state == EX_FAULT) return ad_fail(c, "the mount is in FAULT: reset the faults first");
        if (a->state == EX_OFF) return ad_fail(c, "the axes are off: power them on first");
        if (a->state == EX_TRACKING) return ad_fail(c, "the mount is tracking: reset the trajectory first");
        if (!(goal[i] >= a->pos_min && goal[i] <= a->pos_max)) {
            ad_snprintf(why, sizeof why, "%s %.4f deg is outside %.1f..%.1f deg", i ? "el" : "az",
                     goal[i] / DEG, a->pos_min / DEG, a->pos_max / DEG);
            return ad_fail(c, why);
        }
    }
    for (int i = 0; i < 2; i++) { F.ax[i].target = goal[i]; set_state(&F.ax[i], EX_SLEWING); }
    update_mount_state();
    return AD_OK;
}

static int fn_traj_init(ad_call *c, void *u)
{
    (void)c; (void)u;
    F.head = F.count = 0;
    F.started = 0;
    F.underruns = F.late = F.pushed = 0;
    update_mount_state();
    return AD_OK;
}

static int fn_traj_start(ad_call *c, void *u)
{
    (void)u;
    for (int i = 0; i < 2; i++) {
        axis *a = &F.ax[i];
        if (a->state != EX_HOLDING) return ad_fail(c, "the axes must be holding to start a trajectory");
    }
    if (!F.count) return ad_fail(c, "the trajectory buffer is empty");
    F.started = 1;
    for (int i = 0; i < 2; i++) set_state(&F.ax[i], EX_TRACKING);
    update_mount_state();
    return AD_OK;
}

static int fn_traj_reset(ad_call *c, void *u)
{
    (void)c; (void)u;
    F.head = F.count = 0;
    F.started = 0;
    for (int i = 0; i < 2; i++)
        if (F.ax[i].state == EX_TRACKING) set_state(&F.ax[i], EX_STOPPING);
    update_mount_state();
    return AD_OK;
}

static int fn_traj_push(ad_call *c, void *u)
{
    uint32_t n = ad_arg_len(c, 0);
    (void)u;
    for (uint32_t i = 1; i < 5; i++)
        if (ad_arg_len(c, i) != n) return ad_fail(c, "ValueError: the five arrays must have the same length");
    uint32_t accepted = 0;
    for (uint32_t k = 0; k < n; k++) {
        point p;
        p.t_us = ad_arg_elem_i64(c, 0, k);
        p.pos[0] = ad_arg_elem_f64(c, 1, k);
        p.pos[1] = ad_arg_elem_f64(c, 2, k);
        p.rate[0] = ad_arg_elem_f64(c, 3, k);
        p.rate[1] = ad_arg_elem_f64(c, 4, k);
        int64_t last = F.count ? F.buf[(F.head + F.count - 1) % EX_TRAJ_CAPACITY].t_us : INT64_MIN;
        if (F.count == EX_TRAJ_CAPACITY) break;
        if (p.t_us <= last || p.t_us <= F.mount_us || !isfinite(p.pos[0]) || !isfinite(p.pos[1])
                || !isfinite(p.rate[0]) || !isfinite(p.rate[1])) {
            F.late += p.t_us <= F.mount_us;
            continue;
        }
        F.buf[(F.head + F.count) % EX_TRAJ_CAPACITY] = p;
        F.count++;
        accepted++;
    }
    F.pushed += accepted;
    update_mount_state();
    ad_return_u64(c, accepted);
    return AD_OK;
}

static int fn_set_utc(ad_call *c, void *u)
{
    (void)u;
    F.armed_second = ad_arg_i64(c, 0);
    return AD_OK;
}

static int fn_safety_reset(ad_call *c, void *u)
{
    (void)c; (void)u;
    for (int i = 0; i < 2; i++) {
        axis *a = &F.ax[i];
        a->faults = 0;
        ad_snprintf(a->fault_text, sizeof a->fault_text, "none");
        if (a->state == EX_FAULT) set_state(a, EX_OFF);
    }
    update_mount_state();
    return AD_OK;
}

static int fn_now(ad_call *c, void *u)
{
    (void)u;
    ad_return_i64(c, F.mount_us);
    return AD_OK;
}

/* ---- the tables -------------------------------------------------------------------------- */
#define SIG(n, t, p, un, d) {n, t, AD_SIGNAL, AD_R, TRACED, 0, 0, 0, 0, un, DOC(d), p, 0, NULL}
#define VAL(n, t, p, un, d) {n, t, AD_SIGNAL, AD_R, 0, 0, 0, 0, 0, un, DOC(d), p, 0, NULL}
#define PAR(n, t, p, un, d) {n, t, AD_PARAMETER, AD_RW, 0, 0, 0, 0, 0, un, DOC(d), p, 0, NULL}
#define RANGED(n, t, p, lo, hi, un, d) {n, t, AD_PARAMETER, AD_RW, 0, 1, 1, lo, hi, un, DOC(d), p, 0, NULL}
#define POSITIVE(n, p, hi, un, d) {n, "f64", AD_PARAMETER, AD_RW, 0, 1, 1, 1e-9, hi, un, DOC(d), p, 0, NULL}
#define TEXT(n, k, a, p, cap, d) {n, "str", k, a, 0, 0, 0, 0, 0, "", DOC(d), p, cap, NULL}

#ifdef EX_MCU
static const ad_var VARS[] = {
#else
static ad_var VARS[] = {
#endif
    SIG("wave.sine", "f64", &W.sine, "V", "amplitude*sin(2*pi*frequency_hz*t) + offset"),
    SIG("wave.cosine", "f64", &W.cosine, "V", "amplitude*cos(2*pi*frequency_hz*t)"),
    SIG("counter", "i64", &W.counter, "", "Tick number"),
    SIG("pair.diff", "f64", &W.diff, "", "pair.a - pair.b: zero while both are written together"),
    RANGED("wave.amplitude", "f64", &W.amplitude, 0.0, 100.0, "V", "Sine amplitude"),
    RANGED("wave.frequency_hz", "f64", &W.frequency_hz, 0.0, 5000.0, "Hz", "Sine frequency"),
    PAR("wave.offset", "f64", &W.offset, "V", "Sine offset"),
    PAR("pair.a", "f64", &W.pair_a, "", "Written together with pair.b"),
    PAR("pair.b", "f64", &W.pair_b, "", "Written together with pair.a"),
    RANGED("gains", "f64[3]", W.gains, 0.0, 1000.0, "", "PID gains kp, ki, kd"),
    TEXT("label", AD_PARAMETER, AD_RW, W.label, sizeof W.label, "Device label"),
    PAR("site", "{lat_deg:f64,lon_deg:f64}", &W.site, "deg", "Site position"),
    VAL("power.voltage_v", "f64", &W.voltage_v, "V", "Bus voltage"),
    TEXT("power.mode", AD_PARAMETER, AD_RW, W.mode, sizeof W.mode, "Power mode name"),
    PAR("power.limits.current_a", "f64", &W.current_a, "A", "Current limit of the drive"),
    PAR("power.limits.enabled", "bool", &W.enabled, "", "Drive enabled"),
    /* the follower */
    SIG("mount.tick", "i64", &F.tick, "", "Tick number of the follower's loop"),
    SIG("time.mount_us", "i64", &F.mount_us, "us", "Mount clock (µs since 1970 UTC)"),
    VAL("time.sync_count", "i64", &F.sync_count, "", "UTC seconds taken at a PPS edge"),
    VAL("mount.state", "i64", &F.mount_state, "", "0 off, 1 holding, 2 slewing, 3 tracking, 4 manual, 5 stopping, 6 fault"),
    SIG("axis.az.position", "f64", &F.ax[0].position, "rad", "Azimuth encoder"),
    SIG("axis.el.position", "f64", &F.ax[1].position, "rad", "Elevation encoder"),
    SIG("axis.az.velocity", "f64", &F.ax[0].velocity, "rad/s", "Azimuth rate"),
    SIG("axis.el.velocity", "f64", &F.ax[1].velocity, "rad/s", "Elevation rate"),
    SIG("axis.az.demand", "f64", &F.ax[0].demand, "rad", "Azimuth demand"),
    SIG("axis.el.demand", "f64", &F.ax[1].demand, "rad", "Elevation demand"),
    SIG("axis.az.error_arcsec", "f64", &F.ax[0].error_arcsec, "arcsec", "Azimuth position minus demand"),
    SIG("axis.el.error_arcsec", "f64", &F.ax[1].error_arcsec, "arcsec", "Elevation position minus demand"),
    VAL("axis.az.state", "i64", &F.ax[0].state, "", "Azimuth axis state (as mount.state)"),
    VAL("axis.el.state", "i64", &F.ax[1].state, "", "Elevation axis state (as mount.state)"),
    VAL("axis.az.faults", "i64", &F.ax[0].faults, "", "Azimuth latched faults (bit 2: position limit)"),
    VAL("axis.el.faults", "i64", &F.ax[1].faults, "", "Elevation latched faults (bit 2: position limit)"),
    TEXT("axis.az.fault_text", AD_SIGNAL, AD_R, F.ax[0].fault_text, sizeof F.ax[0].fault_text, "Azimuth latched faults as text"),
    TEXT("axis.el.fault_text", AD_SIGNAL, AD_R, F.ax[1].fault_text, sizeof F.ax[1].fault_text, "Elevation latched faults as text"),
    POSITIVE("axis.az.rate_limit", &F.ax[0].rate_limit, 1.0, "rad/s", "Slew rate limit"),
    POSITIVE("axis.el.rate_limit", &F.ax[1].rate_limit, 1.0, "rad/s", "Slew rate limit"),
    POSITIVE("axis.az.accel_limit", &F.ax[0].accel_limit, 1.0, "rad/s2", "Slew acceleration limit"),
    POSITIVE("axis.el.accel_limit", &F.ax[1].accel_limit, 1.0, "rad/s2", "Slew acceleration limit"),
    POSITIVE("axis.az.ctrl_rate_limit", &F.ax[0].ctrl_rate_limit, 1.0, "rad/s", "Tracking rate limit"),
    POSITIVE("axis.el.ctrl_rate_limit", &F.ax[1].ctrl_rate_limit, 1.0, "rad/s", "Tracking rate limit"),
    VAL("axis.az.position_min", "f64", &F.ax[0].pos_min, "rad", "Azimuth limit (cable wrap)"),
    VAL("axis.az.position_max", "f64", &F.ax[0].pos_max, "rad", "Azimuth limit (cable wrap)"),
    VAL("axis.el.position_min", "f64", &F.ax[1].pos_min, "rad", "Elevation limit"),
    VAL("axis.el.position_max", "f64", &F.ax[1].pos_max, "rad", "Elevation limit"),
    VAL("traj.free_points", "i64", &F.traj_free, "", "Free space in the trajectory buffer (points)"),
    VAL("traj.count", "i64", &F.traj_count, "", "Points in the trajectory buffer"),
    VAL("traj.capacity", "i64", &F.traj_capacity, "", "Trajectory buffer capacity (points)"),
    VAL("traj.underruns", "i64", &F.underruns, "", "Times the buffer ran dry while following"),
    VAL("traj.late", "i64", &F.late, "", "Points refused because their time had passed"),
    /* extra.sNN come last: the application passes as many as it wants */
#define EXTRA(i, s) {"extra.s" s, EXTRA_TYPE, AD_SIGNAL, AD_R, 1, 0, 0, 0, 0, "", DOC("sin(2*pi*frequency_hz*t + " #i ")"), &W.extra[i], 0, NULL}
    EXTRA(0, "00"), EXTRA(1, "01"), EXTRA(2, "02"), EXTRA(3, "03"), EXTRA(4, "04"),
    EXTRA(5, "05"), EXTRA(6, "06"), EXTRA(7, "07"), EXTRA(8, "08"), EXTRA(9, "09"),
    EXTRA(10, "10"), EXTRA(11, "11"), EXTRA(12, "12"), EXTRA(13, "13"), EXTRA(14, "14"),
    EXTRA(15, "15"),
};

static const ad_fn FNS[] = {
    {"counter.reset", "()->i64", fn_counter_reset, NULL, DOC("Restart the counter at 0; returns the tick it had reached")},
    {"math.add", "(a:f64,b:f64)->f64", fn_add, NULL, DOC("Return a + b")},
    {"math.sum", "(x:f64[])->f64", fn_sum, NULL, DOC("Return the sum of an array")},
    {"device.fail", "()->none", fn_fail, NULL, DOC("Always raise (to test error replies)")},
    {"device.wait", "(seconds:f64)->f64", fn_wait, NULL, DOC("Sleep without blocking the loop, return the seconds slept")},
    {"mount.power_on", "()->none", fn_power_on, NULL, DOC("Close the loops of the axes that are off, holding")},
    {"mount.power_off", "()->none", fn_power_off, NULL, DOC("Cut both drives")},
    {"mount.stop", "()->none", fn_stop, NULL, DOC("Ramp both axes to rest")},
    {"mount.slew", "(az_deg:f64,el_deg:f64)->none", fn_slew, NULL, DOC("Slew both axes to (az, el) encoder degrees under the rate/accel limits")},
    {"traj.init", "()->none", fn_traj_init, NULL, DOC("Empty the trajectory buffer, zero its counters")},
    {"traj.start", "()->none", fn_traj_start, NULL, DOC("Start following the trajectory buffer")},
    {"traj.reset", "()->none", fn_traj_reset, NULL, DOC("Abort the trajectory: ramp to rest, empty the buffer")},
    {"traj.push_rates", "(t_us:i64[],az_rad:f64[],el_rad:f64[],az_rate_rad_s:f64[],el_rate_rad_s:f64[])->u32", fn_traj_push, NULL, DOC("Append points with their rates; returns the accepted count")},
    {"time.set_utc", "(utc_second:i64)->none", fn_set_utc, NULL, DOC("Arm a UTC second (since 1970): the mount clock takes it at the next PPS edge")},
    {"time.now_us", "()->i64", fn_now, NULL, DOC("Return the mount clock (µs since 1970 UTC)")},
    {"safety.reset", "()->none", fn_safety_reset, NULL, DOC("Clear latched faults; faulted axes go to OFF")},
};

const ad_var *ex_vars(unsigned n_extra, size_t *n)
{
    if (n_extra > EX_MAX_EXTRA) n_extra = EX_MAX_EXTRA;
    *n = sizeof VARS / sizeof VARS[0] - EX_MAX_EXTRA + n_extra;
#ifndef EX_MCU /* the MCU's table is in flash: its loop is 10 kHz, the bound 5 kHz */
    /* the frequency's upper bound is half the loop rate, as the Python device says */
    for (size_t i = 0; i < *n; i++)
        if (!strcmp(VARS[i].name, "wave.frequency_hz")) VARS[i].max = F.rate_hz / 2.0;
#endif
    return VARS;
}

const ad_fn *ex_fns(size_t *n)
{
    *n = sizeof FNS / sizeof FNS[0];
    return FNS;
}
